"""The ``ballbeam`` command (application layer: it sees the controllers and hands their catalogue down).

Exit codes: 0 success (for ``run``: the ball was held), 1 a run whose ball was lost or not held, or whose
controller failed, 2 bad input (arguments, parameter files, output paths), each with a one-line message
and no traceback; 130 interrupted by Ctrl-C, 143 by SIGTERM (``kill``, ``timeout``), 129 by SIGHUP: a long
job then writes and reports the runs it finished, its outputs marked incomplete.

Outputs (``--log``, ``--plot``, ``--out``) are checked before any work (twin.outputs): a known extension of
the file written (a link's target), not an existing file unless ``--overwrite``, never an input of the
command, two options never naming the same file, a directory that exists and can be written; an ``--out``
folder never ``.``, ``..``, ``/`` or the home folder, and with ``--overwrite`` only the command's own files in
it are replaced. They are written atomically: a failed write leaves an existing file as it was.

Each command is a module of ``twin.app.commands`` (its help, its options in ``add_arguments`` and its
handler ``run``), listed once in ``twin.app.commands.COMMANDS``; the option groups and helpers several
commands share live in ``twin.app.commands.common``. ``--help`` imports nothing heavy: it lists the
registry's names (``controllers.registry`` loads no design code until a controller is built);
python-control, MuJoCo's runs and the plots are imported by the handlers that use them.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence
from typing import Any, NoReturn

from twin.app.catalogue import one_line
from twin.app.commands import COMMANDS
from twin.app.commands.common import package_version
from twin.app.options import GridType, NumberType, SpanType


class _HelpFormatter(argparse.HelpFormatter):
    """Help text wrapped at spaces only: a controller name such as thesis-clp-continuous stays whole."""

    def _split_lines(self, text: str, width: int) -> list[str]:
        import textwrap

        return textwrap.wrap(" ".join(text.split()), width, break_on_hyphens=False)


class _Parser(argparse.ArgumentParser):
    """An argparse parser whose usage errors are one line (exit 2), naming the bad argument."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _HelpFormatter)  # subcommands' parsers too
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        # "argument --x0: --x0 '…': …" (a type that names its option) → "--x0 '…': …"
        message = re.sub(r"^argument (--[\w-]+): \1 ", r"\1 ", message)
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class _VersionAction(argparse.Action):
    """``--version``: read the version only when asked (importlib.metadata is not free)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *_: object) -> None:
        print(f"ballbeam {package_version()}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="ballbeam", description="Digital twin of the two-wire ball-and-beam rig.")
    parser.add_argument("--version", action=_VersionAction, help="print the version and exit")
    sub = parser.add_subparsers(dest="command", required=True)
    for name, module, help_text in COMMANDS:
        command = sub.add_parser(name, help=help_text)
        module.add_arguments(command)
        command.set_defaults(func=module.run)
    return parser


def _option_strings(parser: argparse.ArgumentParser) -> tuple[set[str], set[str]]:
    """The options (of the parser and its subcommands) that take a number, and all options."""
    numeric: set[str] = set()
    every: set[str] = set()
    parsers = [parser]
    while parsers:
        for action in parsers.pop()._actions:
            every.update(action.option_strings)
            if action.option_strings and isinstance(action.type, (NumberType, GridType, SpanType)):
                numeric.update(action.option_strings)
            if isinstance(action, argparse._SubParsersAction):
                parsers.extend(action.choices.values())
    return numeric, every


def _is_number(text: str) -> bool:
    """A number, or a range of numbers ``LO:HI:N``."""
    try:
        for part in text.split(":"):
            float(part)
    except ValueError:
        return False
    return True


def join_negative_numbers(argv: Sequence[str], parser: argparse.ArgumentParser) -> list[str]:
    """``--x0 -1e-2`` → ``--x0=-1e-2`` for the options that take a number.

    argparse reads a token that starts with '-' as an option unless it looks like ``-1`` or ``-.5``, so
    ``-1e-2`` or ``-inf`` after a numeric option would be refused; joined with '=' it is the option's value.
    An unambiguous prefix (``--th -0.3``) counts; nothing after ``--`` is touched."""
    numeric, every = _option_strings(parser)
    args = list(argv)
    out: list[str] = []
    i = 0
    while i < len(args):
        token = args[i]
        if token == "--":
            out.extend(args[i:])
            break
        if (
            token.startswith("--")
            and "=" not in token
            and i + 1 < len(args)
            and args[i + 1].startswith("-")
            and _is_number(args[i + 1])
            and (token in numeric or (token not in every and any(n.startswith(token) for n in numeric)))
        ):
            out.append(f"{token}={args[i + 1]}")
            i += 2
            continue
        out.append(token)
        i += 1
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(join_negative_numbers(sys.argv[1:] if argv is None else argv, parser))
    except SystemExit as exc:  # --help, --version, or a usage error already reported on one line
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    from twin.guard import (
        check_timeout_s,
        command_ended,
        default_timeout_s,
        install_interrupt_handler,
        interrupt_exit_code,
        interrupt_name,
        pending_interrupt,
        set_default_timeout_s,
    )

    # The user's Ctrl-C told apart from a controller's KeyboardInterrupt; SIGTERM and SIGHUP end a job as it
    # does (exit 128 + the signal: 130, 143, 129), keeping what was done.
    install_interrupt_handler(terminate=True)
    previous_timeout_s = default_timeout_s()
    try:
        set_default_timeout_s(
            check_timeout_s(getattr(args, "controller_timeout", None), "--controller-timeout")
        )
        code = int(args.func(args))
        if pending_interrupt():  # it came as the job ended: its outputs are complete, the exit code says so
            print(
                f"ballbeam: interrupted ({interrupt_name()}) after its runs: the outputs are complete",
                file=sys.stderr,
            )
            return interrupt_exit_code()
        return code
    except BrokenPipeError:  # output piped into e.g. head
        return 0
    except SystemExit as exc:  # not ours (the controllers' calls are guarded): never a silent success
        print(f"ballbeam: error: unexpected SystemExit({exc.code!r})", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # Ctrl-C/SIGTERM outside the long jobs (which keep what they did)
        name = interrupt_name()
        print("ballbeam: interrupted" + ("" if name == "Ctrl-C" else f" ({name})"), file=sys.stderr)
        return interrupt_exit_code()
    except (ValueError, OSError) as exc:  # bad input, or an output that cannot be written: no traceback
        print(f"ballbeam: error: {one_line(exc)}", file=sys.stderr)
        return 2
    except FloatingPointError as exc:  # twin.plant.NumericalError: the simulation failed, not the input
        print(f"ballbeam: {one_line(exc)}", file=sys.stderr)
        return 1
    finally:
        set_default_timeout_s(previous_timeout_s)  # the caller's own default (main called in-process)
        command_ended()  # SIGTERM and SIGHUP back to their defaults (main called in-process)


if __name__ == "__main__":
    sys.exit(main())
