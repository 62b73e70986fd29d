"""The rig as an FMI 3.0 co-simulation unit (``ballbeam export-fmu``, twin.fmi): FMPy's validation of its model
description passes; driven from FMPy with the commands an in-process ``appendix-sf`` run wrote, it gives that
run's readings and true state bit for bit; a reset or a new instance repeats it; two instances in one process
keep their own state; a step of another size than the period is refused; its parameters are the twin's."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from controllers import registry
from twin.app.cli import main
from twin.log import RunLog
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop

fmpy = pytest.importorskip("fmpy")
from fmpy.fmi3 import FMU3Slave  # noqa: E402

OUTPUTS = ("time_s", "ball_v", "angle_v", "x_m", "theta_rad", "xdot_m_s", "thetadot_rad_s", "motor_v")
LOGGED = ("timem", "datam1", "datam2", "true_x_m", "true_theta_rad", "true_xdot_m_s", "true_thetadot_rad_s")


def _export(folder: Path, *extra: str) -> Path:
    out = folder / "BallBeam.fmu"
    assert main(["export-fmu", "--out", str(out), "--json", *extra]) == 0
    return out


@pytest.fixture(scope="module")
def unit(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _export(tmp_path_factory.mktemp("fmu"))


@pytest.fixture(scope="module")
def unit2(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _export(tmp_path_factory.mktemp("fmu2"), "--fmi", "2")


class Driver:
    """One instance of a unit (FMI 3.0 or 2.0), stepped by hand as an importer steps it."""

    def __init__(self, path: Path, name: str = "rig") -> None:
        md = fmpy.read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.three = md.fmiVersion.startswith("3")
        if self.three:
            self.fmu = FMU3Slave(
                guid=md.guid,
                unzipDirectory=fmpy.extract(str(path)),
                modelIdentifier=md.coSimulation.modelIdentifier,
                instanceName=name,
            )
            self.fmu.instantiate()
        else:
            self.fmu = fmpy.instantiate_fmu(fmpy.extract(str(path)), md, fmi_type="CoSimulation")
        self.get = self.fmu.getFloat64 if self.three else self.fmu.getReal
        self.set = self.fmu.setFloat64 if self.three else self.fmu.setReal

    def start(self, x0_m: float, theta0_rad: float, seed: int, **floats: float) -> None:
        f = self.fmu
        if not self.three:
            f.setupExperiment(startTime=0.0)
        f.enterInitializationMode()
        names = ["x0_m", "theta0_rad", *floats]
        self.set([self.vr[n] for n in names], [x0_m, theta0_rad, *floats.values()])
        (f.setInt64 if self.three else f.setInteger)([self.vr["seed"]], [seed])
        f.exitInitializationMode()
        self.t = 0.0

    def outputs(self) -> list[float]:
        return list(self.get([self.vr[n] for n in OUTPUTS]))

    def step(self, dac_v: float, h: float = 0.02) -> None:
        self.set([self.vr["dac_v"]], [dac_v])
        self.fmu.doStep(self.t, h)
        self.t += h

    def replay(self, log: RunLog) -> np.ndarray:
        rows = []
        for k, command in enumerate(log.aout):
            rows.append(self.outputs())
            if k < len(log.aout) - 1:
                self.step(float(command))
        return np.array(rows)


def _reference(seed: int = 0, duration_s: float = 4.0, **overrides: Any) -> RunLog:
    params = Parameters().with_overrides(overrides) if overrides else None
    ref = run_closed_loop(
        registry.make("appendix-sf", params), x0_m=0.14, theta0_rad=-0.2, duration_s=duration_s, seed=seed,
        params=params,
    )  # fmt: skip
    return ref.log


def _same(rows: np.ndarray, log: RunLog) -> None:
    for i, name in enumerate(LOGGED):
        assert np.array_equal(rows[:, i], getattr(log, name)), name
    # motor_v is the volts the step was driven with: the log's, one tick later (it logs them after the write)
    assert np.array_equal(rows[1:, 7], log.motor_volts_v[:-1])


@pytest.mark.quick
def test_the_unit_validates_and_replays_an_in_process_run_bit_for_bit(unit: Path) -> None:
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(unit)) == []
    log = _reference()
    d = Driver(unit)
    d.start(0.14, -0.2, 0)
    _same(d.replay(log), log)
    d.fmu.reset()  # FMI reset: instantiated again from its start values
    d.start(0.14, -0.2, 0)
    _same(d.replay(log), log)
    d.fmu.terminate()
    d.fmu.freeInstance()


def test_the_fmi_2_unit_validates_and_replays_the_run_bit_for_bit(unit2: Path) -> None:
    """``--fmi 2`` (pythonfmu): the same rig behind FMI 2.0's calls; its description validates."""
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(unit2)) == [] and fmpy.read_model_description(str(unit2)).fmiVersion == "2.0"
    log = _reference()
    d = Driver(unit2)
    d.start(0.14, -0.2, 0)
    _same(d.replay(log), log)


