"""Every physical, electrical and numerical parameter of the rig, in one typed place.

Each field carries its unit and where its value comes from (thesis table or equation, physics, or a
measurement). Values are validated on construction: an impossible value raises ``ParameterError`` naming
the parameter and the value. Parameters can be overridden from code (``Parameters.with_overrides``) or
from a TOML/JSON file (``Parameters.from_file``); they reach the MuJoCo model only through
``twin.model.build_spec`` (``mujoco.MjSpec``), never by editing XML text.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any, TypeVar

from twin.image import open_regular

__all__ = [
    "ParameterError",
    "Ball",
    "Beam",
    "Track",
    "McuIo",
    "Motor",
    "Amplifier",
    "Physics",
    "AngleSensor",
    "BallSensor",
    "Daq",
    "SoftwareCalibration",
    "Start",
    "Parameters",
    "PartNames",
    "GROUPS",
    "all_groups",
    "choice",
    "register_group",
    "register_loop_period",
    "register_track_geometry",
    "TrackGeometry",
    "two_wires_geometry",
    "READING",
    "check_group",
    "declaration",
    "read_input_file",
    "within_bounds",
]


class ParameterError(ValueError):
    """An impossible or unknown parameter; the message names the parameter, the value and the source."""


class DuplicateKeyError(ParameterError):
    """A JSON object names a key twice (json.loads would keep the last value silently)."""


def _refuse_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            others = ", ".join(repr(k) for k in out if k != key)
            within = f" (beside {_clip(others, 60)})" if others else ""
            raise DuplicateKeyError(
                f"duplicate key {_clip(repr(key), 60)}{within}: a JSON object names it twice; keep one"
            )
        out[key] = value
    return out


def load_json(text: str) -> Any:
    """``json.loads`` that refuses an object naming a key twice (DuplicateKeyError naming the key), as TOML
    does: a parameter, criterion or spread given twice is a mistake, not an override."""
    return json.loads(text, object_pairs_hook=_refuse_duplicate_keys)


# A parameter file with every value and its comments is about 10 kB; anything past 1 MiB is not one, and is
# refused before it is parsed rather than read whole.
MAX_FILE_BYTES = 1 << 20
# A parameter file nests containers at most three deep: the file's table, a group's table, a curve's list
# (group → field → number or list of numbers). Deeper nesting is refused before it reaches the fields.
MAX_FILE_DEPTH = 3
# A block is reduced to its last sample and its mean (appendix A): it needs at least this many samples.
MIN_BLOCK_SAMPLES = 2
# Longest rendering of a value or a name in a message: a refused 1 MiB string or list is not echoed whole.
_SHOW_CHARS = 80
# Card-side voltages (ADC and DAC ranges, sensor and command volts): I/O cards read and write within ±10 V;
# ±100 V leaves room for a divider in front of the card and refuses a value typed in millivolts.
_CARD_V = 100.0
_CARD_V_WHY = "a card-side voltage: I/O cards read and write within ±10 V, ±100 V allows a divider in front"


def param(
    default: float,
    unit: str,
    source: str,
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    why: str = "",
    integer: bool = False,
) -> Any:
    """A dataclass field with its unit, provenance and admissible range; ``why`` gives the reason for the range
    (it is quoted when a value is refused); ``integer`` makes it a whole number (stored as ``int``)."""
    return field(
        default=default,
        metadata={
            "unit": unit,
            "source": source,
            "gt": gt,
            "ge": ge,
            "lt": lt,
            "le": le,
            "why": why,
            "integer": integer,
        },
    )


def curve(
    default: tuple[float, ...],
    unit: str,
    source: str,
    *,
    magnitude: float,
    why: str,
    optional: bool = False,
) -> Any:
    """A dataclass field holding a measured table column (a tuple of floats) with its unit and provenance;
    every value's magnitude is at most ``magnitude`` (reason: ``why``). An ``optional`` curve may also be empty
    (no measured curve: its part's own law holds)."""
    return field(
        default=default,
        metadata={
            "unit": unit,
            "source": source,
            "curve": True,
            "magnitude": magnitude,
            "why": why,
            "optional": optional,
        },
    )


def flag(default: bool, source: str) -> Any:
    """A boolean dataclass field (a switch) with its provenance."""
    return field(default=default, metadata={"unit": "on/off", "source": source, "flag": True})


def choice(default: str, source: str, *, why: str) -> Any:
    """A dataclass field naming an entry of a registry (a rig part by name: ``PartNames``); the registry that
    knows the names checks it (``twin.parts``), the group only that it is a name (``why``: what it names)."""
    return field(default=default, metadata={"unit": "name", "source": source, "choice": True, "why": why})


# A registry name: what a rig description may write for a part (letters, digits, '_' and '-', at most 40).
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,39}")


def _show(value: Any) -> str:
    """``repr(value)``, shortened for a message (a refused value may be a 1 MiB string or list)."""
    try:
        text = repr(value)
    except ValueError:  # an int too long to print (sys.get_int_max_str_digits)
        return f"<an integer of {value.bit_length()} bits>"
    return _clip(text)


def _clip(text: str, limit: int = _SHOW_CHARS) -> str:
    """A name or a parser's message for a message, shortened like ``_show``."""
    return text if len(text) <= limit else f"{text[: limit - 5]}…({len(text)} characters)"


_BOUNDS = (
    ("gt", lambda v, b: v > b, ">"),
    ("ge", lambda v, b: v >= b, ">="),
    ("lt", lambda v, b: v < b, "<"),
    ("le", lambda v, b: v <= b, "<="),
)


def _refuse(name: str, value: Any, unit: str, rule: str, why: str = "") -> ParameterError:
    """The one message format: ``group.field = value unit is impossible: it must be … (reason)``."""
    reason = f" ({why})" if why else ""
    return ParameterError(f"{name} = {_show(value)} {unit} is impossible: it must be {rule}{reason}")


def _check_fields(obj: Any, group: str) -> None:
    for f in fields(obj):
        value = getattr(obj, f.name)
        name = f"{group}.{f.name}"
        md = f.metadata
        if md.get("flag"):
            if not isinstance(value, bool):
                raise ParameterError(f"{name} = {_show(value)} is not true/false")
            continue
        if md.get("curve"):
            object.__setattr__(obj, f.name, _check_curve(name, value, md))
            continue
        if md.get("choice"):
            if not isinstance(value, str) or not _NAME.fullmatch(value):
                raise ParameterError(
                    f"{name} = {_show(value)} is not a name ({md['why']}: a letter, then letters, digits, "
                    f"'_' or '-', at most 40)"
                )
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"{name} = {_show(value)} is not a number")
        unit = md.get("unit", "")
        number = _whole(name, value, unit) if md.get("integer") else _finite(name, value, unit)
        for key, ok, word in _BOUNDS:
            bound = md.get(key)
            if bound is not None and not ok(number, bound):
                # A sign (> 0, >= 0) needs no reason; every other bound quotes the field's.
                why = "" if key in ("gt", "ge") and bound == 0 else md.get("why", "")
                shown = value if md.get("integer") else number
                raise _refuse(name, shown, unit, f"{word} {bound!r}", why)
        object.__setattr__(obj, f.name, number)


def _finite(name: str, value: int | float, unit: str) -> float:
    """``value`` as a finite float (an integer too large for a float is refused, not an OverflowError)."""
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if not math.isfinite(number):
        raise _refuse(name, value, unit, "finite")
    return number


def _whole(name: str, value: int | float, unit: str) -> int:
    """``value`` as an int: a whole float (12.0, as TOML/JSON may write it) is accepted, 12.5 is refused."""
    if isinstance(value, int):
        return int(value)
    if not math.isfinite(value):
        raise _refuse(name, value, unit, "finite")
    if not value.is_integer():
        raise _refuse(name, value, unit, "a whole number")
    return int(value)


