"""Design functions place the poles they are asked for, on any model; the thesis's own numbers where they
follow from its model."""

import numpy as np
import pytest
import scipy.linalg

from controllers import thesis_numbers as T
from controllers.design import (
    DesignError,
    ReducedObserver,
    check_poles,
    clp_gains,
    lqi_design,
    lqr_design,
    reduced_order_observer,
    sliding_surface,
    state_feedback_gain,
    steady_state,
)
from controllers.laws import ClpTerms
from twin.parameters import Parameters
from twin.reference import ReferenceModel

DISTINCT_S = [-1.5 + 2.6j, -1.5 - 2.6j, -7.0, -8.0]
DISTINCT_Z = [0.969 + 0.0504j, 0.969 - 0.0504j, 0.86, 0.87]


@pytest.mark.quick
@pytest.mark.parametrize(
    "params", [Parameters(), Parameters().with_overrides({"ball.mass_kg": 0.03, "beam.cog_height_m": 0.005})]
)
def test_state_feedback_places_poles_continuous_and_discrete(params: Parameters) -> None:
    ref = ReferenceModel(params)
    a, b = ref.linearize("voltage")
    k = state_feedback_gain(a, b, DISTINCT_S)
    assert check_poles(a - b @ k, DISTINCT_S) < 1e-6
    phi, gamma = ref.discretize("voltage")
    kd = state_feedback_gain(phi, gamma, DISTINCT_Z)
    assert check_poles(phi - gamma @ kd, DISTINCT_Z) < 1e-6


def test_repeated_poles_are_placed_by_characteristic_polynomial() -> None:
    a, b = ReferenceModel(Parameters()).linearize("voltage")
    # §4.2's polynomial (s² + 3s + 9)(s + 7.5)²: its dominant pair is −1.5 ± 2.598i, printed as ± 2.6i.
    poles = [-1.5 + 1.5j * np.sqrt(3), -1.5 - 1.5j * np.sqrt(3), -7.5, -7.5]
    k = state_feedback_gain(a, b, poles)
    np.testing.assert_allclose(np.poly(a - b @ k), T.SF_CONT_CHAR_POLY, rtol=1e-9)


@pytest.mark.quick
def test_reduced_order_observer_places_its_poles() -> None:
    phi, gamma = ReferenceModel(Parameters()).discretize("voltage")
    for poles in ([0.835 + 0.199j, 0.835 - 0.199j], [0.2, 0.3], [0.5, 0.6]):
        obs = reduced_order_observer(phi, gamma, poles)
        assert check_poles(obs.f, poles) < 1e-6
        # The regrouped form equals eq 5.2.19 term by term.
        g = obs.gain
        np.testing.assert_allclose(obs.f, phi[2:, 2:] - g @ phi[:2, 2:])
        np.testing.assert_allclose(obs.h, gamma[2:] - g @ gamma[:2])


@pytest.mark.quick
def test_observer_estimates_the_velocities_of_the_linear_model() -> None:
    """Run the linear model with the observer: the estimation error decays as the observer poles say."""
    phi, gamma = ReferenceModel(Parameters()).discretize("voltage")
    obs = reduced_order_observer(phi, gamma, [0.5, 0.6])
    x = np.array([0.1, 0.05, 0.3, -0.5])
    xb_hat = np.zeros(2)
    rng = np.random.default_rng(0)
    for _ in range(40):
        u = rng.uniform(-1, 1)
        x_next = phi @ x + gamma[:, 0] * u
        xb_hat = obs.f @ xb_hat + obs.ga @ x[:2] + obs.gain @ x_next[:2] + obs.h[:, 0] * u
        x = x_next
    assert np.max(np.abs(xb_hat - x[2:])) < 1e-6  # started 0.5 m/s off; 0.6**40 ≈ 1e-9


@pytest.mark.quick
def test_clp_gains_place_the_linearized_loop() -> None:
    params = Parameters()
    ref = ReferenceModel(params)
    terms = ClpTerms.from_params(params)
    for a, b, poles in (
        (*ref.linearize("torque"), [-2.0, -2.5, -3.0, -3.5]),
        (*ref.discretize("torque"), [0.95, 0.955, 0.96, 0.965]),
    ):
        kp, kv = clp_gains(a, b, terms.alpha(0.0), terms.beta_linear(), poles)
        k_eff = np.array(
            [
                [
                    terms.alpha_xdd * kp[0, 0],
                    terms.alpha_thdd * kp[1, 1],
                    terms.alpha_xdd * kv[0, 0],
                    terms.alpha_thdd * kv[1, 1],
                ]
            ]
        )
        assert check_poles(a + b @ terms.beta_linear() - b @ k_eff, poles) < 1e-6


