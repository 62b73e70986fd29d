"""What a calibration leaves behind: the parameter file, the numbers, and a report to read.

    DIR/params.toml        every parameter, the fitted ones replaced (loads with --params)
    DIR/calibration.json   {"params": {name: {value, ci_low, ci_high, initial, unit}}, "rms_residual": …,
                            "converged", "warnings", "correlation", "not_identifiable": {name: {kept,
                            unit, reason}}, …} (a parameter the logs do not identify is out of "params"
                            and the correlations, and keeps its start value in params.toml)
    DIR/report.md          measured against simulated before and after, residuals over time and their
                           histogram, the intervals and the correlation matrix (PNGs beside it;
                           ``calib.report_render``)

The files go to a fresh temporary folder first, then take their places (``twin.outputs.atomic_directory``):
an existing folder is written into only when asked, and then only these files are replaced; the rig logs,
parameter files and anything else in it are kept.
"""

from __future__ import annotations

import json
from pathlib import Path

from calib.identify import Calibration
from twin.outputs import JobFiles, atomic_directory

__all__ = ["OUTPUT_FILES", "write_report"]

# What write_report puts into its folder (checked before the fit); correlation.png only when the fit has a
# correlation matrix.
OUTPUT_FILES = JobFiles(
    "calibrate",
    ("params.toml", "calibration.json", "report.md", "fit.png", "residuals.png", "correlation.png"),
)


def write_report(cal: Calibration, out_dir: str | Path, *, overwrite: bool = False) -> Path:
    from calib.report_render import render_figures, render_markdown

    with atomic_directory(out_dir, OUTPUT_FILES, overwrite=overwrite) as tmp:
        cal.params.save(tmp / "params.toml")
        (tmp / "calibration.json").write_text(json.dumps(cal.to_json(), indent=2) + "\n")
        render_figures(cal, tmp)
        (tmp / "report.md").write_text(render_markdown(cal))
    return Path(out_dir)
