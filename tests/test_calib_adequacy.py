"""Calibration that knows its limits: the audit's cases (tests/independent_rig.py), the adequacy test, the
identifiability checks, the sparse covariance. Each case: the fit is right, or the tool says why not."""

import math
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse
from independent_rig import rig_log_of, simulate

from calib.adequacy import channel_adequacy
from calib.experiments import run_experiment
from calib.identify import (
    SIGMA_ANGLE_RAD,
    CalibrationError,
    WindowProblem,
    _sandwich,
    calibrate,
)
from calib.logs import rig_log
from twin.app.cli import main
from twin.parameters import Parameters

FIT = [
    "motor.resistance_ohm",
    "beam.inertia_pivot_kgm2",
    "beam.pivot_damping_nm_s_per_rad",
    "angle_sensor.zeroing_error_rad",
]
NOMINAL = Parameters().with_overrides({"beam.pivot_damping_nm_s_per_rad": 1e-3})
# The audit's rig (the independent simulator's seed-1 draw of test_calib_identify's recovery test).
_rng = np.random.default_rng(201)
_f = _rng.uniform(-0.2, 0.2, 3)
TRUTH = {
    FIT[0]: 9.4 * (1 + _f[0]),
    FIT[1]: 4e-3 * (1 + _f[1]),
    FIT[2]: 1e-3 * (1 + _f[2]),
    FIT[3]: float(_rng.uniform(-0.015, 0.015)),
}
RIG = NOMINAL.with_overrides(TRUTH)
# Acceptance as test_calib_identify's: resistance and inertia within 3 %, damping 15 %, zeroing 0.5 mrad.
TOLERANCE = {FIT[0]: 0.03, FIT[1]: 0.03, FIT[2]: 0.15, FIT[3]: 0.5e-3}


def _error(name: str, fitted: float, true: float) -> float:
    return abs(fitted - true) if name == FIT[3] else abs(fitted / true - 1)


# --- the adequacy statistics and the covariance ------------------------------------------------------------
def test_white_residuals_stay_in_the_band_and_coloured_ones_do_not() -> None:
    rng = np.random.default_rng(0)
    white = rng.normal(0.0, 0.5e-3, (60, 50))
    a = channel_adequacy(white, channel="angle", unit="rad", floor=SIGMA_ANGLE_RAD)
    assert a.ratio == pytest.approx(0.5, rel=0.05)
    assert all(abs(r) < 3 * a.band for r in a.autocorrelation) and a.band == pytest.approx(
        1.96 / math.sqrt(3000)
    )
    # AR(1) with coefficient 0.9 within each window: ρ(1) ≈ 0.9 (a little less: the windows are short).
    ar = np.zeros((60, 50))
    e = rng.normal(0.0, 1e-3, (60, 50))
    for t in range(1, 50):
        ar[:, t] = 0.9 * ar[:, t - 1] + e[:, t]
    b = channel_adequacy(ar, channel="angle", unit="rad", floor=SIGMA_ANGLE_RAD)
    assert b.lag1 > 0.8
    # Outliers (contact noise) are left out of the ball channel's RMS and correlation.
    spiky = white.copy()
    spiky[::7, 10] = 0.05
    c = channel_adequacy(spiky, channel="ball", unit="m", floor=0.5e-3, outlier=3e-3)
    assert c.outliers == 9 and c.rms == pytest.approx(a.rms, rel=0.01)


def test_the_sparse_sandwich_is_the_dense_one() -> None:
    """The globals' block of H⁻¹·meat·H⁻¹ from a sparse LU equals the dense pinv formula it replaced."""
    run = run_experiment("square", NOMINAL, duration_s=12.0, seed=2)
    problem = WindowProblem([rig_log(run.log)], NOMINAL, FIT[:2])
    rng = np.random.default_rng(3)
    pattern = problem.sparsity().tocoo()
    jac = scipy.sparse.csr_matrix(
        (rng.normal(size=pattern.nnz), (pattern.row, pattern.col)), shape=pattern.shape
    )
    rw = rng.normal(size=pattern.shape[0])
    got = _sandwich(problem, jac, rw)
    J = jac.toarray()
    bread = np.linalg.pinv(J.T @ J)
    per = 5  # 5 s clusters of 1 s windows
    cluster = (
        np.concatenate(
            [np.repeat(np.arange(problem.n_windows), problem.W)] * 2
            + [np.repeat(np.flatnonzero(problem.windows.joined), 4)]
        )
        // per
    )
    meat = np.zeros_like(bread)
    for c in range(cluster.max() + 1):
        g = J[cluster == c].T @ rw[cluster == c]
        meat += np.outer(g, g)
    n_c = cluster.max() + 1
    want = (bread @ meat @ bread)[:2, :2] * n_c / (n_c - 1)
    np.testing.assert_allclose(got.cov, want, rtol=1e-6)
    np.testing.assert_allclose(got.naive_var, np.diag(bread)[:2], rtol=1e-6)


def test_the_jacobian_is_never_dense() -> None:
    """A 1-hour log's pattern: 360 000 rows × 14 400 columns, 13 entries a row at most (a dense one: 40 GiB)."""
    t = 0.01 + 0.02 * np.arange(180_000)
    rl = rig_log_of(
        {
            "timem": np.r_[0.0, t],
            "datam1": np.r_[0.0, 1.5 * np.sin(t)],
            "datam2": np.r_[0.0, 0.1 * np.cos(t)],
            "aout": np.r_[2.5, 2.5 + 0.2 * np.sin(3 * t)],
        }
    )
    problem = WindowProblem([rl], NOMINAL, FIT)
    pattern = problem.sparsity()
    assert scipy.sparse.issparse(pattern) and pattern.shape == (2 * 3599 * 50 + 4 * 3598, 4 + 4 * 3599)
    assert pattern.nnz <= 12 * pattern.shape[0]


# --- refusals ----------------------------------------------------------------------------------------------
def test_a_log_at_another_period_than_daq_period_s_is_refused(tmp_path: Path, capsys) -> None:
    """A 10 ms log read with the thesis's 20 ms period: refused, naming the file and timem (exit 2)."""
    log = simulate(RIG, duration_s=6.0, seed=1, period_s=0.01)
    with pytest.raises(
        CalibrationError, match=r"'timem' \(time_s\) ticks every 10 ms .* daq.period_s is 20 ms"
    ):
        calibrate([rig_log_of(log)], FIT, NOMINAL)
    path = tmp_path / "data_file.mat"
    from scipy.io import savemat

    savemat(path, {k: v[:, None] for k, v in log.items()} | {"k": float(log["timem"].size)})
    assert main(["calibrate", str(path), "--fit", "motor.resistance_ohm"]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "'timem'" in err and "daq.period_s=0.01" in err
