"""Quanser BB01's track (``ROD_AND_STRIP``, role ``track``): the ball rides a steel rod and the edge of a resistive
strip beside it ("a steel rod in parallel with a nickel-chromium wire-wound resistor forming the track": BB01 User
Manual, Quanser Doc. No. 709 Rev 2.1, §2.2.1). Its parameter group ``rod_strip``, its geometry
(``rod_strip_rolling``), its MJCF fragment.

Geometry (the beam's cross-section, y across, z up; heights above the pivot): the rod's axis A at y = 0, height
``rod_axis_height_m``, radius ρ (``rod_radius_m``); the strip flat, its inner top edge E ``edge_offset_m`` across
from the rod's axis at height ``edge_height_m``. On a flat face the contact's normal is vertical and pushes the
ball nowhere sideways, so the ball, pushed off the round rod, rolls to the strip's edge and rests there: its
contacts are the rod's surface and the strip's edge, two lines along the beam.

    centre       C is r + ρ from A (touching the rod) and r from E (touching the edge): the upper intersection of
                 the two circles. With D = |E − A| and u = (E − A)/D, n = u turned +90°:
                 C = A + l·u + k·n,  l = ((r + ρ)² − r² + D²)/(2D),  k = √((r + ρ)² − l²)
    contacts     P₁ = A + ρ·(C − A)/(r + ρ) on the rod, P₂ = E; both r from C, s = |P₂ − P₁| apart
    rolling      the ball rolls about the line P₁P₂ (the two contacts do not move): r* = √(r² − s²/4), its
                 distance from C (the two wires' formula with d = s); the centre's height z_C; h* = z_C − r*

The ball must rest between the rod and the edge (A_y < C_y < E_y, the centre above the edge: else it lies on the
strip's face or falls through the gap, D < 2r + ρ): refused, naming the fields. The model places the rod and the
strip so that the ball's centre lies over the beam's axis (y = 0), as the plant puts it.

The tilt. P₁ and P₂ are at different heights unless the geometry says otherwise (the rod's contact lies on its
flank, below its top): the rolling axis P₁P₂ tilts by β = atan((z₂ − z₁)/(y₂ − y₁)) about the beam's axis, and the
ball's spin relative to the beam, ẋ/r* about P₁P₂, has the component ẋ·cos β/r* about the hinge's axis. The
ball's kinetic energy, ½·m·ẋ² + ½·J·ẋ²/r*² on a still beam, does not see β (a sphere's inertia is the same about
every axis): a held beam's rolling, g·sin θ/(1 + 2r²/(5r*²)), is exact. Turning with the beam it couples through
J·θ̇·ẋ·cos β/r*: eq 3.1.26's k₂ = 2r²/(5r*) becomes k₂·cos β, and eq 3.1.27's h* in α₁ and α₂ becomes z_C − r*·cos β
and z_C − r*/cos β. The reference model keeps β = 0 (h* = z_C − r*): the error is k₂·(1 − cos β), against
k₂ + c in the coupling. With BB01's assumed geometry and ball (r = 12.7 mm) β = 1.51°, 1 − cos β = 3.5e-4, and
k₂ = 5.7 mm against c = 34.4 mm: the coupling's coefficient moves by 0.005 % (the thesis's ball on it: β = 3.40°,
0.023 %; tests/test_part_tracks.py computes both): it does not matter beside the assumed geometry's own
uncertainty. MuJoCo rolls the ball about the true, tilted axis (its spin about the hinge's axis is 1/cos β of
ẋ/r*'s, 1.00035 with BB01's ball, as measured).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

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
from twin.parts.tracks import add_contact_box, geometry_form, remove_wires, set_contact, set_track_sites

__all__ = ["ROD", "ROD_AND_STRIP", "STRIP", "RodStrip", "RodStripRest", "apply_rod_strip", "rod_strip_geometry",
           "rod_strip_rolling"]  # fmt: skip

ROD, STRIP = "track_rod", "track_strip"  # the rod's capsule and the strip's box
# The strip's box beyond its inner edge (drawn and collided; only the edge touches the ball): a 10 mm wide strip
# on a 3 mm plastic carrier (BB01 User Manual §2.2.1: "the black strip that is stuck on the plastic").
_STRIP_WIDTH_M = 0.01
_STRIP_DEPTH_M = 0.003


@dataclass(frozen=True)
class RodStrip:
    """BB01's track: the steel rod (radius, axis height) and the strip's inner top edge (across, height)."""

    rod_radius_m: float = param(
        3.175e-3,
        "m",
        "assumed: a 1/4 in (6.35 mm) steel rod; the BB01 User Manual (§2.2.1, Table 2) names the rod, not its "
        "diameter; measure yours",
        gt=0.0,
        le=0.05,
        why="a rod a bench-top ball rolls on: millimetres thick",
    )
    rod_axis_height_m: float = param(
        0.02,
        "m",
        "assumed: the rod's axis 20 mm above the pivot's axis (not published); measure yours",
        ge=-0.5,
        le=0.5,
        why="the rod lies on the beam, within 0.5 m of its pivot (negative: below it)",
    )
    edge_offset_m: float = param(
        0.0127,
        "m",
        "assumed: the strip's inner edge 1/2 in (12.7 mm) across from the rod's axis (not published); measure "
        "yours",
        gt=0.0,
        le=0.2,
        why="the strip lies beside the rod, closer than the largest ball's diameter",
    )
    edge_height_m: float = param(
        0.023175,
        "m",
        "assumed: the strip's top level with the rod's top (axis 20 mm + 3.175 mm; not published); measure yours",
        ge=-0.5,
        le=0.5,
        why="the strip lies on the beam, within 0.5 m of its pivot (negative: below it)",
    )

    def __post_init__(self) -> None:
        check_group(self, "rod_strip")


class RodStripRest(NamedTuple):
    """Where the ball rests on the rod and the strip's edge, relative to the rod's axis (y across, z up): its
    centre, its contact on the rod, the rolling radius r*, the contacts' spacing s and the axis' tilt β."""

    centre_y_m: Any
    centre_z_m: Any
    rod_contact_y_m: Any
    rod_contact_z_m: Any
    rolling_radius_m: Any
    spacing_m: Any
    tilt_rad: Any


def rod_strip_rolling(radius_m: Any, rod_radius_m: Any, edge_y_m: Any, edge_dz_m: Any) -> RodStripRest:
    """The ball's rest on a rod (radius ρ, axis at the origin) and an edge at (``edge_y_m``, ``edge_dz_m``) from
    the rod's axis (see the module docstring): floats or numpy arrays alike. NaN where the ball falls through."""
    reach = radius_m + rod_radius_m
    dist = np.hypot(edge_y_m, edge_dz_m)
    ux, uz = edge_y_m / dist, edge_dz_m / dist
    along = (reach * reach - radius_m * radius_m + dist * dist) / (2.0 * dist)
    with np.errstate(invalid="ignore"):  # a gap wider than the ball: NaN, refused by the geometry's checks
        up = np.sqrt(reach * reach - along * along)
    cy, cz = along * ux - up * uz, along * uz + up * ux  # n = u turned +90°: (−u_z, u_y)
    py, pz = rod_radius_m * cy / reach, rod_radius_m * cz / reach
    spacing = np.hypot(edge_y_m - py, edge_dz_m - pz)
    rolling = np.sqrt(radius_m * radius_m - spacing * spacing / 4.0)
    return RodStripRest(cy, cz, py, pz, rolling, spacing, np.arctan2(edge_dz_m - pz, edge_y_m - py))


