"""Nothing the user gave is lost (twin.outputs): every data-loss case of issue 17, each file checked bit for bit.

An ``--out`` folder is never deleted: ``--overwrite`` replaces only the files the command writes and keeps
everything else (a ``.git/``, the rig log, params, spread and criteria files). An output never replaces an
input. Links are resolved before the extension check; dangling links, FIFOs, devices and directories where
a file is expected are refused. ``--out`` of ``.``, ``..``, ``/``, the home folder or the repository root is
refused before any work. Every refusal is exit 2, one line naming the option, no traceback.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest
from cli_checks import refused as _refused

import twin.app.fanout as fanout
from twin import outputs
from twin.app.cli import main
from twin.outputs import MANIFEST, JobFiles, OutputError, atomic_directory

ROOT = Path(__file__).resolve().parent.parent
SWEEP = [
    "sweep",
    "--controller",
    "appendix-clp",
    "--x0",
    "-0.1:0.1:2",
    "--theta0",
    "0:0.2:2",
    "--duration",
    "0.2",
]
RUN = ["run", "--controller", "appendix-clp", "--x0", "0.1", "--theta0", "0.1", "--duration", "0.2"]
MAT_HEADER = b"MATLAB 5.0"


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """A refusal must come before the work: a run or a chunk of runs fails the test."""

    def fail(*args: object, **kwargs: object) -> None:
        raise AssertionError("the work started although an output was bad")

    import calib.experiments
    import calib.identify
    import twin.app.montecarlo
    import twin.app.sweep
    import twin.app.validate
    import twin.rigs.sim

    # Imported first, so that no module binds the failing stand-ins by name for the later tests.
    monkeypatch.setattr(twin.rigs.sim, "run_closed_loop", fail)
    monkeypatch.setattr(fanout, "run_chunk", fail)
    for module in (twin.app.sweep, twin.app.montecarlo, twin.app.validate):
        monkeypatch.setattr(module, "run_starts", fail)
    monkeypatch.setattr(calib.identify, "calibrate", fail)
    monkeypatch.setattr(calib.experiments, "run_closed_loop", fail)


def _snapshot(folder: Path) -> dict[str, str]:
    """Every file below ``folder`` (links as their target text) with the SHA-256 of its bytes."""
    out = {}
    for path in sorted(folder.rglob("*")):
        rel = str(path.relative_to(folder))
        if path.is_symlink():
            out[rel] = "-> " + os.readlink(path)
        elif path.is_file():
            out[rel] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def _users_folder(folder: Path) -> dict[str, str]:
    """A folder as a user keeps it: a git repository, a rig log, parameter, spread and criteria files."""
    (folder / ".git" / "objects" / "ab").mkdir(parents=True)
    (folder / ".git" / "HEAD").write_text("ref: refs/heads/main\n")
    (folder / ".git" / "objects" / "ab" / "cdef").write_bytes(bytes(range(256)))
    (folder / "rig_log.mat").write_bytes(MAT_HEADER + os.urandom(3000))
    (folder / "params.toml").write_text("[motor]\nresistance_ohm = 9.1\n")
    (folder / "spread.toml").write_text("[motor]\nresistance_ohm = { rel_sd = 0.05 }\n")
    (folder / "criteria.toml").write_text("nominal_seeds = 1\n")
    (folder / "notes" / "deep").mkdir(parents=True)
    (folder / "notes" / "deep" / "thesis.tex").write_text("\\chapter{Results}\n")
    return _snapshot(folder)


# --- an --out folder is never deleted wholesale --------------------------------------------------------
def test_sweep_overwrite_keeps_every_file_it_did_not_write(tmp_path: Path, capsys) -> None:
    out = tmp_path / "thesis"
    out.mkdir()
    before = _users_folder(out)
    assert main([*SWEEP, "--out", str(out), "--overwrite", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    after = _snapshot(out)
    assert {k: after[k] for k in before} == before  # the user's files, bit for bit
    assert set(after) - set(before) == {"sweep.json", "map.png", MANIFEST}
    assert json.loads((out / "sweep.json").read_text()) == printed
    manifest = json.loads((out / MANIFEST).read_text())
    assert (
        manifest["jobs"]["sweep"]["sweep.json"]
        == hashlib.sha256((out / "sweep.json").read_bytes()).hexdigest()
    )
    # Again: its own two files are replaced, the rest still untouched, no temporary folder left.
    (out / "sweep.json").write_text("{}")  # an older sweep's, recorded as such
    manifest["jobs"]["sweep"]["sweep.json"] = hashlib.sha256(b"{}").hexdigest()
    (out / MANIFEST).write_text(json.dumps(manifest))
    assert main([*SWEEP, "--out", str(out), "--overwrite", "--json"]) == 0
    assert json.loads((out / "sweep.json").read_text()) == json.loads(capsys.readouterr().out)
    again = _snapshot(out)
    assert {k: again[k] for k in before} == before
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".ballbeam-tmp")) == []


def test_overwrite_refuses_a_file_of_the_jobs_name_it_does_not_own(tmp_path: Path, capsys, no_work) -> None:
    """The user's own params.toml in cal/ (not an input), a sweep.json from before manifests, a map.png
    edited since the sweep wrote it, a link: named, refused before the work, kept bit for bit."""
    cal = tmp_path / "cal"
    cal.mkdir()
    before = _users_folder(cal)
    (cal / "log.mat").write_bytes(MAT_HEADER)
    argv = [
        "calibrate",
        str(cal / "log.mat"),
        "--fit",
        "motor.resistance_ohm",
        "--out",
        str(cal),
        "--overwrite",
    ]
    _refused(capsys, argv, "--out", "holds params.toml not written there by calibrate", "move them")
    assert {k: v for k, v in _snapshot(cal).items() if k in before} == before
    roa = tmp_path / "roa"
    roa.mkdir()
    (roa / "sweep.json").write_text('{"points": []}')
    _refused(
        capsys, [*SWEEP, "--out", str(roa), "--overwrite"], "holds sweep.json not written there by sweep"
    )
    (roa / "sweep.json").unlink()
    (roa / "map.png").symlink_to(cal / "params.toml")
    _refused(capsys, [*SWEEP, "--out", str(roa), "--overwrite"], "holds map.png not written there by sweep")
    assert (cal / "params.toml").read_text() == "[motor]\nresistance_ohm = 9.1\n"


def test_a_file_edited_since_the_job_wrote_it_is_the_users(tmp_path: Path, capsys) -> None:
    out = tmp_path / "roa"
    assert main([*SWEEP, "--out", str(out)]) == 0
    capsys.readouterr()
    (out / "map.png").write_bytes(b"my annotated map")
    _refused(capsys, [*SWEEP, "--out", str(out), "--overwrite"], "holds map.png not written there by sweep")
    assert (out / "map.png").read_bytes() == b"my annotated map"


def test_montecarlo_into_a_calibration_folder_keeps_its_files(tmp_path: Path, capsys) -> None:
    """The spread and the calibration it reads live in the --out folder: they survive, bit for bit."""
    out = tmp_path / "mc"
    out.mkdir()
    before = _users_folder(out)
    argv = ["montecarlo", "--controller", "appendix-clp", "--n", "2", "--duration", "0.2"]
    assert main([*argv, "--spread", str(out / "spread.toml"), "--out", str(out), "--overwrite"]) == 0
    capsys.readouterr()
    after = _snapshot(out)
    assert {k: after[k] for k in before} == before
    assert set(after) - set(before) == {"montecarlo.json", "distributions.png", MANIFEST}


def test_without_overwrite_an_existing_folder_is_refused_before_the_work(
    tmp_path: Path, capsys, no_work
) -> None:
    out = tmp_path / "roa"
    out.mkdir()
    before = _users_folder(out)
    line = _refused(
        capsys, [*SWEEP, "--out", str(out)], "--out", "exists; not overwritten", "other files are kept"
    )
    assert "only the sweep files it wrote there are replaced" in line
    assert _snapshot(out) == before


def test_a_directory_where_the_job_writes_a_file_is_refused_before_the_work(
    tmp_path: Path, capsys, no_work
) -> None:
    out = tmp_path / "roa"
    (out / "map.png").mkdir(parents=True)
    (out / "map.png" / "mine.txt").write_text("mine")
    _refused(capsys, [*SWEEP, "--out", str(out), "--overwrite"], "--out", "map.png is a directory")
    assert (out / "map.png" / "mine.txt").read_text() == "mine"


def test_another_commands_file_is_not_replaced(tmp_path: Path) -> None:
    """validate and calibrate both write report.md: validate into a calibration folder is refused."""
    out = tmp_path / "cal"
    with atomic_directory(out, JobFiles("calibrate", ("params.toml", "report.md"))) as tmp:
        (tmp / "report.md").write_text("the calibration")
    with pytest.raises(OutputError, match="holds report.md not written there by validate"):
        with atomic_directory(out, JobFiles("validate", ("report.md",)), overwrite=True):
            raise AssertionError("not reached")
    assert (out / "report.md").read_text() == "the calibration"


def test_a_failed_write_leaves_the_folder_as_it_was(tmp_path: Path) -> None:
    out = tmp_path / "out"
    job = JobFiles("job", ("a.json", "b.png"))
    with atomic_directory(out, job) as tmp:
        (tmp / "a.json").write_text("old a")
    before = _users_folder(out)
    with pytest.raises(RuntimeError, match="disk full"):
        with atomic_directory(out, job, overwrite=True) as tmp:
            (tmp / "a.json").write_text("new a")
            raise RuntimeError("disk full")
    assert _snapshot(out) == before


def test_a_file_the_job_did_not_declare_is_not_moved_in(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    before = _users_folder(out)
    with pytest.raises(RuntimeError, match="undeclared"):
        with atomic_directory(out, JobFiles("job", ("a.json",)), overwrite=True) as tmp:
            (tmp / "a.json").write_text("a")
            (tmp / "rig_log.mat").write_text("not a log")
    assert _snapshot(out) == before


@pytest.mark.quick
def test_a_stale_file_of_the_same_job_goes_and_an_edited_one_stops_it(tmp_path: Path) -> None:
    """An interrupted validate writes no region.png: the previous run's goes (the job owns it) and another
    job's files stay; once the user has edited region.png it is theirs, and the job is refused."""
    out = tmp_path / "report"
    validate = JobFiles("validate", ("report.md", "region.png"))

    def write(job: JobFiles, names: tuple[str, ...], text: str) -> None:
        with atomic_directory(out, job, overwrite=True) as tmp:
            for name in names:
                (tmp / name).write_text(f"{text} {name}")

    write(validate, ("report.md", "region.png"), "first")
    write(JobFiles("sweep", ("other.json",)), ("other.json",), "sweep's")
    write(validate, ("report.md",), "second")
    assert not (out / "region.png").exists()
    assert (out / "report.md").read_text() == "second report.md"
    assert (out / "other.json").read_text() == "sweep's other.json"
    write(validate, ("report.md", "region.png"), "third")
    (out / "region.png").write_text("edited by the user")
    with pytest.raises(OutputError, match="holds region.png not written there by validate"):
        write(validate, ("report.md",), "fourth")
    assert (out / "region.png").read_text() == "edited by the user"
    assert (out / "report.md").read_text() == "third report.md"
    jobs = json.loads((out / MANIFEST).read_text())["jobs"]
    assert set(jobs) == {"validate", "sweep"} and set(jobs["validate"]) == {"report.md", "region.png"}