@pytest.mark.quick
def test_sliding_surface_gives_its_sliding_poles() -> None:
    a, b = ReferenceModel(Parameters()).linearize("torque")
    design = sliding_surface(a, b, [-2.0, -3.0, -10.0])
    assert check_poles(np.diag(design.sliding_poles), [-2.0, -3.0, -10.0]) < 1e-6
    assert (design.surface @ b)[0, 0] == pytest.approx(1.0)
    # On the surface, the equivalent control leaves exactly the sliding poles (and one at 0 along s).
    closed = a - b @ design.equivalent_gain
    eig = np.linalg.eigvals(closed)
    assert check_poles(np.diag(eig), [0.0, -2.0, -3.0, -10.0]) < 1e-6


@pytest.mark.quick
def test_uncontrollable_pair_is_refused() -> None:
    a = np.diag([1.0, 2.0])
    b = np.array([[1.0], [0.0]])
    with pytest.raises(DesignError, match="not controllable"):
        state_feedback_gain(a, b, [-1.0, -2.0])


@pytest.mark.quick
def test_thesis_sf_gain_follows_from_its_own_voltage_model() -> None:
    """§4.2: pole placement on the printed Ā, B̄ gives the printed K (to its printed digits)."""
    k = state_feedback_gain(T.A_VOLTAGE, T.B_VOLTAGE, T.SF_CONT_POLES)
    np.testing.assert_allclose(k, T.SF_CONT_K, rtol=2e-3)


@pytest.mark.quick
def test_appendix_observer_is_the_voltage_model_observer_with_g_4_8() -> None:
    """The printed G = [[4, −8], [−15, 12]] (§5.2.1) gives an unstable observer; the appendix's update
    coefficients are G = [[4, 8], [−15, 12]] on the voltage model, with the stated poles 0.835 ± 0.199i."""
    phi, gamma = ReferenceModel(Parameters(), motor_inertia=False).discretize("voltage")
    printed = ReducedObserver.from_gain(phi, gamma, T.SF_OBS_G)
    assert np.max(np.abs(printed.error_poles())) > 1.05
    appendix = ReducedObserver.from_gain(phi, gamma, np.array([[4.0, 8.0], [-15.0, 12.0]]))
    assert check_poles(appendix.f, T.SF_OBS_POLES_Z) < 2e-3
    np.testing.assert_allclose(appendix.f, [[0.9207, -0.1601], [0.2927, 0.7494]], atol=2e-3)
    np.testing.assert_allclose(appendix.ga, [[-3.9409, -8.0826], [14.257, -11.945]], rtol=0.01)
    np.testing.assert_allclose(appendix.h[:, 0], [-0.0055, 0.0717], atol=5e-4)


# --- LQR and LQI (controllers.design.lqr_design, lqi_design, steady_state) ------------------------------
SCALE = np.array([0.1, 0.2, 0.5, 2.0])
NOISE = (2e-3, 1e-3)


def _voltage_model(params: Parameters) -> tuple[np.ndarray, np.ndarray]:
    return ReferenceModel(params).discretize("voltage", params.daq.period_s)


@pytest.mark.quick
def test_lqr_design_solves_the_two_riccati_equations() -> None:
    """K and the Kalman gain against scipy's Riccati solver (python-control's dlqr/dlqe are the design's)."""
    phi, gamma = _voltage_model(Parameters())
    d = lqr_design(
        phi, gamma, state_scale=SCALE, input_scale_v=12.0, input_noise_v=0.5, measurement_noise=NOISE
    )
    q, r = np.diag(1.0 / SCALE**2), np.array([[1.0 / 12.0**2]])
    p = scipy.linalg.solve_discrete_are(phi, gamma, q, r)
    assert np.allclose(d.gain, np.linalg.solve(r + gamma.T @ p @ gamma, gamma.T @ p @ phi), rtol=1e-8)
    h, rn = np.eye(2, 4), np.diag(np.square(NOISE))
    p_prior = scipy.linalg.solve_discrete_are(phi.T, h.T, gamma @ gamma.T * 0.5**2, rn)
    assert np.allclose(d.kalman_gain, p_prior @ h.T @ np.linalg.inv(h @ p_prior @ h.T + rn), rtol=1e-8)
    assert max(abs(np.linalg.eigvals(phi - gamma @ d.gain))) < 1.0
    assert max(abs(np.linalg.eigvals((np.eye(4) - d.kalman_gain @ h) @ phi))) < 1.0