def _refusal(g: RodStrip, r: float, rest: RodStripRest) -> str | None:
    reach, dist = r + g.rod_radius_m, math.hypot(g.edge_offset_m, g.edge_height_m - g.rod_axis_height_m)
    if dist >= reach + r:
        return f"the gap between the rod and the strip's edge ({dist - g.rod_radius_m:.6g} m) is wider than the ball"
    if not 0.0 < float(rest.centre_y_m) < g.edge_offset_m:
        return "the ball's centre does not lie between the rod and the strip's edge (it rests on the strip's face)"
    if not float(rest.centre_z_m) > g.edge_height_m - g.rod_axis_height_m:
        return "the ball's centre lies below the strip's edge (it is wedged under it)"
    return None


def rod_strip_geometry(params: Parameters) -> TrackGeometry:
    """The rod and strip's ``TrackGeometry`` for the rig ``params`` (its ball and ``rod_strip`` group): r*, the
    centre's height z_C, h* = z_C − r*; sideways, the ball is off past its nearer contact; off the end as the
    wires' (past the end by r)."""
    g, r = params.of(RodStrip), params.ball.radius_m
    dz = g.edge_height_m - g.rod_axis_height_m
    rest = rod_strip_rolling(r, g.rod_radius_m, g.edge_offset_m, dz)
    refusal = _refusal(g, r, rest)
    if refusal is not None:
        raise ParameterError(
            f"rod_strip.rod_radius_m, rod_axis_height_m, edge_offset_m, edge_height_m = {g.rod_radius_m!r}, "
            f"{g.rod_axis_height_m!r}, {g.edge_offset_m!r}, {g.edge_height_m!r} m are impossible together with "
            f"the ball's radius {r!r} m: {refusal}"
        )
    rolling = float(rest.rolling_radius_m)
    cy = float(rest.centre_y_m)
    return TrackGeometry(
        rolling_radius_m=rolling,
        axis_height_m=(g.rod_axis_height_m + float(rest.centre_z_m)) - rolling,
        lateral_limit_m=min(cy - float(rest.rod_contact_y_m), g.edge_offset_m - cy),
        end_limit_m=params.track.half_length_m + r,
    )


