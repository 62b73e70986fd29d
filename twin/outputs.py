"""Output paths of every command: checked before the work, written atomically after it, nothing of the user's lost.

Files (``--log``, ``--plot``, ``calibrate-static --out``, ``experiment --out``): ``check_output`` resolves a
symlink first (the file written is the link's target, so the target's name must carry the extension; a
dangling link is refused rather than creating its target), refuses directories, FIFOs, devices and sockets,
an existing file unless ``--overwrite``, a file that is one of the job's inputs, and a directory that cannot
take the file (``os.access``, a probe file that is removed again, the free space). ``atomic_output`` writes
through a temporary file beside the target and one ``os.replace``, so a failed write keeps the old file.

Folders (``--out`` of sweep, montecarlo, validate, calibrate): ``check_output_folder`` refuses ``/``, the home
folder, the current folder or one of its parents, and the repository's root before any work; an existing
folder needs ``--overwrite``, and then only the files the job owns are replaced: every other file in it (a
``.git/``, a rig log, a params, spread or criteria file) is kept as it is. The job owns a file it wrote there
itself, recorded in ``MANIFEST`` (per job, each file's SHA-256) and unchanged since; a file with one of the
job's names that it does not own (the user's, another command's, edited since, or a link) is refused, named,
and so is one of the job's inputs. ``atomic_directory`` writes the job's files into a new temporary folder,
then moves them into place one by one (each an ``os.replace``) and updates the manifest; a file of the same
job's earlier run that this run does not write is removed only while it is still owned. A folder is never
deleted wholesale.

This module imports nothing heavy: ``ballbeam --help`` must stay fast.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import stat
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

__all__ = [
    "MANIFEST",
    "JobFiles",
    "OutputError",
    "OutputExistsError",
    "atomic_directory",
    "atomic_output",
    "check_distinct",
    "check_output",
    "check_output_folder",
    "check_outputs",
    "write_atomic",
    "write_measured_table",
    "writing",
]

# What a job wrote into a folder, per job: {"jobs": {job: {name: sha256}}} (hidden: it is bookkeeping).
MANIFEST = ".ballbeam-outputs.json"
# Bytes written by the probe file: enough to need a data block, so a full disk shows up before the run.
_PROBE_BYTES = 4096
# The repository (or site-packages) holding this package: never an output folder.
_PACKAGE_ROOT = Path(__file__).resolve().parents[1]

# (option, text as given) of each input file or folder of a job.
Inputs = Sequence[tuple[str, str]]


@dataclass(frozen=True)
class JobFiles:
    """What one kind of job writes into its output folder: its name (its key in ``MANIFEST``) and the names of
    the files it may write (all checked before the job runs)."""

    job: str
    files: tuple[str, ...]


class OutputError(ValueError):
    """An output that cannot be written; the message names the option, the path and why (one line)."""


class OutputExistsError(OutputError, FileExistsError):
    """An existing output, refused without ``overwrite``."""


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


def _kind(mode: int) -> str | None:
    """What a non-regular file is, or None for a regular file."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _resolve(what: str, given: Path) -> Path:
    """``given`` with every symlink resolved; a link whose target does not exist is refused (writing through
    it would create the target, somewhere the user did not name)."""
    try:
        if given.is_symlink():
            try:
                return given.resolve(strict=True)
            except FileNotFoundError:
                raise OutputError(
                    f"{what}: a link to {os.readlink(given)}, which does not exist: give the target itself"
                ) from None
        return given.resolve()
    except (RuntimeError, OSError) as exc:  # a loop of links (RuntimeError before Python 3.13)
        if isinstance(exc, OutputError):
            raise
        raise OutputError(f"{what}: cannot resolve the path: {exc}") from None


def _same(a: Path, b: Path) -> bool:
    if a == b:
        return True
    try:
        return os.path.samefile(a, b)  # hard links, bind mounts
    except OSError:
        return False


