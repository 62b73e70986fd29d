"""``ballbeam validate`` on a rig that is not the thesis's: its default criteria come from its parts
(the region over its whole track less the ball's radius by its beam's whole travel, the middle half of each
required), checked here against boxes computed by hand; a check that does not apply to the rig's parts says so
(never passed); a small validation of open-ball-and-beam gives the verdict of its runs."""

from __future__ import annotations

import math
import textwrap
from dataclasses import replace
from pathlib import Path

import pytest

from twin.app import validate as validate_module
from twin.app.montecarlo import load_spread
from twin.app.validate import (
    ValidationCriteria,
    default_criteria,
    load_criteria,
    rig_battery,
    validate,
)
from twin.app.validate_render import render_markdown
from twin.parameters import Parameters
from twin.parts.description import preset
from twin.parts.linkage import Linkage

ROOT = Path(__file__).resolve().parents[1]


def _lever_theta_rad(link: Linkage, horn_rad: float) -> float:
    """The beam's angle with the horn at ``horn_rad``, by circle intersection (independent of
    twin.parts.linkage): the attachment, L out along the beam, lies one push-rod from the horn's pin."""
    pin_x = link.shaft_x_m + link.crank_m * math.cos(horn_rad)
    pin_z = link.shaft_z_m + link.crank_m * math.sin(horn_rad)
    d = math.hypot(pin_x, pin_z)
    return math.atan2(pin_z, pin_x) + math.acos(
        (link.beam_arm_m**2 + d * d - link.rod_m**2) / (2 * link.beam_arm_m * d)
    )


def _lever_travel(rig: Parameters) -> tuple[float, float]:
    """The beam's travel: the horn at its travel's two ends, within the stops."""
    link = rig.of(Linkage)
    ends = sorted(
        _lever_theta_rad(link, link.horn_neutral_rad + s * link.horn_travel_rad) for s in (-1.0, 1.0)
    )
    stop = rig.beam.stop_angle_rad
    return max(-stop, ends[0]), min(stop, ends[1])


@pytest.mark.quick
def test_the_thesis_rig_keeps_the_thesis_criteria_exactly() -> None:
    """The thesis's boxes (chapter 7's 17 × 15 grid at 4 cm and 0.1 rad, the ±0.2 m × ±0.3 rad box), and the
    latencies and free runs its 20 ms period gives: 0, 5, 10, 15 ms and 0, 10, 20, 40 ms."""
    c = default_criteria(Parameters())
    assert c == ValidationCriteria()
    assert (c.region_x0, c.region_theta0) == ((-0.32, 0.32, 17), (-0.7, 0.7, 15))
    assert (c.required_x0_m, c.required_theta0_rad) == ((-0.2, 0.2), (-0.3, 0.3))
    assert c.latencies_s == (0.0, 0.005, 0.01, 0.015)
    assert c.free_runs_s == (0.0, 0.01, 0.02, 0.04)
    rig = rig_battery(Parameters())
    assert rig.thesis and not rig.not_applicable
    assert rig.starts == ((0.2, 0.3), (-0.2, 0.3), (0.14, -0.2), (-0.13, 0.29), (-0.13, 0.23), (0.08, 0.18))
    assert rig.zeroing_field == "angle_sensor.zeroing_error_rad"
    assert rig.latency_field == "daq.output_latency_s"
    assert rig.rail_v == 12.0


@pytest.mark.quick
@pytest.mark.parametrize(
    ("name", "half_m", "radius_m"),
    [
        ("open-ball-and-beam", 0.105, 0.01905),  # 210 mm of rod; the 1.5 in Delrin ball
        ("quanser-bb01", 0.2, 0.0127),  # L/2 − r_b; the 0.5 in steel ball
    ],
)
def test_a_lever_rigs_boxes_are_its_track_less_the_ball_by_its_linkages_travel(
    name: str, half_m: float, radius_m: float
) -> None:
    rig = preset(name)
    c = default_criteria(rig)
    x = half_m - radius_m  # 0.08595 m and 0.1873 m
    low, high = _lever_travel(rig)
    assert c.region_x0[2] == 17 and c.region_theta0[2] == 15
    assert c.region_x0[:2] == pytest.approx((-x, x), abs=1e-6)
    assert c.required_x0_m == pytest.approx((-x / 2, x / 2), abs=1e-6)
    assert c.region_theta0[:2] == pytest.approx((low, high), abs=1e-6)
    assert c.required_theta0_rad == pytest.approx((low / 2, high / 2), abs=1e-6)
    # rounded inward: every bound is a start the rig takes
    assert -x <= c.region_x0[0] and c.region_x0[1] <= x
    assert low <= c.region_theta0[0] and c.region_theta0[1] <= high


