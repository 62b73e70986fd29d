"""Run logs in the thesis software's own format (appendix A), plus the twin's true state.

The appendix's Plot button runs ``save 'data_file' timem datam1 datam2 aout sampnumber x1 x2 x3 x4 u uhesap k``.
In the ``control == 5`` branch, for each tick k (1-based; index 1 holds the sample taken before driving):

    timem(k)   time of the block's last sample (s)           datam1(k)  raw ball channel, last sample (V)
    datam2(k)  raw angle channel, block mean (V)              aout(k)    DAC command written (V)
    x1…x4(k)   the controller's estimates: x (m), θ (rad), ẋ (m/s), θ̇ (rad/s)
    u(k)       torque (N·m, control-law partitioning) or motor volts (adat − 2.5)·9.6 (state feedback)
    uhesap(k)  the unclipped computed value (``Vhesap`` in the control-law callback)
    k          the last tick index (MATLAB double scalar)

On the rig, index 1 of timem/datam1/datam2/aout stays 0 (only the control == 5 branch writes them), the arrays
are preallocated to sampsize + 1 = 100001 and ``sampnumber`` is declared global but never assigned, so the
file holds it as an empty matrix. ``load_mat`` reads such files (it keeps the first k values) as well as the
twin's own, which add the true state under separate names (``TRUTH_FIELDS``; empty for a rig log).

What a loaded log must hold (``load_mat`` and ``load_csv`` alike; every refusal is a ``LogError`` naming the
file, the variable or column and, for a bad value, its index k, 1-based as in MATLAB):

* ``REQUIRED_FIELDS`` (timem, datam1, datam2, aout): present, finite.
* ``OPTIONAL_FIELDS`` (x1…x4, u, uhesap): used when present; a missing one, or an empty one (declared but never
  written, as ``uhesap`` on the rig), becomes NaN. A .mat may also lack ``k`` (then every value is a tick) and
  ``sampnumber`` (never assigned by the software: it is not read).
* ``timem`` strictly increasing from index 2 on, and from index 1 to 2 unless row 1 is the rig's unwritten
  start row (timem, datam1, datam2, aout all exactly 0; the rig's times may start anywhere after it). Row 1 is
  kept either way: the twin writes a real start block there (its time negative, before release).
* ``ball_lost`` holds 0 or 1 only.
"""

from __future__ import annotations

import csv
import io
import stat
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import BinaryIO

import numpy as np

from twin.outputs import atomic_output

__all__ = [
    "OPTIONAL_FIELDS",
    "REQUIRED_FIELDS",
    "THESIS_FIELDS",
    "TRUTH_FIELDS",
    "LogError",
    "RunLog",
    "load_csv",
    "load_mat",
    "save_csv",
    "save_mat",
    "write_csv",
    "write_mat",
]

THESIS_FIELDS = ("timem", "datam1", "datam2", "aout", "x1", "x2", "x3", "x4", "u", "uhesap")
# What the rig's I/O card recorded (a log without one of them is refused) and the controller's own values.
REQUIRED_FIELDS = THESIS_FIELDS[:4]
OPTIONAL_FIELDS = THESIS_FIELDS[4:]
TRUTH_FIELDS = (
    "true_time_s",
    "true_x_m",
    "true_theta_rad",
    "true_xdot_m_s",
    "true_thetadot_rad_s",
    "motor_volts_v",
    "ball_lost",
)
_BOOL_FIELDS = ("ball_lost",)


class LogError(ValueError):
    """A log that cannot be read or built; the message names the file and the field."""


def _empty() -> np.ndarray:
    return np.zeros(0)


