"""A V-groove or angle channel (``V_GROOVE``, role ``track``): the ball rides between two flat walls meeting at a
vertex line along the beam; its parameter group ``v_groove``, its geometry (``groove_rolling``), its MJCF fragment.

Geometry (the beam's cross-section, y across, z up; the vertex V at y = 0, ``vertex_height_m`` above the pivot;
each wall at the half-angle α from the vertical, ``half_angle_rad``):

    wall ±       the plane through V along the direction (±sin α, cos α); its normal toward the ball
                 n± = (∓cos α, sin α), perpendicular to it
    contact ±    the ball (radius r, centre C) touches a wall where the wall's normal through C meets it, one radius
                 along −n± from C: C + r·(±cos α, −sin α): r·cos α either side of the centre, r·sin α below it
    centre       C's distance to each wall is n±·(C − V) = sin α·(z_C − z_V) = r, so z_C = z_V + r/sin α
    rolling      the ball rolls about the line through its two contacts, r·sin α below its centre:
                 r* = r·sin α (the two wires' √(r² − d²/4) with d = 2r·cos α: √(r² − r²cos²α) = r·sin α);
                 h* = z_C − r* = z_V + r/sin α − r·sin α = z_V + r·cos²α/sin α

So the channel's own inertia ratio is 2r²/(5r*²) = 2/(5·sin²α), whatever the ball's size: 0.8 in a 90° angle
(α = 45°, ẍ = g·sin θ/1.8), against 0.4 on a flat floor. Each contact lies r·cot α up its wall from the vertex:
the wall (``wall_width_m``) must reach past it, or the ball rides on the walls' edges (refused, naming the field).

The walls end at ±``track.half_length_m`` as the wires do: the ball rolls off over their ends and is lost there
(the plant's tests as the wires': ``end_limit_m`` = half length + r; sideways past a contact).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from twin.parameters import (
    GROUPS,
    ParameterError,
    Parameters,
    TrackGeometry,
    check_group,
    param,
    register_group,
    register_track_geometry,
)
from twin.parts.contract import MjcfFragment, Part, register
from twin.parts.tracks import add_contact_box, geometry_form, remove_wires, set_track_sites

__all__ = ["V_GROOVE", "WALLS", "VGroove", "apply_v_groove", "groove_geometry", "groove_rolling"]

WALLS = ("groove_wall_pos", "groove_wall_neg")  # the two walls' geoms (+y, −y)


@dataclass(frozen=True)
class VGroove:
    """A V-groove or angle channel: its half-angle, where its vertex lies, how wide and thick its walls are."""

    half_angle_rad: float = param(
        math.pi / 4,
        "rad",
        "assumed: an equal-leg aluminium angle laid as a V (legs at 90°, each 45° from the vertical: EN 755-9 / "
        "ASTM B221 equal-leg angles are 90°); measure yours (half the angle between the walls)",
        ge=math.radians(10.0),
        le=math.radians(80.0),
        why="a groove the ball rides in: below 10° it sits 5.8 r above the vertex with an inertia ratio over 13 "
        "(a slot, not a groove); above 80° the walls are all but flat and it no longer holds the ball",
    )
    vertex_height_m: float = param(
        0.01,
        "m",
        "assumed: the channel's inner corner 10 mm above the pivot's axis; measure yours (caliper from the axle)",
        ge=-0.5,
        le=0.5,
        why="the groove lies on the beam, within 0.5 m of its pivot (negative: below it)",
    )
    wall_width_m: float = param(
        0.02,
        "m",
        "assumed: 20 mm legs (a 20 × 20 mm angle); the ball touches each r·cot α up from the corner",
        gt=0.0,
        le=0.2,
        why="an angle's leg: a bench-top channel's are millimetres to a few centimetres",
    )
    wall_thickness_m: float = param(
        0.002,
        "m",
        "assumed: 2 mm legs; drawn and collided only (the beam's inertia is its own group's)",
        gt=0.0,
        le=0.05,
        why="a channel's wall: millimetres thick",
    )

    def __post_init__(self) -> None:
        check_group(self, "v_groove")


def groove_rolling(radius_m: Any, half_angle_rad: Any, vertex_height_m: Any) -> tuple[Any, Any]:
    """(r*, h*) of a ball of radius r in a groove of half-angle α whose vertex is ``vertex_height_m`` above the
    pivot: r* = r·sin α, h* = z_V + r/sin α − r* (see the module docstring). Floats or numpy arrays alike."""
    s = np.sin(half_angle_rad)
    rolling = radius_m * s
    return rolling, (vertex_height_m + radius_m / s) - rolling


def groove_geometry(params: Parameters) -> TrackGeometry:
    """The groove's ``TrackGeometry`` for the rig ``params`` (its ball and ``v_groove`` group); refused if the
    contacts lie past the walls' width (``v_groove.wall_width_m``)."""
    g, r = params.of(VGroove), params.ball.radius_m
    reach = r / math.tan(g.half_angle_rad)  # the contact's distance from the vertex along the wall: r·cot α
    if reach >= g.wall_width_m:
        raise ParameterError(
            f"v_groove.wall_width_m = {g.wall_width_m!r} m is impossible: the ball (radius {r!r} m) touches each "
            f"wall r·cot α = {reach:.6g} m from the vertex, past the wall's edge"
        )
    rolling, axis = groove_rolling(r, g.half_angle_rad, g.vertex_height_m)
    return TrackGeometry(
        rolling_radius_m=float(rolling),
        axis_height_m=float(axis),
        lateral_limit_m=r * math.cos(g.half_angle_rad),
        end_limit_m=params.track.half_length_m + r,
    )


