"""Static curves of the part-built rigs' sensors: a sensor's reading against a ruler (or a protractor), fitted to
its part's equation, as ``calib.static`` fits the thesis's wiper from Table 6.3.

A RULER TABLE (``RulerTable``) holds true positions or angles and the board's readings there (its unit: a
VL53L0X's mm, an HC-SR04's echo µs, ``analogRead`` counts or the PCI-1712's volts, an AS5600's counts), one
row a reading or one row a point's mean with its standard deviation and count. ``load_ruler_table`` reads it
from a CSV (``distance_mm|distance_cm|distance_m|angle_deg|angle_rad``, ``reading_<unit>``, optional
``sd_<unit>`` and ``n``; rows of one true value are replicates and are pooled). Distances are from the
sensor's face, as mounted at its part's ``mount_x_m``, to the ball's near surface (``ranging.near_distance_m``);
angles are the beam's, level = 0.

``fit_static(part, table, params)`` fits the part's own parameters by least squares (weighted by each point's
standard error when the table gives its deviations), with 95 % intervals (Student's t; the covariance scaled
by the reduced χ² when it exceeds 1, so a model that misses leaves wide intervals, not false ones), the noise
of one reading, and a verdict: the model is adequate when the reduced χ² is within its 95 % quantile (the
table's deviations, or the part's own noise when it gives none). The part's equations are its module's
(``twin.parts.<part>``), called without their rounding and noise draws (a mean reading is smooth):

    vl53l0x     range = d − crosstalk; σ = k·d·√(33 ms/budget)   → crosstalk_offset_mm, sigma_fraction
                (missing the table: curve_distance_mm/curve_reading_mm, sigma_floor_mm; see below)
    hcsr04      echo = 2(d + δ)/c(T) − ½ µs (pulseIn truncates)  → temperature_c, mount_x_m (+δ), echo_jitter_us
    gp2y0a21    V = a/(d + b) + c beyond the fold               → curve_a_v_m, curve_b_m, curve_c_v, noise_v
    potentiometer  V = V_ref(u + L sin 2πu), u = ½ + (θ − θ₀)/travel
                                                              → zero_angle_rad, electrical_travel_rad (, linearity)
    as5600      counts = (φ + θ)·4096/2π mod 4096 (I²C)         → magnet_angle_at_level_rad, noise_rms_rad

Beside the part's model it reports alternatives a user may need: a straight line with a free gain and the
measured curve itself (linear interpolation, judged by leave-one-out), for a sensor the part's equation does
not capture (the VL53L0X off a round ball). When the VL53L0X's offset-only law misses the table, the fit writes
the table as the part's measured curve (``vl53l0x.curve_distance_mm``/``curve_reading_mm``: the true distances
and mean readings, read between them along the same broken line), and when a constant deviation holds the
table and the proportional law does not, the part's noise floor (``vl53l0x.sigma_floor_mm``: the pooled
deviation less the whole-mm rounding's 1/12 mm² in quadrature). ``StaticFit.to_toml`` is a rig-description
table the twin loads (``--rig-file``; a curve as a TOML array); ``write_static_fit`` writes it atomically.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import optimize, stats

from twin.parameters import ParameterError, Parameters

__all__ = [
    "PARTS",
    "Override",
    "Alternative",
    "Estimate",
    "RulerTable",
    "StaticFit",
    "StaticFitError",
    "fit_static",
    "load_ruler_table",
    "render_lines",
    "ruler_table",
    "table_from_readings",
    "write_static_fit",
]

PARTS = ("vl53l0x", "hcsr04", "gp2y0a21", "potentiometer", "as5600")
_ROLE = {
    "vl53l0x": "ball_sensor",
    "hcsr04": "ball_sensor",
    "gp2y0a21": "ball_sensor",
    "potentiometer": "angle_sensor",
    "as5600": "angle_sensor",
}
# The table's true column and its size in the base unit (mm for a distance, rad for an angle).
_TRUE_UNITS = {
    "distance_mm": ("distance", 1.0),
    "distance_cm": ("distance", 10.0),
    "distance_m": ("distance", 1000.0),
    "angle_rad": ("angle", 1.0),
    "angle_deg": ("angle", math.pi / 180.0),
}
_READING_UNITS = ("mm", "us", "counts", "v")
LEVEL = 0.95
# A reading's deviation is never taken below one step of its resolution over √12 (a point whose readings were
# all equal still has the quantization's spread): mm, µs and counts read in whole units.
_MIN_SD = {"mm": 1 / math.sqrt(12), "us": 1 / math.sqrt(12), "counts": 1 / math.sqrt(12), "v": 1e-4}
MAX_ROWS = 100_000


# A fitted parameter's value: a number, or a measured curve's column (a ``twin.parameters.curve`` field).
Override = float | tuple[float, ...]


class StaticFitError(ValueError):
    """A ruler table or fit that cannot be used; the message names the file, the line and the column."""


# --- tables ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class RulerTable:
    """True values (mm or rad, ``quantity``) and the mean reading at each (``reading_unit``), with one reading's
    standard deviation (None: single readings) and the readings' count at each point."""

    source: str
    quantity: str
    true: np.ndarray
    reading: np.ndarray
    sd: np.ndarray | None
    n: np.ndarray
    reading_unit: str
    lines: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        for name in ("true", "reading", "n"):
            arr = np.array(getattr(self, name), dtype=float)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if self.sd is not None:
            sd = np.array(self.sd, dtype=float)
            sd.setflags(write=False)
            object.__setattr__(self, "sd", sd)
        where = self.source
        if self.quantity not in ("distance", "angle"):
            raise StaticFitError(f"{where}: quantity {self.quantity!r} is not 'distance' or 'angle'")
        if self.reading_unit not in _READING_UNITS:
            raise StaticFitError(f"{where}: reading unit {self.reading_unit!r} not one of {_READING_UNITS}")
        m = self.true.size
        shapes = [self.reading.size, self.n.size] + ([] if self.sd is None else [self.sd.size])
        if self.true.ndim != 1 or any(s != m for s in shapes):
            raise StaticFitError(
                f"{where}: the true values, readings, deviations and counts differ in length"
            )
        for name in ("true", "reading", "n") + (("sd",) if self.sd is not None else ()):
            arr = getattr(self, name)
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                raise StaticFitError(f"{where}, {self._row(int(bad[0]))}, column {name}: not a finite number")
        if np.any(self.n < 1):
            raise StaticFitError(f"{where}, {self._row(int(np.argmax(self.n < 1)))}, column n: below 1")
        if self.sd is not None and np.any(self.sd < 0):
            raise StaticFitError(f"{where}, {self._row(int(np.argmax(self.sd < 0)))}, column sd: negative")
        if np.unique(self.true).size != m:
            raise StaticFitError(
                f"{where}: a true value appears twice (pool replicates with table_from_readings)"
            )

    def _row(self, i: int) -> str:
        return f"line {self.lines[i]}" if self.lines else f"point {i + 1}"

    @property
    def sem(self) -> np.ndarray | None:
        """The standard error of each point's mean reading (None without deviations)."""
        if self.sd is None:
            return None
        return np.maximum(self.sd, _MIN_SD[self.reading_unit]) / np.sqrt(self.n)


