"""Recomputation of the thesis's numbered quantities (controllers/reproduction/numbers.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from controllers import thesis_numbers as tn
from controllers.design import ReducedObserver, state_feedback_gain
from controllers.reproduction import VERDICTS, rel_error
from controllers.reproduction.numbers import (
    APPX_SF_G,
    APPX_SF_OBS_X3,
    APPX_SF_OBS_X4,
    _sf_obs_coeffs,
    entries,
)
from twin.parameters import Parameters
from twin.reference import ReferenceModel, discretize_zoh


@pytest.fixture(scope="module")
def by_id():
    es = entries()
    ids = [e.id for e in es]
    assert len(ids) == len(set(ids)), "entry ids must be unique"
    return {e.id: e for e in es}


REQUIRED = [
    "Table 3.1 r*",
    "Table 3.1 J",
    "eq 3.2.3 coefficients",
    "eq 3.2.4 coefficients",
    "eq 3.2.3/3.2.4 denominator",
    "eq 3.2.8 A θ̈ row",
    "eq 3.2.8 A ẍ row",
    "eq 3.2.8 A",
    "eq 3.2.9 B",
    "eq 3.2.11 TF",
    "§3.2 poles",
    "§3.2 zeros",
    "eq 3.3.2",
    "eq 3.3.5 Ā",
    "eq 3.3.6 B̄",
    "eq 3.3.8 TF",
    "§3.3 poles",
    "§3.3 zeros",
    "eq 3.4.8 Φ",
    "eq 3.4.9 Γ",
    "§3.4 eig Φ",
    "eq 3.4.13 Φ̄",
    "eq 3.4.14 Γ̄",
    "§3.4 eig Φ̄",
    "§3.5 Q_C",
    "§3.5 det Q_C",
    "§3.5 Q_D",
    "§3.5 det Q_D",
    "§3.5 W_C",
    "§3.5 W_D",
    "§4.2 char poly",
    "§4.2 poles",
    "§4.2 t_s, ζ",
    "§4.2 K",
    "§4.2 closed-loop poles",
    "§4.3 α",
    "§4.3 β",
    "§4.3 kp",
    "§4.3 kv",
    "§4.3 closed-loop poles",
    "§4.4 T_r",
    "§4.4 A11 A12 A21 A22 B2",
    "§4.4 M",
    "§4.4 S̄",
    "§4.4 K_eq",
    "§5.2.1 poles",
    "§5.2.1 K",
    "§5.2.1 observer poles",
    "§5.2.1 G",
    "§5.2.2 poles",
    "§5.2.2 kp",
    "§5.2.2 kv",
    "§5.2.2 closed-loop poles",
    "§5.2.2 observer poles",
    "§5.2.2 G",
    "appendix A SF observer",
    "appendix A SF K",
    "appendix A CLP observer",
    "appendix A β",
    "appendix A α",
    "appendix A kp kv",
]


def test_every_item_present(by_id):
    assert len(by_id) >= 45
    missing = [i for i in REQUIRED if i not in by_id]
    assert not missing, missing


def test_verdicts_and_json(by_id):
    for e in by_id.values():
        assert e.verdict in VERDICTS
        assert e.explanation and e.quantity
        if e.rel_error is not None:
            assert np.isfinite(e.rel_error)
    json.dumps([e.as_dict() for e in entries()])


def test_rolling_radius(by_id):
    e = by_id["Table 3.1 r*"]
    assert e.recomputed == pytest.approx(4.676e-3, abs=1e-6)
    assert e.verdict == "misprint"


def test_theta_row_of_a_agrees(by_id):
    a, b = ReferenceModel(Parameters(), motor_inertia=False).linearize("torque")
    assert (
        rel_error([tn.A_TORQUE[3, 0], tn.A_TORQUE[3, 1], tn.B_TORQUE[3, 0]], [a[3, 0], a[3, 1], b[3, 0]])
        < 5e-3
    )
    assert by_id["eq 3.2.8 A θ̈ row"].verdict == "agrees"
    assert by_id["eq 3.2.8 A ẍ row"].verdict in ("inconsistent", "unexplained")


def test_b3_is_missing_ball_rotation_coupling(by_id):
    # B3 = (h* + r*)/det, without 2r²/(5r*): within 0.1 % of the printed 2.4185
    from controllers.reproduction.numbers import thesis_equations_linear

    _, b = thesis_equations_linear(x_row_k2=False)
    assert b[2, 0] == pytest.approx(tn.B_TORQUE[2, 0], rel=1e-3)


def test_sf_cont_k_from_printed_matrices():
    k = state_feedback_gain(tn.A_VOLTAGE, tn.B_VOLTAGE, tn.SF_CONT_POLES)
    assert rel_error(tn.SF_CONT_K, k) < 1e-3


def test_printed_sf_observer_gain_is_unstable(by_id):
    ph, ga = discretize_zoh(tn.A_VOLTAGE, tn.B_VOLTAGE, tn.PERIOD_S)
    lam = ReducedObserver.from_gain(ph, ga, tn.SF_OBS_G).error_poles()
    assert np.max(np.abs(lam)) > 1.05
    assert by_id["§5.2.1 G"].verdict == "misprint"


def test_appendix_observer_reproduced_by_positive_8():
    ph, ga = ReferenceModel(Parameters(), motor_inertia=False).discretize("voltage", tn.PERIOD_S)
    r3, r4 = _sf_obs_coeffs(ReducedObserver.from_gain(ph, ga, APPX_SF_G))
    got, want = np.array([r3, r4]), np.array([APPX_SF_OBS_X3, APPX_SF_OBS_X4])
    assert np.max(np.abs(got[:, :2] - want[:, :2])) < 2e-3  # F = Φbb − GΦab
    assert np.max(np.abs(got[:, 2:] - want[:, 2:]) / np.maximum(np.abs(want[:, 2:]), 1.0)) < 0.07  # Ga, H, G
    lam = ReducedObserver.from_gain(ph, ga, APPX_SF_G).error_poles()
    assert np.allclose(np.sort_complex(lam), np.sort_complex(np.array(tn.SF_OBS_POLES_Z)), atol=2e-3)


def test_voltage_a34_factor_ten(by_id):
    e = by_id["eq 3.3.5 Ā"]
    assert e.recomputed[2][3] == pytest.approx(-0.0061, rel=0.01)


def test_appendix_ball_mass(by_id):
    e = by_id["appendix A β"]
    assert e.rel_error < 0.01
