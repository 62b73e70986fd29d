"""An independent simulator of the rig, for testing identification on logs the twin did not make.

Written from the physics, sharing no code with twin/ beyond the parameter values it is given:

* dynamics: Lagrange's equations in mass-matrix form (q = (x, θ); kinetic energy of the ball's translation
  and rolling on two wires with rolling radius r*, the beam about its pivot, the motor's reflected rotor),
  integrated by scipy's adaptive DOP853 between ticks (the twin uses MuJoCo or fixed-step RK4);
* ball channel: Table 6.3 curve through the 147 Ω / 22 µF RC filter stepped at 40 samples per block
  (exponential update of each sample's wiper volts), plus Gaussian noise (0.3 mm worth of volts) and, on
  4 % of the ticks, the wiper open for the block's last 2 ms (the twin: Poisson dropouts, exact RC);
* angle channel: the counter rounded to the nearest count, the AD561 line, a 12-bit ADC, averaged over 40
  samples per block (the twin: 800 samples from the count-crossing times);
* command: 12-bit DAC, amplifier 9.6·(u − 2.5) within ±12 V, no latency;
* controller: state feedback with finite-difference velocities and a ±0.1 m square-wave setpoint, plus a
  ±0.5 V dither from its own random generator.

The audit's cases (tests/test_calib_adequacy.py) are options of ``simulate``, each written here from the
physics, not from twin/:

* ``beam.pivot_friction_nm`` of the parameters: Coulomb friction in the pivot, F·tanh(θ̇/1 mrad/s) (the
  twin's reference model clips θ̇/10 mrad/s instead);
* ``controller="regulate"``: the same gains at a fixed setpoint 0.05 m, no dither (a user's regulation log);
  ``controller="rails"``: the gains ×3 and a ±6 V dither, so the amplifier sits at its ±12 V rails often;
* ``noise_m``, ``spike_rate``: the ball channel's Gaussian noise and the share of ticks with an open wiper;
* ``dropout_rate_hz``, ``dropout_max_s``: wiper dropouts as a Poisson process in time, each lasting a
  uniform 0…``dropout_max_s``, crossing block boundaries (the ball lifting off the spring as it rolls);
* ``fall_at_s``: from then on the controller holds +2 V at the motor, the ball rolls off the −x end
  (|x| > ``track.half_length_m``), its wiper reads 0 V (open) and the beam turns without it;
* ``period_s``: the tick (40 samples per block whatever the period);
* ``rail_v``: the amplifier's output clipped at ±rail_v instead of ±12 V (a supply that sags, a current
  limit), which the fit does not know.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from twin.parameters import Parameters

K_SF = (-36.34, 24.6, -15.96, 3.98)  # §5.2.1's printed gains (V per m, rad, m/s, rad/s)
PERIOD_S = 0.02


def _rhs(p: Parameters, volts: float, on_track: bool = True, rail_v: float = 12.0):
    m, r, g = p.ball.mass_kg if on_track else 0.0, p.ball.radius_m, p.physics.gravity_m_s2
    rs = math.sqrt(r * r - p.track.contact_spacing_m**2 / 4)
    j_ball = 0.4 * m * r * r
    c = p.track.contact_height_m + rs
    n = p.motor.gear_ratio
    j_beam = p.beam.inertia_pivot_kgm2 + p.motor.rotor_inertia_kgm2 * n * n
    b_beam = p.motor.viscous_damping_nm_s_per_rad * n * n + p.beam.pivot_damping_nm_s_per_rad
    k_t = n * p.motor.torque_constant_nm_per_a / p.motor.resistance_ohm
    k_b = n * p.motor.backemf_constant_v_s_per_rad
    mb, h = p.beam.mass_kg, p.beam.cog_height_m
    dry = p.beam.pivot_friction_nm

    def torque_of(thd: float) -> float:
        return k_t * (min(max(volts, -rail_v), rail_v) - k_b * thd)

    def f(_t: float, s: np.ndarray) -> list[float]:
        x, th, xd, thd = s
        # Ball centre in the pivot frame: (x cos θ − c sin θ, x sin θ + c cos θ); its spin relative to the
        # beam is −ẋ/r*, so its absolute spin is θ̇ − ẋ/r*.
        if not on_track:  # the ball is gone: the beam alone, the ball's coordinate frozen
            q = torque_of(thd) - b_beam * thd - dry * math.tanh(thd / 1e-3) + mb * g * h * math.sin(th)
            return [0.0, thd, 0.0, q / j_beam]
        m11 = m + j_ball / rs**2
        m12 = -(m * c + j_ball / rs)
        m22 = j_beam + j_ball + m * (c * c + x * x)
        torque = torque_of(thd)
        q1 = m * x * thd**2 - m * g * math.sin(th)
        q2 = (
            torque
            - b_beam * thd
            - dry * math.tanh(thd / 1e-3)
            - 2 * m * x * xd * thd
            - m * g * (x * math.cos(th) - c * math.sin(th))
            + mb * g * h * math.sin(th)
        )
        det = m11 * m22 - m12 * m12
        return [xd, thd, (m22 * q1 - m12 * q2) / det, (m11 * q2 - m12 * q1) / det]

    return f


class _ContactLosses:
    """Wiper dropouts as a Poisson process in time (its own generator, so that the other draws stay as they
    were), each lasting a uniform 0…max_s, carried across block boundaries."""

    def __init__(self, rate_hz: float, max_s: float, rng: np.random.Generator) -> None:
        self.rate_hz, self.max_s, self.rng = rate_hz, max_s, rng
        self.open_until = 0.0  # the end of the dropout in progress (s)

    def open_wiper(self, wiper: np.ndarray, times: np.ndarray) -> None:
        """Set the samples at ``times`` during a dropout to the open wiper's 0 V."""
        if self.rate_hz <= 0.0:
            return
        wiper[times < self.open_until] = 0.0  # a dropout carried over from the last block
        t = times[0] - (times[1] - times[0]) + self.rng.exponential(1.0 / self.rate_hz)
        while t < times[-1]:
            end = t + self.rng.uniform(0.0, self.max_s)
            wiper[(times >= t) & (times < end)] = 0.0
            self.open_until = max(self.open_until, end)
            t += self.rng.exponential(1.0 / self.rate_hz)


