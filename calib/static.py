"""Static calibration of the rig's two sensors from measured tables (thesis §6.2–6.3).

- Ball position (§6.3): (position_m, volts_v) pairs like Table 6.3. The thesis's software reads the ball
  with the straight line of eq 6.3.1, x = 0.0693·V + 0.0018. Computed here: that line is least squares
  over the 21 interior points of Table 6.3 (the two end points at ±0.323 m left out). x on V gives
  0.069252 m/V, 0.0017999 m; V on x inverted gives 0.069262 m/V, 0.0018001 m: both round to the printed
  0.0693 / 0.0018, so the printed digits cannot tell the two regressions apart. With the end points
  (all 23) both give 0.0694 / 0.0017: not the printed line. The twin's sensor uses a curve (volts at a
  position); three are compared by leave-one-out: the table interpolated linearly, smoothing splines,
  and the straight line.
- Angle chain's DAC (§6.2): (di, volts_v) pairs like eq 6.2.4. Eq 6.2.6 (0.009818·DI − 5.042) is the
  line through the DI = 0 and DI = 1023 readings; least squares over the three readings rounds to the
  same printed digits.

This module computes (``load_table``, ``calibrate``, ``calibrate_ball``, ``calibrate_dac``, the results'
``to_json``); ``calib.static_render`` renders (``render_lines``, ``render_toml``). Residuals are always "predicted −
measured": what the conversion or curve gives minus what the table says.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt
from scipy.interpolate import UnivariateSpline, make_smoothing_spline

from twin.parameters import AngleSensor, Daq, Parameters, SoftwareCalibration

__all__ = [
    "TABLES_DIR",
    "BALL_COLUMNS",
    "DAC_COLUMNS",
    "TableError",
    "Table",
    "load_table",
    "Residuals",
    "LineFit",
    "fit_line",
    "Curve",
    "BallCalibration",
    "DacCalibration",
    "calibrate",
    "calibrate_ball",
    "calibrate_dac",
]

Array = npt.NDArray[np.float64]
TableKind = Literal["ball", "dac"]
Regression = Literal["x_on_v", "v_on_x"]
PointSet = Literal["all", "interior"]

TABLES_DIR = Path(__file__).resolve().parent / "tables"
"""Example tables shipped with the package: ``table_6_3.csv`` (Table 6.3) and ``eq_6_2_4.csv`` (eq 6.2.4)."""

BALL_COLUMNS = ("position_m", "volts_v")
DAC_COLUMNS = ("di", "volts_v")
MIN_ROWS: dict[TableKind, int] = {"ball": 3, "dac": 2}
"""A ball curve needs a point between its ends to be a curve; a DAC line needs two readings."""

SPLINE_MIN_POINTS = 5
"""scipy's make_smoothing_spline needs 5 points; the same floor for both spline rules."""
SPLINE_GRID_STEP_M = 0.005
"""A spline reaches the twin as a table: its values at the measured positions and every 5 mm between
(131 points for Table 6.3). The twin interpolates linearly; at 5 mm the chord error on Table 6.3 is 1.7 mV
for the ADC-noise spline (under the ADC's 2.4 mV step) and under 1 µV for the GCV spline."""


class TableError(ValueError):
    """A calibration table that cannot be used; the message names the file, the column and the line."""


# --- reading tables -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Table:
    """A measured calibration table as read from a file: ``inputs`` are positions (m) for the ball
    sensor, counter values DI for the angle chain's DAC; ``lines`` are the rows' 1-based file lines."""

    source: str
    kind: TableKind
    inputs: tuple[float, ...]
    volts_v: tuple[float, ...]
    lines: tuple[int, ...]

    @property
    def columns(self) -> tuple[str, str]:
        return BALL_COLUMNS if self.kind == "ball" else DAC_COLUMNS


