"""The beam lifted at one end by a servo's horn and a push-rod (``END_LEVER``, role ``beam_drive``): the exact
closure of the four-bar linkage it makes, its inverse and its ratio, its MJCF fragment and its parameter group
``linkage``.

Geometry (the beam's vertical plane, the pivot P at the origin, x along the level beam, z up; angles from +x
toward +z, so θ > 0 lifts the +x end as on the thesis's rig):

    attachment   A(θ) = L·(cos θ, sin θ)              L = ``beam_arm_m``, on the beam's axis through P
    crank pin    C(φ) = S + c·(cos φ, sin φ)          S = (``shaft_x_m``, ``shaft_z_m``), c = ``crank_m``
    closure      |A(θ) − C(φ)| = r                    r = ``rod_m``

For a horn angle φ, A lies on the circle of radius L about P and on the circle of radius r about C: with d = |C|,
the law of cosines gives cos(θ − ∠C) = (L² + d² − r²)/(2·L·d), two solutions mirrored about the line P→C. The
servo stands below the pivot (``shaft_z_m`` < 0) and the rod pushes up to the beam: the attachment is the one
counter-clockwise of the pin seen from P (θ = ∠C + arccos(…)); the other has the rod crossed under the beam. The
inverse is the same construction about the shaft: φ = ∠(A − S) ∓ arccos((c² + e² − r²)/(2·c·e)), e = |A − S|, the
branch the linkage works on: − where the horn lifts the beam as φ grows (dθ/dφ > 0, a horn pointing toward the
attachment), + where it lowers it (a horn reaching back toward the pivot). Differentiating the closure,
dθ/dφ = ((A − C)·C′)/((A − C)·A′) with A′ = L·(−sin θ, cos θ), C′ = c·(−sin φ, cos φ). Near the default's level
pose the horn is horizontal and the rod vertical, so dθ/dφ = c/L there exactly (both ends of the rod move
vertically at the same speed).

The linkage must close, away from its dead points, over the horn's travel (φ within ``horn_neutral_rad`` ±
``horn_travel_rad``): the pin's distance from P must stay strictly between |L − r| and L + r (at either end the rod
lies along the beam's radius and cannot turn it) and dθ/dφ must keep its sign (it is zero where the rod lines up
with the horn); ``Linkage`` refuses a geometry that does not, naming its fields. The level beam must be reachable
within that travel (the model is built, and the plant starts, with the beam level).

The equations are pure functions of numbers (floats or numpy arrays, each run its own geometry); ``Linkage`` holds
the numbers. The beam's mass properties stay in the ``beam`` group (``twin.model.apply_beam_drive`` writes them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from twin import model as mdl
from twin.drive_equations import (
    lever_horn_closure_rad,
    lever_horn_rad,
    lever_ratio,
    lever_ratio_slope,
    lever_shaft_angles,
    lever_shaft_derivatives,
    lever_theta_rad,
)
from twin.parameters import GROUPS, ParameterError, Parameters, check_group, param, register_group
from twin.parts.contract import BatchForm, MjcfFragment, Part, register
from twin.physics import register_drive_reach
from twin.reference import DriveKinematics, register_shaft_map

__all__ = [
    "END_LEVER",
    "HORN_BODY",
    "ROD_BODY",
    "ROD_END_SITE",
    "SERVO_SHAFT",
    "Linkage",
    "apply_end_lever",
    "lever_closure_refusal",
    "lever_horn_closure_rad",
    "lever_horn_rad",
    "lever_joint_angles",
    "lever_kernel_numbers",
    "lever_ratio",
    "lever_ratio_slope",
    "lever_shaft_angles",
    "lever_shaft_derivatives",
    "lever_theta_rad",
]

# Element names the fragment adds (the view draws them; the actuator's fragment drives SERVO_SHAFT).
HORN_BODY = "servo_arm"
SERVO_SHAFT = "servo_shaft"
ROD_BODY = "push_rod"
ROD_PIN = "rod_pin"
ROD_TIP_SITE = "rod_tip"
ROD_END_SITE = "rod_end"
ROD_EQUALITY = "rod_end_connect"
SERVO_CASE = "servo_case"

# The linkage's plane lies this far in front of the beam's centre plane (toward the front camera, −y): clear of
# the beam bar's 22 mm half width, so the view shows it. Cosmetic: every joint turns about y, so the offset
# changes no dynamics.
_PLANE_Y_M = -0.03
_ROD_RADIUS_M = 0.001  # a 2 mm push-rod wire: its axial inertia (negligible, but a body's must be positive)
# Horn angles at which the closure is checked: dense enough that a dead point between two of them shows as a
# change of sign of dθ/dφ (its ends and the pin's nearest and farthest points from P are added exactly).
_CHECK_POINTS = 721


@dataclass(frozen=True)
class Linkage:
    """The lever drive's geometry and the masses of its moving links (the beam's own stay in ``beam``)."""

    beam_arm_m: float = param(
        0.15,
        "m",
        "assumed (Open Ball & Beam's drawing was not found): the rod's attachment 150 mm from the pivot along the "
        "beam, on the beam's axis through the pivot; measure yours",
        gt=0.0,
        le=1.0,
        why="a bench ball-and-beam is under 2 m long: the attachment lies within 1 m of its pivot",
    )
    rod_m: float = param(
        0.1,
        "m",
        "assumed: a 100 mm push-rod between its two pins (eye to eye); measure yours",
        gt=0.0,
        le=1.0,
        why="a push-rod longer than the beam's half length does not fit under a bench rig",
    )
    crank_m: float = param(
        0.025,
        "m",
        "assumed: the rod in a micro servo's horn hole 25 mm from the shaft (θ ≈ c/L·φ = φ/6 near level); "
        "measure yours",
        gt=0.0,
        le=0.1,
        why="hobby servos' horns and discs reach at most a few cm from the shaft",
    )
    shaft_x_m: float = param(
        0.125,
        "m",
        "assumed: the servo's shaft one crank length short of the attachment (beam_arm − crank), so the horn is "
        "horizontal and the rod vertical when the beam is level",
        ge=-1.0,
        le=1.0,
        why="the servo stands within the rig's 2 m",
    )
    shaft_z_m: float = param(
        -0.1,
        "m",
        "assumed: the servo's shaft one rod length below the pivot, so the rod stands vertical at level",
        ge=-1.0,
        lt=0.0,
        why="the servo stands below the pivot and the rod pushes up to the beam (the closure's branch)",
    )
    horn_neutral_rad: float = param(
        0.0,
        "rad",
        "assumed: the horn splined on pointing along +x (toward the attachment) at the servo's centre pulse, the "
        "servo's positive angle turning it up (from +x toward +z); a mirrored mount negates the servo's map",
        ge=-math.pi,
        le=math.pi,
        why="an angle once round",
    )
    horn_travel_rad: float = param(
        math.pi / 3,
        "rad",
        "assumed: the horn works ±60° about its centre, short of the dead point near +80° where the default "
        "rod lines up with the horn (a sketch limits its pulses to its working travel)",
        gt=0.0,
        le=math.pi,
        why="a hobby servo turns at most half a turn each way",
    )
    rod_mass_kg: float = param(
        0.0025,
        "kg",
        "assumed: a 2 mm steel wire 100 mm long, 7850 kg/m³·π·(1 mm)²·0.1 m = 2.5 g, its mass spread along it",
        gt=0.0,
        le=0.5,
        why="a push-rod of a bench rig weighs grams, not half a kilogram",
    )
    horn_mass_kg: float = param(
        0.001,
        "kg",
        "assumed: a micro servo's plastic single-arm horn, about 1 g (the servo's reflected rotor inertia, "
        "servo.armature_kgm2, dominates the shaft's inertia)",
        gt=0.0,
        le=0.2,
        why="a horn or disc weighs grams",
    )

    def __post_init__(self) -> None:
        check_group(self, "linkage")
        refusal = lever_closure_refusal(
            self.beam_arm_m,
            self.rod_m,
            self.crank_m,
            self.shaft_x_m,
            self.shaft_z_m,
            self.horn_neutral_rad - self.horn_travel_rad,
            self.horn_neutral_rad + self.horn_travel_rad,
        )
        if refusal is not None:
            raise ParameterError(f"{_GEOMETRY_FIELDS} are impossible together: {refusal}")

    def theta_rad(self, phi_rad: Any) -> Any:
        """θ(φ) of this geometry (``lever_theta_rad``)."""
        return lever_theta_rad(phi_rad, *self._geometry())

    def horn_rad(self, theta_rad: Any) -> Any:
        """φ(θ) of this geometry on its working branch, near the horn's neutral (``lever_horn_rad``)."""
        return lever_horn_rad(theta_rad, *self._geometry(), self.sense, self.horn_neutral_rad)

    @property
    def sense(self) -> float:
        """sign(dθ/dφ) over the travel: +1 if the horn lifts the beam as φ grows, −1 if it lowers it."""
        return 1.0 if self.ratio(self.horn_neutral_rad) > 0.0 else -1.0

    def ratio(self, phi_rad: Any) -> Any:
        """dθ/dφ of this geometry (``lever_ratio``)."""
        return lever_ratio(phi_rad, *self._geometry())

    def _geometry(self) -> tuple[float, float, float, float, float]:
        return self.beam_arm_m, self.rod_m, self.crank_m, self.shaft_x_m, self.shaft_z_m


