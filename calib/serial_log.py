"""Logs an Arduino sketch prints over serial: CSV-like lines (time, reading(s), command) read with a column map.

A sketch prints one line a tick, e.g. ``Serial.print(millis()); Serial.print(','); Serial.print(range_mm);
Serial.print(','); Serial.println(pulse_us);``, among other text ("ready", debug lines). The user says which
column is which and in what unit, as a COLUMN MAP (``parse_column_map``)::

    time=ms, distance=mm, pulse=us              roles by word; columns by the same name in a header line, or
                                                without a header by the entry's place in the map (1st → column 1)
    time@1=ms, ball@dist=mm, command@4=us       a column named (header) or numbered (1-based) after '@'
    time=ms, echo=us, pulse=us, sep=tab, header=no

Roles and their words: time (``time``, ``t``, ``millis``, ``micros``); the ball sensor's reading (``ball``,
``distance``, ``dist``, ``range``, ``echo``, ``reading``); the angle sensor's (``angle``); the board's output
(``command``, ``pulse``, ``servo``, ``output``). Options: ``sep=comma|tab|space|auto`` (default auto: the
first line splitting into several cells by comma, else tab, else spaces), ``header=yes|no|auto``. A preset's
map is named instead of spelled out (``MAPS``: ``vl53l0x-servo`` is ``time=ms, distance=mm, pulse=us``;
``quanser-bb01`` is ``time=ms, ball=V, angle=counts, command=V``: the strip's ADC volts, the SRV02 encoder's
counts, the DAC's volts).

``read_serial_log(path, map, params)`` returns a ``SerialLog`` whose ``log`` is what calib's logs hold (a
``twin.log.RunLog``: ``timem`` s, ``datam1`` the ball channel, ``datam2`` the angle channel, ``aout`` the
command), each channel IN THE BOARD'S UNIT as ``twin.interface`` says: the rig ``params`` describes fixes
them (``board_units``: a VL53L0X's mm, an HC-SR04's echo µs, ``analogRead`` counts on an Arduino, the
PCI-1712's volts; the servo pulse's µs); a logged unit of the same kind is converted (cm → mm, ms → µs, the
Servo library's ``write(deg)`` → µs) and one of another kind refused. Without the angle sensor (none in the
rig, none in the map) the angle channel reads 0. As in a thesis log, row 1 is the start sample that
identification drops (``calib.logs.rig_log``): the first data line plays it.

Hostile input never kills or hangs. Refused (``SerialLogError``, naming the file, the line and the column):
a file beyond ``MAX_BYTES`` or with more than ``MAX_TICKS`` data lines, a binary file (a NUL byte), a map
naming a column the header lacks, an unknown unit or role, a unit the rig's board does not read, time not
increasing (a 2³² wrap of ``millis()``/``micros()`` is unwrapped and counted), a value outside the board's
range (a wrong column or unit), no data line, and more than ``MAX_BAD_SHARE`` of the data lines malformed.
Skipped and counted (``SerialLog.text_lines``, ``malformed``): lines of other text, lines that are not UTF-8
(a serial port's noise at connection), lines longer than ``MAX_LINE_BYTES``, and data lines with a value that is
not a finite number (Arduino's ``nan``, ``inf``, ``ovf``) or the wrong number of cells (a truncated line). The
file is read line by line, each line bounded; a BOM and ``\\n``, ``\\r\\n`` or ``\\r`` line ends are accepted.
"""

from __future__ import annotations

import math
import stat
from array import array
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Literal

import numpy as np

from twin.log import RunLog, save_csv
from twin.parameters import Parameters

__all__ = [
    "MAPS",
    "MAX_BAD_SHARE",
    "MAX_BYTES",
    "MAX_LINE_BYTES",
    "MAX_TICKS",
    "ColumnMap",
    "Entry",
    "SerialLog",
    "SerialLogError",
    "board_units",
    "column_map",
    "parse_column_map",
    "read_serial_log",
    "save_serial_log",
]

Role = Literal["time", "ball", "angle", "command"]
ROLES: tuple[Role, ...] = ("time", "ball", "angle", "command")