def ruler_table(
    true: Sequence[float] | np.ndarray,
    reading: Sequence[float] | np.ndarray,
    *,
    quantity: str,
    reading_unit: str,
    sd: Sequence[float] | np.ndarray | None = None,
    n: Sequence[float] | np.ndarray | None = None,
    source: str = "table",
) -> RulerTable:
    """A table of points sorted by true value (mm or rad), each a mean reading (``n`` readings, deviation
    ``sd``), or single readings (``sd`` None, ``n`` 1)."""
    t = np.asarray(true, dtype=float)
    order = np.argsort(t, kind="stable")
    count = np.ones(t.size) if n is None else np.asarray(n, dtype=float)
    dev = None if sd is None else np.asarray(sd, dtype=float)[order]
    return RulerTable(
        source,
        quantity,
        t[order],
        np.asarray(reading, dtype=float)[order],
        dev,
        count[order],
        reading_unit.lower(),
    )


def table_from_readings(
    true: Sequence[float] | np.ndarray,
    readings: Sequence[Sequence[float] | np.ndarray],
    *,
    quantity: str,
    reading_unit: str,
    source: str = "table",
    lines: Sequence[int] = (),
) -> RulerTable:
    """A table from each point's readings (the sketch's printed values): their mean, sample standard deviation
    (ddof 1; None when every point has one reading) and count."""
    if len(readings) != len(true):
        raise StaticFitError(f"{source}: {len(true)} true values but {len(readings)} sets of readings")
    for i, r in enumerate(readings):
        if len(r) == 0:
            raise StaticFitError(f"{source}, point {i + 1}: no reading")
    means = [float(np.mean(r)) for r in readings]
    counts = [len(r) for r in readings]
    sds = None
    if max(counts) > 1:
        sds = [float(np.std(r, ddof=1)) if len(r) > 1 else 0.0 for r in readings]
    t = np.asarray(true, dtype=float)
    order = np.argsort(t, kind="stable")
    return RulerTable(
        source,
        quantity,
        t[order],
        np.asarray(means)[order],
        None if sds is None else np.asarray(sds)[order],
        np.asarray(counts, dtype=float)[order],
        reading_unit.lower(),
        tuple(int(lines[i]) for i in order) if lines else (),
    )