def test_a_new_folder_appears_complete(tmp_path: Path) -> None:
    out = tmp_path / "new"
    with atomic_directory(out, JobFiles("job", ("a.json", "b.png"))) as tmp:
        (tmp / "a.json").write_text("a")
        assert not out.exists()
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST, "a.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new"]
    with pytest.raises(FileExistsError, match="not overwritten"):
        with atomic_directory(out, JobFiles("job", ("a.json",))):
            pass


# --- --out of . .. / ~ and the repository: refused before any work ------------------------------------
@pytest.mark.parametrize(
    ("where", "reason"),
    [
        (".", "the current folder"),
        ("..", "a parent of the current folder"),
        ("../..", "the home folder"),
        ("../../..", "a parent of the current folder"),
        ("/", "the root folder"),
        ("~", "the home folder"),
        ("REPO", "the repository's root"),
    ],
)
@pytest.mark.parametrize("command", ["sweep", "montecarlo", "validate", "calibrate"])
def test_unsafe_output_folders_are_refused_before_the_work(
    tmp_path: Path, capsys, monkeypatch: pytest.MonkeyPatch, no_work, where: str, reason: str, command: str
) -> None:
    home = tmp_path / "home"
    cwd = home / "work" / "today"
    cwd.mkdir(parents=True)
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(cwd)
    (cwd / "log.mat").write_bytes(MAT_HEADER)
    spread = cwd / "spread.toml"
    spread.write_text("[motor]\nresistance_ohm = { rel_sd = 0.05 }\n")
    out = str(ROOT) if where == "REPO" else os.path.expanduser(where)
    argv = {
        "sweep": SWEEP,
        "montecarlo": ["montecarlo", "--controller", "appendix-clp", "--n", "2", "--spread", str(spread)],
        "validate": ["validate", "--controller", "appendix-clp"],
        "calibrate": ["calibrate", str(cwd / "log.mat"), "--fit", "motor.resistance_ohm"],
    }[command]
    before = _snapshot(home)
    _refused(capsys, [*argv, "--out", out, "--overwrite"], f"--out {out}", reason)
    assert _snapshot(home) == before


