"""The printed matrices, gains, pole sets, transfer functions and coefficients of chapters 3–5 and appendix A,
as claims (``twin.app.reproduction.claims``) recomputed on ``models.Model``.

Two recomputations matter: from the thesis's *printed* intermediate results (does the step follow?) and from
the *model* (Tables 3.1/3.2 through eq 3.1.26/3.1.27: does the number follow from the rig?). Each claim's
``recompute`` is the one its check is about; the other appears in its prose or as a hypothesis.
Printed values not held in ``controllers.thesis_numbers`` are defined here.
"""

from __future__ import annotations

import math
from typing import Any

import control
import numpy as np

from controllers import thesis_numbers as tn
from controllers.design import clp_effective_gain, clp_gains, state_feedback_gain
from twin.app.reproduction.claims import (
    FAILS,
    HOLDS,
    INCONSISTENT,
    MISPRINT,
    Claim,
    Close,
    Hypothesis,
    Predicate,
)
from twin.app.reproduction.models import (
    C_OUT,
    Model,
    match,
    pct,
    regular_form,
    rounded,
    sorted_eig,
    theta_row,
    transfer_function,
    vec,
    x_row,
)
from twin.reference import discretize_zoh

__all__ = ["CLAIMS"]

T = tn.PERIOD_S

# --- printed values not held in controllers.thesis_numbers -------------------------------------------------
EQ323 = {  # eq 3.2.3: ẍ numerator coefficients
    "sin θ": -0.0389,
    "x² sin θ": -0.1849,
    "x θ̇²": 0.00401,
    "x cos θ": -0.00406,
    "x ẋ θ̇": -0.000828,
    "x³ θ̇²": 0.01884,
    "τ": 0.02196,
}
EQ324 = {"τ": 2.2691, "sin θ": 0.0351, "x cos θ": -0.4195, "x ẋ θ̇": -0.08553, "x θ̇²": 0.000526}  # eq 3.2.4
EQ32_DEN = (0.00908, 0.0427)  # denominator 0.00908 + 0.0427·x² of eq 3.2.3/3.2.4
A32_COINCIDENCE_DEN = 0.0098  # the printed denominator with a digit dropped (0.00908 → 0.0098)
SLIP = 10  # a slip of the decimal point
SIGN_TOLERANCE = 0.1
DROPPED_DIGIT = 10  # a leading "1" lost: 11.685 printed as 1.685

# §4.2: the desired polynomial (s² + 3s + 9)(s + 7.5)², its ζ/ω_n reading, t_s and ζ as printed
SF_SPEC = {"c1": 3.0, "c0": 9.0, "far": -7.5}
SF_TS_ZETA = [2.67, 0.5]
CLP_SPEC_POLES = [-2.0] * 4  # §4.3: ζ = 1, ω_n = 2 for both loops

# §4.4 regular-form blocks "using (3.2.8) and (3.2.9)"
SMC_A11 = np.array([[0.0, 0.0, -0.011], [0.057, 0.00035, -4.012], [1.0, -4e-6, 0.057]])
SMC_A12 = np.array([[-1.0], [0.0455], [-0.000645]])
SMC_A21 = np.array([[0.043, 42.45, -3.811]])
SMC_A22 = np.array([[-0.587]])
SMC_B2 = -4.092

# Appendix A, state-feedback callback: observer coefficients (x̂3(k−1), x̂4(k−1), x1(k−1), x2(k−1), u(k−1),
# x1(k), x2(k)) and the u_temp gains
APPX_SF_OBS = [
    [0.9207, -0.1601, -3.9409, -8.0826, -0.0055, 4.0, 8.0],
    [0.2927, 0.7494, 14.257, -11.945, 0.0717, -15.0, 12.0],
]
APPX_SF_G = np.array([[4.0, 8.0], [-15.0, 12.0]])  # as coded (+4·x1(k) + 8·x2(k))
APPX_SF_K = np.array([[-36.3437, 24.5992, -15.9593, 3.9815]])
# Appendix A, CLP callback: observer coefficients (u(k−1), x1(k−1), x2(k−1), x̂3(k−1), x̂4(k−1), x1(k), x2(k))
APPX_CLP_OBS = [
    [0.066, -40.011, 0.1797, 0.2, 0.0036, 39.9998, -0.227],
    [3.0244, -0.462, -39.563, -0.0036, 0.2, -0.0452, 39.608],
]
APPX_CLP_G = np.array([[39.9998, -0.227], [-0.0452, 39.608]])
APPX_CLP_BETA = [0.17, 0.0346, -0.000373]  # x cosθ, x ẋ θ̇, x θ̇²
APPX_CLP_ALPHA = [0.003833, 0.01732]  # α₁ and α₂'s x² coefficient as coded
APPX_CLP_GAINS = [[-40.0, 38.0], [-23.5604, 5.1736]]  # kp, kv diagonals


# --- chapter 3 ---------------------------------------------------------------------------------------------
def _r_star_used_by_derived(m: Model, rs: float) -> bool:
    return bool(Close(rel=1e-3, decimals="printed")(EQ324["τ"], m.k1_plus_1(rs)).passed.all())


def _explain_r_star(m: Model, rs: float) -> str:
    r, d = m.params.ball.radius_m, m.params.track.contact_spacing_m
    return (
        f"√(r² − d²/4) with r = {r * 1e3:.4g} mm, d = {d * 1e3:.5g} mm is {rs * 1e3:.4g} mm; eq 3.2.4's τ "
        "coefficient "
        f"2r²/(5r*²) + 1 is {m.k1_plus_1(rs):.5g} with it and {m.k1_plus_1(tn.R_STAR_PRINTED_M):.5g} with "
        "the printed "
        f"r* (printed {EQ324['τ']})."
    )


def _explain_j(m: Model, j: float) -> str:
    return (
        f"Eq 3.1.21 J = 2/5·m·r² = {j:.4g} kg·m²; eq 3.2.4's τ coefficient J/(m r*²) + 1 is "
        f"{m.k1_plus_1(m.rolling_radius_m, j):.5g} with it, "
        f"{m.k1_plus_1(m.rolling_radius_m, tn.J_BALL_PRINTED_KGM2):.5g} "
        "with the tabulated J."
    )


K2_DROPPED = (
    "2r²/(5r*) is missing from the θ̈ coupling of 3.1.26 where it enters the ẍ solution (h* + r* alone)"
)


def _explain_eq323(m: Model, full: list[float]) -> str:
    q = m.coefficients.parts(m.params)
    return (
        f"2r²/(5r*) = {q['k2'] * 1e3:.4g} mm, h* + r* = {q['c'] * 1e3:.4g} mm; with the term kept the τ "
        f"coefficient is {full[-1]:.4g}, without it {m.numerators(x_row_k2=False)[0]['τ']:.4g}."
    )