def load_ruler_table(path: str | Path) -> RulerTable:
    """Read a ruler table from a CSV (module docstring). Refusals name the file, the line and the column; the
    file is only read (at most ``MAX_ROWS`` rows)."""
    path = Path(path)
    where = str(path)
    try:
        if path.stat().st_size > 16 * 1024 * 1024:
            raise StaticFitError(f"{where}: beyond 16 MiB: not a ruler table")
        text = path.read_bytes().decode("utf-8-sig")
    except OSError as exc:
        raise StaticFitError(f"{where}: cannot read the table ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise StaticFitError(f"{where}: not UTF-8 text") from None
    if "\0" in text:
        raise StaticFitError(f"{where}: a NUL byte: a binary file, not a table")
    rows = [
        (number, line)
        for number, line in enumerate(text.replace("\r\n", "\n").replace("\r", "\n").split("\n"), start=1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not rows:
        raise StaticFitError(f"{where}: empty; expected a header such as distance_mm,reading_mm")
    header_line, header_text = rows[0]
    header = [c.strip().lower() for c in next(csv.reader(io.StringIO(header_text)))]
    true_col = next((c for c in header if c in _TRUE_UNITS), None)
    reading_col = next((c for c in header if c.startswith("reading_")), None)
    if true_col is None or reading_col is None:
        raise StaticFitError(
            f"{where}, line {header_line}: header {header_text.strip()!r} needs a true column "
            f"({', '.join(_TRUE_UNITS)}) and a reading_<unit> column (unit: {', '.join(_READING_UNITS)})"
        )
    unit = reading_col.removeprefix("reading_")
    if unit not in _READING_UNITS:
        raise StaticFitError(f"{where}, line {header_line}, column {reading_col}: unit {unit!r} not known")
    sd_col = f"sd_{unit}" if f"sd_{unit}" in header else None
    known = {true_col, reading_col, sd_col, "n"}
    extra = [c for c in header if c not in known]
    if extra:
        raise StaticFitError(f"{where}, line {header_line}: unknown column {extra[0]!r}")
    if len(rows) - 1 > MAX_ROWS:
        raise StaticFitError(f"{where}: more than {MAX_ROWS} rows")
    cols: dict[str, list[float]] = {c: [] for c in header}
    lines: list[int] = []
    for number, line in rows[1:]:
        cells = next(csv.reader(io.StringIO(line)))
        if len(cells) != len(header):
            raise StaticFitError(f"{where}, line {number}: {len(cells)} cells, the header has {len(header)}")
        for name, cell in zip(header, cells, strict=True):
            try:
                value = float(cell)
            except ValueError:
                raise StaticFitError(
                    f"{where}, line {number}, column {name}: {cell.strip()!r} is not a number"
                ) from None
            if not math.isfinite(value):
                raise StaticFitError(f"{where}, line {number}, column {name}: {cell.strip()!r} is not finite")
            cols[name].append(value)
        lines.append(number)
    quantity, scale = _TRUE_UNITS[true_col]
    true = np.asarray(cols[true_col]) * scale
    if sd_col is None and "n" not in header:
        groups: dict[float, list[float]] = {}
        first: dict[float, int] = {}
        for t, r, number in zip(true.tolist(), cols[reading_col], lines, strict=True):
            groups.setdefault(t, []).append(r)
            first.setdefault(t, number)
        keys = list(groups)
        return table_from_readings(
            keys,
            [groups[k] for k in keys],
            quantity=quantity,
            reading_unit=unit,
            source=where,
            lines=[first[k] for k in keys],
        )
    table = RulerTable(
        where,
        quantity,
        true,
        np.asarray(cols[reading_col]),
        None if sd_col is None else np.asarray(cols[sd_col]),
        np.asarray(cols["n"]) if "n" in header else np.ones(true.size),
        unit,
        tuple(lines),
    )
    if np.any(np.diff(table.true) <= 0):
        i = int(np.argmax(np.diff(table.true) <= 0)) + 1
        raise StaticFitError(f"{where}, line {lines[i]}, column {true_col}: true values must increase")
    return table


# --- results --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Estimate:
    """A fitted value with its 95 % interval; ``name`` the parameter (``group.field``) or a quantity of the fit."""

    name: str
    value: float
    low: float
    high: float
    unit: str

    def to_json(self) -> dict[str, object]:
        return {
            "name": self.name,
            "value": self.value,
            "ci_low": self.low,
            "ci_high": self.high,
            "unit": self.unit,
        }


@dataclass(frozen=True)
class Alternative:
    """Another curve for the same table: its equation, estimates and residuals (predicted − measured)."""

    name: str
    equation: str
    estimates: tuple[Estimate, ...]
    residuals: np.ndarray
    chi2_dof: float | None
    adequate: bool | None

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(np.square(self.residuals))))


@dataclass(frozen=True, eq=False)
class StaticFit:
    """A part's parameters fitted to a ruler table (module docstring). ``residuals`` are predicted − measured
    mean readings in the reading's unit; ``noise`` one reading's standard deviation (the table's pooled
    deviation, or the residuals' without one); ``overrides`` the part's parameters for
    ``Parameters.with_overrides``."""

    part: str
    table: RulerTable
    equation: str
    estimates: tuple[Estimate, ...]
    residuals: np.ndarray
    noise: float
    chi2_dof: float
    chi2_limit: float
    adequate: bool
    overrides: dict[str, Override]
    alternatives: tuple[Alternative, ...] = ()
    notes: tuple[str, ...] = ()
    used: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    @property
    def role(self) -> str:
        return _ROLE[self.part]

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(np.square(self.residuals))))

    def estimate(self, name: str) -> Estimate:
        for e in self.estimates:
            if e.name == name:
                return e
        raise KeyError(f"no estimate {name!r}; there are {[e.name for e in self.estimates]}")

    def alternative(self, name: str) -> Alternative:
        for a in self.alternatives:
            if a.name == name:
                return a
        raise KeyError(f"no alternative {name!r}")

    def to_json(self) -> dict[str, object]:
        return {
            "part": self.part,
            "role": self.role,
            "source": self.table.source,
            "equation": self.equation,
            "estimates": [e.to_json() for e in self.estimates],
            "residuals": self.residuals.tolist(),
            "rms": self.rms,
            "noise": self.noise,
            "reading_unit": self.table.reading_unit,
            "chi2_dof": self.chi2_dof,
            "chi2_limit": self.chi2_limit,
            "adequate": self.adequate,
            "overrides": self.overrides,
            "alternatives": [
                {
                    "name": a.name,
                    "equation": a.equation,
                    "estimates": [e.to_json() for e in a.estimates],
                    "rms": a.rms,
                    "chi2_dof": a.chi2_dof,
                    "adequate": a.adequate,
                }
                for a in self.alternatives
            ],
            "notes": list(self.notes),
        }

    def to_toml(self) -> str:
        """A rig-description table (``--rig-file``) setting the part and its fitted fields."""
        lines = [
            f"# Static fit of {self.part} from {self.table.source} (calib.sensor_static): {self.equation}",
            f"# residual RMS {self.rms:.4g} {self.table.reading_unit}, reduced chi2 {self.chi2_dof:.3g} "
            f"(95 % limit {self.chi2_limit:.3g}): {'adequate' if self.adequate else 'the model misses the table'}",
        ]
        lines += [f"# {note}" for note in self.notes]
        lines += ["", f"[{self.role}]", f'part = "{self.part}"']
        by_name = {e.name: e for e in self.estimates}
        for name, value in self.overrides.items():
            if isinstance(value, tuple):  # a measured curve's column: a TOML array of its values
                lines.append(f"{name.partition('.')[2]} = [{', '.join(repr(float(v)) for v in value)}]")
                continue
            e = by_name.get(name)
            why = (
                f"  # 95 %: {e.low:.6g} … {e.high:.6g} {e.unit}"
                if e is not None and math.isfinite(e.low)
                else ""
            )
            text = repr(int(value)) if float(value).is_integer() and "seed" in name else repr(float(value))
            lines.append(f"{name.partition('.')[2]} = {text}{why}")
        return "\n".join(lines) + "\n"


