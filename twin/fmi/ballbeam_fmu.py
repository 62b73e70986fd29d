"""The rig as an FMI 3.0 co-simulation unit: the script ``ballbeam export-fmu`` packs into ``BallBeam.fmu``
(pythonfmu3 wraps it in its FMI library; the importer's Python must have ``ballbeam-twin`` installed).

One ``doStep`` of the DAQ's period is one tick of the engine ``ballbeam run`` uses (``twin.rigs.sim.TwinRig``):
the input ``dac_v`` set at a communication point is the command answering the block read there, written to the
card and held over the step as the card holds it; the step reads the next block. The outputs are that block's
two readings (``ball_v``: the ball channel's last sample, ``angle_v``: the angle channel's mean, as the software
reads them, Table 6.4), its time stamp, and, separately, the true state at the block's end, the motor volts and
the ball-lost and at-stops flags. After initialization the outputs are the start block's (the held rig that
the software's Start reads); FMU time 0 is that block's end. A step of any other size than ``daq.period_s`` is
refused (``fmi3Error``). The rig's parameters are the unit's parameters, with the values it was exported with
(``resources/rig.json``, which also names their source and the exporting version).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from pythonfmu3 import (
    Boolean,
    Float64,
    Fmi3Causality,
    Fmi3Slave,
    Fmi3Status,
    Fmi3StepResult,
    Fmi3Variability,
    Int64,
    Unit,
)

RIG_FILE = "rig.json"
# How far a step may differ from the period and still be the period (the importer's sums of steps).
STEP_TOLERANCE = 1e-9
OUTPUTS = (
    ("time_s", "s", "the block's time stamp: its last sample, from release (the software's time(blocksize))"),
    ("ball_v", "V", "ball channel: the block's last sample, ADC volts (data(blocksize,1))"),
    ("angle_v", "V", "angle channel: the block's mean, ADC volts (mean(data(:,2)))"),
    ("x_m", "m", "true ball position along the beam at the block's end"),
    ("xdot_m_s", "m/s", "true ball velocity"),
    ("theta_rad", "rad", "true beam angle"),
    ("thetadot_rad_s", "rad/s", "true beam rate"),
    ("motor_v", "V", "volts across the motor now (after the DAC and the amplifier's rails)"),
)


class BallBeam(Fmi3Slave):
    """The ball-and-beam rig of the thesis: MuJoCo plant, motor, amplifier, sensor chains and the PCI-1712."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        rig = json.loads((Path(self.resources) / RIG_FILE).read_text())
        self.author = "ballbeam-twin"
        self.description = (
            f"The ball-and-beam rig's twin, ballbeam-twin {rig['version']}; parameters: {rig['source']}. One "
            f"doStep of {rig['values']['daq']['period_s']} s is one DAQ tick; dac_v is held over the step."
        )
        self.version = rig["version"]
        self._rig_values: dict[str, dict[str, Any]] = rig["values"]
        self._declared: dict[str, dict[str, str]] = rig["declared"]
        self._units: set[str] = set()
        self.time = 0.0
        self.register_variable(
            Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous)
        )
        # the start and the noise
        self.x0_m, self.theta0_rad, self.seed, self.noise = 0.0, 0.0, 0, True
        self._parameter("x0_m", "m", "initial ball position (held, released at t = 0)")
        self._parameter("theta0_rad", "rad", "initial beam angle")
        self.register_variable(
            Int64(
                "seed",
                causality=Fmi3Causality.parameter,
                variability=Fmi3Variability.fixed,
                description="the ball sensor's contact-noise seed",
            )  # fmt: skip
        )
        self.register_variable(
            Boolean(
                "noise",
                causality=Fmi3Causality.parameter,
                variability=Fmi3Variability.fixed,
                description="the ball sensor's contact noise on",
            )  # fmt: skip
        )
        # the rig's parameters, by their dotted names
        self._values: dict[str, Any] = {}
        for group, values in rig["values"].items():
            for name, value in values.items():
                if isinstance(value, list):
                    continue  # measured curves stay as exported
                self._rig_parameter(f"{group}.{name}", value)
        # the input, held over a step
        self.dac_v = float(rig["values"]["amplifier"]["zero_command_v"])
        self._unit("V")
        self.register_variable(
            Float64(
                "dac_v",
                causality=Fmi3Causality.input,
                variability=Fmi3Variability.discrete,
                unit="V",
                description="the DAC command (0…5 V; 2.5 V: the motor off), held over the step",
            )  # fmt: skip
        )
        for name, unit, text in OUTPUTS:
            setattr(self, name, math.nan)
            self._unit(unit)
            self.register_variable(
                Float64(
                    name,
                    causality=Fmi3Causality.output,
                    variability=Fmi3Variability.discrete,
                    unit=unit,
                    description=text,
                )  # fmt: skip
            )
        self.ball_lost, self.at_stops = False, False
        for name, text in (("ball_lost", "the ball left the track"), ("at_stops", "the beam at its stops")):
            self.register_variable(
                Boolean(
                    name,
                    causality=Fmi3Causality.output,
                    variability=Fmi3Variability.discrete,
                    description=text,
                )  # fmt: skip
            )
        self.register_units([Unit(name) for name in sorted(self._units)])
        self._sim: Any = None

    # --- declaring -------------------------------------------------------------------------------------------
    def _unit(self, unit: str) -> str | None:
        if unit in ("", "-"):
            return None
        self._units.add(unit)
        return unit

    def _parameter(self, name: str, unit: str, text: str) -> None:
        self.register_variable(
            Float64(
                name,
                causality=Fmi3Causality.parameter,
                variability=Fmi3Variability.fixed,
                unit=self._unit(unit),
                description=text,
            )  # fmt: skip
        )

    def _rig_parameter(self, name: str, value: Any) -> None:
        self._values[name] = value
        declared = self._declared.get(name, {})
        text = declared.get("source", "")
        kind = Boolean if isinstance(value, bool) else Int64 if isinstance(value, int) else Float64
        extra = {} if kind is not Float64 else {"unit": self._unit(declared.get("unit", ""))}
        self.register_variable(
            kind(
                name,
                causality=Fmi3Causality.parameter,
                variability=Fmi3Variability.fixed,
                description=text[:300],
                getter=lambda: self._values[name],
                setter=lambda v: self._values.__setitem__(name, v),
                **extra,
            ),
            nested=False,
        )

    # --- FMI ---------------------------------------------------------------------------------------------------
    def exit_initialization_mode(self) -> None:
        from twin.rigs.sim import TwinRig

        changed = {
            name: value
            for name, value in self._values.items()
            if value != self._rig_values[name.split(".")[0]][name.split(".")[1]]
        }
        params = _exported(self._rig_values)
        if changed:
            params = params.with_overrides(changed, origin="FMU parameters")
        self._period_s = params.daq.period_s
        self._stop_rad = params.beam.stop_angle_rad
        self._sim = TwinRig(params, seed=int(self.seed), noise=bool(self.noise))
        self._sim.reset(float(self.x0_m), float(self.theta0_rad))
        self._show(self._sim.read())

    def do_step(self, current_time: float, step_size: float) -> Fmi3StepResult:
        if self._sim is None:
            return Fmi3StepResult(status=Fmi3Status.error)
        if abs(step_size - self._period_s) > STEP_TOLERANCE * self._period_s:
            self.log(
                f"doStep of {step_size!r} s refused: one step is one DAQ period, {self._period_s!r} s",
                status=Fmi3Status.error,
            )
            return Fmi3StepResult(status=Fmi3Status.error)
        try:
            self._sim.write(float(self.dac_v))
        except ValueError as exc:
            self.log(
                f"dac_v = {self.dac_v!r} refused at t = {current_time!r} s: {exc}", status=Fmi3Status.error
            )
            return Fmi3StepResult(status=Fmi3Status.error)
        self._show(self._sim.read())
        self.time = current_time + step_size
        return Fmi3StepResult(status=Fmi3Status.ok)

    def _show(self, sample: Any) -> None:
        sim = self._sim
        self.time_s, self.ball_v, self.angle_v = sample.time_s, sample.ball_v, sample.angle_v
        self.x_m, self.theta_rad, self.xdot_m_s, self.thetadot_rad_s = (float(v) for v in sim.true_state())
        self.motor_v = sim.motor_volts_v
        self.ball_lost = bool(sim.ball_lost)
        self.at_stops = abs(self.theta_rad) >= self._stop_rad


def _exported(values: dict[str, dict[str, Any]]) -> Any:
    """The exported parameters (every value, the curves included) as ``twin.parameters.Parameters``."""
    from twin.parameters import Parameters

    flat = {f"{group}.{name}": value for group, items in values.items() for name, value in items.items()}
    return Parameters().with_overrides(flat, origin="the FMU's export")
