"""The quick tier (``python -m pytest -m quick``, under a minute) touches every module of twin/, controllers/
and calib/, and holds no slow, real-time or study test.

Read from the test sources (``ast``), as tests/test_layers.py reads the imports, so nothing runs and the
answer does not depend on which worker ran what. A module is *touched* when a test marked ``quick`` uses a
name that the module's import binds: in the test's own body or decorators, in a fixture it asks for (of its
file or of tests/conftest.py), in an autouse fixture of its file, or in a function, class or constant of its
file or of a helper module (tests/cli_checks.py, …) that it uses, followed to any depth. An import that the
reached code makes itself (``from twin.linearize import linearize_mujoco`` inside the test) touches its module
too. A module imported at the top of a test file but used only by the file's other tests does not count.

Two more rules, both sound because an import runs them: a package's ``__init__`` is touched with any of its
modules, and a name a package re-exports (``from twin.viewer import Viewer``) touches the module it comes
from (``twin.viewer.server``). A new module under twin/, controllers/ or calib/ fails
``test_every_module_is_touched_by_a_quick_test`` until a quick test uses it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TESTS = ROOT / "tests"
PACKAGES = ("twin", "controllers", "calib")
NOT_QUICK = ("slow", "realtime", "study")  # the tiers a quick test may not be in


def _module_name(path: Path) -> str:
    return ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")


def project_modules() -> dict[str, Path]:
    """Every module of the three packages by dotted name (a package by its own name)."""
    return {_module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


MODULES = project_modules()


def _dotted(node: ast.AST) -> str | None:
    """``a.b.c`` for a chain of attributes on a name, else None."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return ".".join([node.id, *reversed(parts)])


def _marks(function: ast.FunctionDef | ast.AsyncFunctionDef) -> set[str]:
    """The ``pytest.mark.NAME`` decorators of a function (called or not)."""
    found = set()
    for decorator in function.decorator_list:
        name = _dotted(decorator.func if isinstance(decorator, ast.Call) else decorator) or ""
        if name.startswith("pytest.mark."):
            found.add(name.removeprefix("pytest.mark."))
    return found


def _is_fixture(function: ast.AST, *, autouse: bool = False) -> bool:
    for decorator in getattr(function, "decorator_list", []):
        target = decorator.func if isinstance(decorator, ast.Call) else decorator
        if _dotted(target) != "pytest.fixture":
            continue
        if not autouse:
            return True
        return isinstance(decorator, ast.Call) and any(
            k.arg == "autouse" and isinstance(k.value, ast.Constant) and k.value.value is True
            for k in decorator.keywords
        )
    return False


def _reexports(package: str) -> dict[str, str]:
    """Name → the project module a package's ``__init__`` imports it from (``from pkg.sub import name``)."""
    path = MODULES.get(package)
    if path is None or path.name != "__init__.py":
        return {}
    out = {}
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module in MODULES:
            for alias in node.names:
                out[alias.asname or alias.name] = node.module
    return out


def _imported(node: ast.Import | ast.ImportFrom) -> dict[str, set[str]]:
    """What an import statement binds: name → the project modules (or ``helper:NAME`` of a test helper) it
    names. ``import a.b.c`` binds ``a`` and is resolved by the attribute chain used (see ``_Source``)."""
    bound: dict[str, set[str]] = {}
    if isinstance(node, ast.Import):
        for alias in node.names:
            if alias.asname:
                bound[alias.asname] = {alias.name} & MODULES.keys()
    elif node.level == 0 and node.module:
        helper = TESTS / f"{node.module}.py"
        for alias in node.names:
            name = alias.asname or alias.name
            if helper.is_file() and node.module not in MODULES:
                bound[name] = {f"helper:{node.module}:{alias.name}"}
                continue
            sub = f"{node.module}.{alias.name}"
            if sub in MODULES:
                bound[name] = {sub}
            elif node.module in MODULES:
                home = _reexports(node.module).get(alias.name)
                bound[name] = {node.module} | ({home} if home else set())
    return bound