def write_static_fit(fit: StaticFit, path: str | Path, *, overwrite: bool = False) -> None:
    """Write ``fit.to_toml()`` atomically (``twin.outputs.atomic_output``; an existing file only with
    ``overwrite``)."""
    from twin.outputs import atomic_output

    with atomic_output(path, overwrite=overwrite) as fh:
        fh.write(fit.to_toml().encode("utf-8"))


# --- least squares --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Solved:
    values: np.ndarray
    half: np.ndarray  # 95 % half-widths
    residuals: np.ndarray  # predicted − measured
    chi2_dof: float
    chi2_limit: float
    adequate: bool


def _solve(
    model: Callable[[np.ndarray], np.ndarray],
    start: Sequence[float],
    measured: np.ndarray,
    sigma: np.ndarray,
    bounds: tuple[Sequence[float], Sequence[float]] | None = None,
) -> _Solved:
    """Weighted least squares of ``model(p)`` on ``measured`` (each with standard error ``sigma``), intervals from
    the Jacobian at the optimum, the covariance scaled by the reduced χ² when it is above 1 (Birge)."""
    p0 = np.asarray(start, dtype=float)
    lo, hi = bounds if bounds is not None else ([-np.inf] * p0.size, [np.inf] * p0.size)
    p0 = np.clip(p0, np.asarray(lo, dtype=float), np.asarray(hi, dtype=float))
    result = optimize.least_squares(
        lambda p: (model(p) - measured) / sigma,
        p0,
        bounds=(lo, hi),
        x_scale="jac",
        xtol=1e-14,
        ftol=1e-14,
        gtol=1e-14,
        max_nfev=2000,
    )
    dof = max(measured.size - p0.size, 1)
    chi2 = float(np.sum(result.fun**2)) / dof
    jac = result.jac
    try:
        cov = np.linalg.inv(jac.T @ jac) * max(chi2, 1.0)
        half = stats.t.ppf(0.5 + LEVEL / 2, dof) * np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        half = np.full(p0.size, np.inf)
    limit = float(stats.chi2.ppf(LEVEL, dof) / dof)
    return _Solved(result.x, half, model(result.x) - measured, chi2, limit, chi2 <= limit)


def _sigma(table: RulerTable, part_noise: float, mask: np.ndarray) -> tuple[np.ndarray, str]:
    """Each point's standard error: the table's (sd/√n) or the part's own noise of one reading over √n."""
    sem = table.sem
    if sem is not None:
        return sem[mask], "the table's deviations"
    floor = _MIN_SD[table.reading_unit]
    return np.full(int(mask.sum()), max(part_noise, floor)) / np.sqrt(table.n[mask]), "the part's own noise"


def _pooled_sd(table: RulerTable, mask: np.ndarray, residuals: np.ndarray, p: int) -> float:
    """One reading's deviation: the table's pooled (weighted by n − 1), else the residuals' (dof N − p)."""
    if table.sd is not None and np.sum(table.n[mask] - 1) > 0:
        w = table.n[mask] - 1
        return float(np.sqrt(np.sum(w * table.sd[mask] ** 2) / np.sum(w)))
    return float(np.sqrt(np.sum(residuals**2) / max(residuals.size - p, 1)))


def _bounds(cls: type, name: str) -> tuple[float, float]:
    meta = {f.name: f.metadata for f in dataclasses.fields(cls)}[name]
    lo = meta.get("ge") if meta.get("ge") is not None else meta.get("gt")
    hi = meta.get("le") if meta.get("le") is not None else meta.get("lt")
    return (-np.inf if lo is None else float(lo)), (np.inf if hi is None else float(hi))


def _est(name: str, value: float, half: float, unit: str) -> Estimate:
    return Estimate(name, float(value), float(value - half), float(value + half), unit)


def _line(table: RulerTable, mask: np.ndarray, sigma: np.ndarray, unit: str, x_unit: str) -> Alternative:
    x, y = table.true[mask], table.reading[mask]
    s = _solve(lambda p: p[0] * x + p[1], [1.0, 0.0], y, sigma)
    return Alternative(
        "line",
        f"reading = gain·true + offset (a free gain; {x_unit} → {unit})",
        (
            _est("gain", s.values[0], s.half[0], f"{unit}/{x_unit}"),
            _est("offset", s.values[1], s.half[1], unit),
        ),
        s.residuals,
        s.chi2_dof,
        s.adequate,
    )


def _polynomial(
    table: RulerTable, mask: np.ndarray, sigma: np.ndarray, degree: int, unit: str
) -> Alternative:
    """reading = Σ c_j·z^j, z = (true − mid)/half-span over the table (scaled: the coefficients are the curve's
    reach at the table's ends, in the reading's unit)."""
    x, y = table.true[mask], table.reading[mask]
    mid, half = (x[0] + x[-1]) / 2, (x[-1] - x[0]) / 2
    z = (x - mid) / half
    s = _solve(lambda p: np.polyval(p[::-1], z), [float(np.mean(y))] + [0.0] * degree, y, sigma)
    return Alternative(
        "cubic" if degree == 3 else f"degree-{degree}",
        f"reading = Σ c_j·z^j, j ≤ {degree}, z = (true − {mid:g})/{half:g}",
        tuple(_est(f"c{j}", v, h, unit) for j, (v, h) in enumerate(zip(s.values, s.half, strict=True))),
        s.residuals,
        s.chi2_dof,
        s.adequate,
    )