def _input_entries(inputs: Inputs) -> list[tuple[str, str, list[Path]]]:
    """Each input as (option, text, [its directory entry with the folder resolved, its resolved target])."""
    out = []
    for option, text in inputs:
        given = Path(text)
        try:
            entry = given.parent.resolve() / given.name
            out.append((option, text, [entry, given.resolve()]))
        except (RuntimeError, OSError):
            continue
    return out


def _refuse_inputs(what: str, path: Path, inputs: Inputs) -> None:
    """Refuse an output ``path`` that is one of the job's input files (by name, through links, or the same
    file by inode)."""
    for option, text, candidates in _input_entries(inputs):
        if any(_same(path, c) for c in candidates):
            raise OutputError(
                f"{what}: {path} is the input {option} {text}: an output never replaces an input"
            )


def check_output(
    option: str,
    text: str,
    suffixes: Sequence[str],
    *,
    overwrite: bool,
    needed_bytes: int = 0,
    inputs: Inputs = (),
) -> Path:
    """The resolved path of an output file, or an ``OutputError`` naming ``option`` and ``text``.

    ``suffixes`` are the accepted extensions (lower case, with the dot; compared case-insensitively) of the
    file written: a link's target's name, not the link's."""
    if not text.strip():
        raise OutputError(f"{option}: the path is empty")
    what = f"{option} {text}"
    given = Path(text)
    path = _resolve(what, given)
    through = f" (a link to {path})" if given.is_symlink() else ""
    kind = _kind(os.stat(path).st_mode) if os.path.lexists(path) else None
    if kind is not None:
        raise OutputError(f"{what}{through}: is {kind}, not a file to write")
    suffix = path.suffix
    if suffix.lower() not in suffixes:
        known = " or ".join(suffixes)
        if suffix:
            raise OutputError(f"{what}{through}: unknown extension {suffix!r} (use {known})")
        raise OutputError(f"{what}{through}: no extension (use {known})")
    if os.path.lexists(path) and not overwrite:
        raise OutputExistsError(f"{what}: exists; not overwritten (pass --overwrite)")
    _refuse_inputs(what, path, inputs)
    _probe(path.parent, what, needed_bytes)
    return path


def check_outputs(
    outputs: Sequence[tuple[str, str | None, Sequence[str], int]], *, overwrite: bool, inputs: Inputs = ()
) -> dict[str, Path]:
    """Check every output file of one command: ``(option, text or None, suffixes, needed bytes)`` each.

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
        option: check_output(option, text, suffixes, overwrite=overwrite, needed_bytes=needed, inputs=inputs)
        for option, text, suffixes, needed in given
    }


def _unsafe_folder(path: Path) -> str | None:
    """Why ``path`` (resolved) must never be an output folder, or None."""
    if path == Path(path.anchor):
        return "the root folder"
    home = Path.home().resolve()
    if path == home:
        return "the home folder"
    cwd = Path.cwd().resolve()
    if path == cwd:
        return "the current folder"
    if path in cwd.parents:
        return "a parent of the current folder"
    if path in home.parents:
        return "a parent of the home folder"
    if path == _PACKAGE_ROOT:
        return "the repository's root"
    return None


def _owned(folder: Path, recorded: dict[str, str], name: str) -> bool:
    """Whether ``folder/name`` is a regular file with the bytes the job recorded when it wrote it."""
    entry = folder / name
    if name not in recorded or entry.is_symlink() or not entry.is_file():
        return False
    try:
        return _sha256(entry) == recorded[name]
    except OSError:
        return False


def check_output_folder(
    option: str, text: str, outputs: JobFiles, *, overwrite: bool, inputs: Inputs = ()
) -> Path:
    """The resolved path of the folder a job writes ``outputs`` into, or an ``OutputError`` naming ``option``
    and ``text``. An existing folder needs ``overwrite``, and in it every entry with one of the job's file
    names must be a file the job owns (it wrote it and it is unchanged) and not one of the job's ``inputs``."""
    if not text.strip():
        raise OutputError(f"{option}: the path is empty")
    what = f"{option} {text}"
    path = _resolve(what, Path(text))
    unsafe = _unsafe_folder(path)
    if unsafe is not None:
        raise OutputError(f"{what}: is {unsafe} ({path}): give a folder of its own for the results")
    if not os.path.lexists(path):
        _probe(path.parent, what, 0)
        return path
    if not path.is_dir():
        raise OutputError(f"{what}: exists and is not a directory")
    if not overwrite:
        raise OutputExistsError(
            f"{what}: exists; not overwritten (pass --overwrite: only the {outputs.job} files it wrote there "
            "are replaced, other files are kept)"
        )
    recorded = _read_manifest(path).get(outputs.job, {})
    foreign = []
    for name in outputs.files:
        entry = path / name
        if not os.path.lexists(entry):
            continue
        mode = os.lstat(entry).st_mode
        kind = _kind(mode)
        if kind is not None and not stat.S_ISLNK(mode):
            raise OutputError(f"{what}: {entry} is {kind}, where the command writes a file")
        _refuse_inputs(what, entry, inputs)
        if not _owned(path, recorded, name):
            foreign.append(name)
    if foreign:
        raise OutputError(
            f"{what}: holds {', '.join(foreign)} not written there by {outputs.job} (or changed since): "
            "--overwrite replaces only its own files; move them or give another folder"
        )
    _probe(path, what, 0)
    return path


