"""Parameters: thesis values, derived geometry, validation, files."""

import dataclasses
import json
import math
import time
from pathlib import Path

import pytest

from twin.parameters import GROUPS, MAX_FILE_BYTES, READING, ParameterError, Parameters, PartNames, all_groups


@pytest.mark.quick
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


@pytest.mark.quick
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


def test_fitted_values_by_name_fold_the_ball_reading_into_the_curve(params: Parameters) -> None:
    """``with_values``: the parameters' names as ``with_overrides``; the ball reading's gain and offset
    (``READING``) change the sensor curve so that eq 6.3.1 reads g·(before) + b, bit for bit as numpy does it."""
    import numpy as np

    from twin.converters import ball_position_m

    out = params.with_values(
        {"motor.resistance_ohm": 10.0, "ball_reading.gain": 1.1, "ball_reading.offset_m": 0.002}
    )
    sw = params.software
    read = ball_position_m(np.asarray(params.ball_sensor.curve_volts_v), sw)
    expected = ((1.1 * read + 0.002) - sw.ball_offset_m) / sw.ball_gain_m_per_v
    assert list(out.ball_sensor.curve_volts_v) == expected.tolist()
    assert out.motor.resistance_ohm == 10.0 and out.software == sw
    assert params.with_values({"ball_reading.gain": 1.0, "ball_reading.offset_m": 0.0}) == params
    assert {"ball_reading.gain", "ball_reading.offset_m"} == set(READING)
    with pytest.raises(ParameterError, match="calibration: unknown parameter 'ball_reading.gian'"):
        params.with_values({"ball_reading.gian": 1.1})
    with pytest.raises(ParameterError, match="fit: unknown parameter 'motor.resistnce_ohm'"):
        params.with_values({"motor.resistnce_ohm": 10.0}, origin="fit")


@pytest.mark.quick
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


@pytest.mark.quick
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


@pytest.mark.quick
def test_every_parameter_has_a_unit_and_a_source() -> None:
    rows = Parameters.describe()
    # One row per field of every group, in the order the dataclasses declare them.
    defaults = Parameters()
    expected = [
        f"{group.name}.{f.name}"
        for group in dataclasses.fields(Parameters)
        if group.name != "part_groups"  # the parts' own groups: registered, listed after the table's
        for f in dataclasses.fields(getattr(defaults, group.name))
    ] + [
        f"{name}.{f.name}"
        for name, cls in all_groups().items()
        if name not in GROUPS
        for f in dataclasses.fields(cls)
    ]
    assert [row["name"] for row in rows] == expected
    for row in rows:
        assert row["unit"] and row["source"], row["name"]


# --- issue "Parameters accepted that cannot be" --------------------------------------------------------------

