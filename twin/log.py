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
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import scipy.io

__all__ = [
    "THESIS_FIELDS",
    "TRUTH_FIELDS",
    "LogError",
    "RunLog",
    "load_csv",
    "load_mat",
    "save_csv",
    "save_mat",
]

THESIS_FIELDS = ("timem", "datam1", "datam2", "aout", "x1", "x2", "x3", "x4", "u", "uhesap")
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
                if getattr(self, name).size != n:
                    raise LogError(
                        f"field '{name}' has {getattr(self, name).size} values but '{group[0]}' has {n}"
                    )
        if self.timem.size == 0:
            raise LogError("field 'timem' is empty: a log holds at least the initial sample (k ≥ 1)")

    @property
    def k(self) -> int:
        """The last tick index (1-based, as in appendix A) = the number of logged ticks."""
        return int(self.timem.size)


def _open_new(path: Path, overwrite: bool) -> io.BufferedWriter:
    try:
        return open(path, "wb" if overwrite else "xb")
    except FileExistsError:
        raise FileExistsError(f"{path}: exists; not overwritten (pass overwrite=True)") from None


def save_mat(log: RunLog, path: str | Path, *, overwrite: bool = False) -> None:
    """Write a MATLAB 5 .mat file with the thesis's variable names (1×N rows, ``k`` a scalar double)."""
    path = Path(path)
    data: dict[str, np.ndarray | float] = {name: getattr(log, name) for name in THESIS_FIELDS}
    data["sampnumber"] = np.zeros((0, 0))  # as on the rig: declared global, never assigned
    data["k"] = float(log.k)
    for name in TRUTH_FIELDS:
        value = getattr(log, name)
        data[name] = value.astype(np.uint8) if name in _BOOL_FIELDS else value  # MATLAB: logical(ball_lost)
    with _open_new(path, overwrite) as fh:
        scipy.io.savemat(fh, data, format="5", oned_as="row", do_compression=False)


def _vector(path: Path, name: str, value: object) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        raise LogError(f"{path}: variable '{name}' is not a real numeric array (MATLAB class {arr.dtype})")
    if arr.size and sum(d > 1 for d in arr.shape) > 1:
        raise LogError(f"{path}: variable '{name}' has shape {arr.shape}: it must be a vector")
    return arr.ravel()


def load_mat(path: str | Path) -> RunLog:
    """Read a log written by ``save_mat`` or by the rig's Plot button (``data_file.mat``)."""
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: no such file")
    try:
        raw = scipy.io.loadmat(path, appendmat=False)
    except Exception as exc:  # noqa: BLE001 - for bytes that are not MAT, scipy raises many types (IndexError…)
        raise LogError(f"{path}: not a MATLAB .mat file ({exc})") from None
    if "k" not in raw:
        raise LogError(f"{path}: variable 'k' (the last tick index) is missing")
    k_values = _vector(path, "k", raw["k"])
    if k_values.size != 1 or not float(k_values[0]).is_integer() or k_values[0] < 1:
        raise LogError(f"{path}: variable 'k' = {k_values.tolist()!r} must be one integer ≥ 1")
    k = int(k_values[0])
    if "uhesap" not in raw and "Vhesap" in raw:  # the control-law callback's name for the same value
        raw["uhesap"] = raw["Vhesap"]
    values: dict[str, np.ndarray] = {}
    for name in THESIS_FIELDS:
        if name not in raw:
            raise LogError(f"{path}: variable '{name}' is missing")
        arr = _vector(path, name, raw[name]).astype(np.float64)
        if name == "uhesap" and arr.size == 0:
            arr = np.full(k, np.nan)  # declared but never written (control-law runs on the rig)
        if arr.size < k:
            raise LogError(f"{path}: variable '{name}' has {arr.size} values but k = {k}")
        values[name] = arr[:k]  # the rig preallocates sampsize + 1 values
    present = [name for name in TRUTH_FIELDS if name in raw]
    if present and len(present) != len(TRUTH_FIELDS):
        missing = next(name for name in TRUTH_FIELDS if name not in raw)
        raise LogError(f"{path}: variable '{missing}' is missing (the file has other true-state variables)")
    for name in present:
        arr = _vector(path, name, raw[name])
        values[name] = arr != 0 if name in _BOOL_FIELDS else arr.astype(np.float64)
    try:
        return RunLog(**values)
    except LogError as exc:
        raise LogError(f"{path}: {exc}") from None


def save_csv(log: RunLog, path: str | Path, *, overwrite: bool = False) -> None:
    """Write one column per array with a header row; floats at repr precision (they read back bit-identical).

    Columns shorter than the longest (the true state may have its own length) end in empty cells."""
    path = Path(path)
    names = THESIS_FIELDS + TRUTH_FIELDS
    columns = []
    for name in names:
        value = getattr(log, name)
        if name in _BOOL_FIELDS:
            columns.append([str(int(b)) for b in value.tolist()])
        else:
            columns.append([repr(v) for v in value.tolist()])  # shortest repr that reads back exactly
    rows = max(len(c) for c in columns)
    with _open_new(path, overwrite) as fh, io.TextIOWrapper(fh, encoding="utf-8", newline="") as text:
        writer = csv.writer(text, lineterminator="\n")
        writer.writerow(names)
        for i in range(rows):
            writer.writerow([c[i] if i < len(c) else "" for c in columns])


def load_csv(path: str | Path) -> RunLog:
    """Read a log written by ``save_csv``."""
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: no such file")
    try:
        text = path.read_text(encoding="utf-8")
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
    for name in THESIS_FIELDS:
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
            if not np.all((values[name] == 0) | (values[name] == 1)):
                raise LogError(f"{path}: column '{name}' must hold 0 or 1")
            values[name] = values[name] == 1
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
