"""The end-lever drive (twin.parts.linkage): the linkage's exact closure against triangles solved on paper, its
ratio against a finite difference, its inverse, the refusal of a geometry that cannot close, and its MJCF
fragment closed in the compiled model at any beam angle."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from twin.model import HINGE, build_model, drive_joint
from twin.parameters import ParameterError, Parameters
from twin.parts import part_named, rig_parts
from twin.parts.linkage import (
    END_LEVER,
    ROD_END_SITE,
    SERVO_SHAFT,
    Linkage,
    lever_horn_rad,
    lever_joint_angles,
    lever_ratio,
    lever_theta_rad,
)

LEVER = {"parts.beam_drive": "end_lever"}

# A 3-4-5 linkage: attachment L = 0.2 m out, rod r = 0.15 m, crank c = 0.05 m on a shaft at S = (0.15, −0.15).
# φ = 0: pin C = (0.2, −0.15) right below A = (0.2, 0): the rod stands vertical, θ = 0.
# φ = −90°: C = (0.15, −0.2), |C| = 0.25 = √(0.2² + 0.15²): the triangle P–A–C has its right angle at A, so the
# angle at P is arccos(L/|C|) = arctan(3/4) above the line P→C, which points arctan(4/3) below level:
# θ = arctan(3/4) − arctan(4/3).
TRIANGLE = (0.2, 0.15, 0.05, 0.15, -0.15)
# A parallelogram: crank c = L = 0.1 m, shaft r = 0.08 m straight below the pivot, rod r = 0.08 m. P–A and S–C
# are equal and parallel, P–S and C–A too: the beam turns with the horn, θ = φ (the crossed branch would not).
PARALLELOGRAM = (0.1, 0.08, 0.1, 0.0, -0.08)


@pytest.mark.quick
def test_the_closure_solves_the_triangles_drawn_on_paper() -> None:
    assert lever_theta_rad(0.0, *TRIANGLE) == pytest.approx(0.0, abs=1e-15)
    assert lever_theta_rad(-math.pi / 2, *TRIANGLE) == pytest.approx(
        math.atan(3 / 4) - math.atan(4 / 3), abs=1e-14
    )
    for phi in (-0.4, 0.0, 0.5):
        assert lever_theta_rad(phi, *PARALLELOGRAM) == pytest.approx(phi, abs=1e-14)
    # the same on arrays, each its own geometry (the batch form's call)
    geometry = [np.array([a, b]) for a, b in zip(TRIANGLE, PARALLELOGRAM, strict=True)]
    both = lever_theta_rad(np.array([-math.pi / 2, 0.5]), *geometry)
    np.testing.assert_allclose(both, [math.atan(3 / 4) - math.atan(4 / 3), 0.5], atol=1e-14)


@pytest.mark.quick
def test_the_default_ratio_is_crank_over_arm_at_level_and_the_finite_difference_elsewhere() -> None:
    link = Linkage()
    # at level the horn is horizontal and the rod vertical: both ends of the rod rise at the same speed
    assert link.ratio(0.0) == pytest.approx(link.crank_m / link.beam_arm_m, rel=1e-12)
    assert link.crank_m / link.beam_arm_m == pytest.approx(1 / 6)
    h = 1e-6
    for phi in np.linspace(-link.horn_travel_rad, link.horn_travel_rad, 9):
        central = (link.theta_rad(phi + h) - link.theta_rad(phi - h)) / (2 * h)
        assert link.ratio(phi) == pytest.approx(central, rel=1e-7)
    assert lever_ratio(0.3, *PARALLELOGRAM) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.quick
def test_the_inverse_undoes_the_closure_over_the_travel() -> None:
    link = Linkage()
    phis = np.linspace(-link.horn_travel_rad, link.horn_travel_rad, 41)
    np.testing.assert_allclose(link.horn_rad(link.theta_rad(phis)), phis, atol=1e-12)
    thetas = link.theta_rad(phis)
    np.testing.assert_allclose(link.theta_rad(link.horn_rad(thetas)), thetas, atol=1e-12)
    assert lever_horn_rad(math.atan(3 / 4) - math.atan(4 / 3), *TRIANGLE) == pytest.approx(
        -math.pi / 2, abs=1e-12
    )
    # the attachment the closure finds lies one rod length from the pin (the closure itself, checked directly)
    for phi in phis:
        theta = float(link.theta_rad(phi))
        pin = (link.shaft_x_m + link.crank_m * math.cos(phi), link.shaft_z_m + link.crank_m * math.sin(phi))
        end = (link.beam_arm_m * math.cos(theta), link.beam_arm_m * math.sin(theta))
        assert math.dist(pin, end) == pytest.approx(link.rod_m, abs=1e-14)


@pytest.mark.quick
def test_a_linkage_that_cannot_close_or_passes_a_dead_point_is_refused_naming_its_fields() -> None:
    # rod 20 mm: the pin 0.18 m from the pivot cannot reach an attachment 0.15 m out (needs 0.13…0.17 m)
    with pytest.raises(ParameterError, match=r"linkage\.rod_m.*cannot reach"):
        Parameters().with_overrides({"linkage.rod_m": 0.02})
    # ±90°: the default horn lines up with its rod near +80°
    with pytest.raises(ParameterError, match=r"linkage\.horn_travel_rad.*dead point"):
        Parameters().with_overrides({"linkage.horn_travel_rad": math.pi / 2})
    # the level beam needs the horn at 0°: a travel of 20…60° does not reach it
    with pytest.raises(ParameterError, match="level beam"):
        Parameters().with_overrides({"linkage.horn_neutral_rad": 0.7, "linkage.horn_travel_rad": 0.35})
    with pytest.raises(ParameterError, match=r"linkage\.shaft_z_m"):
        Parameters().with_overrides({"linkage.shaft_z_m": 0.05})  # above the pivot: the other branch


@pytest.mark.quick
def test_the_model_closes_the_linkage_at_any_beam_angle_and_the_actuator_finds_its_joint() -> None:
    params = Parameters().with_overrides(LEVER)
    assert drive_joint(params) == SERVO_SHAFT and drive_joint(Parameters()) == HINGE
    model = build_model(params)
    assert not END_LEVER.mjcf.missing(model)
    assert model.neq == 1 and model.eq_type[0] == mujoco.mjtEq.mjEQ_CONNECT
    data = mujoco.MjData(model)
    link = params.of(Linkage)
    shaft = model.joint(SERVO_SHAFT).qposadr[0]
    rod = model.joint("rod_pin").qposadr[0]
    for theta in (-0.12, 0.0, 0.05, 0.13):
        data.qpos[:] = model.qpos0
        data.qpos[model.joint(HINGE).qposadr[0]] = theta
        data.qpos[shaft], data.qpos[rod] = lever_joint_angles(params, theta)
        mujoco.mj_forward(model, data)
        # the rod's tip sits on the beam's site, L out along the tilted beam
        assert np.linalg.norm(data.site("rod_tip").xpos - data.site(ROD_END_SITE).xpos) < 1e-12
        tilted = data.site(ROD_END_SITE).xpos - data.body("beam").xpos
        assert tilted[[0, 2]] == pytest.approx(link.beam_arm_m * np.array([math.cos(theta), math.sin(theta)]))
        # the shaft's joint reads the servo's own angle: φ − neutral
        assert data.qpos[shaft] == pytest.approx(
            float(link.horn_rad(theta)) - link.horn_neutral_rad, abs=1e-12
        )
    # the push-rod's mass is the linkage group's, on its body
    assert model.body("push_rod").mass[0] == pytest.approx(link.rod_mass_kg)


@pytest.mark.quick
def test_the_part_keeps_its_contract() -> None:
    assert part_named("beam_drive", "end_lever") is END_LEVER
    assert rig_parts(Parameters().with_overrides(LEVER)).beam_drive is END_LEVER
    assert END_LEVER.batch.difference(np.random.default_rng(20261207), 24) <= END_LEVER.batch.tolerance
    for eq in END_LEVER.equations:
        assert (eq.__doc__ or "").strip()


@pytest.mark.quick
def test_a_servo_beyond_the_attachment_with_its_horn_reaching_back_works_the_other_way() -> None:
    # shaft at (L + c, −r) = (0.175, −0.1), horn pointing back along −x at its centre: the pin sits right below the
    # attachment, the rod vertical, so θ = 0; turning the horn by +φ (from −x toward −z) lowers the pin by c·φ:
    # dθ/dφ = −c/L = −1/6 there
    params = Parameters().with_overrides({"linkage.shaft_x_m": 0.175, "linkage.horn_neutral_rad": math.pi})
    link = params.of(Linkage)
    assert link.theta_rad(math.pi) == pytest.approx(0.0, abs=1e-15)
    assert link.ratio(math.pi) == pytest.approx(-1 / 6, rel=1e-12)
    assert link.sense == -1.0
    phis = np.linspace(math.pi - link.horn_travel_rad, math.pi + link.horn_travel_rad, 21)
    np.testing.assert_allclose(link.horn_rad(link.theta_rad(phis)), phis, atol=1e-12)
    model = build_model(params.with_overrides({"parts.beam_drive": "end_lever"}))
    data = mujoco.MjData(model)
    theta = 0.08
    data.qpos[model.joint(HINGE).qposadr[0]] = theta
    shaft, rod = lever_joint_angles(params, theta)
    data.qpos[model.joint(SERVO_SHAFT).qposadr[0]] = shaft
    data.qpos[model.joint("rod_pin").qposadr[0]] = rod
    mujoco.mj_forward(model, data)
    assert np.linalg.norm(data.site("rod_tip").xpos - data.site(ROD_END_SITE).xpos) < 1e-12
    assert shaft < 0.0  # the beam up means the horn turned back (the servo's angle negative)


@pytest.mark.quick
def test_the_closures_slope_is_the_derivative_of_its_ratio() -> None:
    """``twin.drive_equations.lever_ratio_slope`` (the closed form the kernel and the reference model share):
    its dρ/dφ against a central difference of its ρ, at the default geometry's level and ±30°."""
    from twin.drive_equations import lever_ratio, lever_ratio_slope, lever_theta_rad

    geometry = (0.15, 0.1, 0.025, 0.125, -0.1)  # L, r, c, S_x, S_z
    length, _, crank, shaft_x, shaft_z = geometry
    for phi in (-0.5, 0.0, 0.5):
        theta = float(lever_theta_rad(phi, *geometry))
        ratio, slope = lever_ratio_slope(theta, phi, length, crank, shaft_x, shaft_z)
        h = 1e-6
        numeric = (lever_ratio(phi + h, *geometry) - lever_ratio(phi - h, *geometry)) / (2 * h)
        assert ratio == pytest.approx(lever_ratio(phi, *geometry), rel=1e-12)
        assert slope == pytest.approx(numeric, rel=1e-6, abs=1e-9)
