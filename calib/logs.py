"""The calibration package's reader: a log recorded on the rig (or by the twin), reduced to what the rig records.

``load_rig_log(path)`` reads ``data_file.mat`` (appendix A's Plot button) or a CSV through ``twin.log`` and keeps
the four signals the I/O card recorded, for the ticks identification uses:

    time_s     timem    time of the block's last sample (s)
    ball_v     datam1   raw ball channel, last sample of the block (V)
    angle_v    datam2   raw angle channel, block mean (V)
    command_v  aout     DAC command written at that tick (V)

Row 1 of the log (k = 1) is dropped: it is the sample taken before the motor was driven, whose command the rig
never wrote (on the rig its four values stay 0; in the twin's logs it is the held start block). Element ``i``
of a ``RigLog`` array is therefore tick ``k = i + 2`` of the file, and every refusal names that k. The twin's
true state (``true_*``) is never read into a ``RigLog``: identification sees only what the rig sees.

Every refusal is a ``twin.log.LogError`` naming the file, the variable (the file's name, with the RigLog
field's) and the first bad index.

A MATLAB v7.3 ``.mat`` (``save -v7.3``: an HDF5 file behind a 512-byte MATLAB header) is read with h5py and
checked as a v5 file is.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from twin.interface import CommandRange
from twin.log import LogError, RunLog, load_csv, load_mat
from twin.parameters import Parameters

__all__ = [
    "rig_log",
    "ADC_MAX_V",
    "ADC_MIN_V",
    "ADC_STEP_V",
    "DAC_MAX_V",
    "DAC_MIN_V",
    "DAC_STEP_V",
    "FIRST_INDEX",
    "MAX_GAP_PERIODS",
    "MIN_BALL_SPAN_V",
    "MIN_COMMAND_SPAN_V",
    "MIN_DURATION_S",
    "PERIOD_TOLERANCE",
    "RigLog",
    "check_period",
    "load_judged_log",
    "load_rig_log",
    "read_mat73",
]

# The PCI-1712 as the thesis set it up (Table 6.4, §6.5): 12-bit DAC over 0…5 V, 12-bit ADC over −5…5 V.
DAC_MIN_V = 0.0
DAC_MAX_V = 5.0
DAC_STEP_V = (DAC_MAX_V - DAC_MIN_V) / 4096  # 1.221 mV
ADC_STEP_V = 10.0 / 4096  # 2.441 mV
ADC_MIN_V = -5.0
ADC_MAX_V = 5.0

# At least 5 s of data: several periods of the closed loop's slowest motion (the limit cycles seen on the twin
# last 0.7 s, the settling 2.5–3 s), 250 ticks at 50 Hz.
MIN_DURATION_S = 5.0
# A command that never moves by more than 2 DAC steps is a constant plus the DAC's rounding: it says nothing
# about the motor and beam.
MIN_COMMAND_SPAN_V = 2 * DAC_STEP_V
# A ball reading spanning fewer than 10 ADC steps (24 mV, about 1.7 mm through eq 6.3.1) is quantization and
# contact noise (a few steps), not motion of the ball.
MIN_BALL_SPAN_V = 10 * ADC_STEP_V
# A tick spacing beyond 1.5 periods is a missed block (the next one is 2 periods away): the samples are no
# longer one per period, as the zero-order-hold models assume.
MAX_GAP_PERIODS = 1.5

# A log's median tick spacing (timem) must be daq.period_s within 1 %: a PC timer's period holds to far better
# over a log, and a log recorded at another period (10 ms read as 20 ms) or in other units (ms) is a factor away.
PERIOD_TOLERANCE = 0.01

# A MATLAB v7.3 file: the text header "MATLAB 7.3 MAT-file…" in an HDF5 user block of 512 bytes, then HDF5.
MAT73_HEADER = b"MATLAB 7.3 MAT-file"
MAT73_USERBLOCK_BYTES = 512
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"

# Element 0 of a RigLog array is tick k = 2 of the file (row 1, the start sample, is dropped).
FIRST_INDEX = 2

# RigLog field -> the thesis software's variable (the name a refusal shows first: the one in the file).
_SOURCE = {"time_s": "timem", "ball_v": "datam1", "angle_v": "datam2", "command_v": "aout"}


def _name(rig_field: str) -> str:
    return f"'{_SOURCE[rig_field]}' ({rig_field})"


@dataclass(frozen=True, eq=False)
class RigLog:
    """The rig's recorded signals over the identification ticks (k = 2 … the log's k), validated.

    The arrays are read-only float64 copies; ``period_s`` is the median tick spacing. Building one checks
    it (a refusal is a ``LogError`` naming ``path``, the field and the first bad tick k)."""

    path: Path
    time_s: np.ndarray
    ball_v: np.ndarray
    angle_v: np.ndarray
    command_v: np.ndarray
    # False: a span of a longer stream (the shadow's live windows): checked tick by tick as a log is, but not
    # held to identification's minimum duration and excitation.
    whole: bool = field(default=True, repr=False)
    # The board's output range (a rig of other parts: its board's, ``CommandRange``); None: the PCI-1712's DAC,
    # whose ADC's ±5 V the readings are held to as well (another board's readings are in its sensors' units).
    board: CommandRange | None = field(default=None, repr=False)
    period_s: float = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))
        for name in _SOURCE:
            arr = np.array(getattr(self, name), dtype=np.float64)  # a copy
            if arr.ndim != 1:
                raise LogError(f"{self.path}: {_name(name)} has shape {arr.shape}: it must be a 1-D array")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "period_s", self._validate())

    @property
    def ticks(self) -> int:
        """The number of identification ticks (the log's k − 1)."""
        return int(self.time_s.size)

    @property
    def duration_s(self) -> float:
        """Time from the first to the last identification tick."""
        return float(self.time_s[-1] - self.time_s[0]) if self.time_s.size else 0.0

    def _fail(self, rig_field: str, i: int | None, what: str) -> LogError:
        where = "" if i is None else f", index {i + FIRST_INDEX}"
        return LogError(f"{self.path}: {_name(rig_field)}{where}: {what}")

    def _validate(self) -> float:
        """Check the log is usable for identification; return the median tick spacing."""
        t, n = self.time_s, self.time_s.size
        for name in ("ball_v", "angle_v", "command_v"):
            m = getattr(self, name).size
            if m != n:
                raise self._fail(name, min(m, n), f"has {m} values but 'timem' (time_s) has {n}")
        for name in _SOURCE:
            arr = getattr(self, name)
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                i = int(bad[0])
                raise self._fail(name, i, f"{float(arr[i])!r} is not a finite number")
        if n < 2:
            need = (
                f"identification needs at least {MIN_DURATION_S} s of data"
                if self.whole
                else "a log needs at least 2 ticks after it (one tick spacing)"
            )
            raise self._fail(
                "time_s",
                None,
                f"the log ends at index {n - 1 + FIRST_INDEX}, {n} tick(s) after the start sample (index 1): {need}",
            )
        steps = np.diff(t)
        bad = np.flatnonzero(~(steps > 0))
        if bad.size:
            i = int(bad[0]) + 1
            raise self._fail(
                "time_s",
                i,
                f"{float(t[i])!r} s is not after {float(t[i - 1])!r} s: time must increase strictly",
            )
        period = float(np.median(steps))
        bad = np.flatnonzero(steps > MAX_GAP_PERIODS * period)
        if bad.size:
            i = int(bad[0]) + 1
            raise self._fail(
                "time_s",
                i,
                f"{float(steps[i - 1]):.6g} s after the previous tick, more than {MAX_GAP_PERIODS} × the median "
                f"period {period:.6g} s: a gap in the ticks (a missed block?)",
            )
        duration = float(t[-1] - t[0])
        if self.whole and duration < MIN_DURATION_S:
            raise self._fail(
                "time_s",
                n - 1,
                f"the log ends {duration:.6g} s after index {FIRST_INDEX}: identification needs at least "
                f"{MIN_DURATION_S} s of data",
            )
        u = self.command_v
        if self.board is not None:
            bad = np.flatnonzero((u < self.board.low) | (u > self.board.high))
            if bad.size:
                i = int(bad[0])
                raise self._fail(
                    "command_v", i, f"{float(u[i])!r} {self.board.unit} is outside {self.board.text()}"
                )
            return period
        bad = np.flatnonzero((u < DAC_MIN_V) | (u > DAC_MAX_V))
        if bad.size:
            i = int(bad[0])
            raise self._fail(
                "command_v", i, f"{float(u[i])!r} V is outside the DAC's {DAC_MIN_V}…{DAC_MAX_V} V"
            )
        # The two channels are the ADC's volts (a reading, or a block mean of readings): a value beyond its
        # ±5 V range (half a step of rounding allowed) is not what the card recorded — a channel converted
        # to other units (metres, degrees, counts) or a different card.
        for name in ("ball_v", "angle_v"):
            arr = getattr(self, name)
            bad = np.flatnonzero((arr < ADC_MIN_V - ADC_STEP_V / 2) | (arr > ADC_MAX_V + ADC_STEP_V / 2))
            if bad.size:
                i = int(bad[0])
                raise self._fail(
                    name,
                    i,
                    f"{float(arr[i])!r} V is outside the ADC's {ADC_MIN_V:g}…{ADC_MAX_V:g} V: not the card's raw "
                    "volts (a channel in other units?)",
                )
        if not self.whole:
            return period
        last = n - 1 + FIRST_INDEX
        span = float(np.ptp(u))
        if span <= MIN_COMMAND_SPAN_V:
            raise self._fail(
                "command_v",
                None,
                f"spans only {span:.6g} V over indices {FIRST_INDEX}…{last} (not more than 2 DAC steps of "
                f"{DAC_STEP_V:.6g} V): no excitation",
            )
        span = float(np.ptp(self.ball_v))
        if span < MIN_BALL_SPAN_V:
            raise self._fail(
                "ball_v",
                None,
                f"spans only {span:.6g} V over indices {FIRST_INDEX}…{last} (fewer than 10 ADC steps of "
                f"{ADC_STEP_V:.6g} V): the ball hardly moved",
            )
        return period


def load_rig_log(path: str | Path) -> RigLog:
    """Read a ``.mat`` (``data_file.mat``) or ``.csv`` log and return its identification ticks, validated.

    The file is only read. Refusals are ``LogError`` naming the file, the field and the first bad index."""
    path = Path(path)
    return rig_log(read_log(path), path)


def check_period(log: RigLog, period_s: float, field_name: str = "daq.period_s") -> None:
    """Refuse a log whose median tick spacing is not ``period_s`` (the parameters' ``daq.period_s``) within
    ``PERIOD_TOLERANCE``: a log recorded at another period, or its ``timem`` in other units (ms), whose
    zero-order hold, block mean and times the model would read wrong. A ``LogError`` naming the file, the field
    and both periods."""
    if abs(log.period_s - period_s) > PERIOD_TOLERANCE * period_s:
        raise LogError(
            f"{log.path}: {_name('time_s')} ticks every {log.period_s * 1e3:.6g} ms but the parameters' "
            f"{field_name} is {period_s * 1e3:.6g} ms: the model's zero-order hold and block mean would "
            f"be wrong; give the log's period (--set {field_name}={log.period_s:.6g})"
        )


def board_range(params: Parameters) -> CommandRange | None:
    """The output range a log of the rig ``params`` describes is held to: its board's (``RigLog.board``), None
    for the thesis's PCI-1712 (its DAC's and ADC's volts)."""
    from twin.parts import is_thesis_rig, rig_parts

    parts = rig_parts(params)
    return None if is_thesis_rig(parts) else parts.io_board.output_range(params)


def load_judged_log(path: str | Path, params: Parameters) -> RunLog:
    """A log to judge (``ballbeam judge``): read as ``read_log`` does and checked tick by tick as every rig log
    is (``RigLog``: the ADC's and DAC's volts, or the board's range on a rig of other parts, strictly
    increasing time without gaps, at least two ticks), its tick spacing the rig's period (``check_period``),
    but not held to identification's minimum duration and excitation (a ball lost after a second is a verdict
    too). Returns the log as read."""
    path = Path(path)
    log = read_log(path)
    rig = rig_log(log, path, whole=False, board=board_range(params))
    check_period(rig, params.period_s, params.period_field)
    return log


def read_log(path: str | Path) -> RunLog:
    """A ``.mat`` (v5 or MATLAB v7.3) or ``.csv`` log as it is in the file, not yet checked as a rig log
    (``ballbeam judge`` reads logs so). Refusals are ``LogError``s naming the file."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".mat":
        return load_mat(path, variables=read_mat73(path) if _is_mat73(path) else None)
    if suffix == ".csv":
        return load_csv(path)
    shown = f"suffix '{path.suffix}'" if path.suffix else "no suffix"
    raise LogError(f"{path}: {shown}: a rig log is a .mat (data_file.mat) or a .csv file")


def _is_mat73(path: Path) -> bool:
    try:
        with path.open("rb") as fh:
            head = fh.read(MAT73_USERBLOCK_BYTES + len(HDF5_SIGNATURE))
    except OSError:
        return False  # load_mat names the problem
    return head.startswith(MAT73_HEADER) and head[MAT73_USERBLOCK_BYTES:] == HDF5_SIGNATURE


def read_mat73(path: str | Path) -> dict[str, np.ndarray]:
    """The variables of a MATLAB v7.3 file as scipy.io.loadmat gives a v5 file's: 2-D arrays, a column
    vector n × 1. HDF5 keeps MATLAB's column-major arrays as their transposes (an n × 1 vector is stored
    1 × n); MATLAB writes an empty array as its dimensions with the attribute MATLAB_empty. Groups (structs,
    cells) and MATLAB's own ``#refs#`` are skipped: a rig log's variables are numeric arrays."""
    import h5py

    path = Path(path)
    out: dict[str, np.ndarray] = {}
    try:
        with h5py.File(path, "r") as fh:
            for name, obj in fh.items():
                if name.startswith("#") or not isinstance(obj, h5py.Dataset):
                    continue
                if int(np.asarray(obj.attrs.get("MATLAB_empty", 0)).ravel()[0]):
                    out[name] = np.zeros((0, 0))
                    continue
                data = np.asarray(obj[()])
                out[name] = data.T if data.ndim >= 2 else data.reshape(1, -1)
    except OSError as exc:
        raise LogError(f"{path}: a MATLAB v7.3 (HDF5) .mat file that cannot be read ({exc})") from None
    return out


def rig_log(
    log: RunLog, path: str | Path = "<memory>", *, whole: bool = True, board: CommandRange | None = None
) -> RigLog:
    """The identification ticks of a log already in memory (e.g. a twin run), validated as a file would be
    (``whole=False``: tick by tick only, see ``RigLog.whole``; ``board``: see ``RigLog.board``)."""
    return RigLog(
        path=Path(path),
        time_s=log.timem[1:],
        ball_v=log.datam1[1:],
        angle_v=log.datam2[1:],
        command_v=log.aout[1:],
        whole=whole,
        board=board,
    )
