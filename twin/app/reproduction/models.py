"""What the thesis's numbers are recomputed from: the project's models, as functions of ``Parameters``.

``Model(params)`` holds, computed once, the reference model's linearizations (the thesis's own equations
3.1.26/3.1.27 with r* and J from the parameters, no motor inertia: ``ReferenceModel(motor_inertia=False)``),
the thesis's linear model with every ingredient a knob (``ThesisCoefficients``, for hypotheses), and the
matrices derived from the thesis's printed intermediate results (e.g. Ā from the printed A, B), so that a
claim can ask both "does the step follow?" and "does the number follow from the rig?". Change the parameters
(e.g. ``track.contact_spacing_m`` so that r* is the printed 4.264 mm) and every model-derived value follows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import control
import numpy as np

from controllers import thesis_numbers as tn
from controllers.design import ReducedObserver, state_feedback_gain
from twin.parameters import Parameters
from twin.reference import ReferenceModel, discretize_zoh

__all__ = ["C_OUT", "Model", "ThesisCoefficients", "match", "rounded", "sorted_eig", "transfer_function"]

T = tn.PERIOD_S
C_OUT = np.array([[1.0, 0.0, 0.0, 0.0]])
Matrices = tuple[np.ndarray, np.ndarray]


def rounded(x: Any, nd: int = 6) -> Any:
    """Round for display (checks use unrounded values)."""
    a = np.asarray(x)
    if np.iscomplexobj(a):
        return (np.round(a.real, nd) + 1j * np.round(a.imag, nd)).tolist()
    return np.round(a.astype(float), nd).tolist()


def sorted_eig(m: np.ndarray) -> np.ndarray:
    e = np.linalg.eigvals(np.asarray(m, dtype=float))
    return np.array(sorted(e, key=lambda z: (-z.real, z.imag)))


def match(printed: Any, computed: Any) -> np.ndarray:
    """Reorder ``computed`` to pair with ``printed`` (greedy nearest), for eigenvalue comparisons."""
    rem = list(np.asarray(computed, dtype=complex).ravel())
    out = []
    for p in np.asarray(printed, dtype=complex).ravel():
        j = int(np.argmin([abs(p - c) for c in rem]))
        out.append(rem.pop(j))
    return np.array(out)


def transfer_function(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Y(s)/U(s) for y = x: numerator (leading zeros dropped) and denominator coefficients."""
    sys = control.ss2tf(a, b, C_OUT, np.zeros((1, 1)))
    num = np.real(np.atleast_1d(np.squeeze(sys.num[0][0])))
    den = np.real(np.atleast_1d(np.squeeze(sys.den[0][0])))
    num = np.where(np.abs(num) < 1e-9 * np.max(np.abs(num)), 0.0, num)
    while len(num) > 1 and num[0] == 0.0:
        num = num[1:]
    return num, den