# 64 MiB: 97 min of a 115200 Bd line printing without pause (11 520 bytes/s), 12 h of a 50 Hz sketch's
# 30-byte lines; beyond that a log is no longer one session of a bench rig.
MAX_BYTES = 64 * 1024 * 1024
# 2 000 000 ticks: 11 h at 50 Hz; four float64 channels take 64 MB.
MAX_TICKS = 2_000_000
# A sketch's line is tens of bytes; a line of 4 KiB is not one of its ticks (and reading one stays bounded).
MAX_LINE_BYTES = 4096
# Up to 5 % of the data lines may be malformed (skipped); more is a wrong map or a broken log.
MAX_BAD_SHARE = 0.05
# ... counted from 10 lines on, so that one noisy line in a short log is skipped, not refused.
MIN_BAD_REFUSED = 10
# The messages kept for skipped lines (the count is kept whole).
MAX_MESSAGES = 20
# millis() and micros() are unsigned 32-bit counters: they wrap to 0 after 2³² ms (49.7 days) or µs (71.6 min).
WRAP = 2**32

MAPS: dict[str, str] = {
    "vl53l0x-servo": "time=ms, distance=mm, pulse=us",
    "open-ball-and-beam": "time=ms, distance=mm, pulse=us",
    "vl53l0x-servo-pot": "time=ms, distance=mm, angle=counts, pulse=us",
    "hcsr04-servo": "time=ms, echo=us, pulse=us",
    "gp2y0a21-servo": "time=ms, distance=counts, pulse=us",
    "quanser-bb01": "time=ms, ball=V, angle=counts, command=V",
    "thesis": "time@timem=s, ball@datam1=V, angle@datam2=V, command@aout=V",
}
"""Preset column maps by name: a sketch printing ``millis()``, the sensor's reading and the servo pulse (in
that order, or under those header names); ``thesis`` reads a CSV with the thesis software's names."""

_WORDS: dict[str, Role] = {
    "time": "time",
    "t": "time",
    "millis": "time",
    "micros": "time",
    "ball": "ball",
    "distance": "ball",
    "dist": "ball",
    "range": "ball",
    "echo": "ball",
    "reading": "ball",
    "angle": "angle",
    "command": "command",
    "pulse": "command",
    "servo": "command",
    "output": "command",
}

# A unit: (its kind, its size in the kind's base: s, m, count, V, servo degree).
_UNITS: dict[str, tuple[str, float]] = {
    "s": ("time", 1.0),
    "ms": ("time", 1e-3),
    "us": ("time", 1e-6),
    "µs": ("time", 1e-6),
    "m": ("length", 1.0),
    "cm": ("length", 1e-2),
    "mm": ("length", 1e-3),
    "counts": ("counts", 1.0),
    "count": ("counts", 1.0),
    "v": ("volts", 1.0),
    "mv": ("volts", 1e-3),
    "deg": ("servo_deg", 1.0),
}
_KINDS: dict[Role, tuple[str, ...]] = {
    "time": ("time",),
    "ball": ("length", "time", "counts", "volts"),
    "angle": ("counts", "volts"),
    "command": ("time", "volts", "servo_deg"),
}
# The unit each kind is given in when the rig does not say (the board's units for a reading: mm, µs, counts, V).
_CANONICAL: dict[str, str] = {
    "length": "mm",
    "time": "us",
    "counts": "counts",
    "volts": "V",
    "servo_deg": "us",
}
# Each reading role's RunLog field (the thesis software's names).
_CHANNELS: tuple[tuple[Role, str], ...] = (("ball", "datam1"), ("angle", "datam2"), ("command", "aout"))
_SEPARATORS = {"comma": ",", "tab": "\t", "space": " ", "auto": ""}


class SerialLogError(ValueError):
    """A serial log or column map that cannot be used; the message names the file, the line and the column."""


@dataclass(frozen=True)
class Entry:
    """One column of the map: its role, the column (a header name, or a 1-based index) and the logged unit."""

    role: Role
    column: str | int
    unit: str
    explicit: bool  # the column was named after '@' (a name then needs a header)


@dataclass(frozen=True)
class ColumnMap:
    """Which column is which and in what unit, the separator (``""``: auto) and whether a header is there
    (None: auto)."""

    entries: tuple[Entry, ...]
    separator: str = ""
    header: bool | None = None

    def entry(self, role: Role) -> Entry | None:
        return next((e for e in self.entries if e.role == role), None)

    @property
    def by_name(self) -> bool:
        """Whether some column is named (a header line must name it) rather than numbered."""
        return any(isinstance(e.column, str) for e in self.entries)


