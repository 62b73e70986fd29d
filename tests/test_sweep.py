"""Region-of-attraction sweeps: every point is the single run it stands for (same seed, same verdict),
chunking and workers (local processes, a Dask cluster) change nothing, an interrupted sweep keeps what it
did, and the chapter 7 claims are judged from the map."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import twin.app.fanout as fanout
import twin.app.sweep_render as sweep_render_module
from controllers import registry
from twin.app.cli import main
from twin.app.sweep import (
    CLAIMS,
    Grid,
    SweepSettings,
    parse_range,
    point_seeds,
    run_sweep,
    verdict_class,
)
from twin.app.sweep_render import render_map, write_sweep
from twin.parameters import ParameterError
from twin.rigs.sim import run_closed_loop

SMALL = SweepSettings(
    controller="appendix-sf", x0=Grid(-0.3, 0.3, 3), theta0=Grid(0.0, 0.6, 3), duration_s=2.0, noise=True
)


@pytest.mark.quick
@pytest.mark.parametrize(
    ("text", "grid"),
    [("-0.3:0.3:7", Grid(-0.3, 0.3, 7)), ("0.1", Grid(0.1, 0.1, 1)), ("0:0:1", Grid(0.0, 0.0, 1))],
)
def test_ranges_parse(text: str, grid: Grid) -> None:
    assert parse_range("--x0", text) == grid


@pytest.mark.parametrize("text", ["", "a:b:c", "0.3:-0.3:5", "0:1:0", "0:1", "nan:1:3", "0:1:2.5", "0:inf:3"])
def test_bad_ranges_are_refused_naming_the_option(text: str) -> None:
    with pytest.raises(ParameterError, match="--x0"):
        parse_range("--x0", text)


@pytest.mark.quick
def test_point_seeds_depend_on_the_seed_and_the_index_only() -> None:
    assert np.array_equal(point_seeds(7, 10)[:5], point_seeds(7, 5))
    assert len(set(point_seeds(7, 1000).tolist())) == 1000
    assert not np.array_equal(point_seeds(7, 5), point_seeds(8, 5))


def test_every_point_is_its_single_run() -> None:
    """Grid order (x0 outer, θ0 inner), seeds and verdicts: each point equals run_closed_loop from the
    same start with the same seed (the claims' corner states are extra runs, not grid points)."""
    result = run_sweep(SMALL)
    assert result.complete and len(result.points) == 9
    seeds = point_seeds(SMALL.seed, 9 + len(result.corners))
    for k, point in enumerate(result.points):
        x, th = SMALL.x0.values()[k // 3], SMALL.theta0.values()[k % 3]
        assert (point["x0_m"], point["theta0_rad"], point["seed"]) == (x, th, seeds[k])
        single = run_closed_loop(
            registry.make("appendix-sf"), x0_m=x, theta0_rad=th, duration_s=2.0, seed=int(seeds[k])
        )
        assert {key: point[key] for key in single.verdict.to_json()} == single.verdict.to_json()


@pytest.mark.slow
def test_chunks_and_workers_change_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    whole = run_sweep(SMALL).to_json()
    monkeypatch.setattr(fanout, "MIN_BATCH_RUNS", 2)
    monkeypatch.setattr(fanout, "MAX_BATCH_RUNS", 2)
    assert run_sweep(SMALL).to_json() == whole
    assert run_sweep(SMALL, workers=2).to_json() == whole


@pytest.mark.slow
def test_a_dask_cluster_gives_the_local_result() -> None:
    """Brute force and screened (the fast engine on the workers, MuJoCo confirming)."""
    distributed = pytest.importorskip("distributed")
    screened = replace(SMALL, engine="screen", screen_audit=2)
    local = [run_sweep(SMALL).to_json(), run_sweep(screened).to_json()]
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        remote = [run_sweep(s, scheduler=cluster.scheduler_address).to_json() for s in (SMALL, screened)]
    assert remote == local
    assert {p["engine"] for p in local[1]["points"]} <= {"fast", "mujoco"}


def test_an_interrupted_sweep_keeps_the_points_done(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(fanout, "MIN_BATCH_RUNS", 4)
    monkeypatch.setattr(fanout, "MAX_BATCH_RUNS", 4)
    real = fanout.run_chunk
    calls = []

    def interrupted(chunk):
        calls.append(chunk)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(chunk)

    monkeypatch.setattr(fanout, "run_chunk", interrupted)
    result = run_sweep(SMALL)
    assert not result.complete
    assert [bool(p) for p in result.points] == [True] * 4 + [False] * 5
    assert result.to_json()["summary"]["done"] == 4


def test_the_claims_are_judged_from_the_points() -> None:
    """A grid on the state-feedback claim's rectangle: the verdict is 'holds' exactly when no start inside
    loses the ball; the corner at 0.33 m lies beyond the beam's end (0.323 m) and is noted, not run."""
    settings = SweepSettings(
        controller="appendix-sf",
        x0=Grid(-0.25, 0.3, 3),
        theta0=Grid(0.2, 0.68, 3),
        duration_s=3.0,
        noise=False,
    )
    result = run_sweep(settings)
    (claim,) = result.claims
    assert claim["grid_points_inside"] == 9
    lost = sum(p["ball_lost"] for p in result.points)
    assert claim["kept"] == 9 - lost
    assert claim["verdict"] == ("holds" if lost == 0 else "fails")
    far = next(c for c in claim["corners"] if c["x0_m"] == 0.33)
    assert far["kept"] is None and "not on this rig" in far["note"]
    near = next(c for c in claim["corners"] if c["x0_m"] == -0.25)
    single = run_closed_loop(
        registry.make("appendix-sf"),
        x0_m=-0.25,
        theta0_rad=0.2,
        duration_s=3.0,
        noise=False,
        seed=int(point_seeds(0, 10)[9]),
    )
    assert near["kept"] == (not single.verdict.ball_lost)
    assert {c.applies_to for c in CLAIMS if "appendix-clp" in c.applies_to}


@pytest.mark.quick
def test_the_map_and_json_are_written_atomically(tmp_path: Path) -> None:
    result = run_sweep(SMALL)
    out = write_sweep(result, tmp_path / "roa")
    data = json.loads((out / "sweep.json").read_text())
    assert data["summary"]["points"] == 9 and len(data["points"]) == 9
    assert (out / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(FileExistsError, match="not overwritten"):
        write_sweep(result, out)
    (out / "mine.txt").write_text("kept")

    def broken(result, path):
        raise RuntimeError("disk full")

    sweep_module_render = sweep_render_module.render_map
    try:
        sweep_render_module.render_map = broken  # type: ignore[assignment]
        with pytest.raises(RuntimeError):
            write_sweep(result, out, overwrite=True)
    finally:
        sweep_render_module.render_map = sweep_module_render
    assert (out / "mine.txt").read_text() == "kept"  # a failed write leaves the old directory
    assert render_map is sweep_module_render


@pytest.mark.quick
def test_the_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "roa"
    args = [
        "sweep",
        "--controller",
        "appendix-clp",
        "--x0",
        "-0.1:0.1:2",
        "--theta0",
        "0:0.2:2",
        "--duration",
        "1",
    ]
    assert main([*args, "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["summary"]["points"] == 4
    assert json.loads((out / "sweep.json").read_text()) == printed
    assert main([*args, "--out", str(out)]) == 2
    assert "exists; not overwritten" in capsys.readouterr().err
    assert main(["sweep", "--controller", "appendix-clp", "--x0", "0.5:-0.5:3"]) == 2
    assert "--x0 '0.5:-0.5:3'" in capsys.readouterr().err
    assert main(["sweep", "--controller", "appendix-clp", "--x0", "-0.4:0.4:3", "--duration", "1"]) == 2
    assert "the grid leaves the rig" in capsys.readouterr().err
    assert main(["sweep", "--controller", "nope"]) == 2
    assert "unknown controller" in capsys.readouterr().err


FRAGILE = '''
from twin.interface import Controller, DaqSample


class Fragile(Controller):
    """Holds the command at zero volts at the motor; raises when the ball starts above 2.5 V."""

    name = "fragile"

    def start(self, sample: DaqSample) -> None:
        if sample.ball_v > 2.5:
            raise RuntimeError("ball reading above 2.5 V")

    def update(self, sample: DaqSample) -> float:
        return 2.5
'''


@pytest.mark.quick
def test_a_failing_controller_fails_its_own_run_not_the_sweep(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "fragile_ctrl.py").write_text(FRAGILE)
    monkeypatch.syspath_prepend(str(tmp_path))
    settings = SweepSettings(
        controller="fragile_ctrl:Fragile", x0=Grid(-0.2, 0.2, 2), theta0=Grid(0.0, 0.0, 1), duration_s=1.0
    )
    result = run_sweep(settings)
    assert result.complete
    failed = [p for p in result.points if p["failed"]]
    assert len(failed) == 1 and "raised RuntimeError" in failed[0]["reason"] and not failed[0]["held"]
    assert result.to_json()["summary"]["failed"] == 1


@pytest.mark.parametrize(
    "controller",
    ["appendix-sf", pytest.param("appendix-clp", marks=pytest.mark.study)],  # clp: ~1 min
)
def test_a_refined_map_is_the_brute_force_map(controller: str) -> None:
    """--refine runs a coarse grid and only the cells whose corners disagree: every start's class is brute
    force's, every start it ran has brute force's record, at a fraction of the runs."""
    grid = {"x0": Grid(-0.32, 0.32, 17), "theta0": Grid(-0.7, 0.7, 15), "duration_s": 10.0}
    brute = run_sweep(SweepSettings(controller, **grid), nthread=2)  # type: ignore[arg-type]
    refined = run_sweep(SweepSettings(controller, **grid, refine=4, audit=20), nthread=2)  # type: ignore[arg-type]
    assert refined.complete and refined.refinement is not None
    assert [verdict_class(p) for p in refined.points] == [verdict_class(p) for p in brute.points]
    for b, r in zip(brute.points, refined.points, strict=True):
        if not r.get("inferred"):
            assert r == b
    ref = refined.refinement
    assert ref["run"] + ref["inferred"] == len(brute.points) and ref["run"] < len(brute.points)
    assert ref["audit"]["checked"] == 20 and ref["audit"]["mismatches"] == []
    assert refined.claims == brute.claims or [c["verdict"] for c in refined.claims] == [
        c["verdict"] for c in brute.claims
    ]


def _synthetic_map(monkeypatch: pytest.MonkeyPatch, lost: set[tuple[int, int]]) -> None:
    """run_starts on a map of no physics: grid start (i, j) of a 17 × 17 grid (4 cm steps) loses the ball
    exactly where (i, j) is in ``lost``."""

    def fake_run_starts(runs, starts, seeds, **kw):  # type: ignore[no-untyped-def]
        out = []
        for x0, th0 in starts.tolist():
            bad = (round((x0 + 0.32) / 0.04), round((th0 + 0.32) / 0.04)) in lost
            out.append({"x0_m": x0, "theta0_rad": th0, "held": not bad, "ball_lost": bad, "failed": False})
        return out, True

    monkeypatch.setattr("twin.app.sweep.run_starts", fake_run_starts)


SYNTHETIC = SweepSettings("lqr", Grid(-0.32, 0.32, 17), Grid(-0.32, 0.32, 17), refine=4)


@pytest.mark.quick
def test_refinement_follows_a_boundary_between_coarse_starts_and_audits_the_assumption(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Coarse step 4 on 17 × 17: a lost disc about the coarse start (8, 8) with a one-start-wide finger down
    to the edge, which slips between the coarse starts (8, 4) and (12, 4), both held: the trace follows it
    from the disc, every finger start run. An island between coarse starts is missed, as the README says,
    and the audit reports it (and runs it)."""
    nt = 17
    disc = {(i, j) for i in range(17) for j in range(17) if (i - 8) ** 2 + (j - 8) ** 2 < 2.5**2}
    finger = {(10, j) for j in range(9)}
    island = (14, 2)  # between the coarse starts (12, 0), (16, 0), (12, 4), (16, 4), all held
    _synthetic_map(monkeypatch, disc | finger | {island})
    result = run_sweep(SYNTHETIC)
    classes = {(k // nt, k % nt): verdict_class(p) for k, p in enumerate(result.points)}
    assert all(classes[c] == "lost" and not result.points[c[0] * nt + c[1]].get("inferred") for c in finger)
    assert {c for c, cls in classes.items() if cls == "lost"} == disc | finger  # all but the island
    assert result.refinement is not None and result.refinement["run"] < 17 * 17 / 2
    assert classes[island] == "held" and result.points[island[0] * nt + island[1]]["inferred"]
    assert "every start run around its region" in result.points[island[0] * nt + island[1]]["reason"]
    audited = run_sweep(replace(SYNTHETIC, audit=1000))
    assert audited.refinement is not None
    mismatches = audited.refinement["audit"]["mismatches"]
    assert [(m["inferred"], m["run"]) for m in mismatches] == [("held", "lost")]
    assert verdict_class(audited.points[island[0] * nt + island[1]]) == "lost"
    assert audited.refinement["inferred"] == 0  # every inferred start was audited


def test_a_region_whose_run_neighbours_disagree_has_its_rim_traced(monkeypatch: pytest.MonkeyPatch) -> None:
    """A lost blob on the map's corner whose boundary the bisection and the trace leave partly unseen: the
    starts not run next to it border both classes, so their rim is traced until the map is exact."""
    rows = {16: range(13, 15), 15: range(12, 16), 14: range(11, 17), 13: range(11, 17), 12: range(12, 16)}
    blob = {(i, j) for j, xs in rows.items() for i in xs}
    _synthetic_map(monkeypatch, blob)
    result = run_sweep(SYNTHETIC)
    assert {(k // 17, k % 17) for k, p in enumerate(result.points) if verdict_class(p) == "lost"} == blob
    assert result.refinement is not None and result.refinement["rim_run"] > 0


# --- --locate: the boundary to a fraction of a grid step ---------------------------------------------------
EDGE_X0_M, EDGE_THETA0_RAD = 0.0517, 0.1333  # off the grid's starts and off every bisection point


def _threshold_map(monkeypatch: pytest.MonkeyPatch) -> None:
    """run_starts on a map of no physics: the ball is lost exactly where x0 > EDGE_X0_M or θ0 > EDGE_THETA0_RAD,
    at any start, on the grid or off it."""

    def fake_run_starts(runs, starts, seeds, **kw):  # type: ignore[no-untyped-def]
        out = []
        for x0, th0 in starts.tolist():
            bad = x0 > EDGE_X0_M or th0 > EDGE_THETA0_RAD
            out.append(
                {"x0_m": x0, "theta0_rad": th0, "held": not bad, "ball_lost": bad, "failed": False}
                | {"settling_time_s": None if bad else 3.0}
            )
        return out, True

    monkeypatch.setattr("twin.app.sweep.run_starts", fake_run_starts)


@pytest.mark.quick
@pytest.mark.parametrize("refine", [0, 4])
def test_locate_brackets_a_known_boundary_to_the_stated_fraction(
    monkeypatch: pytest.MonkeyPatch, refine: int
) -> None:
    """A boundary at x0 = 0.0517 m (for θ0 below 0.1333 rad) and at θ0 = 0.1333 rad: on a 17 × 17 grid (4 cm
    steps) --locate 4 brackets every crossing within 1/16 of a step (2.5 mm, 2.5 mrad) of where it is, with
    4 runs per crossed edge, brute force or refined alike."""
    _threshold_map(monkeypatch)
    result = run_sweep(replace(SYNTHETIC, refine=refine, locate=4))
    boundary = result.boundary
    assert result.complete and boundary is not None
    # Crossed edges: along x0 between 0.04 and 0.08 for the θ0 rows up to 0.12 (12 rows), along θ0 between
    # 0.12 and 0.16 for the x0 columns up to 0.04 (10 columns).
    assert boundary["edges"] == 12 + 10 and boundary["run"] == 4 * 22
    assert boundary["resolution"] == pytest.approx({"x0_m": 0.04 / 16, "theta0_rad": 0.04 / 16})
    for c in boundary["crossings"]:
        axis, edge = (0, EDGE_X0_M) if c["along"] == "x0" else (1, EDGE_THETA0_RAD)
        (a, b) = (c["between"][0][axis], c["between"][1][axis])
        assert a <= edge < b and b - a == pytest.approx(0.04 / 16)
        assert c["classes"] == ["held", "lost"] and abs(c["at"][axis] - edge) <= 0.04 / 32
    if refine:
        brute = run_sweep(replace(SYNTHETIC, refine=0, locate=4))
        assert brute.boundary == boundary


def test_locate_on_the_twin_nests_and_each_end_is_its_single_run() -> None:
    """appendix-sf on a 9 × 7 grid, 10 s, noise on: a deeper --locate repeats the shallower one's runs (its
    intervals lie inside), and the two ends of a located crossing are the single runs from those starts with
    the seeds locate_seed gives."""
    from fractions import Fraction

    from twin.app.sweep import locate_seed

    grid = SweepSettings("appendix-sf", Grid(-0.32, 0.32, 9), Grid(-0.7, 0.7, 7), duration_s=10.0)
    two = run_sweep(replace(grid, locate=2), nthread=2)
    three = run_sweep(replace(grid, locate=3), nthread=2)
    assert two.boundary is not None and three.boundary is not None and two.boundary["edges"] > 0
    assert two.points == three.points and two.boundary["edges"] == three.boundary["edges"]
    for c2, c3 in zip(two.boundary["crossings"], three.boundary["crossings"], strict=True):
        assert c2["grid_starts"] == c3["grid_starts"]
        assert c2["t"][0] <= c3["t"][0] < c3["t"][1] <= c2["t"][1] and c3["t"][1] - c3["t"][0] == 1 / 8
    c = next(c for c in three.boundary["crossings"] if 0 < c["t"][0] and c["t"][1] < 1)  # two off-grid ends
    k, n = c["grid_starts"]
    for (x, th), t, cls in zip(c["between"], c["t"], c["classes"], strict=True):
        single = run_closed_loop(
            registry.make("appendix-sf"),
            x0_m=x,
            theta0_rad=th,
            duration_s=10.0,
            seed=locate_seed(grid.seed, k, n, Fraction(t)),
        )
        record = {"failed": False, "held": single.verdict.held, "ball_lost": single.verdict.ball_lost}
        assert verdict_class(record) == cls


def test_locate_in_the_command(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _threshold_map(monkeypatch)
    args = ["sweep", "--controller", "lqr", "--x0", "-0.32:0.32:17", "--theta0", "-0.32:0.32:17"]
    assert main([*args, "--locate", "3", "--out", str(tmp_path / "m")]) == 0
    assert "boundary: 22 grid edges crossed, each located to 1/8 of a grid step (66 more runs)" in (
        capsys.readouterr().out
    )
    data = json.loads((tmp_path / "m" / "sweep.json").read_text())
    assert data["boundary"]["bisections"] == 3 and len(data["boundary"]["crossings"]) == 22
    assert main([*args, "--locate", "13"]) == 2
    assert "--locate" in capsys.readouterr().err
    assert main([*args, "--locate", "2", "--rigs", "3", "--spread", "docs/examples/spread.toml"]) == 2
    assert "not with a robust map" in capsys.readouterr().err