def _explain_x_row(m: Model, row: np.ndarray) -> str:
    coincidence = EQ323["sin θ"] / A32_COINCIDENCE_DEN
    return (
        f"Model A31, A32, B3 = {vec(row)}; with 2r²/(5r*) dropped {vec(x_row(*m.linear(x_row_k2=False)))}. "
        f"Eq 3.2.3's sin θ coefficient over the printed denominator is {EQ323['sin θ'] / EQ32_DEN[0]:.4g}; over "
        f"{A32_COINCIDENCE_DEN} (a digit dropped) it is {coincidence:.4g}, "
        f"{pct(abs(coincidence / tn.A_TORQUE[2, 1] - 1))} "
        "from the printed A32: a coincidence, not a stated hypothesis."
    )


def _tf_flat(a: np.ndarray, b: np.ndarray) -> list[float]:
    num, den = transfer_function(a, b)
    return [*num, *den]


def _elements_tf(num: list[float], den: list[float]) -> tuple[str, ...]:
    n, d = len(num) - 1, len(den) - 1
    return tuple(f"num s^{n - i}" for i in range(n + 1)) + tuple(f"den s^{d - i}" for i in range(d + 1))


def _voltage_explain(m: Model, _: Any) -> str:
    av, bv = m.voltage
    return f"Model: Ā34 = {av[2, 3]:.4g}, Ā44 = {av[3, 3]:.4g}, B̄ = {vec(bv, 5)}."


def _det_leading_digit(value: float, like: float) -> float:
    """``value`` with its leading digit replaced by that of ``like`` (a slip of the first digit)."""
    exp = math.floor(math.log10(abs(value)))
    lead = math.floor(abs(value) / 10**exp)
    new = math.floor(abs(like) / 10 ** math.floor(math.log10(abs(like))))
    return math.copysign(abs(value) + (new - lead) * 10**exp, value)


def _shift_b3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Γ as if B3 also drove the θ row: ZOH with B2 := B3."""
    shifted = b.copy()
    shifted[1, 0] = b[2, 0]
    return discretize_zoh(a, shifted, T)[1]


def _ctrb_d(src: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    return control.ctrb(*src)


PRINTED_DISCRETE = {  # kind → (printed A, B, Γ, eig Φ, symbol)
    "torque": (tn.A_TORQUE, tn.B_TORQUE, tn.GAMMA_TORQUE, tn.EIG_PHI_TORQUE, "Γ"),
    "voltage": (tn.A_VOLTAGE, tn.B_VOLTAGE, tn.GAMMA_VOLTAGE, tn.EIG_PHI_VOLTAGE, "Γ̄"),
}


def _gamma_claim(claim_id: str, kind: str, hypothesis: Hypothesis) -> Claim:
    """Γ (or Γ̄) of eq 3.4.9/3.4.14: the ZOH input matrix of the printed model, with its other sources."""
    a, b, gamma, _, sym = PRINTED_DISCRETE[kind]

    def explain(m: Model, v: Any) -> str:
        b_needed = np.linalg.solve(discretize_zoh(a, np.eye(4), T)[1], gamma)
        other = (
            f"; from the printed torque model {vec(m.discrete('derived voltage')[1])}"
            if kind == "voltage"
            else ""
        )
        return (
            f"Model: {vec(m.discrete(kind)[1])}{other}; the input vector that would give the printed {sym}: "
            f"{vec(b_needed, 3)}."
        )

    return Claim(
        claim_id,
        f"{sym} = ∫₀ᵀe^{{Aη}}dη·B of the printed {kind} model",
        gamma.ravel(),
        lambda m: m.discrete(f"printed {kind}")[1].ravel(),
        Close(rel=0.01, decimals="printed"),
        (hypothesis,),
        explain,
        elements=tuple(f"{sym}{i}" for i in range(1, 5)),
        display=rounded,
    )


def _eig_phi_claim(claim_id: str, kind: str) -> Claim:
    """eig Φ (or Φ̄) of §3.4: e^{λT} for the poles of the printed model; the printed Φ's own eigenvalues in prose."""
    a, _, _, printed, _ = PRINTED_DISCRETE[kind]
    phi = tn.PHI_TORQUE if kind == "torque" else tn.PHI_VOLTAGE
    return Claim(
        claim_id,
        f"eigenvalues e^{{λT}} of the printed {kind} model's poles",
        printed,
        lambda m: match(printed, np.exp(np.linalg.eigvals(a) * T)),
        explain=lambda m, v: f"Eig of the printed matrix: {vec(match(printed, np.linalg.eigvals(phi)))}.",
        display=rounded,
    )


def _from_derived_voltage(
    claim_id: str, quantity: str, printed: Any, fn: Any, elements: tuple[str, ...] = ()
) -> Claim:
    """A voltage-model quantity recomputed from Ā, B̄ derived from the printed A, B; the hypothesis that it was
    computed from the printed Ā (eq 3.3.5) instead; the model's value in the prose."""
    return Claim(
        claim_id,
        f"{quantity}, from Ā, B̄ derived from the printed A, B",
        printed,
        lambda m: fn(*m.printed_voltage),
        hypotheses=(
            Hypothesis(
                "computed from the printed Ā of eq 3.3.5, not from the printed A, B",
                INCONSISTENT,
                value=lambda m: fn(tn.A_VOLTAGE, tn.B_VOLTAGE),
            ),
        ),
        explain=lambda m, v: f"Model: {vec(fn(*m.voltage))}.",
        elements=elements,
        display=rounded,
    )


def _gain_claims(
    section: str,
    spec: str,
    printed: tuple[np.ndarray, np.ndarray],
    recompute: Any,
    tried: tuple[Hypothesis, ...],
    explain: Any = None,
) -> list[Claim]:
    """The CLP position and velocity gains of a section as two claims: each half of one recomputation
    (kp₁, kp₂, kv₁, kv₂), with the same designs tried as hypotheses (each all or nothing)."""
    out = []
    for half, (name, gains) in enumerate((("kp", printed[0]), ("kv", printed[1]))):
        part = slice(2 * half, 2 * half + 2)
        out.append(
            Claim(
                f"{section} {name}",
                f"{name} gains {spec}",
                np.diag(gains),
                lambda m, part=part: recompute(m)[part],
                hypotheses=tuple(
                    Hypothesis(
                        h.statement, h.verdict, value=lambda m, h=h, part=part: h.value(m)[part], whole=True
                    )
                    for h in tried
                ),
                explain=explain or (lambda m, v: ""),
                elements=(f"{name}₁", f"{name}₂"),
                display=rounded,
            )
        )
    return out


