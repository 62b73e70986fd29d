"""The public face is typed for a user: a type checker sees each re-exported name's real class or function,
not ``Any`` (the names load lazily at run time through a module ``__getattr__``, which a checker reads as
``Any`` unless the package also imports them under ``TYPE_CHECKING``)."""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
import typing
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _lazy_packages() -> list[Path]:
    return sorted(p for p in (ROOT / "twin").rglob("__init__.py") if "lazy_exports(" in p.read_text())


def _homes_and_typed(init: Path) -> tuple[dict[str, str], dict[str, str]]:
    """The ``_HOMES`` table (name → module) and the names imported under ``if TYPE_CHECKING:``."""
    tree = ast.parse(init.read_text())
    homes: dict[str, str] = {}
    typed: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "_HOMES" for t in node.targets
        ):
            homes = ast.literal_eval(node.value)
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for sub in node.body:
                if isinstance(sub, ast.ImportFrom) and sub.module:
                    typed.update({alias.name: sub.module for alias in sub.names})
    return homes, typed


def _package(init: Path) -> str:
    return ".".join(init.parent.relative_to(ROOT).parts)


@pytest.mark.quick
@pytest.mark.parametrize("init", _lazy_packages(), ids=lambda p: _package(p))
def test_every_lazy_name_is_also_imported_for_the_type_checker_from_the_same_home(init: Path) -> None:
    homes, typed = _homes_and_typed(init)
    assert homes, f"{init}: no _HOMES table"
    assert typed == homes, f"{init}: TYPE_CHECKING imports differ from _HOMES"
    package = importlib.import_module(_package(init))
    assert sorted(package.__all__) == sorted(homes)


def test_mypy_reveals_each_public_name_as_its_real_type(tmp_path: Path) -> None:
    lines: list[str] = []
    expected: list[tuple[str, str]] = []
    for init in _lazy_packages():
        homes, _ = _homes_and_typed(init)
        for name, module in sorted(homes.items()):
            alias = f"{_package(init).replace('.', '_')}_{name}"
            lines.append(f"from {_package(init)} import {name} as {alias}")
            expected.append((f"{_package(init)}.{name}", module))
    lines += [f"reveal_type({line.rsplit(' as ', 1)[1]})" for line in list(lines)]
    snippet = tmp_path / "face.py"
    snippet.write_text("\n".join(lines) + "\n")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "mypy",
            "--follow-imports=silent",
            "--cache-dir",
            str(tmp_path / "cache"),
            "--no-error-summary",
            str(snippet),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )
    revealed = re.findall(r'Revealed type is "(.*)"', done.stdout)
    assert len(revealed) == len(expected), done.stdout + done.stderr
    for (name, module), kind in zip(expected, revealed, strict=True):
        assert kind != "Any", f"{name} is Any to a type checker"
        package, short = name.rsplit(".", 1)
        if typing.get_origin(getattr(importlib.import_module(package), short)) is not None:
            continue  # a type alias (``Literal[...]``): its use in a signature is what a checker reads
        if short[0].isupper():  # a class: its constructor returns the class of its home module
            assert f"{module}.{short}" in kind, f"{name}: revealed {kind!r}, not the class {module}.{short}"
        else:  # a function: a signature, not an unknown
            assert kind.startswith(("def ", "Overload(")), f"{name}: revealed {kind!r}"