_GEOMETRY_FIELDS = (
    "linkage.beam_arm_m, linkage.rod_m, linkage.crank_m, linkage.shaft_x_m, linkage.shaft_z_m, "
    "linkage.horn_neutral_rad, linkage.horn_travel_rad"
)


# --- the equations: pure functions of the geometry's numbers (floats, or arrays: each run its own) --------------
def lever_closure_refusal(
    beam_arm_m: float,
    rod_m: float,
    crank_m: float,
    shaft_x_m: float,
    shaft_z_m: float,
    phi_min_rad: float,
    phi_max_rad: float,
) -> str | None:
    """Why the linkage cannot work over the horn's travel [φ_min, φ_max], or None if it can: it must close
    (the pin's distance d from the pivot strictly inside (|L − r|, L + r)), stay clear of dead points (dθ/dφ of
    one sign, never 0 or infinite, checked at ``_CHECK_POINTS`` horn angles with the travel's ends and the pin's
    nearest and farthest points from the pivot), and reach the level beam within the travel."""
    geometry = (beam_arm_m, rod_m, crank_m, shaft_x_m, shaft_z_m)
    # d² = |S|² + c² + 2·c·|S|·cos(φ − ∠S): extreme at ∠S and ∠S + π; add them where they fall in the travel
    toward = math.atan2(shaft_z_m, shaft_x_m)
    extremes = [
        a + 2.0 * math.pi * k for a in (toward, toward + math.pi) for k in range(-2, 3)
    ]  # fmt: skip
    phis = np.union1d(
        np.linspace(phi_min_rad, phi_max_rad, _CHECK_POINTS),
        [a for a in extremes if phi_min_rad <= a <= phi_max_rad],
    )
    pin_x = shaft_x_m + crank_m * np.cos(phis)
    pin_z = shaft_z_m + crank_m * np.sin(phis)
    d = np.hypot(pin_x, pin_z)
    outside = (d <= abs(beam_arm_m - rod_m)) | (d >= beam_arm_m + rod_m)
    if outside.any():
        phi = float(phis[np.argmax(outside)])
        return (
            f"at horn angle {math.degrees(phi):.1f}° the crank pin is {float(d[np.argmax(outside)]):.4g} m from the "
            f"pivot, where the rod ({rod_m:g} m) cannot reach an attachment {beam_arm_m:g} m out (it must be "
            f"between {abs(beam_arm_m - rod_m):.4g} and {beam_arm_m + rod_m:.4g} m)"
        )
    ratio = lever_ratio(phis, *geometry)
    sense = 1.0 if ratio[len(ratio) // 2] > 0.0 else -1.0
    dead = ~(sense * ratio > 0.0) | ~np.isfinite(ratio)
    if dead.any():
        phi = float(phis[np.argmax(dead)])
        return (
            f"at horn angle {math.degrees(phi):.1f}° the horn passes a dead point (dθ/dφ = "
            f"{float(ratio[np.argmax(dead)]):.3g}: the rod in line with the horn); shorten the horn's travel or "
            "move the shaft"
        )
    level = float(lever_horn_rad(0.0, *geometry, sense, (phi_min_rad + phi_max_rad) / 2.0))
    if not phi_min_rad <= level <= phi_max_rad:
        return (
            f"the level beam needs the horn at {math.degrees(level):.1f}°, outside its travel "
            f"[{math.degrees(phi_min_rad):.1f}°, {math.degrees(phi_max_rad):.1f}°]"
        )
    return None


def lever_joint_angles(params: Parameters, theta_rad: float) -> tuple[float, float]:
    """The model's ``servo_shaft`` and ``rod_pin`` joint values (qpos) that close the linkage with the beam at
    ``theta_rad``: for a start away from level (the model is built closed at level, where both read their
    reference values). The shaft's value is the servo's own angle, φ − ``horn_neutral_rad``."""
    link = params.of(Linkage)
    phi_level, psi_level = _level_pose(link)
    phi = float(link.horn_rad(theta_rad))
    psi = _rod_direction_rad(link, theta_rad, phi)
    return phi - link.horn_neutral_rad, math.remainder((psi - phi) - (psi_level - phi_level), 2.0 * math.pi)


def _rod_direction_rad(link: Linkage, theta_rad: float, phi_rad: float) -> float:
    """The rod's direction (from the pin to the attachment) in the beam's plane."""
    dx = link.beam_arm_m * math.cos(theta_rad) - (link.shaft_x_m + link.crank_m * math.cos(phi_rad))
    dz = link.beam_arm_m * math.sin(theta_rad) - (link.shaft_z_m + link.crank_m * math.sin(phi_rad))
    return math.atan2(dz, dx)


def _level_pose(link: Linkage) -> tuple[float, float]:
    """The horn's angle and the rod's direction with the beam level (the model's reference pose)."""
    phi = float(link.horn_rad(0.0))
    return phi, _rod_direction_rad(link, 0.0, phi)


# --- the MJCF fragment --------------------------------------------------------------------------------------
def _turn_about_hinge(angle_rad: float) -> list[float]:
    """A body's quaternion turned by ``angle_rad`` about the hinges' axis (0, −1, 0): +x toward +z."""
    return [math.cos(angle_rad / 2.0), 0.0, -math.sin(angle_rad / 2.0), 0.0]


def _visual(geom: Any, radius_m: float) -> None:
    """A drawn link: no contacts (the ball rolls on the wires only), the visual geoms' group."""
    geom.type = mujoco.mjtGeom.mjGEOM_CAPSULE
    geom.size = [radius_m, 0.0, 0.0]
    geom.contype = 0
    geom.conaffinity = 0
    geom.group = 2


def _bar_inertia(mass_kg: float, length_m: float, radius_m: float) -> list[float]:
    """A thin bar along x: m·r²/2 about its axis, m·ℓ²/12 about the two others (through its centre)."""
    across = mass_kg * length_m**2 / 12.0
    return [mass_kg * radius_m**2 / 2.0, across, across]


def apply_end_lever(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The beam on its pivot (``beam``: ``twin.model.apply_beam_drive``), lifted by the servo's horn and a
    push-rod (``linkage``): the horn body ``servo_arm`` turning on the hinge ``servo_shaft`` at the shaft, the
    rod body ``push_rod`` on the hinge ``rod_pin`` at the crank pin, and an equality ``connect`` pulling the
    rod's far end (site ``rod_tip``) onto the site ``rod_end`` on the beam at the attachment. Built closed with
    the beam level: the shaft's joint reads the servo's own angle (its ``ref`` is the level pose's), the rod's
    reads 0 there; the shaft stops at the horn's travel. The connect is as stiff as the contacts (time constant
    2·timestep)."""
    mdl.apply_beam_drive(spec, p)
    link = p.of(Linkage)
    phi_level, psi_level = _level_pose(link)
    beam = spec.body(mdl.BEAM_BODY)
    # the pivot, d behind the beam body's frame (the track's centre) on a beam hinged at one end
    offset = p.beam.track_offset_m
    pivot = [float(beam.pos[0]) - offset, float(beam.pos[1]), float(beam.pos[2])]

    horn = spec.worldbody.add_body(
        name=HORN_BODY,
        pos=[pivot[0] + link.shaft_x_m, pivot[1] + _PLANE_Y_M, pivot[2] + link.shaft_z_m],
        quat=_turn_about_hinge(phi_level),
    )
    shaft = horn.add_joint(
        name=SERVO_SHAFT,
        type=mujoco.mjtJoint.mjJNT_HINGE,
        axis=mdl.HINGE_AXIS_BEAM.tolist(),
        ref=phi_level - link.horn_neutral_rad,
    )
    # the horn's travel as stops (as stiff as the contacts): a servo told to turn past it stalls there, the
    # linkage never folds through its dead point onto its other branch
    shaft.limited = mujoco.mjtLimited.mjLIMITED_TRUE
    shaft.range = [-link.horn_travel_rad, link.horn_travel_rad]
    shaft.solref_limit = [p.physics.contact_timeconst_s, 1.0]
    horn.mass = link.horn_mass_kg
    horn.ipos = [link.crank_m / 2.0, 0.0, 0.0]
    horn.inertia = _bar_inertia(link.horn_mass_kg, link.crank_m, _ROD_RADIUS_M)
    horn.explicitinertial = True
    _visual(horn.add_geom(name=HORN_BODY, fromto=[0.0, 0.0, 0.0, link.crank_m, 0.0, 0.0]), 0.003)

    rod = horn.add_body(
        name=ROD_BODY, pos=[link.crank_m, 0.0, 0.0], quat=_turn_about_hinge(psi_level - phi_level)
    )
    rod.add_joint(name=ROD_PIN, type=mujoco.mjtJoint.mjJNT_HINGE, axis=mdl.HINGE_AXIS_BEAM.tolist())
    rod.mass = link.rod_mass_kg
    rod.ipos = [link.rod_m / 2.0, 0.0, 0.0]
    rod.inertia = _bar_inertia(link.rod_mass_kg, link.rod_m, _ROD_RADIUS_M)
    rod.explicitinertial = True
    _visual(rod.add_geom(name=ROD_BODY, fromto=[0.0, 0.0, 0.0, link.rod_m, 0.0, 0.0]), 0.0015)
    rod.add_site(name=ROD_TIP_SITE, pos=[link.rod_m, 0.0, 0.0], size=[0.002, 0.0, 0.0])
    beam.add_site(name=ROD_END_SITE, pos=[link.beam_arm_m - offset, _PLANE_Y_M, 0.0], size=[0.002, 0.0, 0.0])

    connect = spec.add_equality(
        name=ROD_EQUALITY,
        type=mujoco.mjtEq.mjEQ_CONNECT,
        objtype=mujoco.mjtObj.mjOBJ_SITE,
        name1=ROD_TIP_SITE,
        name2=ROD_END_SITE,
    )
    connect.solref = [p.physics.contact_timeconst_s, 1.0]
    # the servo's case (SG90: 22.2 × 11.8 × 31 mm), behind the horn: drawn only
    case = spec.worldbody.add_geom(
        name=SERVO_CASE,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[0.0111, 0.0059, 0.0155],
        pos=[
            pivot[0] + link.shaft_x_m - 0.0055,
            pivot[1] + _PLANE_Y_M + 0.009,
            pivot[2] + link.shaft_z_m - 0.008,
        ],
        rgba=[0.2, 0.35, 0.75, 1.0],
    )
    case.contype = 0
    case.conaffinity = 0
    case.group = 2


# --- the batch form: θ(φ), dθ/dφ and φ(θ) over N geometries at once -------------------------------------------
_VARIED = ("linkage.beam_arm_m", "linkage.rod_m", "linkage.crank_m", "linkage.shaft_x_m", "linkage.shaft_z_m")


# Every other run mounts the servo beyond the attachment, its horn reaching back toward the pivot (dθ/dφ < 0).
_FAR_SIDE = {"linkage.shaft_x_m": 0.175, "linkage.horn_neutral_rad": math.pi}


def _inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    # each run's geometry within ±2 % of its base's, which keeps it closing over its ±60° travel
    bases = [Linkage(), Linkage(**{k.partition(".")[2]: v for k, v in _FAR_SIDE.items()})]
    factors = rng.uniform(0.98, 1.02, (n, len(_VARIED)))
    params = []
    for i, row in enumerate(factors.tolist()):
        base = bases[i % 2]
        values = {
            name: getattr(base, name.partition(".")[2]) * f for name, f in zip(_VARIED, row, strict=True)
        }
        values["linkage.horn_neutral_rad"] = base.horn_neutral_rad
        params.append(Parameters().with_overrides(values, origin="batch form"))
    phis = rng.uniform(-math.pi / 3, math.pi / 3, n) + np.where(np.arange(n) % 2 == 1, math.pi, 0.0)
    return params, phis[:, None]


def _single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One run: the group's methods on a float."""
    link = params.of(Linkage)
    phi = float(row[0])
    theta = float(link.theta_rad(phi))
    return np.array([theta, float(link.ratio(phi)), float(link.horn_rad(theta))])


def _batch(params: Any, rows: np.ndarray) -> np.ndarray:
    """Every run at once: the equations on arrays, each run's geometry a column."""
    links = [p.of(Linkage) for p in params]
    arm, rod, crank, shaft_x, shaft_z = (
        np.array([getattr(k, f.partition(".")[2]) for k in links]) for f in _VARIED
    )
    geometry = (arm, rod, crank, shaft_x, shaft_z)
    phi = rows[:, 0]
    theta = lever_theta_rad(phi, *geometry)
    sense = np.where(lever_ratio(np.array([k.horn_neutral_rad for k in links]), *geometry) > 0.0, 1.0, -1.0)
    neutral = np.array([k.horn_neutral_rad for k in links])
    return np.column_stack(
        [theta, lever_ratio(phi, *geometry), lever_horn_rad(theta, *geometry, sense, neutral)]
    )


def _pose(params: Parameters, theta_rad: float) -> dict[str, float]:
    shaft, pin = lever_joint_angles(params, theta_rad)
    return {SERVO_SHAFT: shaft, ROD_PIN: pin}


def lever_reach_rad(params: Parameters) -> tuple[float, float]:
    """The beam's travel the lever allows: its angles with the horn at its travel's two ends (its stops)."""
    link = params.of(Linkage)
    low, high = sorted(
        float(link.theta_rad(link.horn_neutral_rad + side * link.horn_travel_rad)) for side in (-1.0, 1.0)
    )
    return low, high


def lever_shaft_map(params: Parameters) -> DriveKinematics:
    """The lever for the reference model (``twin.reference.DriveKinematics``): θ → (the servo's angle φ − neutral,
    φ′ = 1/(dθ/dφ), φ″ = −(dθ/dφ)′/(dθ/dφ)³, in closed form: ``lever_shaft_angles``); the horn (a bar, m·c²/3
    about the shaft) and half the push-rod at its pin turn with the shaft, the other half rides on the beam at
    the attachment (a two-point model of the rod: MuJoCo's rod also turns about its own centre, m·ℓ²/12·ψ̇²,
    which this leaves out); the beam's travel is where the horn meets its stops."""
    link = params.of(Linkage)
    numbers = lever_kernel_numbers(link)

    def shaft(theta_rad: float) -> tuple[float, float, float]:
        # NaN where the rod cannot reach, without a warning, as lever_horn_rad
        with np.errstate(invalid="ignore", divide="ignore"):
            phi, dphi, ddphi = lever_shaft_angles(theta_rad, *numbers)
        return float(phi), float(dphi), float(ddphi)

    shaft_inertia = link.horn_mass_kg * link.crank_m**2 / 3.0 + link.rod_mass_kg / 2.0 * link.crank_m**2
    ends = lever_reach_rad(params)
    return DriveKinematics(
        shaft,
        shaft_inertia,
        link.rod_mass_kg / 2.0 * link.beam_arm_m**2,
        (ends[0], ends[1]),
        lever_kernel_numbers(link),
    )


def lever_kernel_numbers(link: Linkage) -> tuple[float, float, float, float, float, float, float]:
    """``lever_shaft_angles``'s numbers after θ: (L, r, c, S_x, S_z, sense, neutral), as the reference model
    and the compiled kernel's row (twin.screen.plant) pass them."""
    return (
        link.beam_arm_m, link.rod_m, link.crank_m, link.shaft_x_m, link.shaft_z_m, link.sense, link.horn_neutral_rad,
    )  # fmt: skip


register_group("linkage", Linkage)
mdl.register_drive_joint("end_lever", SERVO_SHAFT)
mdl.register_drive_pose("end_lever", _pose)
register_drive_reach("end_lever", lever_reach_rad)
register_shaft_map("end_lever", lever_shaft_map)

END_LEVER = register(
    Part(
        name="end_lever",
        role="beam_drive",
        source="the beam on its pivot (Table 3.1's beam group), lifted at one end by a hobby servo's horn and a "
        "push-rod: a four-bar linkage solved exactly (geometry assumed, measure yours)",
        groups={"beam": GROUPS["beam"], "linkage": Linkage},
        equations=(lever_theta_rad, lever_horn_rad, lever_ratio, lever_closure_refusal, lever_joint_angles),
        mjcf=MjcfFragment(
            (
                ("body", mdl.BEAM_BODY),
                ("joint", mdl.HINGE),
                ("body", HORN_BODY),
                ("joint", SERVO_SHAFT),
                ("body", ROD_BODY),
                ("joint", ROD_PIN),
                ("site", ROD_TIP_SITE),
                ("site", ROD_END_SITE),
                ("geom", SERVO_CASE),
            )
            + tuple(("sensor", s) for s in mdl.HINGE_SENSORS),
            apply_end_lever,
        ),
        batch=BatchForm(_single, _batch, _inputs, "twin.parts.linkage.lever_theta_rad", tolerance=1e-12),
    )
)