def _check_curve(name: str, value: Any, md: Mapping[str, Any]) -> tuple[float, ...]:
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, (list, tuple)):
        raise ParameterError(f"{name} = {_show(value)} is not a list of numbers")
    out = []
    unit, magnitude = md.get("unit", ""), md["magnitude"]
    for i, item in enumerate(value):
        if isinstance(item, bool) or not isinstance(item, (int, float)):
            raise ParameterError(f"{name}[{i}] = {_show(item)} is not a finite number")
        try:
            number = float(item)
        except OverflowError:
            number = math.inf
        if not math.isfinite(number):
            raise ParameterError(f"{name}[{i}] = {_show(item)} is not a finite number")
        if abs(number) > magnitude:
            raise _refuse(f"{name}[{i}]", item, unit, f"within ±{magnitude!r}", md["why"])
        out.append(number)
    if len(out) < 2 and not (out == [] and md.get("optional")):
        none = " (or none)" if md.get("optional") else ""
        raise ParameterError(f"{name} has {len(out)} values: a curve needs at least 2 points{none}")
    return tuple(out)


# TOML text with its strings and comments blanked, then a dotted key of more than MAX_FILE_DEPTH parts (outside
# strings and comments a run of dots joined by bare words can only be a key: a number has at most one dot).
# tomllib's cost grows with the square of a dotted key's length (40 kB of "a.x.x…" take seconds), so such a key
# is refused before parsing. Possessive quantifiers keep the scan linear.
_TOML_STRINGS_AND_COMMENTS = re.compile(
    r'"""[\s\S]*?"""|\'\'\'[\s\S]*?\'\'\'|"(?:[^"\\\n]|\\.)*+"|\'[^\'\n]*+\'|#[^\n]*+'
)
_TOML_DEEP_KEY = re.compile(rf"(?<![\w-])[\w-]++(?:[ \t]*+\.[ \t]*+[\w-]++){{{MAX_FILE_DEPTH},}}")


def _toml_deep_key(text: str) -> int | None:
    """The line of a dotted key nested deeper than a parameter file, or None (see ``_TOML_DEEP_KEY``)."""
    # Each string or comment becomes a word of its own length, so offsets (and line numbers) are kept.
    blanked = _TOML_STRINGS_AND_COMMENTS.sub(lambda m: "s" * len(m.group(0)), text)
    match = _TOML_DEEP_KEY.search(blanked)
    return None if match is None else text.count("\n", 0, match.start()) + 1


def _file_depth_error(data: Any) -> str | None:
    """Where ``data`` (a parsed file) nests containers deeper than ``MAX_FILE_DEPTH``, or None.

    Iterative: a deeply nested value that the parser accepted must not raise RecursionError here."""
    stack: list[tuple[Any, str, int]] = [(data, "", 1)]
    while stack:
        obj, where, depth = stack.pop()
        if isinstance(obj, Mapping):
            items: Any = ((f"{where}.{k}" if where else str(k), v) for k, v in obj.items())
        elif isinstance(obj, list):
            items = ((f"{where}[{i}]", v) for i, v in enumerate(obj))
        else:
            continue
        if depth > MAX_FILE_DEPTH:
            return _clip(where)
        stack.extend((v, w, depth + 1) for w, v in items)
    return None


@dataclass(frozen=True)
class Ball:
    """The steel ball."""

    mass_kg: float = param(
        18.848e-3,
        "kg",
        "Table 3.1 (m)",
        gt=0.0,
        le=1.0,
        why="a bench-top rig's ball: 1 kg is a steel ball of 31 mm radius, 50x the thesis's; grams typed as kg "
        "are refused",
    )
    radius_m: float = param(
        8.329e-3,
        "m",
        "Table 3.1 (r)",
        gt=0.0,
        le=0.1,
        why="a ball rolling on two wires of a bench-top beam: 0.1 m is 12x the thesis's; millimetres typed as "
        "metres are refused",
    )

    def __post_init__(self) -> None:
        _check_fields(self, "ball")

    @property
    def inertia_kgm2(self) -> float:
        """Solid sphere, J = 2/5·m·r² (eq 3.1.21). Table 3.1's J = 0.455e-6 is not used by the thesis's
        equations and is not used here."""
        return 0.4 * self.mass_kg * self.radius_m**2


@dataclass(frozen=True)
class Beam:
    """The beam on its pivot P (without the ball)."""

    mass_kg: float = param(
        136.78e-3,
        "kg",
        "Table 3.1 (M_B)",
        gt=0.0,
        le=20.0,
        why="a bench-top beam: 20 kg is 150x the thesis's and more than a small motor can tilt",
    )
    inertia_pivot_kgm2: float = param(
        4e-3,
        "kg·m²",
        "Table 3.1 (J_BP), about the pivot axis",
        gt=0.0,
        le=10.0,
        why="a bench-top beam: 10 kg·m² is 20 kg at 0.7 m from the pivot, 2500x the thesis's",
    )
    cog_height_m: float = param(
        10.2e-3,
        "m",
        "Table 3.1 (h): centre of gravity above the pivot (destabilising, eq 3.1.27)",
        ge=-1.0,
        le=1.0,
        why="a bench-top beam's centre of gravity lies within 1 m of its pivot (negative: below it)",
    )
    stop_angle_rad: float = param(
        math.radians(43.4),
        "rad",
        "§3 (|θ| ≤ 43.4°): mechanical stops",
        gt=0.0,
        lt=math.pi / 2,
        why="a beam that tilts at all and stays short of vertical, where the ball falls off",
    )
    pivot_damping_nm_s_per_rad: float = param(
        0.0,
        "N·m·s/rad",
        "viscous friction of the pivot bearing; the thesis neglects it (§3.1), to be fitted from a rig log",
        ge=0.0,
        le=10.0,
        why="10 N·m·s/rad brakes the beam at 0.02 rad/s with the whole "
        "0.2 N·m the thesis's motor gives at 12 V: a seized bearing",
    )
    pivot_friction_nm: float = param(
        0.0,
        "N·m",
        "Coulomb (dry) friction of the pivot bearing; the thesis neglects it (§3.1), to be fitted from a rig log",
        ge=0.0,
        le=10.0,
        why="10 N·m is 50x the 0.2 N·m the thesis's motor gives at 12 V: a seized bearing",
    )
    track_offset_m: float = param(
        0.0,
        "m",
        "§3: the thesis's beam turns about its middle, under the track's centre (0). A beam hinged at one end "
        "(Quanser's BB01, Open Ball & Beam) has its track's centre this far out from the pivot along +x; the "
        "ball's position x stays measured from the track's centre",
        ge=-1.0,
        le=1.0,
        why="a bench-top beam is under 2 m long: its track's centre lies within 1 m of its pivot",
    )
    cog_along_m: float = param(
        0.0,
        "m",
        "§3: the thesis's beam's centre of gravity lies over its pivot (0, h above it). A beam hinged at one end "
        "has it this far out along +x from the pivot: its weight then loads the drive (M_B·g·x·cos θ)",
        ge=-1.0,
        le=1.0,
        why="a bench-top beam's centre of gravity lies within 1 m of its pivot",
    )

    def __post_init__(self) -> None:
        _check_fields(self, "beam")
        if self.inertia_pivot_kgm2 <= self.mass_kg * (self.cog_height_m**2 + self.cog_along_m**2):
            raise ParameterError(
                f"beam.inertia_pivot_kgm2 = {self.inertia_pivot_kgm2!r} kg·m² is impossible: it must exceed "
                f"M_B·(h² + x_g²) = {self.mass_kg * (self.cog_height_m**2 + self.cog_along_m**2):.6g} "
                "(parallel-axis theorem)"
            )

    @property
    def hinged_off_centre(self) -> bool:
        """Whether the beam turns elsewhere than under its track's centre and centre of gravity (the thesis's)."""
        return self.track_offset_m != 0.0 or self.cog_along_m != 0.0


