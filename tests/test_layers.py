"""Imports go one way (docs/design.md, "Layers"): a module may import only from its own layer or below.

    twin (core: physics, I/O chain, engine, verdict, viewer)  <  controllers  <  calib  <  twin.app

Read from the source text (``ast``), so a lazy import inside a function counts too. Design code in
``controllers.design`` imports no runtime code at all.
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


def test_the_check_sees_an_upward_import(tmp_path: Path) -> None:
    """The rule is not vacuous: the core's viewer importing the registry would be caught."""
    bad = tmp_path / "viewer.py"
    bad.write_text("from controllers import registry\n")
    assert [(1, "controllers")] == _imports(bad)
    assert LAYERS[_layer("controllers") or ""] > LAYERS["twin"]
