"""The 3D scene of the live view: every geom of the rig's MuJoCo model as a viser node under a frame per
body, the setpoint flag on the beam, a ranging ball sensor's beam of light or sound (from its aperture toward
the ball, as long as its current reading says), and the camera presets. Each frame the bodies are posed from the
running rig's state (the reference model has no geometry: a MuJoCo model of the same rig shows it)."""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np
import trimesh
import viser

from twin.parameters import Parameters
from twin.parts import is_thesis_rig, rig_parts
from twin.plant import Plant
from twin.viewer.channels import SensorBeam, sensor_beam
from twin.viewer.session import LiveTwin

# Camera presets: position, look-at point (m, world frame; the pivot is 0.25 m above the floor), up. For the
# thesis's rig; a rig from other parts gets them moved to its track and nearer a shorter one (``rig_cameras``).
Vec3 = tuple[float, float, float]
Cameras = dict[str, tuple[Vec3, Vec3, Vec3]]
CAMERAS: Cameras = {
    "Three-quarter": ((0.2, -0.72, 0.52), (0.0, 0.0, 0.24), (0.0, 0.0, 1.0)),
    "Side": ((0.0, -0.7, 0.27), (0.0, 0.0, 0.25), (0.0, 0.0, 1.0)),
    "Top": ((0.0, -0.02, 0.95), (0.0, 0.0, 0.25), (0.0, 1.0, 0.0)),
}
DEFAULT_CAMERA = "Three-quarter"
NEAREST_CAMERA = 0.5  # a short track's cameras come at most this much nearer than the thesis's
TRACK_MARGIN = 1.25  # the rig in view: its track and a quarter of it beyond each end (a sensor past the end)
SETPOINT_FLAG_M = (0.010, 0.028)  # the setpoint flag's extent above the ball centre (clear of the ball)
# The sensor's beam: a thin translucent rod along the beam's axis (viser's cylinders stand along their z: turned
# a quarter about y to lie along x), drawn only: it shows the distance the reading gives, not the cone it sees.
SENSOR_BEAM_RADIUS_M = 0.0015
SENSOR_BEAM_RGB = (230, 40, 40)
SENSOR_BEAM_OPACITY = 0.6
_ALONG_X = (math.sqrt(0.5), 0.0, math.sqrt(0.5), 0.0)


def _rgb(model: mujoco.MjModel, geom: int) -> tuple[int, int, int]:
    mat = model.geom_matid[geom]
    rgba = model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[geom]
    r, g, b = (int(round(255 * c)) for c in rgba[:3])
    return r, g, b


def build_scene(server: viser.ViserServer, model: mujoco.MjModel) -> dict[int, Any]:
    """Every geom of the MuJoCo model as a viser node under a frame per body; returns body id → frame."""
    frames: dict[int, Any] = {}
    for body in range(model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body) or "world"
        frames[body] = server.scene.add_frame(f"/{name}", show_axes=False)
    for g in range(model.ngeom):
        body = model.geom_bodyid[g]
        body_name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body) or "world"
        name = f"/{body_name}/{mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)}"
        px, py, pz = (float(v) for v in model.geom_pos[g])
        qw, qx, qy, qz = (float(v) for v in model.geom_quat[g])
        position, wxyz = (px, py, pz), (qw, qx, qy, qz)
        size, color, kind = model.geom_size[g], _rgb(model, g), model.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_PLANE:
            server.scene.add_box(
                name,
                color=color,
                dimensions=(2 * size[0], 2 * size[1], 0.002),
                position=(px, py, -0.001),
                wxyz=wxyz,
            )
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            sx, sy, sz = (float(2 * v) for v in size)
            server.scene.add_box(name, color=color, dimensions=(sx, sy, sz), position=position, wxyz=wxyz)
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            server.scene.add_icosphere(
                name, radius=float(size[0]), color=color, subdivisions=3, position=position, wxyz=wxyz
            )
        elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            server.scene.add_cylinder(
                name,
                radius=float(size[0]),
                height=float(2 * size[1]),
                color=color,
                position=position,
                wxyz=wxyz,
            )
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            mesh = trimesh.creation.capsule(height=float(2 * size[1]), radius=float(size[0]), count=[12, 12])
            server.scene.add_mesh_simple(
                name,
                vertices=np.asarray(mesh.vertices, dtype=np.float32),
                faces=np.asarray(mesh.faces, dtype=np.uint32),
                color=color,
                position=position,
                wxyz=wxyz,
            )
    return frames


