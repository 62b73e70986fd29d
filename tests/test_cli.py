"""The ``ballbeam`` command as a user meets it: refusals before the run, atomic outputs, numbers, help.

Every refusal is exit 2 with one line on stderr naming the bad argument, no traceback, and no file lost.
The commands run in-process (``main([...])``); a run that must not happen is replaced by one that fails.
"""

from __future__ import annotations

import argparse
import errno
import json
import os
import stat
import subprocess
import sys
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest
from cli_checks import refused as _refused

import twin.rigs.sim
from twin import outputs
from twin.app import cli
from twin.app.cli import main

ROOT = Path(__file__).resolve().parent.parent
RUN = ["run", "--controller", "appendix-clp", "--x0", "0.1", "--theta0", "0.1", "--duration", "0.2"]


@pytest.fixture
def no_run(monkeypatch: pytest.MonkeyPatch) -> None:
    """The refusal must come before the simulation: running it fails the test."""

    def fail(*args: object, **kwargs: object) -> None:
        raise AssertionError("the run started although an argument was bad")

    monkeypatch.setattr(twin.rigs.sim, "run_closed_loop", fail)


def _listing(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


# --- two outputs, one file ---------------------------------------------------------------------------------
def test_log_and_plot_naming_the_same_file_are_refused(tmp_path: Path, capsys, no_run) -> None:
    same = str(tmp_path / "X.png")
    _refused(capsys, [*RUN, "--log", same, "--plot", same], "--log", "--plot", "same file")
    # The same file spelled differently.
    other = str(tmp_path / "sub" / ".." / "X.png")
    (tmp_path / "sub").mkdir()
    _refused(capsys, [*RUN, "--log", same, "--plot", other], "same file")
    assert _listing(tmp_path) == ["sub"]


def test_a_link_to_the_log_given_as_the_plot_is_refused(tmp_path: Path, capsys, no_run) -> None:
    log = tmp_path / "run.csv"
    log.write_text("precious\n")
    (tmp_path / "run.png").symlink_to(log)
    _refused(
        capsys, [*RUN, "--log", str(log), "--plot", str(tmp_path / "run.png"), "--overwrite"], "same file"
    )
    hard = tmp_path / "hard.png"
    os.link(log, hard)
    _refused(capsys, [*RUN, "--log", str(log), "--plot", str(hard), "--overwrite"], "same file")
    assert log.read_text() == "precious\n"


# --- atomic writes ---------------------------------------------------------------------------------------
def _fail_midway_mat(monkeypatch: pytest.MonkeyPatch) -> None:
    import scipy.io

    def savemat(fh, *args: object, **kwargs: object) -> None:
        fh.write(b"MATLAB 5.0 half a file")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(scipy.io, "savemat", savemat)


def _fail_midway_csv(monkeypatch: pytest.MonkeyPatch) -> None:
    import csv

    class Writer:
        def __init__(self, text, **kwargs: object) -> None:
            self.text = text

        def writerow(self, row: list[str]) -> None:
            self.text.write("timem,half a row")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(csv, "writer", Writer)


def _fail_midway_png(monkeypatch: pytest.MonkeyPatch) -> None:
    from matplotlib.figure import Figure

    def savefig(self, fh, *args: object, **kwargs: object) -> None:
        fh.write(b"\x89PNG half an image")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Figure, "savefig", savefig)


@pytest.mark.parametrize(
    ("option", "name", "fail"),
    [
        ("--log", "run.mat", _fail_midway_mat),
        ("--log", "run.csv", _fail_midway_csv),
        ("--plot", "run.png", _fail_midway_png),
    ],
)
def test_a_failed_overwrite_keeps_the_old_file(
    tmp_path: Path, capsys, monkeypatch, option, name, fail
) -> None:
    target = tmp_path / name
    target.write_bytes(b"the old file")
    fail(monkeypatch)
    line = _refused(capsys, [*RUN, option, str(target), "--overwrite", "--json"], option, str(target))
    assert "No space left on device" in line
    assert target.read_bytes() == b"the old file"
    assert _listing(tmp_path) == [name]  # no temporary file left behind


