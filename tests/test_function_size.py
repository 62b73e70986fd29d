"""No function grows past the project's limit unnoticed (docs/design.md, "The test run"): 120 lines, read with
``ast`` over the packages and the scripts. The exceptions are data tables: the thesis reproduction's claim
builders, which declare one claim record after another."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 120
# Claim tables (twin/app/reproduction/): a list of claim records each, data rather than logic.
DATA_TABLES = {
    "twin/app/reproduction/numbers.py": {"_chapter3", "_chapter4", "_chapter5", "_appendix"},
    "twin/app/reproduction/closed_loop.py": {"_chapter7_torque"},
}


def long_functions(paths: list[Path], root: Path = ROOT, limit: int = MAX_LINES) -> list[str]:
    out = []
    for path in paths:
        rel = str(path.relative_to(root))
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                if lines > limit and node.name not in DATA_TABLES.get(rel, ()):
                    out.append(f"{rel}:{node.lineno} {node.name} ({lines} lines)")
    return out


@pytest.mark.quick
def test_no_function_is_longer_than_the_limit() -> None:
    paths = sorted(p for d in ("twin", "controllers", "calib", "scripts") for p in (ROOT / d).rglob("*.py"))
    assert not long_functions(paths), long_functions(paths)


@pytest.mark.quick
def test_the_check_finds_a_long_function(tmp_path: Path) -> None:
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_LINES))
    (tmp_path / "m.py").write_text(f"def long():\n{body}\ndef short():\n    return 1\n")
    assert long_functions([tmp_path / "m.py"], tmp_path) == [f"m.py:1 long ({MAX_LINES + 1} lines)"]
