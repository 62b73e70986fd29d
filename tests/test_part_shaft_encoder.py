"""The quadrature encoder on the drive's input shaft (``twin.parts.shaft_encoder``): its count at three crank angles
of the BB01's lever, worked by hand from the four-bar's closure written here (not the project's linkage code); on
the thesis's pivot, the beam's own angle; the software's small-angle conversion; and MuJoCo's drive joint against
the shaft map the chain reads."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

import twin.parts  # noqa: F401  (registers the parts)
from twin.model import drive_joint
from twin.parameters import ParameterError, Parameters
from twin.parts import rig_parts
from twin.parts.description import preset
from twin.parts.shaft_encoder import ShaftEncoderBatch, ShaftEncoderChain, encoder_counts, shaft_angle_of
from twin.physics import PhysicsBlock
from twin.plant import Plant

BB01 = preset("quanser-bb01")
# config_bb.m: L = 16.75 in, r_arm = 1 in; the preset's assumed 100 mm link, vertical at level
L, C, ROD = 0.42545, 0.0254, 0.1
SHAFT = (L - C, -ROD)
COUNTS = 4096  # config_servo.m K_ENC = 2π/(4·1024)


def _beam_angle_by_hand(phi_rad: float) -> float:
    """The beam's angle for the arm at φ: the link's pin C = S + c·(cos φ, sin φ); the coupling A on the circle of
    radius L about the hinge and r about C; the law of cosines in the triangle hinge–C–A gives the angle at the
    hinge between C and A, arccos((L² + |C|² − r²)/(2·L·|C|)), A counter-clockwise of C (the link above the pin)."""
    cx, cz = SHAFT[0] + C * math.cos(phi_rad), SHAFT[1] + C * math.sin(phi_rad)
    d = math.hypot(cx, cz)
    return math.atan2(cz, cx) + math.acos((L * L + d * d - ROD * ROD) / (2.0 * L * d))


def _block(theta_end: float) -> PhysicsBlock:
    return PhysicsBlock(
        np.array([0.0, 0.02]), np.zeros(2), np.array([0.0, theta_end]), np.ones(2, dtype=bool)
    )


@pytest.mark.quick
@pytest.mark.parametrize(
    ("crank_deg", "counts"),
    [
        (10.0, 114),  # 10/360·4096 = 113.78 → the nearest count, 114
        (-30.0, -341),  # −341.33 → −341
        (50.0, 569),  # 568.89 → 569
    ],
)
def test_the_count_is_the_cranks_angle_in_4096ths_of_a_turn(crank_deg: float, counts: int) -> None:
    theta = _beam_angle_by_hand(math.radians(crank_deg))  # the beam where the arm stands at crank_deg
    assert _beam_angle_by_hand(0.0) == pytest.approx(0.0, abs=1e-12)  # level with the arm horizontal
    chain = rig_parts(BB01).angle_sensor.chain(BB01)
    assert isinstance(chain, ShaftEncoderChain)
    assert chain.read_block_v(_block(theta)) == counts
    assert chain.level_v(theta) == counts


@pytest.mark.quick
def test_on_the_thesiss_pivot_the_shaft_is_the_beam() -> None:
    rig = Parameters().with_overrides({"parts.angle_sensor": "shaft_encoder"})
    chain = ShaftEncoderChain(rig)
    assert chain.read_block_v(_block(0.1)) == 65  # 0.1 rad·4096/2π = 65.19
    assert chain.read_block_v(_block(-0.2)) == -130  # −130.39
    assert encoder_counts(np.array([0.0, 2 * math.pi]), 4096).tolist() == [0.0, 4096.0]


@pytest.mark.quick
def test_the_softwares_angle_is_quansers_small_angle_ratio() -> None:
    angle_of = rig_parts(BB01).angle_sensor.angle_of
    assert angle_of is not None
    to_beam = angle_of(BB01)
    # θ_beam = (r_arm/L)·θ_l, θ_l = 2π·n/4096 (Quanser's BB01 model; config_servo.m K_ENC)
    for n in (114, -341, 569):
        assert to_beam(float(n)) == pytest.approx(C / L * 2 * math.pi * n / COUNTS, rel=1e-9)
    # not the exact inverse: the exact beam angle falls below the linear one as the arm swings out
    for deg, ratio in ((10.0, 0.9948), (50.0, 0.8612), (-50.0, 0.8949)):
        phi = math.radians(deg)
        assert _beam_angle_by_hand(phi) / (C / L * phi) == pytest.approx(ratio, abs=1e-4)


@pytest.mark.quick
def test_the_batch_reads_each_runs_own_drive_and_resolution() -> None:
    rigs = [
        BB01,
        Parameters().with_overrides(
            {"parts.angle_sensor": "shaft_encoder", "shaft_encoder.counts_per_rev": 1024}
        ),
    ]
    thetas = np.array([[0.0, _beam_angle_by_hand(math.radians(10.0))], [0.0, 0.1]])
    got = ShaftEncoderBatch(rigs).read(np.arange(2), np.array([0.0, 0.02]), thetas)
    assert got.tolist() == [114.0, 16.0]  # 0.1·1024/2π = 16.30


@pytest.mark.quick
def test_a_resolution_out_of_bounds_is_refused_naming_the_field() -> None:
    with pytest.raises(ParameterError, match="shaft_encoder.counts_per_rev"):
        Parameters().with_overrides({"shaft_encoder.counts_per_rev": 2})


@pytest.mark.quick
def test_mujocos_drive_joint_holds_the_angle_the_shaft_map_gives() -> None:
    """In MuJoCo the encoder's shaft is the drive joint (``twin.model.drive_joint``: the SRV02's load shaft); the
    chain reads the shaft map of the beam's angle, which the joint meets to the link's compliance."""
    plant = Plant(BB01)
    plant.reset(x_m=0.0, theta_rad=0.02)
    joint = plant.model.joint(drive_joint(BB01))
    shaft = shaft_angle_of(BB01)
    worst = 0.0
    for volts in (2.0,) * 100 + (-3.0,) * 100:  # the arm swings up, then down
        plant.data.ctrl[0] = volts
        mujoco.mj_step(plant.model, plant.data)
        theta = plant.state()[1]
        worst = max(worst, abs(float(plant.data.qpos[joint.qposadr[0]]) - shaft(theta)))
    # measured 0.97 mrad: the link's soft connect stretched 2.1e-5 m by the beam's weight, over the 1 in arm;
    # under one count (1.53 mrad)
    assert worst < 2 * math.pi / COUNTS