@dataclass(frozen=True)
class ThesisCoefficients:
    """Eq 3.1.26/3.1.27 linearized, with every ingredient a knob so that hypotheses can be recomputed."""

    rs: float  # r*
    j: float  # ball inertia J (k1 = J/(m r*²), k2 = J/(m r*))
    g: float
    jbp: float
    x_row_k2: bool = True  # keep 2r²/(5r*) in the θ̈ coefficient of 3.1.26 where it enters the ẍ solution

    @classmethod
    def from_params(cls, p: Parameters) -> ThesisCoefficients:
        return cls(
            rs=p.rolling_radius_m,
            j=p.ball.inertia_kgm2,
            g=p.physics.gravity_m_s2,
            jbp=p.beam.inertia_pivot_kgm2,
        )

    def parts(self, p: Parameters) -> dict[str, float]:
        m, hs, h, mb = p.ball.mass_kg, p.track.contact_height_m, p.beam.cog_height_m, p.beam.mass_kg
        k1 = self.j / (m * self.rs**2)
        k2 = self.j / (m * self.rs)
        c = hs + self.rs
        jeff = self.jbp - k2 * m * hs
        cx = (k2 + c) if self.x_row_k2 else c
        det = (k1 + 1) * jeff + (k2 + c) * k1 * m * hs
        return dict(m=m, hs=hs, h=h, mb=mb, k1=k1, k2=k2, c=c, jeff=jeff, cx=cx, det=det, g=self.g)

    def numerators(self, p: Parameters) -> tuple[dict[str, float], dict[str, float], tuple[float, float]]:
        """Numerator coefficients of eq 3.2.3 (ẍ) and 3.2.4 (θ̈) and the denominator (const, x²)."""
        q = self.parts(p)
        m, g, c, cx, k1, hs, jeff = q["m"], q["g"], q["c"], q["cx"], q["k1"], q["hs"], q["jeff"]
        mbgh = q["mb"] * g * q["h"]
        xdd = {
            "sin θ": -g * jeff + cx * mbgh,
            "x² sin θ": -g * m,
            "x θ̇²": jeff + cx * m * c,
            "x cos θ": -cx * m * g,
            "x ẋ θ̇": -2 * m * cx,
            "x³ θ̇²": m,
            "τ": cx,
        }
        thdd = {
            "τ": k1 + 1,
            "sin θ": (k1 + 1) * mbgh + k1 * m * hs * g,
            "x cos θ": -(k1 + 1) * m * g,
            "x ẋ θ̇": -(k1 + 1) * 2 * m,
            "x θ̇²": (k1 + 1) * m * c - k1 * m * hs,
        }
        return xdd, thdd, (q["det"], (k1 + 1) * m)

    def linear(self, p: Parameters, den: float | None = None) -> Matrices:
        xdd, thdd, (d0, _) = self.numerators(p)
        d = d0 if den is None else den
        a = np.zeros((4, 4))
        a[0, 2] = a[1, 3] = 1.0
        a[2, 0], a[2, 1] = xdd["x cos θ"] / d, xdd["sin θ"] / d
        a[3, 0], a[3, 1] = thdd["x cos θ"] / d, thdd["sin θ"] / d
        b = np.array([[0.0], [0.0], [xdd["τ"] / d], [thdd["τ"] / d]])
        return a, b


