"""The controller catalogue as data: one entry per named controller (``twin.engine.CatalogueEntry``).

The application layer hands this module to the CLI and the live view (``twin.engine.Catalogue``: ``NAMES``,
``ENTRIES``, ``make``; also ``make_batch``, ``simulation_only``, ``describe``).

    thesis-*-continuous  chapter 4 designs, numbers as printed, on the true state at 1 kHz (simulation-only
                         ``TrueStateLaw``s: they are not hardware controllers)
    thesis-sf, -clp      chapter 5 designs with their reduced-order observers, numbers as printed, 50 Hz
    appendix-sf, -clp    the appendix A callbacks that ran on the rig, ported exactly
    sf, clp, smc         the thesis's design procedures re-run correctly on the reference model, 50 Hz
    lqr                  LQR with a steady-state Kalman filter on the same model, 50 Hz
    lqi                  the same with integral action on the ball position: it reaches a moved setpoint
    rig-lqg              LQR and a Kalman filter from the rig's own linearization, for any rig its parts
                         describe (``controllers.rig_lqg``), in the board's units

"as printed" means a failing printed design fails here too; it is reported, never quietly corrected.

A new controller is its law or design (``controllers.design``, ``controllers.laws``) and one row of
``_TABLE``: a builder, its description and its flags (tests/test_catalogue.py checks the flags against the
built objects). Importing this module is cheap (``ballbeam --help`` lists ``NAMES``): python-control,
MuJoCo and the designs are imported by the builders, and ``ENTRIES`` is built when first read (it computes
``lqr``'s steady error from its design).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    import numpy as np

    from controllers.design import LqrDesign, Poles, ReducedObserver
    from controllers.laws import ClpTerms
    from controllers.loop import MotorInverse, TrueStateLaw
    from twin.engine import CatalogueEntry
    from twin.interface import Controller
    from twin.parameters import Parameters
    from twin.rigs.batch import BatchController

    AnyController = Controller | TrueStateLaw

__all__ = [
    "ENTRIES",
    "NAMES",
    "UnknownControllerError",
    "describe",
    "make",
    "make_batch",
    "simulation_only",
]

FAST_PERIOD_S = 0.001  # chapter 4 designs run "continuously": every physics step


class UnknownControllerError(KeyError):
    def __str__(self) -> str:
        return f"unknown controller {self.args[0]!r}; known: {', '.join(NAMES)}"


def _thesis_motor() -> MotorInverse:
    """Chapter 4's "torque" block (eq 3.3.2 as printed) converts between volts and torque for its designs."""
    from controllers import thesis_numbers as T
    from controllers.loop import MotorInverse

    return MotorInverse(T.MOTOR_TORQUE_PER_VOLT, T.MOTOR_BACKEMF_AT_BEAM)


def _motor(params: Parameters) -> MotorInverse:
    from controllers.loop import MotorInverse

    return MotorInverse(params.motor.torque_per_volt_nm_per_v, params.motor.backemf_at_beam_v_s_per_rad)


def _thesis_clp_terms() -> ClpTerms:
    from controllers import thesis_numbers as T
    from controllers.laws import ClpTerms

    return ClpTerms(T.CLP_ALPHA_XDD, T.CLP_ALPHA_THDD, T.CLP_ALPHA_THDD_X2, T.CLP_BETA)


def _thesis_sf_continuous(params: Parameters) -> TrueStateLaw:
    from controllers import thesis_numbers as T
    from controllers.laws import StateFeedbackLaw
    from controllers.loop import SetpointTrueStateLaw

    law = StateFeedbackLaw(T.SF_CONT_K.copy())
    return SetpointTrueStateLaw("thesis-sf-continuous", law, u_kind="volts", period_s=FAST_PERIOD_S)