def test_overwrite_replaces_the_files_whole_and_keeps_their_mode(tmp_path: Path, capsys) -> None:
    log, plot = tmp_path / "run.csv", tmp_path / "run.png"
    log.write_text("old")
    plot.write_text("old")
    log.chmod(0o640)
    assert main([*RUN, "--log", str(log), "--plot", str(plot), "--overwrite", "--json"]) in (0, 1)
    assert log.read_text().startswith("timem,") and plot.read_bytes().startswith(b"\x89PNG")
    assert stat.S_IMODE(log.stat().st_mode) == 0o640
    assert _listing(tmp_path) == ["run.csv", "run.png"]
    capsys.readouterr()


def test_new_outputs_get_the_usual_mode(tmp_path: Path, capsys) -> None:
    log = tmp_path / "run.mat"
    assert main([*RUN, "--log", str(log), "--json"]) in (0, 1)
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(log.stat().st_mode) == 0o666 & ~umask
    assert _listing(tmp_path) == ["run.mat"]
    capsys.readouterr()


def test_writing_through_a_link_updates_its_target(tmp_path: Path, capsys) -> None:
    real = tmp_path / "real.csv"
    real.write_text("old")
    link = tmp_path / "link.csv"
    link.symlink_to(real)
    assert main([*RUN, "--log", str(link), "--overwrite", "--json"]) in (0, 1)
    assert link.is_symlink() and real.read_text().startswith("timem,")
    capsys.readouterr()


def test_a_file_that_appears_during_the_run_is_not_replaced(tmp_path: Path, capsys, monkeypatch) -> None:
    log = tmp_path / "run.mat"
    real_run = twin.rigs.sim.run_closed_loop

    def run_and_meanwhile(*args: object, **kwargs: object) -> object:
        log.write_text("written by someone else meanwhile")
        return real_run(*args, **kwargs)

    monkeypatch.setattr(twin.rigs.sim, "run_closed_loop", run_and_meanwhile)
    _refused(capsys, [*RUN, "--log", str(log)], "--log", "exists")
    assert log.read_text() == "written by someone else meanwhile"
    assert _listing(tmp_path) == ["run.mat"]


# --- bad paths -----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv",
    [
        [*RUN, "--log", ""],
        [*RUN, "--plot", "  "],
        ["experiment", "square", "--out", ""],
        ["calibrate-static", str(ROOT / "calib" / "tables" / "table_6_3.csv"), "--out", ""],
        ["calibrate", "missing.mat", "--fit", "motor.resistance_ohm", "--out", ""],
    ],
)
def test_an_empty_path_is_refused(capsys, no_run, argv: list[str]) -> None:
    option = argv[argv.index("--out") if "--out" in argv else -2]
    _refused(capsys, argv, option, "empty")


@pytest.mark.parametrize(
    ("option", "name", "says"),
    [
        ("--log", "run.txt", "'.txt'"),
        ("--log", "run.png", "'.png'"),
        ("--log", "run", "no extension"),
        ("--plot", "run.jpg", "'.jpg'"),
        ("--plot", "run.mat", "'.mat'"),
    ],
)
def test_an_unknown_extension_is_refused(tmp_path: Path, capsys, no_run, option, name, says) -> None:
    _refused(capsys, [*RUN, option, str(tmp_path / name)], option, name, says)
    assert _listing(tmp_path) == []


def test_other_commands_check_their_extensions(tmp_path: Path, capsys) -> None:
    _refused(capsys, ["experiment", "square", "--out", str(tmp_path / "log.txt")], "--out", "'.txt'")
    table = str(ROOT / "calib" / "tables" / "table_6_3.csv")
    _refused(capsys, ["calibrate-static", table, "--out", str(tmp_path / "p.json")], "--out", "'.json'")
    assert _listing(tmp_path) == []


def test_extensions_are_not_case_sensitive(tmp_path: Path, capsys) -> None:
    assert main([*RUN, "--log", str(tmp_path / "RUN.CSV"), "--json"]) in (0, 1)
    assert (tmp_path / "RUN.CSV").read_text().startswith("timem,")
    capsys.readouterr()


