"""Print the physical core's acceptance figures: rolling, motor law, linearization, trajectory, lost ball.

Measured by twin.rigs.measurements (the tests assert on the same functions).

python scripts/core_figures.py
"""

from __future__ import annotations

import math

from twin.parameters import Parameters
from twin.reference import InputKind
from twin.rigs import measurements as M


def rolling(params: Parameters) -> None:
    for theta in (0.05, 0.1, 0.3):
        r = M.rolling(params, theta)
        theory = -params.physics.gravity_m_s2 * math.sin(theta) / (1 + params.rolling_inertia_ratio)
        print(
            f"rolling θ={theta:.2f} rad: accel/theory = {r.accel_m_s2 / theory:.6f}, "
            f"v/(r*ω) in [{r.speed_over_spin.min():.6f}, {r.speed_over_spin.max():.6f}]"
        )


def motor(params: Parameters) -> None:
    grid = M.motor_torque_grid(params)
    want = 0.016383 * (grid.volts_v[:, None] - 0.154 * grid.thetadot_rad_s[None, :])
    big = abs(want) > 1e-6
    worst = float(abs(grid.torque_nm[big] / want[big] - 1).max())
    rail = M.motor_torque_nm(params, 20.0, 0.0)
    print(
        f"motor: worst |τ/(0.016383(V−0.154θ̇)) − 1| = {worst:.2e}; 20 V → {rail:.6f} N·m "
        f"(12 V: {0.016383 * 12:.6f})"
    )


def linearization(params: Parameters) -> None:
    kinds: tuple[InputKind, ...] = ("torque", "voltage")
    for kind in kinds:
        worst = M.linearization_error(params, kind).worst_rel
        print(f"linearization ({kind}): worst relative error over entries > 1e-3 = {100 * worst:.3f} %")


def trajectory(params: Parameters) -> None:
    for x0 in ((0.15, 0.1, 0.0, 0.0), (-0.2, 0.3, 0.0, 0.0)):
        t = M.trajectory_agreement(params, x0)
        print(
            f"trajectory from {x0[:2]}: max |Δx| = {1e3 * t.max_dx_m:.3f} mm, "
            f"max |Δθ| = {1e3 * t.max_dtheta_rad:.3f} mrad"
        )


def lost(params: Parameters) -> None:
    b = M.ball_loss(params)
    print(
        f"lost ball: lost={b.lost} at t={b.lost_time_s:.2f} s, "
        f"state finite={b.finite_every_tick}, warnings={b.warnings}"
    )


if __name__ == "__main__":
    p = Parameters()
    rolling(p)
    motor(p)
    linearization(p)
    trajectory(p)
    lost(p)
