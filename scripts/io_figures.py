"""Print the I/O chain's acceptance figures: angle staircase and eq 6.2.4, Table 6.3 readings, RC time
constant, dropout rate, output stage, seeds, log round trip — measured on the twin's own code by
twin.rigs.measurements (the tests assert on the same functions).

    python scripts/io_figures.py
"""

from __future__ import annotations

import math

import numpy as np

from controllers.appendix import AppendixControlLaw
from twin.parameters import Parameters
from twin.rigs import measurements as M
from twin.rigs.sim import run_closed_loop

P = Parameters()


def angle() -> None:
    steps = M.angle_staircase(P).steps_count
    print(
        f"angle staircase: mean step {steps.mean():.5f} Δ; {np.sum(abs(steps - 1) < 0.01)}/{steps.size} steps "
        f"within ±1 % (the others are 5-LSB steps: {np.unique(np.round(steps[abs(steps - 1) >= 0.01], 4))} Δ)"
    )
    for level in M.counter_levels(P):
        print(
            f"  DI={level.di:4d}: eq 6.2.6 {level.dac_v:+.5f} V vs measured {level.measured_v:+.3f} V "
            f"({level.dac_error_lsb:.2f} LSB); after the ±5 V ADC {level.adc_v:+.5f} V "
            f"({level.adc_error_lsb:.2f} LSB)"
        )


def ball() -> None:
    table = M.ball_table_readings(P)
    print(
        f"Table 6.3 on the twin, noise off: worst |reading − table| = {table.worst_error_lsb:.2f} LSB "
        f"over {table.position_m.size} points"
    )
    tau = P.ball_sensor.rc_resistance_ohm * P.ball_sensor.rc_capacitance_f
    fit = M.rc_step(P).tau_fall_s
    print(f"RC step response: fitted time constant {1e3 * fit:.4f} ms (147 Ω × 22 µF = {1e3 * tau:.4f} ms)")
    drops = M.dropouts(P)
    rate = P.ball_sensor.dropout_rate_hz
    expected = rate * drops.seconds
    print(
        f"dropouts over {drops.seconds:.0f} s at {rate} Hz: {drops.count} "
        f"(expected {expected:.0f} ± {3 * math.sqrt(expected):.0f} at 3σ)"
    )


def output() -> None:
    for cmd, volts in M.output_stage(P).items():
        print(f"command {cmd:.2f} V → motor {volts:+.4f} V")


def determinism() -> None:
    d = M.seed_determinism(P)
    print(
        f"seeds: same seed identical = {d.same_seed_identical}, "
        f"different seed differs = {d.other_seed_ball_differs}"
    )
    log = run_closed_loop(AppendixControlLaw(), x0_m=0.1, theta0_rad=0.1, duration_s=2.0, seed=3).log
    print(f".mat round trip of a 2 s run: every array identical = {not M.mat_round_trip_mismatches(log)}")


if __name__ == "__main__":
    angle()
    ball()
    output()
    determinism()