def _measured_curve(table: RulerTable, mask: np.ndarray, unit: str) -> Alternative:
    """The table itself interpolated linearly (as the thesis's wiper curve); its error by leave-one-out at the
    interior points (the ends would be extrapolation)."""
    x, y = table.true[mask], table.reading[mask]
    loo = [float(np.interp(x[i], np.delete(x, i), np.delete(y, i)) - y[i]) for i in range(1, x.size - 1)]
    sem = table.sem
    chi2 = None
    if sem is not None and loo:
        # a left-out point's error has its own and its neighbours' interpolated errors: ≈ √1.5 × its own
        chi2 = float(np.mean((np.asarray(loo) / (sem[mask][1:-1] * math.sqrt(1.5))) ** 2))
    return Alternative(
        "measured-curve",
        "reading interpolated linearly in the table (a measured curve, as the thesis's "
        "ball_sensor.curve_position_m/curve_volts_v); residuals by leave-one-out",
        (),
        np.asarray(loo),
        chi2,
        None if chi2 is None else chi2 <= float(stats.chi2.ppf(LEVEL, len(loo)) / len(loo)),
    )


# --- the parts ------------------------------------------------------------------------------------------


def _need(table: RulerTable, part: str, quantity: str, units: Sequence[str]) -> None:
    if table.quantity != quantity:
        raise StaticFitError(
            f"{table.source}: {part} is fitted against a {quantity}, the table gives a {table.quantity}"
        )
    if table.reading_unit not in units:
        raise StaticFitError(
            f"{table.source}: {part}'s reading is in {' or '.join(units)} on its board, the table's in "
            f"{table.reading_unit}"
        )


def _deviation_law(sd: np.ndarray, n: np.ndarray, shape: np.ndarray) -> _Solved:
    """σ_i = k·shape_i fitted to the points' sample deviations: k² = Σ(n − 1)(sd/shape)²/Σ(n − 1), unbiased
    for normal readings (weighting each point by its own deviation would favour the ones low by chance). A
    sample deviation's relative standard error is 1/√(2(n − 1)): the reduced χ² of sd/(k·shape) − 1 judges the
    law, and the interval is k/√(2Σ(n − 1)) wide per unit of t, scaled by √χ² when that is above 1."""
    dof_each = n - 1.0
    k = float(np.sqrt(np.sum(dof_each * (sd / shape) ** 2) / np.sum(dof_each)))
    m = sd.size
    chi2 = float(np.sum(2.0 * dof_each * (sd / (k * shape) - 1.0) ** 2) / max(m - 1, 1))
    half = (
        stats.t.ppf(0.5 + LEVEL / 2, max(m - 1, 1))
        * k
        / math.sqrt(2.0 * np.sum(dof_each))
        * math.sqrt(max(chi2, 1.0))
    )
    limit = float(stats.chi2.ppf(LEVEL, max(m - 1, 1)) / max(m - 1, 1))
    return _Solved(np.array([k]), np.array([half]), k * shape - sd, chi2, limit, chi2 <= limit)


