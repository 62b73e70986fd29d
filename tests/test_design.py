"""Design functions place the poles they are asked for, on any model; the thesis's own numbers where they
follow from its model."""

import numpy as np
import pytest

from controllers import thesis_numbers as T
from controllers.design import (
    DesignError,
    ReducedObserver,
    check_poles,
    clp_gains,
    reduced_order_observer,
    sliding_surface,
    state_feedback_gain,
)
from controllers.laws import ClpTerms
from twin.parameters import Parameters
from twin.reference import ReferenceModel

DISTINCT_S = [-1.5 + 2.6j, -1.5 - 2.6j, -7.0, -8.0]
DISTINCT_Z = [0.969 + 0.0504j, 0.969 - 0.0504j, 0.86, 0.87]


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


def test_reduced_order_observer_places_its_poles() -> None:
    phi, gamma = ReferenceModel(Parameters()).discretize("voltage")
    for poles in ([0.835 + 0.199j, 0.835 - 0.199j], [0.2, 0.3], [0.5, 0.6]):
        obs = reduced_order_observer(phi, gamma, poles)
        assert check_poles(obs.f, poles) < 1e-6
        # The regrouped form equals eq 5.2.19 term by term.
        g = obs.gain
        np.testing.assert_allclose(obs.f, phi[2:, 2:] - g @ phi[:2, 2:])
        np.testing.assert_allclose(obs.h, gamma[2:] - g @ gamma[:2])


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


def test_sliding_surface_gives_its_sliding_poles() -> None:
    a, b = ReferenceModel(Parameters()).linearize("torque")
    design = sliding_surface(a, b, [-2.0, -3.0, -10.0])
    assert check_poles(np.diag(design.sliding_poles), [-2.0, -3.0, -10.0]) < 1e-6
    assert (design.surface @ b)[0, 0] == pytest.approx(1.0)
    # On the surface, the equivalent control leaves exactly the sliding poles (and one at 0 along s).
    closed = a - b @ design.equivalent_gain
    eig = np.linalg.eigvals(closed)
    assert check_poles(np.diag(eig), [0.0, -2.0, -3.0, -10.0]) < 1e-6


def test_uncontrollable_pair_is_refused() -> None:
    a = np.diag([1.0, 2.0])
    b = np.array([[1.0], [0.0]])
    with pytest.raises(DesignError, match="not controllable"):
        state_feedback_gain(a, b, [-1.0, -2.0])


def test_thesis_sf_gain_follows_from_its_own_voltage_model() -> None:
    """§4.2: pole placement on the printed Ā, B̄ gives the printed K (to its printed digits)."""
    k = state_feedback_gain(T.A_VOLTAGE, T.B_VOLTAGE, T.SF_CONT_POLES)
    np.testing.assert_allclose(k, T.SF_CONT_K, rtol=2e-3)


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