# --- inputs are never replaced -------------------------------------------------------------------------
def test_calibrate_refuses_to_replace_its_params_input(tmp_path: Path, capsys, no_work) -> None:
    cal = tmp_path / "cal"
    cal.mkdir()
    before = _users_folder(cal)
    argv = [
        "calibrate",
        str(cal / "rig_log.mat"),
        "--fit",
        "motor.resistance_ohm",
        "--params",
        str(cal / "params.toml"),
    ]
    _refused(
        capsys, [*argv, "--out", str(cal), "--overwrite"], "--out", "params.toml", "is the input --params"
    )
    assert _snapshot(cal) == before


def test_calibrate_static_refuses_to_replace_its_params_input(tmp_path: Path, capsys) -> None:
    from calib.static import TABLES_DIR

    params = tmp_path / "rig.toml"
    params.write_text("[motor]\nresistance_ohm = 9.1\n")
    table = str(TABLES_DIR / "table_6_3.csv")
    argv = ["calibrate-static", table, "--params", str(params), "--overwrite", "--out"]
    _refused(capsys, [*argv, str(params)], "--out", "is the input --params")
    link = tmp_path / "link.toml"
    link.symlink_to(params)
    _refused(capsys, [*argv, str(link)], "--out", "is the input --params")
    hard = tmp_path / "hard.toml"
    os.link(params, hard)
    _refused(capsys, [*argv, str(hard)], "--out", "is the input --params")
    assert params.read_text() == "[motor]\nresistance_ohm = 9.1\n"