def apply_rod_strip(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The rod (capsule ``track_rod``) and the strip (box ``track_strip``, its inner top edge the contact) in place
    of the wires, along ±``track.half_length_m``, placed so the ball's centre lies over the beam's axis; the
    wires' contact settings; the track's sites on the rolling axis."""
    beam = remove_wires(spec)
    g, r, half_len = p.of(RodStrip), p.ball.radius_m, p.track.half_length_m
    rest = rod_strip_rolling(r, g.rod_radius_m, g.edge_offset_m, g.edge_height_m - g.rod_axis_height_m)
    rod_y = -float(rest.centre_y_m)  # the rod on the −y side, the ball's centre at y = 0
    rod = beam.add_geom()
    rod.name = ROD
    rod.type = mujoco.mjtGeom.mjGEOM_CAPSULE
    rod.size = [g.rod_radius_m, 0.0, 0.0]
    rod.fromto = [-half_len, rod_y, g.rod_axis_height_m, half_len, rod_y, g.rod_axis_height_m]
    rod.mass = 0.0
    rod.rgba = [0.55, 0.57, 0.62, 1.0]
    set_contact(rod, p)
    edge_y = rod_y + g.edge_offset_m
    add_contact_box(
        beam,
        p,
        STRIP,
        [half_len, _STRIP_WIDTH_M / 2, _STRIP_DEPTH_M / 2],
        [0.0, edge_y + _STRIP_WIDTH_M / 2, g.edge_height_m - _STRIP_DEPTH_M / 2],
        rgba=(0.1, 0.1, 0.1, 1.0),
    )
    set_track_sites(spec, p)


def _equation(params: Sequence[Parameters]) -> tuple[np.ndarray, np.ndarray]:
    groups = [p.of(RodStrip) for p in params]
    axis = np.array([g.rod_axis_height_m for g in groups])
    rest = rod_strip_rolling(
        np.array([p.ball.radius_m for p in params]),
        np.array([g.rod_radius_m for g in groups]),
        np.array([g.edge_offset_m for g in groups]),
        np.array([g.edge_height_m for g in groups]) - axis,
    )
    return rest.rolling_radius_m, (axis + rest.centre_z_m) - rest.rolling_radius_m


def _inputs(rng: np.random.Generator, n: int) -> list[Parameters]:
    """BB01-like tracks: the edge 11 to 14 mm across and −1 to +4 mm above the rod's axis, rods of 2.5 to 4 mm
    radius, balls of 8 to 13 mm radius."""
    return [
        Parameters().with_overrides(
            {
                "parts.track": "rod_and_strip",
                "rod_strip.rod_radius_m": rho,
                "rod_strip.edge_offset_m": across,
                "rod_strip.edge_height_m": 0.02 + rise,
                "ball.radius_m": radius,
            },
            origin="batch form",
        )
        for rho, across, rise, radius in zip(
            rng.uniform(0.0025, 0.004, n).tolist(),
            rng.uniform(0.011, 0.014, n).tolist(),
            rng.uniform(-0.001, 0.004, n).tolist(),
            rng.uniform(0.008, 0.013, n).tolist(),
            strict=True,
        )
    ]


register_group("rod_strip", RodStrip)
register_track_geometry("rod_and_strip", rod_strip_geometry)

ROD_AND_STRIP = register(
    Part(
        name="rod_and_strip",
        role="track",
        source="Quanser BB01 User Manual (Doc. No. 709 Rev 2.1) §2.2.1: a steel rod beside a nickel-chromium "
        "wire-wound resistor strip; the ball on the rod and the strip's edge (r* and the centre derived in "
        "twin.parts.rod_strip); dimensions not published: assumed, measure yours",
        groups={"track": GROUPS["track"], "rod_strip": RodStrip},
        equations=(rod_strip_rolling, rod_strip_geometry),
        mjcf=MjcfFragment(
            (("geom", ROD), ("geom", STRIP))
            + tuple(("site", name) for name in ("track_centre", "track_end_pos", "track_end_neg")),
            apply_rod_strip,
        ),
        batch=geometry_form(_equation, _inputs, "twin.parts.rod_strip.rod_strip_rolling"),
    )
)