# The defaults as they were before bounds and integer fields were added: adding bounds must not move one.
THESIS_DEFAULTS = {
    "ball": {"mass_kg": 0.018848, "radius_m": 0.008329},
    "beam": {
        "mass_kg": 0.13678,
        "inertia_pivot_kgm2": 0.004,
        "cog_height_m": 0.0102,
        "stop_angle_rad": math.radians(43.4),
        "pivot_damping_nm_s_per_rad": 0.0,
        "pivot_friction_nm": 0.0,
        "track_offset_m": 0.0,
        "cog_along_m": 0.0,
    },
    "track": {
        "contact_height_m": 0.017281,
        "contact_spacing_m": 0.013785,
        "half_length_m": 0.323,
        "wire_radius_m": 0.001,
        "friction": 1.0,
    },
    "motor": {
        "resistance_ohm": 9.4,
        "torque_constant_nm_per_a": 0.022,
        "backemf_constant_v_s_per_rad": 0.022,
        "gear_ratio": 7.0,
        "rotor_inertia_kgm2": 8.5e-07,
        "viscous_damping_nm_s_per_rad": 4e-07,
        "inductance_h": 0.0008,
        "continuous_current_a": 0.76,
    },
    "amplifier": {"gain_v_per_v": 9.6, "zero_command_v": 2.5, "rail_v": 12.0},
    "physics": {
        "gravity_m_s2": 9.81,
        "timestep_s": 0.001,
        "contact_timeconst_s": 0.002,
        "contact_impedance": 0.99,
        "contact_margin_m": 3.495e-07,
    },
    "angle_sensor": {
        "encoder_pulses_per_rev": 256,
        "counter_bits": 10,
        "counter_zero_count": 512,
        "dac_volts_per_count": 0.009818,
        "dac_offset_v": -5.042,
        "zeroing_error_rad": 0.0,
    },
    "ball_sensor": {
        "curve_position_m": (
            -0.323, -0.3, -0.27, -0.24, -0.21, -0.18, -0.15, -0.12, -0.09, -0.06, -0.03, 0.0,
            0.03, 0.06, 0.09, 0.12, 0.15, 0.18, 0.21, 0.24, 0.27, 0.3, 0.323,
        ),
        "curve_volts_v": (
            -4.62, -4.41, -3.925, -3.46, -3.045, -2.62, -2.17, -1.747, -1.325, -0.895, -0.487, 0.0012,
            0.428, 0.84, 1.28, 1.716, 2.113, 2.47, 3.0, 3.46, 3.89, 4.34, 4.6,
        ),
        "rc_resistance_ohm": 147.0,
        "rc_capacitance_f": 2.2e-05,
        "dropout_rate_hz": 5.0,
        "dropout_mean_duration_s": 0.0005,
        "dropout_voltage_v": 0.0,
        "noise_enabled": True,
    },
    "daq": {
        "sample_rate_hz": 40000.0,
        "period_s": 0.02,
        "adc_bits": 12,
        "adc_min_v": -5.0,
        "adc_max_v": 5.0,
        "dac_bits": 12,
        "dac_min_v": 0.0,
        "dac_max_v": 5.0,
        "output_latency_s": 0.0,
    },
    "software": {
        "ball_gain_m_per_v": 0.0693,
        "ball_offset_m": 0.0018,
        "angle_gain_deg_per_v": 143.22657649,
        "angle_reference_v": 5.002,
        "angle_reference_motor_deg": 718.59375,
        "angle_gear_ratio": 7.0,
        "software_pi": 3.141592654,
        "command_gain_v_per_v": 9.6,
        "command_zero_v": 2.5,
        "command_low_v": 1.25,
        "command_high_v": 3.75,
    },
    "start": {"free_run_s": 0.01},
    "mcu_io": {
        "input_gain_v_per_v": 0.5,
        "input_offset_v": 2.5,
        "adc_bits": 10,
        "adc_reference_v": 5.0,
        "dac_bits": 12,
        "dac_reference_v": 5.0,
        "clock_hz": 16_000_000,
    },
}  # fmt: skip

INTEGER_FIELDS = (
    "daq.adc_bits",
    "daq.dac_bits",
    "mcu_io.adc_bits",
    "mcu_io.dac_bits",
    "mcu_io.clock_hz",
    "angle_sensor.counter_bits",
    "angle_sensor.counter_zero_count",
    "angle_sensor.encoder_pulses_per_rev",
)


def _group_fields() -> list[tuple[str, dataclasses.Field]]:
    """Every field of every group: the table's, ``parts`` and the parts' registered groups."""
    return [
        (f"{group}.{f.name}", f)
        for group in [*Parameters().to_dict(), *(g for g in all_groups() if g not in GROUPS)]
        for f in dataclasses.fields(Parameters().group(group))
    ]


@pytest.mark.quick
def test_defaults_are_unchanged_by_the_bounds() -> None:
    values = Parameters().to_dict()
    assert values.pop("parts") == dataclasses.asdict(PartNames())  # the thesis's parts, by name
    assert values == THESIS_DEFAULTS
    for name in INTEGER_FIELDS:
        group, field_name = name.split(".")
        assert type(getattr(getattr(Parameters(), group), field_name)) is int, name


def test_every_number_has_bounds_on_both_sides_and_a_reason() -> None:
    for name, f in _group_fields():
        md = f.metadata
        if md.get("flag"):
            continue
        assert md.get("why"), name
        if md.get("choice"):  # a part's name: the registry checks it (twin.parts)
            continue
        if md.get("curve"):
            assert 0 < md["magnitude"] < math.inf, name
            continue
        assert md["gt"] is not None or md["ge"] is not None, name
        assert md["lt"] is not None or md["le"] is not None, name
        if name.split(".")[0] in GROUPS:  # the thesis's table; a part's own group declares its own
            assert bool(md.get("integer")) == (name in INTEGER_FIELDS), name