def _thesis_clp_continuous(params: Parameters) -> TrueStateLaw:
    from controllers import thesis_numbers as T
    from controllers.laws import ClpLaw
    from controllers.loop import SetpointTrueStateLaw

    law = ClpLaw(_thesis_clp_terms(), T.CLP_CONT_KP.copy(), T.CLP_CONT_KV.copy())
    return SetpointTrueStateLaw(
        "thesis-clp-continuous", law, u_kind="torque", motor=_thesis_motor(), period_s=FAST_PERIOD_S
    )


def _thesis_smc_continuous(params: Parameters) -> TrueStateLaw:
    from controllers import thesis_numbers as T
    from controllers.laws import SlidingModeLaw
    from controllers.loop import TrueStateLaw

    law = SlidingModeLaw(T.SMC_S.copy(), T.SMC_KEQ.copy(), T.SMC_K_MINUS, T.SMC_K_PLUS, T.SMC_ETA)
    return TrueStateLaw(
        "thesis-smc-continuous", law, u_kind="torque", motor=_thesis_motor(), period_s=FAST_PERIOD_S
    )


def _thesis_sf(params: Parameters) -> Controller:
    from controllers import thesis_numbers as T
    from controllers.design import ReducedObserver
    from controllers.laws import StateFeedbackLaw
    from controllers.loop import ObserverState, SetpointLoopController

    observer = ReducedObserver.from_gain(T.PHI_VOLTAGE, T.GAMMA_VOLTAGE, T.SF_OBS_G)
    return SetpointLoopController(
        "thesis-sf",
        ObserverState(observer),
        StateFeedbackLaw(T.SF_DISC_K.copy()),
        software=params.software,
        u_kind="volts",
        period_s=T.PERIOD_S,
    )


def _thesis_clp(params: Parameters) -> Controller:
    from controllers import thesis_numbers as T
    from controllers.design import ReducedObserver
    from controllers.laws import ClpLaw
    from controllers.loop import ObserverState, SetpointLoopController

    observer = ReducedObserver.from_gain(T.PHI_TORQUE, T.GAMMA_TORQUE, T.CLP_OBS_G)
    law = ClpLaw(_thesis_clp_terms(), T.CLP_DISC_KP.copy(), T.CLP_DISC_KV.copy())
    return SetpointLoopController(
        "thesis-clp",
        ObserverState(observer),
        law,
        software=params.software,
        u_kind="torque",
        motor=_thesis_motor(),
        observer_input="law",
        period_s=T.PERIOD_S,
    )


def _appendix_sf(params: Parameters) -> Controller:
    from controllers.appendix import AppendixStateFeedback

    return AppendixStateFeedback(params.software)


def _appendix_clp(params: Parameters) -> Controller:
    from controllers.appendix import AppendixControlLaw

    return AppendixControlLaw(params.software)


def _discrete(params: Parameters, u_kind: Literal["voltage", "torque"]) -> tuple[np.ndarray, np.ndarray]:
    from twin.reference import ReferenceModel

    return ReferenceModel(params).discretize(u_kind, params.period_s)


def _sf(params: Parameters) -> Controller:
    from controllers import thesis_numbers as T
    from controllers.design import reduced_order_observer, state_feedback_gain
    from controllers.laws import StateFeedbackLaw
    from controllers.loop import ObserverState, SetpointLoopController

    phi, gamma = _discrete(params, "voltage")
    gain = state_feedback_gain(phi, gamma, T.SF_DISC_POLES)
    observer = reduced_order_observer(phi, gamma, T.SF_OBS_POLES_Z)
    return SetpointLoopController(
        "sf",
        ObserverState(observer),
        StateFeedbackLaw(gain),
        software=params.software,
        u_kind="volts",
        period_s=params.period_s,
    )


def _torque_model_observer(
    params: Parameters, poles: Poles
) -> tuple[ReducedObserver, np.ndarray, np.ndarray]:
    from controllers.design import reduced_order_observer

    phi_v, gamma_v = _discrete(params, "voltage")
    return reduced_order_observer(phi_v, gamma_v, poles), *_discrete(params, "torque")


