"""The rig behind an FMI unit, whatever its FMI version: its variables, its start and its step.

``ballbeam_fmu.py`` (FMI 3.0, pythonfmu3) and ``ballbeam_fmu2.py`` (FMI 2.0, pythonfmu) are the scripts
``ballbeam export-fmu`` packs; each registers ``RigUnit``'s variables with its library's classes and hands it
the FMI calls. The convention (one step of the DAQ's period is one tick of the engine ``ballbeam run`` uses) is
in the manual, docs/connect.md: "The twin as an FMU".
"""

from __future__ import annotations

import atexit
import ctypes
import functools
import json
import math
import os
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["OUTPUTS", "RIG_FILE", "STEP_TOLERANCE", "RigUnit", "Variable", "release_state_at_exit"]

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
    (
        "motor_v",
        "V",
        "volts across the motor over the step just taken (after the DAC and the amplifier's rails)",
    ),
)
FLAGS = (("ball_lost", "the ball left the track"), ("at_stops", "the beam at its stops"))


_RELEASED: set[str] = set()  # the libraries whose state is released at exit (one hook each)


def release_state_at_exit(resources: str | Path, identifier: str) -> None:
    """Make the unit's library release its interpreter state when the importer's Python exits.

    pythonfmu's library (both versions) keeps that state in a static ``std::shared_ptr`` which the C++ runtime
    destroys at the process's exit, after which the library's unload hook (``finalizePythonInterpreter``) assigns
    to it again: a use after free, "corrupted double-linked list" and an abort in an importer whose own Python
    loaded the unit and outlives it (FMPy's ``simulate_fmu``, twice in one process). Called first, from the
    importer's exit handlers, that function leaves a null pointer, which the later destruction and hook leave
    alone. Not when the library started Python itself (a host that is no Python program): its own thread ends
    Python then, and the hook would wait for that very thread."""
    if threading.main_thread().native_id != os.getpid():
        return  # Python runs in the library's thread: it is the library's, not the importer's
    for lib in sorted((Path(resources).parent / "binaries").glob(f"*/{identifier}.*")):
        key = str(lib.resolve())
        if key in _RELEASED:
            continue
        try:
            loaded = ctypes.CDLL(
                key, mode=os.RTLD_NOLOAD
            )  # the importer's copy, if this is the one it loaded
        except OSError:
            continue
        _RELEASED.add(key)
        atexit.register(loaded.finalizePythonInterpreter)


@dataclass(frozen=True)
class Variable:
    """One variable of the unit: ``kind`` float, int or bool; ``causality`` parameter, input or output."""

    name: str
    kind: str
    causality: str
    unit: str
    description: str