def load_table(path: str | Path) -> Table:
    """Read a two-column CSV whose header names the columns: ``position_m,volts_v`` (ball sensor, like
    Table 6.3) or ``di,volts_v`` (angle DAC, like eq 6.2.4). Blank lines are skipped; a UTF-8 BOM is
    allowed. Anything else raises ``TableError`` naming the file, the column and the first bad line.
    The file is only read."""
    path = Path(path)
    where = str(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise TableError(f"{where}: cannot read the calibration table ({exc.strerror or exc})") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        body = bytes(exc.object)  # after the BOM, if any: exc.start counts from there
        bad_line = body[: exc.start].count(b"\n") + 1
        raise TableError(f"{where}, line {bad_line}: not UTF-8 text (byte {body[exc.start]:#04x})") from None

    # Universal newlines only (\n, \r\n, \r), so line numbers are the ones an editor shows.
    lines_of_text = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    rows = [(n, line) for n, line in enumerate(lines_of_text, start=1) if line.strip()]
    expected = f"'{','.join(BALL_COLUMNS)}' (ball sensor, Table 6.3) or '{','.join(DAC_COLUMNS)}' (angle DAC, eq 6.2.4)"
    if not rows:
        raise TableError(f"{where}: empty; expected a header line {expected}")
    header_line, header_text = rows[0]
    header = tuple(cell.strip().lower() for cell in _cells(header_text))
    kind: TableKind
    if header == BALL_COLUMNS:
        kind = "ball"
    elif header == DAC_COLUMNS:
        kind = "dac"
    else:
        raise TableError(
            f"{where}, line {header_line}: unknown header {header_text.strip()!r}; expected {expected}"
        )
    columns = BALL_COLUMNS if kind == "ball" else DAC_COLUMNS

    inputs: list[float] = []
    volts: list[float] = []
    lines: list[int] = []
    for n, line in rows[1:]:
        cells = _cells(line)
        if len(cells) != 2:
            hint = " (a decimal comma? write 0.03, not 0,03)" if len(cells) > 2 else ""
            raise TableError(
                f"{where}, line {n}: {len(cells)} cells where the header names 2 ({','.join(columns)}){hint}"
            )
        values = [_number(where, n, name, cell) for name, cell in zip(columns, cells, strict=True)]
        if kind == "ball" and inputs and not values[0] > inputs[-1]:
            raise TableError(
                f"{where}, line {n}, column position_m: {values[0]!r} m does not exceed line {lines[-1]}'s "
                f"{inputs[-1]!r} m: positions must increase strictly"
            )
        if kind == "dac":
            _check_di(where, n, values[0], inputs, lines)
        inputs.append(values[0])
        volts.append(values[1])
        lines.append(n)

    if len(inputs) < MIN_ROWS[kind]:
        what = "a ball-sensor curve" if kind == "ball" else "a DAC line"
        last = lines[-1] if lines else header_line
        raise TableError(
            f"{where}, line {last}, column {columns[0]}: {len(inputs)} data rows; {what} needs at least "
            f"{MIN_ROWS[kind]}"
        )
    return Table(where, kind, tuple(inputs), tuple(volts), tuple(lines))


def _cells(line: str) -> list[str]:
    return next(csv.reader([line]))


def _number(where: str, line: int, column: str, cell: str) -> float:
    try:
        value = float(cell.strip())
    except ValueError:
        raise TableError(f"{where}, line {line}, column {column}: {cell.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise TableError(f"{where}, line {line}, column {column}: {cell.strip()!r} is not a finite number")
    return value


def _check_di(where: str, line: int, di: float, seen: list[float], lines: list[int]) -> None:
    """DI is the 10-bit counter's value (§6.2): a whole number 0…1023, each read once."""
    top = 2 ** int(AngleSensor().counter_bits) - 1
    if di != math.floor(di) or not 0 <= di <= top:
        raise TableError(
            f"{where}, line {line}, column di: {di!r} is not a counter value (a whole number 0…{top})"
        )
    if di in seen:
        raise TableError(
            f"{where}, line {line}, column di: DI {int(di)} repeats line {lines[seen.index(di)]}"
        )


# --- shared result pieces -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Residuals:
    """Predicted − measured at each point, in the unit the owner's name says."""

    values: tuple[float, ...]

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(np.square(self.values))))

    @property
    def max_abs(self) -> float:
        return float(np.max(np.abs(self.values)))

    def to_json(self, digits: int) -> dict[str, object]:
        return {
            "values": [round(v, digits) for v in self.values],
            "rms": round(self.rms, digits),
            "max_abs": round(self.max_abs, digits),
        }


def _same_digits(fitted: float, printed: float) -> bool:
    """True if ``fitted`` rounds to ``printed`` at the printed number's decimals (0.0693 → 4)."""
    exponent = Decimal(repr(printed)).as_tuple().exponent
    decimals = max(0, -exponent) if isinstance(exponent, int) else 0
    return f"{fitted:.{decimals}f}" == f"{printed:.{decimals}f}"