def simulate(
    params: Parameters,
    *,
    duration_s: float = 60.0,
    seed: int = 0,
    controller: str = "square",
    noise_m: float = 0.3e-3,
    spike_rate: float = 0.04,
    fall_at_s: float | None = None,
    period_s: float = PERIOD_S,
    dropout_rate_hz: float = 0.0,
    dropout_max_s: float = 5e-3,
    rail_v: float = 12.0,
) -> dict[str, np.ndarray]:
    """A closed-loop log: {"timem", "datam1", "datam2", "aout"}, one value per tick, row 0 the start sample."""
    if controller not in ("square", "regulate", "rails"):
        raise ValueError(f"unknown controller {controller!r}")
    p = params
    rng = np.random.default_rng(seed)
    curve_x, curve_v = np.array(p.ball_sensor.curve_position_m), np.array(p.ball_sensor.curve_volts_v)
    step = 2 * math.pi / (p.angle_sensor.encoder_pulses_per_rev * p.motor.gear_ratio)
    lsb_adc, lsb_dac = 10.0 / 4096, 5.0 / 4096
    sw = p.software
    gains = tuple(3 * k for k in K_SF) if controller == "rails" else K_SF
    dither_v = {"square": 0.5, "regulate": 0.0, "rails": 6.0}[controller]

    tau = p.ball_sensor.rc_resistance_ohm * p.ball_sensor.rc_capacitance_f
    decay = math.exp(-period_s / 40 / tau)
    filtered = [float(np.interp(0.05, curve_x, curve_v))]
    on_track = [True]

    def adc(v: float) -> float:  # 12 bits over ±5 V: codes 0…4095
        return -5.0 + lsb_adc * min(max(round((v + 5.0) / lsb_adc), 0), 4095)

    losses = _ContactLosses(dropout_rate_hz, dropout_max_s, np.random.default_rng([seed, 7]))

    def ball_reading(xs: np.ndarray, times: np.ndarray) -> float:
        wiper = np.interp(xs, curve_x, curve_v)
        if rng.random() < spike_rate:
            wiper[-4:] = 0.0
        losses.open_wiper(wiper, times)
        if not on_track[0]:
            wiper[:] = 0.0  # no ball on the spring: the wiper is open
        for w in wiper:
            filtered[0] = w + (filtered[0] - w) * decay
        v = filtered[0] + rng.normal(0.0, noise_m / 0.0693)
        return adc(v)

    def angle_level(theta: float) -> float:
        di = 512 + round((theta - p.angle_sensor.zeroing_error_rad) / step)
        return adc(0.009818 * di - 5.042)

    def measured(ball_v: float, angle_v: float) -> tuple[float, float]:
        x = sw.ball_gain_m_per_v * ball_v + sw.ball_offset_m
        deg = (sw.angle_gain_deg_per_v * (angle_v - sw.angle_reference_v) + sw.angle_reference_motor_deg) / 7
        return x, deg * math.pi / 180

    state = np.array([0.05, 0.0, 0.0, 0.0])
    volts = 0.0
    ticks = int(round(duration_s / period_s))
    out = {k: np.zeros(ticks + 1) for k in ("timem", "datam1", "datam2", "aout")}
    out["datam1"][0], out["datam2"][0], out["aout"][0] = (
        ball_reading(np.full(40, state[0]), -period_s + period_s * np.arange(1, 41) / 40),
        angle_level(state[1]),
        2.5,
    )
    out["timem"][0] = 0.0
    prev = measured(out["datam1"][0], out["datam2"][0])
    dither = 0.0
    for k in range(1, ticks + 1):
        t0 = (k - 1) * period_s
        samples = t0 + period_s * np.arange(1, 41) / 40
        sol = solve_ivp(
            _rhs(p, volts, on_track[0], rail_v),
            (t0, t0 + period_s),
            state,
            method="DOP853",
            t_eval=samples,
            rtol=1e-9,
            atol=1e-11,
        )
        state = sol.y[:, -1]
        if abs(state[0]) > p.track.half_length_m:
            on_track[0] = False
        ball_v = ball_reading(sol.y[0], samples)
        angle_v = float(np.mean([angle_level(th) for th in sol.y[1]]))
        x, th = measured(ball_v, angle_v)
        if controller == "regulate":
            setpoint = 0.05
        else:
            setpoint = 0.1 if (t0 // 5.0) % 2 == 0 else -0.1
        xd, thd = (x - prev[0]) / period_s, (th - prev[1]) / period_s
        prev = (x, th)
        u = -(gains[0] * (x - setpoint) + gains[1] * th + gains[2] * xd + gains[3] * thd)
        if dither_v and k % 2 == 1:
            dither = dither_v if rng.random() < 0.5 else -dither_v
        command = u / 9.6 + 2.5 + dither / 9.6
        if fall_at_s is not None and t0 >= fall_at_s:
            command = 2.5 + 2.0 / 9.6  # +2 V at the motor: the beam tilts, the ball rolls to −x and off
        command = lsb_dac * round(min(max(command, 1.25), 3.75) / lsb_dac)
        volts = 9.6 * (command - 2.5)
        out["timem"][k], out["datam1"][k], out["datam2"][k], out["aout"][k] = (
            t0 + period_s,
            ball_v,
            angle_v,
            command,
        )
    return out


def rig_log_of(log: dict[str, np.ndarray], name: str = "independent"):
    """The identification ticks of a simulated log (row 0, the start sample, dropped) as calib reads them."""
    from pathlib import Path

    from calib.logs import RigLog

    return RigLog(
        path=Path(name),
        time_s=log["timem"][1:],
        ball_v=log["datam1"][1:],
        angle_v=log["datam2"][1:],
        command_v=log["aout"][1:],
    )
