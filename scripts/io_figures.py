"""Print the I/O chain's acceptance figures: angle staircase and eq 6.2.4, Table 6.3 readings, RC time
constant, dropout rate, output stage, seeds, log round trip — measured on the twin's own code.

    python scripts/io_figures.py
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from controllers.appendix import AppendixControlLaw
from twin import converters, daq, sensors
from twin.engine import run_closed_loop
from twin.log import load_mat, save_mat
from twin.output_stage import motor_volts
from twin.parameters import Parameters
from twin.rig import TwinRig

P = Parameters()
LSB = daq.adc_lsb_v(P.daq)
STEP = 2 * math.pi / (256 * 7)
KNOTS = np.arange(21) * 1e-3


def angle() -> None:
    counts = np.arange(-216, 217)
    volts = np.array([sensors.angle_block_mean_v(KNOTS, np.full(21, c * STEP), P) for c in counts])
    steps = np.diff(converters.beam_angle_rad(volts, P.software)) / STEP
    print(
        f"angle staircase: mean step {steps.mean():.5f} Δ; {np.sum(abs(steps - 1) < 0.01)}/{steps.size} steps "
        f"within ±1 % (the others are 5-LSB steps: {np.unique(np.round(steps[abs(steps - 1) >= 0.01], 4))} Δ)"
    )
    for di, measured in ((0, -5.042), (512, -0.014), (1023, 5.002)):
        dac_v = sensors.counter_dac_v(di, P)
        read = daq.adc_quantize_v(dac_v, P.daq)
        print(
            f"  DI={di:4d}: eq 6.2.6 {dac_v:+.5f} V vs measured {measured:+.3f} V ({abs(dac_v - measured) / LSB:.2f} "
            f"LSB); after the ±5 V ADC {read:+.5f} V ({abs(read - measured) / LSB:.2f} LSB)"
        )


def ball() -> None:
    worst = 0.0
    rig = TwinRig(P, noise=False)
    for x, v in zip(P.ball_sensor.curve_position_m, P.ball_sensor.curve_volts_v, strict=True):
        rig.reset(x_m=float(x))
        worst = max(worst, abs(rig.read().ball_v - v) / LSB)
    print(f"Table 6.3 on the twin, noise off: worst |reading − table| = {worst:.2f} LSB over 23 points")
    tau = P.ball_sensor.rc_resistance_ohm * P.ball_sensor.rc_capacitance_f
    quiet = P.with_overrides({"ball_sensor.noise_enabled": False})
    chain = sensors.BallPositionChain(quiet, seed=0, x_m=0.30)  # charged to the wiper's 4.340 V
    v0 = chain.filtered_v
    times, volts = [], []
    for _ in range(100):  # the wiper opens (0 V step): sample the capacitor every 0.1 ms
        t = chain.time_s + np.array([0.0, 1e-4])
        chain.advance(t, np.full(2, 0.30), in_contact=False)
        times.append(t[-1])
        volts.append(chain.filtered_v)
    fit = -1.0 / np.polyfit(np.array(times), np.log(np.array(volts) / v0), 1)[0]
    print(f"RC step response: fitted time constant {1e3 * fit:.4f} ms (147 Ω × 22 µF = {1e3 * tau:.4f} ms)")
    chain = sensors.BallPositionChain(P, seed=2024, x_m=0.0)
    for _ in range(10000):  # 200 s
        chain.advance(chain.time_s + np.arange(21) * 1e-3, np.zeros(21))
    n = chain.dropout_count
    rate = P.ball_sensor.dropout_rate_hz
    expected = rate * 200.0
    print(
        f"dropouts over 200 s at {rate} Hz: {n} (expected {expected:.0f} ± {3 * math.sqrt(expected):.0f} at 3σ)"
    )


def output() -> None:
    for cmd in (0.0, 1.25, 2.5, 3.75, 5.0):
        print(f"command {cmd:.2f} V → motor {motor_volts(cmd, P):+.4f} V")


def determinism() -> None:
    def readings(seed: int) -> np.ndarray:
        rig = TwinRig(P, seed=seed)
        rig.reset(0.1, 0.02)
        return np.array([rig.read().ball_v for _ in range(500)])

    a, b, c = readings(1), readings(1), readings(2)
    print(
        f"seeds: same seed identical = {np.array_equal(a, b)}, different seed differs = {not np.array_equal(a, c)}"
    )
    log = run_closed_loop(AppendixControlLaw(), x0_m=0.1, theta0_rad=0.1, duration_s=2.0, seed=3).log
    with tempfile.TemporaryDirectory() as d:
        save_mat(log, Path(d) / "data_file.mat")
        back = load_mat(Path(d) / "data_file.mat")
    same = all(np.array_equal(getattr(log, f), getattr(back, f)) for f in log.__dataclass_fields__)
    print(f".mat round trip of a 2 s run: every array identical = {same}")


if __name__ == "__main__":
    angle()
    ball()
    output()
    determinism()