@pytest.mark.parametrize("name", INTEGER_FIELDS)
def test_integer_fields_refuse_fractions_and_take_whole_floats(name: str) -> None:
    from twin.parameters import declaration

    whole = max(12, int(declaration(name).get("ge") or 0))  # within the field's bounds
    with pytest.raises(ParameterError) as err:
        Parameters().with_overrides({name: whole + 0.5})
    assert f"{name} = {whole + 0.5}" in str(err.value)
    assert "whole number" in str(err.value)
    group, field_name = name.split(".")
    value = getattr(getattr(Parameters().with_overrides({name: float(whole)}), group), field_name)
    assert value == whole and type(value) is int


@pytest.mark.parametrize(
    ("override", "fragment"),
    [
        # the hostile cases
        ({"daq.adc_bits": 1e6}, "daq.adc_bits = 1000000.0 bit is impossible: it must be <= 24"),
        ({"ball.mass_kg": 1e308}, "ball.mass_kg = 1e+308 kg is impossible: it must be <= 1.0"),
        ({"daq.sample_rate_hz": 1}, "daq.sample_rate_hz = 1.0 Hz is impossible: it must be >= 100.0"),
        ({"ball_sensor.dropout_rate_hz": 1e6}, "ball_sensor.dropout_rate_hz = 1000000.0 1/s is impossible"),
        (
            {"angle_sensor.counter_zero_count": 1024},
            "angle_sensor.counter_zero_count = 1024 count is impossible",
        ),
        ({"angle_sensor.counter_zero_count": -1}, "angle_sensor.counter_zero_count = -1 count"),
        # the zero count must fit the counter as it is configured, not only 16 bits
        (
            {"angle_sensor.counter_bits": 8},
            "angle_sensor.counter_zero_count = 512 count is impossible: it must be <= 255",
        ),
        (
            {"angle_sensor.counter_bits": 17},
            "angle_sensor.counter_bits = 17 bit is impossible: it must be <= 16",
        ),
        (
            {"angle_sensor.counter_bits": 0},
            "angle_sensor.counter_bits = 0 bit is impossible: it must be >= 1",
        ),
        ({"daq.dac_bits": 25}, "daq.dac_bits = 25 bit is impossible: it must be <= 24"),
        ({"angle_sensor.encoder_pulses_per_rev": 0}, "angle_sensor.encoder_pulses_per_rev = 0 pulses/rev"),
        ({"daq.adc_bits": math.inf}, "daq.adc_bits = inf bit is impossible: it must be finite"),
        ({"daq.adc_bits": True}, "daq.adc_bits = True is not a number"),
        # the other bounds
        (
            {"daq.sample_rate_hz": 2e6},
            "daq.sample_rate_hz = 2000000.0 Hz is impossible: it must be <= 1000000.0",
        ),
        ({"daq.period_s": 1e-4}, "daq.period_s = 0.0001 s is impossible: it must be >= 0.001"),
        ({"daq.period_s": 2.0}, "daq.period_s = 2.0 s is impossible: it must be <= 1.0"),
        ({"daq.period_s": 0.001, "daq.sample_rate_hz": 1500.0}, "daq.sample_rate_hz = 1500.0 Hz"),
        ({"ball_sensor.dropout_mean_duration_s": 2.0}, "ball_sensor.dropout_mean_duration_s = 2.0 s"),
        ({"beam.mass_kg": 25.0}, "beam.mass_kg = 25.0 kg is impossible: it must be <= 20.0"),
        ({"beam.inertia_pivot_kgm2": 11.0}, "beam.inertia_pivot_kgm2 = 11.0 kg·m²"),
        ({"ball.radius_m": 8.329}, "ball.radius_m = 8.329 m"),
        ({"track.half_length_m": 6.0}, "track.half_length_m = 6.0 m"),
        (
            {"motor.resistance_ohm": 2000.0},
            "motor.resistance_ohm = 2000.0 Ω is impossible: it must be <= 1000.0",
        ),
        ({"motor.gear_ratio": 5000.0}, "motor.gear_ratio = 5000.0 -"),
        ({"motor.rotor_inertia_kgm2": 8.5}, "motor.rotor_inertia_kgm2 = 8.5 kg·m²"),
        ({"physics.gravity_m_s2": 981.0}, "physics.gravity_m_s2 = 981.0 m/s²"),
        ({"physics.timestep_s": 1e-6}, "physics.timestep_s = 1e-06 s is impossible: it must be >= 1e-05"),
        ({"amplifier.rail_v": 1e7}, "amplifier.rail_v = 10000000.0 V"),
        ({"daq.adc_max_v": 5000.0}, "daq.adc_max_v = 5000.0 V is impossible: it must be <= 100.0"),
        ({"ball_sensor.curve_volts_v": [0.0] * 22 + [1e3]}, "ball_sensor.curve_volts_v[22] = 1000.0 V"),
        # an integer too large for a float is a refused value, not an OverflowError
        ({"ball.mass_kg": 10**400}, "ball.mass_kg = 1000000000"),
        ({"ball_sensor.curve_volts_v": [10**400, 1.0]}, "ball_sensor.curve_volts_v[0] = 1000000000"),
        ({"daq.adc_bits": 10**400}, "daq.adc_bits = 1000000000"),
    ],
)
def test_values_out_of_physical_bounds_are_refused_by_name(override: dict, fragment: str) -> None:
    with pytest.raises(ParameterError) as err:
        Parameters().with_overrides(override)
    assert fragment in str(err.value)
    assert len(str(err.value)) < 600  # a huge value is not echoed whole