@pytest.mark.parametrize("setpoint_m", [0.1, -0.05])
def test_a_pure_state_feedback_holds_the_balls_weight_with_a_steady_error(setpoint_m: float) -> None:
    """lqr's linear steady state off centre: θ = 0, at rest, and the motor volts −K·(x − x_ref) are those
    whose torque k_τ·V holds the ball's weight m·g·x on the beam: only a steady error gives them."""
    params = Parameters()
    phi, gamma = _voltage_model(params)
    d = lqr_design(
        phi, gamma, state_scale=SCALE, input_scale_v=12.0, input_noise_v=0.5, measurement_noise=NOISE
    )
    x_ref = np.array([setpoint_m, 0.0, 0.0, 0.0])
    x = steady_state(phi, gamma, d.gain, x_ref)
    assert np.allclose(x[1:], 0.0, atol=1e-12)
    volts = -(d.gain @ (x - x_ref)).item()
    weight_nm = params.ball.mass_kg * params.physics.gravity_m_s2 * x[0]
    assert volts * params.motor.torque_per_volt_nm_per_v == pytest.approx(weight_nm, rel=1e-9)
    assert abs(x[0] - setpoint_m) > 0.05 * abs(setpoint_m)  # a real error, not rounding


@pytest.mark.quick
def test_lqi_reaches_the_setpoint_in_the_linear_model() -> None:
    """The augmented loop is stable and its equilibrium has the ball exactly at the setpoint, at rest, the
    integrator supplying the volts that hold the ball's weight there."""
    params = Parameters()
    period_s = params.daq.period_s
    phi, gamma = _voltage_model(params)
    d = lqi_design(
        phi,
        gamma,
        period_s,
        state_scale=SCALE,
        integral_scale_m_s=0.1,
        input_scale_v=12.0,
        input_noise_v=0.5,
        measurement_noise=NOISE,
    )
    plain = lqr_design(
        phi, gamma, state_scale=SCALE, input_scale_v=12.0, input_noise_v=0.5, measurement_noise=NOISE
    )
    assert np.array_equal(d.kalman_gain, plain.kalman_gain)
    # ξ = (x, z): x⁺ = Φx + Γ(−K(x − x_ref) − k_i z), z⁺ = z + T(x₀ − r)
    r = 0.1
    e1 = np.eye(4)[:, :1]
    a_cl = np.block([[phi - gamma @ d.gain, -gamma * d.integral_gain], [period_s * e1.T, np.ones((1, 1))]])
    assert max(abs(np.linalg.eigvals(a_cl))) < 1.0
    b_r = np.concatenate([(gamma @ d.gain @ e1)[:, 0] * r, [-period_s * r]])
    xi = np.linalg.solve(np.eye(5) - a_cl, b_r)
    assert xi[0] == pytest.approx(r, abs=1e-12) and np.allclose(xi[1:4], 0.0, atol=1e-12)
    volts = -d.integral_gain * xi[4]
    weight_nm = params.ball.mass_kg * params.physics.gravity_m_s2 * r
    assert volts * params.motor.torque_per_volt_nm_per_v == pytest.approx(weight_nm, rel=1e-9)


# --- cases a reader checks on paper ---------------------------------------------------------------------
@pytest.mark.quick
def test_pole_placement_on_a_double_integrator_by_hand() -> None:
    """ẍ = u with u = −K·x: A − B·K = [[0, 1], [−k1, −k2]] has s² + k2·s + k1; poles −2, −3 give
    s² + 5s + 6, so K = [6, 5]."""
    k = state_feedback_gain(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), [-2.0, -3.0])
    assert k == pytest.approx(np.array([[6.0, 5.0]]), abs=1e-12)


@pytest.mark.quick
def test_scalar_lqr_and_kalman_gains_are_the_golden_ratios() -> None:
    """x[k+1] = x[k] + u[k] with Q = R = 1 (Bryson scales 1): the Riccati equation P = 1 + P − P²/(1 + P)
    gives P² − P − 1 = 0, P = φ = (1 + √5)/2 and K = P/(1 + P) = 1/φ = 0.618…. The filter with unit input and
    measurement noise has the same equation for its a-priori covariance, P⁻ = φ, and the current gain
    L = P⁻/(P⁻ + 1) = 1/φ on the measured x; the second measurement row (θ, absent here) gets no gain."""
    golden = (1.0 + 5.0**0.5) / 2.0
    d = lqr_design(
        np.array([[1.0]]),
        np.array([[1.0]]),
        state_scale=[1.0],
        input_scale_v=1.0,
        input_noise_v=1.0,
        measurement_noise=[1.0, 1.0],
    )
    assert d.gain == pytest.approx(np.array([[1.0 / golden]]), rel=1e-12)
    assert d.kalman_gain == pytest.approx(np.array([[1.0 / golden, 0.0]]), rel=1e-9, abs=1e-12)