class RigUnit:
    """The values an FMU's variables read and write, and the rig they drive."""

    def __init__(self, resources: str | Path) -> None:
        rig = json.loads((Path(resources) / RIG_FILE).read_text())
        self.version: str = rig["version"]
        self.source: str = rig["source"]
        self.exported: dict[str, dict[str, Any]] = rig["values"]
        self.values: dict[str, Any] = {"x0_m": 0.0, "theta0_rad": 0.0, "seed": 0, "noise": True}
        self.values["dac_v"] = float(self.exported["amplifier"]["zero_command_v"])
        for name, _, _ in OUTPUTS:
            self.values[name] = math.nan
        for name, _ in FLAGS:
            self.values[name] = False
        declared: dict[str, dict[str, str]] = rig["declared"]
        self.variables = [
            Variable("x0_m", "float", "parameter", "m", "initial ball position (held, released at t = 0)"),
            Variable("theta0_rad", "float", "parameter", "rad", "initial beam angle"),
            Variable("seed", "int", "parameter", "", "the ball sensor's contact-noise seed"),
            Variable("noise", "bool", "parameter", "", "the ball sensor's contact noise on"),
        ]
        for group, items in self.exported.items():
            for field, value in items.items():
                if isinstance(value, (list, str)):
                    continue  # the measured curves and the parts' names stay as exported
                name = f"{group}.{field}"
                self.values[name] = value
                kind = "bool" if isinstance(value, bool) else "int" if isinstance(value, int) else "float"
                info = declared.get(name, {})
                unit = info.get("unit", "") if kind == "float" else ""
                self.variables.append(Variable(name, kind, "parameter", unit, info.get("source", "")[:300]))
        self.variables.append(
            Variable(
                "dac_v",
                "float",
                "input",
                "V",
                "the DAC command (0…5 V; 2.5 V: the motor off), held over the step",
            )
        )
        self.variables += [Variable(name, "float", "output", unit, text) for name, unit, text in OUTPUTS]
        self.variables += [Variable(name, "bool", "output", "", text) for name, text in FLAGS]
        self.period_s = float(self.exported["daq"]["period_s"])
        self._sim: Any = None

    @property
    def description(self) -> str:
        return (
            f"The ball-and-beam rig's twin, ballbeam-twin {self.version}; parameters: {self.source}. One step of "
            f"{self.period_s} s is one DAQ tick; dac_v is held over the step."
        )

    def build_variables(
        self,
        kinds: Mapping[str, Any],
        causality: Mapping[str, Any],
        variability: Mapping[str, Any],
        units: bool,
    ) -> list[Any]:
        """Each variable as an FMI library's classes build it: ``kinds`` maps float/int/bool to its classes,
        ``causality`` and ``variability`` map a causality to its enums; ``units``: floats carry their unit. Reads
        and writes go to ``values`` (outputs are not written)."""
        values = self.values
        out = []
        for v in self.variables:
            setter: Callable[[Any], None] | None = None
            if v.causality != "output":
                setter = functools.partial(values.__setitem__, v.name)
            unit = {"unit": v.unit} if units and v.kind == "float" and v.unit not in ("", "-") else {}
            out.append(
                kinds[v.kind](
                    v.name,
                    causality=causality[v.causality],
                    variability=variability[v.causality],
                    description=v.description,
                    getter=functools.partial(values.__getitem__, v.name),
                    setter=setter,
                    **unit,
                )
            )
        return out

    def units(self) -> list[str]:
        return sorted({v.unit for v in self.variables if v.unit not in ("", "-")})

    def start(self) -> None:
        """Initialization's end: the rig from the exported values and what the importer set, held at the start,
        and the start block read (the outputs)."""
        from twin.parameters import Parameters
        from twin.rigs.sim import TwinRig

        flat = {f"{g}.{f}": v for g, items in self.exported.items() for f, v in items.items()}
        params = Parameters().with_overrides(flat, origin="the FMU's export")
        changed = {
            name: self.values[name]
            for name in flat
            if name in self.values and self.values[name] != flat[name]
        }
        if changed:
            params = params.with_overrides(changed, origin="the FMU's parameters")
        self.period_s = params.period_s
        self._stop_rad = params.beam.stop_angle_rad
        v = self.values
        self._sim = TwinRig(params, seed=int(v["seed"]), noise=bool(v["noise"]))
        self._sim.reset(float(v["x0_m"]), float(v["theta0_rad"]))
        self._show(self._sim.read())

    def step(self, current_time: float, step_size: float) -> str | None:
        """One tick: ``dac_v`` written and held, the next block read. The reason when refused, else ``None``."""
        if self._sim is None:
            return "a step before initialization"
        if abs(step_size - self.period_s) > STEP_TOLERANCE * self.period_s:
            return f"a step of {step_size!r} s refused: one step is one DAQ period, {self.period_s!r} s"
        try:
            self._sim.write(float(self.values["dac_v"]))
        except ValueError as exc:
            return f"dac_v = {self.values['dac_v']!r} refused at t = {current_time!r} s: {exc}"
        self._show(self._sim.read())
        return None

    def _show(self, sample: Any) -> None:
        sim, v = self._sim, self.values
        v["time_s"], v["ball_v"], v["angle_v"] = sample.time_s, sample.ball_v, sample.angle_v
        v["x_m"], v["theta_rad"], v["xdot_m_s"], v["thetadot_rad_s"] = (float(x) for x in sim.true_state())
        v["motor_v"] = sim.motor_volts_v
        v["ball_lost"] = bool(sim.ball_lost)
        v["at_stops"] = abs(v["theta_rad"]) >= self._stop_rad
