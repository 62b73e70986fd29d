"""The serial-log reader (calib/serial_log.py): an Arduino sketch's printed lines through a column map, into the
calibration's log (timem s, datam1 ball, datam2 angle, aout command, each in the board's unit).

Every expected value is written out by hand from the lines the test writes; the Servo library's ``write(deg)``
is Arduino's integer ``map(deg, 0, 180, 544, 2400)`` computed here on paper."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import calib.serial_log as sl
from calib.serial_log import (
    SerialLogError,
    parse_column_map,
    read_serial_log,
    save_serial_log,
)
from twin.log import load_csv
from twin.parameters import Parameters

VL53_SERVO = Parameters().with_overrides(
    {"parts.ball_sensor": "vl53l0x", "parts.angle_sensor": "none", "parts.io_board": "arduino_uno"}
)
HCSR04_SERVO = Parameters().with_overrides(
    {"parts.ball_sensor": "hcsr04", "parts.angle_sensor": "none", "parts.io_board": "arduino_uno"}
)
IR_POT = Parameters().with_overrides(
    {"parts.ball_sensor": "gp2y0a21", "parts.angle_sensor": "potentiometer", "parts.io_board": "arduino_uno"}
)


def _write(tmp_path: Path, data: bytes, name: str = "log.txt") -> Path:
    path = tmp_path / name
    path.write_bytes(data)
    return path


# --- well-formed logs -------------------------------------------------------------------------------------


@pytest.mark.quick
def test_a_sketch_log_with_bom_header_mixed_line_ends_and_chatter(tmp_path: Path) -> None:
    # line 1 "ready" (after a BOM), 2 header, 3-4 data, 5 an Arduino 'nan', 6 data, 7 debug, 8 data;
    # line ends \r\n, \n, a lone \r
    data = (
        b"\xef\xbb\xbfready\r\n"
        b"time,distance,pulse\r\n"
        b"1000,100,1500\n"
        b"1020,101,1510\r"
        b"1040,nan,1500\n"
        b"1060,103,1490\n"
        b"DEBUG x=3\n"
        b"1080,104,1480\n"
    )
    log = read_serial_log(_write(tmp_path, data), "time=ms, distance=mm, pulse=us", VL53_SERVO)
    assert log.log.timem.tolist() == [1.0, 1.02, 1.06, 1.08]
    assert log.log.datam1.tolist() == [100.0, 101.0, 103.0, 104.0]
    assert log.log.datam2.tolist() == [0.0, 0.0, 0.0, 0.0]  # no angle sensor: the channel reads 0
    assert log.log.aout.tolist() == [1500.0, 1510.0, 1490.0, 1480.0]
    assert log.lines.tolist() == [3, 4, 6, 8]
    assert log.header_line == 2
    assert log.text_lines == 2  # "ready", "DEBUG x=3"
    assert log.malformed_count == 1
    assert log.malformed[0].endswith("line 5, column 2 'distance' (ball): 'nan' is not a finite number")
    assert log.units == {"timem": "s", "datam1": "mm", "datam2": "none (0)", "aout": "us"}


@pytest.mark.quick
def test_a_preset_map_by_name_reads_the_same(tmp_path: Path) -> None:
    data = b"time,distance,pulse\n0,80,1500\n20,82,1520\n"
    path = _write(tmp_path, data)
    assert sl.MAPS["vl53l0x-servo"] == "time=ms, distance=mm, pulse=us"
    log = read_serial_log(path, "vl53l0x-servo", VL53_SERVO)
    assert log.log.datam1.tolist() == [80.0, 82.0]
    assert log.log.timem.tolist() == [0.0, 0.02]


@pytest.mark.quick
@pytest.mark.parametrize(
    ("text", "separator"),
    [(b"0\t250\t1500\n20\t251\t1490\n", "\t"), (b"0 250  1500\n20   251 1490\n", " ")],
)
def test_no_header_columns_by_place_tab_or_spaces(tmp_path: Path, text: bytes, separator: str) -> None:
    log = read_serial_log(_write(tmp_path, text), "time=ms, echo=us, pulse=us", HCSR04_SERVO)
    assert log.separator == separator
    assert log.header_line is None
    assert log.log.datam1.tolist() == [250.0, 251.0]  # pulseIn's µs
    assert log.log.aout.tolist() == [1500.0, 1490.0]


@pytest.mark.quick
def test_columns_by_number_and_by_name_in_any_order(tmp_path: Path) -> None:
    data = b"pulse,junk,t_ms,dist\n1500,x,0,12.5\n1490,y,20,12.7\n"
    spec = "time@t_ms=ms, distance@4=cm, pulse@1=us"
    log = read_serial_log(_write(tmp_path, data), spec, VL53_SERVO)
    assert log.log.datam1.tolist() == [125.0, 127.0]  # cm → the VL53L0X's mm
    assert log.log.aout.tolist() == [1500.0, 1490.0]


@pytest.mark.quick
def test_a_servo_write_in_degrees_becomes_its_pulse(tmp_path: Path) -> None:
    # Servo::write(deg): map(deg, 0, 180, 544, 2400) in integer arithmetic: 0 → 544, 90 → 544 + 167040/180 =
    # 1472, 45 → 544 + 83520/180 = 1008, 180 → 2400, 200 → clipped to 180 → 2400; 1500 (≥ 544) is µs already
    data = b"0,100,0\n20,100,90\n40,100,45\n60,100,180\n80,100,200\n100,100,1500\n"
    log = read_serial_log(_write(tmp_path, data), "time=ms, distance=mm, servo=deg", VL53_SERVO)
    assert log.log.aout.tolist() == [544.0, 1472.0, 1008.0, 2400.0, 2400.0, 1500.0]


@pytest.mark.quick
def test_an_analog_sensor_and_a_pot_read_in_counts(tmp_path: Path) -> None:
    data = b"t,ir,pot,us\n0,512,500,1500\n20,513,501,1500\n"
    log = read_serial_log(
        _write(tmp_path, data), "time@t=ms, ball@ir=counts, angle@pot=counts, pulse@us=us", IR_POT
    )
    assert log.log.datam1.tolist() == [512.0, 513.0]
    assert log.log.datam2.tolist() == [500.0, 501.0]
    assert log.units["datam2"] == "counts"


@pytest.mark.quick
def test_a_millis_wrap_is_unwrapped(tmp_path: Path) -> None:
    # millis() wraps at 2^32 ms: 4294967290 → 4294967295 → (2^32 + 4) = 4
    data = b"4294967290,100,1500\n4294967295,100,1500\n4,100,1500\n"
    log = read_serial_log(_write(tmp_path, data), "time=ms, distance=mm, pulse=us", VL53_SERVO)
    assert log.wraps == 1
    np.testing.assert_allclose(np.diff(log.log.timem), [0.005, 0.005], rtol=0, atol=1e-9)


@pytest.mark.quick
def test_saved_atomically_and_read_back_bit_for_bit(tmp_path: Path) -> None:
    data = b"time,distance,pulse\n0,100,1500\n20,101,1510\n40,103,1490\n"
    log = read_serial_log(_write(tmp_path, data), "vl53l0x-servo", VL53_SERVO)
    out = tmp_path / "log.csv"
    save_serial_log(log, out)
    back = load_csv(out)
    for name in ("timem", "datam1", "datam2", "aout"):
        assert getattr(back, name).tolist() == getattr(log.log, name).tolist()
    with pytest.raises(FileExistsError):
        save_serial_log(log, out)
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


# --- hostile input: each refusal names the file, the line and the column -----------------------------------


def _refused(path: Path, spec: str, params: Parameters | None = VL53_SERVO) -> str:
    with pytest.raises(SerialLogError) as info:
        read_serial_log(path, spec, params)
    return str(info.value)


@pytest.mark.quick
def test_a_header_without_a_mapped_column(tmp_path: Path) -> None:
    path = _write(tmp_path, b"time,distance,servo\n0,100,1500\n")
    assert _refused(path, "time=ms, distance=mm, pulse=us") == (
        f"{path}, line 1 (the header): no column 'pulse' (its columns: time, distance, servo)"
    )


@pytest.mark.quick
def test_a_column_number_beyond_the_lines(tmp_path: Path) -> None:
    path = _write(tmp_path, b"0,100,1500\n")
    assert _refused(path, "time@1=ms, distance@2=mm, pulse@4=us") == (
        f"{path}, line 1: no column 4 for the command (the first data line has 3 columns)"
    )


@pytest.mark.quick
@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("time=ms, distance=furlong, pulse=us", "distance='furlong': unit not known"),
        ("time=ms, colour=mm, pulse=us", "'colour' is not a role"),
        ("time=mm, distance=mm, pulse=us", "time='mm': the time is not in length"),
        ("time=ms, pulse=us", "no ball column"),
        ("time=ms, distance=mm, range=mm, pulse=us", "two columns for the ball"),
    ],
)
def test_a_bad_map_is_refused(spec: str, message: str) -> None:
    with pytest.raises(SerialLogError, match=message):
        parse_column_map(spec)


@pytest.mark.quick
def test_a_unit_the_board_does_not_read(tmp_path: Path) -> None:
    path = _write(tmp_path, b"time,distance,pulse\n0,100,1500\n")
    assert _refused(path, "vl53l0x-servo", HCSR04_SERVO) == (
        f"{path}, line 1, column 2 'distance' (ball): logged in mm but the board reads the ball in us "
        "(hcsr04 on arduino_uno): log what the board reads"
    )


@pytest.mark.quick
def test_time_going_backwards(tmp_path: Path) -> None:
    path = _write(tmp_path, b"time,distance,pulse\n0,100,1500\n20,100,1500\n10,100,1500\n")
    assert _refused(path, "vl53l0x-servo") == (
        f"{path}, line 4, column 1 'time' (time): 10.0 ms is not after 20.0 ms at line 3: time must increase "
        "(the board reset? split the log there)"
    )


@pytest.mark.quick
def test_a_value_outside_the_board(tmp_path: Path) -> None:
    path = _write(tmp_path, b"0,512,500,1500\n20,1500,501,1500\n")  # 1500 is no 10-bit count
    assert _refused(path, "time=ms, distance=counts, angle=counts, pulse=us", IR_POT) == (
        f"{path}, line 2, column 2 (ball): 1500.0 counts is outside the board's 0 … 1023 counts "
        "(gp2y0a21 on arduino_uno): a wrong column or unit?"
    )
    path = _write(tmp_path, b"0,100,1500\n20,100,3000\n", "pulse.txt")
    assert "line 2, column 3 (command): 3000.0 us is outside the board's 544 … 2400 us" in _refused(
        path, "time=ms, distance=mm, pulse=us"
    )


@pytest.mark.quick
def test_the_rig_has_an_angle_sensor_the_map_lacks(tmp_path: Path) -> None:
    path = _write(tmp_path, b"0,512,1500\n")
    assert "the rig's angle sensor 'potentiometer' reads the beam's angle but the column map has none" in (
        _refused(path, "time=ms, distance=counts, pulse=us", IR_POT)
    )


@pytest.mark.quick
def test_many_malformed_lines_are_refused_a_few_skipped(tmp_path: Path) -> None:
    good = b"".join(b"%d,100,1500\n" % (20 * i) for i in range(100))
    few = good + b"2000,ovf,1500\n2020,100\n"  # Arduino's overflow text; a truncated line
    log = read_serial_log(_write(tmp_path, few), "vl53l0x-servo", VL53_SERVO)
    assert (log.ticks, log.malformed_count) == (100, 2)
    assert log.malformed[1] == f"{tmp_path / 'log.txt'}, line 102: 2 cells, the log's lines have 3"
    many = good + b"".join(b"%d,inf,1500\n" % (2000 + 20 * i) for i in range(10))
    path = _write(tmp_path, many, "many.txt")
    assert _refused(path, "vl53l0x-servo") == (
        f"{path}: 10 malformed data lines against 100 good ones (more than 5%): a wrong map or a broken log; "
        f"the first: {path}, line 101, column 2 (ball): 'inf' is not a finite number"
    )


@pytest.mark.quick
def test_a_binary_file(tmp_path: Path) -> None:
    path = _write(tmp_path, b"0,100,1500\n\x7fELF\x02\x01\x01\x00\x00\x00\n")
    assert _refused(path, "vl53l0x-servo") == f"{path}, line 2: a NUL byte: a binary file, not a serial log"


@pytest.mark.quick
def test_a_one_gigabyte_file_is_refused_unread(tmp_path: Path) -> None:
    path = tmp_path / "huge.txt"
    with path.open("wb") as fh:
        fh.truncate(1 << 30)  # sparse: 1 GiB of size, nothing written
    assert _refused(path, "vl53l0x-servo") == (
        f"{path}: 1073741824 bytes, beyond the 67108864 bytes (64 MiB) a serial log may have: split it"
    )


@pytest.mark.quick
def test_an_endless_line_and_noise_are_skipped_in_bounded_reads(tmp_path: Path) -> None:
    data = (
        b"\xff\xfe\x80garbage at the wrong baud\n"
        + b"9" * (3 * sl.MAX_LINE_BYTES)
        + b"\n0,100,1500\n20,101,1500\n"
    )
    log = read_serial_log(_write(tmp_path, data), "vl53l0x-servo", VL53_SERVO)
    assert log.ticks == 2
    assert log.text_lines == 1  # the undecodable line
    assert log.malformed == (f"{tmp_path / 'log.txt'}, line 2: longer than 4096 bytes",)
    assert log.lines.tolist() == [3, 4]


@pytest.mark.quick
def test_no_data_and_not_a_file(tmp_path: Path) -> None:
    path = _write(tmp_path, b"ready\nFailed to detect and initialize sensor VL53L0X!\n")
    assert _refused(path, "vl53l0x-servo") == f"{path}: no data line matching the map (2 lines of other text)"
    assert _refused(tmp_path, "vl53l0x-servo") == f"{tmp_path}: a directory, not a log file"
    assert _refused(Path("/dev/zero"), "vl53l0x-servo") == (
        "/dev/zero: not a regular file (a device, pipe or socket)"
    )
    assert _refused(tmp_path / "nope.txt", "vl53l0x-servo") == f"{tmp_path / 'nope.txt'}: no such file"


@pytest.mark.quick
def test_too_many_ticks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sl, "MAX_TICKS", 3)
    path = _write(tmp_path, b"".join(b"%d,100,1500\n" % (20 * i) for i in range(5)))
    assert _refused(path, "vl53l0x-servo") == f"{path}, line 4: more than 3 data lines: split the log"


@pytest.mark.quick
def test_the_open_ball_and_beam_preset_reads_with_its_map(tmp_path: Path) -> None:
    from twin.parts.description import preset

    params = preset("open-ball-and-beam")
    assert (params.parts.ball_sensor, params.parts.angle_sensor) == ("vl53l0x", "none")
    data = b"time,distance,pulse\n0,142,1550\n20,141,1552\n"
    log = read_serial_log(_write(tmp_path, data), "open-ball-and-beam", params)
    assert log.log.datam1.tolist() == [142.0, 141.0]
    assert log.log.aout.tolist() == [1550.0, 1552.0]
    assert log.units == {"timem": "s", "datam1": "mm", "datam2": "none (0)", "aout": "us"}


@pytest.mark.quick
def test_chatter_with_spaces_or_commas_before_the_data_does_not_fix_the_separator(tmp_path: Path) -> None:
    # "Sensor calibration" splits by spaces, "3 retries, then go" by commas and has a number first: both text
    data = b"Sensor calibration\n3 retries, then go\n0,100,1500\n20,101,1500\n"
    log = read_serial_log(_write(tmp_path, data), "time=ms, distance=mm, pulse=us", VL53_SERVO)
    assert (log.separator, log.text_lines, log.lines.tolist()) == (",", 2, [3, 4])


@pytest.mark.quick
def test_an_angle_column_for_a_rig_without_an_angle_sensor(tmp_path: Path) -> None:
    path = _write(tmp_path, b"0,100,512,1500\n")
    assert "the map has an angle column but the rig has no angle sensor (parts.angle_sensor = 'none')" in (
        _refused(path, "time=ms, distance=mm, angle=counts, pulse=us")
    )