def test_a_refusal_gives_the_reason_for_the_bound() -> None:
    with pytest.raises(ParameterError, match=r"PCI-1712 samples at up to 1 MS/s"):
        Parameters().with_overrides({"daq.sample_rate_hz": 2e6})
    with pytest.raises(ParameterError, match="never in contact"):
        Parameters().with_overrides({"ball_sensor.dropout_rate_hz": 1001.0})
    with pytest.raises(ParameterError, match=r"2\*\*angle_sensor.counter_bits − 1"):
        Parameters().with_overrides({"angle_sensor.counter_zero_count": 1024})


def test_bounds_are_inclusive_where_they_say_so() -> None:
    edge = Parameters().with_overrides(
        {
            "daq.adc_bits": 24,
            "daq.dac_bits": 1,
            "angle_sensor.counter_bits": 16,
            "angle_sensor.counter_zero_count": 2**16 - 1,
            "ball_sensor.dropout_rate_hz": 1000.0,
            "ball_sensor.dropout_mean_duration_s": 1.0,
            "daq.period_s": 0.001,
            "daq.sample_rate_hz": 2000.0,  # exactly 2 samples a block
        }
    )
    assert edge.daq.block_size == 2
    assert edge.angle_sensor.counter_zero_count == 65535
    # exactly two samples a block is accepted whatever the rounding of sample_rate × period
    for period in (0.003, 0.007, 0.013, 0.017, 0.019, 0.021, 0.03):
        two = Parameters().with_overrides({"daq.period_s": period, "daq.sample_rate_hz": 2 / period})
        assert two.daq.block_size == 2


def test_values_that_are_tables_or_lists_are_refused_by_name() -> None:
    cases = [
        ({"ball": {"mass_kg": [0.01, 0.02]}}, "ball.mass_kg = [0.01, 0.02] is not a number"),
        ({"ball": {"mass_kg": {"value": 0.02}}}, "ball.mass_kg = {'value': 0.02} is not a number"),
        ({"daq": {"adc_bits": [12]}}, "daq.adc_bits = [12] is not a number"),
        ({"ball_sensor": {"noise_enabled": [True]}}, "ball_sensor.noise_enabled = [True] is not true/false"),
        (
            {"ball_sensor": {"curve_volts_v": {"a": 1.0}}},
            "ball_sensor.curve_volts_v = {'a': 1.0} is not a list",
        ),
        ({"ball_sensor": {"curve_volts_v": [[1.0], [2.0]]}}, "ball_sensor.curve_volts_v[0] = [1.0]"),
        ({"ball": {"mass_kg": "x" * 100_000}}, "ball.mass_kg = 'xxxx"),
    ]
    for override, fragment in cases:
        with pytest.raises(ParameterError) as err:
            Parameters().with_overrides(override)
        assert fragment in str(err.value)
        assert len(str(err.value)) < 600


def test_integral_floats_from_files_are_stored_as_integers(tmp_path) -> None:
    for name, text in (
        (
            "int.toml",
            "[daq]\nadc_bits = 16.0\n[angle_sensor]\ncounter_bits = 12.0\ncounter_zero_count = 2048.0\n",
        ),
        (
            "int.json",
            json.dumps(
                {
                    "daq": {"adc_bits": 16.0},
                    "angle_sensor": {"counter_bits": 12.0, "counter_zero_count": 2048.0},
                }
            ),
        ),
    ):
        path = tmp_path / name
        path.write_text(text)
        loaded = Parameters.from_file(path)
        assert (
            loaded.daq.adc_bits,
            loaded.angle_sensor.counter_bits,
            loaded.angle_sensor.counter_zero_count,
        ) == (
            16,
            12,
            2048,
        )
        assert type(loaded.daq.adc_bits) is int and type(loaded.angle_sensor.counter_zero_count) is int
        path.write_text(text.replace("16.0", "16.5"))
        with pytest.raises(
            ParameterError, match=r"daq.adc_bits = 16.5 bit is impossible: it must be a whole"
        ):
            Parameters.from_file(path)


