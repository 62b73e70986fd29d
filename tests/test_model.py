"""The MJCF rig: compiles, steps without warnings, every element named, XML consistent with the parameters."""

import subprocess
import sys
import zipfile
from pathlib import Path

import mujoco
import numpy as np
import pytest

from twin import model as mdl
from twin.parameters import Parameters
from twin.plant import Plant

REPO = Path(__file__).resolve().parent.parent


def test_steps_two_seconds_of_random_volts_without_warnings() -> None:
    plant = Plant()
    plant.reset(x_m=0.05, theta_rad=0.02)
    rng = np.random.default_rng(20261122)
    for volts in rng.uniform(-12.0, 12.0, size=100):  # a new command every 20 ms for 2 s
        plant.step(float(volts), n_steps=20)
        assert np.all(np.isfinite(plant.data.qpos)) and np.all(np.isfinite(plant.data.qvel))
    assert plant.time_s == pytest.approx(2.0)
    assert plant.warnings() == {}


def test_every_element_is_named() -> None:
    m = mdl.build_model()
    for kind, count in (
        ("body", m.nbody),
        ("jnt", m.njnt),
        ("geom", m.ngeom),
        ("site", m.nsite),
        ("actuator", m.nu),
        ("sensor", m.nsensor),
        ("cam", m.ncam),
        ("light", m.nlight),
    ):
        obj = {
            "body": mujoco.mjtObj.mjOBJ_BODY,
            "jnt": mujoco.mjtObj.mjOBJ_JOINT,
            "geom": mujoco.mjtObj.mjOBJ_GEOM,
            "site": mujoco.mjtObj.mjOBJ_SITE,
            "actuator": mujoco.mjtObj.mjOBJ_ACTUATOR,
            "sensor": mujoco.mjtObj.mjOBJ_SENSOR,
            "cam": mujoco.mjtObj.mjOBJ_CAMERA,
            "light": mujoco.mjtObj.mjOBJ_LIGHT,
        }[kind]
        start = 1 if kind == "body" else 0  # body 0 is the world
        for i in range(start, count):
            assert mujoco.mj_id2name(m, obj, i), f"unnamed {kind} {i}"


@pytest.mark.quick
def test_xml_holds_the_same_values_as_the_parameters() -> None:
    """The XML alone (for viewers and tools) and the twin's build agree: one source of truth."""
    raw = mujoco.MjModel.from_xml_path(str(mdl.model_path()))
    built = mdl.build_model(Parameters())
    for field in (
        "body_mass",
        "body_inertia",
        "body_ipos",
        "body_pos",
        "geom_size",
        "geom_pos",
        "geom_friction",
        "geom_solref",
        "geom_solimp",
        "geom_margin",
        "jnt_range",
        "jnt_axis",
        "actuator_gear",
        "actuator_gainprm",
        "actuator_ctrlrange",
        "actuator_armature",
        "actuator_damping",
    ):
        np.testing.assert_allclose(
            getattr(raw, field), getattr(built, field), rtol=1e-9, atol=1e-12, err_msg=field
        )
    assert raw.opt.timestep == built.opt.timestep
    np.testing.assert_allclose(raw.opt.gravity, built.opt.gravity)


@pytest.mark.quick
def test_model_carries_the_thesis_geometry(params: Parameters) -> None:
    m = mdl.build_model(params)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    ball = m.body("ball").id
    beam = m.body("beam").id
    # Ball centre h* + r* = 21.957 mm above the pivot (eq 3.1.3, r* = 4.676 mm).
    assert d.xpos[ball][2] - d.xpos[beam][2] == pytest.approx(17.281e-3 + 4.676e-3, abs=1e-6)
    assert m.body_mass[ball] == pytest.approx(18.848e-3)
    # J_BP about the pivot: inertia about the centre of gravity + M_B h^2 = 4e-3 kg m^2 (Table 3.1).
    assert m.body_inertia[beam][1] + m.body_mass[beam] * m.body_ipos[beam][2] ** 2 == pytest.approx(4e-3)
    # Each wire's surface point nearest the ball centre is a contact point: h* above P, d/2 to the side.
    centre = np.array([0.0, 0.0, params.ball_centre_height_m])
    for name, side in (("wire_rod", 1.0), ("wire_spring", -1.0)):
        g = m.geom(name)
        axis_point = np.array([0.0, g.pos[1], g.pos[2]])
        to_axis = axis_point - centre
        contact = centre + to_axis / np.linalg.norm(to_axis) * params.ball.radius_m
        assert contact[2] == pytest.approx(17.281e-3, abs=1e-9)
        assert contact[1] == pytest.approx(side * 13.785e-3 / 2, abs=1e-9)
        assert np.linalg.norm(to_axis) == pytest.approx(params.ball.radius_m + g.size[0], abs=1e-12)