def test_two_instances_in_one_process_keep_their_own_state(unit: Path) -> None:
    """Stepped in turn, two seeds: each equals its own in-process run."""
    logs = [_reference(seed) for seed in (0, 1)]
    drivers = [Driver(unit, f"rig{seed}") for seed in (0, 1)]
    for seed, d in enumerate(drivers):
        d.start(0.14, -0.2, seed)
    rows: list[list[list[float]]] = [[], []]
    for k in range(len(logs[0].aout)):
        for i, d in enumerate(drivers):
            rows[i].append(d.outputs())
            if k < len(logs[0].aout) - 1:
                d.step(float(logs[i].aout[k]))
    for i in range(2):
        _same(np.array(rows[i]), logs[i])


def test_a_step_of_another_size_is_refused_and_parameters_are_the_twins(unit: Path) -> None:
    d = Driver(unit)
    d.start(0.14, -0.2, 0)
    with pytest.raises(Exception, match="(?i)error|fmi3"):
        d.step(2.5, 0.01)
    log = _reference(**{"motor.resistance_ohm": 9.0})
    e = Driver(unit, "warm")
    e.start(0.14, -0.2, 0, **{"motor.resistance_ohm": 9.0})
    _same(e.replay(log), log)


@pytest.mark.quick
def test_the_unit_carries_its_parameters_and_provenance(unit: Path, tmp_path: Path) -> None:
    import zipfile

    with zipfile.ZipFile(unit) as z:
        rig = json.loads(z.read("resources/rig.json"))
        assert z.read("resources/requirements.txt").decode().startswith("ballbeam-twin==")
    assert rig["values"] == json.loads(json.dumps(Parameters().to_dict()))
    assert rig["source"] == "the defaults (thesis values)"
    md = fmpy.read_model_description(str(unit))
    starts = {v.name: v.start for v in md.modelVariables if v.causality == "parameter"}
    assert float(starts["motor.resistance_ohm"]) == Parameters().motor.resistance_ohm
    assert md.coSimulation.modelIdentifier == "BallBeam"


def test_a_controller_stepping_the_unit_runs_what_ballbeam_run_runs(unit: Path) -> None:
    """The README's loop: the controller starts on the outputs after initialization, each doStep then its
    update on the new outputs sets dac_v — the same commands and true state as ``run_closed_loop``."""
    from twin.interface import DaqSample

    log = _reference(duration_s=6.0)
    d = Driver(unit)
    d.start(0.14, -0.2, 0)
    controller = registry.make("appendix-sf")

    def read() -> DaqSample:
        return DaqSample(*d.fmu.getFloat64([d.vr["time_s"], d.vr["ball_v"], d.vr["angle_v"]]))

    controller.start(read())  # type: ignore[union-attr]
    commands, xs = [], []
    for _ in range(len(log.aout) - 1):
        d.fmu.doStep(d.t, 0.02)
        d.t += 0.02
        command = controller.update(read())  # type: ignore[union-attr]
        d.fmu.setFloat64([d.vr["dac_v"]], [command])
        commands.append(command)
        xs.append(d.fmu.getFloat64([d.vr["x_m"]])[0])
    assert np.array_equal(commands, log.aout[1:]) and np.array_equal(xs, log.true_x_m[1:])


@pytest.mark.quick
def test_the_description_names_every_parameter_with_its_unit_source_and_a_calibrations_uncertainty() -> None:
    from twin.app.commands import export_fmu
    from twin.fmi import ballbeam_fmu, ballbeam_fmu2, unit
    from twin.fmi.export import rig_description
    from twin.parameters import declaration

    d = rig_description(Parameters(), version="9", source="s", uncertainty={"motor.resistance_ohm": 0.125})
    held = Parameters().held_groups()  # the thesis's groups and its parts' names (no part's own group is set)
    assert set(d["declared"]) == {
        row["name"] for row in Parameters.describe() if row["name"].split(".")[0] in held
    }
    resistance = d["declared"]["motor.resistance_ohm"]
    assert resistance["unit"] == declaration("motor.resistance_ohm")["unit"]
    assert resistance["source"].startswith("calibrated (standard uncertainty 0.125); ")
    assert [name for name, *_ in unit.OUTPUTS][:3] == ["time_s", "ball_v", "angle_v"]
    assert ballbeam_fmu.BallBeam.__name__ == ballbeam_fmu2.BallBeam.__name__ == "BallBeam"
    assert "FMI 3.0" in export_fmu.HELP


