"""Imports go one way inside the layers too: the module graph of ``twin``, ``controllers`` and ``calib`` has no
cycle (docs/design.md, "Layers"). A renderer imports the compute module's types, never the other way round.

Read from the source text (``ast``), so an import inside a function counts as much as one at the top. An edge
goes from a module to the module it names:

* ``import a.b.c`` and ``from a.b.c import name`` import ``a.b.c``;
* ``from a.b import c`` imports the submodule ``a.b.c`` when there is one, else the package ``a.b`` (its
  ``__init__``);
* relative imports (``from . import x``, ``from ..y import z``) are resolved against the importing module's
  package first.

The parent packages that Python also initialises on the way (``import a.b.c`` runs ``a/__init__`` and
``a/b/__init__`` first) are not edges: a package's ``__init__`` re-exporting its own submodules would otherwise
be a cycle with every submodule that imports a sibling, which is how every package works. An ``__init__`` that
re-exports eagerly is an edge like any other module's import (``from calib.report import write_report`` in
``calib/__init__``), so a submodule importing its package's ``__init__`` back does make a cycle. ``twin``'s
``__init__`` re-exports lazily, through a module ``__getattr__`` that calls ``importlib.import_module`` on first
attribute access: nothing is imported when the package is, so it has no edges here and none is drawn for it.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("twin", "controllers", "calib")


def _module_name(path: Path, root: Path) -> str:
    return ".".join(path.relative_to(root).with_suffix("").parts).removesuffix(".__init__")


def _modules(root: Path) -> dict[str, Path]:
    return {
        _module_name(p, root): p
        for pkg in PACKAGES
        if (root / pkg).is_dir()
        for p in (root / pkg).rglob("*.py")
    }


def _imported(module: str, path: Path, known: set[str]) -> set[str]:
    """The modules of ``known`` that ``module`` (its source at ``path``) imports, anywhere in its text."""
    is_package = path.name == "__init__.py"
    tree = ast.parse(path.read_text(encoding="utf-8"))
    if is_package and "lazy_exports(" in ast.unparse(tree):
        # A lazy re-export also names its names under ``if TYPE_CHECKING:`` for a type checker; nothing
        # runs them, so they are no edge (the lazy table itself is none either, see above).
        tree.body = [node for node in tree.body if not _is_type_checking_block(node)]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = module.split(".") if is_package else module.split(".")[:-1]
                base_parts = parts[: len(parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                found.add(sub if sub in known else base)
    return {name for name in found if name in known and name != module}


def _is_type_checking_block(node: ast.stmt) -> bool:
    return isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING"


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    modules = _modules(root)
    known = set(modules)
    return {name: _imported(name, path, known) for name, path in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each as one cycle through it."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def visit(v: str) -> None:  # iterative would be longer; the graph is ~150 modules deep at most
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(_cycle_through(sorted(component), graph))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return components


def _cycle_through(component: list[str], graph: dict[str, set[str]]) -> list[str]:
    """One closed path inside a strongly connected component, from its first module back to it (breadth first)."""
    members, start = set(component), component[0]
    previous: dict[str, str] = {}
    frontier = [start]
    while frontier:
        following = []
        for v in frontier:
            for w in sorted(graph[v] & members):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(previous[path[-1]])
                    return [*reversed(path), start]
                if w not in previous:
                    previous[w] = v
                    following.append(w)
        frontier = following
    raise AssertionError(f"not strongly connected: {component}")


def test_the_module_graph_has_no_cycle() -> None:
    found = cycles(import_graph())
    assert not found, "import cycles: " + "; ".join(" -> ".join(c) for c in found)


def test_the_graph_is_read_and_has_the_known_edges() -> None:
    graph = import_graph()
    assert {"twin.parameters", "twin.app.cli", "calib.identify", "controllers.registry"} <= set(graph)
    assert "twin.app.sweep" in graph["twin.app.sweep_render"]  # the renderer imports the compute module
    assert "calib.report" in graph["calib"]  # an eager re-export is an edge
    assert graph["twin"] == {"twin.exports"}  # the lazy one imports its helper only, not what it re-exports


def test_the_check_sees_a_cycle_through_functions_and_relative_imports(tmp_path: Path) -> None:
    """The rule bites: a function-level import, a relative one and ``from pkg import submodule`` all count."""
    pkg = tmp_path / "calib"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from . import b\n")
    (pkg / "b.py").write_text("from .c import g\n")
    (pkg / "c.py").write_text("def g():\n    from calib import a\n")
    (pkg / "d.py").write_text("from calib import a, ZERO\nimport calib.c\n")
    graph = import_graph(tmp_path)
    assert graph["calib.a"] == {"calib.b"}
    assert graph["calib.b"] == {"calib.c"}
    assert graph["calib.c"] == {"calib.a"}
    assert graph["calib.d"] == {"calib", "calib.a", "calib.c"}
    assert cycles(graph) == [["calib.a", "calib.b", "calib.c", "calib.a"]]
    (pkg / "c.py").write_text("def g():\n    pass\n")
    assert cycles(import_graph(tmp_path)) == []


# The packages bottom up (docs/design.md, "Layers"): the core's own modules (``twin``), the wire and the
# kernels it needs, the rig's parts, the rigs, what serves or hosts a rig, the live view, then the layers
# above the core. A package imports only packages ranked below it (siblings of one rank import neither).
PACKAGE_RANKS = {
    "twin": 0,
    "twin.wire": 1,
    "twin.screen": 1,
    "twin.avr": 1,
    "twin.parts": 2,
    "twin.rigs": 3,
    "twin.fmi": 4,
    "twin.serving": 4,
    "twin.viewer": 5,
    "controllers": 6,
    "calib": 7,
    "twin.app": 8,
}


def package_of(module: str, root: Path = ROOT) -> str:
    """The package a module belongs to: ``twin.<sub>`` for a module of a subpackage of ``twin``, ``twin`` for
    the core's own modules, the top package otherwise."""
    parts = module.split(".")
    if parts[0] == "twin" and len(parts) > 1 and (root / "twin" / parts[1] / "__init__.py").is_file():
        return f"twin.{parts[1]}"
    return parts[0]