def _clp(params: Parameters) -> Controller:
    from controllers import thesis_numbers as T
    from controllers.design import clp_gains
    from controllers.laws import ClpLaw, ClpTerms
    from controllers.loop import ObserverState, SetpointLoopController

    observer, phi_t, gamma_t = _torque_model_observer(params, T.CLP_OBS_POLES_Z)
    terms = ClpTerms.from_params(params)
    # ω_n = 2, ζ = 1 for both x and θ: four poles at z = e^{−2T}
    kp, kv = clp_gains(phi_t, gamma_t, terms.alpha(0.0), terms.beta_linear(), [T.CLP_DISC_POLES[0]] * 4)
    return SetpointLoopController(
        "clp",
        ObserverState(observer),
        ClpLaw(terms, kp, kv),
        software=params.software,
        u_kind="torque",
        motor=_motor(params),
        period_s=params.period_s,
    )


def _smc(params: Parameters) -> Controller:
    from controllers import thesis_numbers as T
    from controllers.design import sliding_surface
    from controllers.laws import SlidingModeLaw
    from controllers.loop import LoopController, ObserverState
    from twin.reference import ReferenceModel

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
        period_s=params.period_s,
    )


# LQR weights (Bryson's rule): 10 cm of ball, 0.2 rad of beam, 0.5 m/s, 2 rad/s, against 12 V of motor.
# Tighter x/θ weights (5 cm, 0.1 rad) saturate the motor from (−0.2 m, 0.3 rad) and lose the ball.
LQR_STATE_SCALE = (0.1, 0.2, 0.5, 2.0)  # (a tuple: importing the registry does not load numpy)
LQR_INPUT_SCALE_V = 12.0
# LQI: the integral of the ball's error weighted as 1 cm held for 10 s (0.1 m·s), against the same 12 V.
# A heavier weight stiffens the state gains too: at 0.05 m·s (0.02 m·s) the motor saturates from one (two)
# of the six thesis starts and the ball is lost, (−0.2 m, 0.3 rad) first; at 0.1 m·s all six are held.
LQI_INTEGRAL_SCALE_M_S = 0.1
# Kalman noise model: input disturbance 0.5 V; measurement: ball 2 mm (contact noise through the RC
# filter), beam one encoder count/√12 (uniform quantization: 1.0 mrad with the thesis's encoder).
KALMAN_INPUT_NOISE_V = 0.5
KALMAN_BALL_NOISE_M = 2e-3
# The setpoint at which lqr's steady error is stated (the experiments' ±0.10 m square wave).
SETPOINT_PROBE_M = 0.10


def _measurement_noise(params: Parameters) -> tuple[float, float]:
    import numpy as np

    from twin.sensors import angle_count_step_rad

    return KALMAN_BALL_NOISE_M, angle_count_step_rad(params) / np.sqrt(12)


def _lqr_design(params: Parameters, phi: np.ndarray, gamma: np.ndarray) -> LqrDesign:
    from controllers.design import lqr_design

    return lqr_design(
        phi,
        gamma,
        state_scale=LQR_STATE_SCALE,
        input_scale_v=LQR_INPUT_SCALE_V,
        input_noise_v=KALMAN_INPUT_NOISE_V,
        measurement_noise=_measurement_noise(params),
    )


def _lqr(params: Parameters) -> Controller:
    from controllers.laws import KalmanState, StateFeedbackLaw
    from controllers.loop import SetpointLoopController

    phi, gamma = _discrete(params, "voltage")
    design = _lqr_design(params, phi, gamma)
    return SetpointLoopController(
        "lqr",
        KalmanState(phi, gamma, design.kalman_gain),
        StateFeedbackLaw(design.gain),
        software=params.software,
        u_kind="volts",
        period_s=params.period_s,
    )


