"""Closed-loop scenarios of the reproduction: declared, run once through ``twin.rigs.sim.run_closed_loop``, cached.

A ``Scenario`` names a controller (a registry name, or a law of ``LAWS`` built here from printed numbers), the
plant and the start. Two plants:

* ``"reference"`` — what the thesis did (Simulink): the reference plant (RK4 at 1 ms) with ideal converters,
  the thesis's own model (no motor inertia or damping) and the first command at release
  (``start.free_run_s`` = 0); no track end (widened to ``SIMULINK_TRACK_M``; ``left_track`` says whether the
  ball passed the real one). Chapter 4 laws run on the true state every 1 ms with no voltage limit; the
  discrete controllers at 20 ms with the ±rail limits.
* ``"twin"`` — the MuJoCo twin with its I/O chain, noise on, seed ``SEED``, the rig's default start timing;
  a start beyond ``TWIN_START_LIMIT_M`` is clamped to it.

Settling, steady values, "held", lost and stops are the run's ``twin.verdict.Verdict``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import control
import numpy as np

from controllers import registry
from controllers import thesis_numbers as tn
from controllers.laws import SlidingModeLaw, StateFeedbackLaw
from controllers.loop import TrueStateLaw
from twin.dcmotor import torque_nm
from twin.engine import RunResult, StateLaw
from twin.interface import Controller
from twin.parameters import Parameters
from twin.reference import ReferenceModel
from twin.rigs.backends import backend
from twin.rigs.sim import run_closed_loop
from twin.verdict import Criteria, Verdict

__all__ = ["LAWS", "RIG", "Scenario", "Trace", "closed_loop_eigenvalues", "run", "thesis_params"]

RIG = Parameters()
TRACK_END_M = RIG.track.half_length_m
TWIN_START_LIMIT_M = 0.32  # starts beyond the track end are clamped to this on the twin
SEED = 0
CRITERIA = Criteria()
THESIS_MODEL = {  # §3.3: no motor inertia or damping; the thesis's simulations apply the first command at release
    "motor.rotor_inertia_kgm2": 0.0,
    "motor.viscous_damping_nm_s_per_rad": 0.0,
    "start.free_run_s": 0.0,
}
SIMULINK_TRACK_M = 1.0
NO_LIMIT_RAIL_V = 1e6  # chapter 4 (Simulink): no voltage limit

# Chapter 7's SF redesign ("settling time 0.6 second and critical damped ω_n = 0.666"): readings as pole sets
REDESIGN_OMEGA_N = 0.666
REDESIGN_TS_PRINTED_S = 0.6
REDESIGN_READINGS: dict[str, tuple[list[float], str]] = {
    "dominant pair at ω_n, far pair as §4.2": (
        [-REDESIGN_OMEGA_N] * 2 + [tn.SF_CONT_POLES[2].real] * 2,
        "§4.2's procedure with the dominant pair critically damped at ω_n, the far pair kept as §4.2",
    ),
    "dominant pair at ω_n, far pair at §4.2's ratio": (
        [-REDESIGN_OMEGA_N] * 2
        + [-REDESIGN_OMEGA_N * tn.SF_CONT_POLES[2].real / tn.SF_CONT_POLES[0].real] * 2,
        "the far pair at §4.2's ratio of far to dominant real parts",
    ),
    "all four at ω_n": ([-REDESIGN_OMEGA_N] * 4, "critically damped throughout"),
    "all four for the printed t_s": (
        [-4 / REDESIGN_TS_PRINTED_S] * 4,
        "the printed t_s taken literally: ω_n = 4/t_s for all four",
    ),
}
PRIMARY_READING = "dominant pair at ω_n, far pair as §4.2"


def redesigned_sf_gain(reading: str) -> np.ndarray:
    """The chapter 7 SF redesign placed on the printed voltage model (eq 3.3.5/3.3.6), as §4.2 placed K."""
    return np.atleast_2d(control.acker(tn.A_VOLTAGE, tn.B_VOLTAGE, REDESIGN_READINGS[reading][0]))


def _sf_redesign(reading: str) -> StateLaw:
    return TrueStateLaw(
        f"sf-redesign ({reading})",
        StateFeedbackLaw(redesigned_sf_gain(reading)),
        u_kind="volts",
        period_s=registry.FAST_PERIOD_S,
        description="chapter 7 SF redesign, true state at 1 kHz",
    )


def _smc_consistent_keq() -> StateLaw:
    """The printed S̄ and switching law with K_eq = (S̄B)⁻¹S̄A on the printed A, B."""
    printed = registry.make("thesis-smc-continuous")
    assert isinstance(printed, TrueStateLaw)
    keq = np.linalg.solve(tn.SMC_S @ tn.B_TORQUE, tn.SMC_S @ tn.A_TORQUE)
    law = SlidingModeLaw(tn.SMC_S.copy(), keq, tn.SMC_K_MINUS, tn.SMC_K_PLUS, tn.SMC_ETA)
    return TrueStateLaw(
        "smc-keq-from-printed-S", law, u_kind="torque", motor=printed.motor, period_s=printed.period_s
    )


LAWS: dict[str, Callable[[], StateLaw]] = {
    "smc-keq-from-printed-S": _smc_consistent_keq,
    **{f"sf-redesign ({r})": functools.partial(_sf_redesign, r) for r in REDESIGN_READINGS},
}


def thesis_params(*, continuous: bool = False, zeroing_error_rad: float = 0.0) -> Parameters:
    """The thesis model's parameters: ``continuous`` for chapter 4 (no voltage limit, a log row per 1 ms
    law period), else chapters 5/7 (±rail, the DAQ period); ``zeroing_error_rad`` as in Fig 7.20."""
    overrides: dict[str, float] = {**THESIS_MODEL, "track.half_length_m": SIMULINK_TRACK_M}
    if continuous:
        overrides |= {"amplifier.rail_v": NO_LIMIT_RAIL_V, "daq.period_s": registry.FAST_PERIOD_S}
    if zeroing_error_rad:
        overrides["angle_sensor.zeroing_error_rad"] = zeroing_error_rad
    return Parameters().with_overrides(overrides)


@dataclass(frozen=True)
class Scenario:
    controller: str
    plant: str  # a registered backend's name (twin.rigs.backends): "reference" (the thesis's model) or "twin"
    x0_m: float
    theta0_rad: float
    duration_s: float
    zeroing_error_rad: float = 0.0

    @property
    def continuous(self) -> bool:
        return self.controller in LAWS or self.controller.endswith("-continuous")

    @property
    def label(self) -> str:
        return f"{self.controller}, {'twin' if backend(self.plant).exact else 'thesis model'}"

    def params(self) -> Parameters:
        if not backend(self.plant).exact:  # the thesis's analytic model, with the thesis's parameters
            return thesis_params(continuous=self.continuous, zeroing_error_rad=self.zeroing_error_rad)
        if self.zeroing_error_rad:
            return RIG.with_overrides({"angle_sensor.zeroing_error_rad": self.zeroing_error_rad})
        return RIG

    def controller_object(self, params: Parameters) -> Controller | StateLaw:
        if self.controller in LAWS:
            return LAWS[self.controller]()
        return registry.make(self.controller, None if self.continuous else params)


@dataclass
class Trace:
    """One run as plotted: times, true state rows (x, θ, ẋ, θ̇), motor volts, torque at the beam (eq 3.3.1
    with the plant's constants), the controller's estimate (x1..x4) and the run's verdict."""

    scenario: Scenario
    t: np.ndarray
    state: np.ndarray
    volts: np.ndarray
    torque: np.ndarray
    estimate: np.ndarray
    verdict: Verdict
    extra: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_run(cls, scenario: Scenario, run: RunResult, params: Parameters) -> Trace:
        log = run.log
        state = np.column_stack(
            [log.true_x_m, log.true_theta_rad, log.true_xdot_m_s, log.true_thetadot_rad_s]
        )
        volts = np.asarray(log.motor_volts_v, dtype=float)
        m = params.motor
        torque = np.asarray(
            torque_nm(volts, state[:, 3], m.torque_per_volt_nm_per_v, m.backemf_at_beam_v_s_per_rad),
            dtype=float,
        )
        estimate = np.column_stack([log.x1, log.x2, log.x3, log.x4])
        return cls(
            scenario, np.asarray(log.true_time_s, dtype=float), state, volts, torque, estimate, run.verdict
        )

    @property
    def x(self) -> np.ndarray:
        return self.state[:, 0]

    @property
    def theta(self) -> np.ndarray:
        return self.state[:, 1]

    @property
    def lost(self) -> bool:
        return self.verdict.ball_lost

    @property
    def left_track(self) -> bool:
        return bool(self.extra.get("left_track", False))

    @property
    def kept(self) -> bool:
        """Ball never lost and never past the real track end (thesis-model runs have none)."""
        return not self.lost and not self.left_track

    @property
    def peak_torque_nm(self) -> float:
        return float(np.max(np.abs(self.torque[self.t >= 0.0])))

    def status(self) -> str:
        if self.verdict.ball_lost_time_s is not None:
            return f"lost at {self.verdict.ball_lost_time_s:.2f} s"
        base = "held" if self.verdict.held else "kept"
        return base + ", past the track end" if self.left_track else base

    def summary(self) -> dict[str, Any]:
        v = self.verdict
        return {
            "status": self.status(),
            "ball_kept": not v.ball_lost,
            "ball_lost_time_s": _round(v.ball_lost_time_s, 3),
            "held": v.held,
            "settling_time_s": _round(v.settling_time_s, 3),
            "steady_x_m": _round(v.steady_x_m, 4),
            "hit_stops": v.hit_stops,
            "peak_theta_rad": round(v.peak_theta_rad, 4),
            "peak_torque_nm": round(self.peak_torque_nm, 4),
            "peak_volts_v": round(v.peak_motor_voltage_v, 3),
            "final_x_m": round(float(self.x[-1]), 4),
            **self.extra,
        }


def _round(value: float | None, digits: int) -> float | None:
    return None if value is None else round(float(value), digits)


@functools.cache
def run(scenario: Scenario) -> Trace:
    """The scenario's run (once per process)."""
    params = scenario.params()
    twin = backend(scenario.plant).exact
    x0 = float(np.clip(scenario.x0_m, -TWIN_START_LIMIT_M, TWIN_START_LIMIT_M)) if twin else scenario.x0_m
    result = run_closed_loop(
        scenario.controller_object(params),
        x0_m=x0,
        theta0_rad=scenario.theta0_rad,
        duration_s=scenario.duration_s,
        seed=SEED,
        noise=twin,
        params=params,
        plant=scenario.plant,
        ideal_sensors=not twin,
    )
    tr = Trace.from_run(scenario, result, params)
    if twin and x0 != scenario.x0_m:
        tr.extra["start_clamped_to_m"] = x0
    if not twin:
        max_x = float(np.max(np.abs(tr.x)))
        tr.extra["max_abs_x_m"] = round(max_x, 4)
        tr.extra["left_track"] = bool(max_x > max(TRACK_END_M, abs(scenario.x0_m) + 1e-6))
    return tr


def closed_loop_eigenvalues(name: str, h: float = 1e-6) -> np.ndarray:
    """Eigenvalues of a chapter 4 loop (the law's volts on the thesis model, as simulated) linearized at 0."""
    law = registry.make(name)
    assert isinstance(law, TrueStateLaw)
    model = ReferenceModel(thesis_params(continuous=True))

    def f(s: np.ndarray) -> np.ndarray:
        return model.derivative(s, law.motor_volts(s), "voltage")

    jac = np.column_stack([(f(h * e) - f(-h * e)) / (2 * h) for e in np.eye(4)])
    law.reset()
    return np.linalg.eigvals(jac)
