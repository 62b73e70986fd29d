"""Each command reads its options once, into its own typed record: no ``getattr`` on the parsed namespace in
``commands/common.py``, no command writing into it, and a record field for every option a parser defines."""

from __future__ import annotations

import argparse
import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

from twin.app.cli import build_parser
from twin.app.commands import COMMANDS, Command
from twin.app.commands.common import ParamsOptions, option_names, options_from

pytestmark = pytest.mark.quick

COMMANDS_DIR = Path(__file__).resolve().parents[1] / "twin" / "app" / "commands"


def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _getattr_on_args(tree: ast.Module) -> list[int]:
    """Lines that call ``getattr``, ``hasattr`` or ``setattr`` on ``args``."""
    return [
        node.lineno
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and isinstance(node.func, ast.Name)
        and node.func.id in ("getattr", "hasattr", "setattr")
        and node.args
        and isinstance(node.args[0], ast.Name)
        and node.args[0].id == "args"
    ]


def _writes_to_args(tree: ast.Module) -> list[int]:
    """Lines that assign to ``args.<attr>`` (plain, augmented, annotated or in a tuple)."""
    lines: list[int] = []
    for node in ast.walk(tree):
        targets: list[ast.expr] = []
        if isinstance(node, ast.Assign):
            targets = list(node.targets)
        elif isinstance(node, (ast.AugAssign, ast.AnnAssign)):
            targets = [node.target]
        for target in targets:
            for part in ast.walk(target):
                if (
                    isinstance(part, ast.Attribute)
                    and isinstance(part.value, ast.Name)
                    and part.value.id == "args"
                ):
                    lines.append(target.lineno)
    return lines


def test_common_reads_no_option_through_getattr() -> None:
    assert _getattr_on_args(_tree(COMMANDS_DIR / "common.py")) == []


def test_the_scan_finds_what_it_looks_for() -> None:
    """The two scans are not vacuous: they see the patterns they forbid."""
    bad = ast.parse("x = getattr(args, 'set', None)\nargs.plant = 'twin'\nargs.a, args.b = 1, 2\n")
    assert _getattr_on_args(bad) == [1]
    assert _writes_to_args(bad) == [2, 3, 3]


@pytest.mark.parametrize("path", sorted(COMMANDS_DIR.glob("*.py")), ids=lambda p: p.name)
def test_no_command_writes_into_its_parsed_options(path: Path) -> None:
    tree = _tree(path)
    assert _writes_to_args(tree) == [], f"{path.name} assigns to args.<option>"
    assert _getattr_on_args(tree) == [], f"{path.name} reads an option by getattr"


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


@pytest.mark.parametrize(
    "name, module", [(name, module) for name, module, _ in COMMANDS], ids=lambda v: str(v)
)
def test_each_commands_record_reads_every_option_it_defines(name: str, module: Command) -> None:
    """A new option without its field in the command's record (or a field without its option) fails here."""
    dests = {a.dest for a in _subparsers()[name]._actions if a.dest != "help"}
    record = module.Options
    assert option_names(record) == dests
    # The record is filled from the parser's own defaults (every option and group found by name).
    defaults = argparse.Namespace(**{dest: None for dest in dests})
    filled = options_from(record, defaults)
    with pytest.raises(Exception, match="frozen|cannot assign"):
        next_field = next(iter(vars(filled)))
        setattr(filled, next_field, None)


def test_a_field_the_parser_lacks_is_refused_not_defaulted() -> None:
    @dataclass(frozen=True)
    class Record:
        seed: int
        parameters: ParamsOptions

    given = argparse.Namespace(seed=3, rig_file=None, params="p.toml", set=["a.b=1"])
    assert options_from(Record, given) == Record(3, ParamsOptions(None, "p.toml", ["a.b=1"]))
    with pytest.raises(TypeError, match="set"):
        options_from(Record, argparse.Namespace(seed=3, rig_file=None, params="p.toml"))
    with pytest.raises(TypeError, match="seed"):
        options_from(Record, argparse.Namespace(rig_file=None, params=None, set=None))


@pytest.mark.quick
def test_a_many_run_commands_job_carries_its_records_fields() -> None:
    from twin.app import cli
    from twin.app.commands import sweep, validate
    from twin.app.commands.common import options_from
    from twin.app.commands.job import ManyRunJob

    args = cli.build_parser().parse_args(["sweep", "--controller", "lqr", "--workers", "2"])
    record = options_from(sweep.Options, args)
    job = record.job()
    assert isinstance(job, ManyRunJob)
    assert (job.command, job.controller, job.workers) == ("sweep", "lqr", 2)
    assert (job.parameters, job.rigs, job.output) == (record.parameters, record.spread, record.output)
    assert job.scheduler is None and not job.is_served
    served = options_from(
        validate.Options, cli.build_parser().parse_args(["validate", "--serve", "udp://127.0.0.1:0"])
    )
    assert served.job().is_served and served.job().command == "validate"