# --- controllers as FMUs ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def controller_unit(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from fmu_units import example_unit

    return example_unit(tmp_path_factory.mktemp("ctl"))


@pytest.mark.quick
def test_the_example_controller_unit_gives_the_c_clients_commands_bit_for_bit(controller_unit: Path) -> None:
    """examples/fmu (the appendix law's C source with FMPy's FMI 3.0 headers) validates, and run as
    ``fmu:…`` (its own process) it writes the commands of the Python ``appendix-sf``, which the C client writes
    bit for bit (tests/test_c_controller.py)."""
    from fmpy.validation import validate_fmu

    from twin.app.hosts import build

    assert validate_fmu(str(controller_unit)) == []
    log = _reference(duration_s=6.0)
    controller = build(f"fmu:{controller_unit}", Parameters())
    got = run_closed_loop(controller, x0_m=0.14, theta0_rad=-0.2, duration_s=6.0, seed=0)
    assert np.array_equal(got.log.aout, log.aout) and got.verdict.held


def test_the_twin_unit_and_the_controller_unit_alone_reach_ballbeam_runs_verdict(
    unit: Path, controller_unit: Path
) -> None:
    """FMPy alone steps both units (no ballbeam loop): at each communication point the controller gets the rig's
    readings and steps, the rig gets its command and steps. The commands and the true state are the run's bit
    for bit, so the verdict is."""
    from twin.engine import judge
    from twin.verdict import Trace

    log = _reference(duration_s=8.0)
    rig = Driver(unit)
    rig.start(0.14, -0.2, 0)
    ctl = Driver(controller_unit, "controller")
    ctl.fmu.enterInitializationMode()
    ctl.fmu.exitInitializationMode()
    rows, commands = [], []
    for k in range(len(log.aout)):
        rows.append(rig.outputs())
        ctl.fmu.setFloat64([ctl.vr["ball_v"], ctl.vr["angle_v"]], rows[-1][1:3])
        ctl.fmu.doStep(0.02 * k, 0.02)
        commands.append(ctl.fmu.getFloat64([ctl.vr["dac_v"]])[0])
        if k < len(log.aout) - 1:
            rig.step(commands[-1])
    table = np.array(rows)
    _same(table, log)
    assert np.array_equal(commands, log.aout)
    ours = run_closed_loop(registry.make("appendix-sf"), x0_m=0.14, theta0_rad=-0.2, duration_s=8.0, seed=0)
    theirs = judge(
        Parameters(),
        Trace(
            table[:, 0], table[:, 3], table[:, 4], log.motor_volts_v, np.array([ours.verdict.peak_theta_rad])
        ),
        x0_m=0.14,
        ball_lost_time_s=None,
    )
    assert theirs.to_json() == ours.verdict.to_json()


HOSTILE_UNITS = {
    "error_status": ("if (u->steps == 10) return fmi3Error;", r"fmi3DoStep|Error|error"),
    "nan": ("u->dac_v = u->steps == 10 ? NAN : 2.5;", r"nan"),
    "crash": ("if (u->steps == 10) raise(SIGSEGV);", r"process ended \(signal SIGSEGV\)"),
    "exit": ("if (u->steps == 10) exit(3);", r"process ended \(exit code 3\)"),
    "hang": ("if (u->steps == 10) for (;;) { }", r"did not return within"),
}


@pytest.mark.parametrize("name", sorted(HOSTILE_UNITS))
def test_a_failing_controller_unit_fails_its_run_naming_the_tick(name: str, tmp_path: Path) -> None:
    from fmu_units import hostile_unit

    from twin.app.hosts import build
    from twin.engine import ControllerError

    body, message = HOSTILE_UNITS[name]
    spec = f"fmu:{hostile_unit(tmp_path, name, body)}"
    with pytest.raises(ControllerError, match=message) as caught:
        run_closed_loop(build(spec, Parameters()), x0_m=0.1, theta0_rad=0.0, duration_s=2.0)
    assert "tick k = " in str(caught.value)


@pytest.mark.quick
def test_a_unit_without_the_conventions_variables_is_refused_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from cli_checks import refused
    from fmu_units import FMU_DIR, hostile_unit

    renamed = (FMU_DIR / "modelDescription.xml").read_text().replace('name="dac_v"', 'name="command_v"')
    spec = f"fmu:{hostile_unit(tmp_path, 'renamed', '', renamed)}"
    refused(capsys, ["run", "--controller", spec, "--x0", "0", "--theta0", "0"], "no variable 'dac_v'")
    refused(capsys, ["run", "--controller", "fmu:/no/such.fmu", "--x0", "0", "--theta0", "0"], "no such FMU")