def _chapter3() -> list[Claim]:
    derived = Hypothesis(
        "the derived coefficients use the recomputed r*, not the printed one (eq 3.2.4's τ coefficient)",
        MISPRINT,
        test=lambda m: (
            _r_star_used_by_derived(m, m.rolling_radius_m)
            and not _r_star_used_by_derived(m, tn.R_STAR_PRINTED_M)
        ),
    )
    j_used = Hypothesis(
        "the equations use J = 2/5·m·r²: eq 3.2.4's τ coefficient follows from it, not from the tabulated J",
        INCONSISTENT,
        test=lambda m: (
            bool(Close(rel=1e-3)(EQ324["τ"], m.k1_plus_1(m.rolling_radius_m)).passed.all())
            and not Close(rel=1e-3)(
                EQ324["τ"], m.k1_plus_1(m.rolling_radius_m, tn.J_BALL_PRINTED_KGM2)
            ).passed.all()
        ),
    )
    k2_x = Hypothesis(K2_DROPPED, INCONSISTENT, value=lambda m: x_row(*m.linear(x_row_k2=False)))
    slip_carried = Hypothesis(
        f"a ×{SLIP} slip (printed = {SLIP} × recomputed), carried on: the printed TF of eq 3.3.8 follows "
        "from the slipped Ā",
        INCONSISTENT,
        value=lambda m: SLIP * m.printed_voltage[0],
        test=lambda m: bool(
            Close()(
                [*tn.TF_VOLTAGE_NUM, *tn.TF_VOLTAGE_DEN], _tf_flat(tn.A_VOLTAGE, tn.B_VOLTAGE)
            ).passed.all()
        ),
    )
    slip = Hypothesis(f"a ×{SLIP} slip", MISPRINT, value=lambda m: SLIP * m.printed_voltage[0])

    def voltage_zeros(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return match(tn.ZEROS_VOLTAGE, np.roots(transfer_function(a, b)[0]))

    def voltage_poles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return match(tn.POLES_VOLTAGE, np.linalg.eigvals(a))

    gamma_shift = Hypothesis(
        "B3 also drives the θ row: Γ2 = T·B3 + T²/2·B4",
        INCONSISTENT,
        value=lambda m: _shift_b3(tn.A_TORQUE, tn.B_TORQUE),
    )
    gamma_bar_shift = Hypothesis(
        "B̄3 also drives the θ row: Γ̄2 = T·B̄3 + T²/2·B̄4",
        INCONSISTENT,
        value=lambda m: _shift_b3(tn.A_VOLTAGE, tn.B_VOLTAGE),
    )
    from_printed_gamma = Hypothesis(
        "built from the printed Φ, Γ of eq 3.4.8/3.4.9 (Γ itself does not follow from A, B)",
        INCONSISTENT,
        value=lambda m: _ctrb_d((tn.PHI_TORQUE, tn.GAMMA_TORQUE)),
        check=Close(rel=0.01, decimals=4),
    )
    num_p, den_p = tn.TF_TORQUE_NUM, tn.TF_TORQUE_DEN
    return [
        Claim(
            "Table 3.1 r*",
            "rolling radius r* = √(r² − d²/4) (m)",
            tn.R_STAR_PRINTED_M,
            lambda m: m.rolling_radius_m,
            Close(rel=1e-3, decimals="printed"),
            (derived,),
            _explain_r_star,
        ),
        Claim(
            "Table 3.1 J",
            "ball moment of inertia J (kg·m²)",
            tn.J_BALL_PRINTED_KGM2,
            lambda m: m.ball_inertia_kgm2,
            hypotheses=(j_used,),
            explain=_explain_j,
        ),
        Claim(
            "eq 3.2.3 coefficients",
            "ẍ numerator coefficients " + ", ".join(EQ323),
            list(EQ323.values()),
            lambda m: list(m.numerators()[0].values()),
            hypotheses=(
                Hypothesis(
                    K2_DROPPED, INCONSISTENT, value=lambda m: list(m.numerators(x_row_k2=False)[0].values())
                ),
            ),
            explain=_explain_eq323,
            elements=tuple(EQ323),
        ),
        Claim(
            "eq 3.2.4 coefficients",
            "θ̈ numerator coefficients " + ", ".join(EQ324),
            list(EQ324.values()),
            lambda m: [m.numerators()[1][k] for k in EQ324],
            elements=tuple(EQ324),
            explain=lambda m, v: (
                f"The x θ̇² coefficient (k1+1)·m·(h*+r*) − k1·m·h* = {v[-1]:.4g} reads 3.1.27's term as x·θ̇²."
            ),
        ),
        Claim(
            "eq 3.2.3/3.2.4 denominator",
            "denominator: constant and x² coefficient",
            list(EQ32_DEN),
            lambda m: list(m.numerators()[2]),
            elements=("constant", "x²"),
        ),
        Claim(
            "eq 3.2.8 A θ̈ row",
            "A41, A42 and B4 (eq 3.2.9)",
            theta_row(tn.A_TORQUE, tn.B_TORQUE),
            lambda m: theta_row(*m.torque),
            elements=("A41", "A42", "B4"),
        ),
        Claim(
            "eq 3.2.8 A ẍ row",
            "A31, A32 and B3 (eq 3.2.9)",
            x_row(tn.A_TORQUE, tn.B_TORQUE),
            lambda m: x_row(*m.torque),
            hypotheses=(k2_x,),
            explain=_explain_x_row,
            elements=("A31", "A32", "B3"),
        ),
        Claim(
            "eq 3.2.8 A",
            "state matrix A (torque input)",
            tn.A_TORQUE,
            lambda m: m.torque[0],
            hypotheses=(Hypothesis(K2_DROPPED, INCONSISTENT, value=lambda m: m.linear(x_row_k2=False)[0]),),
            display=rounded,
        ),
        Claim(
            "eq 3.2.9 B",
            "input matrix B (torque input)",
            tn.B_TORQUE.ravel(),
            lambda m: m.torque[1].ravel(),
            elements=("B1", "B2", "B3", "B4"),
            hypotheses=(
                Hypothesis(K2_DROPPED, INCONSISTENT, value=lambda m: m.linear(x_row_k2=False)[1].ravel()),
            ),
            display=rounded,
        ),
        Claim(
            "eq 3.2.11 TF",
            "Y(s)/τ(s) numerator and denominator, from the printed A, B",
            [*num_p, *den_p],
            lambda m: _tf_flat(tn.A_TORQUE, tn.B_TORQUE),
            elements=_elements_tf(num_p, den_p),
            explain=lambda m, v: f"From the model: {vec(_tf_flat(*m.torque))}.",
            display=rounded,
        ),
        Claim(
            "§3.2 poles",
            "open-loop poles (torque input), eig of the printed A",
            tn.POLES_TORQUE,
            lambda m: match(tn.POLES_TORQUE, np.linalg.eigvals(tn.A_TORQUE)),
            explain=lambda m, v: (
                f"The model's: {vec(match(tn.POLES_TORQUE, np.linalg.eigvals(m.torque[0])))}."
            ),
            display=rounded,
        ),
        Claim(
            "§3.2 zeros",
            "open-loop zeros (torque input), from the printed A, B",
            tn.ZEROS_TORQUE,
            lambda m: match(tn.ZEROS_TORQUE, np.roots(transfer_function(tn.A_TORQUE, tn.B_TORQUE)[0])),
            explain=lambda m, v: (
                f"The model's: {vec(np.roots(transfer_function(*m.torque)[0]))} (they move with B3)."
            ),
            display=rounded,
        ),
        Claim(
            "eq 3.3.2",
            "τ = k·(V − k_b·θ̇): k = N·K_t/R, k_b = N·K_b",
            [tn.MOTOR_TORQUE_PER_VOLT, tn.MOTOR_BACKEMF_AT_BEAM],
            lambda m: list(m.motor_constants),
            elements=("k", "k_b"),
        ),
        Claim(
            "eq 3.3.5 Ā",
            "state matrix Ā = A − k·k_b·B·e₄ᵀ from the printed A, B",
            tn.A_VOLTAGE,
            lambda m: m.printed_voltage[0],
            Close(rel=0.01, decimals="printed"),
            (slip_carried, slip),
            _voltage_explain,
            display=rounded,
        ),
        Claim(
            "eq 3.3.6 B̄",
            "input matrix B̄ = k·B from the printed B",
            tn.B_VOLTAGE.ravel(),
            lambda m: m.printed_voltage[1].ravel(),
            explain=_voltage_explain,
            display=rounded,
        ),
        _from_derived_voltage(
            "eq 3.3.8 TF",
            "Y(s)/V(s) coefficients",
            [*tn.TF_VOLTAGE_NUM, *tn.TF_VOLTAGE_DEN],
            _tf_flat,
            _elements_tf(tn.TF_VOLTAGE_NUM, tn.TF_VOLTAGE_DEN),
        ),
        _from_derived_voltage(
            "§3.3 poles", "open-loop poles (the conjugate pair implied)", tn.POLES_VOLTAGE, voltage_poles
        ),
        _from_derived_voltage(
            "§3.3 zeros",
            "open-loop zeros (a feedback through B cannot move zeros: the torque zeros "
            + "; ".join(f"{z:.5g}" for z in np.roots(transfer_function(tn.A_TORQUE, tn.B_TORQUE)[0]).real)
            + ")",
            tn.ZEROS_VOLTAGE,
            voltage_zeros,
        ),
        Claim(
            "eq 3.4.8 Φ",
            f"Φ = e^{{AT}} of the printed A, T = {T * 1e3:g} ms",
            tn.PHI_TORQUE,
            lambda m: m.discrete("printed torque")[0],
            Close(rel=0.01, decimals=4),
            explain=lambda m, v: f"Model Φ[3,1], Φ[3,2] = {vec(m.discrete('torque')[0][2, :2])}.",
            display=rounded,
        ),
        _gamma_claim("eq 3.4.9 Γ", "torque", gamma_shift),
        _eig_phi_claim("§3.4 eig Φ", "torque"),
        Claim(
            "eq 3.4.13 Φ̄",
            "Φ̄ = e^{ĀT} of the printed Ā",
            tn.PHI_VOLTAGE,
            lambda m: m.discrete("printed voltage")[0],
            Close(rel=0.01, decimals=3),
            (
                Hypothesis(
                    "the entry is copied from the torque Φ of eq 3.4.8",
                    MISPRINT,
                    value=lambda m: tn.PHI_TORQUE,
                ),
            ),
            lambda m, v: (
                f"With Ā from the printed A, B: Φ̄[3,4] = {m.discrete('derived voltage')[0][2, 3]:.3g}; "
                f"model Φ̄[3,4], Φ̄[4,4] = {vec(m.discrete('voltage')[0][2:, 3])}."
            ),
            display=rounded,
        ),
        _gamma_claim("eq 3.4.14 Γ̄", "voltage", gamma_bar_shift),
        _eig_phi_claim("§3.4 eig Φ̄", "voltage"),
        Claim(
            "§3.5 Q_C",
            "controllability matrix [B AB A²B A³B] of the printed A, B",
            tn.QC_TORQUE,
            lambda m: control.ctrb(tn.A_TORQUE, tn.B_TORQUE),
            display=rounded,
        ),
        Claim(
            "§3.5 det Q_C",
            "det Q_C of the printed A, B",
            tn.DET_QC_TORQUE,
            lambda m: float(np.linalg.det(control.ctrb(tn.A_TORQUE, tn.B_TORQUE))),
            hypotheses=(
                Hypothesis(
                    "the leading digit slipped; the digits after it agree",
                    MISPRINT,
                    value=lambda m: _det_leading_digit(
                        float(np.linalg.det(control.ctrb(tn.A_TORQUE, tn.B_TORQUE))), tn.DET_QC_TORQUE
                    ),
                    check=Close(rel=1e-4),
                ),
            ),
            explain=lambda m, v: (
                f"Model: {float(np.linalg.det(control.ctrb(*m.torque))):.4e}; non-zero either way."
            ),
        ),
        Claim(
            "§3.5 Q_D",
            "controllability matrix [Γ ΦΓ Φ²Γ Φ³Γ] of the ZOH of the printed A, B",
            tn.QD_TORQUE,
            lambda m: _ctrb_d(m.discrete("printed torque")),
            Close(rel=0.01, decimals=4),
            (from_printed_gamma,),
            lambda m, v: f"Model: {vec(_ctrb_d(m.discrete('torque')), 3)}.",
            display=rounded,
        ),
        Claim(
            "§3.5 det Q_D",
            "det Q_D of the ZOH of the printed A, B",
            tn.DET_QD_TORQUE,
            lambda m: float(np.linalg.det(_ctrb_d(m.discrete("printed torque")))),
            hypotheses=(
                Hypothesis(
                    from_printed_gamma.statement,
                    INCONSISTENT,
                    value=lambda m: float(np.linalg.det(_ctrb_d((tn.PHI_TORQUE, tn.GAMMA_TORQUE)))),
                ),
            ),
            explain=lambda m, v: (
                f"Model: {float(np.linalg.det(_ctrb_d(m.discrete('torque')))):.4e}; non-zero in every case."
            ),
        ),
        Claim(
            "§3.5 W_C",
            "observability matrix [C; CA; CA²; CA³] of the printed A (y = x)",
            tn.WC_TORQUE,
            lambda m: control.obsv(tn.A_TORQUE, C_OUT),
        ),
        Claim(
            "§3.5 W_D",
            "observability matrix [H; HΦ; HΦ²; HΦ³] of the printed Φ",
            tn.WD_TORQUE,
            lambda m: control.obsv(tn.PHI_TORQUE, C_OUT),
            Close(rel=0.01, decimals="printed"),
            display=rounded,
        ),
    ]


# --- chapter 4 ---------------------------------------------------------------------------------------------
def _sf_spec_poles() -> list[complex]:
    c1, c0 = SF_SPEC["c1"], SF_SPEC["c0"]
    pair = np.roots([1.0, c1, c0])
    return [*sorted(pair, key=lambda z: -z.imag), complex(SF_SPEC["far"]), complex(SF_SPEC["far"])]


def _beta_lin() -> np.ndarray:
    return np.array([[tn.CLP_BETA[1], tn.CLP_BETA[0], 0.0, 0.0]])


def _alpha0() -> np.ndarray:
    return np.array([tn.CLP_ALPHA_XDD, tn.CLP_ALPHA_THDD])


def _clp_cont_gains(a: np.ndarray, b: np.ndarray, alpha: np.ndarray | None = None) -> list[float]:
    kp, kv = clp_gains(a, b, _alpha0() if alpha is None else alpha, _beta_lin(), CLP_SPEC_POLES)
    return [*np.diag(kp), *np.diag(kv)]


def _clp_cont_loop(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    k_eff = clp_effective_gain(_alpha0(), tn.CLP_CONT_KP, tn.CLP_CONT_KV)
    return sorted_eig(a + b @ (_beta_lin() - k_eff))


def _sliding_motion(s: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The three non-zero eigenvalues of (I − B(SB)⁻¹S)A: the motion on the surface s = 0."""
    ev = np.linalg.eigvals((np.eye(4) - b @ np.linalg.solve(s @ b, s)) @ a)
    return np.array(sorted(np.delete(ev, np.argmin(np.abs(ev))), key=lambda z: z.real))


def _smc_blocks(d: dict[str, Any]) -> list[float]:
    return [*d["a11"].ravel(), *d["a12"].ravel(), *d["a21"].ravel(), float(d["a22"][0, 0]), d["b2"]]


SMC_BLOCK_NAMES = (
    tuple(f"A11[{i},{j}]" for i in (1, 2, 3) for j in (1, 2, 3))
    + tuple(f"A12[{i}]" for i in (1, 2, 3))
    + tuple(f"A21[{j}]" for j in (1, 2, 3))
    + ("A22", "B2")
)


def _keq(s: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.solve(s @ b, s @ a).ravel()


def _stable_eigs(recomputed: dict[str, list[complex]]) -> bool:
    return all(max(np.real(v)) < 0 for v in recomputed.values())


def _chapter4() -> list[Claim]:
    k_printed_poles = lambda m: state_feedback_gain(tn.A_VOLTAGE, tn.B_VOLTAGE, tn.SF_CONT_POLES).ravel()  # noqa: E731
    clp_tried = (
        Hypothesis(
            "placed on the model instead of the printed A, B",
            INCONSISTENT,
            value=lambda m: _clp_cont_gains(*m.torque),
            whole=True,
        ),
        Hypothesis(
            "placed with appendix A's α₁",
            INCONSISTENT,
            value=lambda m: _clp_cont_gains(
                tn.A_TORQUE, tn.B_TORQUE, np.array([APPX_CLP_ALPHA[0], tn.CLP_ALPHA_THDD])
            ),
            whole=True,
        ),
        Hypothesis(
            "two independent loops s² + kv·s + kp at the spec's poles",
            INCONSISTENT,
            value=lambda m: [CLP_SPEC_POLES[0] ** 2] * 2 + [-2 * CLP_SPEC_POLES[0]] * 2,
            whole=True,
        ),
    )

    def explain_clp_gains(m: Model, v: list[float]) -> str:
        kp, kv = np.diag(tn.CLP_CONT_KP), np.diag(tn.CLP_CONT_KV)
        return (
            f"The printed gains as two loops s² + kv·s + kp: roots {vec(np.roots([1, kv[0], kp[0]]), 3)} and "
            f"{vec(np.roots([1, kv[1], kp[1]]), 3)}; linearized on the printed A, B the loop's poles are "
            f"{vec(_clp_cont_loop(tn.A_TORQUE, tn.B_TORQUE), 3)}."
        )

    def explain_k(m: Model, v: np.ndarray) -> str:
        k_exact = state_feedback_gain(tn.A_VOLTAGE, tn.B_VOLTAGE, _sf_spec_poles()).ravel()
        k_derived = state_feedback_gain(*m.printed_voltage, tn.SF_CONT_POLES).ravel()
        k_model = state_feedback_gain(*m.voltage, _sf_spec_poles()).ravel()
        return (
            f"With the unrounded spec poles: {vec(k_exact)}; with Ā from the printed A, B: {vec(k_derived)}; "
            f"on the model: {vec(k_model)} ({pct(float(np.max(np.abs(k_model / tn.SF_CONT_K.ravel() - 1))))} off)."
        )

    def sf_loops(m: Model) -> dict[str, list[complex]]:
        return {
            "printed Ā, B̄": list(sorted_eig(tn.A_VOLTAGE - tn.B_VOLTAGE @ tn.SF_CONT_K)),
            "model": list(sorted_eig(m.voltage[0] - m.voltage[1] @ tn.SF_CONT_K)),
        }

    def explain_sf_loop(m: Model, v: dict[str, list[complex]]) -> str:
        dom = v["model"][0]
        return (
            f"On the model the dominant pair has ζ = {-dom.real / abs(dom):.3g}, σ = {-dom.real:.3g} 1/s "
            f"(4/σ = {4 / -dom.real:.3g} s). " + "; ".join(f"{k}: {vec(e, 3)}" for k, e in v.items()) + "."
        )

    def alpha(m: Model) -> list[float]:
        q = m.coefficients.parts(m.params)
        return [q["k1"] * q["m"] * q["hs"], q["jeff"], q["m"]]

    def beta(m: Model) -> list[float]:
        p, q = m.params, m.coefficients.parts(m.params)
        return [-p.beam.mass_kg * q["g"] * p.beam.cog_height_m, q["m"] * q["g"], 2 * q["m"], -q["m"] * q["c"]]

    def smc_blocks_torque(m: Model) -> list[float]:
        return _smc_blocks(regular_form(tn.A_TORQUE, tn.B_TORQUE))

    printed_blocks = [*SMC_A11.ravel(), *SMC_A12.ravel(), *SMC_A21.ravel(), float(SMC_A22[0, 0]), SMC_B2]
    return [
        Claim(
            "§4.2 char poly",
            "desired characteristic polynomial (s² + c1·s + c0)(s − p)²",
            tn.SF_CONT_CHAR_POLY,
            lambda m: np.real(np.poly(_sf_spec_poles())),
        ),
        Claim(
            "§4.2 poles",
            "dominant poles of s² + c1·s + c0 and the far pair",
            tn.SF_CONT_POLES,
            lambda m: _sf_spec_poles(),
            display=rounded,
        ),
        Claim(
            "§4.2 t_s, ζ",
            "settling time 4/(ζω_n) and damping of s² + c1·s + c0",
            SF_TS_ZETA,
            lambda m: [4 / (SF_SPEC["c1"] / 2), SF_SPEC["c1"] / (2 * math.sqrt(SF_SPEC["c0"]))],
            elements=("t_s", "ζ"),
            confirmed=HOLDS,
        ),
        Claim(
            "§4.2 K",
            "state-feedback gain (voltage input) by Ackermann on the printed Ā, B̄",
            tn.SF_CONT_K.ravel(),
            k_printed_poles,
            explain=explain_k,
            display=rounded,
        ),
        Claim(
            "§4.2 closed-loop poles",
            "eig(Ā − B̄K) with the printed K",
            tn.SF_CONT_POLES,
            sf_loops,
            Predicate("stable on the printed Ā, B̄ and on the model", lambda p, v: _stable_eigs(v)),
            explain=explain_sf_loop,
            confirmed=HOLDS,
            display=lambda v: {k: rounded(e, 4) for k, e in v.items()},
        ),
        Claim(
            "§4.3 α",
            "α: k1·m·h*, J_BP − k2·m·h*, and m (the x² coefficient)",
            [tn.CLP_ALPHA_XDD, tn.CLP_ALPHA_THDD, tn.CLP_ALPHA_THDD_X2],
            alpha,
            Close(rel=0.01, decimals="printed"),
            elements=("α₁", "α₂", "α₂ x²"),
            display=rounded,
        ),
        Claim(
            "§4.3 β",
            "β coefficients of sin θ, x cos θ, x ẋ θ̇, x θ̇²",
            list(tn.CLP_BETA),
            beta,
            elements=("sin θ", "x cos θ", "x ẋ θ̇", "x θ̇²"),
            display=rounded,
        ),
        *_gain_claims(
            "§4.3",
            "for four poles at the spec (ζ = 1, ω_n = 2) on the printed A, B",
            (tn.CLP_CONT_KP, tn.CLP_CONT_KV),
            lambda m: _clp_cont_gains(tn.A_TORQUE, tn.B_TORQUE),
            clp_tried,
            explain_clp_gains,
        ),
        Claim(
            "§4.3 closed-loop poles",
            "linearized closed loop of the printed kp, kv on the printed A, B",
            CLP_SPEC_POLES,
            lambda m: match(CLP_SPEC_POLES, _clp_cont_loop(tn.A_TORQUE, tn.B_TORQUE)),
            explain=lambda m, v: (
                f"On the model: {vec(_clp_cont_loop(*m.torque), 3)}; slowest time constant "
                f"{1 / min(abs(np.real(v))):.3g} s."
            ),
            otherwise=FAILS,
            display=rounded,
        ),
        Claim(
            "§4.4 T_r",
            "regular-form transformation (QR of B): orthogonal",
            tn.SMC_TR,
            lambda m: float(np.max(np.abs(tn.SMC_TR @ tn.SMC_TR.T - np.eye(4)))),
            Predicate("the printed T_r is orthogonal to the printed digits", lambda p, v: v < 1e-3),
            explain=lambda m, v: (
                f"max |T_r·T_rᵀ − I| = {v:.3g}; QR of the printed B̄ gives "
                f"{vec(regular_form(tn.A_VOLTAGE, tn.B_VOLTAGE)['tr'], 3)}."
            ),
            otherwise=INCONSISTENT,
        ),
        Claim(
            "§4.4 A11 A12 A21 A22 B2",
            "regular-form blocks of eq 3.2.8/3.2.9 (as the text says)",
            printed_blocks,
            smc_blocks_torque,
            Close(rel=0.01, decimals="printed"),
            (
                Hypothesis(
                    "taken from the voltage model Ā, B̄ of eq 3.3.5/3.3.6 instead",
                    INCONSISTENT,
                    value=lambda m: _smc_blocks(regular_form(tn.A_VOLTAGE, tn.B_VOLTAGE)),
                ),
            ),
            elements=SMC_BLOCK_NAMES,
            display=rounded,
        ),
        Claim(
            "§4.4 M",
            "M with eig(A11 − A12·M) at the sliding poles, on the printed Ā, B̄",
            tn.SMC_M.ravel(),
            lambda m: regular_form(tn.A_VOLTAGE, tn.B_VOLTAGE)["m"].ravel(),
            hypotheses=(
                Hypothesis(
                    "placed on the printed A11, A12 (which are not the system's blocks)",
                    INCONSISTENT,
                    value=lambda m: state_feedback_gain(SMC_A11, SMC_A12, list(tn.SMC_SLIDING_POLES)).ravel(),
                ),
            ),
            explain=lambda m, v: f"Model: {vec(regular_form(*m.voltage)['m'])}.",
            display=rounded,
        ),
        Claim(
            "§4.4 S̄",
            "sliding motion of the printed S̄ on the printed Ā, B̄",
            tn.SMC_SLIDING_POLES,
            lambda m: _sliding_motion(tn.SMC_S, tn.A_VOLTAGE, tn.B_VOLTAGE),
            Close(rel=0.05),
            explain=lambda m, v: (
                f"[M 1]·T_r with the printed M, T_r = {vec(np.hstack([tn.SMC_M, np.ones((1, 1))]) @ tn.SMC_TR, 4)}; "
                "the design on the printed Ā, B̄ gives S̄ = "
                f"{vec(regular_form(tn.A_VOLTAGE, tn.B_VOLTAGE)['s'])}; sliding "
                f"motion of the printed S̄ on the model: {vec(_sliding_motion(tn.SMC_S, *m.voltage), 3)}."
            ),
            otherwise=FAILS,
            display=rounded,
        ),
        Claim(
            "§4.4 K_eq",
            "K_eq = (S̄B̄)⁻¹S̄Ā with the printed S̄ on the printed Ā, B̄",
            tn.SMC_KEQ.ravel(),
            lambda m: _keq(tn.SMC_S, tn.A_VOLTAGE, tn.B_VOLTAGE),
            hypotheses=(
                Hypothesis(
                    f"the sign is flipped (printed = −recomputed within {SIGN_TOLERANCE:.0%})",
                    INCONSISTENT,
                    value=lambda m: -_keq(tn.SMC_S, tn.A_VOLTAGE, tn.B_VOLTAGE),
                    check=Close(rel=SIGN_TOLERANCE),
                ),
            ),
            explain=lambda m, v: (
                "eig(Ā − B̄K_eq) with the printed K_eq: "
                f"{vec(sorted_eig(tn.A_VOLTAGE - tn.B_VOLTAGE @ tn.SMC_KEQ), 3)}; "
                f"model: {vec(sorted_eig(m.voltage[0] - m.voltage[1] @ tn.SMC_KEQ), 3)}."
            ),
            display=rounded,
        ),
    ]


# --- chapter 5 and appendix A -----------------------------------------------------------------------------
def _sf_obs_rows(o: Any) -> list[list[float]]:
    return [
        [o.f[i, 0], o.f[i, 1], o.ga[i, 0], o.ga[i, 1], o.h[i, 0], o.gain[i, 0], o.gain[i, 1]]
        for i in range(2)
    ]


def _clp_obs_rows(o: Any) -> list[list[float]]:
    return [
        [o.h[i, 0], o.ga[i, 0], o.ga[i, 1], o.f[i, 0], o.f[i, 1], o.gain[i, 0], o.gain[i, 1]]
        for i in range(2)
    ]


SF_OBS_NAMES = tuple(
    f"{row} {c}" for row in ("x̂3", "x̂4") for c in ("F1", "F2", "Ga1", "Ga2", "H", "G1", "G2")
)
CLP_OBS_NAMES = tuple(
    f"{row} {c}" for row in ("x̂3", "x̂4") for c in ("H", "Ga1", "Ga2", "F1", "F2", "G1", "G2")
)


def _sf_disc_gain(src: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    return state_feedback_gain(src[0], src[1], tn.SF_DISC_POLES).ravel()


def _clp_disc_gains(src: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    ph, ga = src
    z = [math.exp(CLP_SPEC_POLES[0] * T)] * 4
    k = np.real(control.acker(ph + ga @ _beta_lin(), ga, z)).ravel()
    a1, a2 = _alpha0()
    return np.array([k[0] / a1, k[1] / a2, k[2] / a1, k[3] / a2])


def _clp_disc_loop(src: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    k_eff = clp_effective_gain(_alpha0(), tn.CLP_DISC_KP, tn.CLP_DISC_KV)
    return sorted_eig(src[0] + src[1] @ (_beta_lin() - k_eff))


def _chapter5() -> list[Claim]:
    def sf_k(m: Model) -> np.ndarray:
        return _sf_disc_gain(m.voltage_sources["model"])

    k_tried = tuple(
        Hypothesis(
            f"placed on the {name}",
            INCONSISTENT,
            value=lambda m, name=name: _sf_disc_gain(m.voltage_sources[name]),
            whole=True,
        )
        for name in ("printed Φ̄, Γ̄", "ZOH of printed Ā, B̄", "ZOH of Ā, B̄ from printed A, B")
    )
    clp_tried = tuple(
        Hypothesis(
            f"placed on the {name}",
            INCONSISTENT,
            value=lambda m, name=name: _clp_disc_gains(m.torque_sources[name]),
            whole=True,
        )
        for name in ("printed Φ, Γ", "model")
    )

    def obs_poles_sf(gain: np.ndarray) -> Any:
        return lambda m: match(tn.SF_OBS_POLES_Z, m.observer(m.voltage_sources["model"], gain).error_poles())

    def explain_sf_g(m: Model, v: np.ndarray) -> str:
        return (
            "; ".join(
                f"{k}: printed G {vec(m.observer(src, tn.SF_OBS_G).error_poles(), 3)}, appendix G "
                f"{vec(m.observer(src, APPX_SF_G).error_poles(), 3)}"
                for k, src in m.voltage_sources.items()
            )
            + "."
        )

    s_obs = np.array(tn.SF_OBS_POLES_S)
    zc = math.exp(CLP_SPEC_POLES[0] * T)
    return [
        Claim(
            "§5.2.1 poles",
            "discrete poles z = e^{sT} of §4.2's poles",
            tn.SF_DISC_POLES,
            lambda m: match(tn.SF_DISC_POLES, np.exp(np.array(_sf_spec_poles()) * T)),
            display=rounded,
        ),
        Claim(
            "§5.2.1 K",
            "discrete state-feedback gain (voltage) by Ackermann, on the model",
            tn.SF_DISC_K.ravel(),
            sf_k,
            hypotheses=k_tried,
            explain=lambda m, v: (
                "; ".join(f"{h.statement}: {vec(h.value(m))}" for h in k_tried if h.value) + "."
            ),
            display=rounded,
        ),
        Claim(
            "§5.2.1 observer poles",
            "observer poles z = e^{sT} of the printed s",
            tn.SF_OBS_POLES_Z,
            lambda m: np.exp(s_obs * T),
            hypotheses=(
                Hypothesis(
                    f"the imaginary part of s lost its leading digit (the z are for {DROPPED_DIGIT} more rad/s)",
                    MISPRINT,
                    value=lambda m: np.exp((s_obs + np.sign(s_obs.imag) * DROPPED_DIGIT * 1j) * T),
                ),
            ),
            explain=lambda m, v: (
                f"ln z / T of the printed z: {vec(np.log(np.array(tn.SF_OBS_POLES_Z)) / T)}."
            ),
            display=rounded,
        ),
        Claim(
            "§5.2.1 G",
            f"observer error poles eig(Φ̄bb − GΦ̄ab) of the printed G = {tn.SF_OBS_G.tolist()}, model Φ̄",
            tn.SF_OBS_POLES_Z,
            obs_poles_sf(tn.SF_OBS_G),
            hypotheses=(
                Hypothesis(
                    f"a sign slip: G = {APPX_SF_G.tolist()}, as appendix A codes",
                    MISPRINT,
                    value=obs_poles_sf(APPX_SF_G),
                ),
            ),
            explain=explain_sf_g,
            display=rounded,
        ),
        Claim(
            "§5.2.2 poles",
            "discrete poles e^{sT} for ζ = 1, ω_n = 2",
            tn.CLP_DISC_POLES,
            lambda m: [zc, zc],
        ),
        *_gain_claims(
            "§5.2.2",
            "for four discrete poles at the spec on the ZOH of the printed A, B",
            (tn.CLP_DISC_KP, tn.CLP_DISC_KV),
            lambda m: _clp_disc_gains(m.torque_sources["ZOH of printed A, B"]),
            clp_tried,
        ),
        Claim(
            "§5.2.2 closed-loop poles",
            "eig(Φ + Γ(β_lin − K_eff)) with the printed kp, kv, model Φ, Γ",
            [zc] * 4,
            lambda m: match([zc] * 4, _clp_disc_loop(m.torque_sources["model"])),
            explain=lambda m, v: (
                "; ".join(
                    f"{k}: max |z| {np.max(np.abs(_clp_disc_loop(s))):.4f}"
                    for k, s in m.torque_sources.items()
                )
                + f"; the model's slowest time constant {-T / math.log(np.max(np.abs(v))):.3g} s."
            ),
            otherwise=FAILS,
            display=rounded,
        ),
        Claim(
            "§5.2.2 observer poles",
            "s = ln z / T of the observer poles z",
            tn.CLP_OBS_POLES_S,
            lambda m: np.log(np.array(tn.CLP_OBS_POLES_Z)) / T,
        ),
        Claim(
            "§5.2.2 G",
            "observer error poles of the printed G on the model's Φ",
            tn.CLP_OBS_POLES_Z,
            lambda m: match(
                tn.CLP_OBS_POLES_Z, m.observer(m.torque_sources["model"], tn.CLP_OBS_G).error_poles()
            ),
            Close(rel=0.03),
            confirmed=HOLDS,
            explain=lambda m, v: (
                "; ".join(
                    f"{k}: {vec(m.observer(s, tn.CLP_OBS_G).error_poles())}"
                    for k, s in m.torque_sources.items()
                )
                + "."
            ),
            display=rounded,
        ),
    ]


def _appendix() -> list[Claim]:
    m2_from_alpha = APPX_CLP_ALPHA[1]

    def appx_beta(m: Model) -> list[float]:
        q = m.coefficients.parts(m.params)
        return [q["m"] * q["g"], 2 * q["m"], -q["m"] * q["c"]]

    def light_ball_beta(m: Model) -> list[float]:
        g_ = m.params.physics.gravity_m_s2
        c = m.params.track.contact_height_m + tn.R_STAR_PRINTED_M
        return [m2_from_alpha * g_, 2 * m2_from_alpha, -m2_from_alpha * c]

    def chapter_alpha(m: Model) -> list[float]:
        q = m.coefficients.parts(m.params)
        return [q["k1"] * q["m"] * q["hs"], q["m"]]

    def beta_mass(m: Model) -> float:
        return APPX_CLP_BETA[0] / m.params.physics.gravity_m_s2

    def light_ball_alpha(m: Model) -> list[float]:
        q = m.coefficients.parts(m.params)
        return [q["k1"] * beta_mass(m) * q["hs"], beta_mass(m)]

    def clp_obs(m: Model) -> list[list[float]]:
        return _clp_obs_rows(m.observer(m.torque_sources["ZOH of printed A, B"], APPX_CLP_G))

    def clp_obs_as_designed(m: Model) -> list[list[float]]:
        rows = np.array(clp_obs(m))
        rows[:, 3:5] = abs(tn.CLP_OBS_POLES_Z[0]) * np.eye(2)
        return rows.tolist()

    def appx_clp_loop(m: Model) -> np.ndarray:
        k_a = clp_effective_gain(
            np.array([APPX_CLP_ALPHA[0], tn.CLP_ALPHA_THDD]),
            np.diag(APPX_CLP_GAINS[0]),
            np.diag(APPX_CLP_GAINS[1]),
        )
        bl = np.array([[APPX_CLP_BETA[0], tn.CLP_BETA[0], 0.0, 0.0]])
        ph, ga = m.torque_sources["model"]
        return sorted_eig(ph + ga @ (bl - k_a))

    return [
        Claim(
            "appendix A SF observer",
            "x̂3, x̂4 coefficients with the coded G, on the model's Φ̄, Γ̄",
            APPX_SF_OBS,
            lambda m: _sf_obs_rows(m.observer(m.voltage_sources["model"], APPX_SF_G)),
            Close(rel=0.02),
            explain=lambda m, v: (
                "; ".join(
                    f"{k}: F2 of x̂3 = {_sf_obs_rows(m.observer(s, APPX_SF_G))[0][1]:.4f}"
                    for k, s in m.voltage_sources.items()
                )
                + f" (printed {APPX_SF_OBS[0][1]})."
            ),
            elements=SF_OBS_NAMES,
            display=lambda v: rounded(v, 4),
        ),
        Claim(
            "appendix A SF K",
            "u_temp gains vs §5.2.1's K",
            tn.SF_DISC_K.ravel(),
            lambda m: APPX_SF_K.ravel(),
            Close(rel=0.01, decimals="printed"),
            otherwise=INCONSISTENT,
        ),
        Claim(
            "appendix A CLP observer",
            "x̂3, x̂4 coefficients with the coded G, on the ZOH of the printed A, B",
            APPX_CLP_OBS,
            clp_obs,
            hypotheses=(
                Hypothesis(
                    "F written as the requested error-pole matrix z·I, not Φbb − GΦab",
                    INCONSISTENT,
                    value=clp_obs_as_designed,
                ),
                Hypothesis(
                    "built on the printed Φ, Γ of eq 3.4.8/3.4.9",
                    INCONSISTENT,
                    value=lambda m: _clp_obs_rows(m.observer(m.torque_sources["printed Φ, Γ"], APPX_CLP_G)),
                ),
            ),
            elements=CLP_OBS_NAMES,
            display=lambda v: rounded(v, 4),
        ),
        Claim(
            "appendix A β",
            "β coefficients x cos θ, x ẋ θ̇, x θ̇² as coded, vs the model's",
            APPX_CLP_BETA,
            appx_beta,
            hypotheses=(
                Hypothesis(
                    "a ball of the mass in α₂'s coded x² coefficient and the printed r* of Table 3.1",
                    INCONSISTENT,
                    value=light_ball_beta,
                ),
            ),
            explain=lambda m, v: (
                f"That mass is {m2_from_alpha * 1e3:.4g} g (Table 3.1: {m.params.ball.mass_kg * 1e3:.4g} g); "
                f"with it: {vec(light_ball_beta(m))}."
            ),
            elements=("x cos θ", "x ẋ θ̇", "x θ̇²"),
            display=rounded,
        ),
        Claim(
            "appendix A α",
            "α₁ and α₂'s x² coefficient as coded, vs the model's",
            APPX_CLP_ALPHA,
            chapter_alpha,
            hypotheses=(
                Hypothesis(
                    "a ball of the mass in β's coded m·g",
                    INCONSISTENT,
                    value=light_ball_alpha,
                    check=Close(rel=1e-3, decimals="printed"),
                ),
                Hypothesis(
                    "α₁ is ten times k1·m·h* with that mass (a slip of the decimal point)",
                    MISPRINT,
                    value=lambda m: [10 * v for v in light_ball_alpha(m)],
                    check=Close(rel=1e-3, decimals="printed"),
                ),
            ),
            explain=lambda m, v: f"With that mass: {vec(light_ball_alpha(m))}.",
            elements=("α₁", "α₂ x²"),
            display=rounded,
        ),
        Claim(
            "appendix A kp kv",
            "CLP gains as coded vs §5.2.2's",
            [np.diag(tn.CLP_DISC_KP).tolist(), np.diag(tn.CLP_DISC_KV).tolist()],
            lambda m: APPX_CLP_GAINS,
            explain=lambda m, v: (
                f"The coded gains' linearized loop on the model's Φ, Γ: {vec(appx_clp_loop(m), 4)} "
                f"(max |z| {np.max(np.abs(appx_clp_loop(m))):.4f})."
            ),
            elements=("kp₁", "kp₂", "kv₁", "kv₂"),
            otherwise=INCONSISTENT,
        ),
    ]


CLAIMS: tuple[Claim, ...] = (*_chapter3(), *_chapter4(), *_chapter5(), *_appendix())
