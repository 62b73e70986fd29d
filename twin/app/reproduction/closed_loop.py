"""The closed-loop claims of chapters 4, 5 and 7 (figures and statements), each declaring its scenarios.

Every claim's recomputation reads the cached runs of its scenarios (``scenarios.run``) and their verdicts;
its check is a predicate on those verdicts. A figure's claim is what its caption and text say the plotted
run shows; the figure itself is drawn by ``figures`` from the same runs.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from controllers import registry
from controllers import thesis_numbers as tn
from controllers.loop import LoopController, ObserverState
from twin.app.reproduction.claims import (
    AGREES,
    FAILS,
    HOLDS,
    MISPRINT,
    Claim,
    Hypothesis,
    Predicate,
    Within,
    range_error,
)
from twin.app.reproduction.models import g
from twin.app.reproduction.scenarios import (
    CRITERIA,
    PRIMARY_READING,
    REDESIGN_OMEGA_N,
    REDESIGN_READINGS,
    REDESIGN_TS_PRINTED_S,
    RIG,
    TRACK_END_M,
    TWIN_START_LIMIT_M,
    Scenario,
    Trace,
    closed_loop_eigenvalues,
    run,
)
from twin.rigs.backends import backend

__all__ = ["CLAIMS", "FIGURE_SHOW"]

# run lengths: a settling time needs the verdict's final window after it; CLP settles after tens of seconds
CONT_S = {"thesis-sf-continuous": 10.0, "thesis-clp-continuous": 35.0, "thesis-smc-continuous": 3.0}
CONT_TWIN_S = {"thesis-sf-continuous": 10.0, "thesis-clp-continuous": 12.0, "thesis-smc-continuous": 3.0}
DISC_S = 15.0
CORNER_S, GRID_S = 10.0, 6.0
REDESIGN_S, REDESIGN_TWIN_S, FIXED_SMC_S = 30.0, 20.0, 5.0
ZEROING_S = 15.0
SETTLING_SLACK = 0.05  # relative: a settling range read off a plot
CLP_SETTLING_SLACK = 0.1
TORQUE_LIKE = 0.3  # "nearly the same" torque: peak within ±30 % of CLP's (after the start spike)
SPIKE_S = 0.1  # CLP's torque starts with a step kp·θ0; peaks compared also after it
LATE_ERROR_SHARE = 0.2  # observer error "converges": late max below this share of the overall max
CH4_STARTS = tn.CHAPTER4_STARTS
SF_SETTLING_CH7 = (2.0, 3.0)  # chapter 7: "2 < t_s < 3, as expected"
ZEROING_ERRORS_RAD = (-0.04, -0.02, 0.0, 0.02, 0.04)
ZEROING_START = (0.1, 0.0)
GRID_X = (-0.3, -0.15, 0.0, 0.15, 0.3)
GRID_TH = (-0.7, -0.35, 0.0, 0.35, 0.7)
RANGE_FIGURE_CORNERS = {"sf": ((-0.25, 0.2), (0.33, 0.68)), "clp": ((-0.26, 0.3), (0.33, 0.7))}
CLAIM_BOXES = {"sf": tn.SF_DISC_RANGE, "clp": tn.CLP_DISC_RANGE}
LABELS = {"sf": "state feedback", "clp": "control law partitioning", "smc": "sliding mode"}

Plant = str  # a registered backend's name (twin.rigs.backends): "reference" (the thesis's model) or "twin"

# what each figure plots (rows of panels) — read by ``figures``
FIGURE_SHOW: dict[str, tuple[str, ...]] = {}


def cont(name: str, x0: float, th0: float, plant: Plant = "reference", dur: float | None = None) -> Scenario:
    table = CONT_TWIN_S if backend(plant).exact else CONT_S
    return Scenario(
        name, plant, x0, th0, dur if dur is not None else table.get(name, CONT_S["thesis-sf-continuous"])
    )


def disc(name: str, x0: float, th0: float, plant: Plant, dur: float = DISC_S, e: float = 0.0) -> Scenario:
    return Scenario(name, plant, x0, th0, dur, e)


def _seconds(value: float | None) -> str:
    return "none" if value is None else f"{value:.3f} s"


def _summaries(scenarios: Iterable[Scenario]) -> dict[str, Any]:
    return {s.label: run(s).summary() for s in scenarios}


def _statuses(scenarios: Iterable[Scenario]) -> str:
    return "; ".join(f"{s.label}: {run(s).status()}" for s in scenarios)


def _eig_list(ev: np.ndarray) -> list[Any]:
    return [
        round(float(z.real), 3) if abs(z.imag) < 1e-9 else [round(float(z.real), 3), round(float(z.imag), 3)]
        for z in sorted(ev, key=lambda z: (z.real, z.imag))
    ]


def _figure(
    fig_id: str,
    quantity: str,
    printed: str,
    scenarios: tuple[Scenario, ...],
    judge: Predicate,
    explain: Callable[[Any, Any], str],
    show: tuple[str, ...],
    recompute: Callable[[Any], Any] | None = None,
    confirmed: str = HOLDS,
) -> Claim:
    FIGURE_SHOW[fig_id] = show
    return Claim(
        fig_id,
        quantity,
        printed,
        recompute or (lambda m: _summaries(scenarios)),
        judge,
        explain=explain,
        confirmed=confirmed,
        otherwise=FAILS,
        scenarios=scenarios,
    )


# --- chapter 4 ---------------------------------------------------------------------------------------------
def _chapter4() -> list[Claim]:
    out = []
    sf_eig = closed_loop_eigenvalues("thesis-sf-continuous")
    clp_eig = closed_loop_eigenvalues("thesis-clp-continuous")
    slow = min(abs(z.real) for z in clp_eig)
    lo, hi = tn.SF_CONT_SETTLING_S
    for fid, (x0, th0) in zip(("Fig 4.4", "Fig 4.5"), CH4_STARTS, strict=True):
        runs: tuple[Scenario, ...] = (
            cont("thesis-sf-continuous", x0, th0),
            cont("thesis-sf-continuous", x0, th0, "twin"),
        )
        out.append(
            _figure(
                fid,
                f"§4.2 state feedback from (x, θ) = ({x0} m, {th0} rad): settling time",
                f"reaches the desired value in {lo}–{hi} s",
                runs,
                Predicate(
                    f"both settling times within the printed range widened by {SETTLING_SLACK:.0%}",
                    lambda p, v, runs=runs: all(
                        (e := range_error(run(s).verdict.settling_time_s, lo, hi)) is not None
                        and e <= SETTLING_SLACK
                        for s in runs
                    ),
                ),
                lambda m, v: (
                    f"Settling times (the verdict's, band max({CRITERIA.settling_fraction:.0%}·|x0|, "
                    f"{CRITERIA.settling_floor_m * 1e3:g} mm)): "
                    + ", ".join(f"{k}: {_seconds(s['settling_time_s'])}" for k, s in v.items())
                    + f". Linearized loop on the thesis model: {_eig_list(sf_eig)}."
                ),
                ("x", "theta", "torque"),
                confirmed=AGREES,
            )
        )
    lo7, hi7 = tn.CLP_CONT_SETTLING_S
    for fid, (x0, th0) in zip(("Fig 4.8", "Fig 4.9"), CH4_STARTS, strict=True):
        runs = (cont("thesis-clp-continuous", x0, th0), cont("thesis-clp-continuous", x0, th0, "twin"))
        out.append(
            _figure(
                fid,
                f"§4.3 control law partitioning from ({x0} m, {th0} rad): response and settling time",
                f"ball brought back; chapter 7: t_s between {lo7} and {hi7} s",
                runs,
                Predicate(
                    f"thesis model settles within the range widened by {CLP_SETTLING_SLACK:.0%}, on the "
                    "track; twin keeps the ball",
                    lambda p, v, runs=runs: (
                        run(runs[0]).kept
                        and not run(runs[1]).lost
                        and (e := range_error(run(runs[0]).verdict.settling_time_s, lo7, hi7)) is not None
                        and e <= CLP_SETTLING_SLACK
                    ),
                ),
                lambda m, v, runs=runs: (
                    f"Linearized loop {_eig_list(clp_eig)}: the slow pair's real part {slow:.3f} 1/s "
                    f"gives 4/σ = {4 / slow:.0f} s. {_statuses(runs)}; thesis-model settling "
                    f"{_seconds(run(runs[0]).verdict.settling_time_s)}, largest |x| "
                    f"{run(runs[0]).extra['max_abs_x_m']} m "
                    f"(track end {TRACK_END_M} m)."
                ),
                ("x", "theta", "torque"),
                confirmed=AGREES,
            )
        )
    eig_eq = np.linalg.eigvals(tn.A_TORQUE - tn.B_TORQUE @ tn.SMC_KEQ)
    sb = float((tn.SMC_S @ tn.B_TORQUE)[0, 0])
    for fid, (x0, th0) in zip(("Fig 4.11", "Fig 4.12"), CH4_STARTS, strict=True):
        runs = (
            cont("thesis-smc-continuous", x0, th0),
            cont("thesis-smc-continuous", x0, th0, "twin"),
            cont("smc-keq-from-printed-S", x0, th0, dur=FIXED_SMC_S),
        )
        out.append(
            _figure(
                fid,
                f"§4.4 sliding mode from ({x0} m, {th0} rad)",
                "system reaches the sliding surface in a few seconds and is brought to the origin",
                runs,
                Predicate(
                    "held (the verdict) on the thesis model and the twin",
                    lambda p, v, runs=runs: run(runs[0]).verdict.held and run(runs[1]).verdict.held,
                ),
                lambda m, v, runs=runs: (
                    f"eig(A − B·K_eq) with the printed K_eq: largest real part {max(eig_eq.real):.0f} 1/s; "
                    f"S̄B = {sb:.1f}, so the switching terms push away from the surface. {_statuses(runs)}; "
                    f"beam on its stops: {', '.join(str(run(s).verdict.hit_stops) for s in runs)}."
                ),
                ("x", "theta", "torque"),
                confirmed=AGREES,
            )
        )
    return out


# --- chapter 5 ---------------------------------------------------------------------------------------------
def _observer_magnitudes(name: str) -> list[float]:
    ctrl = registry.make(name)
    assert isinstance(ctrl, LoopController) and isinstance(ctrl.state, ObserverState)
    return [round(float(abs(z)), 4) for z in ctrl.state.observer.error_poles()]


def observer_error(tr: Trace) -> dict[str, float]:
    err = tr.state[:, 2:] - tr.estimate[:, 2:]
    late = slice(len(tr.t) // 2, None)
    return {
        "max_abs_error_xdot_m_s": round(float(np.max(np.abs(err[:, 0]))), 4),
        "max_abs_error_thetadot_rad_s": round(float(np.max(np.abs(err[:, 1]))), 4),
        "late_abs_error_thetadot_rad_s": round(float(np.max(np.abs(err[late, 1]))), 4),
    }


def _chapter5() -> list[Claim]:
    out = []
    groups = (
        ("sf", ("Fig 5.3", "Fig 5.4", "Fig 5.5"), "§5.2.1"),
        ("clp", ("Fig 5.8", "Fig 5.9", "Fig 5.10"), "§5.2.2"),
    )
    for kind, (f_pos, f_neg, f_err), sec in groups:
        name, appendix = f"thesis-{kind}", f"appendix-{kind}"
        mags = _observer_magnitudes(name)
        for fid, (x0, th0) in zip((f_pos, f_neg), CH4_STARTS, strict=True):
            runs = tuple(disc(n, x0, th0, p) for n in (name, appendix) for p in ("reference", "twin"))
            out.append(
                _figure(
                    fid,
                    f"{sec} discrete {LABELS[kind]} with reduced-order observer from ({x0} m, {th0} rad)",
                    "ball brought back to the origin (response plotted)",
                    runs,
                    Predicate(
                        f"{name} held on the thesis model (on the track) and on the twin",
                        lambda p, v, runs=runs: (
                            run(runs[0]).verdict.held and run(runs[0]).kept and run(runs[1]).verdict.held
                        ),
                    ),
                    lambda m, v, runs=runs, mags=mags: (
                        f"Observer error poles |z| = {mags}. {_statuses(runs)}."
                    ),
                    ("x", "theta", "volts"),
                    confirmed=AGREES,
                )
            )
        x0, th0 = CH4_STARTS[1]
        runs = (
            disc(name, x0, th0, "reference"),
            disc(name, x0, th0, "twin"),
            disc(appendix, x0, th0, "reference"),
        )

        def converges(p: Any, v: Any, runs: tuple[Scenario, ...] = runs, mags: list[float] = mags) -> bool:
            err = observer_error(run(runs[0]))
            late, peak = err["late_abs_error_thetadot_rad_s"], err["max_abs_error_thetadot_rad_s"]
            return max(mags) < 1.0 and late < LATE_ERROR_SHARE * max(peak, 1e-9) and not run(runs[0]).lost

        out.append(
            _figure(
                f_err,
                f"observer error (ẋ − ẋ̂, θ̇ − θ̇̂) of the {LABELS[kind]} observer from ({x0} m, {th0} rad)",
                "observer error converges to zero",
                runs,
                Predicate(
                    f"error poles inside the unit circle, and the late error (second half) below "
                    f"{LATE_ERROR_SHARE:.0%} of the peak on the thesis model",
                    converges,
                ),
                lambda m, v, mags=mags, runs=runs: f"Error poles |z| = {mags}; {_statuses(runs)}.",
                ("observer error",),
                confirmed=AGREES,
                recompute=lambda m, runs=runs, mags=mags: {
                    **{s.label: observer_error(run(s)) for s in runs},
                    "observer_error_pole_magnitudes": mags,
                },
            )
        )
    return out


# --- chapter 7: torque ------------------------------------------------------------------------------------
def _rail_torque_nm() -> float:
    return RIG.amplifier.rail_v * RIG.motor.torque_per_volt_nm_per_v


def _chapter7_torque() -> list[Claim]:
    out = []
    names = ("thesis-smc-continuous", "thesis-clp-continuous", "thesis-sf-continuous")
    figs = {("Fig 7.1", "Fig 7.2", "Fig 7.3"): (0.2, -0.3), ("Fig 7.4", "Fig 7.5", "Fig 7.6"): (0.2, 0.3)}
    for ids, (x0, th0) in figs.items():
        for fid, name in zip(ids, names, strict=True):
            runs = (cont(name, x0, th0), cont(name, x0, th0, "twin"))
            out.append(
                _figure(
                    fid,
                    f"required torque, {LABELS[name.split('-')[1]]}, from ({x0} m, {th0} rad)",
                    "required torque versus time (of a run that brings the ball back)",
                    runs,
                    Predicate(
                        "ball kept on the thesis model (on the track) and on the twin",
                        lambda p, v, runs=runs: run(runs[0]).kept and not run(runs[1]).lost,
                    ),
                    lambda m, v, runs=runs: (
                        f"Peak |τ| {', '.join(f'{s.label}: {run(s).peak_torque_nm:.4f} N·m' for s in runs)} "
                        f"(the rails cap it at {_rail_torque_nm():.3f} N·m); {_statuses(runs)}."
                    ),
                    ("torque", "x"),
                )
            )
    starts = tuple(figs.values())
    smc = tuple(cont("thesis-smc-continuous", *st) for st in starts)
    others = tuple(cont(n, *st) for n in names[1:] for st in starts)

    def smc_claim(p: Any, v: Any) -> bool:
        return all(run(s).verdict.held for s in smc) and all(
            run(s).peak_torque_nm > max(run(o).peak_torque_nm for o in others) for s in smc
        )

    out.append(
        Claim(
            "§7 claim SMC torque",
            "sliding mode's required torque vs SF and CLP",
            "SMC torque is temporary, greater than SF/CLP, with chattering; nearly zero on the sliding surface",
            lambda m: _summaries(smc),
            Predicate("SMC held (so on the surface) and its peak torque above SF's and CLP's", smc_claim),
            explain=lambda m, v: (
                f"{_statuses(smc)}: without reaching the surface there is no temporary torque to see."
            ),
            otherwise=FAILS,
            scenarios=smc + others,
        )
    )
    pairs = {st: (cont(names[1], *st), cont(names[2], *st)) for st in starts}

    def clp_lower(p: Any, v: Any) -> bool:
        return all(run(c).peak_torque_nm < run(s).peak_torque_nm for c, s in pairs.values())

    out.append(
        Claim(
            "§7 claim CLP torque lower",
            "maximum required torque, CLP vs SF (thesis model, both starts)",
            "maximum required torque for control law partitioning is lower than for state feedback",
            lambda m: {
                str(st): {"clp_peak_nm": run(c).peak_torque_nm, "sf_peak_nm": run(s).peak_torque_nm}
                for st, (c, s) in pairs.items()
            },
            Predicate("CLP's peak |τ| below SF's from every start", clp_lower),
            explain=lambda m, v: (
                "; ".join(
                    f"{k}: CLP {g(d['clp_peak_nm'])} vs SF {g(d['sf_peak_nm'])} N·m" for k, d in v.items()
                )
                + "."
            ),
            otherwise=FAILS,
            scenarios=tuple(s for pr in pairs.values() for s in pr),
        )
    )
    # Fig 7.7
    x0, th0 = figs[("Fig 7.1", "Fig 7.2", "Fig 7.3")]
    variants = {r: cont(f"sf-redesign ({r})", x0, th0, dur=REDESIGN_S) for r in REDESIGN_READINGS}
    twin_primary = cont(f"sf-redesign ({PRIMARY_READING})", x0, th0, "twin", dur=REDESIGN_TWIN_S)
    clp = cont("thesis-clp-continuous", x0, th0)

    def late_peak(tr: Trace) -> float:
        return float(np.max(np.abs(tr.torque[tr.t >= SPIKE_S])))

    def table(m: Any) -> dict[str, Any]:
        return {
            r: {
                "poles": REDESIGN_READINGS[r][0],
                "peak_torque_nm": round(run(s).peak_torque_nm, 4),
                "ratio_to_clp_after_spike": round(late_peak(run(s)) / late_peak(run(clp)), 3),
                "ball_kept_thesis_model": not run(s).lost,
                "hit_stops_thesis_model": run(s).verdict.hit_stops,
            }
            for r, s in variants.items()
        } | {"twin_primary": run(twin_primary).summary()}

    def similar(p: Any, v: dict[str, Any]) -> bool:
        row = v[PRIMARY_READING]
        return bool(row["ball_kept_thesis_model"] and abs(row["ratio_to_clp_after_spike"] - 1) <= TORQUE_LIKE)

    FIGURE_SHOW["Fig 7.7"] = ("torque", "x")
    out.append(
        Claim(
            "Fig 7.7",
            f"required torque of the redesigned SF (critically damped, ω_n = {REDESIGN_OMEGA_N}) from ({x0} "
            f"m, {th0} rad)",
            "required torque nearly the same as control law partitioning's",
            table,
            Predicate(
                f"primary reading ({PRIMARY_READING}) keeps the ball, peak |τ| after {SPIKE_S} s within "
                f"±{TORQUE_LIKE:.0%} of CLP's",
                similar,
            ),
            explain=lambda m, v: (
                "Readings: "
                + "; ".join(f"{r}: {d}" for r, (_, d) in REDESIGN_READINGS.items())
                + f". CLP's peak {run(clp).peak_torque_nm:.3f} N·m, after the start spike "
                f"{late_peak(run(clp)):.3f} N·m. "
                + "; ".join(
                    f"{r}: ratio {d['ratio_to_clp_after_spike']}, kept {d['ball_kept_thesis_model']}"
                    for r, d in v.items()
                    if r in variants
                )
                + "."
            ),
            confirmed=HOLDS,
            otherwise=FAILS,
            scenarios=(*variants.values(), twin_primary, clp),
        )
    )
    out.append(
        Claim(
            "§7 SF redesign spec",
            "settling time t_s = 4/(ζω_n) of the critically damped redesign (ζ = 1)",
            REDESIGN_TS_PRINTED_S,
            lambda m: 4 / REDESIGN_OMEGA_N,
            hypotheses=(
                Hypothesis(
                    "a slip of the decimal point: the printed t_s is a tenth of 4/(ζω_n)",
                    MISPRINT,
                    value=lambda m: 4 / REDESIGN_OMEGA_N / 10,
                ),
            ),
            explain=lambda m, v: (
                f"4/ω_n = {v:.3f} s for the printed ω_n; the printed t_s would need ω_n = "
                f"{4 / REDESIGN_TS_PRINTED_S:.3f} (tried in Fig 7.7: "
                f"{'kept' if not run(variants['all four for the printed t_s']).lost else 'loses the ball'})."
            ),
        )
    )
    # settling-time statements
    three = (*CH4_STARTS, (CH4_STARTS[0][0], -CH4_STARTS[0][1]))
    sf_runs = tuple(cont("thesis-sf-continuous", *st, plant=p) for st in three for p in ("reference", "twin"))
    lo, hi = SF_SETTLING_CH7
    out.append(
        Claim(
            "§7 claim SF settling",
            "settling time of the chapter 4 state feedback",
            (lo, hi),
            lambda m: [run(s).verdict.settling_time_s for s in sf_runs],
            Within(),
            explain=lambda m, v: (
                "; ".join(
                    f"{s.label} from ({s.x0_m}, {s.theta0_rad}): {_seconds(t)}"
                    for s, t in zip(sf_runs, v, strict=True)
                )
                + "."
            ),
            confirmed=HOLDS,
            otherwise=FAILS,
            scenarios=sf_runs,
        )
    )
    clp_runs = tuple(cont("thesis-clp-continuous", *st) for st in three)

    def first_near_centre(tr: Trace) -> float | None:
        near = np.abs(tr.x) < CRITERIA.offset_band_m * 2
        return None if not near.any() else round(float(tr.t[np.argmax(near)]), 3)

    out.append(
        Claim(
            "§7 claim CLP settling",
            "settling time of the chapter 4 control law partitioning (thesis model)",
            tuple(tn.CLP_CONT_SETTLING_S),
            lambda m: [run(s).verdict.settling_time_s for s in clp_runs],
            Within(),
            explain=lambda m, v: (
                "The slow pair's real part is "
                f"{min(abs(z.real) for z in closed_loop_eigenvalues('thesis-clp-continuous')):.3f} 1/s. "
                + "; ".join(
                    f"from ({s.x0_m}, {s.theta0_rad}): settling {_seconds(t)}, first within "
                    f"{CRITERIA.offset_band_m * 2e3:g} mm of the centre at {_seconds(first_near_centre(run(s)))}"
                    for s, t in zip(clp_runs, v, strict=True)
                )
                + "."
            ),
            confirmed=HOLDS,
            otherwise=FAILS,
            scenarios=clp_runs,
        )
    )
    return out


# --- chapter 7: ranges of initial states ------------------------------------------------------------------
def _box_points(box: Any) -> list[tuple[float, float]]:
    (x_lo, th_lo), (x_hi, th_hi) = box
    return [(x_lo, th_lo), (x_hi, th_hi), (x_lo, th_hi), (x_hi, th_lo)]


def _range_points(kind: str) -> list[tuple[float, float]]:
    box = CLAIM_BOXES[kind]
    pts = _box_points(box)
    pts += [p for p in RANGE_FIGURE_CORNERS[kind] if p not in pts]
    (x_lo, th_lo), (x_hi, th_hi) = box
    grid = [(x, th) for x in GRID_X for th in GRID_TH]
    return pts + [p for p in grid if x_lo <= p[0] <= x_hi and th_lo <= p[1] <= th_hi and p not in pts]


def _chapter7_ranges() -> list[Claim]:
    out = []
    for kind, corners in RANGE_FIGURE_CORNERS.items():
        ids = iter(
            f"Fig 7.{i}" for i in ((8, 9, 10, 11, 12, 13) if kind == "sf" else (14, 15, 16, 17, 18, 19))
        )
        for x0, th0 in corners:
            runs = tuple(
                disc(n, x0, th0, p, CORNER_S)
                for n in (f"thesis-{kind}", f"appendix-{kind}")
                for p in ("reference", "twin")
            )
            for what, show in (("motor voltage", "volts"), ("ball position", "x"), ("beam angle", "theta")):
                out.append(
                    _figure(
                        next(ids),
                        f"{what} of the discrete {LABELS[kind]} from ({x0} m, {th0} rad)",
                        "the ball rolls on the beam without dropping from this start",
                        runs,
                        Predicate(
                            f"thesis-{kind} keeps the ball on the thesis model",
                            lambda p, v, runs=runs: run(runs[0]).kept,
                        ),
                        lambda m, v, runs=runs, x0=x0: (
                            f"{_statuses(runs)}."
                            + (
                                f" The start is beyond the {TRACK_END_M} m track end; the twin starts at "
                                f"{TWIN_START_LIMIT_M} m."
                                if abs(x0) > TRACK_END_M
                                else ""
                            )
                        ),
                        (show,),
                    )
                )
    for kind in ("sf", "clp"):
        pts = _range_points(kind)
        runs = tuple(
            disc(n, x, th, p, CORNER_S)
            for x, th in pts
            for n in (f"thesis-{kind}", f"appendix-{kind}")
            for p in ("reference", "twin")
        )
        printed_runs = tuple(
            s for s in runs if s.controller.startswith("thesis") and not backend(s.plant).exact
        )
        box = CLAIM_BOXES[kind]
        out.append(
            Claim(
                f"§7 claim {kind.upper()} range",
                f"initial states the discrete {LABELS[kind]} brings back",
                f"ball rolls without dropping for initial states between {list(box[0])} and {list(box[1])} [m, rad]",
                lambda m, runs=runs: {
                    f"({s.x0_m:+.2f} m, {s.theta0_rad:+.2f} rad) {s.label}": run(s).status() for s in runs
                },
                Predicate(
                    f"thesis-{kind} keeps the ball on the thesis model from every tested start",
                    lambda p, v, pr=printed_runs: all(run(s).kept for s in pr),
                ),
                explain=lambda m, v, runs=runs, pts=pts: (
                    "Tested: the printed corners, the other two corners, the figures' corners and "
                    "the grid points inside; "
                    + "; ".join(
                        f"{lab}: {sum(run(s).kept for s in runs if s.label == lab)} of {len(pts)} kept"
                        for lab in dict.fromkeys(s.label for s in runs)
                    )
                    + "."
                ),
                confirmed=HOLDS,
                otherwise=FAILS,
                scenarios=runs,
            )
        )
    grid = [(x, th) for x in GRID_X for th in GRID_TH]
    grid_runs = {
        (n, p): tuple(disc(n, x, th, p, GRID_S) for x, th in grid)
        for n in ("thesis-sf", "thesis-clp", "appendix-sf", "appendix-clp")
        for p in ("reference", "twin")
    }

    def kept(n: str, p: str) -> set[tuple[float, float]]:
        return {(s.x0_m, s.theta0_rad) for s in grid_runs[(n, p)] if run(s).kept}

    out.append(
        Claim(
            "§7 claim CLP range larger",
            "range of initial states kept: CLP vs SF (discrete, with observers)",
            "the range of controllable initial conditions for control law partitioning is larger than for "
            "state feedback",
            lambda m: {f"{n}, {p}": len(kept(n, p)) for n, p in grid_runs},
            Predicate(
                "thesis-clp's kept set on the thesis model strictly contains thesis-sf's",
                lambda p, v: kept("thesis-clp", "reference") > kept("thesis-sf", "reference"),
            ),
            explain=lambda m, v: (
                f"Kept of {len(grid)} grid starts: "
                + ", ".join(f"{k}: {n}" for k, n in v.items())
                + f". thesis-sf keeps the ball from {len(kept('thesis-sf', 'reference') - {(0.0, 0.0)})} "
                "starts other than rest."
            ),
            confirmed=HOLDS,
            otherwise=FAILS,
            scenarios=tuple(s for r in grid_runs.values() for s in r),
        )
    )
    return out


# --- Fig 7.20 ---------------------------------------------------------------------------------------------
def zeroing_runs() -> dict[str, tuple[Scenario, ...]]:
    return {
        f"{n}, {'twin' if backend(p).exact else 'thesis model'}": tuple(
            disc(n, *ZEROING_START, p, ZEROING_S, e) for e in ZEROING_ERRORS_RAD
        )
        for n in ("appendix-sf", "appendix-clp")
        for p in ("twin", "reference")
    }


def _steady(s: Scenario) -> tuple[float, float]:
    v = run(s).verdict
    return (
        math.nan if v.steady_x_m is None else v.steady_x_m,
        math.nan if v.steady_theta_rad is None else v.steady_theta_rad,
    )


def _fig720() -> Claim:
    series = zeroing_runs()

    def monotonic(xs: list[float]) -> bool:
        d = np.diff(xs)
        return bool(np.all(np.isfinite(d)) and (np.all(d > 0) or np.all(d < 0)))

    def recompute(m: Any) -> dict[str, Any]:
        return {
            label: {
                "steady_x_m": [round(_steady(s)[0], 5) for s in runs],
                "steady_theta_rad": [round(_steady(s)[1], 5) for s in runs],
            }
            for label, runs in series.items()
        }

    FIGURE_SHOW["Fig 7.20"] = ("zeroing",)
    return Claim(
        "Fig 7.20",
        "equilibrium reached with a beam-angle zeroing error e (appendix A controllers)",
        "setting the beam angle other than 0° at initialization makes the system stabilize at a different "
        "equilibrium point",
        recompute,
        Predicate(
            "the twin's steady ball position moves monotonically with e, for both controllers",
            lambda p, v: all(monotonic(d["steady_x_m"]) for k, d in v.items() if k.endswith("twin")),
        ),
        explain=lambda m, v: (
            f"Zeroing errors {list(ZEROING_ERRORS_RAD)} rad from {ZEROING_START}; slopes of the steady x: "
            + ", ".join(
                f"{k}: {np.polyfit(ZEROING_ERRORS_RAD, d['steady_x_m'], 1)[0]:.3f} m/rad"
                for k, d in v.items()
                if np.all(np.isfinite(d["steady_x_m"]))
            )
            + f"; largest |steady θ| {max(np.nanmax(np.abs(d['steady_theta_rad'])) for d in v.values()):.4f} rad."
        ),
        confirmed=HOLDS,
        otherwise=FAILS,
        scenarios=tuple(s for r in series.values() for s in r),
    )


def claims() -> tuple[Claim, ...]:
    return (*_chapter4(), *_chapter5(), *_chapter7_torque(), *_chapter7_ranges(), _fig720())


CLAIMS: tuple[Claim, ...] = claims()