def _fit_vl53l0x(table: RulerTable, params: Parameters) -> StaticFit:
    from twin.parts.vl53l0x import SIGMA_BUDGET_S, Vl53l0x, vl53l0x_sigma_mm

    _need(table, "vl53l0x", "distance", ("mm",))
    group = params.of(Vl53l0x)
    mask = np.ones(table.true.size, dtype=bool)
    d, r = table.true, table.reading
    model_sd = np.asarray(vl53l0x_sigma_mm(np.maximum(d, 1.0), group.sigma_fraction, group.timing_budget_s))
    sem = table.sem
    sigma = sem if sem is not None else np.maximum(model_sd, _MIN_SD["mm"]) / np.sqrt(table.n)
    s = _solve(lambda p: d - p[0], [group.crosstalk_offset_mm], r, sigma)
    notes = []
    estimates = [_est("vl53l0x.crosstalk_offset_mm", s.values[0], s.half[0], "mm")]
    overrides: dict[str, Override] = {"vl53l0x.crosstalk_offset_mm": float(s.values[0])}
    scale = math.sqrt(SIGMA_BUDGET_S / group.timing_budget_s)
    if table.sd is not None and np.all(table.n >= 2):
        # σ_i = k·d_i·√(B₀/B) (the part's) against a constant σ₀, each fitted to the points' deviations
        prop = _deviation_law(table.sd, table.n, d * scale)
        const = _deviation_law(table.sd, table.n, np.ones(d.size))
        estimates.append(_est("vl53l0x.sigma_fraction", prop.values[0], prop.half[0], "-"))
        estimates.append(_est("noise floor σ₀ (constant)", const.values[0], const.half[0], "mm"))
        verdict = (
            f"the deviations against the part's σ ∝ distance: reduced χ² {prop.chi2_dof:.3g}, against a constant "
            f"σ₀ = {const.values[0]:.3g} mm: {const.chi2_dof:.3g} (95 % limit {prop.chi2_limit:.3g})"
        )
        if prop.adequate:
            overrides["vl53l0x.sigma_fraction"] = float(prop.values[0])
            notes.append(verdict)
        elif const.adequate:
            # the twin rounds a range to whole mm after its noise: a reading's variance is σ₀² + 1/12 mm²
            floor = math.sqrt(max(float(const.values[0]) ** 2 - 1.0 / 12.0, 0.0))
            overrides["vl53l0x.sigma_floor_mm"] = floor
            top = floor / (float(d[-1]) * scale)
            notes.append(
                f"{verdict}: the part's noise law does not hold this table, a floor does: vl53l0x.sigma_floor_mm "
                f"= {floor:.4g} mm (σ₀ less the whole-mm rounding in quadrature; σ = max(σ₀, k·d·√(33 ms/B))); "
                f"vl53l0x.sigma_fraction is left as it was ({group.sigma_fraction:g}): k ≤ {top:.3g} keeps the "
                f"floor alone up to the table's {float(d[-1]):g} mm"
            )
        else:
            notes.append(
                f"{verdict}: the part's noise law does not hold this table, vl53l0x.sigma_fraction is left as it was"
            )
    notes.append(
        f"the timing budget is the parameters' vl53l0x.timing_budget_s = {group.timing_budget_s:g} s; distances "
        "are from the sensor's face to the ball's near surface"
    )
    line = _line(table, mask, sigma, "mm", "mm")
    curve = _measured_curve(table, mask, "mm")
    cubic = _polynomial(table, mask, sigma, 3, "mm")
    if not s.adequate:
        g = line.estimates[0]
        monotone = bool(np.all(np.diff(r) > 0) and d[0] >= 0.0)
        if monotone:
            # the measured curve replaces range = d − crosstalk for the ball: the offset fitted above is not a
            # cover's crosstalk but the curve's mean, so it is not written
            del overrides["vl53l0x.crosstalk_offset_mm"]
            overrides["vl53l0x.curve_distance_mm"] = tuple(float(v) for v in d)
            overrides["vl53l0x.curve_reading_mm"] = tuple(float(v) for v in r)
        written = (
            f"vl53l0x.curve_distance_mm/curve_reading_mm are written ({d.size} points) and the crosstalk left "
            "as it was"
            if monotone
            else "none is written: the mean readings do not increase strictly with the distance (no inverse)"
        )
        notes.append(
            f"the part's offset-only range leaves an RMS of {float(np.sqrt(np.mean(s.residuals**2))):.3g} mm; "
            f"a free gain ({g.value:.4g}, 95 % {g.low:.4g} … {g.high:.4g}) leaves {line.rms:.3g} mm "
            f"({'adequate' if line.adequate else 'still beyond the noise'}), a cubic {cubic.rms:.3g} mm "
            f"({'adequate' if cubic.adequate else 'still beyond the noise'}); the measured curve's "
            f"leave-one-out RMS is {curve.rms:.3g} mm: the part needs a measured curve (distance → reading, as "
            f"the thesis's wiper curve) to hold this sensor: {written}"
        )
    return _result(
        "vl53l0x",
        table,
        "range = d − crosstalk_offset_mm",
        estimates,
        s,
        mask,
        overrides,
        (line, cubic, curve),
        notes,
        1,
    )


def _fit_hcsr04(table: RulerTable, params: Parameters) -> StaticFit:
    from twin.parts.hcsr04 import Hcsr04, speed_of_sound_m_s

    _need(table, "hcsr04", "distance", ("us",))
    group = params.of(Hcsr04)
    mask = np.ones(table.true.size, dtype=bool)
    d_m = table.true * 1e-3
    sigma, _ = _sigma(table, group.echo_jitter_us, mask)

    def echo(p: np.ndarray) -> np.ndarray:
        # pulseIn truncates to whole µs: the mean of ⌊w + jitter⌋ is w − ½ for a jitter of a µs or more
        return 2.0 * (d_m + p[1] * 1e-3) / speed_of_sound_m_s(p[0]) * 1e6 - 0.5

    lo_t, hi_t = _bounds(Hcsr04, "temperature_c")
    s = _solve(echo, [group.temperature_c, 0.0], table.reading, sigma, ([lo_t, -1000.0], [hi_t, 1000.0]))
    noise = _pooled_sd(table, mask, s.residuals, 2)
    c = float(speed_of_sound_m_s(s.values[0]))
    estimates = [
        _est("hcsr04.temperature_c", s.values[0], s.half[0], "°C"),
        _est("distance offset δ", s.values[1], s.half[1], "mm"),
        _est("speed of sound", c, float(abs(speed_of_sound_m_s(s.values[0] + s.half[0]) - c)), "m/s"),
        Estimate("hcsr04.echo_jitter_us", noise, math.nan, math.nan, "µs"),
    ]
    overrides = {
        "hcsr04.temperature_c": float(s.values[0]),
        "hcsr04.mount_x_m": float(group.mount_x_m + s.values[1] * 1e-3),
        "hcsr04.echo_jitter_us": noise,
    }
    notes = (
        "the offset δ moves the sensor's mount: hcsr04.mount_x_m = the parameters' "
        f"{group.mount_x_m:g} m + δ (the ruler's zero at the face as mounted there)",
    )
    return _result(
        "hcsr04",
        table,
        "echo = 2(d + δ)/c(T) − ½ µs",
        estimates,
        s,
        mask,
        overrides,
        (_line(table, mask, sigma, "µs", "mm"),),
        notes,
        2,
        noise,
    )


def _volts(table: RulerTable, params: Parameters) -> tuple[np.ndarray, np.ndarray, float]:
    """The readings as the pin's volts, the standard errors in volts and one ADC step (V): ``analogRead``
    counts read ⌊V·1024/V_ref⌋, so a mean count c is (c + ½)·V_ref/1024 (``twin.parts.arduino``)."""
    if table.reading_unit == "v":
        step = (params.daq.adc_max_v - params.daq.adc_min_v) / 2 ** int(params.daq.adc_bits)
        return table.reading, np.ones(table.reading.size), step
    from twin.parts.arduino import ADC_CODES, Arduino

    ref = params.of(Arduino).adc_reference_v
    step = ref / ADC_CODES
    return (table.reading + 0.5) * step, np.full(table.reading.size, step), step


