"""The ``ballbeam`` subcommands, one module each: its help (``HELP``), its options (``add_arguments``), the
frozen record they are read into once (``Options``, filled by ``common.options_from``) and its handler
(``run``, returning the exit code). ``COMMANDS`` lists them once, in the order ``ballbeam --help`` shows them;
``twin.app.cli`` builds its parser from it. What several commands share is in ``common``, the many-run jobs'
skeleton in ``job``.

Every module imports only light code at its top (``--help`` imports them all); a handler imports what it
needs when it runs.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Protocol

from twin.app.commands import (
    calibrate,
    calibrate_static,
    certify,
    compare,
    experiment,
    export_fmu,
    falsify,
    judge,
    linearize,
    montecarlo,
    params,
    run,
    serve,
    shadow,
    sweep,
    validate,
    view,
)

if TYPE_CHECKING:
    from _typeshed import DataclassInstance


class Command(Protocol):
    """A command's module: its options, their typed record and its handler (the exit code)."""

    @property
    def Options(self) -> type[DataclassInstance]: ...  # noqa: N802 (the module's class)

    def add_arguments(self, parser: argparse.ArgumentParser) -> None: ...

    def run(self, args: argparse.Namespace) -> int: ...


# The subcommands in the order ``--help`` lists them: (name, module, help).
COMMANDS: tuple[tuple[str, Command, str], ...] = (
    ("linearize", linearize, linearize.HELP),
    ("run", run, run.HELP),
    ("serve", serve, serve.HELP),
    ("shadow", shadow, shadow.HELP),
    ("judge", judge, judge.HELP),
    ("sweep", sweep, sweep.HELP),
    ("montecarlo", montecarlo, montecarlo.HELP),
    ("validate", validate, validate.HELP),
    ("falsify", falsify, falsify.HELP),
    ("certify", certify, certify.HELP),
    ("view", view, view.HELP),
    ("calibrate", calibrate, calibrate.HELP),
    ("compare", compare, compare.HELP),
    ("calibrate-static", calibrate_static, calibrate_static.HELP),
    ("experiment", experiment, experiment.HELP),
    ("params", params, params.HELP),
    ("export-fmu", export_fmu, export_fmu.HELP),
)
