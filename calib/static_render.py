"""A static calibration as text: terminal lines and a TOML parameter file. Rendering only, the numbers come
from ``calib.static``."""

from __future__ import annotations

from calib.static import BallCalibration, DacCalibration

__all__ = ["render_lines", "render_toml"]


def render_lines(result: BallCalibration | DacCalibration) -> list[str]:
    """The result as plain text lines for a terminal."""
    return _ball_lines(result) if isinstance(result, BallCalibration) else _dac_lines(result)


def _signed(value: float) -> str:
    return f"− {-value!r}" if value < 0 else f"+ {value!r}"


def _yes(ok: bool) -> str:
    return "yes" if ok else "no"


def _ball_lines(r: BallCalibration) -> list[str]:
    sw = r.software
    n = len(r.position_m)
    out = [
        f"Ball-position sensor (§6.3), {r.source}: {n} points, {r.position_m[0]:g} … {r.position_m[-1]:g} m",
        "",
        f"Straight lines x = gain·V + offset; the software's is {sw.ball_gain_m_per_v!r}·V {_signed(sw.ball_offset_m)} "
        "(eq 6.3.1):",
        f"  {'fit':<52} {'gain m/V':>10} {'offset m':>10}  rounds to the software's digits",
    ]
    for fit in r.candidates:
        gain_ok, offset_ok = r.reproduces_software(fit)
        out.append(
            f"  {fit.label:<52} {fit.gain_m_per_v:>10.6f} {fit.offset_m:>10.7f}  "
            f"gain {_yes(gain_ok)}, offset {_yes(offset_ok)}"
        )
    out += [
        f"  refit: {r.line.label}",
        "",
        "Residuals x_line(V) − x (mm):",
        f"  {'x m':>8} {'V':>8} {'software':>9} {'refit':>9}",
    ]
    for i in range(n):
        out.append(
            f"  {r.position_m[i]:>8.3f} {r.volts_v[i]:>8.4f} "
            f"{r.software_residuals_m.values[i] * 1e3:>9.2f} {r.line_residuals_m.values[i] * 1e3:>9.2f}"
        )
    for label, res in (("rms", "rms"), ("max |·|", "max_abs")):
        out.append(
            f"  {label:>17} {getattr(r.software_residuals_m, res) * 1e3:>9.2f} "
            f"{getattr(r.line_residuals_m, res) * 1e3:>9.2f}"
        )
    gain = r.line.gain_m_per_v
    out += [
        "",
        "Curves for the twin's sensor (volts at a position); leave-one-out over the interior points "
        f"(mm at the refit's {gain:.4f} m/V):",
    ]
    for c in r.curves:
        if c.loo_v is None:
            loo = "leave-one-out: too few points"
        else:
            loo = (
                f"leave-one-out rms {c.loo_v.rms * 1e3:.1f} mV (≈ {c.loo_v.rms * gain * 1e3:.2f} mm), "
                f"max {c.loo_v.max_abs * 1e3:.1f} mV"
            )
        out.append(f"  {c.name:<11} {loo}; at the points rms {c.residuals_v.rms * 1e3:.1f} mV")
        out.append(f"  {'':<11} {c.rule}")
    best = r.recommended
    out += [
        f"  predicts best: {best.name} ({len(best.position_m)} points)",
        "",
        "Overrides (Parameters.with_overrides, or a --params TOML file):",
    ]
    out += [f"  {k} = {val:.7g}" for k, val in r.software_overrides().items()]
    out.append(
        "  ball_sensor.curve_position_m, ball_sensor.curve_volts_v = "
        f"the {best.name} curve, {len(best.position_m)} points"
    )
    return out


def _dac_lines(r: DacCalibration) -> list[str]:
    s = r.sensor
    out = [
        f"Angle chain's DAC (§6.2), {r.source}: {len(r.di)} readings, DI {int(min(r.di))} … {int(max(r.di))}",
        "",
        f"Lines Va = slope·DI + offset; the twin's is {s.dac_volts_per_count!r}·DI "
        f"{_signed(s.dac_offset_v)} (eq 6.2.6):",
        f"  {'fit':<28} {'slope V/count':>14} {'offset V':>10}  rounds to the twin's digits",
    ]
    for label, k, b in (
        ("least squares", r.volts_per_count, r.offset_v),
        ("through the end readings", r.ends_volts_per_count, r.ends_offset_v),
    ):
        k_ok, b_ok = r.reproduces_sensor(k, b)
        out.append(f"  {label:<28} {k:>14.8f} {b:>10.5f}  slope {_yes(k_ok)}, offset {_yes(b_ok)}")
    out += ["", "Residuals Va_line − Va (mV):", f"  {'DI':>6} {'Va V':>9} {'eq 6.2.6':>9} {'refit':>9}"]
    for i, di in enumerate(r.di):
        out.append(
            f"  {int(di):>6} {r.volts_v[i]:>9.4f} "
            f"{r.sensor_residuals_v.values[i] * 1e3:>9.2f} {r.residuals_v.values[i] * 1e3:>9.2f}"
        )
    for label, res in (("rms", "rms"), ("max |·|", "max_abs")):
        out.append(
            f"  {label:>16} {getattr(r.sensor_residuals_v, res) * 1e3:>9.2f} {getattr(r.residuals_v, res) * 1e3:>9.2f}"
        )
    out += ["", "Overrides (Parameters.with_overrides, or a --params TOML file):"]
    out += [f"  {k} = {val:.7g}" for k, val in r.overrides().items()]
    out.append("  and, for the controllers' eq 6.2.9 reading of the angle:")
    out += [f"  {k} = {val:.7g}" for k, val in r.software_overrides().items()]
    return out


def render_toml(result: BallCalibration | DacCalibration, *, curve: str | None = None) -> str:
    """The overrides as a TOML parameter file (``Parameters.from_file``): the twin's sensor and the
    software's conversion, as a rig recalibrated with this table would have them. For the ball, ``curve``
    names the twin's curve (default the best predicting); the software gets the refit line."""
    groups: dict[str, dict[str, float | tuple[float, ...]]] = {}
    if isinstance(result, BallCalibration):
        overrides: dict[str, float | tuple[float, ...]] = {
            **result.software_overrides(),
            **result.sensor_overrides(curve),
        }
        header = f"# static calibration of {result.source}: software line {result.line.label}; twin curve "
        header += curve or result.recommended.name
    else:
        overrides = {**result.overrides(), **result.software_overrides()}
        header = f"# static calibration of {result.source}: least-squares DAC line"
    for key, value in overrides.items():
        group, name = key.split(".", 1)
        groups.setdefault(group, {})[name] = value
    lines = [header]
    for group, values in groups.items():
        lines += ["", f"[{group}]"]
        for name, value in values.items():
            text = "[" + ", ".join(repr(x) for x in value) + "]" if isinstance(value, tuple) else repr(value)
            lines.append(f"{name} = {text}")
    return "\n".join(lines) + "\n"
