"""Imports go one way (docs/design.md, "Layers"): a module may import only from its own layer or below.

    twin (core: physics, I/O chain, engine, verdict, viewer)  <  controllers  <  calib  <  twin.app

Read from the source text (``ast``), so a lazy import inside a function counts too. Design code in
``controllers.design`` imports no runtime code at all. The core's tests import nothing of ``twin.app`` but
its command line.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LAYERS = {"twin": 0, "controllers": 1, "calib": 2, "twin.app": 3}


def _layer(module: str) -> str | None:
    if module == "twin.app" or module.startswith("twin.app."):
        return "twin.app"
    top = module.split(".")[0]
    return top if top in LAYERS else None


def _modules() -> list[Path]:
    return sorted(p for pkg in ("twin", "controllers", "calib") for p in (ROOT / pkg).rglob("*.py"))


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.lineno, node.module))
    return found


def _module_name(path: Path) -> str:
    return ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")


@pytest.mark.quick
@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_imports_a_layer_above_its_own(path: Path) -> None:
    own = _layer(_module_name(path))
    assert own is not None
    upward = [
        f"line {line}: {name}"
        for line, name in _imports(path)
        if (target := _layer(name)) is not None and LAYERS[target] > LAYERS[own]
    ]
    assert not upward, f"{path.relative_to(ROOT)} ({own}) imports upward: {upward}"


def test_design_code_imports_no_runtime_code() -> None:
    names = [name for _, name in _imports(ROOT / "controllers" / "design.py")]
    assert not [n for n in names if _layer(n) is not None], names


def test_the_hardware_contract_carries_no_simulation_truth() -> None:
    text = (ROOT / "twin" / "interface.py").read_text(encoding="utf-8")
    assert "true_state" not in text and "mujoco" not in text


# Core tests not named after one core module: the plant's rolling and its trajectory against the reference.
CORE_PHYSICS_TESTS = ("test_rolling.py", "test_trajectory.py")
# What a core test may use of the application layer: the command line, for its end-to-end command checks.
CORE_TEST_MAY_USE = ("twin.app.cli",)


def _core_tests() -> list[Path]:
    """tests/test_<m>.py for every core module twin/<m>.py or twin/<package>/<m>.py (the rigs, the wire, the
    viewer), and the core's physics tests."""
    core = {p.stem for p in (ROOT / "twin").rglob("*.py") if "app" not in p.relative_to(ROOT / "twin").parts}
    return sorted(
        p
        for p in (ROOT / "tests").glob("test_*.py")
        if p.stem.removeprefix("test_") in core or p.name in CORE_PHYSICS_TESTS
    )


def _app_imports(path: Path) -> list[str]:
    return [
        f"line {line}: {name}"
        for line, name in _imports(path)
        if _layer(name) == "twin.app" and name not in CORE_TEST_MAY_USE
    ]


@pytest.mark.parametrize("path", _core_tests(), ids=lambda p: p.name)
def test_core_tests_use_no_application_layer(path: Path) -> None:
    """The core is tested with the core: its tests' measurements live in twin.rigs.measurements."""
    assert not _app_imports(path), f"{path.name} imports the application layer: {_app_imports(path)}"


@pytest.mark.quick
def test_the_core_tests_are_found_and_the_rule_bites(tmp_path: Path) -> None:
    names = {p.name for p in _core_tests()}
    assert {
        "test_sensors.py",
        "test_sim.py",
        "test_batch.py",
        "test_protocol.py",
        "test_log.py",
        "test_rolling.py",
    } <= names
    assert "test_cli.py" not in names and "test_sweep.py" not in names
    bad = tmp_path / "test_sensors.py"
    bad.write_text("from twin.app import measurements\nfrom twin.app.cli import main\n")
    assert _app_imports(bad) == ["line 1: twin.app"]


def test_the_check_sees_an_upward_import(tmp_path: Path) -> None:
    """The rule is not vacuous: the core's viewer importing the registry would be caught."""
    bad = tmp_path / "viewer.py"
    bad.write_text("from controllers import registry\n")
    assert [(1, "controllers")] == _imports(bad)
    assert LAYERS[_layer("controllers") or ""] > LAYERS["twin"]


def test_the_design_records_diagram_is_these_layers() -> None:
    """docs/design.md's diagram lists the layers top down, as LAYERS ranks them (the core as "twin (core)")."""
    text = (ROOT / "docs" / "design.md").read_text(encoding="utf-8")
    block = text.split("## Layers", 1)[1].split("```", 2)[1]
    drawn = [
        line.split()[0] for line in block.splitlines() if line[:1].isalpha() and not line.startswith("models")
    ]
    assert drawn == sorted(LAYERS, key=LAYERS.__getitem__, reverse=True), drawn


def test_the_design_records_loop_diagram_names_every_rig() -> None:
    """docs/design.md's diagram of the one loop names a class of every rig module (twin/rigs/, but the remote
    sessions' orchestration), and every rig it names exists: a new rig module must be drawn there."""
    import importlib
    import re

    text = (ROOT / "docs" / "design.md").read_text(encoding="utf-8")
    block = text.split("## One loop, many rigs", 1)[1].split("```", 2)[1]
    named = set(re.findall(r"twin\.rigs\.(\w+)\.(\w+)", block))
    for module, name in named:
        assert hasattr(importlib.import_module(f"twin.rigs.{module}"), name), (module, name)
    # not rigs: the remote sessions' orchestration, the backend registry, the warm-up and the measurements
    not_rigs = {"__init__", "session", "backends", "warm", "measurements"}
    modules = {p.stem for p in (ROOT / "twin" / "rigs").glob("*.py")} - not_rigs
    assert {m for m, _ in named} == modules
    assert "ClosedLoop(rig, controller)" in block
