"""Parameters: thesis values, derived geometry, validation, files."""

import json
import math

import pytest

from twin.parameters import ParameterError, Parameters


def test_derived_values_follow_the_thesis(params: Parameters) -> None:
    # r* = sqrt(r^2 - d^2/4) with Table 3.1's r and d: 4.676 mm (Table 3.1 misprints 4.264 mm).
    assert params.rolling_radius_m == pytest.approx(4.676e-3, abs=0.5e-6)
    # eq 3.3.2: tau = 0.016383 (V - 0.154 thetadot)
    assert params.motor.torque_per_volt_nm_per_v == pytest.approx(0.016383, rel=1e-4)
    assert params.motor.backemf_at_beam_v_s_per_rad == pytest.approx(0.154, rel=1e-12)
    # eq 3.1.21 with Table 3.1: J = 2/5 m r^2 = 5.23e-7 kg m^2 (not Table 3.1's 0.455e-6)
    assert params.ball.inertia_kgm2 == pytest.approx(5.23e-7, rel=1e-3)
    assert params.beam.stop_angle_rad == pytest.approx(math.radians(43.4))
    assert params.daq.block_size == 800


@pytest.mark.parametrize(
    ("override", "fragment"),
    [
        ({"ball.mass_kg": 0.0}, "ball.mass_kg = 0.0"),
        ({"ball.mass_kg": -1.0}, "ball.mass_kg = -1.0"),
        ({"ball.radius_m": float("nan")}, "ball.radius_m = nan"),
        ({"track.contact_spacing_m": 0.017}, "track.contact_spacing_m = 0.017"),
        ({"beam.inertia_pivot_kgm2": 1e-6}, "beam.inertia_pivot_kgm2 = 1e-06"),
        ({"beam.stop_angle_rad": 2.0}, "beam.stop_angle_rad = 2.0"),
        ({"physics.contact_timeconst_s": 1e-3}, "physics.contact_timeconst_s = 0.001"),
        ({"motor.resistance_ohm": "9.4"}, "motor.resistance_ohm = '9.4'"),
        ({"ball.colour": 1.0}, "ball.colour"),
        ({"wheel": {"mass_kg": 1.0}}, "wheel"),
        ({"daq.output_latency_s": 0.05}, "daq.output_latency_s = 0.05"),
        ({"ball_sensor.noise_enabled": 1}, "ball_sensor.noise_enabled = 1"),
    ],
)
def test_impossible_values_are_refused_by_name(override: dict, fragment: str) -> None:
    with pytest.raises(ParameterError) as err:
        Parameters().with_overrides(override)
    assert fragment in str(err.value)


def test_overrides_from_code_keep_everything_else(params: Parameters) -> None:
    heavier = params.with_overrides({"ball": {"mass_kg": 0.02}, "motor.resistance_ohm": 10.0})
    assert heavier.ball.mass_kg == 0.02
    assert heavier.motor.resistance_ohm == 10.0
    assert heavier.ball.radius_m == params.ball.radius_m
    assert params.ball.mass_kg == 18.848e-3  # the original is untouched


def test_files_round_trip_and_are_not_overwritten(tmp_path, params: Parameters) -> None:
    changed = params.with_overrides({"beam.cog_height_m": 0.011, "ball_sensor.noise_enabled": False})
    for name in ("p.toml", "p.json"):
        path = tmp_path / name
        changed.save(path)
        assert Parameters.from_file(path) == changed
        before = path.read_bytes()
        with pytest.raises(FileExistsError, match=name):
            params.save(path)
        assert path.read_bytes() == before


def test_partial_file_overrides_only_what_it_names(tmp_path) -> None:
    path = tmp_path / "rig.toml"
    path.write_text("[ball]\nmass_kg = 0.0191\n")
    loaded = Parameters.from_file(path)
    assert loaded.ball.mass_kg == 0.0191
    assert loaded.beam == Parameters().beam


@pytest.mark.parametrize(
    ("name", "text", "fragment"),
    [
        ("bad.toml", "[ball\nmass_kg = 1", "not a valid TOML file"),
        ("bad.json", "{", "not a valid JSON file"),
        ("neg.toml", "[ball]\nmass_kg = -2.0\n", "ball.mass_kg = -2.0"),
        ("unknown.json", json.dumps({"ball": {"mas_kg": 1.0}}), "unknown parameter 'ball.mas_kg'"),
        ("list.json", "[1, 2]", "expected a table"),
    ],
)
def test_bad_files_name_the_file_and_the_field(tmp_path, name: str, text: str, fragment: str) -> None:
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ParameterError) as err:
        Parameters.from_file(path)
    assert str(path) in str(err.value)
    assert fragment in str(err.value)


def test_missing_file_is_reported(tmp_path) -> None:
    with pytest.raises(ParameterError, match="cannot read"):
        Parameters.from_file(tmp_path / "absent.toml")


def test_every_parameter_has_a_unit_and_a_source() -> None:
    rows = Parameters.describe()
    assert len(rows) > 30
    for row in rows:
        assert row["unit"] and row["source"], row["name"]
