"""Static calibration of the two sensors (calib/static.py): Table 6.3 → eq 6.3.1, eq 6.2.4 → eq 6.2.6."""

import json
from pathlib import Path

import numpy as np
import pytest
from thesis_data import TABLE_6_3_POSITION_M, TABLE_6_3_VOLTAGE_V

from calib.static import (
    TABLES_DIR,
    BallCalibration,
    DacCalibration,
    TableError,
    calibrate,
    calibrate_ball,
    calibrate_dac,
    load_table,
)
from calib.static_render import render_lines, render_toml
from twin.parameters import Parameters

X, V = TABLE_6_3_POSITION_M, TABLE_6_3_VOLTAGE_V
# Eq 6.2.4: the DAC's measured output at three counter values.
EQ_6_2_4_DI = np.array([0.0, 512.0, 1023.0])
EQ_6_2_4_VOLTS_V = np.array([-5.042, -0.014, 5.002])


@pytest.fixture(scope="module")
def ball() -> BallCalibration:
    return calibrate_ball(X, V, source="Table 6.3")


@pytest.fixture(scope="module")
def dac() -> DacCalibration:
    return calibrate_dac(EQ_6_2_4_DI, EQ_6_2_4_VOLTS_V, source="eq 6.2.4")


# --- the example tables ---------------------------------------------------------------------------------


@pytest.mark.quick
def test_shipped_tables_are_the_thesis_numbers():
    t = load_table(TABLES_DIR / "table_6_3.csv")
    assert t.kind == "ball" and t.columns == ("position_m", "volts_v")
    np.testing.assert_array_equal(t.inputs, X)
    np.testing.assert_array_equal(t.volts_v, V)
    assert t.lines[0] == 2 and t.lines[-1] == 24
    d = load_table(TABLES_DIR / "eq_6_2_4.csv")
    assert d.kind == "dac"
    np.testing.assert_array_equal(d.inputs, EQ_6_2_4_DI)
    np.testing.assert_array_equal(d.volts_v, EQ_6_2_4_VOLTS_V)


# --- which fit is eq 6.3.1 --------------------------------------------------------------------------------


@pytest.mark.quick
def test_least_squares_over_the_21_interior_points_reproduces_eq_6_3_1(ball: BallCalibration):
    # Independently: x on V and V on x (inverted) over the 21 interior points, and over all 23.
    gain, offset = np.polyfit(V[1:-1], X[1:-1], 1)
    assert (f"{gain:.4f}", f"{offset:.4f}") == ("0.0693", "0.0018")
    assert gain == pytest.approx(0.0692523, abs=1e-7) and offset == pytest.approx(0.0017999, abs=1e-7)
    slope, intercept = np.polyfit(X[1:-1], V[1:-1], 1)
    assert (f"{1 / slope:.4f}", f"{-intercept / slope:.4f}") == ("0.0693", "0.0018")
    for g, o in (
        np.polyfit(V, X, 1),
        (1 / np.polyfit(X, V, 1)[0], -np.polyfit(X, V, 1)[1] / np.polyfit(X, V, 1)[0]),
    ):
        assert (f"{g:.4f}", f"{o:.4f}") == ("0.0694", "0.0017")  # with the end points: not the printed line

    found = {(f.regression, f.points): (f, ball.reproduces_software(f)) for f in ball.candidates}
    assert found[("x_on_v", "interior")][1] == (True, True)
    assert found[("v_on_x", "interior")][1] == (True, True)
    assert found[("x_on_v", "all")][1] == (False, False)
    assert found[("v_on_x", "all")][1] == (False, False)
    fit = found[("x_on_v", "interior")][0]
    assert fit.n_points == 21
    assert fit.gain_m_per_v == pytest.approx(gain, rel=1e-12)
    assert fit.offset_m == pytest.approx(offset, rel=1e-9)
    assert (ball.line.regression, ball.line.points) == ("x_on_v", "interior")


