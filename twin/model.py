"""Build the MuJoCo model of the rig from ``models/ballbeam.xml`` and a ``Parameters`` set.

The XML gives the structure (bodies, joints, geoms, actuator, sensors, scene); every physical number is
reapplied here from ``Parameters`` through ``mujoco.MjSpec``, one function per rig part's fragment (``apply_ball``,
``apply_track``, ``apply_beam_drive``, ``apply_actuator``: ``twin.parts`` names the elements each owns).
"""

from __future__ import annotations

import copy
import functools
import math
from collections.abc import Callable, Sequence
from importlib import resources
from pathlib import Path

import mujoco
import numpy as np

from twin.parameters import Parameters

__all__ = [
    "THESIS_FRAGMENTS",
    "ModelError",
    "apply_actuator",
    "apply_ball",
    "apply_beam_drive",
    "apply_physics",
    "apply_track",
    "build_model",
    "drive_joint",
    "drive_pose",
    "register_drive_joint",
    "register_drive_pose",
    "fragments_of",
    "register_fragment",
    "build_spec",
    "measure_rest_gap_m",
    "model_path",
]

MODEL_FILE = "ballbeam.xml"

# Element names in models/ballbeam.xml that the twin relies on.
BEAM_BODY = "beam"
BALL_BODY = "ball"
HINGE = "beam_hinge"
BALL_JOINT = "ball_free"
MOTOR = "motor"
WIRES = ("wire_rod", "wire_spring")
TRACK_SITES = ("track_centre", "track_end_pos", "track_end_neg")
BALL_GEOM = "ball"
BALL_SITE = "ball_centre"
BALL_IN_BEAM = "ball_in_beam"  # the ball's position in the beam's frame (a framepos sensor)
HINGE_SENSORS = ("beam_angle", "beam_rate")
MOTOR_SENSOR = "motor_torque"
HINGE_AXIS_BEAM = np.array([0.0, -1.0, 0.0])  # theta > 0 lifts the +x end (eq 3.1.26 sign convention)

# Cosmetic lateral/long-axis inertia of the beam bar (40 mm x 10 mm section); only the hinge-axis inertia
# (Table 3.1) enters the dynamics because the hinge removes the other rotations.
_BEAM_BAR_WIDTH_M = 0.04
_BEAM_BAR_THICKNESS_M = 0.01


class ModelError(RuntimeError):
    """The model file is missing or does not have the elements the twin needs."""


def model_path() -> Path:
    """Path of ballbeam.xml: inside the installed package, or models/ at the repository root."""
    packaged = resources.files("twin").joinpath("models", MODEL_FILE)
    if packaged.is_file():
        return Path(str(packaged))
    source = Path(__file__).resolve().parent.parent / "models" / MODEL_FILE
    if source.is_file():
        return source
    raise ModelError(f"{MODEL_FILE} not found (looked in {packaged} and {source})")


def _find(spec: mujoco.MjSpec, kind: str, name: str):
    element = getattr(spec, kind)(name)
    if element is None:
        raise ModelError(f"{model_path()}: no {kind} named '{name}'")
    return element


def build_spec(
    params: Parameters | None = None,
    *,
    hold_beam_rad: float | None = None,
    fragments: Sequence[Callable[[mujoco.MjSpec, Parameters], None]] | None = None,
) -> mujoco.MjSpec:
    """The rig's MjSpec with every physical value taken from ``params``: the numerical options, then each
    part's fragment patched from its parameters (``fragments``, default the fragments of the parts ``params``
    names, ``fragments_of``: ``twin.parts`` registers each part's; each writes or replaces its own elements).

    ``hold_beam_rad`` replaces the hinge by a rigid mount at that angle (the beam "held" by hand, for
    rolling checks and static sensor calibration); the motor is then removed with the hinge."""
    p = params or Parameters()
    spec = mujoco.MjSpec.from_file(str(model_path()))
    apply_physics(spec, p)
    for apply in fragments_of(p) if fragments is None else fragments:
        apply(spec, p)
    if hold_beam_rad is not None:
        if not math.isfinite(hold_beam_rad):
            raise ValueError(f"hold_beam_rad = {hold_beam_rad!r} is not finite")
        beam, motor = _find(spec, "body", BEAM_BODY), _find(spec, "actuator", MOTOR)
        # Rotation by theta about the hinge axis (0, -1, 0).
        beam.quat = [math.cos(hold_beam_rad / 2), 0.0, -math.sin(hold_beam_rad / 2), 0.0]
        spec.delete(motor)
        for sensor in list(spec.sensors):
            if sensor.name in (*HINGE_SENSORS, MOTOR_SENSOR):
                spec.delete(sensor)
        spec.delete(_find(spec, "joint", HINGE))
    return spec