def parse_column_map(spec: str) -> ColumnMap:
    """A column map from its text (module docstring) or a preset's name (``MAPS``). Refused with the entry."""
    text = MAPS.get(spec.strip(), spec)
    entries: list[Entry] = []
    separator, header = "", None
    parts = [p.strip() for p in text.split(",")]
    for part in (p for p in parts if p):
        key, eq, value = part.partition("=")
        key, value = key.strip(), value.strip()
        if not eq or not key or not value:
            raise SerialLogError(
                f"column map {spec!r}: entry {part!r} is not ROLE=UNIT or ROLE@COLUMN=UNIT (known maps: "
                f"{', '.join(MAPS)})"
            )
        if key == "sep":
            if value not in _SEPARATORS:
                raise SerialLogError(f"column map {spec!r}: sep={value!r}: one of {', '.join(_SEPARATORS)}")
            separator = _SEPARATORS[value]
            continue
        if key == "header":
            if value not in ("yes", "no", "auto"):
                raise SerialLogError(f"column map {spec!r}: header={value!r}: one of yes, no, auto")
            header = {"yes": True, "no": False, "auto": None}[value]
            continue
        entries.append(_entry(spec, key, value, len(entries) + 1))
    roles = [e.role for e in entries]
    for role in ("time", "ball", "command"):
        if role not in roles:
            raise SerialLogError(
                f"column map {spec!r}: no {role} column (the map needs time, the ball's reading and the command; "
                "the angle is optional)"
            )
    for role in ROLES:
        if roles.count(role) > 1:
            raise SerialLogError(f"column map {spec!r}: two columns for the {role}")
    columns = [e.column for e in entries]
    if len(set(columns)) != len(columns):
        raise SerialLogError(f"column map {spec!r}: one column mapped twice")
    return ColumnMap(tuple(entries), separator, header)


def _entry(spec: str, key: str, unit_text: str, place: int) -> Entry:
    word, at, column = key.partition("@")
    word = word.strip().lower()
    role = _WORDS.get(word)
    if role is None:
        raise SerialLogError(
            f"column map {spec!r}: {word!r} is not a role (words: {', '.join(sorted(_WORDS))})"
        )
    unit = unit_text.strip().lower().replace("µ", "u")
    if unit not in _UNITS:
        raise SerialLogError(
            f"column map {spec!r}: {key}={unit_text!r}: unit not known (known: {', '.join(sorted(_UNITS))})"
        )
    kind = _UNITS[unit][0]
    if kind not in _KINDS[role]:
        raise SerialLogError(
            f"column map {spec!r}: {key}={unit_text!r}: the {role} is not in {kind} (it may be in: "
            f"{', '.join(u for u, (k, _) in _UNITS.items() if k in _KINDS[role] and u != 'µs')})"
        )
    col: str | int
    if at:
        name = column.strip()
        if not name:
            raise SerialLogError(f"column map {spec!r}: {key!r}: no column after '@'")
        if name.isdigit():
            if int(name) < 1:
                raise SerialLogError(f"column map {spec!r}: {key!r}: columns are numbered from 1")
            col = int(name)
        else:
            col = name.lower()
        return Entry(role, col, unit, True)
    return Entry(role, _implicit(word, place), unit, False)


def _implicit(word: str, place: int) -> str:
    """An entry without '@' is looked up by its word in a header; ``place`` is used when there is none."""
    return f"{word}#{place}"


def column_map(spec: str | ColumnMap) -> ColumnMap:
    """A map as given, or parsed from its text or a preset's name."""
    return spec if isinstance(spec, ColumnMap) else parse_column_map(spec)


# --- the rig's units ----------------------------------------------------------------------------------------

_ADC_UNIT = {"pci1712": "V", "arduino_uno": "counts", "arduino_nano": "counts"}


@dataclass(frozen=True)
class BoardUnits:
    """The board's unit of each channel (``None``: no angle sensor, the channel reads 0) and its range."""

    ball: str
    angle: str | None
    command: str
    ball_range: tuple[float, float] = (-math.inf, math.inf)
    angle_range: tuple[float, float] = (-math.inf, math.inf)
    command_range: tuple[float, float] = (-math.inf, math.inf)
    servo_us: tuple[float, float] = (544.0, 2400.0)
    rig: str = ""


