"""A user's image file, a firmware ELF (``avr:``) or a controller FMU (``fmu:``): checked before it is read or
loaded. It must be a regular file of bounded size; a missing path, a directory, a device, a pipe or a file
larger than its limit is refused with a message naming the path and what it is (``/dev/zero`` would be read
without end, a 1 GiB file read whole)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

__all__ = ["check_image", "open_regular", "read_image"]


def _size_text(n: int) -> str:
    return f"{n} bytes ({n / (1 << 20):.1f} MiB)" if n >= 1 << 20 else f"{n} bytes"


def open_regular(
    path: str | Path, error: type[Exception], what: str, must: str, missing: str | None = None
) -> int:
    """A descriptor open for reading the regular file at ``path`` (the caller closes it); ``error`` naming the
    path when it is missing (``missing``: the message's text then), unreadable, a directory, or a device, pipe or
    socket. ``what``: the file's kind in "cannot read …"; ``must``: what such a file is, after the refusal."""
    try:
        # O_NONBLOCK: opening a FIFO does not wait for a writer; the fstat below refuses it
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError as exc:
        text = missing if missing is not None else f"cannot read {what} ({exc.strerror or exc})"
        raise error(f"{path}: {text}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        kind = "a directory" if stat.S_ISDIR(mode) else "a device, pipe or socket"
        raise error(f"{path}: not a regular file ({kind}): {must}")
    return fd


def check_image(path: Path, what: str, max_bytes: int, error: type[Exception]) -> int:
    """The size of the image at ``path`` (``what``: "firmware image", "FMU"); ``error`` naming the path when it
    is missing or unreadable, not a regular file, or larger than ``max_bytes``."""
    fd = open_regular(path, error, f"the {what}", f"the {what} must be a regular file", f"no such {what}")
    try:
        size = os.fstat(fd).st_size
    finally:
        os.close(fd)
    if size > max_bytes:
        raise error(
            f"{path}: {_size_text(size)}, larger than the {what} limit of {_size_text(max_bytes)}; not read"
        )
    return size


def read_image(path: Path, what: str, max_bytes: int, error: type[Exception]) -> bytes:
    """The bytes of the image at ``path``, checked first (``check_image``); at most ``max_bytes`` are read even
    if the file grows meanwhile."""
    check_image(path, what, max_bytes, error)
    try:
        with open(path, "rb") as fh:
            raw = fh.read(max_bytes + 1)
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    if len(raw) > max_bytes:
        raise error(f"{path}: larger than the {what} limit of {_size_text(max_bytes)}; not read further")
    return raw
