"""Named controllers: ``make(name, params)`` builds one ready to run.

This module is the controller catalogue the application layer hands to the CLI and the live view
(``NAMES``, ``make``, ``simulation_only``, ``describe``).

    thesis-*-continuous  chapter 4 designs, numbers as printed, on the true state at 1 kHz (simulation-only
                         ``TrueStateLaw``s: they are not hardware controllers)
    thesis-sf, -clp      chapter 5 designs with their reduced-order observers, numbers as printed, 50 Hz
    appendix-sf, -clp    the appendix A callbacks that ran on the rig, ported exactly
    sf, clp, smc         the thesis's design procedures re-run correctly on the reference model, 50 Hz
    lqr                  LQR with a steady-state Kalman filter on the same model, 50 Hz

"as printed" means a failing printed design fails here too; it is reported, never quietly corrected.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence

import control
import numpy as np

from controllers import thesis_numbers as T
from controllers.appendix import AppendixControlLaw, AppendixStateFeedback
from controllers.batch import batched
from controllers.design import (
    ReducedObserver,
    clp_gains,
    reduced_order_observer,
    sliding_surface,
    state_feedback_gain,
)
from controllers.laws import ClpLaw, ClpTerms, KalmanState, SlidingModeLaw, StateFeedbackLaw
from controllers.loop import LoopController, MotorInverse, ObserverState, TrueStateLaw
from twin.batch import BatchController
from twin.interface import Controller
from twin.parameters import Parameters
from twin.reference import ReferenceModel
from twin.sensors import angle_count_step_rad

__all__ = ["NAMES", "UnknownControllerError", "describe", "make", "make_batch", "simulation_only"]

AnyController = Controller | TrueStateLaw

FAST_PERIOD_S = 0.001  # chapter 4 designs run "continuously": every physics step

# Chapter 4's "torque" block (eq 3.3.2 as printed) converts between volts and torque for the thesis designs.
_THESIS_MOTOR = MotorInverse(T.MOTOR_TORQUE_PER_VOLT, T.MOTOR_BACKEMF_AT_BEAM)
_THESIS_CLP_TERMS = ClpTerms(T.CLP_ALPHA_XDD, T.CLP_ALPHA_THDD, T.CLP_ALPHA_THDD_X2, T.CLP_BETA)

# Sliding-mode switching (§4.4) and the chapter 5 pole choices, reused by the re-done designs.
_CLP_POLES_Z = [T.CLP_DISC_POLES[0]] * 4  # ω_n = 2, ζ = 1 for both x and θ: four poles at z = e^{−2T}


class UnknownControllerError(KeyError):
    def __str__(self) -> str:
        return f"unknown controller {self.args[0]!r}; known: {', '.join(NAMES)}"


def _motor(params: Parameters) -> MotorInverse:
    return MotorInverse(params.motor.torque_per_volt_nm_per_v, params.motor.backemf_at_beam_v_s_per_rad)


def _thesis_sf_continuous(params: Parameters) -> TrueStateLaw:
    return TrueStateLaw(
        "thesis-sf-continuous",
        StateFeedbackLaw(T.SF_CONT_K.copy()),
        u_kind="volts",
        period_s=FAST_PERIOD_S,
        description="§4.2 state feedback, K as printed, on the true state at 1 kHz (simulation only)",
    )


def _thesis_clp_continuous(params: Parameters) -> TrueStateLaw:
    law = ClpLaw(_THESIS_CLP_TERMS, T.CLP_CONT_KP.copy(), T.CLP_CONT_KV.copy())
    return TrueStateLaw(
        "thesis-clp-continuous",
        law,
        u_kind="torque",
        motor=_THESIS_MOTOR,
        period_s=FAST_PERIOD_S,
        description="§4.3 control law partitioning, kp/kv as printed, on the true state at 1 kHz (simulation only)",
    )


def _thesis_smc_continuous(params: Parameters) -> TrueStateLaw:
    law = SlidingModeLaw(T.SMC_S.copy(), T.SMC_KEQ.copy(), T.SMC_K_MINUS, T.SMC_K_PLUS, T.SMC_ETA)
    return TrueStateLaw(
        "thesis-smc-continuous",
        law,
        u_kind="torque",
        motor=_THESIS_MOTOR,
        period_s=FAST_PERIOD_S,
        description="§4.4 sliding mode, S̄/K_eq as printed, on the true state at 1 kHz (simulation only)",
    )


def _thesis_sf(params: Parameters) -> Controller:
    observer = ReducedObserver.from_gain(T.PHI_VOLTAGE, T.GAMMA_VOLTAGE, T.SF_OBS_G)
    return LoopController(
        "thesis-sf",
        ObserverState(observer),
        StateFeedbackLaw(T.SF_DISC_K.copy()),
        software=params.software,
        u_kind="volts",
        period_s=T.PERIOD_S,
        description="§5.2.1 state feedback + observer G as printed, 50 Hz",
    )


def _thesis_clp(params: Parameters) -> Controller:
    observer = ReducedObserver.from_gain(T.PHI_TORQUE, T.GAMMA_TORQUE, T.CLP_OBS_G)
    law = ClpLaw(_THESIS_CLP_TERMS, T.CLP_DISC_KP.copy(), T.CLP_DISC_KV.copy())
    return LoopController(
        "thesis-clp",
        ObserverState(observer),
        law,
        software=params.software,
        u_kind="torque",
        motor=_THESIS_MOTOR,
        observer_input="law",
        period_s=T.PERIOD_S,
        description="§5.2.2 control law partitioning + observer G as printed, 50 Hz",
    )


def _sf(params: Parameters) -> Controller:
    phi, gamma = ReferenceModel(params).discretize("voltage", params.daq.period_s)
    gain = state_feedback_gain(phi, gamma, T.SF_DISC_POLES)
    observer = reduced_order_observer(phi, gamma, T.SF_OBS_POLES_Z)
    return LoopController(
        "sf",
        ObserverState(observer),
        StateFeedbackLaw(gain),
        software=params.software,
        u_kind="volts",
        period_s=params.daq.period_s,
        description="§5.2.1 procedure re-run: poles 0.969±0.0504i, 0.861², observer "
        "0.835±0.199i, on the reference model",
    )


def _torque_model_observer(params: Parameters, poles) -> tuple[ReducedObserver, np.ndarray, np.ndarray]:
    ref = ReferenceModel(params)
    phi_v, gamma_v = ref.discretize("voltage", params.daq.period_s)
    return reduced_order_observer(phi_v, gamma_v, poles), *ref.discretize("torque", params.daq.period_s)


def _clp(params: Parameters) -> Controller:
    observer, phi_t, gamma_t = _torque_model_observer(params, T.CLP_OBS_POLES_Z)
    terms = ClpTerms.from_params(params)
    kp, kv = clp_gains(phi_t, gamma_t, terms.alpha(0.0), terms.beta_linear(), _CLP_POLES_Z)
    return LoopController(
        "clp",
        ObserverState(observer),
        ClpLaw(terms, kp, kv),
        software=params.software,
        u_kind="torque",
        motor=_motor(params),
        period_s=params.daq.period_s,
        description="§5.2.2 procedure re-run: four poles at z = 0.9608 (ω_n = 2, ζ = 1), "
        "observer poles 0.2, on the reference model",
    )


def _smc(params: Parameters) -> Controller:
    a, b = ReferenceModel(params).linearize("torque")
    design = sliding_surface(a, b, T.SMC_SLIDING_POLES)
    observer, _, _ = _torque_model_observer(params, T.CLP_OBS_POLES_Z)
    law = SlidingModeLaw(design.surface, design.equivalent_gain, T.SMC_K_MINUS, T.SMC_K_PLUS, T.SMC_ETA)
    return LoopController(
        "smc",
        ObserverState(observer),
        law,
        software=params.software,
        u_kind="torque",
        motor=_motor(params),
        period_s=params.daq.period_s,
        description="§4.4 procedure re-run: sliding poles −2, −2, −10, k± = ±0.5, "
        "η = 0.001, at 50 Hz with the observer of clp",
    )


# LQR weights (Bryson's rule): 10 cm of ball, 0.2 rad of beam, 0.5 m/s, 2 rad/s, against 12 V of motor.
# Tighter x/θ weights (5 cm, 0.1 rad) saturate the motor from (−0.2 m, 0.3 rad) and lose the ball.
LQR_STATE_SCALE = np.array([0.1, 0.2, 0.5, 2.0])
LQR_INPUT_SCALE_V = 12.0
# Kalman noise model: input disturbance 0.5 V; measurement: ball 2 mm (contact noise through the RC
# filter), beam one encoder count/√12 (uniform quantization: 1.0 mrad with the thesis's encoder).
KALMAN_INPUT_NOISE_V = 0.5
KALMAN_BALL_NOISE_M = 2e-3


def _lqr(params: Parameters) -> Controller:
    phi, gamma = ReferenceModel(params).discretize("voltage", params.daq.period_s)
    q = np.diag(1.0 / LQR_STATE_SCALE**2)
    r = np.array([[1.0 / LQR_INPUT_SCALE_V**2]])
    gain, _, _ = control.dlqr(phi, gamma, q, r)
    h = np.eye(2, 4)
    qn = np.array([[KALMAN_INPUT_NOISE_V**2]])
    angle_noise_rad = angle_count_step_rad(params) / np.sqrt(12)
    rn = np.diag([KALMAN_BALL_NOISE_M**2, angle_noise_rad**2])
    # Current-estimator gain: L = P⁻Hᵀ(HP⁻Hᵀ + R)⁻¹ with P⁻ the a-priori steady-state covariance.
    _, p_prior, _ = control.dlqe(phi, gamma, h, qn, rn)
    kalman = p_prior @ h.T @ np.linalg.inv(h @ p_prior @ h.T + rn)
    return LoopController(
        "lqr",
        KalmanState(phi, gamma, kalman),
        StateFeedbackLaw(np.atleast_2d(gain)),
        software=params.software,
        u_kind="volts",
        period_s=params.daq.period_s,
        description="discrete LQR (Bryson weights) + steady-state Kalman "
        "filter on the reference model, 50 Hz",
    )


_FACTORIES: dict[str, Callable[[Parameters], AnyController]] = {
    "thesis-sf-continuous": _thesis_sf_continuous,
    "thesis-clp-continuous": _thesis_clp_continuous,
    "thesis-smc-continuous": _thesis_smc_continuous,
    "thesis-sf": _thesis_sf,
    "thesis-clp": _thesis_clp,
    "appendix-sf": lambda params: AppendixStateFeedback(params.software),
    "appendix-clp": lambda params: AppendixControlLaw(params.software),
    "sf": _sf,
    "clp": _clp,
    "smc": _smc,
    "lqr": _lqr,
}
NAMES: tuple[str, ...] = tuple(_FACTORIES)


def make(name: str, params: Parameters | None = None) -> AnyController:
    """A fresh controller by name (designed now for ``params``, the rig the designs assume; it receives
    the rig software's calibration ``params.software``)."""
    try:
        factory = _FACTORIES[name]
    except KeyError:
        raise UnknownControllerError(name) from None
    return factory(params or Parameters())


def make_batch(
    name: str, params: Parameters | Sequence[Parameters] | None = None, n: int | None = None
) -> BatchController | None:
    """The controller ``name`` for a batch of runs in numpy (``twin.batch.BatchController``), each run's
    commands those of ``make(name, params_i)`` bit for bit; None when ``name`` has no batched version (the
    batch engine then runs one scalar instance per run). ``params``: one set for all ``n`` runs or one per
    run (each distinct set designs its own controller)."""
    if params is None or isinstance(params, Parameters):
        if n is None:
            raise ValueError("make_batch: give n with a single parameter set")
        run_params = [params or Parameters()] * n
    else:
        run_params = list(params)
    if not run_params:
        return None
    designed: dict[Parameters, AnyController] = {}
    for p in run_params:
        if p not in designed:
            designed[p] = make(name, p)
    return batched([designed[p] for p in run_params])


@functools.cache
def simulation_only(name: str) -> bool:
    """Whether ``name`` is a law on the true state (chapter 4): it cannot drive the hardware."""
    return isinstance(make(name), TrueStateLaw)


def describe(name: str) -> str:
    """One line saying what the controller is."""
    controller = make(name)
    return str(getattr(controller, "description", "") or "appendix A: the code that ran on the rig")
