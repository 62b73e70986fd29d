"""A closed tube (``TUBE``, role ``track``): the ball rolls along the bottom of a tube of inner radius R > r and
cannot leave it sideways; end caps close it. Its parameter group ``tube``, its geometry (``tube_rolling``), its
MJCF fragment.

Geometry (the beam's cross-section, y across, z up; the tube's inner bottom ``bottom_height_m`` above the pivot):

    contact      the ball (radius r < R) rests on the tube's lowest line, under its centre: one contact line,
                 the normal vertical (the wall's tangent plane there is horizontal)
    rolling      it rolls about that line, r* = r (the flat floor's 2r²/(5r*²) = 2/5: ẍ = g·sin θ/1.4), h* = the
                 bottom's height, its centre h* + r above the pivot

The ends, and what the verdict calls a lost ball. On the wires a ball past the track's end falls off; in a tube it
meets a cap and stays. The rule here: **a ball that reaches a cap is lost** (the controller let it run to the
end: on the rig it strikes the cap and rebounds, which no controller is designed to use), with the same test in
both engines, the track's own: |x| > ``track.half_length_m`` (the reference model's ``step_boundary``, and
``end_limit_m`` = the half length for MuJoCo's plant). So ``track.half_length_m`` is how far the ball's centre
travels from the middle before it touches a cap: for caps L apart inside, L/2 − r. The caps' inner faces stand
``CAP_CLEARANCE_M`` beyond the ball's touching point, at ±(half length + r + 0.1 mm): MuJoCo's ball then counts
as lost where the reference's does, before its soft contact with the cap (µm deep) could hold it short of the
test, and it comes to rest against the cap 0.1 mm later, inside the tube.

MuJoCo's tube is a duct: a floor at the bottom, side walls R either side of the axis, a roof 2R above the floor
(the square circumscribing the tube's circle) and two caps, all boxes with the wires' contact settings; a
translucent cylinder draws the tube itself. Rolling along the tube the ball touches the floor only, as it touches
the round tube's bottom; knocked sideways it stops at a wall, where a round tube would roll it back to the bottom.
"""

from __future__ import annotations

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

__all__ = [
    "CAPS",
    "CAP_CLEARANCE_M",
    "DUCT",
    "SHELL",
    "TUBE",
    "Tube",
    "apply_tube",
    "tube_geometry",
    "tube_rolling",
]

DUCT = ("tube_floor", "tube_wall_pos", "tube_wall_neg", "tube_roof")  # the geoms along the tube
CAPS = ("tube_cap_pos", "tube_cap_neg")  # at +x, −x
SHELL = "tube_shell"  # the drawn tube (no contacts)
# How far beyond the ball's touching point (|x| = track.half_length_m) a cap's inner face stands: far more than a
# contact's µm-deep give, far less than any distance a controller works at.
CAP_CLEARANCE_M = 1e-4


@dataclass(frozen=True)
class Tube:
    """A closed tube: its inner radius, where its inner bottom lies, its wall's thickness."""

    inner_radius_m: float = param(
        0.01,
        "m",
        "assumed: a clear acrylic tube of 20 mm inner diameter (AutomationShield's BOBShield uses 10 mm for an "
        "8 mm ball: BOBShield wiki page); measure yours (half the bore)",
        gt=0.0,
        le=0.2,
        why="a bench-top tube's bore: millimetres to a few centimetres; the ball's own radius is checked with "
        "the ball",
    )
    bottom_height_m: float = param(
        0.01,
        "m",
        "assumed: the tube's inner bottom 10 mm above the pivot's axis; measure yours",
        ge=-0.5,
        le=0.5,
        why="the tube lies on the beam, within 0.5 m of its pivot (negative: below it)",
    )
    wall_thickness_m: float = param(
        0.001,
        "m",
        "assumed: a 1 mm wall (BOBShield: 12 mm outside, 10 mm inside); drawn and collided only (the beam's "
        "inertia is its own group's)",
        gt=0.0,
        le=0.05,
        why="a tube's wall: millimetres thick",
    )

    def __post_init__(self) -> None:
        check_group(self, "tube")


def tube_rolling(radius_m: Any, bottom_height_m: Any) -> tuple[Any, Any]:
    """(r*, h*) of a ball of radius r on a tube's bottom ``bottom_height_m`` above the pivot: r* = r (one contact
    line, under the centre), h* = the bottom's height. Floats or numpy arrays alike."""
    return radius_m * 1.0, bottom_height_m * 1.0