def test_a_missing_directory_is_refused_before_the_run(tmp_path: Path, capsys, no_run) -> None:
    _refused(capsys, [*RUN, "--log", str(tmp_path / "nowhere" / "run.mat")], "--log", "does not exist")
    (tmp_path / "file").write_text("")
    _refused(capsys, [*RUN, "--plot", str(tmp_path / "file" / "run.png")], "--plot", "not a directory")
    (tmp_path / "dir.mat").mkdir()
    _refused(capsys, [*RUN, "--log", str(tmp_path / "dir.mat")], "--log", "is a directory")
    _refused(
        capsys,
        ["calibrate", "missing.mat", "--fit", "motor.resistance_ohm", "--out", str(tmp_path / "no" / "cal")],
        "--out",
        "does not exist",
    )


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_a_read_only_directory_is_refused_before_the_run(tmp_path: Path, capsys, no_run) -> None:
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        _refused(capsys, [*RUN, "--log", str(locked / "run.mat")], "--log", "not writable")
    finally:
        locked.chmod(0o755)


def test_an_unwritable_directory_is_refused_before_the_run(
    tmp_path: Path, capsys, no_run, monkeypatch
) -> None:
    """What os.access says (as for a user without write permission), and what the probe file finds (as on a
    read-only mount, where root too is refused)."""
    with monkeypatch.context() as m:
        m.setattr(outputs.os, "access", lambda *args, **kwargs: False)
        _refused(capsys, [*RUN, "--log", str(tmp_path / "run.mat")], "--log", "not writable")

    def read_only(*args: object, **kwargs: object) -> None:
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))

    with monkeypatch.context() as m:
        m.setattr(outputs.tempfile, "mkstemp", read_only)
        _refused(capsys, [*RUN, "--plot", str(tmp_path / "run.png")], "--plot", "Read-only file system")
    assert _listing(tmp_path) == []


def test_a_full_disk_is_refused_before_the_run(tmp_path: Path, capsys, no_run, monkeypatch) -> None:
    import shutil

    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(outputs.shutil, "disk_usage", lambda _: usage._replace(free=1000))
    line = _refused(
        capsys, [*RUN, "--duration", "60", "--log", str(tmp_path / "run.mat")], "--log", "MB free"
    )
    assert "0.4 MB" in line  # 3002 ticks of 17 float64 columns at least
    _refused(capsys, [*RUN, "--plot", str(tmp_path / "run.png")], "--plot", "MB free")
    assert _listing(tmp_path) == []


def test_a_failed_probe_write_is_refused_before_the_run(tmp_path: Path, capsys, no_run, monkeypatch) -> None:
    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(outputs.os, "fsync", full)
    _refused(capsys, [*RUN, "--log", str(tmp_path / "run.csv")], "--log", "No space left on device")
    assert _listing(tmp_path) == []  # the probe file is removed


def test_an_existing_output_is_still_refused_without_overwrite(tmp_path: Path, capsys, no_run) -> None:
    plot = tmp_path / "run.png"
    plot.write_bytes(b"keep")
    _refused(capsys, [*RUN, "--plot", str(plot)], "--plot", "exists; not overwritten (pass --overwrite)")
    assert plot.read_bytes() == b"keep"


# --- runs shorter than the verdict's window ------------------------------------------------------------
@pytest.mark.quick
@pytest.mark.parametrize("duration", ["0.05", "1"])
def test_json_works_on_runs_shorter_than_the_final_window(capsys, duration: str) -> None:
    argv = ["run", "--controller", "appendix-clp", "--x0", "0.1", "--theta0", "0", "--duration", duration]
    assert main([*argv, "--json"]) == 1
    verdict = json.loads(capsys.readouterr().out)
    assert verdict["held"] is False and "shorter than the final window" in verdict["reason"]
    for key in ("steady_x_m", "steady_theta_rad", "limit_cycle_x_pp_m", "limit_cycle_theta_pp_rad"):
        assert verdict[key] is None
    assert main(argv) == 1  # the text form too
    assert "held" in capsys.readouterr().out