@dataclass(frozen=True)
class Track:
    """The track: the thesis's two wires (h*, d, the wire's radius) and what every track has, its half length
    and its contacts' friction (another track's own shape is its part's group, ``twin.parts``)."""

    contact_height_m: float = param(
        17.281e-3,
        "m",
        "Table 3.1 (h*): the wires' contact line above the pivot",
        gt=0.0,
        le=1.0,
        why="the wires are above the pivot, within 1 m of it on a bench-top beam",
    )
    contact_spacing_m: float = param(
        13.785e-3,
        "m",
        "Table 3.1 (d): distance between the two contacts",
        gt=0.0,
        le=0.2,
        why="two separate contacts, closer than the largest ball's diameter (2 × 0.1 m); the ball's own "
        "diameter is checked with the ball",
    )
    half_length_m: float = param(
        0.323,
        "m",
        "§3: |x| ≤ 0.323 m, the ball leaves the track beyond",
        gt=0.0,
        le=5.0,
        why="a bench-top beam is at most 10 m long",
    )
    wire_radius_m: float = param(
        1.0e-3,
        "m",
        "not given in the thesis; only the contact geometry (h*, d) enters the dynamics",
        gt=0.0,
        le=0.1,
        why="a wire: no thicker than the largest ball (0.1 m)",
    )
    friction: float = param(
        1.0,
        "-",
        "not given; rolling without slipping (thesis §1) needs μ > ≈0.3 up to the 43.4° stop",
        gt=0.0,
        le=10.0,
        why="a friction coefficient: dry contacts rarely exceed 1.5; 10 is already no-slip for any tilt",
    )

    def __post_init__(self) -> None:
        _check_fields(self, "track")


@dataclass(frozen=True)
class Motor:
    """Escap 26L18-216 DC motor and its 1:7 gearbox (Table 3.2, §3.3)."""

    resistance_ohm: float = param(
        9.4,
        "Ω",
        "Table 3.2 (R)",
        gt=0.0,
        le=1000.0,
        why="a small DC motor's armature: 1 kΩ is 100x the Escap's and passes 12 mA at 12 V",
    )
    torque_constant_nm_per_a: float = param(
        0.022,
        "N·m/A",
        "Table 3.2 (K_t)",
        gt=0.0,
        le=10.0,
        why="10 N·m/A is a large industrial servo's, 450x the Escap's",
    )
    backemf_constant_v_s_per_rad: float = param(
        0.022,
        "V·s/rad",
        "Table 3.2 (K_b)",
        gt=0.0,
        le=10.0,
        why="equal to K_t in SI units: 10 V·s/rad is a large industrial servo's, 450x the Escap's",
    )
    gear_ratio: float = param(
        7.0,
        "-",
        "§3.3: gearbox 1:7 (N2/N1 in eq 3.3.1)",
        gt=0.0,
        le=1000.0,
        why="a gearbox: at 1:1000 the Escap's full speed (≈ 5 200 rpm at 12 V) turns the beam at 0.55 rad/s, too "
        "slow to catch the ball",
    )
    rotor_inertia_kgm2: float = param(
        8.5e-7,
        "kg·m²",
        "Table 3.2 (J_m), reflected ×N² to the beam; the thesis neglects it",
        ge=0.0,
        le=0.01,
        why="a small motor's rotor: 0.01 kg·m² is a 2 kg disc 10 cm in radius, 10⁴x the Escap's; g·cm² "
        "typed as kg·m² are refused",
    )
    viscous_damping_nm_s_per_rad: float = param(
        0.4e-6,
        "N·m·s/rad",
        "Table 3.2 (B_m), reflected ×N² to the beam; the thesis neglects it",
        ge=0.0,
        le=0.01,
        why="0.01 N·m·s/rad is 25000x the Escap's and 10 N·m of drag at 10 000 rpm",
    )
    inductance_h: float = param(
        0.8e-3,
        "H",
        "Table 3.2 (L); L/R = 85 µs ≪ 1 ms step, neglected as in §3.3",
        ge=0.0,
        le=1.0,
        why="a small motor's winding: 1 H is 1250x the Escap's",
    )
    continuous_current_a: float = param(
        0.76,
        "A",
        "Table 3.2 (I_a), a rating, not a limit",
        gt=0.0,
        le=100.0,
        why="a bench-top motor's rating: 100 A is 130x the Escap's",
    )

    def __post_init__(self) -> None:
        _check_fields(self, "motor")

    @property
    def torque_per_volt_nm_per_v(self) -> float:
        """N·K_t/R of eq 3.3.1: 0.016383 N·m/V at the beam."""
        return self.gear_ratio * self.torque_constant_nm_per_a / self.resistance_ohm

    @property
    def backemf_at_beam_v_s_per_rad(self) -> float:
        """N·K_b of eq 3.3.1: 0.154 V·s/rad at the beam."""
        return self.gear_ratio * self.backemf_constant_v_s_per_rad


@dataclass(frozen=True)
class Amplifier:
    """Power amplifier between the I/O card's DAC and the motor (§6.4)."""

    gain_v_per_v: float = param(
        9.6,
        "V/V",
        "§6.4: gain 9.6",
        gt=0.0,
        le=1000.0,
        why="a power amplifier: 1000 V/V takes a 1 mV command step to 1 V at the motor",
    )
    zero_command_v: float = param(
        2.5, "V", "§6.4: 2.5 V command gives 0 V at the motor", ge=-_CARD_V, le=_CARD_V, why=_CARD_V_WHY
    )
    rail_v: float = param(
        12.0,
        "V",
        "§6.4: ±12 V full scale across the motor",
        gt=0.0,
        le=1e6,
        why="1e6 V is the reproduction's stand-in for chapter 4's unlimited voltage "
        "(twin/app/reproduction); a real amplifier's rails are at most a few hundred volts",
    )

    def __post_init__(self) -> None:
        _check_fields(self, "amplifier")


@dataclass(frozen=True)
class Physics:
    """Numerical settings of the MuJoCo model: the values that make rolling on two wires exact (measured;
    docs/design.md)."""

    gravity_m_s2: float = param(
        9.81,
        "m/s²",
        "standard gravity, as used by the thesis",
        gt=0.0,
        le=100.0,
        why="100 m/s² is 10 g, beyond any place a bench-top rig stands",
    )
    timestep_s: float = param(
        1e-3,
        "s",
        "measured: 1 ms with implicitfast keeps rolling on two wires exact (docs/design.md)",
        ge=1e-5,
        le=0.02,
        why="at most one 20 ms control period; at 10 µs a 15 s run is already 1.5 million MuJoCo steps",
    )
    contact_timeconst_s: float = param(
        2e-3,
        "s",
        "measured: solref time constant = 2·timestep, stiff enough that the ball does not sink (docs/design.md)",
        gt=0.0,
        le=0.1,
        why="the contact's stiffness falls as 1/τ²: the ball rests 0.35 µm deep at 2 ms and about 1 mm deep "
        "at 0.1 s, sinking into the wires beyond",
    )
    contact_impedance: float = param(
        0.99,
        "-",
        "MuJoCo solimp d (dmin = dmax): 0.99 instead of the default 0.9-0.95 makes the no-slip friction 10x "
        "harder; with 0.9 the soft friction lets the ball creep (linearization off by 2 % in ∂ẍ/∂θ̇)",
        gt=0.0,
        lt=1.0,
        why="MuJoCo's solimp impedance lies strictly between 0 and 1",
    )
    contact_margin_m: float = param(
        3.495e-7,
        "m",
        "measured: rest penetration of the ball on the wires with no margin at the default timestep, "
        "time constant and impedance (twin.model.measure_rest_gap_m; tests/test_model.py keeps it current)",
        ge=0.0,
        le=1e-3,
        why="a margin is a contact's rest penetration (0.35 µm here); 1 mm would float the ball visibly "
        "above the wires",
    )

    def __post_init__(self) -> None:
        _check_fields(self, "physics")
        if self.contact_timeconst_s < 2 * self.timestep_s:
            raise ParameterError(
                f"physics.contact_timeconst_s = {self.contact_timeconst_s!r} s is impossible: MuJoCo needs at "
                f"least 2·timestep = {2 * self.timestep_s!r} s"
            )


