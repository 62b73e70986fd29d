"""The validation report as Markdown: rendering only, every figure formatted from ``twin.app.validate``'s
runs."""

from __future__ import annotations

from dataclasses import asdict

from twin.app.validate import ValidationReport

__all__ = ["render_markdown"]


def render_markdown(report: ValidationReport) -> str:
    mark = {True: "pass", False: "**FAIL**", None: "not run"}
    lines = [
        f"# Validation of `{report.controller}`",
        "",
        f"**Verdict: {'PASS' if report.passed else 'FAIL'}** ({report.wall_s:.0f} s of computing)"
        + ("" if report.complete else " — **interrupted**: only the checks below were run"),
        "",
        "| check | result | criterion | measured |",
        "| --- | --- | --- | --- |",
    ]
    for c in report.checks:
        lines.append(f"| {c.name} | {mark[c.passed]} | {c.criterion} | {c.measured} |")
    if report.region is not None:
        lines += ["", "![region of attraction](region.png)", ""]
    nominal = next((c for c in report.checks if c.name == "nominal"), None)
    if nominal is None:
        return "\n".join(lines) + "\n"
    lines += [
        "## Nominal runs",
        "",
        "| x0 (m) | θ0 (rad) | seed | held | settling (s) | steady x (mm) | cycle (mm p-p) | peak V | rails |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in nominal.rows:
        settle = "—" if r["settling_time_s"] is None else f"{r['settling_time_s']:.2f}"
        steady = "—" if r["steady_x_m"] is None else f"{1e3 * r['steady_x_m']:+.1f}"
        cycle = "—" if r["limit_cycle_x_pp_m"] is None else f"{1e3 * r['limit_cycle_x_pp_m']:.1f}"
        if r.get("failed"):  # the controller or the simulation failed: no figures
            peak, rails = "—", "—"
        else:
            peak, rails = f"{r['peak_motor_voltage_v']:.1f}", f"{100 * r['saturated_fraction']:.0f} %"
        lines.append(
            f"| {r['x0_m']:+.2f} | {r['theta0_rad']:+.2f} | {r['seed']} | {'yes' if r['held'] else r['reason']} | "
            f"{settle} | {steady} | {cycle} | {peak} | {rails} |"
        )
    lines += ["", "Criteria (override with `--criteria FILE`):", ""]
    lines += [f"- `{k}` = {v}" for k, v in asdict(report.criteria).items()]
    return "\n".join(lines) + "\n"
