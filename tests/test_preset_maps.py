"""A preset's map (screened, MuJoCo confirming, classes equal to brute force): the map's
axes follow the rig's track and travel (``twin.app.sweep.rig_grids``), the Open Ball & Beam map screened by the
fast engine (its beam hinged off the track's centre) has brute force's classes, and scripts/preset_maps.py
refuses a folder with something in it."""

from __future__ import annotations

import importlib.util
import math
from dataclasses import replace
from pathlib import Path
from types import ModuleType

import pytest

import twin.parts  # noqa: F401  (registers the parts)
from twin.app.sweep import (
    DEFAULT_THETA0,
    DEFAULT_X0,
    Grid,
    SweepSettings,
    rig_grids,
    run_sweep,
    verdict_class,
)
from twin.parameters import Parameters
from twin.parts.description import preset
from twin.parts.linkage import Linkage
from twin.physics import check_initial_state


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "preset_maps", Path(__file__).resolve().parents[1] / "scripts" / "preset_maps.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _horn_of(theta: float, link: Linkage) -> float:
    """The horn's angle φ (about its neutral) that holds the beam at θ, by bisection on the closure
    |A(θ) − C(φ)| = r from 1.6 rad below the neutral to 1.0 rad above it (the rod too long at one end, too short
    at the other; the dead point lies just past +0.98 rad), independent of the code's closed form."""

    def gap(phi: float) -> float:
        ax, az = link.beam_arm_m * math.cos(theta), link.beam_arm_m * math.sin(theta)
        cx = link.shaft_x_m + link.crank_m * math.cos(phi)
        cz = link.shaft_z_m + link.crank_m * math.sin(phi)
        return math.hypot(ax - cx, az - cz) - link.rod_m

    a, b = link.horn_neutral_rad - 1.6, link.horn_neutral_rad + 1.0
    assert gap(a) > 0.0 > gap(b)
    for _ in range(200):
        mid = 0.5 * (a + b)
        if (gap(mid) > 0.0) == (gap(a) > 0.0):
            a = mid
        else:
            b = mid
    return 0.5 * (a + b) - link.horn_neutral_rad


@pytest.mark.quick
def test_a_maps_axes_are_the_chapter_7_grid_on_the_thesis_and_the_rigs_travel_elsewhere() -> None:
    """The thesis keeps the chapter 7 grid. Open Ball & Beam: its 2 × 0.105 m track less the 19.05 mm ball's
    radius at each end (the rail holders stop the ball's centre there), and its beam's travel,
    whose ends are where the horn reaches its ±0.98 rad (checked here on the closure solved by bisection); every
    corner of the grid is a start the rig accepts."""
    assert rig_grids(Parameters()) == (DEFAULT_X0, DEFAULT_THETA0)
    obb = preset("open-ball-and-beam")
    x0, theta0 = rig_grids(obb)
    assert (x0.lo, x0.hi, x0.n) == pytest.approx((-0.08595, 0.08595, 41), abs=1e-12) and theta0.n == 41
    link = obb.of(Linkage)
    travel = link.horn_travel_rad
    # the lever lifts the beam as the horn turns up (sense +1): its low end at −travel, its high end at +travel
    assert _horn_of(theta0.lo, link) == pytest.approx(-travel, abs=1e-7)
    assert _horn_of(theta0.hi, link) == pytest.approx(travel, abs=1e-7)
    for x in (x0.lo, x0.hi):
        for th in (theta0.lo, theta0.hi):
            check_initial_state(obb, x, th, 0.0, 0.0)


@pytest.mark.quick
def test_the_script_screens_the_presets_the_fast_engine_runs_and_refuses_a_folder_in_use(
    tmp_path: Path,
) -> None:
    script = _script()
    names = script.screenable()
    assert "open-ball-and-beam" in names and "thesis" in names
    assert "arduino-stepper-ultrasonic" in names  # the stepper's kernel form: tests/test_screen_stepper.py
    (tmp_path / "old.json").write_text("{}")
    with pytest.raises(SystemExit, match="not an empty folder"):
        script.main(["--out", str(tmp_path)])


@pytest.mark.slow
def test_open_ball_and_beams_screened_and_refined_maps_are_the_brute_force_map() -> None:
    """rig-lqg on Open Ball & Beam, a 9 × 9 map over the rig's track and travel, 6 s runs: screened (the fast engine,
    MuJoCo near every class change and on an audit sample) and refined (--refine 4: the coarse 3 × 3, then the
    boundary's cells), each start's class brute force's; every start MuJoCo ran is brute force's record."""
    obb = preset("open-ball-and-beam")
    x0, theta0 = rig_grids(obb, 9)
    base = SweepSettings("rig-lqg", x0, theta0, duration_s=6.0)
    brute = run_sweep(base, obb, nthread=2)
    classes = [verdict_class(p) for p in brute.points]
    assert len(set(classes)) > 1  # a map with a boundary: the screen has something to confirm
    screened = run_sweep(replace(base, engine="screen", screen_audit=8), obb, nthread=2)
    assert screened.complete and screened.screening is not None
    assert [verdict_class(p) for p in screened.points] == classes
    assert screened.screening["audit"]["mismatches"] == []
    for s, b in zip(screened.points, brute.points, strict=True):
        if s["engine"] == "mujoco":
            assert s == b
    assert 0 < screened.screening["decided_by_fast"]
    refined = run_sweep(replace(base, refine=4), obb, nthread=2)
    assert [verdict_class(p) for p in refined.points] == classes


@pytest.mark.quick
def test_the_grid_of_another_rig_is_refused_off_its_track() -> None:
    """The chapter 7 grid on Open Ball & Beam leaves its 0.105 m track: refused naming it, not run."""
    from twin.parameters import ParameterError

    with pytest.raises(ParameterError, match="the grid leaves the rig"):
        run_sweep(
            SweepSettings("rig-lqg", Grid(-0.32, 0.32, 3), Grid(-0.1, 0.05, 3)), preset("open-ball-and-beam")
        )