def x_row(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(A31, A32, B3)."""
    return np.array([a[2, 0], a[2, 1], b[2, 0]])


def theta_row(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(A41, A42, B4)."""
    return np.array([a[3, 0], a[3, 1], b[3, 0]])


def regular_form(a: np.ndarray, b: np.ndarray) -> dict[str, Any]:
    """§4.4's regular form by QR of B and the sliding design for −2, −2, −10 (S₂ = 1)."""
    q, _ = np.linalg.qr(b, mode="complete")
    tr = q.T[::-1]
    ar, br = tr @ a @ tr.T, tr @ b
    a11, a12 = ar[:3, :3], ar[:3, 3:]
    mm = state_feedback_gain(a11, a12, list(tn.SMC_SLIDING_POLES))
    s = np.hstack([mm, np.ones((1, 1))]) @ tr
    keq = np.linalg.solve(s @ b, s @ a)
    return dict(
        tr=tr, a11=a11, a12=a12, a21=ar[3:, :3], a22=ar[3:, 3:], b2=float(br[3, 0]), m=mm, s=s, keq=keq
    )


def printed_voltage_from_torque(
    kv: float = tn.MOTOR_TORQUE_PER_VOLT, kb: float = tn.MOTOR_BACKEMF_AT_BEAM
) -> Matrices:
    """Ā = A − k·k_b·B·e₄ᵀ and B̄ = k·B from the printed A, B (eq 3.3.2–3.3.6)."""
    a = tn.A_TORQUE.copy()
    a[:, 3] -= kv * kb * tn.B_TORQUE[:, 0]
    return a, kv * tn.B_TORQUE


class Model:
    """The recomputation context of the number claims, from one set of parameters."""

    def __init__(self, params: Parameters | None = None) -> None:
        self.params = params or Parameters()
        self.period_s = T

    @cached_property
    def reference(self) -> ReferenceModel:
        return ReferenceModel(self.params, motor_inertia=False)

    @cached_property
    def torque(self) -> Matrices:
        return self.reference.linearize("torque")

    @cached_property
    def voltage(self) -> Matrices:
        return self.reference.linearize("voltage")

    @cached_property
    def coefficients(self) -> ThesisCoefficients:
        return ThesisCoefficients.from_params(self.params)

    def linear(self, **knobs: Any) -> Matrices:
        """The thesis's linear model with some ingredients replaced (rs, j, g, jbp, x_row_k2)."""
        return replace(self.coefficients, **knobs).linear(self.params)

    def numerators(self, **knobs: Any) -> tuple[dict[str, float], dict[str, float], tuple[float, float]]:
        return replace(self.coefficients, **knobs).numerators(self.params)

    @cached_property
    def rolling_radius_m(self) -> float:
        r, d = self.params.ball.radius_m, self.params.track.contact_spacing_m
        return math.sqrt(r * r - d * d / 4)

    @cached_property
    def ball_inertia_kgm2(self) -> float:
        return 0.4 * self.params.ball.mass_kg * self.params.ball.radius_m**2

    def k1_plus_1(self, rs: float, j: float | None = None) -> float:
        """2r²/(5r*²) + 1 (or J/(m r*²) + 1): the θ̈ numerator's τ coefficient of eq 3.2.4."""
        m = self.params.ball.mass_kg
        return (self.ball_inertia_kgm2 if j is None else j) / (m * rs * rs) + 1

    @cached_property
    def motor_constants(self) -> tuple[float, float]:
        mo = self.params.motor
        return mo.torque_per_volt_nm_per_v, mo.backemf_at_beam_v_s_per_rad

    @cached_property
    def printed_voltage(self) -> Matrices:
        """Ā, B̄ from the printed A, B with the printed motor constants (eq 3.3.2)."""
        return printed_voltage_from_torque()

    def discrete(self, kind: str) -> Matrices:
        """ZOH at T: 'torque'/'voltage' of the model, 'printed torque' (printed A, B), 'printed voltage'
        (printed Ā, B̄), 'derived voltage' (Ā, B̄ from the printed A, B)."""
        source = {
            "torque": self.torque,
            "voltage": self.voltage,
            "printed torque": (tn.A_TORQUE, tn.B_TORQUE),
            "printed voltage": (tn.A_VOLTAGE, tn.B_VOLTAGE),
            "derived voltage": self.printed_voltage,
        }[kind]
        return discretize_zoh(*source, T)

    @cached_property
    def voltage_sources(self) -> dict[str, Matrices]:
        return {
            "printed Φ̄, Γ̄": (tn.PHI_VOLTAGE, tn.GAMMA_VOLTAGE),
            "ZOH of printed Ā, B̄": self.discrete("printed voltage"),
            "ZOH of Ā, B̄ from printed A, B": self.discrete("derived voltage"),
            "model": self.discrete("voltage"),
        }

    @cached_property
    def torque_sources(self) -> dict[str, Matrices]:
        return {
            "printed Φ, Γ": (tn.PHI_TORQUE, tn.GAMMA_TORQUE),
            "ZOH of printed A, B": self.discrete("printed torque"),
            "model": self.discrete("torque"),
        }

    def observer(self, source: Matrices, gain: np.ndarray) -> ReducedObserver:
        return ReducedObserver.from_gain(source[0], source[1], gain)


# --- formatting of computed values for the prose ----------------------------------------------------------
def g(x: Any, digits: int = 4) -> str:
    """A number (real or complex) to ``digits`` significant digits."""
    z = complex(x)
    if abs(z.imag) < 1e-12 * max(abs(z.real), 1.0):
        return f"{z.real:.{digits}g}"
    return f"{z.real:.{digits}g}{z.imag:+.{digits}g}i"


def pct(x: float, digits: int = 2) -> str:
    return f"{100 * x:.{digits}g} %"


def vec(values: Any, digits: int = 4) -> str:
    return "[" + ", ".join(g(v, digits) for v in np.asarray(values).ravel()) + "]"