def board_units(params: Parameters) -> BoardUnits:
    """What the board of the rig ``params`` describes reads and writes (``twin.interface``): the ball sensor's
    reading (VL53L0X mm over I²C, HC-SR04 echo µs by ``pulseIn``, an analog sensor's ADC reading), the angle
    sensor's (none: absent), the output's unit and range (``IoBoardPart.output_range``)."""
    from twin.parts.contract import IoBoardPart, part_named

    names = params.parts
    board = part_named("io_board", names.io_board)
    assert isinstance(board, IoBoardPart)  # the registry holds io_boards as IoBoardParts
    out = board.output_range(params)
    command = "us" if out.unit in ("µs", "us") else "V"
    adc = _ADC_UNIT.get(names.io_board, "V" if command == "V" else "counts")
    adc_range = (0.0, 1023.0) if adc == "counts" else (-math.inf, math.inf)
    ball = {"vl53l0x": "mm", "hcsr04": "us"}.get(names.ball_sensor, adc)
    angle: str | None = adc
    if names.angle_sensor == "none":
        angle = None
    elif names.angle_sensor == "as5600":
        from twin.parts.as5600 import AS5600, COUNTS

        if not params.of(AS5600).analog_output:
            angle = "counts"
            adc_range = adc_range if adc == "counts" else (0.0, float(COUNTS - 1))
    angle_range = (0.0, 4095.0) if angle == "counts" and adc != "counts" else adc_range
    if names.angle_sensor == "shaft_encoder":  # the card's signed counter, not its ADC
        angle, angle_range = "counts", (-math.inf, math.inf)
    servo = (out.low, out.high) if command == "us" else (544.0, 2400.0)
    rig = f"{names.ball_sensor} on {names.io_board}"
    return BoardUnits(
        ball=ball,
        angle=angle,
        command=command,
        ball_range=adc_range if ball == adc else (0.0, math.inf),
        angle_range=angle_range,
        command_range=(out.low, out.high),
        servo_us=servo,
        rig=rig,
    )


# --- reading ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SerialLog:
    """A serial log read through a column map: ``log`` (``RunLog``: timem s, datam1 ball, datam2 angle, aout
    command, in ``units``), ``lines`` the file line of each tick, the header's line (None: none), the lines of
    other text skipped, the malformed data lines skipped (a count and the first messages), the clock wraps
    unwrapped."""

    path: Path
    log: RunLog
    lines: np.ndarray
    units: dict[str, str]
    header_line: int | None
    text_lines: int
    malformed_count: int
    malformed: tuple[str, ...]
    wraps: int
    separator: str
    notes: tuple[str, ...] = field(default=())

    @property
    def ticks(self) -> int:
        return int(self.log.timem.size)


def _split(line: str, sep: str) -> list[str]:
    if sep == " ":
        return line.split()
    return [c.strip() for c in line.split(sep)]


def _guess_separator(line: str) -> str:
    for sep in (",", "\t"):
        if sep in line and len(_split(line, sep)) >= 2:
            return sep
    return " "


def _number(cell: str) -> float | None:
    try:
        value = float(cell)
    except ValueError:
        return None
    return value if math.isfinite(value) else math.nan


def _lines(fh: BinaryIO, path: Path) -> Iterator[tuple[int, str | None, bool]]:
    """(line number, text or None for undecodable, too long flag) for each line, bounded in length; a NUL
    byte is refused as binary."""
    number = 0
    first = True
    while True:
        raw = fh.readline(MAX_LINE_BYTES + 1)
        if not raw:
            return
        too_long = len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n")
        if too_long:  # drop the rest of the line, a bounded chunk at a time
            while True:
                rest = fh.readline(MAX_LINE_BYTES)
                if not rest or rest.endswith(b"\n"):
                    break
                if b"\0" in rest:
                    raise SerialLogError(
                        f"{path}, line {number + 1}: a NUL byte: a binary file, not a serial log"
                    )
        if first and raw.startswith(b"\xef\xbb\xbf"):
            raw = raw[3:]
        first = False
        if b"\0" in raw:
            raise SerialLogError(f"{path}, line {number + 1}: a NUL byte: a binary file, not a serial log")
        body = raw.rstrip(b"\n").replace(b"\r\n", b"\n")
        pieces = body.split(b"\r")
        if len(pieces) > 1 and pieces[-1] == b"":
            pieces.pop()  # a line ended by \r\n
        for piece in pieces:
            number += 1
            if too_long:
                yield number, None, True
                continue
            try:
                yield number, piece.decode("utf-8"), False
            except UnicodeDecodeError:
                yield number, None, False


