"""What the track parts beyond the thesis's wires share (``twin.parts.v_groove``, ``rod_strip``, ``tube``): their
MJCF fragments' common steps (the wires removed, a contact geom set as ``twin.model.apply_track`` sets the wires,
the track's sites) and their batch form's common shape (each run's geometry from the rig against the track's
equation on arrays).

A track enters the dynamics only through its geometry (``twin.parameters.TrackGeometry``: r* and h*), which
each track's module registers with ``twin.parameters.register_track_geometry``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import mujoco
import numpy as np

from twin import model as mdl
from twin.parameters import Parameters
from twin.parts.contract import BatchForm

__all__ = ["add_contact_box", "geometry_form", "remove_wires", "set_track_sites"]


def remove_wires(spec: mujoco.MjSpec) -> Any:
    """Delete the two wires ``wire_rod`` and ``wire_spring`` from the beam (a track of another shape replaces
    them); returns the beam's body, for the track's own geoms."""
    for name in mdl.WIRES:
        wire = spec.geom(name)
        if wire is not None:
            spec.delete(wire)
    beam = spec.body(mdl.BEAM_BODY)
    if beam is None:
        raise mdl.ModelError(f"the model has no body {mdl.BEAM_BODY!r} to lay the track on")
    return beam


def set_contact(geom: Any, p: Parameters) -> None:
    """The contact settings ``twin.model.apply_track`` gives the wires: condim 3 (rolling without slipping),
    the track's friction, solref with the 2·timestep time constant, the contacts' impedance and margin."""
    impedance = p.physics.contact_impedance
    geom.condim = 3
    geom.contype = 1
    geom.conaffinity = 1
    geom.group = 3
    geom.friction = [p.track.friction, 0.0, 0.0]
    geom.solref = [p.physics.contact_timeconst_s, 1.0]
    geom.solimp = [impedance, impedance, 0.001, 0.5, 2.0]
    geom.margin = p.physics.contact_margin_m


def add_contact_box(
    beam: Any,
    p: Parameters,
    name: str,
    half_m: Sequence[float],
    pos_m: Sequence[float],
    quat: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
    rgba: Sequence[float] = (0.75, 0.77, 0.80, 1.0),
) -> Any:
    """A box of half-sizes ``half_m`` at ``pos_m`` (beam frame, turned by ``quat``) that the ball touches
    (``set_contact``); massless, the beam's inertia is its group's (``twin.model.apply_beam_drive``)."""
    geom = beam.add_geom()
    geom.name = name
    geom.type = mujoco.mjtGeom.mjGEOM_BOX
    geom.size = [float(v) for v in half_m]
    geom.pos = [float(v) for v in pos_m]
    geom.quat = [float(v) for v in quat]
    geom.mass = 0.0
    geom.rgba = [float(v) for v in rgba]
    set_contact(geom, p)
    return geom


def set_track_sites(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The track's sites ``track_centre``, ``track_end_pos``, ``track_end_neg``: at x = 0, ±``half_length_m`` on
    the rolling axis (h* above the pivot), as the wires' fragment puts them."""
    half, height = p.track.half_length_m, p.rolling_axis_height_m
    for name, x in zip(mdl.TRACK_SITES, (0.0, half, -half), strict=True):
        site = spec.site(name)
        if site is None:
            raise mdl.ModelError(f"the model has no site {name!r}")
        site.pos = [x, 0.0, height]


def geometry_form(
    equation: Callable[[Sequence[Parameters]], tuple[np.ndarray, np.ndarray]],
    inputs: Callable[[np.random.Generator, int], list[Parameters]],
    home: str,
) -> BatchForm:
    """A track's batch form: one run's (r*, h*, ball centre height) as the rig reads them (``Parameters``'
    properties, through the registered geometry) against ``equation`` on every run's numbers at once (arrays,
    one entry a run), which gives (r*, h*); ``inputs(rng, n)`` draws the runs' parameters."""

    def single(params: Parameters, row: np.ndarray) -> np.ndarray:
        return np.array([params.rolling_radius_m, params.rolling_axis_height_m, params.ball_centre_height_m])

    def batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
        rolling, axis = equation(params)
        return np.column_stack([rolling, axis, axis + rolling])

    def draw(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
        return inputs(rng, n), np.zeros((n, 0))

    return BatchForm(single, batch, draw, home, tolerance=1e-15)
