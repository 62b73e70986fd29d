"""The 1 kHz path of the laws on the true state: the state handed on as Python floats, the laws' ``of_floats``
in Python. The same bits as the laws' formulas with every sum of products written out left to right (no
BLAS, whose kernel would choose the order: twin.fixedorder), the same errors."""

import copy
import math
import pickle

import numpy as np
import pytest

from controllers import registry
from controllers import thesis_numbers as T
from controllers.laws import ClpLaw, ClpTerms, SlidingModeLaw, StateFeedbackLaw
from controllers.loop import MotorInverse, TrueStateLaw
from twin.engine import ControllerError
from twin.interface import Telemetry
from twin.rigs.sim import TwinRig, run_closed_loop

TERMS = ClpTerms(T.CLP_ALPHA_XDD, T.CLP_ALPHA_THDD, T.CLP_ALPHA_THDD_X2, T.CLP_BETA)


def _ltr(a, b) -> np.float64:
    """a·b with numpy float64 scalars, products rounded and added left to right (written out here, not
    twin.fixedorder's, so the laws' order is checked, not assumed)."""
    acc = np.float64(a[0]) * np.float64(b[0])
    for ai, bi in zip(a[1:], b[1:], strict=True):
        acc = acc + np.float64(ai) * np.float64(bi)
    return acc


# The laws' formulas on a state vector (what ``of_floats`` must compute, bit for bit).
def _sf(law: StateFeedbackLaw, x: np.ndarray) -> float:
    return float(-_ltr(law.gain[0], x - np.array([law.ref_x_m, 0.0, 0.0, 0.0])))


def _clp(law: ClpLaw, x: np.ndarray) -> float:
    t = law.terms
    minus_err = -np.array([x[0] - law.ref_x_m, x[1]])
    tau_bar = [_ltr(law.kp[i], minus_err) - _ltr(law.kv[i], x[2:]) for i in range(2)]
    alpha = np.array([t.alpha_xdd, t.alpha_thdd + t.alpha_thdd_x2 * x[0] ** 2])
    b1, b2, b3, b4 = t.beta
    xm, th, xd, thd = x
    beta = (
        b1 * math.sin(th)
        + b2 * xm * math.cos(th)
        + b3 * xm * xd * thd
        + b4 * xm * thd**2
        + t.beta_thetadot * thd
    )
    return float(_ltr(alpha, tau_bar) + beta)


def _smc(law: SlidingModeLaw, x: np.ndarray) -> float:
    s = float(_ltr(law.surface[0], x))
    k = np.where(s * x > 0, law.k_minus, law.k_plus)
    return float(-_ltr(law.equivalent_gain[0], x) + _ltr(k, x) - law.eta * np.sign(s))


def _states(n: int) -> np.ndarray:
    """Random states at the rig's scales and far from them, with exact zeros of both signs."""
    rng = np.random.default_rng(3)
    x = np.concatenate(
        [
            rng.uniform(-1, 1, (n, 4)) * [0.3, 0.7, 1.0, 5.0],
            rng.normal(0, 1, (n, 4)),
            rng.uniform(-1e-6, 1e-6, (n, 4)),
            rng.normal(0, 1e3, (n, 4)),
        ]
    )
    zeros = x[:n].copy()
    zeros[rng.random(zeros.shape) < 0.3] = 0.0
    zeros[rng.random(zeros.shape) < 0.1] = -0.0
    return np.concatenate([x, zeros])


def _laws() -> list[tuple[StateFeedbackLaw | ClpLaw | SlidingModeLaw, object]]:
    rng = np.random.default_rng(4)
    return [
        (StateFeedbackLaw(T.SF_CONT_K.copy()), _sf),
        (StateFeedbackLaw(T.SF_DISC_K.copy(), ref_x_m=0.1), _sf),
        (ClpLaw(TERMS, T.CLP_CONT_KP.copy(), T.CLP_CONT_KV.copy()), _clp),
        (ClpLaw(TERMS, T.CLP_DISC_KP.copy(), T.CLP_DISC_KV.copy(), ref_x_m=-0.05), _clp),
        # full gains (not the diagonal ones the fast product takes) and the motor's damping term
        (
            ClpLaw(
                ClpTerms(4e-4, 3e-3, 0.02, (-0.01, 0.2, 0.03, -4e-4), 0.0123), *rng.normal(0, 50, (2, 2, 2))
            ),
            _clp,
        ),
        (SlidingModeLaw(T.SMC_S.copy(), T.SMC_KEQ.copy(), T.SMC_K_MINUS, T.SMC_K_PLUS, T.SMC_ETA), _smc),
    ]


def _bits(values: list[float]) -> np.ndarray:
    return np.array(values, dtype=np.float64).view(np.int64)


@pytest.mark.parametrize(("law", "formula"), _laws())
def test_the_float_path_gives_the_numpy_formulas_bits(law, formula) -> None:
    states = _states(5000)
    expected = _bits([formula(law, x) for x in states])
    np.testing.assert_array_equal(_bits([law.of_floats(*x) for x in states.tolist()]), expected)
    np.testing.assert_array_equal(_bits([law(x) for x in states]), expected)