def _fit_gp2y0a21(table: RulerTable, params: Parameters) -> StaticFit:
    from twin.parts.gp2y0a21 import Gp2y0a21, gp2y0a21_volts

    _need(table, "gp2y0a21", "distance", ("counts", "v"))
    group = params.of(Gp2y0a21)
    d_m = table.true * 1e-3
    mask = d_m >= group.fold_distance_m
    if mask.sum() < 4:
        raise StaticFitError(
            f"{table.source}: {int(mask.sum())} points beyond the fold (gp2y0a21.fold_distance_m = "
            f"{group.fold_distance_m:g} m); the curve a/(d + b) + c needs at least 4"
        )
    volts, per_unit, step = _volts(table, params)
    sem = table.sem
    sigma = (
        (sem * per_unit)[mask]
        if sem is not None
        else np.full(int(mask.sum()), max(group.noise_v, step / math.sqrt(12))) / np.sqrt(table.n[mask])
    )
    names = ("curve_a_v_m", "curve_b_m", "curve_c_v")
    lo, hi = zip(*(_bounds(Gp2y0a21, n) for n in names), strict=True)

    def model(p: np.ndarray) -> np.ndarray:
        return np.asarray(
            gp2y0a21_volts(d_m[mask], a_v_m=p[0], b_m=p[1], c_v=p[2], fold_m=group.fold_distance_m)
        )

    start = [group.curve_a_v_m, group.curve_b_m, group.curve_c_v]
    s = _solve(model, start, volts[mask], sigma, (lo, hi))
    sd_v = _pooled_sd(table, mask, s.residuals, 3) * (per_unit[0] if table.sd is not None else 1.0)
    noise = math.sqrt(max(sd_v**2 - step**2 / 12, 0.0))  # less the ADC's own quantization
    units = ("V·m", "m", "V")
    estimates = [
        _est(f"gp2y0a21.{n}", v, h, u) for n, v, h, u in zip(names, s.values, s.half, units, strict=True)
    ]
    estimates.append(Estimate("gp2y0a21.noise_v", noise, math.nan, math.nan, "V"))
    overrides = {f"gp2y0a21.{n}": float(v) for n, v in zip(names, s.values, strict=True)}
    overrides["gp2y0a21.noise_v"] = noise
    notes = [f"{int((~mask).sum())} point(s) nearer than the fold ({group.fold_distance_m:g} m) left out"]
    if table.reading_unit == "counts":
        notes.append("counts read as the pin's volts (c + ½)·V_ref/1024; residuals in volts")
    return _result("gp2y0a21", table, "V = a/(d + b) + c", estimates, s, mask, overrides, (), notes, 3, noise)


def _fit_potentiometer(table: RulerTable, params: Parameters) -> StaticFit:
    from twin.parts.potentiometer import Potentiometer, pot_wiper_v

    _need(table, "potentiometer", "angle", ("counts", "v"))
    group = params.of(Potentiometer)
    mask = np.ones(table.true.size, dtype=bool)
    volts, per_unit, step = _volts(table, params)
    sem = table.sem
    sigma = (
        sem * per_unit
        if sem is not None
        else np.full(table.true.size, max(group.noise_rms_v, step / math.sqrt(12)))
    )
    span = float(np.ptp(table.true)) / group.electrical_travel_rad
    names = ["zero_angle_rad", "electrical_travel_rad"]
    # the linearity's sine is separable from the travel only over a wide part of the track: near mid-track
    # V ≈ V_ref(½ + (1 − 2πL)(θ − θ₀)/travel), one slope for two parameters
    free_linearity = span >= 0.4
    if free_linearity:
        names.append("linearity_error")
    lo, hi = zip(*(_bounds(Potentiometer, n) for n in names), strict=True)

    def model(p: np.ndarray) -> np.ndarray:
        values = dict(zip(names, p.tolist(), strict=True))
        pot = dataclasses.replace(group, **values)
        return np.asarray(pot_wiper_v(table.true, pot), dtype=float)

    s = _solve(model, [getattr(group, n) for n in names], volts, sigma, (lo, hi))
    sd_v = _pooled_sd(table, mask, s.residuals, len(names)) * (per_unit[0] if table.sd is not None else 1.0)
    noise = math.sqrt(max(sd_v**2 - step**2 / 12, 0.0))
    units = {"zero_angle_rad": "rad", "electrical_travel_rad": "rad", "linearity_error": "fraction of V_ref"}
    estimates = [
        _est(f"potentiometer.{n}", v, h, units[n]) for n, v, h in zip(names, s.values, s.half, strict=True)
    ]
    estimates.append(Estimate("potentiometer.noise_rms_v", noise, math.nan, math.nan, "V"))
    overrides = {f"potentiometer.{n}": float(v) for n, v in zip(names, s.values, strict=True)}
    overrides["potentiometer.noise_rms_v"] = noise
    notes = (
        []
        if free_linearity
        else [
            f"the table spans {span:.0%} of the track: the linearity error is held at "
            f"potentiometer.linearity_error = {group.linearity_error:g} (not separable from the travel over a "
            "short swing; the fitted travel is the effective one)"
        ]
    )
    return _result(
        "potentiometer",
        table,
        "V = V_ref(u + L sin 2πu), u = ½ + (θ − θ₀)/travel",
        estimates,
        s,
        mask,
        overrides,
        (),
        notes,
        len(names),
        noise,
    )