def test_a_user_controllers_module_is_an_input(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The module of ``--controller MODULE:CLASS`` is one of the job's inputs: an output never replaces it."""
    from twin.app import cli
    from twin.app.catalogue import user_controller
    from twin.app.commands import sweep
    from twin.app.commands.common import options_from

    module = tmp_path / "myctl_outputs.py"
    module.write_text(
        "from twin.interface import Controller\n"
        "class C(Controller):\n"
        "    def start(self, sample):\n        pass\n"
        "    def update(self, sample):\n        return 2.5\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    user_controller("myctl_outputs:C")  # the command imports it before the output checks
    args = cli.build_parser().parse_args(["sweep", "--controller", "myctl_outputs:C"])
    inputs = options_from(sweep.Options, args).job().inputs  # the files the sweep job reads
    assert ("--controller", str(module)) in inputs()
    with pytest.raises(OutputError, match="is the input --controller"):
        outputs.check_output_folder(
            "--out",
            str(tmp_path),
            JobFiles("x", ("myctl_outputs.py",)),
            overwrite=True,
            inputs=inputs(),
        )


# --- links and special files ---------------------------------------------------------------------------
def test_a_link_to_another_kind_of_file_is_refused(tmp_path: Path, capsys, no_work) -> None:
    notes = tmp_path / "notes.toml"
    notes.write_text("precious = true\n")
    (tmp_path / "run.mat").symlink_to(notes)
    _refused(
        capsys, [*RUN, "--log", str(tmp_path / "run.mat"), "--overwrite"], "--log", "a link to", "'.toml'"
    )
    assert notes.read_text() == "precious = true\n"


def test_a_dangling_link_does_not_create_its_target(tmp_path: Path, capsys, no_work) -> None:
    (tmp_path / "run.mat").symlink_to(tmp_path / "elsewhere" / "made.mat")
    (tmp_path / "elsewhere").mkdir()
    _refused(capsys, [*RUN, "--log", str(tmp_path / "run.mat")], "--log", "does not exist")
    _refused(capsys, [*RUN, "--log", str(tmp_path / "run.mat"), "--overwrite"], "--log", "does not exist")
    assert not (tmp_path / "elsewhere" / "made.mat").exists()
    (tmp_path / "out").symlink_to(tmp_path / "nowhere")
    _refused(capsys, [*SWEEP, "--out", str(tmp_path / "out")], "--out", "does not exist")
    assert not (tmp_path / "nowhere").exists()


@pytest.mark.quick
def test_special_files_and_directories_are_refused(tmp_path: Path, capsys, no_work) -> None:
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    _refused(capsys, [*RUN, "--log", str(fifo), "--overwrite"], "--log", "is a FIFO")
    device = tmp_path / "null.mat"
    device.symlink_to("/dev/null")
    _refused(capsys, [*RUN, "--log", str(device), "--overwrite"], "--log", "is a device")
    folder = tmp_path / "plots.png"
    folder.mkdir()
    _refused(capsys, [*RUN, "--plot", str(folder), "--overwrite"], "--plot", "is a directory")
    afile = tmp_path / "roa"
    afile.write_text("a file")
    _refused(capsys, [*SWEEP, "--out", str(afile), "--overwrite"], "--out", "not a directory")
    assert afile.read_text() == "a file" and fifo.exists() and folder.is_dir()


def test_a_link_to_a_folder_writes_into_the_folder(tmp_path: Path, capsys) -> None:
    real = tmp_path / "runs" / "5"
    real.mkdir(parents=True)
    (real / "mine.txt").write_text("mine")
    (tmp_path / "latest").symlink_to(real)
    assert main([*SWEEP, "--out", str(tmp_path / "latest"), "--overwrite"]) == 0
    capsys.readouterr()
    assert (tmp_path / "latest").is_symlink()
    assert sorted(p.name for p in real.iterdir()) == [MANIFEST, "map.png", "mine.txt", "sweep.json"]


# --- the interrupted command ----------------------------------------------------------------------------------
@pytest.mark.slow
def test_calibrate_overwrite_keeps_the_rig_log_it_fitted(tmp_path: Path, capsys) -> None:
    """``ballbeam calibrate cal/rig_log.mat --fit … --out cal --overwrite`` (issue 17): the log, a spread,
    params and criteria file and a .git in cal/ survive, bit for bit."""
    cal = tmp_path / "cal"
    cal.mkdir()
    log = cal / "rig_log.mat"
    assert main(["experiment", "square", "--out", str(log), "--duration", "6", "--seed", "3"]) == 0
    (cal / "spread.toml").write_text("[motor]\nresistance_ohm = { rel_sd = 0.05 }\n")
    (cal / "criteria.toml").write_text("nominal_seeds = 1\n")
    (cal / "start.toml").write_text("[motor]\nresistance_ohm = 9.4\n")
    (cal / ".git").mkdir()
    (cal / ".git" / "HEAD").write_text("ref: refs/heads/main\n")
    before = _snapshot(cal)
    argv = ["calibrate", str(log), "--fit", "motor.resistance_ohm", "--params", str(cal / "start.toml")]
    assert main([*argv, "--out", str(cal), "--overwrite"]) == 0
    capsys.readouterr()
    after = _snapshot(cal)
    assert {k: after[k] for k in before} == before
    assert {"params.toml", "calibration.json", "report.md", "fit.png"} <= set(after) - set(before)


# --- analysis apart from rendering ------------------------------------------------------------------------
COMPUTING = [
    "twin/log.py",
    "twin/app/sweep.py",
    "twin/app/montecarlo.py",
    "twin/app/validate.py",
    "twin/app/robust.py",
    "calib/static.py",
]
COMPUTING += ["calib/report.py", "calib/compare.py"]


@pytest.mark.quick
@pytest.mark.parametrize("name", COMPUTING)
def test_computation_modules_never_import_matplotlib(name: str) -> None:
    """Rendering lives in the *_render modules, with the writers of the jobs' folders; they import the
    computation, never the other way round (tests/test_import_graph.py), and calib.report imports its renderer
    only when it writes."""
    import ast

    tree = ast.parse((ROOT / name).read_text(encoding="utf-8"))
    imported = [
        (node.lineno, alias.name)
        for node in ast.walk(tree)
        if isinstance(node, ast.Import)
        for alias in node.names
    ] + [(node.lineno, node.module or "") for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)]
    assert not [(line, m) for line, m in imported if m.split(".")[0] == "matplotlib"]
    top = {node.module for node in tree.body if isinstance(node, ast.ImportFrom)}
    assert not [m for m in top if m and m.endswith("_render")], "a render module imported at module level"


def test_importing_the_analyses_loads_no_matplotlib_and_outputs_loads_no_numpy() -> None:
    import subprocess
    import sys

    code = (
        "import sys\n"
        "import twin.outputs\n"
        "assert 'numpy' not in sys.modules, 'twin.outputs loads numpy'\n"
        "import twin.log, twin.app.sweep, twin.app.montecarlo, twin.app.validate, twin.app.robust\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'matplotlib' or m.endswith('_render')))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_write_atomic_writes_utf8_and_refuses_an_existing_file_unless_asked(tmp_path: Path) -> None:
    path = tmp_path / "claims.md"
    outputs.write_atomic(path, "θ — held\n")
    assert path.read_bytes() == "θ — held\n".encode()
    with pytest.raises(FileExistsError, match="not overwritten"):
        outputs.write_atomic(path, b"other")
    outputs.write_atomic(path, b"other", overwrite=True)
    assert path.read_bytes() == b"other" and sorted(p.name for p in tmp_path.iterdir()) == ["claims.md"]