@dataclass(frozen=True)
class AngleSensor:
    """Beam-angle chain (§6.2): motor encoder → 10-bit up/down counter → AD561 DAC → I/O card ADC."""

    encoder_pulses_per_rev: int = param(
        256,
        "pulses/rev",
        "§6.2: HEDS 5540, 256 pulses per turn",
        ge=1,
        le=100_000,
        why="whole pulses; optical encoders have up to ≈ 10 000 lines (40 000 edges in quadrature)",
        integer=True,
    )
    counter_bits: int = param(
        10,
        "bit",
        "§6.2: 10-bit counter (three 74LS193, top 2 bits unused)",
        ge=1,
        le=16,
        why="a counter of whole bits; the twin tabulates the DAC's level for each of its 2**bits counts, and "
        "16 bits (four 74LS193) is already 65 536 levels",
        integer=True,
    )
    counter_zero_count: int = param(
        512,
        "count",
        "§6.6: counters set to 512 at 0° by the zero switch",
        ge=0,
        le=2**16 - 1,
        why="a value the counter can hold: 0 … 2**angle_sensor.counter_bits − 1",
        integer=True,
    )
    dac_volts_per_count: float = param(
        0.009818,
        "V/count",
        "eq 6.2.6 (fit of the measured eq 6.2.4)",
        gt=0.0,
        le=_CARD_V,
        why="one count's step within the card-side ±100 V (the AD561's is 9.8 mV)",
    )
    dac_offset_v: float = param(
        -5.042, "V", "eq 6.2.6: Va at DI = 0 (measured, eq 6.2.4)", ge=-_CARD_V, le=_CARD_V, why=_CARD_V_WHY
    )
    zeroing_error_rad: float = param(
        0.0,
        "rad",
        "Fig 7.20: beam angle at which the counter was zeroed (0 = beam level)",
        ge=-math.pi / 2,
        le=math.pi / 2,
        why="the beam is zeroed short of vertical (it has stops at ±43.4°)",
    )

    def __post_init__(self) -> None:
        _check_fields(self, "angle_sensor")
        top = 2**self.counter_bits - 1
        if self.counter_zero_count > top:
            raise _refuse(
                "angle_sensor.counter_zero_count",
                self.counter_zero_count,
                "count",
                f"<= {top}",
                f"2**angle_sensor.counter_bits − 1: the largest value a {self.counter_bits}-bit counter holds",
            )


@dataclass(frozen=True)
class BallSensor:
    """Ball-position chain (§6.3): resistive wire wiper → contact noise → RC low-pass → I/O card ADC.

    The static curve is the measured Table 6.3 (ball position against the volts read at the I/O card),
    interpolated piecewise linearly; the contact-noise numbers are not in the thesis (its Figs 6.10/6.11
    are not numeric): defaults are assumptions to be fitted from a rig log."""

    curve_position_m: tuple[float, ...] = curve(
        (-0.323, -0.30, -0.27, -0.24, -0.21, -0.18, -0.15, -0.12, -0.09, -0.06, -0.03, 0.0,
         0.03, 0.06, 0.09, 0.12, 0.15, 0.18, 0.21, 0.24, 0.27, 0.30, 0.323),
        "m",
        "Table 6.3: ball positions of the static calibration (measured on the rig), strictly increasing",
        magnitude=5.0,
        why="a position on a beam at most 10 m long",
    )  # fmt: skip
    curve_volts_v: tuple[float, ...] = curve(
        (-4.620, -4.410, -3.925, -3.460, -3.045, -2.620, -2.170, -1.747, -1.325, -0.895, -0.487, 0.0012,
         0.428, 0.840, 1.280, 1.716, 2.113, 2.470, 3.000, 3.460, 3.890, 4.340, 4.600),
        "V",
        "Table 6.3: volts measured at the I/O card for each position (not a straight line; eq 6.3.1 fits it)",
        magnitude=_CARD_V,
        why=_CARD_V_WHY,
    )  # fmt: skip

    rc_resistance_ohm: float = param(
        147.0,
        "Ω",
        "§6.3: low-pass filter resistor",
        gt=0.0,
        le=1e6,
        why="a filter resistor: 1 MΩ with the 22 µF capacitor is a 22 s time constant, a filter that passes "
        "nothing a 50 Hz loop could use",
    )
    rc_capacitance_f: float = param(
        22e-6,
        "F",
        "§6.3: low-pass filter capacitor",
        gt=0.0,
        le=1.0,
        why="a filter capacitor: 1 F with the 147 Ω resistor is a 147 s time constant; µF typed as F are "
        "refused",
    )
    dropout_rate_hz: float = param(
        5.0,
        "1/s",
        "assumed: rate of contact losses between ball and spring (§6.3), fit from a log",
        ge=0.0,
        le=1000.0,
        why="beyond one loss per millisecond (a physics step, 40 samples) the "
        "wiper is not a contact that sometimes opens but a wire that is never in contact, and the noise "
        "process's work and memory grow with the rate",
    )
    dropout_mean_duration_s: float = param(
        0.5e-3,
        "s",
        "assumed: mean duration of a contact loss, fit from a log",
        gt=0.0,
        le=1.0,
        why="a contact loss lasting longer than 1 s on average is a broken wire, not contact noise",
    )
    dropout_voltage_v: float = param(
        0.0,
        "V",
        "assumed: the open wiper floats to ground through the measurement circuit (Fig 6.9)",
        ge=-_CARD_V,
        le=_CARD_V,
        why=_CARD_V_WHY,
    )
    noise_enabled: bool = flag(True, "switch: False turns the contact noise off")

    def __post_init__(self) -> None:
        _check_fields(self, "ball_sensor")
        pos, volts = self.curve_position_m, self.curve_volts_v
        if len(pos) != len(volts):
            raise ParameterError(
                f"ball_sensor.curve_volts_v has {len(volts)} values but ball_sensor.curve_position_m has "
                f"{len(pos)}: one volt reading per position"
            )
        for i in range(1, len(pos)):
            if not pos[i] > pos[i - 1]:
                raise ParameterError(
                    f"ball_sensor.curve_position_m[{i}] = {pos[i]!r} m is impossible: positions must increase "
                    f"strictly (previous {pos[i - 1]!r} m)"
                )
        # A wiper's volts rise with its position, and the calibration reads a position back from the volts
        # by inverting the curve (calib.identify): volts that do not increase strictly have no inverse.
        for i in range(1, len(volts)):
            if not volts[i] > volts[i - 1]:
                raise ParameterError(
                    f"ball_sensor.curve_volts_v[{i}] = {volts[i]!r} V is impossible: the volts must increase "
                    f"strictly with the position (previous {volts[i - 1]!r} V), or the reading has no inverse"
                )