@pytest.mark.quick
def test_open_ball_and_beams_travel_is_its_measured_lopsided_range() -> None:
    """OBB's beam reaches −7.2° and +3.8° (its servo_calibration_data.txt: −7.60° at 1000 µs and +3.86° at
    2000 µs; the preset's horn travels 1040…1960 µs), so the region is lopsided: −0.1257 … +0.0667 rad."""
    c = default_criteria(preset("open-ball-and-beam"))
    assert c.region_theta0[0] == pytest.approx(-0.1257, abs=1e-4)
    assert c.region_theta0[1] == pytest.approx(0.0667, abs=1e-4)


@pytest.mark.quick
def test_a_pivoted_rigs_boxes_are_its_track_less_the_ball_by_its_stops() -> None:
    """The stepper build: 0.2 m of channel less the 19.05 mm ball, the frame's stops at ±0.35 rad."""
    rig = preset("arduino-stepper-ultrasonic")
    c = default_criteria(rig)
    assert c.region_x0 == (-0.18095, 0.18095, 17)
    assert c.required_x0_m == (-0.090475, 0.090475)
    assert c.region_theta0 == (-0.35, 0.35, 15)
    assert c.required_theta0_rad == (-0.175, 0.175)
    b = rig_battery(rig)
    # the required box's four corners and its two edges at level; sensitivities from the upper corners
    assert b.starts == (
        (0.090475, 0.175),
        (-0.090475, 0.175),
        (0.090475, -0.175),
        (-0.090475, -0.175),
        (0.090475, 0.0),
        (-0.090475, 0.0),
    )
    assert b.sensitivity_starts == ((0.090475, 0.175), (-0.090475, 0.175))
    assert b.montecarlo_start == (-0.090475, 0.175)


@pytest.mark.quick
@pytest.mark.parametrize(
    ("name", "missing", "rail_v"),
    [
        ("open-ball-and-beam", {"zeroing_counts", "latencies_s", "saturation"}, None),
        ("arduino-stepper-ultrasonic", {"zeroing_counts", "latencies_s", "saturation"}, None),
        ("quanser-bb01", {"zeroing_counts", "latencies_s"}, 24.0),  # the SRV02's amplifier: 24 V rails
    ],
)
def test_checks_the_rigs_parts_do_not_have_are_not_applicable(
    name: str, missing: set[str], rail_v: float | None
) -> None:
    rig = preset(name)
    b = rig_battery(rig)
    assert set(b.not_applicable) == missing
    assert b.zeroing_field is None and b.latency_field is None and b.rail_v == rail_v
    assert (
        f"parts.angle_sensor = {rig.parts.angle_sensor!r} has no zeroing error"
        in b.not_applicable["zeroing_counts"]
    )
    assert f"parts.io_board = {rig.parts.io_board!r} has no output latency" in b.not_applicable["latencies_s"]
    # only the free run is tried: 0, 10, 20, 40 ms at the 20 ms boards
    cases = validate_module._sensitivity_cases(default_criteria(rig), rig)
    assert [(n, label) for n, label, _ in cases] == [
        ("start.free_run_s", "0 ms"),
        ("start.free_run_s", "10 ms"),
        ("start.free_run_s", "20 ms"),
        ("start.free_run_s", "40 ms"),
    ]


@pytest.mark.quick
def test_a_criteria_file_overrides_the_rigs_defaults_not_the_thesiss(tmp_path: Path) -> None:
    rig = preset("open-ball-and-beam")
    path = tmp_path / "criteria.toml"
    path.write_text("nominal_seeds = 1\n")
    c = load_criteria(path, rig)
    assert c == replace(default_criteria(rig), nominal_seeds=1)
    assert c.region_x0 == (-0.08595, 0.08595, 17)


# A controller that cannot hold: it keeps the servo at 1800 µs (the beam about 3° up at its tip), so the
# ball rolls to the hinge's end and off the track from every start.
TILTED = """
from twin.interface import Controller


class Tilted(Controller):
    name = "tilted"

    def start(self, sample):
        pass

    def update(self, sample):
        return 1800.0
"""

