"""The manual is a site built by MkDocs Material from docs/ (mkdocs.yml), strictly: a broken link or anchor fails
the build. Its reference pages are generated at build time from the parser and the parameter table
(docs/hooks.py), its measured tables are the committed JSON rendered (scripts/docs_pages.py), and README.md is a
landing page that links into it."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
SETUP = (
    "pip install . && ballbeam view                  # install, then open the live twin: http://127.0.0.1:8080",
    "pip install '.[test]' && python -m pytest       # install, then run the tests (browser tests need Debian's "
    "chromium)",
)


def _module(path: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(path.stem, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # a dataclass looks its module up there
    spec.loader.exec_module(module)
    return module


def _build(config: Path, site: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(site)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
        env={"NO_MKDOCS_2_WARNING": "1", "PATH": str(Path(sys.executable).parent) + ":/usr/bin:/bin"},
        check=False,
    )


def test_the_site_builds_strictly_with_its_generated_reference(tmp_path: Path) -> None:
    from twin.parameters import Parameters

    done = _build(ROOT / "mkdocs.yml", tmp_path / "site")
    assert done.returncode == 0, done.stderr[-3000:]
    assert "WARNING" not in done.stderr, done.stderr[-3000:]
    commands = (tmp_path / "site" / "reference" / "cli" / "index.html").read_text(encoding="utf-8")
    for name in ("run", "sweep", "validate", "calibrate", "view", "export-fmu"):
        assert f"ballbeam {name}" in commands and f"usage: ballbeam {name} " in commands, name
    parameters = (tmp_path / "site" / "reference" / "parameters" / "index.html").read_text(encoding="utf-8")
    assert all(row["name"] in parameters for row in Parameters.describe())
    for page in ("watch", "validate", "firmware", "requirements", "calibrate", "connect", "learn", "design"):
        assert (tmp_path / "site" / page / "index.html").is_file(), page


def test_a_broken_link_or_anchor_fails_the_build(tmp_path: Path) -> None:
    """The site's own validation settings, on a page with one broken link and one broken anchor."""
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "index.md").write_text("# Home\n\n[a page](missing.md), [an anchor](other.md#nowhere)\n")
    (docs / "other.md").write_text("# Other\n")
    settings = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    validation = re.search(r"^validation:\n(?:  .*\n)+", settings, re.M)
    assert validation is not None and "anchors: warn" in validation[0]
    config = tmp_path / "mkdocs.yml"
    config.write_text(f"site_name: t\ndocs_dir: {docs}\nstrict: true\n{validation[0]}")
    done = _build(config, tmp_path / "site")
    assert done.returncode == 1, done.stderr
    assert "missing.md" in done.stderr and "#nowhere" in done.stderr


@pytest.mark.quick
def test_the_reference_is_every_commands_help_and_every_parameter() -> None:
    import argparse

    from twin.app.cli import build_parser
    from twin.parameters import Parameters

    hooks = _module(ROOT / "docs" / "hooks.py")
    text = hooks.commands_markdown()
    (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    for name, command in sub.choices.items():
        assert f"## `ballbeam {name}`" in text, name
        options = {o for action in command._actions for o in action.option_strings}
        assert all(o in text for o in options), name
    table = hooks.parameters_markdown()
    rows = Parameters.describe()
    assert len(table.strip().splitlines()) == len(rows) + 2
    assert all(f"`{row['name']}`" in table and row["unit"] in table for row in rows)
    for page, marker in (("cli.md", hooks.COMMANDS_MARKER), ("parameters.md", hooks.PARAMETERS_MARKER)):
        assert marker in (ROOT / "docs" / "reference" / page).read_text(encoding="utf-8"), page


def test_the_measured_tables_are_their_json_rendered() -> None:
    docs_pages = _module(ROOT / "scripts" / "docs_pages.py")
    assert docs_pages.stale() == []
    assert {t.page.name for t in docs_pages.tables()} == {"engines.md", "firmware.md"}


def test_a_stale_table_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    docs_pages = _module(ROOT / "scripts" / "docs_pages.py")
    page = tmp_path / "engines.md"
    page.write_text(
        (ROOT / "docs" / "validation" / "engines.md").read_text().replace("| appendix-sf |", "| x |")
    )
    real = docs_pages.tables

    def tables() -> list:
        return [
            docs_pages.Table(page, t.marker, t.data, t.render) if t.page.name == page.name else t
            for t in real()
        ]

    monkeypatch.setattr(docs_pages, "tables", tables)
    assert docs_pages.stale() == [page]


@pytest.mark.quick
def test_the_readme_is_a_landing_page() -> None:
    text = README.read_text(encoding="utf-8")
    lines = text.splitlines()
    assert len(lines) <= 200
    assert lines[2] == "```bash" and tuple(lines[3:5]) == SETUP  # the two set-up commands, first, as always
    assert "](docs/view.png)" in text
    for page in ("watch", "calibrate", "validate"):  # the three jobs
        assert f"](docs/{page}.md)" in text, page
    for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", text):  # every link resolves in the clone
        assert (ROOT / target).exists(), target