@dataclass(frozen=True)
class Daq:
    """Advantech PCI-1712 as the thesis software used it (Table 6.4, appendix A)."""

    sample_rate_hz: float = param(
        40000.0,
        "Hz",
        "Table 6.4: data acquisition rate",
        gt=0.0,
        le=1e6,
        why="the PCI-1712 samples at up to 1 MS/s; a block holds sample_rate × period samples and is "
        "allocated whole, so 1 MS/s × 1 s caps it at a million samples (8 MB a channel) instead of exhausting "
        "memory; at least 2 samples per block is checked with daq.period_s",
    )
    period_s: float = param(
        0.02,
        "s",
        "Table 6.4: timer period (control at 50 Hz)",
        ge=1e-3,
        le=1.0,
        why="a software timer's period: 1 ms is the finest a desktop timer fires (the thesis's ran at 20 ms); a "
        "loop slower than 1 s cannot hold this open-loop unstable rig",
    )
    adc_bits: int = param(
        12,
        "bit",
        "§6.5: 12-bit A/D",
        ge=1,
        le=24,
        why="a converter of whole bits; DAQ cards stop at 24 bits (the PCI-1712 has 12)",
        integer=True,
    )
    adc_min_v: float = param(
        -5.0, "V", "Table 6.4: analog input interval −5 V…5 V", ge=-_CARD_V, le=_CARD_V, why=_CARD_V_WHY
    )
    adc_max_v: float = param(
        5.0, "V", "Table 6.4: analog input interval −5 V…5 V", ge=-_CARD_V, le=_CARD_V, why=_CARD_V_WHY
    )
    dac_bits: int = param(
        12,
        "bit",
        "§6.5: 12-bit analog outputs",
        ge=1,
        le=24,
        why="a converter of whole bits; DAQ cards stop at 24 bits (the PCI-1712 has 12)",
        integer=True,
    )
    dac_min_v: float = param(
        0.0, "V", "Table 6.4: analog output interval 0…5 V", ge=-_CARD_V, le=_CARD_V, why=_CARD_V_WHY
    )
    dac_max_v: float = param(
        5.0, "V", "Table 6.4: analog output interval 0…5 V", ge=-_CARD_V, le=_CARD_V, why=_CARD_V_WHY
    )
    output_latency_s: float = param(
        0.0,
        "s",
        "assumed: delay from reading a block to the DAC update (computation time), 0…period",
        ge=0.0,
        le=1.0,
        why="shorter than daq.period_s (checked with it), itself at most 1 s",
    )

    def __post_init__(self) -> None:
        _check_fields(self, "daq")
        # (1e-9: a rate of exactly 2/period must not be refused for the rounding of the product)
        if self.sample_rate_hz * self.period_s < MIN_BLOCK_SAMPLES - 1e-9:
            raise _refuse(
                "daq.sample_rate_hz",
                self.sample_rate_hz,
                "Hz",
                f">= {MIN_BLOCK_SAMPLES / self.period_s!r}",
                f"at least {MIN_BLOCK_SAMPLES} samples in a daq.period_s = {self.period_s!r} s block: the "
                "software reads a block's last sample and its mean, and an empty block divides by zero",
            )
        if self.adc_max_v <= self.adc_min_v:
            raise ParameterError(
                f"daq.adc_max_v = {self.adc_max_v!r} V must exceed daq.adc_min_v = {self.adc_min_v!r} V"
            )
        if self.dac_max_v <= self.dac_min_v:
            raise ParameterError(
                f"daq.dac_max_v = {self.dac_max_v!r} V must exceed daq.dac_min_v = {self.dac_min_v!r} V"
            )
        if self.output_latency_s >= self.period_s:
            raise ParameterError(
                f"daq.output_latency_s = {self.output_latency_s!r} s is impossible: it must be shorter than "
                f"the period {self.period_s!r} s"
            )

    @property
    def block_size(self) -> int:
        """Samples per block: 40 kHz × 20 ms = 800 (appendix A: bsize = SampleRate·TimerPeriod)."""
        return int(round(self.sample_rate_hz * self.period_s))


@dataclass(frozen=True)
class SoftwareCalibration:
    """The rig software's conversion constants (appendix A), which controllers receive rather than import.

    These are the numbers typed into the MATLAB callbacks, not properties of the hardware: the hardware's
    own curves are ``ball_sensor`` and ``angle_sensor``. A controller converts the card's volts with these
    (twin.converters); the ideal sensors (twin.sensors.IdealSensors) invert them. A recalibrated rig
    changes them here instead of editing controller code."""

    ball_gain_m_per_v: float = param(
        0.0693,
        "m/V",
        "eq 6.3.1 / appendix A: x1 = 0.0693·V + 0.0018",
        gt=0.0,
        le=10.0,
        why="metres per card volt: 10 m/V sweeps a 10 m beam with 1 V, 140x the thesis's",
    )
    ball_offset_m: float = param(
        0.0018,
        "m",
        "eq 6.3.1 / appendix A: x1 = 0.0693·V + 0.0018",
        ge=-5.0,
        le=5.0,
        why="a position on a beam at most 10 m long",
    )
    angle_gain_deg_per_v: float = param(
        143.22657649,
        "deg/V",
        "eq 6.2.9–6.2.10 / appendix A: (360/256)/(5 kΩ·2.0108 mA/1024), motor degrees per volt",
        gt=0.0,
        le=1e5,
        why="700x the thesis's 143 °/V; the bound refuses unit mistakes (counts, arc minutes) more than it "
        "states a physical limit",
    )
    angle_reference_v: float = param(
        5.002,
        "V",
        "eq 6.2.4 / appendix A: measured DAC output at DI = 1023",
        ge=-_CARD_V,
        le=_CARD_V,
        why=_CARD_V_WHY,
    )
    angle_reference_motor_deg: float = param(
        718.59375,
        "deg",
        "§6.2 / appendix A: motor angle at DI = 1023, (1023 − 512)·360/256",
        ge=-(2**16 - 1) * 360.0,
        le=(2**16 - 1) * 360.0,
        why="a counter of at most 16 bits at 1 pulse per turn spans at most 65 535 motor turns",
    )
    angle_gear_ratio: float = param(
        7.0,
        "-",
        "appendix A: the literal '/ 7' (gearbox 1:7, §6.2)",
        gt=0.0,
        le=1000.0,
        why="as motor.gear_ratio: a gearbox of at most 1:1000",
    )
    software_pi: float = param(
        3.141592654,
        "-",
        "appendix A: x2 = x2_temp_2·(3.141592654/180), π as typed",
        gt=3.14,
        lt=3.15,
        why="π as typed, to two decimals at least",
    )
    command_gain_v_per_v: float = param(
        9.6,
        "V/V",
        "§6.4 / appendix A: adat = u/9.6 + 2.5",
        gt=0.0,
        le=1000.0,
        why="as amplifier.gain_v_per_v: a power amplifier's gain of at most 1000 V/V",
    )
    command_zero_v: float = param(
        2.5,
        "V",
        "§6.4 / appendix A: 2.5 V is zero volts at the motor",
        ge=-_CARD_V,
        le=_CARD_V,
        why=_CARD_V_WHY,
    )
    command_low_v: float = param(
        1.25,
        "V",
        "appendix A: adat clipped to 1.25…3.75 V (−12 V…+12 V)",
        ge=-_CARD_V,
        le=_CARD_V,
        why=_CARD_V_WHY,
    )
    command_high_v: float = param(
        3.75,
        "V",
        "appendix A: adat clipped to 1.25…3.75 V (−12 V…+12 V)",
        ge=-_CARD_V,
        le=_CARD_V,
        why=_CARD_V_WHY,
    )

    def __post_init__(self) -> None:
        _check_fields(self, "software")
        if not self.command_low_v < self.command_high_v:
            raise ParameterError(
                f"software.command_low_v = {self.command_low_v!r} V must be below "
                f"software.command_high_v = {self.command_high_v!r} V"
            )


@dataclass(frozen=True)
class Start:
    """How a run starts (appendix A's button sequence, §6.6): the rig is held at its initial state while the
    software reads it (Start, Clear Buffer), then Drive Motor is pressed and the rig released."""

    free_run_s: float = param(
        0.01,
        "s",
        "not in the thesis: time the released rig runs at 0 V before the first command reaches the amplifier. "
        "The timer callback that sends it fires 0…20 ms after Drive Motor is pressed (one 20 ms period, "
        "Table 6.4); 10 ms is the mean of that wait with the rig released at the press. 0 = released "
        "exactly when the first command arrives (as the thesis's simulations start)",
        ge=0.0,
        le=1.0,
        why="after 1 s the released rig has long fallen",
    )

    def __post_init__(self) -> None:
        _check_fields(self, "start")