def package_graph(root: Path = ROOT) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for module, targets in import_graph(root).items():
        own = package_of(module, root)
        graph.setdefault(own, set()).update(package_of(t, root) for t in targets)
        graph[own].discard(own)
    return graph


def upward(graph: dict[str, set[str]]) -> list[str]:
    """The package edges that do not go strictly down the ranks (an unranked package is one too)."""
    found = [f"{p} is not ranked" for p in sorted(graph) if p not in PACKAGE_RANKS]
    found += [
        f"{p} -> {q}"
        for p in sorted(graph)
        for q in sorted(graph[p])
        if p in PACKAGE_RANKS and (q not in PACKAGE_RANKS or PACKAGE_RANKS[q] >= PACKAGE_RANKS[p])
    ]
    return found


def test_the_package_graph_has_no_cycle_and_no_upward_import() -> None:
    graph = package_graph()
    assert set(PACKAGE_RANKS) <= set(graph), sorted(set(PACKAGE_RANKS) - set(graph))
    found = cycles(graph)
    assert not found, "package cycles: " + "; ".join(" -> ".join(c) for c in found)
    assert not upward(graph), upward(graph)


def test_the_package_check_sees_a_circle_and_an_upward_import(tmp_path: Path) -> None:
    """The engine importing a rig made the circle core -> rigs -> core: the check names it."""
    for package in ("twin", "twin/rigs", "twin/wire"):
        (tmp_path / package).mkdir(parents=True)
        (tmp_path / package / "__init__.py").write_text("")
    (tmp_path / "twin" / "engine.py").write_text("def run():\n    from twin.rigs.sim import make_rig\n")
    (tmp_path / "twin" / "rigs" / "sim.py").write_text(
        "from twin.engine import run\nfrom twin.wire import links\n"
    )
    (tmp_path / "twin" / "wire" / "links.py").write_text("")
    graph = package_graph(tmp_path)
    assert graph["twin"] == {"twin.rigs"} and graph["twin.rigs"] == {"twin", "twin.wire"}
    assert cycles(graph) == [["twin", "twin.rigs", "twin"]]
    assert upward(graph) == ["twin -> twin.rigs"]