def apply_physics(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The numerical options (``physics``): time step and gravity."""
    spec.option.timestep = p.physics.timestep_s
    spec.option.gravity = [0.0, 0.0, -p.physics.gravity_m_s2]


def _contact_solimp(p: Parameters) -> list[float]:
    impedance = p.physics.contact_impedance
    return [impedance, impedance, 0.001, 0.5, 2.0]


def apply_beam_drive(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The beam turned at its pivot (``beam``): its body's inertia and the hinge's stops and bearing."""
    # Beam: mass M_B at h above P; J_BP about P means J_BP - M_B h^2 about the centre of gravity.
    beam = _find(spec, "body", BEAM_BODY)
    i_hinge = p.beam.inertia_pivot_kgm2 - p.beam.mass_kg * p.beam.cog_height_m**2
    i_long = p.beam.mass_kg * (_BEAM_BAR_WIDTH_M**2 + _BEAM_BAR_THICKNESS_M**2) / 12.0
    beam.mass = p.beam.mass_kg
    beam.ipos = [0.0, 0.0, p.beam.cog_height_m]
    if p.beam.hinged_off_centre:
        # A beam hinged at one end: the body's frame stays at the track's centre (every track, sensor and ball
        # coordinate is along it from there), the hinge moves to the pivot, d behind it, and the beam's centre of
        # gravity lies x_g out from the pivot; the world keeps the pivot where the stand holds it.
        d, x_g = p.beam.track_offset_m, p.beam.cog_along_m
        i_hinge = p.beam.inertia_pivot_kgm2 - p.beam.mass_kg * (p.beam.cog_height_m**2 + x_g**2)
        beam.ipos = [x_g - d, 0.0, p.beam.cog_height_m]
        beam.pos = [beam.pos[0] + d, beam.pos[1], beam.pos[2]]
        _find(spec, "joint", HINGE).pos = [-d, 0.0, 0.0]
    beam.iquat = [1.0, 0.0, 0.0, 0.0]
    beam.inertia = [i_long, i_hinge, i_hinge]
    beam.explicitinertial = True

    hinge = _find(spec, "joint", HINGE)
    hinge.range = [-p.beam.stop_angle_rad, p.beam.stop_angle_rad]
    hinge.axis = HINGE_AXIS_BEAM.tolist()
    # The stops as stiff as the wire contacts (time constant 2·timestep): MuJoCo's default 20 ms lets a beam
    # driven at 12 V overshoot 43.4° by 3.4°; this keeps it within 0.2°.
    hinge.solref_limit = [p.physics.contact_timeconst_s, 1.0]
    # The pivot bearing's own viscous and dry friction (default 0, as the thesis neglects them).
    hinge.damping = [p.beam.pivot_damping_nm_s_per_rad, 0.0, 0.0]
    hinge.frictionloss = p.beam.pivot_friction_nm


def apply_track(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The two wires (``track``, with the ball's radius): their axes, radius, friction and contact, and the
    track's sites."""
    # Wires: each contact point lies h* above P and d/2 to the side; the wire axis lies one wire radius
    # further along the line from the ball centre through the contact point.
    r, rho, rs = p.ball.radius_m, p.track.wire_radius_m, p.rolling_radius_m
    h_star, half_d, half_len = p.track.contact_height_m, p.track.contact_spacing_m / 2, p.track.half_length_m
    y_axis = half_d * (1.0 + rho / r)
    z_axis = h_star - rho * rs / r
    timeconst = p.physics.contact_timeconst_s
    solimp = _contact_solimp(p)
    for name, side in zip(WIRES, (1.0, -1.0), strict=True):
        wire = _find(spec, "geom", name)
        wire.type = mujoco.mjtGeom.mjGEOM_CAPSULE
        wire.size = [rho, 0.0, 0.0]
        wire.fromto = [-half_len, side * y_axis, z_axis, half_len, side * y_axis, z_axis]
        wire.friction = [p.track.friction, 0.0, 0.0]
        wire.solref = [timeconst, 1.0]
        wire.solimp = solimp
        wire.margin = p.physics.contact_margin_m
    for name, x in zip(TRACK_SITES, (0.0, half_len, -half_len), strict=True):
        _find(spec, "site", name).pos = [x, 0.0, h_star]


def apply_ball(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The ball (``ball``): a solid sphere resting on the track above the pivot."""
    # Ball: solid sphere, J = 2/5 m r^2 (eq 3.1.21), resting with its centre h* + r* above P.
    beam = _find(spec, "body", BEAM_BODY)
    ball = _find(spec, "body", BALL_BODY)
    ball.mass = p.ball.mass_kg
    ball.inertia = [p.ball.inertia_kgm2] * 3
    ball.ipos = [0.0, 0.0, 0.0]
    ball.explicitinertial = True
    ball.pos = [beam.pos[0], beam.pos[1], beam.pos[2] + p.ball_centre_height_m]
    ball_geom = _find(spec, "geom", BALL_GEOM)
    ball_geom.size = [p.ball.radius_m, 0.0, 0.0]
    ball_geom.friction = [p.track.friction, 0.0, 0.0]
    ball_geom.solref = [p.physics.contact_timeconst_s, 1.0]
    ball_geom.solimp = _contact_solimp(p)


def apply_actuator(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The geared DC motor and its amplifier's rails (``motor``, ``amplifier``) on the hinge."""
    # Motor (eq 3.3.1): joint torque = N Kt/R (V - Kb N thetadot); rotor inertia and viscous damping are
    # reflected by N^2 by MuJoCo; the amplifier's rails bound the terminal volts (§6.4).
    motor = _find(spec, "actuator", MOTOR)
    motor.set_to_dcmotor(
        motorconst=[p.motor.torque_constant_nm_per_a, p.motor.backemf_constant_v_s_per_rad],
        resistance=p.motor.resistance_ohm,
    )
    motor.target = drive_joint(p)  # the beam's hinge on the thesis's pivot; a lever's servo shaft
    motor.gear = [p.motor.gear_ratio, 0, 0, 0, 0, 0]
    motor.armature = p.motor.rotor_inertia_kgm2
    motor.damping = [p.motor.viscous_damping_nm_s_per_rad, 0.0, 0.0]
    motor.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
    motor.ctrlrange = [-p.amplifier.rail_v, p.amplifier.rail_v]


# Today's rig's fragments (``build_spec``'s default): the beam turned at its pivot, the two wires, the ball, the
# geared DC motor.
THESIS_FRAGMENTS: tuple[Callable[[mujoco.MjSpec, Parameters], None], ...] = (
    apply_beam_drive,
    apply_track,
    apply_ball,
    apply_actuator,
)


Fragment = Callable[[mujoco.MjSpec, Parameters], None]
# The role order fragments are applied in: the thesis's (beam drive, track, ball, actuator), then the sensors and
# the board, whose fragments (a sensor's housing and its beam, drawn) add elements of their own.
FRAGMENT_ROLES = ("beam_drive", "track", "ball", "actuator", "ball_sensor", "angle_sensor", "io_board")
_FRAGMENTS: dict[tuple[str, str], Fragment] = {
    ("beam_drive", "pivot"): apply_beam_drive,
    ("track", "two_wires"): apply_track,
    ("ball", "steel_ball"): apply_ball,
    ("actuator", "escap_dc_motor"): apply_actuator,
}
# The parts whose fragment is nothing (a sensor outside MuJoCo): registered as such, so a name never registered
# is told apart from a part that owns no element.
_NO_FRAGMENT: set[tuple[str, str]] = {
    ("ball_sensor", "resistive_wire"),
    ("angle_sensor", "encoder_counter"),
    ("io_board", "pci1712"),
}


def register_fragment(role: str, name: str, apply: Fragment | None) -> None:
    """The MJCF fragment of the part ``name`` in ``role`` (``twin.parts.register`` calls this for every part;
    None: the part owns no element). A rig's model applies the fragments of the parts its parameters name."""
    if role not in FRAGMENT_ROLES:
        raise ModelError(f"no role {role!r} in a rig's model (roles: {list(FRAGMENT_ROLES)})")
    key = (role, name)
    if key in _FRAGMENTS or key in _NO_FRAGMENT:
        if _FRAGMENTS.get(key) is apply or (apply is None and key in _NO_FRAGMENT):
            return  # the thesis's own, registered again by its part
        raise ModelError(f"the {role} {name!r} has a fragment already")
    if apply is None:
        _NO_FRAGMENT.add(key)
    else:
        _FRAGMENTS[key] = apply


# The joint each beam drive takes its input at, by the drive's name: the actuator's fragment puts the actuator
# "motor" on it (``drive_joint``). The thesis's pivot is driven at the beam's hinge; a lever drive at its servo's
# shaft (``twin.parts.linkage``).
_DRIVE_JOINTS: dict[str, str] = {"pivot": HINGE}


def register_drive_joint(drive: str, joint: str) -> None:
    """Name the joint the beam drive ``drive`` takes its input at (its module calls this once, beside its
    ``register``); a drive named twice with another joint is refused."""
    if _DRIVE_JOINTS.get(drive, joint) != joint:
        raise ModelError(f"the beam drive {drive!r} takes its input at {_DRIVE_JOINTS[drive]!r} already")
    _DRIVE_JOINTS[drive] = joint


# A beam drive with joints of its own besides the beam's hinge (a lever's horn and push-rod): the values that close
# it with the beam at θ, by joint name (``drive_pose``), registered beside its input joint.
_DRIVE_POSES: dict[str, Callable[[Parameters, float], dict[str, float]]] = {}


def register_drive_pose(drive: str, pose: Callable[[Parameters, float], dict[str, float]]) -> None:
    """How the drive ``drive`` stands with the beam at θ: ``pose(params, θ)`` gives its own joints' values (qpos)
    by name (a rig held at θ starts with its linkage closed there, not snapping shut in the first steps)."""
    _DRIVE_POSES[drive] = pose


def drive_pose(params: Parameters, theta_rad: float, thetadot_rad_s: float) -> dict[str, tuple[float, float]]:
    """The drive's own joints (qpos, qvel) with the beam at θ turning at θ̇ (none for the pivot): the velocities
    by the pose's central difference (a rigid linkage's joints move as θ does)."""
    pose = _DRIVE_POSES.get(params.parts.beam_drive)
    if pose is None:
        return {}
    h = 1e-6
    here, up, down = pose(params, theta_rad), pose(params, theta_rad + h), pose(params, theta_rad - h)
    return {name: (value, (up[name] - down[name]) / (2 * h) * thetadot_rad_s) for name, value in here.items()}


def drive_joint(params: Parameters) -> str:
    """The joint the actuator of the rig ``params`` names drives: its beam drive's input joint."""
    drive = params.parts.beam_drive
    if drive not in _DRIVE_JOINTS:
        raise ModelError(f"parts.beam_drive = {drive!r}: no input joint is registered for it (twin.model)")
    return _DRIVE_JOINTS[drive]


def fragments_of(params: Parameters) -> tuple[Fragment, ...]:
    """The fragments of the parts ``params.parts`` names, in ``FRAGMENT_ROLES`` order (``ModelError`` for a
    part whose fragment was never registered: its module, under ``twin.parts``, was not imported)."""
    out = []
    for role in FRAGMENT_ROLES:
        key = (role, getattr(params.parts, role))
        if key in _FRAGMENTS:
            out.append(_FRAGMENTS[key])
        elif key not in _NO_FRAGMENT:
            raise ModelError(
                f"parts.{role} = {key[1]!r}: no such part's MJCF fragment is registered (twin.parts)"
            )
    return tuple(out)


def build_model(params: Parameters | None = None, *, hold_beam_rad: float | None = None) -> mujoco.MjModel:
    """Compiled model; see ``build_spec``. Compiled once per parameters, held angle and version of the model
    file, and handed out as a copy (each caller may change its own; compiling costs about 4 ms a run, a
    copy 0.5 ms)."""
    p = params or Parameters()
    path = model_path()
    stat = path.stat()
    try:
        return copy.copy(_compiled(p, hold_beam_rad, (str(path), stat.st_mtime_ns, stat.st_size)))
    except TypeError:  # parameters that cannot be a cache key (an unhashable value): compile them
        return build_spec(p, hold_beam_rad=hold_beam_rad).compile()


@functools.lru_cache(maxsize=16)
def _compiled(
    params: Parameters, hold_beam_rad: float | None, source: tuple[str, int, int]
) -> mujoco.MjModel:
    return build_spec(params, hold_beam_rad=hold_beam_rad).compile()


def measure_rest_gap_m(params: Parameters | None = None, settle_s: float = 0.5) -> float:
    """Distance between the ball and the wires once the ball rests at the centre of the level beam.

    Negative means the ball sinks into the wires. With ``contact_margin_m`` = 0 this is minus the rest
    penetration, the measurement the default margin comes from; with the default margin it is ≈ 0."""
    model = build_model(params, hold_beam_rad=0.0)
    data = mujoco.MjData(model)
    for _ in range(int(round(settle_s / model.opt.timestep))):
        mujoco.mj_step(model, data)
    wires = {model.geom(n).id for n in WIRES}
    dists = [c.dist for c in data.contact[: data.ncon] if c.geom1 in wires or c.geom2 in wires]
    if len(dists) != 2:
        raise ModelError(f"ball rests on {len(dists)} wire contacts, expected 2")
    return float(np.mean(dists))