class _Source:
    """A test file's (or helper's) top-level names: what its imports bind, and its definitions."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.tree = ast.parse(path.read_text(encoding="utf-8"))
        self.bound: dict[str, set[str]] = {}
        self.dotted: set[str] = set()  # `import a.b.c` without an alias
        self.defs: dict[str, ast.AST] = {}
        for node in self.tree.body:
            self._bind(node)

    def _bind(self, node: ast.stmt) -> None:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            for name, modules in _imported(node).items():
                self.bound.setdefault(name, set()).update(modules)
            if isinstance(node, ast.Import):
                self.dotted.update(a.name for a in node.names if not a.asname and a.name in MODULES)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            self.defs[node.name] = node
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                for name in ast.walk(target):
                    if isinstance(name, ast.Name):
                        self.defs[name.id] = node
        elif isinstance(node, (ast.If, ast.Try, ast.With)):
            for child in ast.iter_child_nodes(node):
                if isinstance(child, ast.stmt):
                    self._bind(child)

    def quick_tests(self) -> list[ast.FunctionDef | ast.AsyncFunctionDef]:
        return [
            node
            for node in self.tree.body
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.name.startswith("test")
            and "quick" in _marks(node)
        ]

    def autouse(self) -> list[ast.AST]:
        return [node for node in self.defs.values() if _is_fixture(node, autouse=True)]


_SOURCES: dict[Path, _Source] = {}


def _source(path: Path) -> _Source:
    if path not in _SOURCES:
        _SOURCES[path] = _Source(path)
    return _SOURCES[path]


def touched_by(source: _Source, roots: list[ast.AST]) -> set[str]:
    """The project modules the code reachable from ``roots`` (nodes of ``source``) uses."""
    conftest = _source(TESTS / "conftest.py")
    touched: set[str] = set()
    seen: set[int] = set()
    todo: list[tuple[_Source, ast.AST]] = [(source, root) for root in roots]
    while todo:
        where, node = todo.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        for child in ast.walk(node):
            if isinstance(child, (ast.Import, ast.ImportFrom)):  # an import the reached code runs
                for modules in _imported(child).values():
                    touched |= {m for m in modules if m in MODULES}
                if isinstance(child, ast.Import):
                    touched |= {a.name for a in child.names if a.name in MODULES}
                if isinstance(child, ast.ImportFrom) and child.level == 0 and child.module in MODULES:
                    touched.add(child.module)
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):  # fixtures asked for by name
                for arg in child.args.args + child.args.kwonlyargs:
                    for home in (where, conftest):
                        if arg.arg in home.defs and _is_fixture(home.defs[arg.arg]):
                            todo.append((home, home.defs[arg.arg]))
                            break
            elif isinstance(child, ast.Attribute) and (chain := _dotted(child)):
                touched |= {m for m in where.dotted if chain == m or chain.startswith(m + ".")}
            elif isinstance(child, ast.Name):
                for target in where.bound.get(child.id, ()):
                    if target.startswith("helper:"):
                        _, helper, name = target.split(":")
                        other = _source(TESTS / f"{helper}.py")
                        if name in other.defs:
                            todo.append((other, other.defs[name]))
                    else:
                        touched.add(target)
                if child.id in where.defs:
                    todo.append((where, where.defs[child.id]))
    return touched


def quick_coverage(test_files: list[Path]) -> dict[str, set[str]]:
    """Project module → the quick tests (``file::name``) that touch it."""
    covered: dict[str, set[str]] = {}
    for path in test_files:
        source = _source(path)
        for test in source.quick_tests():
            modules = touched_by(source, [test, *source.autouse()])
            for module in set(modules):  # importing a module runs its packages' __init__ first
                parts = module.split(".")
                modules |= {".".join(parts[:i]) for i in range(1, len(parts))}
            for module in modules:
                covered.setdefault(module, set()).add(f"{path.name}::{test.name}")
    return covered


def _test_files() -> list[Path]:
    return sorted(TESTS.glob("test_*.py"))


@pytest.mark.quick
def test_every_module_is_touched_by_a_quick_test() -> None:
    covered = quick_coverage(_test_files())
    missing = sorted(set(MODULES) - set(covered))
    assert not missing, f"no test marked quick uses these modules (mark one, or write one): {missing}"


@pytest.mark.quick
def test_no_quick_test_is_slow_realtime_or_study() -> None:
    """The quick tier stays quick: a test of a longer tier is not also quick (nor a file's whole tier)."""
    both = []
    for path in _test_files():
        source = _source(path)
        whole_file = {
            _dotted(node.value) or ""
            for node in source.tree.body
            if isinstance(node, ast.Assign)
            and any(getattr(t, "id", "") == "pytestmark" for t in node.targets)
        }
        for test in source.quick_tests():
            other = (_marks(test) | {m.removeprefix("pytest.mark.") for m in whole_file}) & set(NOT_QUICK)
            if other:
                both.append(f"{path.name}::{test.name} ({', '.join(sorted(other))})")
    assert not both, both


@pytest.mark.quick
def test_the_check_follows_what_a_quick_test_uses_and_nothing_else(tmp_path: Path) -> None:
    """The rule bites: a module imported at the top but used only by an unmarked test is not touched; one used
    through a fixture, a helper function, an attribute chain or a package's re-export is."""
    path = tmp_path / "test_example.py"
    path.write_text(
        "import pytest\n"
        "import twin.engine\n"
        "from twin import sensors\n"
        "from twin.rigs import sim as rig\n"
        "from twin.viewer import Viewer\n"
        "from calib.logs import load_rig_log\n"
        "from cli_checks import refused\n"
        "@pytest.fixture\n"
        "def made():\n"
        "    return sensors.BallSensor\n"
        "def _helper():\n"
        "    return twin.engine.run_closed_loop\n"
        "@pytest.mark.quick\n"
        "def test_fast(made, params):\n"
        "    from twin.linearize import linearize_mujoco\n"
        "    return _helper(), Viewer, refused\n"
        "def test_other():\n"
        "    return rig.SimRig, load_rig_log\n",
        encoding="utf-8",
    )
    covered = quick_coverage([path])
    expected = {
        "twin.sensors",  # the fixture asked for
        "twin.parameters",  # conftest's ``params``
        "twin.engine",  # the helper's attribute chain
        "twin.linearize",  # the test's own import
        "twin.viewer",
        "twin.viewer.server",  # Viewer, re-exported by twin.viewer
        "twin.app",
        "twin.app.cli",  # cli_checks.refused calls twin.app.cli.main
        "twin",
    }
    assert expected <= set(covered), sorted(covered)
    assert "twin.rigs.sim" not in covered and "calib.logs" not in covered and "calib" not in covered
    path.write_text(path.read_text(encoding="utf-8").replace("@pytest.mark.quick\n", ""), encoding="utf-8")
    _SOURCES.pop(path)
    assert quick_coverage([path]) == {}