# --- ball sensor ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LineFit:
    """A straight line x = gain·V + offset (the software's form, eq 6.3.1) and how it was fitted."""

    regression: Regression
    points: PointSet
    n_points: int
    gain_m_per_v: float
    offset_m: float

    @property
    def label(self) -> str:
        how = "x on V" if self.regression == "x_on_v" else "V on x, inverted"
        which = "all" if self.points == "all" else "interior"
        return f"least squares {how}, {which} {self.n_points} points"

    def position_m(self, volts_v: Array) -> Array:
        return self.gain_m_per_v * volts_v + self.offset_m

    def volts_v(self, position_m: Array) -> Array:
        return (position_m - self.offset_m) / self.gain_m_per_v


def fit_line(
    position_m: Sequence[float] | Array,
    volts_v: Sequence[float] | Array,
    regression: Regression,
    points: PointSet,
) -> LineFit:
    """Least squares straight line through a ball table. ``interior`` leaves out the first and last
    points (the track's ends in Table 6.3); ``v_on_x`` fits V = a·x + b and returns its inverse."""
    x = np.asarray(position_m, dtype=float)
    v = np.asarray(volts_v, dtype=float)
    if points == "interior":
        x, v = x[1:-1], v[1:-1]
    if x.size < 2:
        raise ValueError(f"a {points} line fit needs 2 points, the table gives {x.size}")
    if regression == "x_on_v":
        gain, offset = np.polyfit(v, x, 1)
    else:
        slope, intercept = np.polyfit(x, v, 1)
        gain, offset = 1.0 / slope, -intercept / slope
    return LineFit(regression, points, int(x.size), float(gain), float(offset))


@dataclass(frozen=True)
class Curve:
    """A candidate for the twin's ball-sensor curve (volts at a position): ``position_m``/``volts_v`` is
    the table the twin interpolates linearly; ``residuals_v`` are at the measured points; ``loo_v`` is
    the leave-one-out error at the interior points (None if the table is too short for this curve)."""

    name: str
    rule: str
    position_m: tuple[float, ...]
    volts_v: tuple[float, ...]
    residuals_v: Residuals
    loo_v: Residuals | None


@dataclass(frozen=True)
class BallCalibration:
    """Static calibration of the ball-position sensor (§6.3) from one table.

    ``software`` is the line the controllers use now (default eq 6.3.1); ``line`` the refit, by the
    method that reproduces eq 6.3.1 from Table 6.3; ``candidates`` every least-squares variant."""

    source: str
    position_m: tuple[float, ...]
    volts_v: tuple[float, ...]
    software: SoftwareCalibration
    candidates: tuple[LineFit, ...]
    line: LineFit
    software_residuals_m: Residuals
    line_residuals_m: Residuals
    curves: tuple[Curve, ...]
    adc_noise_v: float

    def reproduces_software(self, fit: LineFit) -> tuple[bool, bool]:
        """Whether the fit's gain and offset round to the software's values at their printed digits."""
        sw = self.software
        return _same_digits(fit.gain_m_per_v, sw.ball_gain_m_per_v), _same_digits(
            fit.offset_m, sw.ball_offset_m
        )

    @property
    def recommended(self) -> Curve:
        """The curve with the smallest leave-one-out RMS (the first one on a tie)."""
        best = self.curves[0]
        for c in self.curves:
            if c.loo_v is not None and (best.loo_v is None or c.loo_v.rms < best.loo_v.rms):
                best = c
        return best

    def curve(self, name: str) -> Curve:
        for c in self.curves:
            if c.name == name:
                return c
        raise ValueError(f"no curve {name!r}; known: {[c.name for c in self.curves]}")

    def sensor_overrides(self, curve: str | None = None) -> dict[str, tuple[float, ...]]:
        """``Parameters.with_overrides`` values for the twin's sensor: a curve by name (default the
        recommended one)."""
        c = self.recommended if curve is None else self.curve(curve)
        return {"ball_sensor.curve_position_m": c.position_m, "ball_sensor.curve_volts_v": c.volts_v}

    def software_overrides(self) -> dict[str, float]:
        """``Parameters.with_overrides`` values for the controllers' conversion (eq 6.3.1's form)."""
        return {
            "software.ball_gain_m_per_v": self.line.gain_m_per_v,
            "software.ball_offset_m": self.line.offset_m,
        }

    def to_json(self) -> dict[str, object]:
        """Plain JSON: metres to the µm, volts to 0.1 mV, m/V to 0.1 µm/V."""
        m, v, g = 6, 4, 7

        def line_json(fit: LineFit) -> dict[str, object]:
            gain_ok, offset_ok = self.reproduces_software(fit)
            return {
                "regression": fit.regression,
                "points": fit.points,
                "n_points": fit.n_points,
                "gain_m_per_v": round(fit.gain_m_per_v, g),
                "offset_m": round(fit.offset_m, m),
                "gain_rounds_to_software": gain_ok,
                "offset_rounds_to_software": offset_ok,
            }

        return {
            "kind": "ball",
            "source": self.source,
            "table": {"position_m": list(self.position_m), "volts_v": list(self.volts_v)},
            "software": {
                "ball_gain_m_per_v": self.software.ball_gain_m_per_v,
                "ball_offset_m": self.software.ball_offset_m,
            },
            "candidates": [line_json(f) for f in self.candidates],
            "line": line_json(self.line),
            "software_residuals_m": self.software_residuals_m.to_json(m),
            "line_residuals_m": self.line_residuals_m.to_json(m),
            "adc_noise_v": round(self.adc_noise_v, 6),
            "curves": [
                {
                    "name": c.name,
                    "rule": c.rule,
                    "n_points": len(c.position_m),
                    "residuals_v": c.residuals_v.to_json(v),
                    "loo_v": None if c.loo_v is None else c.loo_v.to_json(v),
                }
                for c in self.curves
            ],
            "recommended_curve": self.recommended.name,
            "overrides": {
                "software": {
                    k: round(val, g if "gain" in k else m) for k, val in self.software_overrides().items()
                },
                "ball_sensor": {
                    "ball_sensor.curve_position_m": [round(p, m) for p in self.recommended.position_m],
                    "ball_sensor.curve_volts_v": [round(p, v) for p in self.recommended.volts_v],
                },
            },
        }


