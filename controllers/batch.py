"""The named controllers over a batch of runs (``twin.rigs.batch.BatchController``): numpy over a leading batch
axis, each line the scalar controller's line with the same operations in the same order, so each run gets
the bits its scalar controller computes alone (tests/test_batch.py checks every log array).

What keeps the bits:

* elementwise +, −, ×, /, np.sin, np.cos and np.clip give what Python's float operations and ``math`` give;
* Python's ``x**2`` is libm's pow, which differs from x·x in the last bit for about 1 value in 1000:
  ``np.float_power(x, 2)`` calls the same pow (numpy's ``x**2`` squares);
* a matrix times a vector is ``twin.fixedorder``'s: ``matvec`` on floats alone, ``matvecs`` over the batch
  (the same products added left to right: no BLAS, whose kernel would choose the order).

``appendix-sf``, ``appendix-clp`` and the ``LoopController``s on a reduced-order observer or a Kalman filter
with a state-feedback law in volts (``lqr``, ``sf``, ``thesis-sf``) or a control-law-partitioning or
sliding-mode law in N·m (``clp``, ``thesis-clp``, ``smc``) are batched; ``make_batch`` returns None for the
others (``lqi``'s integrator, a user's controller), which the batch engine runs one scalar instance per run.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from controllers.appendix import (
    AppendixControlLaw,
    AppendixStateFeedback,
    control_law_step,
    state_feedback_step,
)
from controllers.laws import ClpLaw, KalmanState, SlidingModeLaw, StateFeedbackLaw
from controllers.loop import LoopController, ObserverState
from twin import fixedorder as fo
from twin.converters import (
    ball_position_m,
    beam_angle_rad,
    clip_command_v,
    dac_command_v,
    motor_volts_from_command,
)
from twin.dcmotor import volts_for_torque_v
from twin.interface import Controller
from twin.parameters import SoftwareCalibration
from twin.rigs.batch import BatchSamples, BatchTelemetry

__all__ = ["BatchAppendixControlLaw", "BatchAppendixStateFeedback", "BatchLoopController", "batched"]


def _mv(matrix: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """``fo.matvec(matrix, v)`` for each row v of ``vectors`` (n, c); ``matrix`` (r, c) for all or (n, r, c)
    per run."""
    return fo.matvecs(matrix, vectors)


def _measure(samples: BatchSamples, sw: SoftwareCalibration) -> tuple[np.ndarray, np.ndarray]:
    return ball_position_m(samples.ball_v, sw), beam_angle_rad(samples.angle_v, sw)


class _AppendixBatch:
    """``controllers.appendix._AppendixCallback`` over the batch: the MATLAB values at k − 1 as arrays."""

    period_s = Controller.period_s

    def __init__(self, name: str, software: SoftwareCalibration) -> None:
        self.name = name
        self.software = software
        self.telemetry = BatchTelemetry(np.empty((0, 4)), np.empty(0), np.empty(0))
        self.prev: tuple[np.ndarray, ...] = ()

    def start(self, samples: BatchSamples) -> None:
        x1, x2 = _measure(samples, self.software)
        zero = np.zeros_like(x1)
        self.prev = (x1, x2, zero, zero, zero)
        self.telemetry = BatchTelemetry(np.stack([x1, x2, zero, zero], axis=1), zero, zero)

    def keep(self, runs: np.ndarray) -> None:
        self.prev = tuple(a[runs] for a in self.prev)

    def _command(self, value_v: np.ndarray) -> np.ndarray:
        return clip_command_v(dac_command_v(value_v, self.software), self.software)


class BatchAppendixStateFeedback(_AppendixBatch):
    """``AppendixStateFeedback.update`` over the batch (the same ``state_feedback_step``)."""

    def __init__(self, software: SoftwareCalibration) -> None:
        super().__init__(AppendixStateFeedback.name, software)

    def update(self, samples: BatchSamples) -> np.ndarray:
        x1_k, x2_k = _measure(samples, self.software)
        x3_k, x4_k, u_temp = state_feedback_step(self.prev, x1_k, x2_k)
        adat = self._command(u_temp)
        u_k = motor_volts_from_command(adat, self.software)
        self.prev = (x1_k, x2_k, x3_k, x4_k, u_k)
        self.telemetry = BatchTelemetry(np.stack([x1_k, x2_k, x3_k, x4_k], axis=1), u_k, u_temp)
        return adat


class BatchAppendixControlLaw(_AppendixBatch):
    """``AppendixControlLaw.update`` over the batch (the same ``control_law_step``)."""

    def __init__(self, software: SoftwareCalibration) -> None:
        super().__init__(AppendixControlLaw.name, software)

    def update(self, samples: BatchSamples) -> np.ndarray:
        x1_k, x2_k = _measure(samples, self.software)
        x3_k, x4_k, t, v_temp = control_law_step(self.prev, x1_k, x2_k, np.sin, np.cos, np.float_power)
        adat = self._command(v_temp)
        self.prev = (x1_k, x2_k, x3_k, x4_k, t)
        self.telemetry = BatchTelemetry(np.stack([x1_k, x2_k, x3_k, x4_k], axis=1), t, v_temp)
        return adat


class _PerRun:
    """Arrays a batch holds once when every run shares them (as the scalar controllers hold them) or stacked
    on a leading axis, one entry per run; ``keep`` selects the runs that go on."""

    def __init__(self) -> None:
        self._per_run: list[str] = []

    def _matrix(self, name: str, arrays: Sequence[np.ndarray | float]) -> None:
        values = [np.asarray(a, dtype=float) for a in arrays]
        first = values[0]
        if all(np.array_equal(a, first) for a in values):
            setattr(self, name, first)
        else:
            setattr(self, name, np.stack(values))
            self._per_run.append(name)

    def keep(self, runs: np.ndarray) -> None:
        for name in self._per_run:
            setattr(self, name, getattr(self, name)[runs])


class _BatchStateFeedback(_PerRun):
    """``StateFeedbackLaw.of_floats`` over the batch: u = −K·(x − x_ref)."""

    gain: np.ndarray
    ref: np.ndarray

    def __init__(self, laws: Sequence[StateFeedbackLaw]) -> None:
        super().__init__()
        self._matrix("gain", [law.gain for law in laws])
        self._matrix("ref", [np.array([law.ref_x_m, 0.0, 0.0, 0.0]) for law in laws])

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return -(_mv(self.gain, x - self.ref)[:, 0])


class _BatchClp(_PerRun):
    """``ClpLaw.of_floats`` over the batch: τ = α·τ̄ + β, each sum and product in the scalar law's order."""

    kp: np.ndarray
    kv: np.ndarray
    ref: np.ndarray
    alpha_xdd: np.ndarray
    alpha_thdd: np.ndarray
    alpha_thdd_x2: np.ndarray
    beta: np.ndarray
    beta_thetadot: np.ndarray

    def __init__(self, laws: Sequence[ClpLaw]) -> None:
        super().__init__()
        self._matrix("kp", [law.kp for law in laws])
        self._matrix("kv", [law.kv for law in laws])
        self._matrix("ref", [law.ref_x_m for law in laws])
        for name in ("alpha_xdd", "alpha_thdd", "alpha_thdd_x2", "beta_thetadot"):
            self._matrix(name, [getattr(law.terms, name) for law in laws])
        self._matrix("beta", [np.array(law.terms.beta) for law in laws])

    def __call__(self, x: np.ndarray) -> np.ndarray:
        xm, th, xd, thd = x[:, 0], x[:, 1], x[:, 2], x[:, 3]
        tau_bar = _mv(self.kp, np.stack([-(xm - self.ref), -th], axis=1)) - _mv(self.kv, x[:, 2:])
        with np.errstate(over="ignore"):  # x², θ̇² overflow to inf, as ClpTerms takes them
            x2, thd2 = np.float_power(xm, 2), np.float_power(thd, 2)
        alpha_theta = self.alpha_thdd + self.alpha_thdd_x2 * x2
        b1, b2, b3, b4 = (self.beta[..., i] for i in range(4))
        beta = (
            b1 * np.sin(th)
            + b2 * xm * np.cos(th)
            + b3 * xm * xd * thd
            + b4 * xm * thd2
            + self.beta_thetadot * thd
        )
        return (self.alpha_xdd * tau_bar[:, 0] + alpha_theta * tau_bar[:, 1]) + beta