def _lqi(params: Parameters) -> Controller:
    from controllers.design import lqi_design
    from controllers.laws import IntegralStateFeedbackLaw, KalmanState
    from controllers.loop import SetpointLoopController
    from twin.converters import motor_volts_from_command

    phi, gamma = _discrete(params, "voltage")
    design = lqi_design(
        phi,
        gamma,
        params.period_s,
        state_scale=LQR_STATE_SCALE,
        integral_scale_m_s=LQI_INTEGRAL_SCALE_M_S,
        input_scale_v=LQR_INPUT_SCALE_V,
        input_noise_v=KALMAN_INPUT_NOISE_V,
        measurement_noise=_measurement_noise(params),
    )
    sw = params.software
    law = IntegralStateFeedbackLaw(
        design.gain,
        design.integral_gain,
        design.period_s,
        u_min_v=motor_volts_from_command(sw.command_low_v, sw),
        u_max_v=motor_volts_from_command(sw.command_high_v, sw),
    )
    return SetpointLoopController(
        "lqi",
        KalmanState(phi, gamma, design.kalman_gain),
        law,
        software=sw,
        u_kind="volts",
        period_s=params.period_s,
    )


def lqr_steady_error_m(setpoint_m: float, params: Parameters | None = None) -> float:
    """How far from a setpoint ``setpoint_m`` the linear model says ``lqr`` settles (m; + beyond it): its
    state feedback has no integral action, so the motor torque that holds the ball's weight off centre
    comes from a steady error."""
    import numpy as np

    from controllers.design import steady_state
    from twin.parameters import Parameters

    p = params or Parameters()
    phi, gamma = _discrete(p, "voltage")
    x = steady_state(phi, gamma, _lqr_design(p, phi, gamma).gain, np.array([setpoint_m, 0.0, 0.0, 0.0]))
    return float(x[0]) - setpoint_m


def _lqr_description() -> str:
    error_m = lqr_steady_error_m(SETPOINT_PROBE_M)
    return (
        "discrete LQR (Bryson weights) + steady-state Kalman filter on the reference model; no integral "
        f"action: a moved setpoint settles off it by {error_m / SETPOINT_PROBE_M:+.0%} of the move "
        f"({error_m * 1e3:+.1f} mm at {SETPOINT_PROBE_M:+.2f} m, the linear model's steady state)"
    )


def _rig_lqg(params: Parameters) -> Controller:
    from controllers.rig_lqg import rig_lqg

    return rig_lqg(params)


@dataclass(frozen=True)
class _Row:
    """An entry as written here (``CatalogueEntry`` lives with the engine, which imports MuJoCo)."""

    name: str
    build: Callable[[Parameters], AnyController]
    description: str | Callable[[], str]  # a callable computes a figure of the design when ENTRIES is built
    simulation_only: bool = False
    batched: bool = False
    setpoint: bool = False


_TABLE: tuple[_Row, ...] = (
    _Row(
        "thesis-sf-continuous",
        _thesis_sf_continuous,
        "§4.2 state feedback, K as printed, on the true state at 1 kHz (simulation only)",
        simulation_only=True,
        setpoint=True,
    ),
    _Row(
        "thesis-clp-continuous",
        _thesis_clp_continuous,
        "§4.3 control law partitioning, kp/kv as printed, on the true state at 1 kHz (simulation only)",
        simulation_only=True,
        setpoint=True,
    ),
    _Row(
        "thesis-smc-continuous",
        _thesis_smc_continuous,
        "§4.4 sliding mode, S̄/K_eq as printed, on the true state at 1 kHz (simulation only)",
        simulation_only=True,
    ),
    _Row(
        "thesis-sf",
        _thesis_sf,
        "§5.2.1 state feedback + observer G as printed, 50 Hz",
        batched=True,
        setpoint=True,
    ),
    _Row(
        "thesis-clp",
        _thesis_clp,
        "§5.2.2 control law partitioning + observer G as printed, 50 Hz",
        batched=True,
        setpoint=True,
    ),
    _Row(
        "appendix-sf",
        _appendix_sf,
        "appendix A's d_cb_state_feedback: the code that ran on the rig",
        batched=True,
    ),
    _Row(
        "appendix-clp",
        _appendix_clp,
        "appendix A's d_cb_control_law: the code that ran on the rig",
        batched=True,
    ),
    _Row(
        "sf",
        _sf,
        "§5.2.1 procedure re-run: poles 0.969±0.0504i, 0.861², observer 0.835±0.199i, on the reference model",
        batched=True,
        setpoint=True,
    ),
    _Row(
        "clp",
        _clp,
        "§5.2.2 procedure re-run: four poles at z = 0.9608 (ω_n = 2, ζ = 1), observer poles 0.2, on the "
        "reference model",
        batched=True,
        setpoint=True,
    ),
    _Row(
        "smc",
        _smc,
        "§4.4 procedure re-run: sliding poles −2, −2, −10, k± = ±0.5, η = 0.001, at 50 Hz with the observer "
        "of clp",
        batched=True,
    ),
    _Row("lqr", _lqr, _lqr_description, batched=True, setpoint=True),
    _Row(
        "lqi",
        _lqi,
        "LQR with integral action on the ball position (and lqr's Kalman filter), anti-windup at the "
        "command limits: reaches a moved setpoint; a setpoint step acts at once (no shaping), and a large one "
        "can throw the ball (docs/design.md)",
        setpoint=True,
    ),
    _Row(
        "rig-lqg",
        _rig_lqg,
        "LQR and a Kalman filter designed from the rig's own linearization (any rig --rig-file describes: "
        "it reads and writes the board's units through the parts' conversions)",
    ),
)
_ROWS: dict[str, _Row] = {row.name: row for row in _TABLE}
NAMES: tuple[str, ...] = tuple(_ROWS)