Predictor = Callable[[Array], Array]
Builder = Callable[[Array, Array], Predictor | None]


def _piecewise(x: Array, v: Array) -> Predictor | None:
    return lambda q: np.interp(q, x, v)


def _spline_gcv(x: Array, v: Array) -> Predictor | None:
    if x.size < SPLINE_MIN_POINTS:
        return None
    spline = make_smoothing_spline(x, v)
    return lambda q: np.asarray(spline(q), dtype=float)


def _spline_noise(noise_v: float) -> Builder:
    def build(x: Array, v: Array) -> Predictor | None:
        if x.size < SPLINE_MIN_POINTS:
            return None
        spline = UnivariateSpline(x, v, k=3, s=x.size * noise_v**2)
        return lambda q: np.asarray(spline(q), dtype=float)

    return build


def _line_builder(regression: Regression, points: PointSet) -> Builder:
    def build(x: Array, v: Array) -> Predictor | None:
        if x.size - (2 if points == "interior" else 0) < 2:
            return None
        fit = fit_line(x, v, regression, points)
        return fit.volts_v

    return build


def _loo_v(x: Array, v: Array, build: Builder) -> Residuals | None:
    """Leave each interior point out, rebuild the curve from the rest, predict its volts. The end points
    are not left out: the twin's curve is used between the table's ends, and predicting an end would
    test extrapolation, which the linear table cannot do."""
    errors = []
    for i in range(1, x.size - 1):
        keep = np.arange(x.size) != i
        predict = build(x[keep], v[keep])
        if predict is None:
            return None
        errors.append(float(predict(x[i : i + 1])[0] - v[i]))
    return Residuals(tuple(errors))


def _grid_m(x: Array) -> Array:
    """The table's positions and every multiple of the grid step between its ends (to the µm)."""
    step = SPLINE_GRID_STEP_M
    inner = np.arange(math.floor(x[0] / step) + 1, math.ceil(x[-1] / step)) * step
    grid = np.round(np.concatenate([x, inner]), 6)
    grid = np.unique(grid[(grid >= x[0]) & (grid <= x[-1])])
    return grid[np.concatenate([[True], np.diff(grid) > 1e-6])]