# Tiny criteria (about 10 s of computing): 6 nominal starts at 5 s, a 3 × 3 region at 4 s, two free runs.
TINY = {
    "nominal_seeds": 1,
    "duration_s": 5.0,
    "region_x0": (-0.06, 0.06, 3),
    "region_theta0": (-0.06, 0.03, 3),
    "required_x0_m": (-0.03, 0.03),
    "required_theta0_rad": (-0.03, 0.03),
    "region_duration_s": 4.0,
    "free_runs_s": (0.0,),
}


def test_a_small_validation_of_open_ball_and_beam_gives_its_runs_verdict(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "tilted_controller.py").write_text(textwrap.dedent(TILTED))
    monkeypatch.syspath_prepend(str(tmp_path))
    rig = preset("open-ball-and-beam")
    criteria = replace(default_criteria(rig), **TINY)
    # a thesis spread: it varies the motor and amplifier, which no part of this rig uses
    spread = load_spread(ROOT / "docs" / "examples" / "spread.toml", rig)

    held = validate("rig-lqg", rig, criteria, engine="mujoco")
    tilted = validate("tilted_controller:Tilted", rig, criteria, spread=spread, engine="mujoco")

    checks = {c.name: c for c in tilted.checks}
    assert not tilted.passed
    assert checks["nominal"].passed is False and checks["nominal"].measured == "held 0 of 6"
    assert all(r["ball_lost"] for r in checks["nominal"].rows)
    assert checks["region"].passed is False
    assert checks["sensitivity: start.free_run_s"].passed is False
    for name in ("saturation", "sensitivity: zeroing error", "sensitivity: output latency"):
        assert checks[name].passed is None and checks[name].measured.startswith("not applicable: ")
    for name in ("robust region", "monte carlo"):
        assert checks[name].passed is None
        assert checks[name].measured.startswith("not applicable: the spread")
        assert "which no part of this rig uses" in checks[name].measured
    text = render_markdown(tilted)
    assert "**Verdict: FAIL**" in text and "| saturation | not applicable |" in text
    assert "## The rig" in text and "the whole track less the ball's radius at 17 points" in text

    # the same battery under the rig's own LQG: every run it makes is held, so it passes
    good = {c.name: c for c in held.checks}
    assert held.passed, [(c.name, c.measured) for c in held.checks]
    assert good["nominal"].measured == "held 6 of 6"
    assert good["robust region"].passed is None and good["robust region"].measured.startswith("not run")
    assert held.to_json()["rig"]["parts"]["actuator"] == "hobby_servo"


def test_the_region_falls_back_to_mujoco_on_whatever_the_kernel_refuses(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """validate asks ``twin.screen.plant.kernel_refusal`` (through the backends' stand-in) at each call: a rig
    the fast engine refuses has its region decided by MuJoCo alone, and the report says why."""
    import twin.screen.plant

    reason = "parts.beam_drive = 'end_lever': refused here for the test"
    monkeypatch.setattr(twin.screen.plant, "kernel_refusal", lambda params: reason)
    rig = preset("open-ball-and-beam")
    report = validate("rig-lqg", rig, replace(default_criteria(rig), **TINY), engine="screen")
    assert report.region is not None and report.region.screening is None
    region = next(c for c in report.checks if c.name == "region")
    assert region.measured.endswith(f"(MuJoCo alone: the fast engine refuses this rig: {reason})")
    assert {p["engine"] for p in report.region.points if p} == {"mujoco"}  # every start decided by MuJoCo


def test_a_stepper_rigs_batch_runs_are_its_single_runs() -> None:
    """The batch engine cannot step the stepper's law between MuJoCo's steps, so ``run_batch`` (every run of
    a validation) runs such a rig one run at a time: each result is ``run_closed_loop``'s with its seed."""
    import numpy as np

    from controllers.rig_lqg import rig_lqg
    from twin.app.hosts import catalogue_for
    from twin.rigs.batch import run_batch
    from twin.rigs.sim import run_closed_loop

    rig = preset("arduino-stepper-ultrasonic")
    starts = ((0.05, 0.0), (-0.03, 0.02))
    batch = run_batch(
        catalogue_for("rig-lqg", rig, None),
        "rig-lqg",
        x0_m=np.array([s[0] for s in starts]),
        theta0_rad=np.array([s[1] for s in starts]),
        seeds=np.array([7, 8]),
        duration_s=1.0,
        params=rig,
    )
    for (x0, th0), seed, result in zip(starts, (7, 8), batch, strict=True):
        alone = run_closed_loop(rig_lqg(rig), x0_m=x0, theta0_rad=th0, duration_s=1.0, seed=seed, params=rig)
        assert result.verdict == alone.verdict