# --- negative numbers ----------------------------------------------------------------------------------
@pytest.mark.quick
@pytest.mark.parametrize(
    ("args", "x0", "theta0"),
    [
        (["--x0", "-1e-2", "--theta0", "0"], -0.01, 0.0),
        (["--x0", "0", "--theta0", "-.3"], 0.0, -0.3),
        (["--x0=-0.1", "--theta0", "-3E-1"], -0.1, -0.3),
        (["--x0", "-0.1", "--th", "-2e-1"], -0.1, -0.2),  # an abbreviated option too
    ],
)
def test_negative_numbers_are_values(capsys, args: list[str], x0: float, theta0: float) -> None:
    assert main(["run", "--controller", "appendix-clp", *args, "--duration", "0.1", "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert (out["x0_m"], out["theta0_rad"]) == (x0, theta0)


def test_a_negative_infinity_is_refused_as_a_value(capsys, no_run) -> None:
    _refused(
        capsys, ["run", "--controller", "appendix-clp", "--x0", "-inf", "--theta0", "0"], "--x0", "finite"
    )


def test_only_numeric_options_take_negative_numbers() -> None:
    parser = cli.build_parser()
    join = cli.join_negative_numbers
    assert join(["run", "--x0", "-1e-2", "--seed", "-1"], parser) == ["run", "--x0=-1e-2", "--seed=-1"]
    assert join(["run", "--log", "-1e-2"], parser) == ["run", "--log", "-1e-2"]  # a path, not a number
    assert join(["run", "--x0", "-h"], parser) == ["run", "--x0", "-h"]
    assert join(["calibrate", "--", "--window", "-1"], parser) == ["calibrate", "--", "--window", "-1"]


# --- durations and speeds ------------------------------------------------------------------------------
@pytest.mark.parametrize("duration", ["1e12", "3600.5", "0", "-1", "nan"])
def test_run_durations_are_bounded(capsys, no_run, duration: str) -> None:
    line = _refused(
        capsys, ["run", "--controller", "lqr", "--x0", "0", "--theta0", "0", "--duration", duration]
    )
    assert "--duration" in line
    if duration in ("1e12", "3600.5"):
        assert "3600 s" in line and "memory" in line


@pytest.mark.parametrize("speed", ["5", "4.01", "0.05", "0", "-1", "inf"])
def test_view_refuses_speeds_its_slider_cannot_show(capsys, monkeypatch, speed: str) -> None:
    import twin.viewer

    monkeypatch.setattr(twin.viewer, "serve", lambda *a, **k: pytest.fail("served"))
    _refused(capsys, ["view", "--speed", speed, "--duration", "1"], "--speed", "0.1…4")


@pytest.mark.quick
@pytest.mark.parametrize("speed", ["0.1", "1", "4"])
def test_view_accepts_the_slider_range(capsys, monkeypatch, speed: str) -> None:
    import twin.viewer

    seen: dict[str, object] = {}
    monkeypatch.setattr(twin.viewer, "serve", lambda catalogue, **kwargs: seen.update(kwargs) or {})
    assert main(["view", "--speed", speed, "--duration", "1"]) == 0
    assert seen["speed"] == float(speed)


# --- help and version ----------------------------------------------------------------------------------
def test_help_imports_no_controller_code() -> None:
    """--help builds the parser from the registry's names without its designs (python-control), MuJoCo, the
    plots or the viewer."""
    code = (
        "import sys\n"
        "from twin.app.cli import main\n"
        "assert main(['--help']) == 0 and main(['run', '--help']) == 0 and main(['view', '--help']) == 0\n"
        "heavy = [m for m in ('numpy', 'control', 'scipy', 'mujoco', 'controllers.design', 'controllers.laws', "
        "'controllers.loop', 'controllers.batch', 'twin.engine', 'calib', 'matplotlib', 'viser', 'twin.viewer') "
        "if m in sys.modules]\n"
        "print('HEAVY', heavy)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout
    assert "HEAVY []" in out, out


def _commands() -> list[str]:
    (sub,) = [a for a in cli.build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return sorted(sub.choices)


@pytest.mark.quick
@pytest.mark.parametrize("command", _commands())
def test_every_command_has_its_help(capsys, command: str) -> None:
    """Each subcommand's --help prints its usage and exits 0 (the quick tier's smoke of every command)."""
    assert main([command, "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: ballbeam {command}") and "options:" in out


@pytest.mark.quick
def test_help_lists_the_registry_names(capsys) -> None:
    from controllers import registry

    assert not hasattr(cli, "CONTROLLER_NAMES")  # one home for the names: the registry
    assert main(["run", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "MODULE:CLASS" in text and "software" in text
    for name in registry.NAMES:
        assert name in text


@pytest.mark.quick
def test_version(capsys) -> None:
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"ballbeam {cli.package_version()}"


def test_version_falls_back_to_pyproject(monkeypatch) -> None:
    from importlib import metadata

    def not_installed(name: str) -> str:
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(metadata, "version", not_installed)
    with open(ROOT / "pyproject.toml", "rb") as fh:
        assert cli.package_version() == tomllib.load(fh)["project"]["version"]


@pytest.mark.quick
def test_usage_errors_are_one_line(capsys) -> None:
    _refused(capsys, ["run", "--x0"], "--x0")
    _refused(capsys, ["run", "--controller", "lqr", "--x0", "zero", "--theta0", "0"], "--x0", "'zero'")
    _refused(capsys, ["launch"], "'launch'")


def test_an_unknown_controller_name_is_refused(capsys, no_run) -> None:
    _refused(capsys, ["run", "--controller", "pid", "--x0", "0", "--theta0", "0"], "'pid'", "appendix-clp")


# --- the user's own controller -------------------------------------------------------------------------
USER_MODULE = '''
from twin import converters
from twin.interface import Controller

CALLS = []
K = (-36.34, 24.6, -15.96, 3.98)


class WithSoftware(Controller):
    """README's example: state feedback with velocities by finite differences."""

    name = "mine"

    def __init__(self, software):
        super().__init__()
        CALLS.append(("WithSoftware", software))
        self.sw = software

    def _measure(self, sample):
        return (converters.ball_position_m(sample.ball_v, self.sw),
                converters.beam_angle_rad(sample.angle_v, self.sw))

    def start(self, sample):
        self.previous = self._measure(sample)

    def update(self, sample):
        x, theta = self._measure(sample)
        xdot = (x - self.previous[0]) / self.period_s
        thetadot = (theta - self.previous[1]) / self.period_s
        self.previous = (x, theta)
        volts = -(K[0] * x + K[1] * theta + K[2] * xdot + K[3] * thetadot)
        return converters.clip_command_v(converters.dac_command_v(volts, self.sw), self.sw)


class NoArguments(Controller):
    def __init__(self):
        super().__init__()
        CALLS.append(("NoArguments", None))

    def start(self, sample):
        pass

    def update(self, sample):
        return 2.5


class Abstract(Controller):
    pass


class Raising(NoArguments):
    def __init__(self):
        raise ValueError("no rig here\\nsecond line")


class NotAController:
    pass


def function():
    pass


def make_mine(software):
    CALLS.append(("make_mine", software))
    return WithSoftware(software)


def raising_factory():
    raise RuntimeError("no policy file")


CONSTANT = 3
'''


@pytest.fixture
def user_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A project directory with the user's modules, as the current directory; sys.path and sys.modules are
    restored afterwards."""
    (tmp_path / "my_controllers.py").write_text(USER_MODULE)
    (tmp_path / "broken_syntax.py").write_text("def oops(:\n")
    (tmp_path / "broken_import.py").write_text("raise RuntimeError('cannot talk to the card')\n")
    (tmp_path / "needs_missing.py").write_text("import not_installed_anywhere_xyz\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    before = set(sys.modules)
    yield tmp_path
    for name in set(sys.modules) - before:
        if name.startswith(("my_controllers", "broken_", "needs_missing")):
            del sys.modules[name]


@pytest.mark.quick
def test_run_a_user_controller_built_with_the_software_calibration(user_dir: Path, capsys) -> None:
    from twin.parameters import Parameters

    spec = "my_controllers:WithSoftware"
    rc = main(["run", "--controller", spec, "--x0", "0.14", "--theta0", "-0.2", "--duration", "4", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == (0 if out["held"] else 1) and out["controller"] == spec and not out["ball_lost"]
    calls = sys.modules["my_controllers"].CALLS
    assert calls == [("WithSoftware", Parameters().software)]


def test_run_a_controller_a_users_function_builds(user_dir: Path, capsys) -> None:
    """``MODULE:FUNCTION``: a factory (a trained policy's, say) given the software calibration, as a class is."""
    from twin.parameters import Parameters

    spec = "my_controllers:make_mine"
    rc = main(["run", "--controller", spec, "--x0", "0.14", "--theta0", "-0.2", "--duration", "4", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == (0 if out["held"] else 1) and out["controller"] == spec and not out["ball_lost"]
    calls = sys.modules["my_controllers"].CALLS
    assert calls[:2] == [("make_mine", Parameters().software), ("WithSoftware", Parameters().software)]


def test_run_a_user_controller_built_without_arguments(user_dir: Path, capsys) -> None:
    rc = main(
        [
            "run",
            "--controller",
            "my_controllers:NoArguments",
            "--x0",
            "0",
            "--theta0",
            "0",
            "--duration",
            "0.2",
        ]
    )
    assert rc == 1 and sys.modules["my_controllers"].CALLS == [("NoArguments", None)]
    capsys.readouterr()


@pytest.mark.parametrize(
    ("spec", "says"),
    [
        ("not_a_module_xyz:C", "no module named 'not_a_module_xyz'"),
        ("my_controllers.sub:C", "no module named 'my_controllers.sub'"),
        ("needs_missing:C", "importing needs_missing failed"),
        ("broken_syntax:C", "SyntaxError"),
        ("broken_import:C", "RuntimeError: cannot talk to the card"),
        ("my_controllers:Missing", "has no 'Missing'"),
        ("my_controllers:NotAController", "not a subclass of twin.interface.Controller"),
        ("my_controllers:function", "function() returned NoneType, not a twin.interface.Controller"),
        ("my_controllers:raising_factory", "raising_factory() failed: RuntimeError: no policy file"),
        ("my_controllers:CONSTANT", "neither a twin.interface.Controller class nor a function"),
        ("my_controllers:Abstract", "Abstract() failed: TypeError"),
        ("my_controllers:Raising", "Raising() failed: ValueError: no rig here second line"),
        ("my_controllers:", "expected MODULE:CLASS"),
        (":WithSoftware", "expected MODULE:CLASS"),
    ],
)
@pytest.mark.parametrize("command", ["run", "view"])
def test_a_bad_user_controller_is_refused(
    user_dir: Path, capsys, monkeypatch, no_run, spec, says, command
) -> None:
    import twin.viewer

    monkeypatch.setattr(twin.viewer, "serve", lambda *a, **k: pytest.fail("served"))
    argv = ["--x0", "0", "--theta0", "0"] if command == "run" else ["--duration", "1"]
    _refused(capsys, [command, "--controller", spec, *argv], "--controller", spec, says)


def test_view_offers_the_user_controller_beside_the_registry(user_dir: Path, capsys, monkeypatch) -> None:
    import twin.viewer
    from controllers import registry
    from twin.interface import Controller

    spec = "my_controllers:WithSoftware"
    seen: dict[str, object] = {}

    def serve(catalogue, **kwargs: object) -> dict[str, float]:
        seen.update(kwargs, catalogue=catalogue)
        return {}

    monkeypatch.setattr(twin.viewer, "serve", serve)
    assert main(["view", "--controller", spec, "--duration", "1"]) == 0
    catalogue = seen["catalogue"]
    assert seen["controller"] == spec
    assert catalogue.NAMES == (*registry.NAMES, spec)
    assert isinstance(catalogue.make(spec), Controller)
    assert type(catalogue.make("lqr")) is type(registry.make("lqr"))


@pytest.mark.parametrize(
    ("value", "says"),
    [
        ("70000", "PORT an integer 0…65535"),
        ("127.0.0.1:65536", "PORT an integer 0…65535"),
        ("127.0.0.1:-1", "PORT an integer 0…65535"),
        ("localhost:http", "PORT an integer 0…65535"),
        ("", "PORT an integer 0…65535"),
        ("bad_host!:5750", "'bad_host!' is not a host name or an IP address"),
        (":5750", "'' is not a host name or an IP address"),
        ("[::1:5750", "is not a host name or an IP address"),
    ],
)
def test_view_refuses_a_bad_serve_address(capsys, monkeypatch, value: str, says: str) -> None:
    import twin.viewer

    monkeypatch.setattr(twin.viewer, "serve", lambda *a, **k: pytest.fail("served"))
    _refused(capsys, ["view", "--serve", value, "--duration", "1"], "--serve", says)


def test_view_refuses_a_udp_port_that_is_taken(capsys) -> None:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        line = _refused(capsys, ["view", "--serve", f"127.0.0.1:{port}", "--duration", "1"], "--serve")
    assert (
        line == f"ballbeam view: error: --serve: cannot bind udp://127.0.0.1:{port}: Address already in use"
    )


@pytest.mark.parametrize(
    ("argv", "wire", "controller"),
    [
        (["--serve", "5750"], ("127.0.0.1", 5750), None),  # the wire client starts
        (["--serve", "0.0.0.0:0"], ("0.0.0.0", 0), None),
        (["--serve", "[::1]:5750"], ("::1", 5750), None),
        (["--serve", "lab-pc.local:5750", "--controller", "lqr"], ("lab-pc.local", 5750), "lqr"),
        ([], None, "appendix-clp"),
    ],
)
def test_view_serve_options_reach_the_view(monkeypatch, argv: list[str], wire, controller) -> None:
    import twin.viewer

    seen: dict[str, object] = {}
    monkeypatch.setattr(twin.viewer, "serve", lambda catalogue, **kwargs: seen.update(kwargs) or {})
    assert main(["view", *argv, "--seed", "3", "--no-noise", "--duration", "1"]) == 0
    assert seen["wire"] == wire and seen["controller"] == controller and seen["seed"] == 3
    assert seen["params"].ball_sensor.noise_enabled is False  # type: ignore[attr-defined]


@pytest.mark.quick
def test_the_command_table_is_one_module_per_command() -> None:
    """``twin.app.commands.COMMANDS`` is the dispatcher's one table: a row per command module, named as the
    module, each with its help line, its options and its handler, and the parser's subcommands are its rows."""
    from twin.app import commands
    from twin.app.commands import (
        calibrate,
        calibrate_static,
        certify,
        compare,
        experiment,
        export_fmu,
        falsify,
        judge,
        linearize,
        montecarlo,
        params,
        run,
        serve,
        shadow,
        sweep,
        validate,
        view,
    )

    modules = [
        linearize, run, serve, shadow, judge, sweep, montecarlo, validate, view, calibrate, compare,
        calibrate_static, experiment, params, export_fmu, falsify, certify,
    ]  # fmt: skip
    rows = commands.COMMANDS
    assert sorted(m.__name__ for _, m, _ in rows) == sorted(m.__name__ for m in modules)
    for name, module, help_line in rows:
        assert module.__name__.rsplit(".", 1)[1] == name.replace("-", "_")
        assert help_line == module.HELP and help_line.strip()
        assert callable(module.add_arguments) and callable(module.run)
    assert sorted(_commands()) == sorted(name for name, _, _ in rows)


@pytest.mark.quick
def test_run_json_keeps_a_chatty_controllers_prints_off_stdout(user_dir: Path, capsys) -> None:
    """``run --json``: stdout is the summary alone; what the controller prints at import and every tick goes
    to stderr."""
    (user_dir / "broken_chatty.py").write_text(
        "from controllers.appendix import AppendixStateFeedback\n"
        "print('import chatter')\n"
        "class Chatty(AppendixStateFeedback):\n"
        "    def update(self, sample):\n"
        "        print('tick chatter')\n"
        "        return super().update(sample)\n"
    )
    code = main(
        [
            "run",
            "--controller",
            "broken_chatty:Chatty",
            "--x0",
            "0.1",
            "--theta0",
            "0",
            "--duration",
            "0.2",
            "--json",
        ]
    )
    out, err = capsys.readouterr()
    assert code == 1  # too short to be judged held
    assert json.loads(out)["controller"] == "broken_chatty:Chatty" and len(out.splitlines()) == 1
    # update_ticks: 1 + ⌈(0.2 s − free run 0.01 s)/0.02 s⌉ = 11 updates
    assert "import chatter" in err and err.count("tick chatter") == 11


@pytest.mark.quick
def test_a_controller_module_that_calls_os_exit_at_import_is_refused(user_dir: Path, capsys) -> None:
    """``os._exit(0)`` at import would end the process with exit code 0 and no report: it is refused naming
    the module (exit 2), and os._exit is the real one again afterwards."""
    import os

    (user_dir / "broken_exit.py").write_text("import os\nos._exit(0)\n")
    real = os._exit
    line = _refused(
        capsys, ["run", "--controller", "broken_exit:X", "--x0", "0.1", "--theta0", "0"], "--controller"
    )
    assert "importing broken_exit failed" in line and "os._exit(0) called while importing" in line
    assert os._exit is real