def test_files_round_trip_exactly_with_integers_and_every_group_changed(tmp_path) -> None:
    changed = Parameters().with_overrides(
        {
            "daq.adc_bits": 16,
            "daq.dac_bits": 14.0,
            "angle_sensor.counter_bits": 12,
            "angle_sensor.counter_zero_count": 2047,
            "angle_sensor.encoder_pulses_per_rev": 500,
            "ball.mass_kg": 1,  # an integer for a float field is stored as a float
            "beam.cog_height_m": -0.0031,
            "ball_sensor.dropout_rate_hz": 0.1 + 0.2,  # not exactly representable in decimal
            "ball_sensor.curve_volts_v": [-4.6, 0.1 + 0.2, 4.6],
            "ball_sensor.curve_position_m": [-0.3, 0.0, 0.3],
            "ball_sensor.noise_enabled": False,
            "software.angle_gain_deg_per_v": 1 / 3,
        }
    )
    assert type(changed.ball.mass_kg) is float
    for name in ("p.toml", "p.json"):
        path = tmp_path / name
        changed.save(path)
        loaded = Parameters.from_file(path)
        assert loaded == changed
        assert loaded.to_dict() == changed.to_dict()
        for group, values in loaded.to_dict().items():
            for key, value in values.items():
                assert type(value) is type(changed.to_dict()[group][key]), f"{name}: {group}.{key}"


def _refused(path, fragment: str) -> str:
    """from_file on ``path`` raises ParameterError (no other exception) naming the file and ``fragment``."""
    with pytest.raises(ParameterError) as err:
        Parameters.from_file(path)
    message = str(err.value)
    assert str(path) in message
    assert fragment in message
    assert len(message) < 1000
    return message


def test_an_oversized_file_is_refused_without_reading_it_whole(tmp_path) -> None:
    path = tmp_path / "big.toml"
    path.write_text("# " + "x" * (MAX_FILE_BYTES - 3) + "\n")  # exactly 1 MiB of comment: still a file
    assert Parameters.from_file(path) == Parameters()
    path.write_text("# " + "x" * (MAX_FILE_BYTES - 2) + "\n")  # one byte more
    _refused(path, f"larger than {MAX_FILE_BYTES} bytes (1 MiB)")
    # An endless source (/dev/zero) is refused before a byte is read instead of filling memory: not a regular
    # file (twin.parameters.read_input_file, which the spread files' reader shares).
    if Path("/dev/zero").exists():
        endless = tmp_path / "zero.json"
        endless.symlink_to("/dev/zero")
        _refused(endless, "not a regular file (a device, pipe or socket)")


