"""A replay file is data, not a program (``twin.app.replay``): ``run --replay`` and ``view --replay`` run the
controller a falsify.json or certify.json names only when it is a built-in name, when the user names the same
one with ``--controller``, or with ``--trust-replay-controller``; what runs must match the SHA-256 the writer
recorded (a ``MODULE:CLASS``'s module file, an ``avr:``/``fmu:`` image), checked before anything is imported or
loaded."""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import pytest
from cli_checks import refused

from twin.app.cli import main
from twin.app.falsify import Axis, FalsifySettings, falsify
from twin.app.falsify_render import write_falsify
from twin.app.replay import load_replay, replay_entry
from twin.parameters import Parameters
from twin.requirements import Spec, parse_requirements

MODULE = "replay_marker_ctl"
SPEC = Spec(parse_requirements({"requirements": {"on_track": "always (abs(x_m) <= 0.323)"}}, "t"), {}, "t")


@pytest.fixture
def user_module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """``replay_marker_ctl.py`` in the current folder: importing it writes MARKER (then an appendix-sf)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", list(sys.path))  # the lookup adds the current folder
    monkeypatch.delitem(sys.modules, MODULE, raising=False)
    marker = tmp_path / "MARKER"
    (tmp_path / f"{MODULE}.py").write_text(
        f"import pathlib\npathlib.Path({str(marker)!r}).write_text('imported')\n"
        "from controllers.appendix import AppendixStateFeedback as Ctl\n"
    )
    return marker


def _write(path: Path, controller: str, sha: str | None, **extra: Any) -> Path:
    """A falsify.json as the writer keeps its runs to repeat (``replay_entry``), 0.4 s long."""
    run = {"x0_m": 0.1, "theta0_rad": 0.0, "seed": 0, "parameters": {}, "requirements": {"on_track": 0.2}}
    entry = replay_entry(
        controller, {**run, "ball_lost": False}, False, 0.4, SPEC, controller_sha256=sha, plant="twin"
    )
    entry.update(extra)
    path.write_text(json.dumps({"counterexample": None, "least_robust": entry}))
    return path


def _forget(monkeypatch: pytest.MonkeyPatch) -> None:
    """As in a fresh process: the module imports again."""
    monkeypatch.delitem(sys.modules, MODULE, raising=False)


def test_a_module_the_file_names_is_not_imported_unless_the_user_names_or_trusts_it(
    tmp_path: Path, user_module: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    spec = f"{MODULE}:Ctl"
    # the writer: the search imports the user's module (the user named it) and records its file's hash
    result = falsify(
        FalsifySettings(
            spec, (Axis("x0_m", 0.1, 0.12),), duration_s=0.4, noise=False, budget=2, engine="mujoco"
        ),
        Parameters(),
        SPEC,
    )
    write_falsify(result, tmp_path / "fz")
    replay_file = tmp_path / "fz" / "falsify.json"
    sha = hashlib.sha256((tmp_path / f"{MODULE}.py").read_bytes()).hexdigest()
    assert load_replay(replay_file).controller_sha256 == sha
    user_module.unlink()
    _forget(monkeypatch)
    for command in (["run", "--replay", str(replay_file)], ["view", "--replay", str(replay_file)]):
        line = refused(capsys, command, str(replay_file), spec, "--trust-replay-controller", "--controller")
        assert "code" in line
        assert not user_module.exists() and MODULE not in sys.modules
    # another controller named than the file's: refused, nothing imported
    refused(capsys, ["run", "--replay", str(replay_file), "--controller", "appendix-sf"], "appendix-sf", spec)
    assert not user_module.exists()
    # named by the user: it runs
    assert main(["run", "--replay", str(replay_file), "--controller", spec, "--json"]) in (0, 1)
    assert user_module.exists() and json.loads(capsys.readouterr().out)["replayed"]["same"]
    user_module.unlink()
    _forget(monkeypatch)
    # trusted: it runs, and stderr says what ran, from which file, with its hash
    assert main(["run", "--replay", str(replay_file), "--trust-replay-controller"]) in (0, 1)
    err = capsys.readouterr().err
    assert user_module.exists() and "--trust-replay-controller: running" in err and sha in err
    user_module.unlink()
    _forget(monkeypatch)
    # the module changed since the file was written: refused, naming the file, the field and both hashes
    with (tmp_path / f"{MODULE}.py").open("a") as fh:
        fh.write("# changed\n")
    now = hashlib.sha256((tmp_path / f"{MODULE}.py").read_bytes()).hexdigest()
    for extra in (["--controller", spec], ["--trust-replay-controller"]):
        refused(
            capsys,
            ["run", "--replay", str(replay_file), *extra],
            str(replay_file),
            "controller_sha256",
            sha,
            now,
        )
    assert not user_module.exists()
    refused(capsys, ["run", "--trust-replay-controller", "--controller", "lqr"], "--replay")


@pytest.mark.quick
def test_a_file_written_before_hashes_needs_the_user_to_name_or_trust_its_code(
    tmp_path: Path, user_module: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    old = _write(tmp_path / "old.json", f"{MODULE}:Ctl", None)
    data = json.loads(old.read_text())
    for key in ("controller_sha256", "plant", "ideal_sensors"):
        data["least_robust"].pop(key)
    old.write_text(json.dumps(data))
    refused(capsys, ["run", "--replay", str(old)], str(old), "--trust-replay-controller")
    assert not user_module.exists()
    assert main(["run", "--replay", str(old), "--trust-replay-controller"]) in (0, 1)
    assert "no controller_sha256 in the file" in capsys.readouterr().err and user_module.exists()
    user_module.unlink()
    _forget(monkeypatch)
    assert main(["run", "--replay", str(old), "--controller", f"{MODULE}:Ctl"]) in (0, 1)
    assert user_module.exists()
    # a built-in controller is the project's own: it replays without either (old files too)
    capsys.readouterr()
    builtin = _write(tmp_path / "builtin.json", "appendix-sf", None)
    assert main(["run", "--replay", str(builtin), "--json"]) in (0, 1)  # a 0.4 s run is not judged held
    assert json.loads(capsys.readouterr().out)["controller"] == "appendix-sf"


def test_firmware_and_fmu_images_are_checked_against_the_files_hash_before_loading(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from avr_images import board_image

    import twin.app.hosts as hosts

    image = board_image("hold", "dac(0x3800);", tmp_path)
    sha = hashlib.sha256(image.read_bytes()).hexdigest()
    spec = f"avr:{image}"
    replay_file = _write(tmp_path / "avr.json", spec, sha)
    loaded: list[str] = []
    real_firmware, real_fmu = hosts.firmware, hosts.fmu_controller
    monkeypatch.setattr(hosts, "firmware", lambda s, *a, **k: loaded.append(s) or real_firmware(s, *a, **k))
    monkeypatch.setattr(hosts, "fmu_controller", lambda s, *a: loaded.append(s) or real_fmu(s, *a))
    refused(
        capsys, ["run", "--replay", str(replay_file)], str(replay_file), spec, "--trust-replay-controller"
    )
    assert loaded == []
    assert main(["run", "--replay", str(replay_file), "--controller", spec]) in (0, 1)
    assert loaded == [spec]
    capsys.readouterr()
    with image.open("ab") as fh:  # another image at the same path
        fh.write(b"\0")
    now = hashlib.sha256(image.read_bytes()).hexdigest()
    refused(
        capsys, ["run", "--replay", str(replay_file), "--controller", spec], "controller_sha256", sha, now
    )
    refused(
        capsys, ["run", "--replay", str(replay_file), "--trust-replay-controller"], "controller_sha256", now
    )
    # an FMU likewise: a file that is no unit at all is refused by its hash, never opened as a unit
    unit = tmp_path / "ctl.fmu"
    unit.write_bytes(b"not the unit that ran")
    fmu_file = _write(tmp_path / "fmu.json", f"fmu:{unit}", hashlib.sha256(b"the unit that ran").hexdigest())
    refused(capsys, ["run", "--replay", str(fmu_file)], f"fmu:{unit}", "--trust-replay-controller")
    refused(capsys, ["view", "--replay", str(fmu_file), "--controller", f"fmu:{unit}"], "controller_sha256")
    refused(capsys, ["run", "--replay", str(fmu_file), "--trust-replay-controller"], "controller_sha256")
    unit.unlink()
    refused(capsys, ["run", "--replay", str(fmu_file), "--trust-replay-controller"], str(unit))
    assert loaded == [spec]


@pytest.mark.quick
def test_a_malformed_hash_or_engine_is_refused_naming_the_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = _write(tmp_path / "bad.json", "appendix-sf", "../../etc")
    refused(capsys, ["run", "--replay", str(bad)], str(bad), "controller_sha256")
    bad = _write(tmp_path / "bad.json", "appendix-sf", None, plant="mujoco-ish")
    refused(capsys, ["run", "--replay", str(bad)], str(bad), "plant")
    good = _write(tmp_path / "good.json", "appendix-sf", None)
    refused(capsys, ["run", "--replay", str(good), "--plant", "reference"], "--replay brings", "--plant")
