"""Print the physical core's acceptance figures: rolling, motor law, linearization, trajectory, lost ball.

python scripts/core_figures.py
"""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from twin.linearize import linearize_mujoco
from twin.parameters import Parameters
from twin.plant import Plant
from twin.reference import ReferenceModel


def rolling(params: Parameters) -> None:
    for theta in (0.05, 0.1, 0.3):
        plant = Plant(params, hold_beam_rad=theta)
        plant.reset(x_m=0.25)
        t, x, v, w = [], [], [], []
        for _ in range(300):
            plant.step(0.0)
            s = plant.state()
            (
                t.append(plant.time_s),
                x.append(s[0]),
                v.append(s[2]),
                w.append(plant.ball_kinematics().spin_rad_s),
            )
        accel = 2 * np.polyfit(t, x, 2)[0]
        theory = -params.physics.gravity_m_s2 * math.sin(theta) / (1 + params.rolling_inertia_ratio)
        ratio = np.array(v[50:]) / (-params.rolling_radius_m * np.array(w[50:]))
        print(
            f"rolling θ={theta:.2f} rad: accel/theory = {accel / theory:.6f}, "
            f"v/(r*ω) in [{ratio.min():.6f}, {ratio.max():.6f}]"
        )


def motor(params: Parameters) -> None:
    import mujoco

    plant = Plant(params)
    worst = 0.0
    for volts in np.linspace(-12, 12, 13):
        for rate in np.linspace(-10, 10, 11):
            plant.reset(thetadot_rad_s=float(rate))
            plant.data.ctrl[0] = volts
            mujoco.mj_forward(plant.model, plant.data)
            want = 0.016383 * (volts - 0.154 * rate)
            if abs(want) > 1e-6:
                worst = max(worst, abs(plant.motor_torque_nm() / want - 1))
    plant.reset()
    plant.data.ctrl[0] = 20.0
    mujoco.mj_forward(plant.model, plant.data)
    print(
        f"motor: worst |τ/(0.016383(V−0.154θ̇)) − 1| = {worst:.2e}; 20 V → {plant.motor_torque_nm():.6f} N·m "
        f"(12 V: {0.016383 * 12:.6f})"
    )


def linearization(params: Parameters) -> None:
    ref = ReferenceModel(params)
    for kind in ("torque", "voltage"):
        a, b = linearize_mujoco(params, kind)
        ar, br = ref.linearize(kind)
        worst = max(
            (np.abs(g - w)[np.abs(w) > 1e-3] / np.abs(w)[np.abs(w) > 1e-3]).max()
            for g, w in ((a, ar), (b, br))
        )
        print(f"linearization ({kind}): worst relative error over entries > 1e-3 = {100 * worst:.3f} %")


def trajectory(params: Parameters) -> None:
    ref = ReferenceModel(params)
    a, b = ref.linearize("voltage")
    gain = scipy.signal.place_poles(a, b, [-2.0, -3.0, -4.0, -5.0]).gain_matrix[0]
    for x0 in ((0.15, 0.1, 0.0, 0.0), (-0.2, 0.3, 0.0, 0.0)):
        s, volts = np.array(x0), []
        for _ in range(50):
            volts.append(float(-gain @ s))
            s = ref.simulate(s, [volts[-1]], 0.02, samples_per_hold=1)[1][-1]
        _, rs = ref.simulate(np.array(x0), volts, 0.02)
        plant = Plant(params)
        plant.reset(*x0)
        ts = [plant.state()]
        for u in volts:
            for _ in range(20):
                plant.step(u)
                ts.append(plant.state())
        ts = np.array(ts)
        print(
            f"trajectory from {x0[:2]}: max |Δx| = {1e3 * np.abs(ts[:, 0] - rs[:, 0]).max():.3f} mm, "
            f"max |Δθ| = {1e3 * np.abs(ts[:, 1] - rs[:, 1]).max():.3f} mrad"
        )


def lost(params: Parameters) -> None:
    plant = Plant(params, hold_beam_rad=0.2)
    plant.reset()
    for _ in range(200):
        plant.step(0.0, 20)
    print(
        f"lost ball: lost={plant.ball_lost} at t={plant.ball_lost_time_s:.2f} s, "
        f"state finite={bool(np.all(np.isfinite(plant.state())))}, warnings={plant.warnings()}"
    )


if __name__ == "__main__":
    p = Parameters()
    rolling(p)
    motor(p)
    linearization(p)
    trajectory(p)
    lost(p)