def check_distinct(outputs: Sequence[tuple[str, str, Path]]) -> None:
    """Refuse two outputs that are the same file: ``(option, text, resolved path)`` each."""
    for i, (option_a, text_a, a) in enumerate(outputs):
        for option_b, text_b, b in outputs[i + 1 :]:
            same = a == b
            if not same and a.exists() and b.exists():
                same = _same(a, b)
            if same:
                raise OutputError(
                    f"{option_a} {text_a} and {option_b} {text_b} are the same file: one would replace the other"
                )


@contextmanager
def writing(option: str, text: str) -> Iterator[None]:
    """Turn a failed write into a one-line ``OutputError`` naming the option and the file."""
    try:
        yield
    except FileExistsError:  # appeared since the check
        raise OutputExistsError(f"{option} {text}: exists; not overwritten (pass --overwrite)") from None
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(f"{option} {text}: cannot write: {_reason(exc)}") from None


# --- writing ----------------------------------------------------------------------------------------------
def _exists_error(path: Path) -> FileExistsError:
    return FileExistsError(f"{path}: exists; not overwritten (pass overwrite=True)")


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


def _file_mode(path: Path) -> int:
    """The mode of the file being replaced, or a new file's (0o666 less the umask)."""
    try:
        return stat.S_IMODE(os.stat(path).st_mode)
    except OSError:
        return 0o666 & ~_umask()


@contextmanager
def atomic_output(path: str | Path, *, overwrite: bool = False) -> Iterator[BinaryIO]:
    """A binary file to write ``path`` through, atomically: the data goes to a temporary file in the same
    directory, which replaces ``path`` in one step (``os.replace``) when the block ends without error. On
    an error the temporary file is removed and whatever was at ``path`` is left as it was. Without
    ``overwrite`` an existing ``path`` is refused (``FileExistsError``), also one that appears meanwhile
    (the file is linked into place, which fails on an existing name)."""
    path = Path(path)
    if not overwrite and os.path.lexists(path):
        raise _exists_error(path)
    try:
        fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:  # name the file asked for, not the temporary one
        raise type(exc)(exc.errno, exc.strerror, str(path)) from None
    tmp = Path(tmp_name)
    try:
        with os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, _file_mode(path))
        if overwrite:
            os.replace(tmp, path)
            return
        try:
            os.link(tmp, path)  # fails if path exists: a file created since the check is not replaced
        except FileExistsError:
            raise _exists_error(path) from None
        except OSError:  # no hard links on this file system
            if os.path.lexists(path):
                raise _exists_error(path) from None
            os.replace(tmp, path)
            return
    except BaseException:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise
    try:  # linked into place: the temporary name goes
        tmp.unlink()
    except OSError:
        pass


