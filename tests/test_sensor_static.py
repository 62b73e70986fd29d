"""Static curves of the part-built rigs' sensors (calib/sensor_static.py): each part's parameters from a table
of true positions/angles and readings, with 95 % intervals.

Synthetic tables are made here from each sensor's physics written out independently of twin/parts (the speed of
sound, the Sharp curve, the pot's wiper, the AS5600's counts), with seeded noise; the fit must land the values
the table was made with inside its intervals. Then the real VL53L0X table of Open Ball & Beam
(github.com/TSummersLab/open-ball-beam, ballbeam/calibration/sensor_calibration_data.txt, commit 58cb136: 18 true
distances, 20 readings each, VL53L0X at a 20 ms timing budget), with its residual stated."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from calib.sensor_static import (
    Estimate,
    RulerTable,
    StaticFitError,
    fit_static,
    load_ruler_table,
    ruler_table,
    table_from_readings,
    write_static_fit,
)
from twin.parameters import Parameters
from twin.parts.description import rig_from_text

ARDUINO = Parameters().with_overrides({"parts.io_board": "arduino_uno"})


def _inside(fit_estimate: Estimate, truth: float) -> None:
    low, high = fit_estimate.low, fit_estimate.high
    assert low <= truth <= high, f"{fit_estimate} does not hold {truth}"


# --- synthetic tables: recovery within the intervals -------------------------------------------------------


# Each table is drawn 40 times (seeds 0…39): a 95 % interval must hold the value the table was made with in
# at least 34 of them (a binomial count of 95 % below 34 of 40 has a chance under 1.5 %); measured: 38-40.
SEEDS = range(40)
MIN_HITS = 34


def _coverage(fits: list[list[Estimate]], truths: list[float]) -> list[int]:
    hits = [0] * len(truths)
    for estimates in fits:
        for j, (e, truth) in enumerate(zip(estimates, truths, strict=True)):
            hits[j] += int(e.low <= truth <= e.high)
    assert min(hits) >= MIN_HITS, hits
    return hits


def _vl53l0x_table(seed: int) -> RulerTable:
    # range = d − 12 mm (a cover glass's crosstalk), σ = 0.05·d, whole mm
    rng = np.random.default_rng(seed)
    d = np.arange(40.0, 401.0, 20.0)
    readings = [np.rint(x - 12.0 + rng.normal(0.0, 0.05 * x, 30)) for x in d]
    return table_from_readings(d, readings, quantity="distance", reading_unit="mm")


@pytest.mark.quick
def test_vl53l0x_offset_and_noise_recovered() -> None:
    budget = Parameters().with_overrides({"vl53l0x.timing_budget_s": 0.020})
    k = 0.05 / math.sqrt(0.033 / 0.020)  # the part's σ = k·d·√(33 ms/20 ms) = 0.05·d
    fits = [fit_static("vl53l0x", _vl53l0x_table(s), budget) for s in SEEDS]
    names = ("vl53l0x.crosstalk_offset_mm", "vl53l0x.sigma_fraction")
    _coverage([[f.estimate(n) for n in names] for f in fits], [12.0, k])
    assert sum(f.adequate for f in fits) >= MIN_HITS
    assert fits[0].overrides["vl53l0x.sigma_fraction"] == fits[0].estimate("vl53l0x.sigma_fraction").value


def _hcsr04_table(seed: int) -> RulerTable:
    # echo = ⌊2(d + 4 mm)/c + jitter⌋ µs, c = 331.3·√(1 + 28/273.15) = 347.83 m/s (28 °C), jitter σ 6 µs
    rng = np.random.default_rng(seed)
    c = 331.3 * math.sqrt(1.0 + 28.0 / 273.15)
    d = np.arange(30.0, 301.0, 10.0)
    readings = [np.floor(2.0 * (x + 4.0) * 1e-3 / c * 1e6 + rng.normal(0.0, 6.0, 25)) for x in d]
    return table_from_readings(d, readings, quantity="distance", reading_unit="us")


@pytest.mark.quick
def test_hcsr04_temperature_and_offset_recovered() -> None:
    c = 331.3 * math.sqrt(1.0 + 28.0 / 273.15)
    fits = [fit_static("hcsr04", _hcsr04_table(s)) for s in SEEDS]
    names = ("hcsr04.temperature_c", "distance offset δ", "speed of sound")
    _coverage([[f.estimate(n) for n in names] for f in fits], [28.0, 4.0, c])
    fit = fits[0]
    assert fit.noise == pytest.approx(6.0, rel=0.1)  # pooled over 28 × 24 degrees of freedom
    assert fit.overrides["hcsr04.mount_x_m"] == pytest.approx(
        0.333 + fit.estimate("distance offset δ").value / 1e3
    )
    assert sum(f.adequate for f in fits) >= MIN_HITS


def _ir_table(seed: int) -> RulerTable:
    # V = 0.30/(d + 0.02) + 0.10 (V, m) + 15 mV noise, read by analogRead: ⌊V·1024/5⌋; two points in the fold,
    # where the volts fall linearly to 0 at 0 m from the curve's value at 6 cm
    rng = np.random.default_rng(seed)
    d = np.concatenate([[0.02, 0.04], np.arange(0.08, 0.71, 0.04)])
    volts = np.where(d < 0.06, (0.30 / 0.08 + 0.10) * d / 0.06, 0.30 / (d + 0.02) + 0.10)
    readings = [np.floor((v + rng.normal(0.0, 0.015, 30)) * 1024 / 5.0) for v in volts]
    return table_from_readings(d * 1000, readings, quantity="distance", reading_unit="counts")


@pytest.mark.quick
def test_gp2y0a21_curve_recovered_from_analog_read_counts() -> None:
    fits = [fit_static("gp2y0a21", _ir_table(s), ARDUINO) for s in SEEDS]
    names = ("gp2y0a21.curve_a_v_m", "gp2y0a21.curve_b_m", "gp2y0a21.curve_c_v")
    _coverage([[f.estimate(n) for n in names] for f in fits], [0.30, 0.02, 0.10])
    fit = fits[0]
    assert fit.used.tolist() == [False, False] + [True] * 16
    assert fit.noise == pytest.approx(0.015, rel=0.1)  # the ADC's 4.9 mV step taken out in quadrature
    assert sum(f.adequate for f in fits) >= MIN_HITS


def _wiper(theta: np.ndarray, zero: float, travel: float, lin: float) -> np.ndarray:
    u = 0.5 + (theta - zero) / travel
    return 5.0 * (u + lin * np.sin(2.0 * np.pi * u))


@pytest.mark.quick
def test_potentiometer_zero_and_travel_over_a_beams_swing() -> None:
    # a 300° pot, its level 30 mrad off, the linearity error at the parameters' 2 %, ±40° of beam
    rng = np.random.default_rng(7)
    theta = np.radians(np.arange(-40.0, 41.0, 5.0))
    volts = _wiper(theta, 0.03, math.radians(300.0), 0.02)
    readings = [np.floor((v + rng.normal(0.0, 0.004, 20)) * 1024 / 5.0) for v in volts]
    table = table_from_readings(theta, readings, quantity="angle", reading_unit="counts")
    fit = fit_static("potentiometer", table, ARDUINO)
    _inside(fit.estimate("potentiometer.zero_angle_rad"), 0.03)
    _inside(fit.estimate("potentiometer.electrical_travel_rad"), math.radians(300.0))
    assert "linearity error is held" in fit.notes[0]
    assert fit.adequate


@pytest.mark.quick
def test_potentiometer_linearity_over_a_wide_sweep() -> None:
    # ±150° of a 330° track (91 % of it): the sine's shape separates the linearity (5 %) from the travel
    rng = np.random.default_rng(8)
    theta = np.radians(np.arange(-150.0, 151.0, 10.0))
    volts = _wiper(theta, -0.02, math.radians(330.0), 0.05)
    readings = [np.floor((v + rng.normal(0.0, 0.004, 20)) * 1024 / 5.0) for v in volts]
    table = table_from_readings(theta, readings, quantity="angle", reading_unit="counts")
    fit = fit_static("potentiometer", table, ARDUINO)
    _inside(fit.estimate("potentiometer.zero_angle_rad"), -0.02)
    _inside(fit.estimate("potentiometer.electrical_travel_rad"), math.radians(330.0))
    _inside(fit.estimate("potentiometer.linearity_error"), 0.05)


def _as5600_readings(seed: int) -> tuple[np.ndarray, list[np.ndarray]]:
    # the level beam at 6.2 rad of the magnet: counts (6.2 + θ)·4096/2π mod 4096 cross 4095 → 0 within ±20°
    rng = np.random.default_rng(seed)
    theta = np.radians(np.arange(-20.0, 21.0, 2.5))
    return theta, [
        np.mod(np.round((6.2 + x) * 4096 / (2 * math.pi) + rng.normal(0.0, 1.0, 10)), 4096) for x in theta
    ]


@pytest.mark.quick
def test_as5600_magnet_angle_across_the_wrap() -> None:
    fits = []
    for seed in SEEDS:
        theta, readings = _as5600_readings(seed)
        fits.append(
            fit_static(
                "as5600", table_from_readings(theta, readings, quantity="angle", reading_unit="counts")
            )
        )
    theta, readings = _as5600_readings(0)
    assert min(min(r) for r in readings) < 100 and max(max(r) for r in readings) > 4000
    _coverage([[f.estimate("as5600.magnet_angle_at_level_rad")] for f in fits], [6.2])
    fit = fits[0]
    # σ of a reading √(1 + 1/12) counts less the count's quantization: 1 count = 1.534 mrad
    assert fit.estimate("as5600.noise_rms_rad").value == pytest.approx(2 * math.pi / 4096, rel=0.1)


# --- Open Ball & Beam's VL53L0X against true distance --------------------------------------------------------

# github.com/TSummersLab/open-ball-beam, ballbeam/calibration/sensor_calibration_data.txt (commit 58cb136), as
# its sketch ballbeam/arduino/sensor_calibration/sensor_calibration.ino printed it: per true distance (mm, along
# the 210 mm of exposed rod from the sensor's end: hardware_configurator.py DISTANCE_MID = 105), 20 readings of
# readRangeContinuousMillimeters() 100 ms apart, timing budget 20 ms. The Delrin ball is 38.1 mm across.
OBB_READINGS_MM: dict[int, tuple[int, ...]] = {
    14: (26, 27, 31, 29, 24, 24, 32, 30, 33, 29, 27, 25, 29, 25, 27, 29, 24, 28, 34, 29),
    30: (53, 46, 50, 50, 46, 50, 43, 45, 47, 54, 47, 47, 49, 49, 46, 47, 46, 48, 47, 46),
    40: (56, 58, 58, 58, 55, 54, 60, 59, 60, 58, 61, 62, 62, 57, 63, 58, 61, 62, 63, 58),
    50: (71, 75, 78, 72, 72, 70, 75, 70, 70, 73, 72, 72, 73, 70, 73, 71, 73, 70, 73, 67),
    60: (78, 85, 80, 84, 80, 83, 80, 86, 82, 82, 83, 83, 82, 79, 86, 87, 86, 83, 77, 85),
    70: (89, 90, 85, 93, 91, 94, 90, 95, 89, 92, 89, 97, 92, 92, 92, 91, 94, 93, 93, 92),
    80: (98, 102, 104, 104, 105, 102, 101, 105, 106, 106, 102, 109, 103, 109, 105, 104, 105, 103, 100, 104),
    90: (119, 121, 118, 118, 116, 117, 116, 117, 119, 119, 113, 118, 119, 115, 117, 117, 116, 118, 119, 116),
    100: (132, 129, 135, 136, 132, 135, 133, 131, 132, 134, 133, 132, 134, 136, 137, 131, 132, 136, 133, 132),
    105: (141, 143, 143, 143, 138, 143, 139, 145, 142, 142, 139, 145, 140, 141, 144, 148, 141, 145, 140, 144),
    110: (152, 148, 157, 154, 155, 155, 152, 152, 152, 155, 151, 153, 157, 156, 153, 155, 154, 152, 152, 153),
    120: (176, 171, 178, 170, 179, 174, 175, 173, 178, 177, 177, 174, 173, 174, 173, 170, 179, 172, 172, 173),
    130: (201, 202, 203, 202, 202, 208, 200, 198, 205, 204, 205, 197, 204, 200, 198, 199, 205, 197, 199, 203),
    140: (220, 223, 220, 221, 223, 219, 215, 218, 223, 225, 219, 220, 226, 220, 224, 224, 219, 222, 220, 218),
    150: (240, 241, 240, 244, 241, 240, 241, 243, 241, 243, 243, 244, 239, 240, 243, 239, 239, 238, 246, 238),
    160: (256, 253, 256, 254, 259, 254, 256, 262, 253, 254, 258, 259, 256, 259, 253, 259, 259, 253, 256, 260),
    170: (269, 269, 272, 270, 270, 268, 270, 270, 267, 267, 265, 270, 270, 267, 271, 266, 264, 267, 271, 263),
    196: (282, 289, 287, 291, 290, 292, 289, 285, 287, 292, 290, 293, 289, 291, 293, 289, 289, 292, 289, 287),
}
# Each distance's mean reading and sample deviation, computed here from the readings.
OBB_MEAN_MM = np.array([np.mean(v) for v in OBB_READINGS_MM.values()])
OBB_SD_MM = np.array([np.std(v, ddof=1) for v in OBB_READINGS_MM.values()])
OBB_BUDGET = Parameters().with_overrides({"vl53l0x.timing_budget_s": 0.020})


@pytest.fixture(scope="module")
def obb_table() -> RulerTable:
    d = list(OBB_READINGS_MM)
    return table_from_readings(
        d, [OBB_READINGS_MM[k] for k in d], quantity="distance", reading_unit="mm", source="open-ball-beam"
    )


@pytest.mark.quick
def test_obb_table_is_the_published_one(obb_table: RulerTable) -> None:
    # 14 mm → 28.1 mm (sd 2.97), 196 mm → 289.3 mm (sd 2.75): the readings' own means and deviations
    assert obb_table.reading.tolist() == pytest.approx(OBB_MEAN_MM.tolist(), abs=1e-12)
    assert (OBB_MEAN_MM[0], OBB_MEAN_MM[-1]) == pytest.approx((28.1, 289.3), abs=1e-9)
    assert obb_table.sd is not None and obb_table.sd.tolist() == pytest.approx(OBB_SD_MM.tolist(), abs=1e-12)
    assert (round(OBB_SD_MM[0], 2), round(OBB_SD_MM[-1], 2)) == (2.97, 2.75)
    assert obb_table.n.tolist() == [20.0] * 18


@pytest.mark.quick
def test_obb_vl53l0x_is_not_offset_only(obb_table: RulerTable) -> None:
    fit = fit_static("vl53l0x", obb_table, OBB_BUDGET)
    # the part's range = d − crosstalk, weighted by the means' standard errors: crosstalk is the weighted mean
    # of d − reading, computed here independently
    d, r = np.array(list(OBB_READINGS_MM), dtype=float), OBB_MEAN_MM
    w = 20.0 / np.square(OBB_SD_MM)
    crosstalk = float(np.sum(w * (d - r)) / np.sum(w))
    assert fit.estimate("vl53l0x.crosstalk_offset_mm").value == pytest.approx(crosstalk, abs=1e-6)
    assert crosstalk == pytest.approx(-47.0, abs=0.05)  # the readings run long by 47 mm on average …
    # … but by 14 mm at 14 mm and 93 mm at 196 mm: residuals (model − mean reading) from +33 mm to −51 mm
    assert fit.residuals[0] == pytest.approx(32.9, abs=0.05)
    assert fit.residuals.min() == pytest.approx(-51.3, abs=0.05)
    assert fit.rms == pytest.approx(30.5, abs=0.05)
    assert fit.chi2_dof > 1000 and not fit.adequate
    # a free gain: weighted least squares of reading on d (numpy's polyfit, weights 1/standard error)
    gain, offset = np.polyfit(d, r, 1, w=np.sqrt(w))
    line = fit.alternative("line")
    assert line.estimates[0].value == pytest.approx(gain, rel=1e-7)
    assert line.estimates[1].value == pytest.approx(offset, abs=1e-5)
    assert (round(gain, 3), round(line.rms, 1)) == (1.589, 11.0)
    assert not line.adequate  # still 11 mm RMS against means known to ±0.6 mm: an S-shaped residual
    # … in four runs of one sign (predicted − measured: −18 mm at 14 mm, +13 mm at 90-100, −15 mm at 150, +10 mm
    # at 196): the round ball's returns bend the curve twice, which no gain or offset straightens
    assert 1 + np.count_nonzero(np.diff(np.sign(line.residuals))) == 4
    assert (round(line.residuals[0], 1), round(line.residuals[8], 1), round(line.residuals[-1], 1)) == (
        -18.4,
        13.1,
        9.6,
    )
    assert fit.alternative("cubic").rms == pytest.approx(6.4, abs=0.05)
    assert not fit.alternative("cubic").adequate
    # the measured curve interpolated between neighbours: 1.77 mm RMS by leave-one-out over the 16 interior
    curve = fit.alternative("measured-curve")
    assert curve.rms == pytest.approx(1.77, abs=0.01)
    assert "the part needs a measured curve" in fit.notes[-1]


@pytest.mark.quick
def test_obb_vl53l0x_noise_is_a_floor_not_proportional(obb_table: RulerTable) -> None:
    fit = fit_static("vl53l0x", obb_table, OBB_BUDGET)
    # the deviations (1.8 … 3.1 mm) do not grow ×14 from 14 to 196 mm as the part's σ = k·d·√(33/20) would
    floor = fit.estimate("noise floor σ₀ (constant)")
    assert 2.26 < floor.value < 2.67 and floor.low < 2.46 < floor.high
    assert "vl53l0x.sigma_fraction" not in fit.overrides
    assert "the part's noise law does not hold this table" in fit.notes[0]


# --- files: the table in, the rig-description table out ------------------------------------------------------


@pytest.mark.quick
def test_a_csv_of_single_readings_pools_replicates(tmp_path: Path) -> None:
    path = tmp_path / "ruler.csv"
    path.write_text(
        "\ufeffdistance_cm,reading_us\n# a comment\n3,190\n3,192\r\n5,307\r\n7,423\n7,425\n", "utf-8"
    )
    table = load_ruler_table(path)
    assert table.true.tolist() == [30.0, 50.0, 70.0]
    assert table.reading.tolist() == [191.0, 307.0, 424.0]
    assert table.n.tolist() == [2.0, 1.0, 2.0]
    assert table.lines == (3, 5, 6)


@pytest.mark.quick
@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("distance_mm,reading_mm\n10,abc\n", "line 2, column reading_mm: 'abc' is not a number"),
        ("distance_mm,reading_mm\n10,nan\n", "line 2, column reading_mm: 'nan' is not finite"),
        ("distance_mm,reading_mm\n10,12,3\n", "line 2: 3 cells, the header has 2"),
        ("position,volts\n1,2\n", "line 1: header 'position,volts' needs a true column"),
        ("distance_mm,reading_mm,colour\n1,2,3\n", "line 1: unknown column 'colour'"),
        ("distance_mm,reading_mm,sd_mm,n\n20,20,1,5\n10,12,1,5\n", "line 3, column distance_mm: true values"),
    ],
)
def test_a_bad_table_is_refused_naming_the_line_and_column(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "t.csv"
    path.write_text(text, "utf-8")
    with pytest.raises(StaticFitError, match=message):
        load_ruler_table(path)


@pytest.mark.quick
def test_a_binary_table_and_a_wrong_part(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    path.write_bytes(b"distance_mm,reading_mm\n\x00\x01\n")
    with pytest.raises(StaticFitError, match="a NUL byte"):
        load_ruler_table(path)
    table = ruler_table([10, 20, 30], [1, 2, 3], quantity="distance", reading_unit="mm")
    with pytest.raises(StaticFitError, match="hcsr04's reading is in us on its board, the table's in mm"):
        fit_static("hcsr04", table)
    with pytest.raises(StaticFitError, match="potentiometer is fitted against a angle"):
        fit_static("potentiometer", table)
    with pytest.raises(StaticFitError, match="the static fit knows vl53l0x, hcsr04"):
        fit_static("camera", table)


@pytest.mark.quick
def test_a_fit_beyond_its_fields_bounds_is_refused() -> None:
    table = ruler_table([50, 100, 150, 200], [200, 250, 300, 350], quantity="distance", reading_unit="mm")
    with pytest.raises(StaticFitError) as info:
        fit_static("vl53l0x", table)
    assert "vl53l0x.crosstalk_offset_mm = -150.0 mm is impossible: it must be >= -100.0" in str(info.value)


@pytest.mark.quick
def test_the_parameter_file_loads_as_a_rig_description(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    c = 331.3 * math.sqrt(1.0 + 15.0 / 273.15)
    d = np.arange(50.0, 251.0, 25.0)
    readings = [np.floor(2.0 * x * 1e-3 / c * 1e6 + rng.normal(0.0, 5.0, 10)) for x in d]
    fit = fit_static("hcsr04", table_from_readings(d, readings, quantity="distance", reading_unit="us"))
    out = tmp_path / "hcsr04.toml"
    write_static_fit(fit, out)
    rig = rig_from_text(out.read_text("utf-8"), origin=str(out))
    assert rig.parts.ball_sensor == "hcsr04"
    assert rig.group("hcsr04").temperature_c == fit.overrides["hcsr04.temperature_c"]
    assert rig.group("hcsr04").echo_jitter_us == fit.overrides["hcsr04.echo_jitter_us"]
    with pytest.raises(FileExistsError):
        write_static_fit(fit, out)


@pytest.mark.quick
def test_calibrate_static_sensor_from_the_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from twin.app.cli import main

    # echo widths of a ball 30, 50, 70, 90 mm away at 20 °C (2d/343.2 m/s − ½ µs: 174.3, 290.9, 407.4, 524.0)
    table = tmp_path / "ruler.csv"
    table.write_text("distance_mm,reading_us\n30,174\n30,175\n50,291\n70,407\n70,408\n90,524\n", "utf-8")
    out = tmp_path / "hcsr04.toml"
    assert main(["calibrate-static", str(table), "--sensor", "hcsr04", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith(f"hcsr04 (ball_sensor), {table}: 4 points, echo = 2(d + δ)/c(T) − ½ µs")
    rig = rig_from_text(out.read_text("utf-8"), origin=str(out))
    assert rig.group("hcsr04").temperature_c == pytest.approx(20.0, abs=3.0)
    assert (
        main(["calibrate-static", str(table), "--sensor", "hcsr04", "--out", str(out)]) == 2
    )  # no --overwrite
    assert main(["calibrate-static", str(table), "--sensor", "vl53l0x"]) == 2
    assert "vl53l0x's reading is in mm on its board, the table's in us" in capsys.readouterr().err


@pytest.mark.quick
def test_every_parts_file_loads_with_its_fitted_values(tmp_path: Path) -> None:
    theta, readings = _as5600_readings(1)
    pot_theta = np.radians(np.arange(-40.0, 41.0, 5.0))
    pot = [np.floor(_wiper(np.array([x]), 0.03, math.radians(300.0), 0.02) * 1024 / 5.0) for x in pot_theta]
    fits = [
        fit_static(
            "vl53l0x", _vl53l0x_table(1), Parameters().with_overrides({"vl53l0x.timing_budget_s": 0.020})
        ),
        fit_static("hcsr04", _hcsr04_table(1)),
        fit_static("gp2y0a21", _ir_table(1), ARDUINO),
        fit_static(
            "potentiometer",
            table_from_readings(pot_theta, pot, quantity="angle", reading_unit="counts"),
            ARDUINO,
        ),
        fit_static("as5600", table_from_readings(theta, readings, quantity="angle", reading_unit="counts")),
    ]
    for fit in fits:
        path = tmp_path / f"{fit.part}.toml"
        write_static_fit(fit, path)
        rig = rig_from_text(path.read_text("utf-8"), origin=str(path))
        assert getattr(rig.parts, fit.role) == fit.part
        for name, value in fit.overrides.items():
            group, _, attr = name.partition(".")
            assert getattr(rig.group(group), attr) == value, name
