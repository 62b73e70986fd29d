"""An option is applied or refused, never silently ignored: an option that only matters with another (or
with an engine, a mode, an output) given without it is refused before any work (exit 2, one line naming the
option and its value), and so is a flick the run would not apply or the live view would refuse."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_checks import refused

from twin.app.cli import main
from twin.viewer.common import FLICK

ROOT = Path(__file__).resolve().parents[1]
SPREAD = str(ROOT / "docs" / "examples" / "spread.toml")
FALSIFY_SPEC = str(ROOT / "docs" / "examples" / "falsify.toml")
SF = ["--controller", "appendix-sf"]
RUN = ["run", *SF, "--x0", "0.1", "--theta0", "0", "--duration", "2"]
RIG = ["run", *SF, "--rig", "udp://127.0.0.1:9"]
FALSIFY = ["falsify", *SF, "--spec", FALSIFY_SPEC, "--x0", "0.1:0.2", "--theta0", "-0.1:0"]
MC = ["montecarlo", *SF, "--spread", SPREAD]
SERVE = ["serve", "--x0", "0", "--theta0", "0"]

CASES: dict[str, tuple[list[str], tuple[str, ...]]] = {
    # a flick: both options, within the run, within the live view's Flick range (either way)
    "flick time alone": ([*RUN, "--flick-time", "1"], ("--flick-time 1", "--flick-speed")),
    "flick speed alone": ([*RUN, "--flick-speed", "0.3"], ("--flick-speed 0.3", "--flick-time")),
    "flick after the run": ([*RUN, "--flick-time", "5", "--flick-speed", "0.1"], ("--flick-time 5", "2 s")),
    "flick at the end": ([*RUN, "--flick-time", "2", "--flick-speed", "0.1"], ("--flick-time 2", "end")),
    "flick of 0": ([*RUN, "--flick-time", "1", "--flick-speed", "0"], ("--flick-speed 0", "0.02…0.5 m/s")),
    "flick of 1000": ([*RUN, "--flick-time", "1", "--flick-speed", "1000"], ("--flick-speed 1000",)),
    "flick of -0.6": ([*RUN, "--flick-time", "1", "--flick-speed", "-0.6"], ("--flick-speed -0.6",)),
    "falsify flick alone": ([*FALSIFY, "--flick-time", "1:2"], ("--flick-time 1:2", "--flick-speed")),
    "falsify flick late": ([*FALSIFY, "--flick-time", "1:50", "--flick-speed", "0.1"], ("--flick-time 1:50",)),
    "falsify kick range": ([*FALSIFY, "--flick-time", "1", "--flick-speed", "0:1000"], ("--flick-speed 0:1000",)),
    "falsify tiny kicks": ([*FALSIFY, "--flick-time", "1", "--flick-speed", "0:0.01"], ("--flick-speed 0:0.01",)),
    # the search: a generation larger than the budget
    "population above budget": ([*FALSIFY, "--budget", "10", "--population", "20"], ("--population 20", "--budget 10")),
    # the screen engine's band and audit
    "band with mujoco": (["sweep", *SF, "--engine", "mujoco", "--band", "3"], ("--band 3", "mujoco")),
    "band with fast": (["sweep", *SF, "--engine", "fast", "--band", "3"], ("--band 3", "fast")),
    "band with refine": (["sweep", *SF, "--refine", "6", "--band", "2"], ("--band 2", "mujoco")),
    "validate band fast": (["validate", *SF, "--engine", "fast", "--band", "2"], ("--band 2", "fast")),
    "audit with mujoco": ([*MC, "--engine", "mujoco", "--audit", "3"], ("--audit 3", "--engine screen or fast")),
    "audit by default": ([*MC, "--audit", "3"], ("--audit 3",)),
    # what a run on a rig over the wire leaves to the server
    "rig x0": ([*RIG, "--x0", "0.1"], ("--x0 0.1", "--rig")),
    "rig duration": ([*RIG, "--duration", "3"], ("--duration 3", "--rig")),
    "rig seed": ([*RIG, "--seed", "4"], ("--seed 4", "--rig")),
    "rig no noise": ([*RIG, "--no-noise"], ("--no-noise", "--rig")),
    "rig plant": ([*RIG, "--plant", "reference"], ("--plant reference", "--rig")),
    "rig realtime": ([*RIG, "--realtime"], ("--realtime", "--rig")),
    "rig setpoint": ([*RIG, "--setpoint", "0.05"], ("--setpoint 0.05", "--rig")),
    "rig flick": ([*RIG, "--flick-time", "1", "--flick-speed", "0.1"], ("--flick-time 1", "--rig")),
    "rig plot": ([*RIG, "--plot", "p.png"], ("--plot p.png", "--rig")),
    # --overwrite with nothing to overwrite
    "run overwrite": ([*RUN, "--overwrite"], ("--overwrite", "--log or --plot")),
    "sweep overwrite": (["sweep", *SF, "--overwrite"], ("--overwrite", "--out")),
    "montecarlo overwrite": ([*MC, "--overwrite"], ("--overwrite", "--out")),
    "calibrate overwrite": (["calibrate", "x.mat", "--fit", "motor.resistance_ohm", "--overwrite"], ("--overwrite",)),
    "serve overwrite": ([*SERVE, "--overwrite"], ("--overwrite", "--log")),
    # a scheduler's workers are its own; a lock-step server has no watchdog; JSON has nothing to quieten
    "scheduler workers": (["sweep", *SF, "--scheduler", "tcp://h:1", "--workers", "2"], ("--workers 2", "--scheduler")),
    "watchdog in lockstep": ([*SERVE, "--watchdog", "3"], ("--watchdog 3", "--mode realtime")),
    "shadow quiet json": (["shadow", "--rig", "udp://127.0.0.1:9", "--quiet", "--json"], ("--quiet", "--json")),
}  # fmt: skip


@pytest.fixture
def nothing_starts(monkeypatch: pytest.MonkeyPatch, no_work: None) -> None:
    """Beyond ``no_work``: a search, a certification, a server, an observer or a rig session that starts
    fails the test."""

    def fail(*args: object, **kwargs: object) -> None:
        raise AssertionError("the work started although an argument was bad")

    for target in (
        "twin.app.falsify.falsify",
        "twin.app.certify.certify",
        "twin.serving.server.Server",
        "twin.serving.observer.open_observer",
        "twin.rigs.session.run_on_remote_rig",
    ):
        monkeypatch.setattr(target, fail)


@pytest.mark.quick
@pytest.mark.parametrize("case", list(CASES))
def test_an_option_that_would_be_ignored_is_refused_before_the_work(
    case: str,
    capsys: pytest.CaptureFixture[str],
    nothing_starts: None,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    argv, needles = CASES[case]
    refused(capsys, argv, *needles)


@pytest.mark.quick
def test_the_flick_bounds_are_the_live_views(
    capsys: pytest.CaptureFixture[str], nothing_starts: None
) -> None:
    line = refused(capsys, [*RUN, "--flick-time", "1", "--flick-speed", str(FLICK.high * 2)], "--flick-speed")
    assert f"{FLICK.low:g}…{FLICK.high:g} {FLICK.unit}" in line


@pytest.mark.quick
def test_the_options_in_their_place_are_accepted(nothing_starts: None) -> None:
    """The same options where they apply pass the checks (the work then starts: ``nothing_starts`` says so)."""
    applied = [
        [*RUN, "--flick-time", "1", "--flick-speed", f"{-FLICK.high:g}"],
        [
            *FALSIFY,
            "--flick-time",
            "1:2",
            "--flick-speed",
            f"{-FLICK.high:g}:{FLICK.high:g}",
            "--budget",
            "20",
        ],
        [*MC, "--engine", "fast", "--audit", "3"],
        ["sweep", *SF, "--engine", "screen", "--band", "3"],
    ]
    for argv in applied:
        with pytest.raises(AssertionError, match="work started"):
            main(argv)


@pytest.mark.quick
def test_a_flick_within_the_range_either_way_is_applied(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*RUN, "--flick-time", "1", "--flick-speed", "-0.3", "--json"]) in (0, 1)
    kicked = json.loads(capsys.readouterr().out)
    assert main([*RUN, "--json"]) in (0, 1)
    plain = json.loads(capsys.readouterr().out)
    assert kicked["peak_theta_rad"] != plain["peak_theta_rad"]  # the kick changed the run