def calibrate_ball(
    position_m: Sequence[float] | Array,
    volts_v: Sequence[float] | Array,
    *,
    source: str = "table",
    params: Parameters | None = None,
    regression: Regression = "x_on_v",
    points: PointSet | None = None,
) -> BallCalibration:
    """Fit the ball sensor's straight line and curves to a (position, volts) table (Table 6.3's form).

    ``regression``/``points`` choose the refit line; the default (x on V over the interior points, all
    points when the table has fewer than 4) is a method that reproduces eq 6.3.1 from Table 6.3.
    ``params`` supplies the current software line (the comparison) and the ADC (the spline's noise)."""
    params = params if params is not None else Parameters()
    x = np.asarray(position_m, dtype=float)
    v = np.asarray(volts_v, dtype=float)
    if x.ndim != 1 or x.shape != v.shape or x.size < MIN_ROWS["ball"]:
        raise TableError(f"{source}: needs matching position_m and volts_v columns of at least 3 rows")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(v)) and np.all(np.diff(x) > 0)):
        raise TableError(f"{source}: positions and volts must be finite and positions strictly increasing")
    chosen_points: PointSet = points if points is not None else ("interior" if x.size >= 4 else "all")

    candidates = tuple(
        fit_line(x, v, reg, pts)
        for pts in ("all", "interior")
        for reg in ("x_on_v", "v_on_x")
        if pts == "all" or x.size >= 4
    )
    line = fit_line(x, v, regression, chosen_points)
    if line.gain_m_per_v <= 0:
        raise TableError(
            f"{source}, column volts_v: the volts fall as the position rises (gain {line.gain_m_per_v:.4g} m/V); "
            "the software's x = gain·V + offset needs gain > 0"
        )
    sw = params.software
    software_res = Residuals(tuple((sw.ball_gain_m_per_v * v + sw.ball_offset_m - x).tolist()))
    line_res = Residuals(tuple((line.position_m(v) - x).tolist()))

    daq: Daq = params.daq
    noise_v = (daq.adc_max_v - daq.adc_min_v) / 2 ** int(daq.adc_bits) / math.sqrt(12.0)
    specs: list[tuple[str, str, Builder, Array]] = [
        ("piecewise", "the table itself, interpolated linearly as the twin reads its curve", _piecewise, x),
        (
            "spline-gcv",
            "cubic smoothing spline, smoothing chosen by generalized cross-validation "
            "(scipy make_smoothing_spline)",
            _spline_gcv,
            _grid_m(x),
        ),
        (
            "spline-adc",
            f"cubic smoothing spline to the ADC's quantization noise, s = n·({noise_v * 1e3:.3f} mV)² "
            "(scipy UnivariateSpline)",
            _spline_noise(noise_v),
            _grid_m(x),
        ),
        (
            "line",
            f"the refit straight line ({line.label})",
            _line_builder(regression, chosen_points),
            x[[0, -1]],
        ),
    ]
    curves = []
    for name, rule, build, grid in specs:
        predict = build(x, v)
        if predict is None:
            continue
        curves.append(
            Curve(
                name=name,
                rule=rule,
                position_m=tuple(grid.tolist()),
                volts_v=tuple(np.round(predict(grid), 6).tolist()),
                residuals_v=Residuals(tuple((predict(x) - v).tolist())),
                loo_v=_loo_v(x, v, build),
            )
        )
    return BallCalibration(
        source=source,
        position_m=tuple(x.tolist()),
        volts_v=tuple(v.tolist()),
        software=sw,
        candidates=candidates,
        line=line,
        software_residuals_m=software_res,
        line_residuals_m=line_res,
        curves=tuple(curves),
        adc_noise_v=noise_v,
    )