class _BatchSlidingMode(_PerRun):
    """``SlidingModeLaw.of_floats`` over the batch: u = −K_eq·x + Σ kᵢxᵢ − η·sgn(s)."""

    surface: np.ndarray
    equivalent_gain: np.ndarray
    k_minus: np.ndarray
    k_plus: np.ndarray
    eta: np.ndarray

    def __init__(self, laws: Sequence[SlidingModeLaw]) -> None:
        super().__init__()
        self._matrix("surface", [np.asarray(law.surface, dtype=float)[0] for law in laws])
        self._matrix("equivalent_gain", [np.asarray(law.equivalent_gain, dtype=float)[0] for law in laws])
        for name in ("k_minus", "k_plus", "eta"):
            self._matrix(name, [getattr(law, name) for law in laws])

    def __call__(self, x: np.ndarray) -> np.ndarray:
        s = fo.dots(x, self.surface)  # S̄·x (IEEE products commute: x·S̄ has the bits of S̄·x)
        k = np.where(s[:, None] * x > 0, self.k_minus[..., None], self.k_plus[..., None])
        equivalent = fo.dots(x, self.equivalent_gain)
        # The scalar law's sign: 0.0 for ±0, NaN for NaN.
        sign = np.where(s > 0, 1.0, np.where(s < 0, -1.0, np.where(s != s, s, 0.0)))
        return -equivalent + fo.dots(k, x) - self.eta * sign