def rig_cameras(params: Parameters) -> Cameras:
    """The camera presets for the rig ``params.parts`` names: the thesis's ``CAMERAS`` for its parts; for
    another, each looks at the same height above its track's middle (``beam.track_offset_m`` out from the pivot
    along x: a beam hinged at one end), in the same direction, from as far as its track and a quarter more
    (``TRACK_MARGIN``: a sensor mounted beyond its end) against the thesis's track (never nearer than
    ``NEAREST_CAMERA`` of it, never farther)."""
    if is_thesis_rig(rig_parts(params)):
        return CAMERAS
    ratio = TRACK_MARGIN * params.track.half_length_m / Parameters().track.half_length_m
    scale = min(max(ratio, NEAREST_CAMERA), 1.0)
    shift = params.beam.track_offset_m
    moved: Cameras = {}
    for name, (position, look_at, up) in CAMERAS.items():
        target = (look_at[0] + shift, look_at[1], look_at[2])
        eye = tuple(t + scale * (p - a) for t, p, a in zip(target, position, look_at, strict=True))
        moved[name] = ((eye[0], eye[1], eye[2]), target, up)
    return moved


def on_camera(name: str, cameras: Cameras, event: Any) -> None:
    set_camera(event.client, name, cameras)


def set_camera(client: Any, name: str, cameras: Cameras = CAMERAS) -> None:
    """One browser's camera to a preset (per client: other viewers keep their own view)."""
    if client is None or name not in cameras:
        return
    position, look_at, up = cameras[name]
    with client.atomic():
        client.camera.up_direction = up
        client.camera.position = position
        client.camera.look_at = look_at


def set_initial_camera(server: viser.ViserServer, cameras: Cameras = CAMERAS) -> None:
    position, look_at, up = cameras[DEFAULT_CAMERA]
    server.initial_camera.position = position
    server.initial_camera.look_at = look_at
    server.initial_camera.up = up


class Scene:
    """The rig's nodes in one viser server, posed from a ``LiveTwin`` each frame."""

    def __init__(self, server: viser.ViserServer, live: LiveTwin) -> None:
        self.live = live
        self._display = Plant(live.params)
        self.frames = build_scene(server, self._display.model)
        # The setpoint on the beam: a thin flag across both wires above the ball's path, in the beam's frame.
        p = live.params
        self._setpoint_flag_z_m = p.ball_centre_height_m + 0.5 * sum(SETPOINT_FLAG_M)
        self.setpoint_marker = server.scene.add_box(
            "/beam/setpoint",
            color=(20, 20, 20),
            dimensions=(0.002, 0.04, SETPOINT_FLAG_M[1] - SETPOINT_FLAG_M[0]),
            position=(live.setpoint_m, 0.0, self._setpoint_flag_z_m),
        )
        self._shown_setpoint = live.setpoint_m
        self.beam: SensorBeam | None = sensor_beam(p, self._display.model)
        self.beam_node: Any = None
        self.beam_length_m = math.nan  # the length drawn (NaN: hidden)
        if self.beam is not None:
            self.beam_node = server.scene.add_cylinder(
                f"/{self.beam.body}/{self.beam.site}_beam",
                radius=SENSOR_BEAM_RADIUS_M,
                height=1e-3,
                color=SENSOR_BEAM_RGB,
                opacity=SENSOR_BEAM_OPACITY,
                cast_shadow=False,
                receive_shadow=False,
                wxyz=_ALONG_X,
                position=self.beam.aperture_m,
                visible=False,
            )

    def _update_beam(self) -> None:
        """The beam as long as the board's current reading says (hidden for a reading without a distance):
        from the aperture toward −x, its middle halfway (only what changed is sent)."""
        sample = self.live.last_sample
        if self.beam is None or self.beam_node is None:
            return
        length = self.beam.length_m(sample.ball_v) if sample is not None else math.nan
        if length == self.beam_length_m or (math.isnan(length) and math.isnan(self.beam_length_m)):
            return
        self.beam_length_m = length
        if math.isnan(length):
            self.beam_node.visible = False
            return
        x, y, z = self.beam.aperture_m
        self.beam_node.height = length
        self.beam_node.position = (x - 0.5 * length, y, z)
        self.beam_node.visible = True

    def update(self) -> None:
        """Pose every body for the current state (inside the caller's atomic batch) and move the flag."""
        live = self.live
        physics = live.rig.physics
        if isinstance(physics, Plant):
            model, data = physics.model, physics.data
        else:
            x, theta = (float(v) for v in live.rig.true_state()[:2])
            p = live.params
            model, data = self._display.model, self._display.data
            self._display.reset(
                float(np.clip(x, -p.track.half_length_m, p.track.half_length_m)) if math.isfinite(x) else 0.0,
                float(np.clip(theta, -p.beam.stop_angle_rad, p.beam.stop_angle_rad))
                if math.isfinite(theta)
                else 0.0,
            )
        mujoco.mj_kinematics(model, data)  # poses of the current state (mj_step leaves xpos one step behind)
        for body, frame in self.frames.items():
            if body == 0:
                continue
            frame.position = tuple(data.xpos[body])
            frame.wxyz = tuple(data.xquat[body])
        if self._shown_setpoint != live.setpoint_m:
            self._shown_setpoint = live.setpoint_m
            self.setpoint_marker.position = (live.setpoint_m, 0.0, self._setpoint_flag_z_m)
        self._update_beam()