@dataclass(frozen=True)
class McuIo:
    """An Arduino-class board in place of the PCI-1712 (firmware in the loop, ``twin.avr``): the analog front
    end that maps each ±5 V sensor signal onto the microcontroller's pin, its ADC, and the SPI DAC that drives
    the amplifier's 0…5 V command input. The thesis's rig has no such board: each value says where it comes
    from (a datasheet, or "assumed" with the reason)."""

    input_gain_v_per_v: float = param(
        0.5,
        "V/V",
        "assumed: a resistor divider halves each ±5 V sensor signal (the angle channel spans ±5 V, eq 6.2.4) so "
        "that, offset by input_offset_v, it spans the ADC's 0…5 V",
        gt=0.0,
        le=10.0,
        why="a front end that amplifies more than 10× saturates the pin on any sensor signal",
    )
    input_offset_v: float = param(
        2.5,
        "V",
        "assumed: the divider's foot at half the 5 V supply, so 0 V of signal reads mid-scale",
        ge=-5.0,
        le=5.0,
        why=_CARD_V_WHY,
    )
    adc_bits: int = param(
        10,
        "bit",
        "ATmega328P datasheet §24: a 10-bit successive-approximation ADC",
        ge=8,
        le=16,
        integer=True,
        why="microcontroller ADCs have 8 to 16 bits",
    )
    adc_reference_v: float = param(
        5.0,
        "V",
        "assumed: AVcc, an Arduino Uno's 5 V supply, as the reference (REFS0)",
        gt=0.0,
        le=5.5,
        why="the ATmega328P's reference may not exceed AVcc (5.5 V at most)",
    )
    dac_bits: int = param(
        12,
        "bit",
        "MCP4921 datasheet: a 12-bit SPI DAC",
        ge=8,
        le=16,
        integer=True,
        why="SPI DACs for this use have 8 to 16 bits",
    )
    dac_reference_v: float = param(
        5.0,
        "V",
        "assumed: the MCP4921's VREF tied to the 5 V supply, so its 0…5 V span is the amplifier's command range "
        "(§6.4: 2.5 V is 0 V at the motor)",
        gt=0.0,
        le=5.5,
        why="the MCP4921's VREF may not exceed its supply (5.5 V at most)",
    )

    clock_hz: int = param(
        16_000_000,
        "Hz",
        "an Arduino Uno's 16 MHz crystal (the ATmega328P's maximum at 5 V, datasheet §29); it must be the F_CPU "
        "the firmware was built with",
        ge=1_000_000,
        le=32_000_000,
        integer=True,
        why="AVR cores run at 1 to 32 MHz",
    )

    def __post_init__(self) -> None:
        _check_fields(self, "mcu_io")


@dataclass(frozen=True)
class PartNames:
    """Which part takes each place in the rig, by its registered name (``twin.parts``: the registry refuses a name
    it does not know for the role, naming the field). The defaults are the thesis's rig; a rig description
    (``twin.parts.description``) names others, each with its own parameter group (``register_group``)."""

    ball: str = choice("steel_ball", "Table 3.1: the thesis's steel ball", why="the ball's part")
    track: str = choice("two_wires", "§3, Table 3.1: two wires", why="the track's part")
    beam_drive: str = choice(
        "pivot", "§3: the beam turned at its pivot through the gearbox", why="how the beam is driven"
    )
    actuator: str = choice(
        "escap_dc_motor", "Table 3.2, §6.4: the Escap motor and its amplifier", why="the actuator's part"
    )
    ball_sensor: str = choice("resistive_wire", "§6.3: the resistive wire", why="the ball sensor's part")
    angle_sensor: str = choice(
        "encoder_counter", "§6.2: the encoder, counter and DAC", why="the angle sensor's part"
    )
    io_board: str = choice("pci1712", "Table 6.4: the Advantech PCI-1712", why="the I/O board's part")

    def __post_init__(self) -> None:
        _check_fields(self, "parts")


# The ball reading's gain and offset relative to the sensor curve, with their units: what a calibration fits of
# the ball channel beside the parameters; no field, folded into the curve (``Parameters.with_values``). Any
# value that leaves the curve increasing is physical, so they declare no bounds of their own.
READING: Mapping[str, str] = MappingProxyType({"ball_reading.gain": "-", "ball_reading.offset_m": "m"})

_GROUPS: dict[str, type] = {
    "ball": Ball,
    "beam": Beam,
    "track": Track,
    "motor": Motor,
    "amplifier": Amplifier,
    "physics": Physics,
    "angle_sensor": AngleSensor,
    "ball_sensor": BallSensor,
    "daq": Daq,
    "software": SoftwareCalibration,
    "start": Start,
    "mcu_io": McuIo,
}
# The parameter table's groups by name, read-only: each rig part points at its own (``twin.parts``).
GROUPS: Mapping[str, type] = MappingProxyType(_GROUPS)
# Which part takes each place: a group of names, beside the values (``Parameters.parts``).
PARTS_GROUP = "parts"

# The parameter groups of parts beyond the thesis's, registered by their part's module (``register_group``): a
# rig holds the values of those it has set (``Parameters.part_groups``), every other one reads as its defaults.
_PART_GROUPS: dict[str, type] = {}
G = TypeVar("G")


def register_group(name: str, cls: type[G]) -> type[G]:
    """Add a part's parameter group ``cls`` (a frozen dataclass of ``param``/``curve``/``flag``/``choice`` fields
    whose ``__post_init__`` calls ``check_group``) to the table under ``name``; returns ``cls``. A name the
    table has (the thesis's groups, ``parts``, a registered group) is refused, as is a class registered twice."""
    if not _NAME.fullmatch(name) or "-" in name:
        raise ParameterError(f"parameter group name {_show(name)} is not an identifier")
    if name in _GROUPS or name == PARTS_GROUP or name in _PART_GROUPS:
        raise ParameterError(f"parameter group '{name}' is in the table already")
    if cls in _PART_GROUPS.values() or cls in _GROUPS.values():
        raise ParameterError(f"{cls.__name__} is a parameter group already")
    cls()  # its defaults must make a valid group: refused here, not in a user's run
    _PART_GROUPS[name] = cls
    return cls


@dataclass(frozen=True)
class TrackGeometry:
    """Where the ball rides on a track, in the beam frame: all the dynamics and the plant read of a track.

    ``rolling_radius_m`` r*: the ball centre above its rolling axis, the line through its contacts (eq 3.1.13:
    ẋ = −r*·ω); ``axis_height_m`` h*: that axis above the pivot (the ball centre is h* + r* above it, eq
    3.1.3); ``lateral_limit_m``: the ball centre's sideways offset at which it has left the track;
    ``end_limit_m``: its |x| beyond which MuJoCo's plant counts it off the track's end (the reference model's
    test is |x| > ``track.half_length_m``, ``twin.reference.step_boundary``)."""

    rolling_radius_m: float
    axis_height_m: float
    lateral_limit_m: float
    end_limit_m: float


def two_wires_geometry(params: Parameters) -> TrackGeometry:
    """The thesis's two wires (Table 3.1: h*, d): the contacts d apart at h*, the ball centre r* = √(r² − d²/4)
    above their line; it leaves sideways past a wire (d/2) and off the end once past the wires' ends by its
    radius (where it has rolled over them). Refused unless d < 2r (the ball would fall between the wires)."""
    r, d = params.ball.radius_m, params.track.contact_spacing_m
    if d >= 2 * r:
        raise ParameterError(
            f"track.contact_spacing_m = {d!r} m is impossible: the ball (radius {r!r} m) falls between "
            f"the wires unless d < 2r = {2 * r!r} m"
        )
    return TrackGeometry(
        rolling_radius_m=math.sqrt(r * r - d * d / 4.0),
        axis_height_m=params.track.contact_height_m,
        lateral_limit_m=d / 2,
        end_limit_m=params.track.half_length_m + r,
    )


# Each track's geometry by its part's name (``Parameters.track_geometry``): the thesis's two wires here, the
# others registered by their part's module (``register_track_geometry``).
_TRACK_GEOMETRY: dict[str, Callable[[Parameters], TrackGeometry]] = {"two_wires": two_wires_geometry}


def register_track_geometry(name: str, geometry: Callable[[Parameters], TrackGeometry]) -> None:
    """The geometry of the track part ``name``: ``geometry(params)`` (raising ``ParameterError`` naming the field
    for a geometry the ball cannot ride, which ``Parameters`` then refuses on construction). A name registered
    with another function is refused."""
    if _TRACK_GEOMETRY.get(name, geometry) is not geometry:
        raise ParameterError(f"the track {name!r} has a geometry already")
    _TRACK_GEOMETRY[name] = geometry


# Each board's control period by its part's name (``Parameters.period_s``): "group.field" of the board's own
# group; a board not registered (the thesis's PCI-1712) ticks at ``daq.period_s``.
_LOOP_PERIOD: dict[str, str] = {}