@pytest.mark.quick
@pytest.mark.parametrize(("law", "formula"), _laws())
def test_the_float_path_at_non_finite_and_extreme_states(law, formula) -> None:
    """NaN, ±inf and squares that overflow: the same value (NaN for NaN) or the same exception."""
    special = [0.0, -0.0, np.inf, np.nan, 1e-320, 1e200, -0.2]
    states = np.ascontiguousarray(np.array(np.meshgrid(*[special] * 4)).reshape(4, -1).T)

    def outcome(f, *args) -> str:
        try:
            v = float(f(*args))
        except Exception as exc:  # noqa: BLE001
            return type(exc).__name__
        return "nan" if math.isnan(v) else v.hex()

    with np.errstate(all="ignore"):
        expected = [outcome(formula, law, x) for x in states]
        assert [outcome(law.of_floats, *x) for x in states.tolist()] == expected


def test_laws_pickle_and_copy_with_their_scratch_vectors() -> None:
    x = np.array([0.1, -0.2, 0.3, 0.05])
    for law, _ in _laws():
        for other in (pickle.loads(pickle.dumps(law)), copy.deepcopy(law)):
            assert other(x) == law(x)


def test_the_true_state_law_takes_an_array_or_four_floats() -> None:
    law = registry.make("thesis-clp-continuous")
    assert isinstance(law, TrueStateLaw)
    x = np.array([0.12, -0.05, 0.3, -0.4])
    volts = law.motor_volts(x)
    assert law.motor_volts_of_floats(*x.tolist()) == volts
    tel = law.telemetry
    np.testing.assert_array_equal(tel.estimate, x)
    assert tel.u_computed == volts


@pytest.mark.quick
def test_a_state_law_without_the_float_path_gets_the_same_state_arrays() -> None:
    """A StateLaw that only takes arrays (here wrapping the registry's) runs the same episode, bit for bit."""

    class ArraysOnly:
        def __init__(self, inner: TrueStateLaw) -> None:
            self.inner, self.name, self.period_s = inner, inner.name, inner.period_s
            self.types: set[type] = set()

        @property
        def telemetry(self) -> Telemetry:
            return self.inner.telemetry

        def reset(self) -> None:
            self.inner.reset()

        def motor_volts(self, state: np.ndarray) -> float:
            self.types.add(type(state))
            return self.inner.motor_volts(state)

    def run(law):
        return run_closed_loop(
            law, x0_m=0.2, theta0_rad=0.3, duration_s=0.5, seed=0, stop_when_lost=False
        ).log

    wrapped = ArraysOnly(registry.make("thesis-smc-continuous"))  # type: ignore[arg-type]
    direct, via_arrays = run(registry.make("thesis-smc-continuous")), run(wrapped)
    assert wrapped.types == {np.ndarray}
    for name in ("true_x_m", "true_theta_rad", "true_xdot_m_s", "true_thetadot_rad_s", "motor_volts_v", "x1"):
        np.testing.assert_array_equal(getattr(via_arrays, name), getattr(direct, name))


def _nan_volts_after(evaluations: int):
    class NanVolts:
        name, period_s = "nan-volts", 0.001

        def __init__(self) -> None:
            self.k = 0

        @property
        def telemetry(self) -> Telemetry:
            return Telemetry()

        def reset(self) -> None:
            self.k = 0

        def motor_volts(self, state: np.ndarray) -> float:
            self.k += 1
            return math.nan if self.k > evaluations else 0.0

    return NanVolts()


def _raises_below(x_m: float):
    def law(x: np.ndarray) -> float:
        if x[0] < x_m:
            raise ZeroDivisionError("division by zero")
        return 0.0

    return law


@pytest.mark.parametrize(
    ("law", "message"),
    [
        (
            TrueStateLaw("nan-law", lambda x: math.nan, u_kind="volts"),
            "nan-law raised FloatingPointError at t = 0.010 s: nan-law: control law returned nan for state "
            "[0.1999253756407279, 0.2996481894486109, -0.013560598627769642, -0.06391121965476176]",
        ),
        (
            TrueStateLaw(
                "nan-torque",
                SlidingModeLaw(T.SMC_S.copy(), T.SMC_KEQ.copy(), T.SMC_K_MINUS, T.SMC_K_PLUS, math.nan),
                u_kind="torque",
                motor=MotorInverse(T.MOTOR_TORQUE_PER_VOLT, T.MOTOR_BACKEMF_AT_BEAM),
            ),
            "nan-torque raised FloatingPointError at t = 0.010 s: nan-torque: control law returned nan for "
            "state [0.1999253756407279, 0.2996481894486109, -0.013560598627769642, -0.06391121965476176]",
        ),
        (
            TrueStateLaw("raises", _raises_below(0.1995), u_kind="volts"),
            "raises raised ZeroDivisionError at t = 0.027 s: division by zero",
        ),
        (_nan_volts_after(30), "nan-volts returned nan volts at t = 0.040 s"),
    ],
)
def test_a_failing_state_law_is_reported_with_its_time(law, message: str) -> None:
    with pytest.raises(ControllerError) as err:
        run_closed_loop(law, x0_m=0.2, theta0_rad=0.3, duration_s=0.5, seed=0)
    assert str(err.value) == message


def test_the_rig_reports_a_non_finite_law_and_hands_it_state_arrays() -> None:
    rig = TwinRig(seed=0)
    rig.reset(0.2, 0.3)
    rig.read()
    rig.read()
    seen: list[np.ndarray] = []

    def law(state: np.ndarray) -> float:
        seen.append(state)
        return math.nan if len(seen) > 3 else 0.0

    with pytest.raises(FloatingPointError, match=r"the state law returned nan volts at t = 0\.01\d s"):
        rig.read_with_state_law(law, 0.001)
    assert all(type(s) is np.ndarray and s.shape == (4,) and s.dtype == np.float64 for s in seen)