def write_atomic(path: str | Path, data: bytes | str, *, overwrite: bool = False) -> None:
    """Write ``data`` (text as UTF-8) to ``path`` through ``atomic_output``: a failure keeps the old file."""
    with atomic_output(path, overwrite=overwrite) as fh:
        fh.write(data.encode("utf-8") if isinstance(data, str) else data)


def write_measured_table(
    json_path: str | Path, data: Any, readme: str | Path, marker: str, table: str
) -> None:
    """A measurement's JSON (``data``) and its rendering (``table``) into the README between ``<!-- marker -->``
    and ``<!-- /marker -->`` (the documentation scripts' ``--write-docs``), each file atomically."""
    write_atomic(json_path, json.dumps(data, indent=1) + "\n", overwrite=True)
    begin, end = f"<!-- {marker} -->\n", f"<!-- /{marker} -->"
    head, found, rest = Path(readme).read_text().partition(begin)
    if not found:
        raise ValueError(f"{readme}: no {begin.strip()} marker to write the table after")
    _, _, tail = rest.partition(end)
    write_atomic(readme, head + begin + table + end + tail, overwrite=True)


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def _read_manifest(folder: Path) -> dict[str, dict[str, str]]:
    """The jobs' records of an existing folder ({} when there is none or it is not ours)."""
    try:
        data = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
        jobs = data["jobs"]
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    if not isinstance(jobs, dict):
        return {}
    return {
        str(job): {str(k): str(v) for k, v in record.items()}
        for job, record in jobs.items()
        if isinstance(record, dict)
    }


def _manifest_bytes(jobs: dict[str, dict[str, str]]) -> bytes:
    return (json.dumps({"jobs": jobs}, indent=1, sort_keys=True) + "\n").encode("utf-8")


@contextmanager
def atomic_directory(path: str | Path, outputs: JobFiles, *, overwrite: bool = False) -> Iterator[Path]:
    """A new temporary folder to write the job's files (``outputs.files``, names only) into; when the block
    ends without error they take their places in ``path``.

    A new ``path`` is the temporary folder renamed (it appears complete or not at all). An existing one
    (only with ``overwrite``, and only if the job owns every file it replaces: ``check_output_folder``) gets
    each file by ``os.replace``, every other entry kept; a file the job wrote there before, does not write
    now and still owns is removed. On an error the temporary folder is removed and ``path`` is as it was (a
    failure while the files are being moved in leaves those already moved)."""
    out = check_output_folder("output folder", str(path), outputs, overwrite=overwrite)
    exists = os.path.lexists(out)
    tmp = Path(tempfile.mkdtemp(prefix=".ballbeam-tmp.", dir=out if exists else out.parent))
    try:
        yield tmp
        written = sorted(p.name for p in tmp.iterdir())
        undeclared = [name for name in written if name not in outputs.files]
        if undeclared:  # a writer's bug: an undeclared name was not checked against the inputs
            raise RuntimeError(f"{out}: the job wrote undeclared files {undeclared}")
        record = {name: _sha256(tmp / name) for name in written}
        if not exists:
            (tmp / MANIFEST).write_bytes(_manifest_bytes({outputs.job: record}))
            os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp makes it 0700
            try:
                os.rename(tmp, out)  # an empty folder created meanwhile is replaced, a non-empty one refuses
            except OSError:
                if os.path.lexists(out):
                    raise _exists_error(out) from None
                raise
            return
        check_output_folder("output folder", str(out), outputs, overwrite=True)  # nothing changed meanwhile
        jobs = _read_manifest(out)
        before = jobs.get(outputs.job, {})
        stale = [n for n in before if n not in record and n in outputs.files and _owned(out, before, n)]
        for name in written:
            target = out / name
            if os.path.lexists(target):
                os.chmod(tmp / name, _file_mode(target))
            os.replace(tmp / name, target)
        for name in stale:
            (out / name).unlink()
        jobs[outputs.job] = record
        with atomic_output(out / MANIFEST, overwrite=True) as fh:
            fh.write(_manifest_bytes(jobs))
        tmp.rmdir()
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