@dataclass(eq=False)
class RunLog:
    """One run: the thesis's logged arrays (one value per 50 Hz tick) and the twin's true state.

    The true state has its own time base ``true_time_s`` (per tick or per physics step) and is empty for a
    log recorded on the rig."""

    timem: np.ndarray
    datam1: np.ndarray
    datam2: np.ndarray
    aout: np.ndarray
    x1: np.ndarray
    x2: np.ndarray
    x3: np.ndarray
    x4: np.ndarray
    u: np.ndarray
    uhesap: np.ndarray
    true_time_s: np.ndarray = field(default_factory=_empty)
    true_x_m: np.ndarray = field(default_factory=_empty)
    true_theta_rad: np.ndarray = field(default_factory=_empty)
    true_xdot_m_s: np.ndarray = field(default_factory=_empty)
    true_thetadot_rad_s: np.ndarray = field(default_factory=_empty)
    motor_volts_v: np.ndarray = field(default_factory=_empty)
    ball_lost: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            try:
                arr = np.array(value, dtype=bool if f.name in _BOOL_FIELDS else np.float64)  # a copy
            except (TypeError, ValueError):
                raise LogError(f"field '{f.name}' is not numeric") from None
            if arr.ndim != 1:
                raise LogError(f"field '{f.name}' has shape {arr.shape}: it must be a 1-D array")
            setattr(self, f.name, arr)
        for group in (THESIS_FIELDS, TRUTH_FIELDS):
            n = getattr(self, group[0]).size
            for name in group[1:]:
                m = getattr(self, name).size
                if m != n:
                    raise LogError(
                        f"field '{name}' has {m} values but '{group[0]}' has {n} "
                        f"(first unmatched index {min(m, n) + 1})"
                    )
        if self.timem.size == 0:
            raise LogError("field 'timem' is empty: a log holds at least the initial sample (k ≥ 1)")

    @property
    def k(self) -> int:
        """The last tick index (1-based, as in appendix A) = the number of logged ticks."""
        return int(self.timem.size)


def write_mat(log: RunLog, fh: BinaryIO) -> None:
    """Write ``log`` to an open binary file as MATLAB 5 with the thesis's variable names (1×N rows, ``k`` a
    scalar double)."""
    data: dict[str, np.ndarray | float] = {name: getattr(log, name) for name in THESIS_FIELDS}
    data["sampnumber"] = np.zeros((0, 0))  # as on the rig: declared global, never assigned
    data["k"] = float(log.k)
    for name in TRUTH_FIELDS:
        value = getattr(log, name)
        data[name] = value.astype(np.uint8) if name in _BOOL_FIELDS else value  # MATLAB: logical(ball_lost)
    import scipy.io  # lazily: 0.12 s of import that a run without a .mat file does not need

    scipy.io.savemat(fh, data, format="5", oned_as="row", do_compression=False)


def save_mat(log: RunLog, path: str | Path, *, overwrite: bool = False) -> None:
    """Write a MATLAB 5 .mat file (``write_mat``) atomically."""
    with atomic_output(path, overwrite=overwrite) as fh:  # a failed write leaves an existing file as it was
        write_mat(log, fh)


def _vector(path: Path, name: str, value: object) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        raise LogError(f"{path}: variable '{name}' is not a real numeric array (MATLAB class {arr.dtype})")
    if arr.size and sum(d > 1 for d in arr.shape) > 1:
        raise LogError(f"{path}: variable '{name}' has shape {arr.shape}: it must be a vector")
    return arr.ravel()


def _at(kind: str, name: str, index: int) -> str:
    """Where a value sits: ``index`` is 1-based (the log's k); in a CSV also its line (the header is line 1)."""
    where = f"{kind} '{name}', index {index}"
    return f"{where} (line {index + 1})" if kind == "column" else where


def _is_rig_start_row(values: dict[str, np.ndarray]) -> bool:
    """Row 1 as the rig leaves it: only the ``control == 5`` branch writes timem/datam1/datam2/aout."""
    return all(values[name].size > 0 and values[name][0] == 0.0 for name in REQUIRED_FIELDS)


def _bools(path: Path, kind: str, name: str, arr: np.ndarray) -> np.ndarray:
    """0/1 (MATLAB logical, or a number equal to 0 or 1) as booleans; anything else is refused."""
    bad = np.flatnonzero((arr != 0) & (arr != 1))  # NaN compares unequal to both: refused too
    if bad.size:
        i = int(bad[0])
        raise LogError(f"{path}: {_at(kind, name, i + 1)} is {float(arr[i]):g}: '{name}' must hold 0 or 1")
    return arr == 1


