"""The analytic reference model against the thesis's own equations and independent computations."""

import math

import numpy as np
import pytest

from twin.parameters import Parameters
from twin.reference import EquationCoefficients, ReferenceModel, discretize_zoh


def _thesis_residuals(
    p: Parameters, state: np.ndarray, acc: np.ndarray, torque: float
) -> tuple[float, float]:
    """Residuals of eq 3.1.26 and eq 3.1.27 (θ̇² in place of the printed ẋ²), written as printed."""
    x, th, xd, thd = state
    xdd, thdd = acc
    m, r, rs, hs, g = p.ball.mass_kg, p.ball.radius_m, p.rolling_radius_m, p.track.contact_height_m, 9.81
    jbp, mb, h = p.beam.inertia_pivot_kgm2, p.beam.mass_kg, p.beam.cog_height_m
    k1 = 2 * r**2 / (5 * rs**2)
    k2 = 2 * r**2 / (5 * rs)
    e26 = (k1 + 1) * xdd - x * thd**2 + g * math.sin(th) - (k2 + hs + rs) * thdd
    e27 = (
        (jbp - k2 * m * hs) * thdd
        + m * x**2 * thdd
        - mb * g * h * math.sin(th)
        + m * g * x * math.cos(th)
        + 2 * m * x * xd * thd
        - m * (hs + rs) * x * thd**2
        + k1 * m * hs * xdd
        - torque
    )
    return e26, e27


@pytest.mark.quick
def test_nonlinear_dynamics_satisfy_the_thesis_equations(params: Parameters) -> None:
    thesis_model = ReferenceModel(params, motor_inertia=False)
    rng = np.random.default_rng(7)
    for _ in range(50):
        state = rng.uniform([-0.3, -0.7, -1.0, -5.0], [0.3, 0.7, 1.0, 5.0])
        torque = rng.uniform(-0.2, 0.2)
        acc = thesis_model.accelerations(state, torque)
        e26, e27 = _thesis_residuals(params, state, acc, torque)
        assert abs(e26) < 1e-9 * (1 + abs(acc[0]))
        assert abs(e27) < 1e-12 * (1 + abs(acc[1]))


def test_stacked_coefficients_are_each_parameter_sets_columns_and_accelerate_each_row(
    params: Parameters,
) -> None:
    """``EquationCoefficients.stack``: row b of every coefficient (and of each β) is parameter set b's, bit for
    bit, and a batch's accelerations are each row's as the arrays compute them one set at a time."""
    sets = [params, params.with_overrides({"ball.mass_kg": 0.03, "beam.pivot_friction_nm": 0.002})]
    rows = [EquationCoefficients.from_params(p) for p in sets]
    q = EquationCoefficients.stack(rows)
    for b, row in enumerate(rows):
        assert q.k1.shape == (2, 1) and all(c.shape == (2, 1) for c in q.beta)
        assert [q.k1[b, 0], q.g[b, 0], q.coulomb_nm[b, 0]] == [row.k1, row.g, row.coulomb_nm]
        assert [c[b, 0] for c in q.beta] == list(row.beta)
    state = np.array([[0.1, -0.05, 0.2, 0.3], [-0.2, 0.1, -0.1, 0.4]]).T[:, :, None]  # (4, B = 2, 1)
    xdd, thdd = q.accelerations(*state, np.full((2, 1), 0.01))
    for b, row in enumerate(rows):
        one = row.accelerations(*state[:, b : b + 1, 0], np.full(1, 0.01))
        assert (xdd[b, 0], thdd[b, 0]) == (one[0][0], one[1][0])