# (file name, text, what the refusal says)
BAD_FILES = [
    # deep enough to exhaust the parser's recursion: RecursionError becomes a ParameterError
    ("deep.json", "[" * 100_000 + "]" * 100_000, "nested deeper than a parameter file's two levels"),
    ("deep_object.json", '{"a":' * 100_000 + "1" + "}" * 100_000, "nested deeper"),
    ("deep.toml", "a = " + "[" * 100_000 + "]" * 100_000, "nested deeper"),
    ("deep_inline.toml", "a = " + "{b = " * 50_000 + "1" + "}" * 50_000, "nested deeper"),
    # deep without recursion (dotted table names, moderate JSON): refused before reaching the fields
    ("dotted_header.toml", "[ball" + ".x" * 400_000 + "]\n", "line 1 has a dotted key of more than 3 parts"),
    ("dotted_key.toml", "[ball]\nmass_kg" + ".x" * 300_000 + " = 1\n", "line 2 has a dotted key"),
    ("dotted_quoted.toml", '"ball"."mass_kg" . "x".y = 1\n', "line 1 has a dotted key"),
    (
        "dotted_after_strings.toml",
        '[ball] # a.b.c.d.e in a comment\nmass_kg = """1.2.3.4\n5.6.7.8"""\na.b.c.d = 1\n',
        "line 4 has a dotted key",
    ),
    (
        "curve_of_lists.json",
        json.dumps({"ball_sensor": {"curve_volts_v": [[1.0], [2.0]]}}),
        "at ball_sensor.curve_volts_v[1]",
    ),
    ("list_in_list.json", json.dumps({"ball": {"mass_kg": [[0.02]]}}), "at ball.mass_kg[0]"),
    # tables and lists where a number is expected
    ("table.toml", "[ball.mass_kg]\nvalue = 0.02\n", "ball.mass_kg = {'value': 0.02} is not a number"),
    ("list.toml", "[daq]\nadc_bits = [12]\n", "daq.adc_bits = [12] is not a number"),
    (
        "date.toml",
        "[ball]\nmass_kg = 2024-01-01\n",
        "ball.mass_kg = datetime.date(2024, 1, 1) is not a number",
    ),
    ("string.json", json.dumps({"ball": {"mass_kg": "0.02"}}), "ball.mass_kg = '0.02' is not a number"),
    ("group_value.json", json.dumps({"ball": 0.02}), "'ball' is not a parameter group"),
    # numbers that cannot be
    ("big.toml", "[ball]\nmass_kg = 1e308\n", "ball.mass_kg = 1e+308 kg is impossible"),
    ("huge_int.toml", "[ball]\nmass_kg = 1" + "0" * 400 + "\n", "ball.mass_kg = 1000"),
    ("huge_int_digits.json", '{"ball": {"mass_kg": 1' + "0" * 5000 + "}}", "not a valid JSON file"),
    ("huge_int_digits.toml", "[ball]\nmass_kg = 1" + "0" * 5000 + "\n", "not a valid TOML file"),
    ("nan.json", '{"ball": {"mass_kg": NaN}}', "ball.mass_kg = nan"),
    ("inf.toml", "[ball]\nmass_kg = inf\n", "ball.mass_kg = inf"),
    ("adc.toml", "[daq]\nadc_bits = 1e6\n", "daq.adc_bits = 1000000.0 bit is impossible"),
    (
        "rate.json",
        json.dumps({"daq": {"sample_rate_hz": 1}}),
        "daq.sample_rate_hz = 1.0 Hz is impossible",
    ),
    ("dropout.toml", "[ball_sensor]\ndropout_rate_hz = 1e6\n", "ball_sensor.dropout_rate_hz = 1000000.0"),
    (
        "zero.toml",
        "[angle_sensor]\ncounter_zero_count = 4096\n",
        "angle_sensor.counter_zero_count = 4096",
    ),
    ("bits.json", json.dumps({"daq": {"dac_bits": 11.5}}), "daq.dac_bits = 11.5 bit"),
    (
        "utf16.toml",
        "[ball]\nmass_kg = 0.02\n".encode("utf-16").decode("latin-1"),
        "not a valid TOML file",
    ),
]


@pytest.mark.parametrize(("name", "text", "fragment"), BAD_FILES, ids=[case[0] for case in BAD_FILES])
def test_files_that_cannot_be_parameter_files_are_refused(
    tmp_path, name: str, text: str, fragment: str
) -> None:
    path = tmp_path / name
    path.write_bytes(text.encode("latin-1") if name.startswith("utf16") else text.encode("utf-8"))
    message = _refused(path, fragment)
    assert "Traceback" not in message


@pytest.mark.realtime
def test_a_long_dotted_key_is_refused_before_the_parser_spends_minutes_on_it(tmp_path) -> None:
    # tomllib's time grows with the square of a dotted key's length: 40 kB take seconds, 1 MiB would take an hour.
    path = tmp_path / "dotted.toml"
    path.write_text("a" + ".x" * (MAX_FILE_BYTES // 2 - 8) + " = 1\n")
    start = time.perf_counter()
    _refused(path, "line 1 has a dotted key")
    assert time.perf_counter() - start < 5.0


def test_a_parameter_file_of_the_usual_shape_is_not_too_deep(tmp_path) -> None:
    path = tmp_path / "full.json"
    path.write_text(
        json.dumps(
            {
                "ball": {"mass_kg": 0.0191},
                "ball_sensor.curve_position_m": [-0.323, 0.0, 0.323],
                "ball_sensor": {"curve_volts_v": [-4.62, 0.0, 4.60]},
            }
        )
    )
    loaded = Parameters.from_file(path)
    assert loaded.ball.mass_kg == 0.0191
    assert loaded.ball_sensor.curve_volts_v == (-4.62, 0.0, 4.60)