def _check_values(path: Path, kind: str, values: dict[str, np.ndarray], hint: str = "") -> None:
    """Refuse required values that are not finite and a ``timem`` that does not increase strictly (row 1 is
    exempt when it is the rig's unwritten start row)."""
    for name in REQUIRED_FIELDS:
        arr = values[name]
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            i = int(bad[0])
            raise LogError(f"{path}: {_at(kind, name, i + 1)} is {float(arr[i])!r}: '{name}' must be finite")
    t = values["timem"]
    increases = np.diff(t) > 0
    if increases.size and _is_rig_start_row(values):
        increases[0] = True
    bad = np.flatnonzero(~increases)
    if bad.size:
        i = int(bad[0]) + 1  # 0-based position of the value that fails to increase
        raise LogError(
            f"{path}: {_at(kind, 'timem', i + 1)} is {float(t[i])!r} s, not after {float(t[i - 1])!r} s at "
            f"index {i}: 'timem' must increase strictly{hint}"
        )


def _check_file(path: Path) -> None:
    """A ``LogError`` naming what ``path`` is when it is not a regular file a log can be read from: missing, a
    directory, or a device, pipe or socket (a link to ``/dev/zero`` would be endless)."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise LogError(f"{path}: no such file") from None
    except OSError as exc:
        raise LogError(f"{path}: cannot read the log ({exc.strerror or exc})") from None
    if stat.S_ISDIR(mode):
        raise LogError(f"{path}: a directory, not a log file")
    if not stat.S_ISREG(mode):
        raise LogError(f"{path}: not a regular file (a device, pipe or socket): a log is a .mat or .csv file")


def load_mat(path: str | Path, *, variables: dict[str, np.ndarray] | None = None) -> RunLog:
    """Read a log written by ``save_mat`` or by the rig's Plot button (``data_file.mat``).

    Only timem, datam1, datam2 and aout are required (see the module docstring); the file is only read.
    ``variables``: the file's variables already read as scipy.io.loadmat gives them (a MATLAB v7.3 file,
    which calib.logs reads with h5py); ``path`` then only names the file in messages."""
    path = Path(path)
    if variables is not None:
        raw = dict(variables)
    else:
        _check_file(path)
        try:
            import scipy.io

            raw = scipy.io.loadmat(path, appendmat=False)
        except NotImplementedError:  # scipy's answer to a v7.3 (HDF5) file
            raise LogError(
                f"{path}: a MATLAB v7.3 (HDF5) .mat file: ballbeam calibrate reads it; for other readers save "
                "it with save(..., '-v7') in MATLAB"
            ) from None
        except Exception as exc:  # noqa: BLE001 - for bytes that are not MAT, scipy raises many types (IndexError…)
            raise LogError(f"{path}: not a MATLAB .mat file ({exc})") from None
    k: int | None = None
    if "k" in raw:
        k_values = _vector(path, "k", raw["k"])
        if k_values.size != 1 or not float(k_values[0]).is_integer() or k_values[0] < 1:
            raise LogError(f"{path}: variable 'k' = {k_values.tolist()!r} must be one integer ≥ 1")
        k = int(k_values[0])
    if "uhesap" not in raw and "Vhesap" in raw:  # the control-law callback's name for the same value
        raw["uhesap"] = raw["Vhesap"]
    for name in REQUIRED_FIELDS:
        if name not in raw:
            raise LogError(f"{path}: variable '{name}' is missing")
    arrays = {
        name: _vector(path, name, raw[name]).astype(np.float64) for name in THESIS_FIELDS if name in raw
    }
    n = arrays["timem"].size if k is None else k
    values: dict[str, np.ndarray] = {}
    for name in THESIS_FIELDS:
        arr = arrays.get(name)
        if arr is None or (name in OPTIONAL_FIELDS and arr.size == 0):
            values[name] = np.full(n, np.nan)  # not saved, or declared but never written (uhesap on the rig)
            continue
        if arr.size < n or (k is None and arr.size != n):
            than = f"k = {k}" if k is not None else f"'timem' has {n} (there is no 'k')"
            raise LogError(
                f"{path}: variable '{name}' has {arr.size} values but {than} "
                f"(first unmatched index {min(arr.size, n) + 1})"
            )
        values[name] = arr[:n]  # the rig preallocates sampsize + 1 values
    hint = "" if k is not None else " (the file has no 'k', so every stored value is taken as a tick)"
    _check_values(path, "variable", values, hint)
    present = [name for name in TRUTH_FIELDS if name in raw]
    if present and len(present) != len(TRUTH_FIELDS):
        missing = next(name for name in TRUTH_FIELDS if name not in raw)
        raise LogError(f"{path}: variable '{missing}' is missing (the file has other true-state variables)")
    for name in present:
        arr = _vector(path, name, raw[name]).astype(np.float64)
        values[name] = _bools(path, "variable", name, arr) if name in _BOOL_FIELDS else arr
    try:
        return RunLog(**values)
    except LogError as exc:
        raise LogError(f"{path}: {exc}") from None


def write_csv(log: RunLog, fh: BinaryIO) -> None:
    """Write ``log`` to an open binary file as UTF-8 CSV: one column per array with a header row; floats at
    repr precision (they read back bit-identical). Columns shorter than the longest (the true state may have
    its own length) end in empty cells."""
    names = THESIS_FIELDS + TRUTH_FIELDS
    columns = []
    for name in names:
        value = getattr(log, name)
        if name in _BOOL_FIELDS:
            columns.append([str(int(b)) for b in value.tolist()])
        else:
            columns.append([repr(v) for v in value.tolist()])  # shortest repr that reads back exactly
    rows = max(len(c) for c in columns)
    text = io.TextIOWrapper(fh, encoding="utf-8", newline="")
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(names)
    for i in range(rows):
        writer.writerow([c[i] if i < len(c) else "" for c in columns])
    text.flush()
    text.detach()  # the caller closes the file


def save_csv(log: RunLog, path: str | Path, *, overwrite: bool = False) -> None:
    """Write a CSV file (``write_csv``) atomically."""
    with atomic_output(path, overwrite=overwrite) as fh:  # a failed write leaves an existing file as it was
        write_csv(log, fh)


def load_csv(path: str | Path) -> RunLog:
    """Read a log written by ``save_csv`` (or by hand: only timem, datam1, datam2 and aout are required; a
    UTF-8 byte-order mark is accepted). The file is only read."""
    path = Path(path)
    _check_file(path)
    try:
        # utf-8-sig: a leading byte-order mark (a spreadsheet's "CSV UTF-8") is dropped, none is needed
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise LogError(f"{path}: not a CSV text file (not UTF-8 text)") from None
    rows = list(csv.reader(io.StringIO(text, newline="")))
    if not rows:
        raise LogError(f"{path}: empty file, expected a header row naming the columns")
    header = rows[0]
    known = THESIS_FIELDS + TRUTH_FIELDS
    for name in header:
        if name not in known:
            raise LogError(f"{path}: unknown column '{name}' (expected {', '.join(known)})")
    if len(set(header)) != len(header):
        raise LogError(f"{path}: a column appears twice in the header")
    for name in REQUIRED_FIELDS:
        if name not in header:
            raise LogError(f"{path}: column '{name}' is missing")
    present_truth = [name for name in TRUTH_FIELDS if name in header]
    if present_truth and len(present_truth) != len(TRUTH_FIELDS):
        missing = next(name for name in TRUTH_FIELDS if name not in header)
        raise LogError(f"{path}: column '{missing}' is missing (the file has other true-state columns)")
    cells: dict[str, list[str]] = {name: [] for name in header}
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise LogError(f"{path}: line {line} has {len(row)} cells, the header has {len(header)}")
        for name, cell in zip(header, row, strict=True):
            cells[name].append(cell)
    values: dict[str, np.ndarray] = {}
    for name, column in cells.items():
        n = column.index("") if "" in column else len(column)
        if any(cell != "" for cell in column[n:]):
            raise LogError(f"{path}: column '{name}' has an empty cell at line {n + 2} followed by values")
        try:
            numbers = [float(cell) for cell in column[:n]]
        except ValueError:
            bad = next(i for i, cell in enumerate(column[:n]) if not _is_float(cell))
            raise LogError(
                f"{path}: column '{name}', line {bad + 2}: {column[bad]!r} is not a number"
            ) from None
        values[name] = np.array(numbers, dtype=np.float64)
        if name in _BOOL_FIELDS:
            values[name] = _bools(path, "column", name, values[name])
    ticks = values["timem"].size
    for name in OPTIONAL_FIELDS:
        if name not in values or values[name].size == 0:
            values[name] = np.full(ticks, np.nan)  # not recorded: as a .mat without the variable
    _check_values(path, "column", values)
    try:
        return RunLog(**values)
    except LogError as exc:
        raise LogError(f"{path}: {exc}") from None


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