@pytest.mark.quick
def test_linearization_equals_finite_differences_of_the_nonlinear_model(reference: ReferenceModel) -> None:
    for kind in ("torque", "voltage"):
        a, b = reference.linearize(kind)
        eps = 1e-6
        fd_a = np.column_stack(
            [
                (reference.derivative(eps * e, 0.0, kind) - reference.derivative(-eps * e, 0.0, kind))
                / (2 * eps)
                for e in np.eye(4)
            ]
        )
        fd_b = (
            reference.derivative(np.zeros(4), eps, kind) - reference.derivative(np.zeros(4), -eps, kind)
        ) / (2 * eps)
        np.testing.assert_allclose(a, fd_a, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(b[:, 0], fd_b, rtol=1e-6, atol=1e-8)


def test_rows_the_thesis_got_right_are_reproduced(params: Parameters) -> None:
    """Eq 3.2.8/3.2.9 (θ̈ row, B) and 3.3.5/3.3.6 (θ̈ row of A-bar) from the thesis's model (no motor inertia).

    The ẍ row of eq 3.2.8 (−0.4471, −3.97, B 2.4185) does not follow from the thesis's own equations;
    the reproduction report explains it."""
    a, b = ReferenceModel(params, motor_inertia=False).linearize("torque")
    assert a[3, 0] == pytest.approx(-46.2004, rel=0.002)
    assert a[3, 1] == pytest.approx(3.8656, rel=0.002)
    assert b[3, 0] == pytest.approx(249.9, rel=0.002)
    av, bv = ReferenceModel(params, motor_inertia=False).linearize("voltage")
    assert av[3, 3] == pytest.approx(-0.6311, rel=0.005)
    assert bv[3, 0] == pytest.approx(4.0984, rel=0.005)


@pytest.mark.quick
def test_open_loop_is_unstable_with_the_expected_pole_structure(
    params: Parameters, reference: ReferenceModel
) -> None:
    # Torque input, no damping: a ± pair on the real axis and an imaginary pair (thesis §3.2).
    poles = np.sort_complex(
        np.linalg.eigvals(ReferenceModel(params, motor_inertia=False).linearize("torque")[0])
    )
    real = poles[np.abs(poles.imag) < 1e-9].real
    assert len(real) == 2 and real[0] == pytest.approx(-real[1], rel=1e-6) and real[1] > 3.5
    # Voltage input: back-EMF damps, one pole remains in the right half plane (thesis §3.3).
    poles_v = np.linalg.eigvals(reference.linearize("voltage")[0])
    assert np.sum(poles_v.real > 0) == 1


def test_zero_order_hold_matches_python_control(reference: ReferenceModel) -> None:
    import control  # here, not at the top: python-control costs every collection half a second

    for kind in ("torque", "voltage"):
        a, b = reference.linearize(kind)
        phi, gamma = discretize_zoh(a, b, 0.02)
        sysd = control.sample_system(control.ss(a, b, np.eye(4), np.zeros((4, 1))), 0.02, method="zoh")
        np.testing.assert_allclose(phi, sysd.A, rtol=1e-10, atol=1e-13)
        np.testing.assert_allclose(gamma, sysd.B, rtol=1e-10, atol=1e-13)


@pytest.mark.quick
def test_simulation_conserves_energy_without_motor_and_damping(params: Parameters) -> None:
    """Torque-free, undamped: kinetic + potential energy stays constant (an independent check of the EOM)."""
    model = ReferenceModel(params, motor_inertia=False)
    m, mb, h, g = params.ball.mass_kg, params.beam.mass_kg, params.beam.cog_height_m, 9.81
    c, rs, j = params.ball_centre_height_m, params.rolling_radius_m, params.ball.inertia_kgm2

    def energy(s: np.ndarray) -> float:
        x, th, xd, thd = s
        kinetic = (
            0.5 * m * ((xd - c * thd) ** 2 + (x * thd) ** 2)
            + 0.5 * j * (thd - xd / rs) ** 2
            + 0.5 * params.beam.inertia_pivot_kgm2 * thd**2
        )
        potential = m * g * (x * math.sin(th) + c * math.cos(th)) + mb * g * h * math.cos(th)
        return kinetic + potential

    x0 = np.array([0.1, 0.05, 0.0, 0.0])
    _, states = model.simulate(x0, np.zeros(25), 0.02, input="torque")
    energies = np.array([energy(s) for s in states])
    assert np.ptp(energies) < 1e-9 * abs(energies[0])