def register_loop_period(board: str, name: str) -> None:
    """The board part ``board`` runs its control loop every ``name`` ("group.field", a period in seconds)."""
    if _LOOP_PERIOD.get(board, name) != name:
        raise ParameterError(f"the board {board!r} has a loop period already")
    _LOOP_PERIOD[board] = name


def all_groups() -> Mapping[str, type]:
    """Every parameter group by name: the thesis's (``GROUPS``), then the parts' registered ones."""
    return MappingProxyType({**_GROUPS, **_PART_GROUPS})


def check_group(obj: Any, group: str) -> None:
    """Check a parameter group's values as declared by its fields (``param``, ``curve``, ``flag``), naming
    ``group.field`` in the refusal: what each group's ``__post_init__`` calls, for a part's own group too."""
    _check_fields(obj, group)


def read_input_file(path: str | Path, what: str, typical: str = "") -> bytes:
    """The bytes of a small input file (``what``: "parameter file", "spread file"): a regular file of at most
    ``MAX_FILE_BYTES``. Anything else is a ``ParameterError`` naming the file, before it is parsed: a missing or
    unreadable file, a directory, a device or a pipe (``/dev/zero`` would be endless, a FIFO would wait for a
    writer), or a larger file (only ``MAX_FILE_BYTES`` + 1 bytes are read). ``typical``: the size such a file
    has, for the message."""
    path = Path(path)
    fd = open_regular(path, ParameterError, what, f"a {what} is a TOML or JSON text file")
    with os.fdopen(fd, "rb") as fh:
        try:
            text = fh.read(MAX_FILE_BYTES + 1)
        except OSError as exc:
            raise ParameterError(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    if len(text) > MAX_FILE_BYTES:
        note = f": {typical}" if typical else ""
        raise ParameterError(f"{path}: larger than {MAX_FILE_BYTES} bytes (1 MiB), not read further{note}")
    return text


def declaration(name: str) -> Mapping[str, Any]:
    """What the parameter ``group.field`` declares (``param``, ``curve``, ``flag``: its unit, source, physical
    bounds ``gt``/``ge``/``lt``/``le`` and their reason); for the ball reading's names (``READING``) their unit.
    An unknown name raises ``ParameterError`` naming it."""
    if name in READING:
        return MappingProxyType({"unit": READING[name]})
    group, _, field_name = name.partition(".")
    cls = _group_class(group)
    declared = {f.name: f.metadata for f in fields(cls)} if cls is not None else {}
    if field_name not in declared:
        raise ParameterError(f"unknown parameter '{_clip(name)}'")
    return declared[field_name]


def _group_class(group: str) -> type | None:
    """The class of the group ``group`` (the thesis's, ``parts`` or a part's registered one), None if unknown."""
    if group == PARTS_GROUP:
        return PartNames
    return _GROUPS.get(group) or _PART_GROUPS.get(group)


def _known_groups() -> list[str]:
    return sorted([*_GROUPS, PARTS_GROUP, *_PART_GROUPS])


def within_bounds(name: str, value: float) -> bool:
    """Whether ``value`` lies inside the physical bounds the parameter ``name`` declares (as a value is checked
    when a parameter group is built; a name without bounds admits every value)."""
    md = declaration(name)
    return all(md.get(key) is None or ok(value, md[key]) for key, ok, _ in _BOUNDS)


@dataclass(frozen=True)
class Parameters:
    """All parameters of the rig. Defaults are the thesis's values (see each field's ``source``)."""

    ball: Ball = field(default_factory=Ball)
    beam: Beam = field(default_factory=Beam)
    track: Track = field(default_factory=Track)
    motor: Motor = field(default_factory=Motor)
    amplifier: Amplifier = field(default_factory=Amplifier)
    physics: Physics = field(default_factory=Physics)
    angle_sensor: AngleSensor = field(default_factory=AngleSensor)
    ball_sensor: BallSensor = field(default_factory=BallSensor)
    daq: Daq = field(default_factory=Daq)
    software: SoftwareCalibration = field(default_factory=SoftwareCalibration)
    start: Start = field(default_factory=Start)
    mcu_io: McuIo = field(default_factory=McuIo)
    # Which part takes each place (the thesis's by default) and the values of the parts' own groups that differ
    # from their defaults' group, as (name, group) pairs sorted by name: hashable, so a rig stays a cache key.
    parts: PartNames = field(default_factory=PartNames)
    part_groups: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        for name, group in self.part_groups:
            cls = _PART_GROUPS.get(name)
            if cls is None or type(group) is not cls:
                raise ParameterError(f"part_groups: '{_clip(str(name))}' is not a registered part's group")
        geometry = _TRACK_GEOMETRY.get(self.parts.track)
        if geometry is not None:
            geometry(self)  # the track's own checks (the two wires: d < 2r), naming its fields

    # --- the parts' groups ------------------------------------------------------------------------
    def group(self, name: str) -> Any:
        """The group ``name``: the thesis's, ``parts``, or a part's registered one (its values here, else its
        defaults). An unknown name raises ``ParameterError``."""
        if name in _GROUPS or name == PARTS_GROUP:
            return getattr(self, name)
        cls = _PART_GROUPS.get(name)
        if cls is None:
            raise ParameterError(
                f"unknown parameter group '{_clip(name)}' (expected one of {_known_groups()})"
            )
        return dict(self.part_groups).get(name) or cls()

    def of(self, cls: type[G]) -> G:
        """A part's registered group by its class (typed): its values here, else its defaults."""
        for name, registered in _PART_GROUPS.items():
            if registered is cls:
                group: G = self.group(name)
                return group
        raise ParameterError(f"{cls.__name__} is not a registered parameter group")

    @property
    def period_s(self) -> float:
        """The control loop's period: the board's and its controller's (``register_loop_period``: an Arduino's
        ``arduino.loop_period_s``), ``daq.period_s`` on the thesis's PCI-1712. The rig ticks at it."""
        group, field_name = self.period_field.split(".", 1)
        return float(getattr(self.group(group), field_name))

    @property
    def period_field(self) -> str:
        """The name of the field ``period_s`` reads ("daq.period_s", "arduino.loop_period_s"): what a message
        about the period names."""
        return _LOOP_PERIOD.get(self.parts.io_board, "daq.period_s")

    # --- derived geometry -------------------------------------------------------------------------
    @property
    def track_geometry(self) -> TrackGeometry:
        """Where the ball rides on the track ``parts.track`` names (its registered geometry,
        ``register_track_geometry``; the thesis's two wires: ``two_wires_geometry``)."""
        geometry = _TRACK_GEOMETRY.get(self.parts.track)
        if geometry is None:
            raise ParameterError(
                f"parts.track = {self.parts.track!r}: no track geometry of that name is registered (there are: "
                f"{sorted(_TRACK_GEOMETRY)}; a track's module under twin.parts registers its own)"
            )
        return geometry(self)

    @property
    def rolling_radius_m(self) -> float:
        """r*: height of the ball centre above the line through its contacts, about which it rolls (the two
        wires: √(r² − d²/4); each track's own, ``track_geometry``).

        Table 3.1 prints 4.264 mm; its own formula gives 4.676 mm, which the thesis's derived numbers use."""
        return self.track_geometry.rolling_radius_m

    @property
    def rolling_axis_height_m(self) -> float:
        """h*: the line through the ball's contacts (its rolling axis) above the pivot, in the beam frame (Table
        3.1's h* for the two wires: ``track.contact_height_m``)."""
        return self.track_geometry.axis_height_m

    @property
    def ball_centre_height_m(self) -> float:
        """h* + r*: the ball centre above the pivot, in the beam frame (eq 3.1.3)."""
        geometry = self.track_geometry
        return geometry.axis_height_m + geometry.rolling_radius_m

    @property
    def rolling_inertia_ratio(self) -> float:
        """2r²/(5r*²): rotational over translational inertia of the ball rolling on two wires (eq 3.1.26)."""
        return 0.4 * self.ball.radius_m**2 / self.rolling_radius_m**2

    # --- overrides and files ----------------------------------------------------------------------
    def with_overrides(self, overrides: Mapping[str, Any], *, origin: str = "overrides") -> Parameters:
        """A copy with some values replaced.

        ``overrides`` is nested (``{"ball": {"mass_kg": 0.02}}``) or dotted (``{"ball.mass_kg": 0.02}``).
        Unknown groups or names raise ``ParameterError`` naming them and ``origin``."""
        nested: dict[str, dict[str, Any]] = {}
        for key, value in overrides.items():
            if not isinstance(key, str):
                raise ParameterError(f"{origin}: {_show(key)} is not a parameter name")
            if "." in key:
                group, name = key.split(".", 1)
                nested.setdefault(group, {})[name] = value
            elif isinstance(value, Mapping):
                nested.setdefault(key, {}).update(value)
            else:
                raise ParameterError(
                    f"{origin}: '{_clip(key)}' is not a parameter group (expected one of {sorted(_GROUPS)})"
                )
        changes: dict[str, Any] = {}
        part_groups = dict(self.part_groups)
        for group, values in nested.items():
            cls = _group_class(group)
            if cls is None:
                raise ParameterError(
                    f"{origin}: unknown parameter group '{_clip(group)}' (expected one of {_known_groups()})"
                )
            known = {f.name for f in fields(cls)}
            for name in values:
                if name not in known:
                    raise ParameterError(
                        f"{origin}: unknown parameter '{group}.{_clip(str(name))}' (known: {sorted(known)})"
                    )
            try:
                replaced = dataclasses.replace(self.group(group), **values)
            except ParameterError as exc:
                raise ParameterError(f"{origin}: {exc}") from None
            if group in _PART_GROUPS:
                part_groups[group] = replaced
            else:
                changes[group] = replaced
        if part_groups != dict(self.part_groups):
            # a group equal to its defaults is not held: the same rig has one value, whichever way it was made
            held = {k: v for k, v in part_groups.items() if v != _PART_GROUPS[k]()}
            changes["part_groups"] = tuple(sorted(held.items()))
        try:
            return dataclasses.replace(self, **changes)
        except ParameterError as exc:
            raise ParameterError(f"{origin}: {exc}") from None

    def with_values(self, values: Mapping[str, float], *, origin: str = "calibration") -> Parameters:
        """A copy with values by dotted name as a calibration fits them (``calib.identify``) and a Monte Carlo
        study samples them: the parameters' own names (through ``with_overrides``, which refuses an unknown
        one) and the ball reading's gain g and offset b (``READING``: no field of their own, the identity
        1 and 0), which are folded into the ball sensor's curve so that the software's eq 6.3.1 reads
        g·(what it read before) + b."""
        strange = [
            k for k in values if isinstance(k, str) and k.startswith("ball_reading.") and k not in READING
        ]
        if strange:
            raise ParameterError(
                f"{origin}: unknown parameter '{_clip(strange[0])}' (known: {list(READING)})"
            )
        plain = {k: v for k, v in values.items() if k not in READING}
        out = self.with_overrides(plain, origin=origin) if plain else self
        gain, offset = values.get("ball_reading.gain", 1.0), values.get("ball_reading.offset_m", 0.0)
        if gain != 1.0 or offset != 0.0:
            k, c = out.software.ball_gain_m_per_v, out.software.ball_offset_m
            # each curve point's reading by eq 6.3.1 (k·V + c, twin.converters.ball_position_m), times g plus b,
            # turned back into volts by the inverse of eq 6.3.1
            curve = [((gain * (k * v + c) + offset) - c) / k for v in out.ball_sensor.curve_volts_v]
            out = out.with_overrides({"ball_sensor.curve_volts_v": curve}, origin=origin)
        return out

    @classmethod
    def from_file(cls, path: str | Path, *, base: Parameters | None = None) -> Parameters:
        """Defaults (``base``'s values, if given) overridden by a TOML or JSON file (groups as tables/objects,
        e.g. ``[ball] mass_kg = …``).

        Anything that is not a parameter file raises ``ParameterError`` naming the file: a file larger than
        ``MAX_FILE_BYTES`` (only that much is read), one that does not parse, or one nested deeper than a
        parameter file (group → field → number or list of numbers)."""
        path = Path(path)
        kind = "JSON" if path.suffix.lower() == ".json" else "TOML"
        text = read_input_file(
            path, "parameter file", "a parameter file with every value and its comments is about 10 kB"
        )
        nested = (
            f"{path}: nested deeper than a parameter file's two levels (group → field → number or list of "
            f"numbers)"
        )
        deep_line: int | None = None
        try:
            # utf-8-sig: a leading byte-order mark (an editor's "UTF-8 with BOM") is dropped, none is needed
            decoded = text.decode("utf-8-sig")
            if kind == "JSON":
                data = load_json(decoded)
            else:
                deep_line = _toml_deep_key(decoded)
                data = {} if deep_line is not None else tomllib.loads(decoded)
        except RecursionError:
            raise ParameterError(nested) from None
        except DuplicateKeyError as exc:
            raise ParameterError(f"{path}: {exc}") from None
        except ValueError as exc:  # JSONDecodeError, TOMLDecodeError, UnicodeDecodeError, over-long integers
            raise ParameterError(f"{path}: not a valid {kind} file: {_clip(str(exc), 200)}") from None
        if deep_line is not None:
            raise ParameterError(
                f"{nested}: line {deep_line} has a dotted key of more than {MAX_FILE_DEPTH} parts"
            )
        if not isinstance(data, dict):
            raise ParameterError(f"{path}: expected a table of parameter groups at the top level")
        where = _file_depth_error(data)
        if where is not None:
            raise ParameterError(f"{nested}: at {where}")
        return (base or cls()).with_overrides(data, origin=str(path))

    def held_groups(self) -> list[str]:
        """The groups this rig holds values of: the thesis's, ``parts`` and the parts' groups it has set."""
        return [*_GROUPS, PARTS_GROUP, *(name for name, _ in self.part_groups)]

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return {group: dataclasses.asdict(self.group(group)) for group in self.held_groups()}

    def changed(self) -> dict[str, Any]:
        """The values that differ from the defaults, by dotted name (``{"motor.resistance_ohm": 1e-09}``)."""
        default = Parameters()
        out: dict[str, Any] = {}
        for group in self.held_groups():
            mine, theirs = self.group(group), default.group(group)
            for f in fields(mine):
                value = getattr(mine, f.name)
                if value != getattr(theirs, f.name):
                    out[f"{group}.{f.name}"] = value
        return out

    def save(self, path: str | Path, *, overwrite: bool = False) -> None:
        """Write all values as TOML (or JSON for a .json path). Refuses to overwrite unless asked."""
        path = Path(path)
        if path.exists() and not overwrite:
            raise FileExistsError(f"{path}: exists; not overwritten")
        if path.suffix.lower() == ".json":
            path.write_text(json.dumps(self.to_dict(), indent=2) + "\n")
            return
        lines = []
        for group, values in self.to_dict().items():
            lines.append(f"[{group}]")
            for f in fields(self.group(group)):
                value = values[f.name]
                if isinstance(value, str):
                    text = json.dumps(value)
                elif isinstance(value, bool):
                    text = "true" if value else "false"
                elif isinstance(value, tuple):
                    text = "[" + ", ".join(repr(v) for v in value) + "]"
                else:
                    text = repr(value)
                lines.append(f"{f.name} = {text}  # {f.metadata['unit']}; {f.metadata['source']}")
            lines.append("")
        path.write_text("\n".join(lines))

    @staticmethod
    def describe() -> list[dict[str, str]]:
        """Name, default, unit and source of every parameter (for documentation and reports)."""
        rows = []
        for group, cls_ in {**_GROUPS, PARTS_GROUP: PartNames, **_PART_GROUPS}.items():
            default = cls_()
            for f in fields(cls_):
                rows.append(
                    {
                        "name": f"{group}.{f.name}",
                        "default": repr(getattr(default, f.name)),
                        "unit": f.metadata["unit"],
                        "source": f.metadata["source"],
                    }
                )
        return rows
