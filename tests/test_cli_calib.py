"""The calibration commands from the command line: calibrate-static and experiment."""

from pathlib import Path

import numpy as np
import pytest
from thesis_data import TABLE_6_3_POSITION_M, TABLE_6_3_VOLTAGE_V

from calib.logs import load_rig_log
from calib.static import TABLES_DIR
from twin.app.cli import main
from twin.parameters import Parameters


@pytest.mark.quick
def test_calibrate_static_reproduces_eq_6_3_1_and_writes_a_parameter_file(tmp_path: Path, capsys) -> None:
    out = tmp_path / "sensor.toml"
    assert main(["calibrate-static", str(TABLES_DIR / "table_6_3.csv"), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "0.0692523" in text and "0.0017999" in text
    params = Parameters.from_file(out)
    # The straight line of x on V over the 21 interior points of Table 6.3, by numpy.
    slope, offset = np.polyfit(TABLE_6_3_VOLTAGE_V[1:-1], TABLE_6_3_POSITION_M[1:-1], 1)
    assert params.software.ball_gain_m_per_v == pytest.approx(slope, rel=1e-12)
    assert params.software.ball_offset_m == pytest.approx(offset, rel=1e-9)
    assert main(["calibrate-static", str(TABLES_DIR / "table_6_3.csv"), "--out", str(out)]) == 2
    assert "exists; not overwritten" in capsys.readouterr().err


@pytest.mark.quick
def test_calibrate_static_refuses_a_bad_table_naming_the_line(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("position_m,volts_v\n0.0,0.0\n0.1,abc\n0.2,2.0\n")
    assert main(["calibrate-static", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "line 3" in err and "volts_v" in err


@pytest.mark.quick
def test_experiment_writes_a_log_calibrate_can_read(tmp_path: Path, capsys) -> None:
    log = tmp_path / "square.mat"
    assert main(["experiment", "square", "--out", str(log), "--duration", "6", "--seed", "2"]) == 0
    rig = load_rig_log(log)
    assert rig.ticks == 301 and abs(rig.period_s - 0.02) < 1e-12  # blocks to 6.01 s: the first ends at 10 ms
    assert main(["experiment", "square", "--out", str(log), "--duration", "6"]) == 2
    assert main(["experiment", "wiggle", "--out", str(tmp_path / "w.mat")]) == 2
    assert "unknown experiment 'wiggle'" in capsys.readouterr().err


@pytest.mark.quick
def test_the_shipped_tables_are_found_without_a_clone(capsys: pytest.CaptureFixture[str]) -> None:
    """``thesis:table_6_3`` is the table the package ships: the same fit as the repository's file, from any
    directory; an unknown name lists the shipped ones."""
    import json

    from twin.app.commands.calibrate_static import table_path

    assert main(["calibrate-static", str(TABLES_DIR / "table_6_3.csv"), "--json"]) == 0
    from_file = json.loads(capsys.readouterr().out)
    assert main(["calibrate-static", "thesis:table_6_3", "--json"]) == 0
    shipped = json.loads(capsys.readouterr().out)
    assert table_path("thesis:table_6_3").read_bytes() == (TABLES_DIR / "table_6_3.csv").read_bytes()
    from_file.pop("table", None), shipped.pop("table", None)
    assert shipped == from_file
    assert main(["calibrate-static", "thesis:table_9_9"]) == 2
    assert "thesis:eq_6_2_4, thesis:table_6_3" in capsys.readouterr().err