@pytest.mark.quick
def test_residuals_of_eq_6_3_1_and_of_the_refit(ball: BallCalibration):
    eq_6_3_1 = 0.0693 * V + 0.0018 - X
    np.testing.assert_allclose(ball.software_residuals_m.values, eq_6_3_1, atol=1e-15)
    assert ball.software_residuals_m.rms == pytest.approx(np.sqrt(np.mean(eq_6_3_1**2)), rel=1e-12)
    assert ball.software_residuals_m.rms == pytest.approx(2.31e-3, abs=0.01e-3)
    assert ball.software_residuals_m.max_abs == pytest.approx(7.03e-3, abs=0.01e-3)  # at 0.18 m, V = 2.470
    assert int(np.argmax(np.abs(ball.software_residuals_m.values))) == 17

    refit = np.polyval(np.polyfit(V[1:-1], X[1:-1], 1), V) - X
    np.testing.assert_allclose(ball.line_residuals_m.values, refit, atol=1e-12)
    assert ball.line_residuals_m.rms == pytest.approx(2.34e-3, abs=0.01e-3)
    assert ball.line_residuals_m.max_abs == pytest.approx(7.15e-3, abs=0.01e-3)


# --- curves for the twin --------------------------------------------------------------------------------


def test_leave_one_out_compares_the_curves(ball: BallCalibration):
    # Piecewise-linear, independently: each interior point predicted from its neighbours.
    errors = [np.interp(X[i], np.delete(X, i), np.delete(V, i)) - V[i] for i in range(1, len(X) - 1)]
    piecewise = ball.curve("piecewise")
    np.testing.assert_allclose(piecewise.loo_v.values, errors, atol=1e-12)
    assert piecewise.residuals_v.max_abs == 0.0
    assert piecewise.position_m == tuple(X) and piecewise.volts_v == tuple(V)

    rms = {c.name: c.loo_v.rms for c in ball.curves}
    assert rms["piecewise"] == pytest.approx(0.0342, abs=1e-4)
    assert rms["spline-gcv"] == pytest.approx(0.0352, abs=1e-4)
    assert rms["spline-adc"] == pytest.approx(0.0288, abs=1e-4)
    assert rms["line"] == pytest.approx(0.0346, abs=1e-4)
    assert ball.recommended.name == "spline-adc"


def test_gcv_spline_is_a_straight_line_and_the_adc_spline_nearly_interpolates(ball: BallCalibration):
    # GCV finds the table's bends indistinguishable from its scatter: the spline is the least-squares line.
    gcv = ball.curve("spline-gcv")
    line = np.polyval(np.polyfit(X, V, 1), gcv.position_m)
    assert np.max(np.abs(np.array(gcv.volts_v) - line)) < 1e-5
    adc = ball.curve("spline-adc")
    assert adc.residuals_v.rms <= ball.adc_noise_v * 1.0001
    assert ball.adc_noise_v == pytest.approx(10 / 4096 / np.sqrt(12), rel=1e-12)
    for curve in (gcv, adc):
        assert len(curve.position_m) == 131
        assert set(np.round(X, 6)) <= set(curve.position_m)
        assert np.all(np.diff(curve.position_m) > 0) and np.all(np.diff(curve.volts_v) > 0)


# --- the angle chain's DAC ------------------------------------------------------------------------------


@pytest.mark.quick
def test_dac_line_against_eq_6_2_6(dac: DacCalibration):
    slope, offset = np.polyfit(EQ_6_2_4_DI, EQ_6_2_4_VOLTS_V, 1)
    assert dac.volts_per_count == pytest.approx(slope, rel=1e-12)
    assert dac.offset_v == pytest.approx(offset, rel=1e-12)
    assert (f"{dac.volts_per_count:.6f}", f"{dac.offset_v:.3f}") == ("0.009818", "-5.042")
    assert dac.reproduces_sensor(dac.volts_per_count, dac.offset_v) == (True, True)
    # Eq 6.2.6 is the line through the DI = 0 and 1023 readings: (5.002 + 5.042)/1023 = 0.00981818.
    assert dac.ends_volts_per_count == pytest.approx(10.044 / 1023, rel=1e-12)
    assert dac.ends_offset_v == pytest.approx(-5.042, abs=1e-12)
    np.testing.assert_allclose(
        dac.residuals_v.values, slope * EQ_6_2_4_DI + offset - EQ_6_2_4_VOLTS_V, atol=1e-12
    )
    assert dac.residuals_v.max_abs == pytest.approx(0.73e-3, abs=0.01e-3)
    np.testing.assert_allclose(dac.sensor_residuals_v.values, [0.0, -1.184e-3, -0.186e-3], atol=1e-9)