ENTRIES: Mapping[str, CatalogueEntry]  # built when first read (module __getattr__ below)


_entries_built: dict[str, CatalogueEntry] = {}


def _entries() -> dict[str, CatalogueEntry]:
    """``ENTRIES``, built once."""
    if not _entries_built:
        _entries_built.update(_build_entries())
    return _entries_built


def _build_entries() -> dict[str, CatalogueEntry]:
    from twin.engine import CatalogueEntry

    return {
        row.name: CatalogueEntry(
            name=row.name,
            build=row.build,
            description=row.description if isinstance(row.description, str) else row.description(),
            simulation_only=row.simulation_only,
            batched=row.batched,
            setpoint=row.setpoint,
        )
        for row in _TABLE
    }


def __getattr__(name: str) -> object:
    if name == "ENTRIES":
        return _entries()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _row(name: str) -> _Row:
    try:
        return _ROWS[name]
    except KeyError:
        raise UnknownControllerError(name) from None


def make(name: str, params: Parameters | None = None) -> AnyController:
    """A fresh controller by name (designed now for ``params``, the rig the designs assume; it receives
    the rig software's calibration ``params.software``)."""
    from twin.parameters import Parameters

    return _row(name).build(params or Parameters())


def make_batch(
    name: str, params: Parameters | Sequence[Parameters] | None = None, n: int | None = None
) -> BatchController | None:
    """The controller ``name`` for a batch of runs in numpy (``twin.rigs.batch.BatchController``), each run's
    commands those of ``make(name, params_i)`` bit for bit; None when ``name`` has no batched version (the
    batch engine then runs one scalar instance per run). ``params``: one set for all ``n`` runs or one per
    run (each distinct set designs its own controller)."""
    from controllers.batch import batched
    from twin.parameters import Parameters

    if params is None or isinstance(params, Parameters):
        if n is None:
            raise ValueError("make_batch: give n with a single parameter set")
        run_params = [params or Parameters()] * n
    else:
        run_params = list(params)
    if not run_params or not _row(name).batched:
        return None
    designed: dict[Parameters, AnyController] = {}
    for p in run_params:
        if p not in designed:
            designed[p] = make(name, p)
    return batched([designed[p] for p in run_params])


def simulation_only(name: str) -> bool:
    """Whether ``name`` is a law on the true state (chapter 4): it cannot drive the hardware."""
    return _row(name).simulation_only


def describe(name: str) -> str:
    """One line saying what the controller is."""
    _row(name)
    return _entries()[name].description
