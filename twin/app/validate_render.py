"""The validation report as Markdown and the validation's folder: rendering and writing only, every figure
formatted from ``twin.app.validate``'s runs (imported here, never the other way round)."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

from twin.app.sweep_render import render_map
from twin.app.validate import OUTPUT_FILES, ValidationReport
from twin.outputs import atomic_directory

__all__ = ["render_markdown", "write_validation"]


def write_validation(report: ValidationReport, out_dir: str | Path, *, overwrite: bool = False) -> Path:
    """``report.md``, ``validation.json`` and ``region.png`` (``twin.app.sweep_render``) into ``out_dir``,
    atomically (``twin.outputs.atomic_directory``: the folder's other files are kept)."""
    with atomic_directory(out_dir, OUTPUT_FILES, overwrite=overwrite) as tmp:
        (tmp / "validation.json").write_text(json.dumps(report.to_json(), indent=1) + "\n")
        if report.region is not None:
            render_map(report.region, tmp / "region.png")
        (tmp / "report.md").write_text(render_markdown(report))
    return Path(out_dir)


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
        shown = "not applicable" if c.measured.startswith("not applicable") else mark[c.passed]
        lines.append(f"| {c.name} | {shown} | {c.criterion} | {c.measured} |")
    if report.region is not None:
        lines += ["", "![region of attraction](region.png)", ""]
    nominal = next((c for c in report.checks if c.name == "nominal"), None)
    if nominal is None:
        return "\n".join(lines) + "\n"
    # an actuator without amplifier rails (a servo, a stepper): its drive's peak is not volts at a rail
    no_rails = any(c.name == "saturation" and c.measured.startswith("not applicable") for c in report.checks)
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
        if r.get("failed") or no_rails:  # failed: no figures; no rails: its drive is not in volts
            peak, rails = "—", "—"
        else:
            peak, rails = f"{r['peak_motor_voltage_v']:.1f}", f"{100 * r['saturated_fraction']:.0f} %"
        lines.append(
            f"| {r['x0_m']:+.2f} | {r['theta0_rad']:+.2f} | {r['seed']} | {'yes' if r['held'] else r['reason']} | "
            f"{settle} | {steady} | {cycle} | {peak} | {rails} |"
        )
    lines += ["", "Criteria (override with `--criteria FILE`):", ""]
    lines += [f"- `{k}` = {v}" for k, v in asdict(report.criteria).items()]
    if report.rig is not None:
        lines += _rig_section(report.rig)
    return "\n".join(lines) + "\n"


def _rig_section(rig: dict[str, Any]) -> list[str]:
    """A rig that is not the thesis's: its parts, the starts, why each default is what it is, and the checks
    that do not apply to it."""
    lines = ["", "## The rig", "", "Parts: " + ", ".join(f"{k} `{v}`" for k, v in rig["parts"].items()), ""]
    lines += [
        f"Nominal starts, {rig['starts_why']}: "
        + ", ".join(f"({x:+.4g} m, {t:+.4g} rad)" for x, t in rig["starts"]),
        "",
        f"Sensitivity starts: {', '.join(f'({x:+.4g} m, {t:+.4g} rad)' for x, t in rig['sensitivity_starts'])}; "
        f"Monte Carlo start: ({rig['montecarlo_start'][0]:+.4g} m, {rig['montecarlo_start'][1]:+.4g} rad)",
        "",
        "The rig's defaults (derived from its parts, never typed per rig):",
        "",
    ]
    lines += [f"- `{k}`: {why}" for k, why in rig["default_reasons"].items()]
    if rig["not_applicable"]:
        lines += ["", "Not applicable to this rig:", ""]
        lines += [f"- `{k}`: {why}" for k, why in rig["not_applicable"].items()]
    return lines
