"""Physics and sensors at the edges: the stops hold, a lost ball stays where it left, histories are bounded."""

import json
import math

import numpy as np
import pytest

from twin import sensors
from twin.parameters import Parameters
from twin.plant import Plant


@pytest.mark.quick
def test_the_stops_hold_the_beam_at_full_voltage() -> None:
    """12 V from level for 1.5 s drives the beam into its stop: it overshoots 43.4° by less than 0.5°."""
    plant = Plant()
    plant.reset(0.0, 0.0)
    block = plant.advance(np.full(1500, 12.0))
    assert math.degrees(float(np.max(np.abs(block.theta_rad)))) - 43.4 < 0.5


@pytest.mark.quick
def test_a_lost_ball_keeps_the_state_it_left_the_track_with() -> None:
    plant = Plant(hold_beam_rad=0.2)
    plant.reset(0.0)
    while not plant.ball_lost:
        plant.advance(np.zeros(20))
    left = plant.state()
    assert abs(left[0]) > 0.323 - 0.02 and abs(left[0]) < 0.323 + 0.02  # near the track's end
    plant.advance(np.zeros(500))  # the ball falls to the floor meanwhile
    np.testing.assert_array_equal(plant.state(), left)


def test_the_dropout_history_stays_bounded_in_a_long_session() -> None:
    """200 contact losses per second for 60 s: 12 000 expected (±3σ = ±329); at most 2·1000 kept."""
    params = Parameters().with_overrides({"ball_sensor.dropout_rate_hz": 200.0})
    chain = sensors.BallPositionChain(params, seed=4)
    knots = np.arange(21) * 1e-3
    for _ in range(3000):
        chain.advance(chain.time_s + knots, np.zeros(21))
    assert chain.dropout_count == pytest.approx(12000, abs=3 * math.sqrt(12000))
    assert len(chain.dropout_intervals) <= 2 * sensors.DROPOUT_HISTORY + 50


def test_a_motor_that_drives_the_beam_through_its_stops_is_told(capsys) -> None:
    """An amplifier of 1000 V/V with a ±2500 V rail drives the beam past its stops further than their contact
    yields (``twin.plant.STOP_YIELD_RAD``): the run says so on stderr and in its summary; the thesis's
    amplifier never does."""
    from twin.app.cli import main
    from twin.plant import STOP_YIELD_RAD

    base = [
        "run",
        "--controller",
        "appendix-sf",
        "--x0",
        "0.2",
        "--theta0",
        "0.3",
        "--duration",
        "1",
        "--json",
    ]
    main([*base, "--set", "amplifier.gain_v_per_v=1000", "--set", "amplifier.rail_v=2500"])
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    past = summary["peak_theta_rad"] - math.radians(43.4)
    assert past > STOP_YIELD_RAD and "past its ±43.4° stops" in summary["warning"]
    assert "ballbeam run: warning: the beam went" in captured.err
    main(base)
    captured = capsys.readouterr()
    assert "warning" not in json.loads(captured.out) and "warning" not in captured.err