_BatchLaw = _BatchStateFeedback | _BatchClp | _BatchSlidingMode
_BATCH_LAWS: tuple[tuple[type, type[_BatchLaw], str], ...] = (
    (StateFeedbackLaw, _BatchStateFeedback, "volts"),
    (ClpLaw, _BatchClp, "torque"),
    (SlidingModeLaw, _BatchSlidingMode, "torque"),
)


def _batch_law(laws: Sequence[object], u_kind: str) -> _BatchLaw | None:
    for law_type, batch_type, kind in _BATCH_LAWS:
        if kind == u_kind and all(type(law) is law_type for law in laws):
            return batch_type(laws)  # type: ignore[arg-type]
    return None


class BatchLoopController(_PerRun):
    """``LoopController`` on an ``ObserverState`` or a ``KalmanState`` with a state-feedback law in volts or
    a control-law-partitioning or sliding-mode law in N·m (turned into volts by the design's motor inverse),
    over the batch (each run may have its own design: the arrays are then stacked per run)."""

    # The design's arrays: shared (as the scalar controller holds them) or stacked per run.
    phi: np.ndarray
    gamma0: np.ndarray
    k_gain: np.ndarray
    h: np.ndarray
    f: np.ndarray
    ga: np.ndarray
    o_gain: np.ndarray
    h0: np.ndarray
    torque_per_volt: np.ndarray
    backemf_at_beam: np.ndarray

    def __init__(self, controllers: Sequence[LoopController]) -> None:
        super().__init__()
        c0 = controllers[0]
        self.name = c0.name
        self.period_s = c0.period_s
        self.software = c0.software
        self.command_limits = c0.command_limits
        self.u_kind = c0.u_kind
        self.feed_applied = c0.observer_input == "applied_volts"
        law = _batch_law([c.law for c in controllers], c0.u_kind)
        if law is None or any(
            c.u_kind != c0.u_kind or c.observer_input != c0.observer_input for c in controllers
        ):
            raise TypeError(f"{self.name}: BatchLoopController takes one kind of batched law")
        self.law = law
        if self.u_kind == "torque":
            motors = [c.motor for c in controllers]
            self._matrix("torque_per_volt", [m.torque_per_volt for m in motors if m is not None])
            self._matrix("backemf_at_beam", [m.backemf_at_beam for m in motors if m is not None])
        states = [c.state for c in controllers]
        self.kalman = isinstance(states[0], KalmanState)
        if self.kalman:
            ks = [s for s in states if isinstance(s, KalmanState)]
            self._matrix("phi", [s.phi for s in ks])
            self._matrix("gamma0", [s.gamma[:, 0] for s in ks])
            self._matrix("k_gain", [s.gain for s in ks])
            self._matrix("h", [s.h for s in ks])
        else:
            obs = [s.observer for s in states if isinstance(s, ObserverState)]
            self._matrix("f", [o.f for o in obs])
            self._matrix("ga", [o.ga for o in obs])
            self._matrix("o_gain", [o.gain for o in obs])
            self._matrix("h0", [o.h[:, 0] for o in obs])
        self.telemetry = BatchTelemetry(np.empty((0, 4)), np.empty(0), np.empty(0))

    @staticmethod
    def supports(controller: object) -> bool:
        if not isinstance(controller, LoopController) or not isinstance(
            controller.state, KalmanState | ObserverState
        ):
            return False
        if controller.u_kind == "torque" and controller.motor is None:
            return False
        return any(
            type(controller.law) is law_type and controller.u_kind == kind
            for law_type, _, kind in _BATCH_LAWS
        )

    def _xa(self, samples: BatchSamples) -> np.ndarray:
        x, theta = _measure(samples, self.software)
        return np.stack([x, theta], axis=1)

    def start(self, samples: BatchSamples) -> None:
        xa = self._xa(samples)
        zeros = np.zeros_like(xa)
        self._x = np.concatenate([xa, zeros], axis=1)  # Kalman: the estimate; observer: (xa, xb)
        self._u_prev = np.zeros(len(xa))
        self.telemetry = BatchTelemetry(self._x.copy(), self._u_prev.copy(), self._u_prev.copy())

    def keep(self, runs: np.ndarray) -> None:
        self._x, self._u_prev = self._x[runs], self._u_prev[runs]
        super().keep(runs)
        self.law.keep(runs)

    def update(self, samples: BatchSamples) -> np.ndarray:
        sw = self.software
        xa = self._xa(samples)
        u_prev = self._u_prev[:, None]
        if self.kalman:  # KalmanState.update
            predicted = _mv(self.phi, self._x) + self.gamma0 * u_prev
            x = predicted + _mv(self.k_gain, xa - _mv(self.h, predicted))
        else:  # ObserverState.update
            xa_prev, xb = self._x[:, :2], self._x[:, 2:]
            xb = _mv(self.f, xb) + _mv(self.ga, xa_prev) + _mv(self.o_gain, xa) + self.h0 * u_prev
            x = np.concatenate([xa, xb], axis=1)
        self._x = x
        u = self.law(x)
        if not np.isfinite(u).all():  # LoopController's _volts
            j = int(np.flatnonzero(~np.isfinite(u))[0])
            raise FloatingPointError(
                f"{self.name}: control law returned {float(u[j])!r} for state {x[j].tolist()}"
            )
        torque = self.u_kind == "torque"
        volts = (
            np.asarray(volts_for_torque_v(u, x[:, 3], self.torque_per_volt, self.backemf_at_beam))
            if torque
            else u
        )
        command = dac_command_v(volts, sw)
        if self.command_limits:
            command = clip_command_v(command, sw)
        applied = motor_volts_from_command(command, sw)
        self._u_prev = applied if self.feed_applied else u
        self.telemetry = BatchTelemetry(x.copy(), u if torque else applied, u)
        return command


def batched(
    controllers: Sequence[object],
) -> BatchAppendixStateFeedback | BatchAppendixControlLaw | BatchLoopController | None:
    """The batched version of these controllers (one per run, all of one kind and software calibration),
    or None when there is none."""
    c0 = controllers[0]
    if not all(type(c) is type(c0) for c in controllers):
        return None
    if isinstance(c0, AppendixStateFeedback | AppendixControlLaw):
        software = c0.software
        if not all(c.software == software for c in controllers):  # type: ignore[attr-defined]
            return None
        if isinstance(c0, AppendixStateFeedback):
            return BatchAppendixStateFeedback(software)
        return BatchAppendixControlLaw(software)
    if all(BatchLoopController.supports(c) for c in controllers):
        loops = [c for c in controllers if isinstance(c, LoopController)]
        if all(c.software == loops[0].software for c in loops):
            return BatchLoopController(loops)
    return None
