"""Output paths of the ``ballbeam`` command: checked before the work, written atomically after it.

Before a long run the command checks every output it will write (``check_output``, ``check_output_dir``,
``check_distinct``): a non-empty path with a known extension, not an existing directory, not an existing
file unless ``--overwrite``, in a directory that exists and can be written (``os.access`` and a probe file
that is removed again), with the space the output needs. Files are written by ``twin.log.atomic_output``
(a temporary file beside the target, then one rename), so a failed write leaves the old file as it was;
``writing`` turns an ``OSError`` at write time into a one-line ``OutputError`` naming the option and file.

This module imports nothing heavy: ``ballbeam --help`` must stay fast.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

__all__ = ["OutputError", "check_distinct", "check_output", "check_output_dir", "check_outputs", "writing"]

# Bytes written by the probe file: enough to need a data block, so a full disk shows up before the run.
_PROBE_BYTES = 4096


class OutputError(ValueError):
    """An output that cannot be written; the message names the option, the path and why (one line)."""


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc) or type(exc).__name__


def _probe(directory: Path, what: str, needed_bytes: int) -> None:
    """Refuse a directory that cannot take a new file of ``needed_bytes`` (a lower bound of the output)."""
    if not directory.exists():
        raise OutputError(f"{what}: the directory {directory} does not exist")
    if not directory.is_dir():
        raise OutputError(f"{what}: {directory} is not a directory")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise OutputError(f"{what}: the directory {directory} is not writable")
    try:
        fd, probe = tempfile.mkstemp(dir=directory, prefix=".ballbeam-probe.", suffix=".tmp")
    except OSError as exc:
        raise OutputError(f"{what}: cannot create a file in {directory}: {_reason(exc)}") from None
    try:
        try:
            os.write(fd, b"\0" * _PROBE_BYTES)
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as exc:
        raise OutputError(f"{what}: cannot write in {directory}: {_reason(exc)}") from None
    finally:
        try:
            os.unlink(probe)
        except OSError:
            pass
    if needed_bytes > 0:
        try:
            free = shutil.disk_usage(directory).free
        except OSError:
            return
        if free < needed_bytes:
            raise OutputError(
                f"{what}: needs at least {needed_bytes / 1e6:.1f} MB, {directory} has {free / 1e6:.1f} MB free"
            )


def check_output(
    option: str,
    text: str,
    suffixes: Sequence[str],
    *,
    overwrite: bool,
    needed_bytes: int = 0,
) -> Path:
    """The resolved path of an output file, or an ``OutputError`` naming ``option`` and ``text``.

    ``suffixes`` are the accepted extensions (lower case, with the dot; compared case-insensitively)."""
    if not text.strip():
        raise OutputError(f"{option}: the path is empty")
    what = f"{option} {text}"
    suffix = Path(text).suffix
    if suffix.lower() not in suffixes:
        known = " or ".join(suffixes)
        if suffix:
            raise OutputError(f"{what}: unknown extension {suffix!r} (use {known})")
        raise OutputError(f"{what}: no extension (use {known})")
    path = Path(text).resolve()  # symlinks followed: the file written is the one the link points to
    if path.is_dir():
        raise OutputError(f"{what}: is a directory")
    if path.exists() and not overwrite:
        raise OutputError(f"{what}: exists; not overwritten (pass --overwrite)")
    _probe(path.parent, what, needed_bytes)
    return path


def check_outputs(
    outputs: Sequence[tuple[str, str | None, Sequence[str], int]], *, overwrite: bool
) -> dict[str, Path]:
    """Check every output of one command: ``(option, text or None, suffixes, needed bytes)`` each.

    Empty paths first, then two options naming the same file, then each file (``check_output``); returns
    the resolved path of each given option."""
    given = [
        (option, text, suffixes, needed) for option, text, suffixes, needed in outputs if text is not None
    ]
    for option, text, _, _ in given:
        if not text.strip():
            raise OutputError(f"{option}: the path is empty")
    check_distinct([(option, text, Path(text).resolve()) for option, text, _, _ in given])
    return {
        option: check_output(option, text, suffixes, overwrite=overwrite, needed_bytes=needed)
        for option, text, suffixes, needed in given
    }


def check_output_dir(option: str, text: str) -> Path:
    """An output directory (created by the command): a non-empty path whose parent can be written."""
    if not text.strip():
        raise OutputError(f"{option}: the path is empty")
    path = Path(text).resolve()
    if path.exists() and not path.is_dir():
        raise OutputError(f"{option} {text}: exists and is not a directory")
    _probe(path.parent, f"{option} {text}", 0)
    return path


def check_distinct(outputs: Sequence[tuple[str, str, Path]]) -> None:
    """Refuse two outputs that are the same file: ``(option, text, resolved path)`` each."""
    for i, (option_a, text_a, a) in enumerate(outputs):
        for option_b, text_b, b in outputs[i + 1 :]:
            same = a == b
            if not same and a.exists() and b.exists():
                try:
                    same = os.path.samefile(a, b)  # hard links
                except OSError:
                    same = False
            if same:
                raise OutputError(
                    f"{option_a} {text_a} and {option_b} {text_b} are the same file: one would replace the other"
                )


@contextmanager
def writing(option: str, text: str) -> Iterator[None]:
    """Turn a failed write into a one-line ``OutputError`` naming the option and the file."""
    try:
        yield
    except FileExistsError:
        raise OutputError(f"{option} {text}: exists; not overwritten (pass --overwrite)") from None
    except OSError as exc:
        raise OutputError(f"{option} {text}: cannot write: {_reason(exc)}") from None