def apply_v_groove(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The groove in place of the wires: two box walls ``groove_wall_pos``/``_neg`` along the track
    (±``track.half_length_m``), each one's inner face the plane through the vertex at α from the vertical, with
    the wires' contact settings (``twin.parts.tracks.set_contact``); the track's sites on the rolling axis."""
    beam = remove_wires(spec)
    g = p.of(VGroove)
    alpha, half_len = g.half_angle_rad, p.track.half_length_m
    half_w, half_t = g.wall_width_m / 2, g.wall_thickness_m / 2
    for name, side in zip(WALLS, (1.0, -1.0), strict=True):
        up = (side * math.sin(alpha), math.cos(alpha))  # along the wall from the vertex (y, z)
        inward = (-side * math.cos(alpha), math.sin(alpha))  # the wall's normal toward the ball
        centre = [
            0.0,
            half_w * up[0] - half_t * inward[0],
            g.vertex_height_m + half_w * up[1] - half_t * inward[1],
        ]
        turn = -side * alpha  # about x: the box's z axis onto the wall's direction, its y axis onto −n
        quat = [math.cos(turn / 2), math.sin(turn / 2), 0.0, 0.0]
        add_contact_box(beam, p, name, [half_len, half_t, half_w], centre, quat)
    set_track_sites(spec, p)


def _equation(params: Sequence[Parameters]) -> tuple[np.ndarray, np.ndarray]:
    groups = [p.of(VGroove) for p in params]
    return groove_rolling(
        np.array([p.ball.radius_m for p in params]),
        np.array([g.half_angle_rad for g in groups]),
        np.array([g.vertex_height_m for g in groups]),
    )


def _inputs(rng: np.random.Generator, n: int) -> list[Parameters]:
    """Grooves from 20° to 70° half-angle, vertices within ±20 mm of the pivot, balls of 5 to 9 mm radius."""
    out = []
    for alpha, vertex, radius in zip(
        rng.uniform(math.radians(20.0), math.radians(70.0), n).tolist(),
        rng.uniform(-0.02, 0.02, n).tolist(),
        rng.uniform(0.005, 0.009, n).tolist(),
        strict=True,
    ):
        out.append(
            Parameters().with_overrides(
                {
                    "parts.track": "v_groove",
                    "v_groove.half_angle_rad": alpha,
                    "v_groove.vertex_height_m": vertex,
                    "v_groove.wall_width_m": 0.05,
                    "ball.radius_m": radius,
                },
                origin="batch form",
            )
        )
    return out


register_group("v_groove", VGroove)
register_track_geometry("v_groove", groove_geometry)

V_GROOVE = register(
    Part(
        name="v_groove",
        role="track",
        source="a V-groove or angle channel: two flat walls at a half-angle α from the vertical, the ball "
        "touching each where the wall's normal through its centre meets it (r* = r·sin α, derived in "
        "twin.parts.v_groove); geometry assumed (a 90° equal-leg angle), measure yours",
        groups={"track": GROUPS["track"], "v_groove": VGroove},
        equations=(groove_rolling, groove_geometry),
        mjcf=MjcfFragment(
            tuple(("geom", name) for name in WALLS)
            + tuple(("site", name) for name in ("track_centre", "track_end_pos", "track_end_neg")),
            apply_v_groove,
        ),
        batch=geometry_form(_equation, _inputs, "twin.parts.v_groove.groove_rolling"),
    )
)