def _fit_as5600(table: RulerTable, params: Parameters) -> StaticFit:
    from twin.parts.as5600 import AS5600, COUNTS, as5600_counts

    _need(table, "as5600", "angle", ("counts",))
    group = params.of(AS5600)
    if group.analog_output:
        raise StaticFitError(
            f"{table.source}: as5600.analog_output is set: the fit reads the RAW ANGLE register's counts over I²C "
            "(set it false, or fit the OUT pin's volts as a potentiometer's)"
        )
    mask = np.ones(table.true.size, dtype=bool)
    per_rad = COUNTS / (2 * math.pi)
    # the counts unwrapped around the model at the mounting's magnet angle: a reading across 4095 → 0 stays near
    base = np.asarray(as5600_counts(table.true, group), dtype=float)
    unwrapped = table.reading + COUNTS * np.round((base - table.reading) / COUNTS)
    sem = table.sem
    sigma = (
        sem
        if sem is not None
        else np.full(table.true.size, max(group.noise_rms_rad * per_rad, _MIN_SD["counts"]))
    )

    def model(p: np.ndarray) -> np.ndarray:
        return (
            np.asarray(as5600_counts(table.true, dataclasses.replace(group, magnet_angle_at_level_rad=0.0)))
            + p[0] * per_rad
        )

    s = _solve(model, [group.magnet_angle_at_level_rad], unwrapped, sigma)
    phi = float(np.mod(s.values[0], 2 * math.pi))
    sd = _pooled_sd(table, mask, s.residuals, 1)
    noise = math.sqrt(max(sd**2 - 1 / 12, 0.0)) / per_rad  # less the count's own quantization
    estimates = [
        _est("as5600.magnet_angle_at_level_rad", phi, s.half[0], "rad"),
        Estimate("as5600.noise_rms_rad", noise, math.nan, math.nan, "rad"),
    ]
    line = _line(dataclasses.replace(table, reading=unwrapped), mask, sigma, "counts", "rad")
    notes = (
        f"a free gain gives {line.estimates[0].value:.2f} counts/rad against the chip's 4096/2π = {per_rad:.2f} "
        "(another ratio: a gear or the magnet off the shaft)",
    )
    overrides = {"as5600.magnet_angle_at_level_rad": phi, "as5600.noise_rms_rad": noise}
    return _result(
        "as5600",
        table,
        "counts = (φ + θ)·4096/2π mod 4096",
        estimates,
        s,
        mask,
        overrides,
        (line,),
        notes,
        1,
        noise,
    )


def _result(
    part: str,
    table: RulerTable,
    equation: str,
    estimates: Sequence[Estimate],
    s: _Solved,
    mask: np.ndarray,
    overrides: Mapping[str, Override],
    alternatives: Sequence[Alternative],
    notes: Sequence[str],
    p: int,
    noise: float | None = None,
) -> StaticFit:
    return StaticFit(
        part=part,
        table=table,
        equation=equation,
        estimates=tuple(estimates),
        residuals=s.residuals,
        noise=_pooled_sd(table, mask, s.residuals, p) if noise is None else noise,
        chi2_dof=s.chi2_dof,
        chi2_limit=s.chi2_limit,
        adequate=s.adequate,
        overrides=dict(overrides),
        alternatives=tuple(alternatives),
        notes=tuple(notes),
        used=mask,
    )


_FITS: dict[str, Callable[[RulerTable, Parameters], StaticFit]] = {
    "vl53l0x": _fit_vl53l0x,
    "hcsr04": _fit_hcsr04,
    "gp2y0a21": _fit_gp2y0a21,
    "potentiometer": _fit_potentiometer,
    "as5600": _fit_as5600,
}


def fit_static(part: str, table: RulerTable, params: Parameters | None = None) -> StaticFit:
    """Fit ``part``'s static curve (``PARTS``) to ``table`` from the parameters ``params`` (default the
    defaults: the start values and the fixed ones). The fitted values are checked against their fields' bounds
    (a value beyond them is refused naming ``group.field``)."""
    if part not in _FITS:
        raise StaticFitError(f"part {part!r}: the static fit knows {', '.join(PARTS)}")
    if table.true.size < 3:
        raise StaticFitError(f"{table.source}: {table.true.size} points; a static curve needs at least 3")
    params = params if params is not None else Parameters()
    fit = _FITS[part](table, params)
    try:
        params.with_overrides(dict(fit.overrides), origin=f"static fit of {part}")
    except ParameterError as exc:
        raise StaticFitError(f"{table.source}: {exc}") from None
    return fit


def render_lines(fit: StaticFit) -> list[str]:
    """The fit as plain text lines for a terminal."""
    unit = fit.table.reading_unit
    out = [
        f"{fit.part} ({fit.role}), {fit.table.source}: {fit.table.true.size} points, {fit.equation}",
        f"  {'parameter':<36} {'value':>12} {'95 % interval':>27}",
    ]
    for e in fit.estimates:
        ci = "" if math.isnan(e.low) else f"{e.low:>12.6g} … {e.high:<12.6g}"
        out.append(f"  {e.name:<36} {e.value:>12.6g} {ci:>27} {e.unit}")
    verdict = "adequate" if fit.adequate else "the model misses the table"
    out.append(
        f"  residual RMS {fit.rms:.4g} {unit}, one reading's noise {fit.noise:.4g}, reduced χ² {fit.chi2_dof:.3g} "
        f"(95 % limit {fit.chi2_limit:.3g}): {verdict}"
    )
    for a in fit.alternatives:
        word = "adequate" if a.adequate else "misses"
        judged = "" if a.adequate is None else f", reduced χ² {a.chi2_dof:.3g} ({word})"
        out.append(f"  alternative {a.name}: RMS {a.rms:.4g} {unit}{judged}")
    out += [f"  note: {n}" for n in fit.notes]
    return out