# --- angle chain's DAC ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class DacCalibration:
    """The angle chain's DAC line Va = slope·DI + offset (eq 6.2.6's form) from measured readings.

    ``volts_per_count``/``offset_v`` are least squares; ``ends_*`` the line through the lowest and
    highest DI (how eq 6.2.6 follows from eq 6.2.4); ``sensor`` the twin's current line (eq 6.2.6)."""

    source: str
    di: tuple[float, ...]
    volts_v: tuple[float, ...]
    sensor: AngleSensor
    volts_per_count: float
    offset_v: float
    ends_volts_per_count: float
    ends_offset_v: float
    residuals_v: Residuals
    sensor_residuals_v: Residuals
    full_scale_count: int = 1023

    def reproduces_sensor(self, volts_per_count: float, offset_v: float) -> tuple[bool, bool]:
        """Whether a slope and offset round to the twin's current values at their printed digits."""
        s = self.sensor
        return _same_digits(volts_per_count, s.dac_volts_per_count), _same_digits(offset_v, s.dac_offset_v)

    def overrides(self) -> dict[str, float]:
        """``Parameters.with_overrides`` values for the twin's DAC (the least-squares line)."""
        return {
            "angle_sensor.dac_volts_per_count": self.volts_per_count,
            "angle_sensor.dac_offset_v": self.offset_v,
        }

    def software_overrides(self) -> dict[str, float]:
        """The software's eq 6.2.9 constants that follow from the refit: motor degrees per volt
        (360/pulses per volt-per-count) and the volts at full scale (eq 6.2.4's 5.002 V at DI = 1023)."""
        deg_per_count = 360.0 / self.sensor.encoder_pulses_per_rev
        return {
            "software.angle_gain_deg_per_v": deg_per_count / self.volts_per_count,
            "software.angle_reference_v": self.volts_per_count * self.full_scale_count + self.offset_v,
        }

    def to_json(self) -> dict[str, object]:
        """Plain JSON: volts to 0.1 mV, V/count to 1e-8 (10 µV over full scale), deg/V to 1e-4."""
        v, slope = 4, 8

        def line_json(k: float, b: float) -> dict[str, object]:
            k_ok, b_ok = self.reproduces_sensor(k, b)
            return {
                "volts_per_count": round(k, slope),
                "offset_v": round(b, v),
                "slope_rounds_to_sensor": k_ok,
                "offset_rounds_to_sensor": b_ok,
            }

        sw = self.software_overrides()
        return {
            "kind": "dac",
            "source": self.source,
            "table": {"di": [int(d) for d in self.di], "volts_v": list(self.volts_v)},
            "sensor": {
                "dac_volts_per_count": self.sensor.dac_volts_per_count,
                "dac_offset_v": self.sensor.dac_offset_v,
            },
            "least_squares": line_json(self.volts_per_count, self.offset_v),
            "through_ends": line_json(self.ends_volts_per_count, self.ends_offset_v),
            "residuals_v": self.residuals_v.to_json(v),
            "sensor_residuals_v": self.sensor_residuals_v.to_json(v),
            "overrides": {
                "angle_sensor": {
                    k: round(val, slope if "per_count" in k else v) for k, val in self.overrides().items()
                },
                "software": {
                    "software.angle_gain_deg_per_v": round(sw["software.angle_gain_deg_per_v"], 4),
                    "software.angle_reference_v": round(sw["software.angle_reference_v"], v),
                },
            },
        }


def calibrate_dac(
    di: Sequence[float] | Array,
    volts_v: Sequence[float] | Array,
    *,
    source: str = "table",
    params: Parameters | None = None,
) -> DacCalibration:
    """Fit the DAC line to (DI, volts) readings (eq 6.2.4's form) and compare it with the twin's
    (default eq 6.2.6)."""
    params = params if params is not None else Parameters()
    d = np.asarray(di, dtype=float)
    v = np.asarray(volts_v, dtype=float)
    if d.ndim != 1 or d.shape != v.shape or d.size < MIN_ROWS["dac"] or np.unique(d).size != d.size:
        raise TableError(f"{source}: needs matching di and volts_v columns of at least 2 distinct readings")
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(v))):
        raise TableError(f"{source}: di and volts must be finite")
    slope, offset = (float(c) for c in np.polyfit(d, v, 1))
    lo, hi = int(np.argmin(d)), int(np.argmax(d))
    ends_slope = float((v[hi] - v[lo]) / (d[hi] - d[lo]))
    ends_offset = float(v[lo] - ends_slope * d[lo])
    s = params.angle_sensor
    return DacCalibration(
        source=source,
        di=tuple(d.tolist()),
        volts_v=tuple(v.tolist()),
        sensor=s,
        volts_per_count=slope,
        offset_v=offset,
        ends_volts_per_count=ends_slope,
        ends_offset_v=ends_offset,
        residuals_v=Residuals(tuple((slope * d + offset - v).tolist())),
        sensor_residuals_v=Residuals(tuple((s.dac_volts_per_count * d + s.dac_offset_v - v).tolist())),
        full_scale_count=2 ** int(s.counter_bits) - 1,
    )


def calibrate(table: Table, params: Parameters | None = None) -> BallCalibration | DacCalibration:
    """The calibration a loaded table calls for (by its header)."""
    if table.kind == "ball":
        return calibrate_ball(table.inputs, table.volts_v, source=table.source, params=params)
    return calibrate_dac(table.inputs, table.volts_v, source=table.source, params=params)