@pytest.mark.quick
def test_the_controller_process_frames_and_names_are_the_documented_ones(tmp_path: Path) -> None:
    """twin.fmi.host's request is four doubles (time, step, ball_v, angle_v); the convention's names; a file that
    is no FMU is refused by the process, saying so."""
    from twin.fmi import host
    from twin.fmi.controller import FmuController, FmuError

    assert host.REQUEST.format == "<4d" and host.INPUTS == ("ball_v", "angle_v") and host.OUTPUT == "dac_v"
    with pytest.raises(FmuError, match="no such FMU"):
        FmuController(tmp_path / "missing.fmu")
    junk = tmp_path / "junk.fmu"
    junk.write_bytes(b"not a zip")
    with pytest.raises(FmuError, match="junk.fmu: "):
        FmuController(junk)


@pytest.mark.quick
def test_an_export_from_a_calibration_starts_at_its_values_with_their_uncertainties(tmp_path: Path) -> None:
    import zipfile

    cal = tmp_path / "cal"
    cal.mkdir()
    Parameters().with_overrides({"motor.resistance_ohm": 9.1}).save(cal / "params.toml")
    (cal / "calibration.json").write_text(
        json.dumps({"params": {"motor.resistance_ohm": {"value": 9.1, "sd": 0.05}}})
    )
    out = tmp_path / "MyRig.fmu"
    assert main(["export-fmu", "--out", str(out), "--calibration", str(cal)]) == 0
    with zipfile.ZipFile(out) as z:
        rig = json.loads(z.read("resources/rig.json"))
    assert rig["values"]["motor"]["resistance_ohm"] == 9.1 and rig["source"].startswith("--calibration")
    assert rig["declared"]["motor.resistance_ohm"]["source"].startswith(
        "calibrated (standard uncertainty 0.05); "
    )
    starts = {v.name: v.start for v in fmpy.read_model_description(str(out)).modelVariables}
    assert float(starts["motor.resistance_ohm"]) == 9.1
    assert main(["export-fmu", "--out", str(out), "--calibration", str(cal)]) == 2  # kept: no --overwrite


@pytest.mark.quick
def test_a_helper_process_that_ends_or_hangs_is_told_not_fatal() -> None:
    """twin.childproc.Child: an exit is named with its code, a signal with its name, silence with the deadline."""
    import sys

    from twin.childproc import Child

    def child(code: str, timeout_s: float = 5.0) -> Child:
        return Child(
            [sys.executable, "-c", code], name="probe", what="the probe", error=OSError, timeout_s=timeout_s
        )

    with pytest.raises(OSError, match=r"^probe: the probe ended \(exit code 3\)$"):
        child("import sys; sys.exit(3)").read(1)
    with pytest.raises(OSError, match=r"\(signal SIGSEGV\)"):
        child("import os, signal; os.kill(os.getpid(), signal.SIGSEGV)").read(1)
    quiet = child("import time; time.sleep(30)", timeout_s=0.2)
    with pytest.raises(OSError, match="did not answer within 0.2 s"):
        quiet.read(1)
    quiet.close()
    echo = child("import sys; sys.stdout.buffer.write(b'OK\\n'); sys.stdout.flush()")
    assert echo.line() == b"OK"
    echo.close()


def test_a_controller_unit_drives_a_served_rig_and_the_live_view(
    controller_unit: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``run --rig udp://…`` with ``fmu:…`` (the served twin: a session over the wire) holds the ball; the live
    view runs the unit as it runs any controller, the same commands as ``ballbeam run``."""
    import subprocess
    import sys

    from twin.app.hosts import catalogue_for
    from twin.engine import update_ticks
    from twin.viewer import LiveTwin

    spec = f"fmu:{controller_unit}"
    start = ["--x0", "0.14", "--theta0", "-0.2", "--duration", "8", "--seed", "0", "--wait-client", "60"]
    serve = [sys.executable, "-m", "twin.app.cli", "serve", *start, "--json"]
    server = subprocess.Popen(serve, stdout=subprocess.PIPE, text=True)
    assert server.stdout is not None
    url = json.loads(server.stdout.readline())["serving_on"]
    assert main(["run", "--rig", url, "--controller", spec, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["held"] and summary["ended"] == "last sample" and summary["ticks"] == 402
    server.communicate(timeout=60)
    p = Parameters()
    live = LiveTwin(p, catalogue_for(spec, p), spec, seed=0, speed=1.0)
    for _ in range(update_ticks(2.0, p)):
        live.tick()
    reference = run_closed_loop(registry.make("appendix-sf"), x0_m=live.x0_m, theta0_rad=live.theta0_rad,
                                duration_s=2.0, seed=0)  # fmt: skip
    assert np.array_equal(live.loop.log().aout, reference.log.aout)
    live.close()
