"""The live view's simulation side (no server): it waits for the first browser, judges the run so far with
the engine's verdict, records the run as the thesis's log, and shows the parameters that differ."""

from __future__ import annotations

import numpy as np
import pytest
from viewer_stubs import StubCatalogue

from controllers import registry
from twin.engine import update_ticks
from twin.log import load_csv, load_mat
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop
from twin.viewer import LiveTwin, parameter_changes, verdict_text


def _live(controller: str = "appendix-clp", **kwargs: object) -> LiveTwin:
    return LiveTwin(Parameters(), StubCatalogue(), controller, seed=0, speed=1.0, **kwargs)  # type: ignore[arg-type]


def _run(live: LiveTwin, seconds: float) -> None:
    for _ in range(int(round(seconds / 0.02))):
        live.tick()


def test_the_twin_waits_for_the_first_browser_and_starts_it_at_t_0() -> None:
    live = _live(wait_for_client=True)
    assert not live.running and live.awaiting_client and "waiting for a browser" in live.status_markdown()
    live.apply("connected")
    assert live.running and not live.awaiting_client and live.runs == 1 and live.rig.time_s <= 0.0
    _run(live, 0.2)
    live.apply("connected")  # a second browser joins the running twin
    assert live.runs == 1 and live.rig.time_s > 0.19


def test_the_live_verdict_is_the_engines_verdict_of_the_same_run() -> None:
    """Same controller, start, seed and noise: the live view judges exactly what `ballbeam run` judges."""
    live = _live()
    for _ in range(update_ticks(6.0, live.params)):
        live.tick()
    reference = run_closed_loop(
        registry.make("appendix-clp"), x0_m=live.x0_m, theta0_rad=live.theta0_rad, duration_s=6.0, seed=0
    )
    verdict = live.verdict()
    assert verdict is not None
    assert verdict.to_json() == reference.verdict.to_json()
    np.testing.assert_array_equal(live.loop.log().true_x_m, reference.log.true_x_m)
    assert verdict_text(verdict).startswith(
        "verdict so far: held" if verdict.held else "verdict so far: not held"
    )


def test_the_verdict_is_judged_about_the_setpoint() -> None:
    """lqr moved to x = 0.05 m: the steady offset is measured from the setpoint, not from the centre."""
    live = _live("lqr")
    live.apply("reference", 0.05)
    _run(live, 10.0)
    verdict = live.verdict()
    assert verdict is not None and verdict.steady_x_m is not None
    x = live.loop.log().true_x_m
    assert verdict.steady_x_m == pytest.approx(float(np.mean(x[-150:])) - 0.05, abs=2e-3)
    assert "about the setpoint x = +0.05 m" in verdict_text(verdict, live.setpoint_m)
    assert live.history.array("x_ref")[-1] == np.float32(0.05)


def test_a_lost_ball_pauses_and_the_banner_gives_the_verdict() -> None:
    live = _live()
    live.apply("initial", (-0.3, 0.7))
    assert live.initial_pending and "apply on Reset" in live.status_markdown()
    live.apply("reset")
    assert not live.initial_pending
    for _ in range(200):
        live.tick()
        if not live.running:
            break
    assert live.rig.ball_lost and live.lost_paused and not live.running
    banner = live.lost_banner_html()
    assert f"Ball lost at t = {live.rig.ball_lost_time_s:.2f} s" in banner and "verdict: lost" in banner
    assert abs(live.rig.true_state()[0]) < 0.4  # frozen where it left the track: the plots keep their range
    x = float(live.rig.true_state()[0])
    if abs(x) >= live.rig.params.track.half_length_m:  # the banner says which way it went
        assert f"rolled off the {'+' if x > 0 else '−'} end of the track (x = {x:+.3f} m)" in banner
    else:
        assert f"thrown off the wires at x = {x:+.3f} m, on the beam" in banner
    live.apply("initial", (0.15, 0.1))
    live.apply("reset")  # the next run goes (the pause was the lost ball's)
    assert live.running and not live.rig.ball_lost and live.lost_banner_html() == ""


@pytest.mark.parametrize("kind", ["mat", "csv"])
def test_the_record_is_the_runs_log(kind: str, tmp_path) -> None:
    live = _live()
    _run(live, 1.0)
    name, data = live.recording(kind)
    assert name == f"ballbeam_run1_appendix-clp.{kind}"
    path = tmp_path / name
    path.write_bytes(data)
    loaded = (load_mat if kind == "mat" else load_csv)(path)
    expected = live.loop.log()
    for field in ("timem", "datam1", "datam2", "aout", "x1", "true_x_m", "ball_lost"):
        np.testing.assert_array_equal(getattr(loaded, field), getattr(expected, field))
    assert loaded.k == 51  # the start sample and 50 ticks


@pytest.mark.quick
def test_the_record_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("twin.viewer.session.RECORD_LIMIT_S", 0.1)
    live = _live()
    _run(live, 0.5)
    assert live.loop.log().k == 6  # 0.1 s / 20 ms + 1: the first ticks; the run goes on
    assert live.rig.time_s > 0.45


@pytest.mark.quick
def test_a_download_of_an_unknown_format_is_refused() -> None:
    live = _live()
    received: list[tuple[str, bytes]] = []
    live.apply("download", ("xlsx", lambda name, data: received.append((name, data))))
    assert not received and live.refused == 1 and "formats are mat and csv" in live.refusals[-1].reason
    live.apply("download", ("csv", lambda name, data: received.append((name, data))))
    assert received and load_csv_bytes(received[0][1]).k == 1


def load_csv_bytes(data: bytes):
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.csv"
        path.write_bytes(data)
        return load_csv(path)


@pytest.mark.quick
def test_the_panel_lists_the_parameters_that_differ() -> None:
    assert parameter_changes(Parameters()) == []
    changed = Parameters().with_overrides({"start.free_run_s": 0.02, "ball.mass_kg": 0.03})
    assert parameter_changes(changed) == ["ball.mass_kg = 0.03", "start.free_run_s = 0.02"]


def test_the_status_says_when_the_computer_cannot_keep_up() -> None:
    live = _live()
    live.speed = 4.0
    live.achieved_speed = 3.75
    assert "speed ×4 (achieved ×3.75: this computer cannot keep up)" in live.status_markdown()
    live.achieved_speed = 3.95  # within 2 %: as asked
    assert "achieved" not in live.status_markdown()
    live.achieved_speed, live.running = 1.0, False  # paused: nothing to achieve
    assert "achieved" not in live.status_markdown()