def tube_geometry(params: Parameters) -> TrackGeometry:
    """The tube's ``TrackGeometry`` for the rig ``params``: lost past the half length (at a cap, the module's
    rule), never sideways. Refused unless the ball fits the bore (r < R, ``tube.inner_radius_m``)."""
    t, r = params.of(Tube), params.ball.radius_m
    if r >= t.inner_radius_m:
        raise ParameterError(
            f"tube.inner_radius_m = {t.inner_radius_m!r} m is impossible: the ball (radius {r!r} m) does not fit "
            f"in the tube unless r < R"
        )
    rolling, axis = tube_rolling(r, t.bottom_height_m)
    return TrackGeometry(
        rolling_radius_m=float(rolling),
        axis_height_m=float(axis),
        lateral_limit_m=t.inner_radius_m,  # the centre stays within R − r of the axis: never reached
        end_limit_m=params.track.half_length_m,
    )


def apply_tube(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The tube in place of the wires (see the module docstring): the duct's floor, walls and roof along
    ±(half length + r + clearance), the caps closing it, the drawn shell; the track's sites on the bottom line."""
    beam = remove_wires(spec)
    t, r = p.of(Tube), p.ball.radius_m
    big_r, wall, bottom = t.inner_radius_m, t.wall_thickness_m, t.bottom_height_m
    half_t = wall / 2
    inside = p.track.half_length_m + r + CAP_CLEARANCE_M  # the caps' inner faces
    along = inside + wall  # the duct's half length, the caps included
    axis_z = bottom + big_r
    glass = (0.80, 0.90, 0.95, 0.25)
    add_contact_box(beam, p, DUCT[0], [along, big_r + wall, half_t], [0.0, 0.0, bottom - half_t], rgba=glass)
    add_contact_box(beam, p, DUCT[1], [along, half_t, big_r], [0.0, big_r + half_t, axis_z], rgba=glass)
    add_contact_box(beam, p, DUCT[2], [along, half_t, big_r], [0.0, -(big_r + half_t), axis_z], rgba=glass)
    add_contact_box(
        beam, p, DUCT[3], [along, big_r + wall, half_t], [0.0, 0.0, axis_z + big_r + half_t], rgba=glass
    )
    for name, side in zip(CAPS, (1.0, -1.0), strict=True):
        add_contact_box(beam, p, name, [half_t, big_r, big_r], [side * (inside + half_t), 0.0, axis_z])
    shell = beam.add_geom()
    shell.name = SHELL
    shell.type = mujoco.mjtGeom.mjGEOM_CYLINDER
    shell.size = [big_r + wall, 0.0, 0.0]
    shell.fromto = [-along, 0.0, axis_z, along, 0.0, axis_z]
    shell.contype = 0
    shell.conaffinity = 0
    shell.group = 2
    shell.mass = 0.0
    shell.rgba = [0.80, 0.90, 0.95, 0.3]
    set_track_sites(spec, p)


def _equation(params: Sequence[Parameters]) -> tuple[np.ndarray, np.ndarray]:
    return tube_rolling(
        np.array([p.ball.radius_m for p in params]), np.array([p.of(Tube).bottom_height_m for p in params])
    )


def _inputs(rng: np.random.Generator, n: int) -> list[Parameters]:
    """Tubes of 10 to 20 mm bore radius, bottoms within ±20 mm of the pivot, balls of 4 to 9 mm radius."""
    return [
        Parameters().with_overrides(
            {
                "parts.track": "tube",
                "tube.inner_radius_m": big_r,
                "tube.bottom_height_m": bottom,
                "ball.radius_m": radius,
            },
            origin="batch form",
        )
        for big_r, bottom, radius in zip(
            rng.uniform(0.01, 0.02, n).tolist(),
            rng.uniform(-0.02, 0.02, n).tolist(),
            rng.uniform(0.004, 0.009, n).tolist(),
            strict=True,
        )
    ]


register_group("tube", Tube)
register_track_geometry("tube", tube_geometry)

TUBE = register(
    Part(
        name="tube",
        role="track",
        source="a closed tube: the ball on its bottom (r* = r), held in sideways, stopped by end caps; a ball "
        "that reaches a cap is lost (twin.parts.tube); geometry assumed (a 20 mm bore), measure yours",
        groups={"track": GROUPS["track"], "tube": Tube},
        equations=(tube_rolling, tube_geometry),
        mjcf=MjcfFragment(
            tuple(("geom", name) for name in (*DUCT, *CAPS, SHELL))
            + tuple(("site", name) for name in ("track_centre", "track_end_pos", "track_end_neg")),
            apply_tube,
        ),
        batch=geometry_form(_equation, _inputs, "twin.parts.tube.tube_rolling"),
    )
)