def _cell_name(entry: Entry, index: int, header: list[str] | None) -> str:
    name = header[index] if header is not None else None
    return f"column {index + 1}" + (f" '{name}'" if name else "") + f" ({entry.role})"


def _open(path: Path) -> BinaryIO:
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise SerialLogError(f"{path}: no such file") from None
    except OSError as exc:
        raise SerialLogError(f"{path}: cannot read the log ({exc.strerror or exc})") from None
    if stat.S_ISDIR(mode):
        raise SerialLogError(f"{path}: a directory, not a log file")
    if not stat.S_ISREG(mode):
        raise SerialLogError(f"{path}: not a regular file (a device, pipe or socket)")
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise SerialLogError(
            f"{path}: {size} bytes, beyond the {MAX_BYTES} bytes (64 MiB) a serial log may have: split it"
        )
    try:
        return path.open("rb")
    except OSError as exc:
        raise SerialLogError(f"{path}: cannot read the log ({exc.strerror or exc})") from None


class _Reader:
    """The state of one pass over a file (``read_serial_log``)."""

    def __init__(self, path: Path, cmap: ColumnMap) -> None:
        self.path = path
        self.cmap = cmap
        self.sep = cmap.separator
        self.header: list[str] | None = None
        self.header_line: int | None = None
        self.index: dict[Role, int] = {}
        self.width: int | None = None
        self.values = {role: array("d") for role in ROLES}
        self.lines = array("q")
        self.text = 0
        self.bad = 0
        self.messages: list[str] = []
        self.wraps = 0
        self.offset = 0.0
        self.last: tuple[float, int] | None = None

    def skip(self, message: str) -> None:
        self.bad += 1
        if len(self.messages) < MAX_MESSAGES:
            self.messages.append(message)

    def try_header(self, number: int, cells: list[str]) -> bool:
        """A line naming the map's columns is the header; one naming some of them but not all is refused."""
        names = [c.lower() for c in cells]
        wanted = {e.role: _wanted_name(e) for e in self.cmap.entries if isinstance(e.column, str)}
        found = {role: name for role, name in wanted.items() if name in names}
        if not found or any(_number(c) is not None for c in cells):
            return False
        if len(found) < len(wanted):
            missing = next(name for role, name in wanted.items() if role not in found)
            raise SerialLogError(
                f"{self.path}, line {number} (the header): no column '{missing}' (its columns: "
                f"{', '.join(cells)})"
            )
        for entry in self.cmap.entries:
            self.index[entry.role] = (
                names.index(_wanted_name(entry)) if isinstance(entry.column, str) else entry.column - 1
            )
        self.header, self.header_line, self.width = cells, number, len(cells)
        _check_width(self.path, number, self.cmap, self.index, len(cells), cells)
        return True

    def positional(self, number: int, cells: list[str]) -> None:
        """No header before the first data line: columns by number, or by the entry's place in the map."""
        for entry in self.cmap.entries:
            if isinstance(entry.column, int):
                self.index[entry.role] = entry.column - 1
            elif entry.explicit or self.cmap.header is True:
                raise SerialLogError(
                    f"{self.path}, line {number}: data before any header line naming column "
                    f"'{_wanted_name(entry)}' ({entry.role}): the map names columns by name; give their numbers "
                    f"(e.g. {entry.role}@2={entry.unit}) or a header line"
                )
            else:
                self.index[entry.role] = int(str(entry.column).rpartition("#")[2]) - 1
        self.width = len(cells)
        _check_width(self.path, number, self.cmap, self.index, len(cells), None)

    def first(self, number: int, text: str) -> None:
        """Before the header or the first data line: the separator is guessed line by line (a sketch's "ready,
        set" or "starting now" does not fix it) and fixed by the header, or by the first line whose cells are
        all numbers."""
        sep = self.sep or _guess_separator(text)
        cells = _split(text, sep)
        if len(cells) < 2:
            self.text += 1
            return
        if self.cmap.header is not False and self.cmap.by_name and self.try_header(number, cells):
            self.sep = sep
            return
        if any(_number(c) is None for c in cells):
            self.text += 1
            return
        self.sep = sep
        self.positional(number, cells)
        self.line(number, text)

    def line(self, number: int, text: str) -> None:
        if not text.strip():
            return
        if self.width is None:
            self.first(number, text)
            return
        cells = _split(text, self.sep)
        if len(cells) != self.width:
            if cells and _number(cells[0]) is not None:
                self.skip(
                    f"{self.path}, line {number}: {len(cells)} cells, the log's lines have {self.width}"
                )
            else:
                self.text += 1
            return
        row: dict[Role, float] = {}
        for entry in self.cmap.entries:
            i = self.index[entry.role]
            try:
                value = float(cells[i])
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                if _number(cells[0]) is None:  # a line of text that happens to have as many cells
                    self.text += 1
                    return
                self.skip(
                    f"{self.path}, line {number}, {_cell_name(entry, i, self.header)}: {cells[i]!r} is not a "
                    "finite number"
                )
                return
            row[entry.role] = value
        self.time(number, row)
        for role, value in row.items():
            self.values[role].append(value)
        self.lines.append(number)
        if len(self.lines) > MAX_TICKS:
            raise SerialLogError(
                f"{self.path}, line {number}: more than {MAX_TICKS} data lines: split the log"
            )

    def time(self, number: int, row: dict[Role, float]) -> None:
        t = row["time"] + self.offset
        if self.last is not None and t <= self.last[0]:
            entry = self.cmap.entry("time")
            assert entry is not None  # parse_column_map requires it
            prev, prev_line = self.last
            wrapped = entry.unit in ("ms", "us") and prev - t > WRAP / 2 and t + WRAP > prev
            if not wrapped:
                column = _cell_name(entry, self.index["time"], self.header)
                raise SerialLogError(
                    f"{self.path}, line {number}, {column}: {row['time']!r} {entry.unit} is not after "
                    f"{prev - self.offset!r} {entry.unit} at line {prev_line}: time must increase (the board "
                    "reset? split the log there)"
                )
            self.offset += WRAP
            self.wraps += 1
            t += WRAP
        row["time"] = t
        self.last = (t, number)