# --- overrides ------------------------------------------------------------------------------------------


def test_overrides_round_trip_through_parameters(ball: BallCalibration, dac: DacCalibration, tmp_path: Path):
    for curve in ball.curves:
        p = Parameters().with_overrides(ball.sensor_overrides(curve.name))
        assert p.ball_sensor.curve_position_m == curve.position_m
        assert p.ball_sensor.curve_volts_v == curve.volts_v
    assert (
        Parameters().with_overrides(ball.sensor_overrides()).ball_sensor.curve_volts_v
        == ball.recommended.volts_v
    )
    sw = Parameters().with_overrides(ball.software_overrides()).software
    assert (sw.ball_gain_m_per_v, sw.ball_offset_m) == (ball.line.gain_m_per_v, ball.line.offset_m)

    angle = Parameters().with_overrides(dac.overrides()).angle_sensor
    assert (angle.dac_volts_per_count, angle.dac_offset_v) == (dac.volts_per_count, dac.offset_v)
    soft = Parameters().with_overrides(dac.software_overrides()).software
    assert soft.angle_gain_deg_per_v == pytest.approx((360 / 256) / dac.volts_per_count, rel=1e-12)
    assert soft.angle_reference_v == pytest.approx(5.002, abs=0.5e-3)  # eq 6.2.4's reading at DI = 1023

    for result, name in ((ball, "ball.toml"), (dac, "dac.toml")):
        path = tmp_path / name
        path.write_text(render_toml(result), encoding="utf-8")
        loaded = Parameters.from_file(path)
        expected = Parameters().with_overrides(
            {**ball.software_overrides(), **ball.sensor_overrides()}
            if result is ball
            else {**dac.overrides(), **dac.software_overrides()}
        )
        assert loaded == expected


@pytest.mark.quick
def test_json_and_text(ball: BallCalibration, dac: DacCalibration):
    data = json.loads(json.dumps(ball.to_json()))
    assert data["line"]["gain_m_per_v"] == 0.0692523 and data["line"]["offset_m"] == 0.0018
    assert data["line"]["gain_rounds_to_software"] and data["line"]["offset_rounds_to_software"]
    assert data["software_residuals_m"]["max_abs"] == 0.007029  # 0.0693·2.470 + 0.0018 − 0.18
    assert data["recommended_curve"] == "spline-adc"
    assert {c["name"]: c["loo_v"]["rms"] for c in data["curves"]}["piecewise"] == 0.0342
    d = json.loads(json.dumps(dac.to_json()))
    assert d["least_squares"]["volts_per_count"] == 0.00981818 and d["through_ends"]["offset_v"] == -5.042

    text = "\n".join(render_lines(ball))
    assert "least squares x on V, interior 21 points" in text and "gain yes, offset yes" in text
    assert "predicts best: spline-adc" in text and "software.ball_gain_m_per_v = 0.0692523" in text
    text = "\n".join(render_lines(dac))
    assert (
        "0.009818·DI − 5.042 (eq 6.2.6)" in text and "angle_sensor.dac_volts_per_count = 0.009818183" in text
    )


def test_short_ball_table_falls_back_to_all_points(tmp_path: Path):
    path = tmp_path / "short.csv"
    path.write_text("position_m,volts_v\n-0.3,-4.4\n0,0\n0.3,4.3\n", encoding="utf-8")
    result = calibrate(load_table(path))
    assert isinstance(result, BallCalibration)
    assert result.line.points == "all" and [c.name for c in result.curves] == ["piecewise", "line"]
    assert result.curve("piecewise").loo_v is not None and result.curve("line").loo_v is not None
    render_lines(result)
    json.dumps(result.to_json())


