"""A user's image file, a firmware ELF (``avr:``) or a controller FMU (``fmu:``): checked before it is read or
loaded. It must be a regular file of bounded size; a missing path, a directory, a device, a pipe or a file
larger than its limit is refused with a message naming the path and what it is (``/dev/zero`` would be read
without end, a 1 GiB file read whole)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

__all__ = ["check_image", "read_image"]


def _size_text(n: int) -> str:
    return f"{n} bytes ({n / (1 << 20):.1f} MiB)" if n >= 1 << 20 else f"{n} bytes"


def check_image(path: Path, what: str, max_bytes: int, error: type[Exception]) -> int:
    """The size of the image at ``path`` (``what``: "firmware image", "FMU"); ``error`` naming the path when it
    is missing or unreadable, not a regular file, or larger than ``max_bytes``."""
    try:
        # O_NONBLOCK: opening a FIFO does not wait for a writer; the fstat below refuses it
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise error(f"{path}: no such {what}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    try:
        info = os.fstat(fd)
    finally:
        os.close(fd)
    if stat.S_ISDIR(info.st_mode):
        raise error(f"{path}: a directory; the {what} must be a file")
    if not stat.S_ISREG(info.st_mode):
        raise error(f"{path}: a device, pipe or socket; the {what} must be a regular file")
    if info.st_size > max_bytes:
        raise error(
            f"{path}: {_size_text(info.st_size)}, larger than the {what} limit of {_size_text(max_bytes)}; "
            "not read"
        )
    return info.st_size


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