def _wanted_name(entry: Entry) -> str:
    return str(entry.column).rpartition("#")[0] if not entry.explicit else str(entry.column)


def _check_width(
    path: Path, number: int, cmap: ColumnMap, index: dict[Role, int], width: int, header: list[str] | None
) -> None:
    for entry in cmap.entries:
        if index[entry.role] >= width:
            what = "the header" if header is not None else "the first data line"
            raise SerialLogError(
                f"{path}, line {number}: no column {index[entry.role] + 1} for the {entry.role} ({what} has "
                f"{width} columns)"
            )


def read_serial_log(path: str | Path, spec: str | ColumnMap, params: Parameters | None = None) -> SerialLog:
    """Read a sketch's serial log through the column map ``spec`` (text, a preset's name or a ``ColumnMap``),
    its channels in the board's units of the rig ``params`` (None: each in its kind's board unit, mm, µs,
    counts or V). Refusals are ``SerialLogError`` naming the file, the line and the column (module docstring)."""
    path = Path(path)
    cmap = column_map(spec)
    reader = _Reader(path, cmap)
    with _open(path) as fh:
        for number, text, too_long in _lines(fh, path):
            if too_long:
                reader.skip(f"{path}, line {number}: longer than {MAX_LINE_BYTES} bytes")
            elif text is None:
                reader.text += 1  # not UTF-8: a serial port's noise (the board's reset, a wrong baud rate)
            else:
                reader.line(number, text)
    n = len(reader.lines)
    if n == 0:
        raise SerialLogError(
            f"{path}: no data line matching the map ({reader.text} lines of other text"
            + (f", {reader.bad} malformed: {reader.messages[0]}" if reader.messages else "")
            + ")"
        )
    if reader.bad >= MIN_BAD_REFUSED and reader.bad > MAX_BAD_SHARE * (n + reader.bad):
        raise SerialLogError(
            f"{path}: {reader.bad} malformed data lines against {n} good ones (more than "
            f"{MAX_BAD_SHARE:.0%}): a wrong map or a broken log; the first: {reader.messages[0]}"
        )
    return _converted(reader, params)


