"""A controller FMU's archive, checked before anything in it is extracted or loaded, and extracted once per
process (``unpack``).

Checked first: the file itself (``twin.image``), every entry's name (no absolute path, no ``..``, no
backslash or drive) and size (``MAX_ENTRY_BYTES`` each, ``MAX_UNPACKED_BYTES`` together: a declared size is what
extraction writes, so nothing is written before the sizes pass), and every ``modelIdentifier`` the description
names: a plain C identifier, since FMPy joins it onto ``binaries/PLATFORM/`` and would load a library from
outside the unit for ``../`` or an absolute path. Then the unit is extracted into one temporary folder per
process and per unit, which the process removes when it exits (a folder left by a process that was killed is
removed by the next extraction).
"""

from __future__ import annotations

import atexit
import os
import re
import shutil
import tempfile
import zipfile
from pathlib import Path, PurePosixPath
from typing import Any

from twin.image import check_image

__all__ = [
    "MAX_ENTRY_BYTES",
    "MAX_UNPACKED_BYTES",
    "PREFIX",
    "UnitError",
    "check_description",
    "unpack",
]

# The largest unit taken: an FMU is a shared library, its description and resources (a few MB; the exported
# twin's is 1 MB).
MAX_UNPACKED_BYTES = 256 << 20
MAX_ENTRY_BYTES = 256 << 20
PREFIX = "ballbeam-fmu-"  # the extracted folders' names: PREFIX, the extracting process's id, "-", a suffix
_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_unpacked: dict[tuple[str, int, int], Path] = {}


class UnitError(RuntimeError):
    """A unit refused before it is loaded: the message names the file, the entry or field and its value."""


def _mib(n: int) -> str:
    return f"{n} bytes ({n / (1 << 20):.1f} MiB)"


def _check_entries(path: Path, archive: zipfile.ZipFile) -> None:
    total = 0
    for info in archive.infolist():
        name = info.filename
        parts = PurePosixPath(name).parts
        if "\\" in name or ":" in name or name.startswith("/") or ".." in parts:
            raise UnitError(f"{path}: entry {name!r} names a path outside the unit; not extracted")
        if info.file_size > MAX_ENTRY_BYTES:
            raise UnitError(
                f"{path}: entry {name!r} unpacks to {_mib(info.file_size)}, more than an entry's limit of "
                f"{_mib(MAX_ENTRY_BYTES)}; not extracted"
            )
        total += info.file_size
        if total > MAX_UNPACKED_BYTES:
            raise UnitError(
                f"{path}: its entries unpack to more than {_mib(MAX_UNPACKED_BYTES)} (at entry {name!r}); "
                "not extracted"
            )
    if "modelDescription.xml" not in archive.namelist():
        raise UnitError(f"{path}: not an FMU (no modelDescription.xml in the archive)")


def check_description(path: Path | str, md: Any) -> None:
    """Every interface's ``modelIdentifier`` in the description ``md`` (FMPy's) is a plain C identifier: the name
    of a library in the unit's ``binaries/PLATFORM/``, never a path (``UnitError`` naming it otherwise)."""
    for tag, interface in (
        ("CoSimulation", md.coSimulation),
        ("ModelExchange", md.modelExchange),
        ("ScheduledExecution", getattr(md, "scheduledExecution", None)),
    ):
        if interface is None:
            continue
        identifier = interface.modelIdentifier
        if not isinstance(identifier, str) or not _IDENTIFIER.fullmatch(identifier):
            raise UnitError(
                f"{path}: modelDescription.xml's <{tag} modelIdentifier={identifier!r}> is not a plain name (a C "
                "identifier: the library binaries/PLATFORM/NAME inside the unit); nothing loaded"
            )


def _check_libraries(path: Path, folder: Path, md: Any) -> None:
    """The libraries the identifiers name, where extracted, are files inside ``folder`` (no link out of it)."""
    root = folder.resolve()
    binaries = folder / "binaries"
    if not binaries.is_dir():
        return
    for interface in (md.coSimulation, md.modelExchange, getattr(md, "scheduledExecution", None)):
        if interface is None:
            continue
        for platform in binaries.iterdir():
            for lib in platform.glob(f"{interface.modelIdentifier}.*"):
                if lib.is_symlink() or not lib.resolve().is_relative_to(root):
                    rel = lib.relative_to(folder)
                    raise UnitError(f"{path}: {rel} is a link out of the unit; nothing loaded")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _sweep(base: Path) -> None:
    """Remove the folders of processes that ended without removing theirs (killed: no exit handler ran)."""
    uid = os.getuid()
    for folder in base.glob(f"{PREFIX}*-*"):
        pid_text = folder.name[len(PREFIX) :].partition("-")[0]
        try:
            if not pid_text.isdigit() or folder.stat().st_uid != uid or _alive(int(pid_text)):
                continue
        except OSError:
            continue
        shutil.rmtree(folder, ignore_errors=True)


def _remove(folder: Path, owner: int) -> None:
    if os.getpid() == owner:  # a forked worker shares its parent's folder: the parent removes it
        shutil.rmtree(folder, ignore_errors=True)


def _extract(path: Path, archive: zipfile.ZipFile) -> Path:
    base = Path(tempfile.gettempdir())
    _sweep(base)
    folder = Path(tempfile.mkdtemp(prefix=f"{PREFIX}{os.getpid()}-", dir=base))
    atexit.register(_remove, folder, os.getpid())
    try:
        archive.extractall(folder)
    except BaseException as exc:  # a full disk, Ctrl-C: nothing half-written stays behind
        shutil.rmtree(folder, ignore_errors=True)
        if isinstance(exc, OSError):
            raise UnitError(
                f"{path}: extracting the unit failed ({exc.strerror or exc}); nothing kept"
            ) from None
        raise
    return folder


def unpack(path: Path) -> Path:
    """The folder the unit at ``path`` is extracted into, checked (the module's doc); extracted once per process
    for the same file (its path, size and time stamp). ``UnitError`` naming what is refused."""
    import fmpy

    size = check_image(path, "FMU", MAX_UNPACKED_BYTES, UnitError)
    key = (str(path.resolve()), size, path.stat().st_mtime_ns)
    if key in _unpacked and _unpacked[key].is_dir():
        return _unpacked[key]
    try:
        with zipfile.ZipFile(path) as archive:
            _check_entries(path, archive)
            try:
                md = fmpy.read_model_description(str(path))
            except Exception as exc:  # noqa: BLE001 - FMPy's parser raises plain Exceptions
                raise UnitError(f"{path}: modelDescription.xml: {' '.join(str(exc).split())[:300]}") from None
            check_description(path, md)
            folder = _extract(path, archive)
    except (zipfile.BadZipFile, EOFError):
        raise UnitError(f"{path}: not an FMU (not a ZIP archive)") from None
    try:
        _check_libraries(path, folder, md)
    except UnitError:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    _unpacked[key] = folder
    return folder