# --- bad tables -----------------------------------------------------------------------------------------


def _write(tmp_path: Path, content: str | bytes) -> Path:
    path = tmp_path / "t.csv"
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")
    return path


def _error(path: Path) -> str:
    with pytest.raises(TableError) as info:
        load_table(path)
    assert isinstance(info.value, ValueError)
    assert str(path) in str(info.value)
    return str(info.value)


def test_missing_file(tmp_path: Path):
    assert "cannot read" in _error(tmp_path / "nope.csv")


@pytest.mark.parametrize("bom", [b"", b"\xef\xbb\xbf"])
def test_not_utf8(tmp_path: Path, bom: bytes):
    message = _error(_write(tmp_path, bom + b"position_m,volts_v\n0.0,1.0\n0.1,\xff2\n"))
    assert "line 3" in message and "not UTF-8" in message and "0xff" in message


def test_empty(tmp_path: Path):
    assert "empty" in _error(_write(tmp_path, "\n  \n"))


@pytest.mark.quick
def test_unknown_header(tmp_path: Path):
    message = _error(_write(tmp_path, "x,v\n0,0\n"))
    assert "line 1" in message and "unknown header 'x,v'" in message and "position_m,volts_v" in message


@pytest.mark.parametrize("cell", ["nan", "inf", "-Infinity"])
def test_non_finite_cell(tmp_path: Path, cell: str):
    message = _error(_write(tmp_path, f"position_m,volts_v\n-0.1,-1\n0.0,{cell}\n0.1,1\n"))
    assert "line 3, column volts_v" in message and "not a finite number" in message


def test_non_number_cell(tmp_path: Path):
    message = _error(_write(tmp_path, "position_m,volts_v\n-0.1,-1\nzero,0\n0.1,1\n"))
    assert "line 3, column position_m" in message and "'zero' is not a number" in message


def test_decimal_comma(tmp_path: Path):
    message = _error(_write(tmp_path, "position_m,volts_v\n-0,30,-4.41\n"))
    assert "line 2" in message and "3 cells" in message and "decimal comma" in message


def test_too_few_ball_rows(tmp_path: Path):
    message = _error(_write(tmp_path, "position_m,volts_v\n-0.1,-1\n0.1,1\n"))
    assert "line 3, column position_m" in message and "2 data rows" in message and "at least 3" in message


def test_too_few_dac_rows(tmp_path: Path):
    message = _error(_write(tmp_path, "di,volts_v\n0,-5.042\n"))
    assert "line 2, column di" in message and "1 data rows" in message and "at least 2" in message


def test_positions_not_increasing(tmp_path: Path):
    message = _error(_write(tmp_path, "position_m,volts_v\n-0.1,-1\n0.1,1\n0.1,1.1\n0.2,2\n"))
    assert "line 4, column position_m" in message and "line 3" in message and "increase strictly" in message


def test_duplicate_di(tmp_path: Path):
    message = _error(_write(tmp_path, "di,volts_v\n0,-5.0\n512,0.0\n0,-5.1\n"))
    assert "line 4, column di" in message and "DI 0 repeats line 2" in message


def test_di_not_a_counter_value(tmp_path: Path):
    message = _error(_write(tmp_path, "di,volts_v\n0,-5.0\n511.5,0.0\n"))
    assert "line 3, column di" in message and "0…1023" in message


def test_bom_and_blank_lines_are_accepted_and_the_file_is_not_modified(tmp_path: Path):
    content = "\ufeffDI,volts_v\r\n0,-5.042\r\n\r\n512,-0.014\r\n1023,5.002\r\n\r\n".encode()
    path = _write(tmp_path, content)
    before = path.stat().st_mtime_ns
    table = load_table(path)
    assert table.kind == "dac" and table.inputs == (0.0, 512.0, 1023.0) and table.lines == (2, 4, 5)
    assert path.read_bytes() == content and path.stat().st_mtime_ns == before


def test_falling_volts_are_refused():
    with pytest.raises(TableError, match="volts fall as the position rises"):
        calibrate_ball(X, -V, source="reversed")