@pytest.mark.quick
def test_ball_rests_on_the_wires_without_sinking(params: Parameters) -> None:
    # With the default margin the ball's rest gap is below 10 nm (0.2 % of r* would be 9 µm).
    assert abs(mdl.measure_rest_gap_m(params)) < 1e-8
    # The default margin is the measured rest penetration without margin (kept current within 2 %).
    no_margin = params.with_overrides({"physics.contact_margin_m": 0.0})
    assert -mdl.measure_rest_gap_m(no_margin) == pytest.approx(params.physics.contact_margin_m, rel=0.02)


def test_held_beam_has_no_hinge_and_the_given_angle() -> None:
    plant = Plant(hold_beam_rad=0.1)
    assert plant.model.nu == 0 and plant.model.nq == 7
    assert plant.state()[1] == pytest.approx(0.1)


@pytest.mark.quick
def test_bad_initial_states_are_refused() -> None:
    plant = Plant()
    with pytest.raises(ValueError, match="x_m = 0.5"):
        plant.reset(x_m=0.5)
    with pytest.raises(ValueError, match="theta_rad = 1.0"):
        plant.reset(theta_rad=1.0)
    with pytest.raises(ValueError, match="nan"):
        plant.reset(xdot_m_s=float("nan"))
    with pytest.raises(ValueError, match="motor_volts = nan"):
        plant.step(float("nan"))


@pytest.mark.slow
def test_plain_install_ships_the_model(tmp_path) -> None:
    """A non-editable wheel carries models/ballbeam.xml inside the twin package."""
    pytest.importorskip("hatchling")
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(tmp_path),
            str(REPO),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    wheel = next(tmp_path.glob("ballbeam_twin-*.whl"))
    target = tmp_path / "site"
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
        assert "twin/models/ballbeam.xml" in names
        assert any(n.startswith("controllers/") for n in names) and any(n.startswith("calib/") for n in names)
        zf.extractall(target)
    probe = subprocess.run(
        [sys.executable, "-c", "import twin.model as m; print(m.model_path()); m.build_model()"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={"PYTHONPATH": str(target), "PATH": ""},
        timeout=120,
    )
    assert probe.returncode == 0, probe.stderr
    assert Path(probe.stdout.strip()).is_relative_to(target)


def test_compiled_once_and_each_caller_gets_its_own_copy():
    """``build_model`` compiles once per parameters and hands out copies: a caller that changes its model
    (the linearization switches the integrator) changes no other's, and different parameters compile anew."""
    first, second = mdl.build_model(), mdl.build_model()
    assert first is not second
    first.opt.timestep = 0.005
    first.actuator_gainprm[0, 0] = 0.0
    third = mdl.build_model()
    assert third.opt.timestep == second.opt.timestep == Parameters().physics.timestep_s
    assert third.actuator_gainprm[0, 0] == second.actuator_gainprm[0, 0] != 0.0
    heavier = mdl.build_model(Parameters().with_overrides({"ball.mass_kg": 0.1}))
    assert heavier.body(mdl.BALL_BODY).mass[0] == pytest.approx(0.1)
    assert mdl.build_model().body(mdl.BALL_BODY).mass[0] == pytest.approx(Parameters().ball.mass_kg)