def _converted(reader: _Reader, params: Parameters | None) -> SerialLog:
    path, cmap = reader.path, reader.cmap
    lines = np.frombuffer(reader.lines, dtype=np.int64).copy()
    units = board_units(params) if params is not None else None
    notes: list[str] = []
    channels: dict[Role, np.ndarray] = {}
    unit_of: dict[str, str] = {"timem": "s"}
    for role, name in _CHANNELS:
        entry = cmap.entry(role)
        target = getattr(units, role) if units is not None else None
        if entry is not None and units is not None and target is None:
            assert params is not None
            raise SerialLogError(
                f"{path}: the map has an angle column but the rig has no angle sensor (parts.angle_sensor = "
                f"'{params.parts.angle_sensor}'): its board reads 0 there; leave the angle out of the map"
            )
        if entry is None:
            if target is not None:
                assert params is not None
                raise SerialLogError(
                    f"{path}: the rig's angle sensor '{params.parts.angle_sensor}' reads the beam's angle but the "
                    "column map has none: map it (e.g. angle@3=counts) or describe the rig with "
                    "parts.angle_sensor = 'none'"
                )
            channels[role] = np.zeros(lines.size)  # no angle sensor: the channel reads 0
            unit_of[name] = "none (0)"
            continue
        raw = np.frombuffer(reader.values[role], dtype=np.float64)
        channels[role], unit_of[name] = _to_board(path, reader, entry, raw, target, units)
        if units is not None:
            low, high = getattr(units, f"{role}_range")
            bad = np.flatnonzero((channels[role] < low) | (channels[role] > high))
            if bad.size:
                i = int(bad[0])
                column = _cell_name(entry, reader.index[role], reader.header)
                raise SerialLogError(
                    f"{path}, line {int(lines[i])}, {column}: {float(raw[i])!r} {entry.unit} is outside the board's "
                    f"{low:g} … {high:g} {unit_of[name]} ({units.rig}): a wrong column or unit?"
                )
    entry = cmap.entry("time")
    assert entry is not None
    t = np.frombuffer(reader.values["time"], dtype=np.float64) * _UNITS[entry.unit][1]
    if reader.wraps:
        notes.append(f"the clock wrapped {reader.wraps} time(s) (2³² {entry.unit}): unwrapped")
    nan = np.full(lines.size, np.nan)
    log = RunLog(
        timem=t,
        datam1=channels["ball"],
        datam2=channels["angle"],
        aout=channels["command"],
        x1=nan,
        x2=nan,
        x3=nan,
        x4=nan,
        u=nan,
        uhesap=nan,
    )
    return SerialLog(
        path=path,
        log=log,
        lines=lines,
        units=unit_of,
        header_line=reader.header_line,
        text_lines=reader.text,
        malformed_count=reader.bad,
        malformed=tuple(reader.messages),
        wraps=reader.wraps,
        separator=reader.sep,
        notes=tuple(notes),
    )


def _to_board(
    path: Path, reader: _Reader, entry: Entry, raw: np.ndarray, target: str | None, units: BoardUnits | None
) -> tuple[np.ndarray, str]:
    """A logged channel in the board's unit ``target`` (None: its kind's board unit)."""
    kind, size = _UNITS[entry.unit]
    want = target if target is not None else _CANONICAL[kind]
    want_kind, want_size = _UNITS[want.lower()]
    if kind == "servo_deg" and want_kind == "time":
        low, high = units.servo_us if units is not None else (544.0, 2400.0)
        return _servo_write_us(raw, low, high), want
    if kind != want_kind:
        column = _cell_name(entry, reader.index[entry.role], reader.header)
        rig = units.rig if units is not None else "the rig"
        raise SerialLogError(
            f"{path}, line {reader.header_line or int(reader.lines[0])}, {column}: logged in {entry.unit} but the "
            f"board reads the {entry.role} in {want} ({rig}): log what the board reads"
        )
    return raw * (size / want_size), want


def _servo_write_us(value: np.ndarray, min_us: float, max_us: float) -> np.ndarray:
    """What the AVR Servo library's ``write(value)`` sends (src/avr/Servo.cpp): a value below 544 is degrees,
    clipped to 0 … 180 and mapped with Arduino's integer ``map(value, 0, 180, min, max)`` (truncating); a value
    from 544 on is already µs (``writeMicroseconds``)."""
    deg = np.clip(np.trunc(value), 0.0, 180.0)
    mapped = min_us + np.trunc(deg * (max_us - min_us) / 180.0)
    return np.where(value < 544.0, mapped, value)


def save_serial_log(log: SerialLog, path: str | Path, *, overwrite: bool = False) -> None:
    """Write the log's ``RunLog`` as the calibration's CSV (``twin.log.save_csv``: atomically; an existing file
    only with ``overwrite``)."""
    save_csv(log.log, path, overwrite=overwrite)
