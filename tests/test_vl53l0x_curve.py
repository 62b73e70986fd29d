"""The VL53L0X's measured curve and noise floor (twin/parts/vl53l0x.py: ``vl53l0x.curve_distance_mm``,
``curve_reading_mm``, ``sigma_floor_mm``), against Open Ball & Beam's sensor calibration
(github.com/TSummersLab/open-ball-beam, ballbeam/calibration/sensor_calibration_data.txt, commit 58cb136: 18 true
distances, 20 readings each, VL53L0X at a 20 ms timing budget; the readings are tests/test_sensor_static.py's).

The reading at a curve point is the measured mean, between points the broken line computed here by hand, beyond
the ends the end segments; the floor is fitted here from the 18 sample deviations; a batch of runs reads the same
bits as each run alone; the open-ball-and-beam preset carries the curve and the floor; ``calibrate-static``
writes them in a rig description the twin loads back."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from test_batch_parts import Catalogue, _check
from test_sensor_static import OBB_READINGS_MM

from controllers.rig_lqg import rig_lqg
from twin.parameters import ParameterError, Parameters
from twin.parts.description import preset, rig_from_text
from twin.parts.ranging import form_batch, form_inputs, form_single
from twin.parts.vl53l0x import (
    VL53L0X,
    Vl53l0x,
    Vl53l0xBatch,
    Vl53l0xChain,
    vl53l0x_curve_mm,
    vl53l0x_position_of,
    vl53l0x_range_mm,
    vl53l0x_sigma_mm,
)

OBB = preset("open-ball-and-beam")
DISTANCES_MM = [float(d) for d in OBB_READINGS_MM]
MEANS_MM = [float(np.mean(v)) for v in OBB_READINGS_MM.values()]
SDS_MM = np.array([np.std(v, ddof=1) for v in OBB_READINGS_MM.values()])
QUIET = {"ball_sensor.noise_enabled": False}


def _x_at(p: Parameters, distance_mm: float) -> float:
    """The ball's centre for a near-surface distance from the sensor's face (mount − x − r = d)."""
    return p.of(Vl53l0x).mount_x_m - p.ball.radius_m - distance_mm / 1000.0


# --- the curve ----------------------------------------------------------------------------------------------------


@pytest.mark.quick
def test_the_preset_carries_obbs_18_means_and_its_mount_puts_105_mm_at_the_centre() -> None:
    g = OBB.of(Vl53l0x)
    assert g.curve_distance_mm == tuple(DISTANCES_MM)
    assert g.curve_reading_mm == pytest.approx(MEANS_MM, abs=1e-12)  # 28.1 … 289.3, each the mean of 20
    # OBB's software: position = true distance − 105 mm (DISTANCE_MID); the twin's x points the other way
    # (the sensor at +x): the face at 105 mm + the ball's 19.05 mm radius from the centre
    assert g.mount_x_m == pytest.approx(0.105 + 0.01905, abs=1e-12)
    assert _x_at(OBB, 105.0) == pytest.approx(0.0, abs=1e-15)
    assert (_x_at(OBB, 14.0), _x_at(OBB, 196.0)) == pytest.approx((0.091, -0.091), abs=1e-15)  # the end stops


@pytest.mark.quick
def test_the_reading_at_the_18_true_distances_is_the_measured_mean() -> None:
    g = OBB.of(Vl53l0x)
    exact = vl53l0x_curve_mm(np.array(DISTANCES_MM), g.curve_distance_mm, g.curve_reading_mm)
    assert exact.tolist() == MEANS_MM  # bit for bit at the knots: (1 − t)·v_j + t·v_j+1 at t = 0 or 1
    quiet = OBB.with_overrides(QUIET)
    for d, mean in zip(DISTANCES_MM, MEANS_MM, strict=True):
        chain = Vl53l0xChain(quiet, 0, x_m=_x_at(quiet, d))
        assert chain.reading_v == float(np.rint(mean)), d  # the board reads whole mm
    # e.g. 14 mm reads 28, 105 mm 142, 196 mm 289: the offset-only law (d − crosstalk) read 14, 105, 196
    assert [Vl53l0xChain(quiet, 0, x_m=_x_at(quiet, d)).reading_v for d in (14.0, 105.0, 196.0)] == [
        28.0,
        142.0,
        289.0,
    ]


@pytest.mark.quick
def test_between_and_beyond_the_points_the_curve_is_the_broken_line() -> None:
    g = OBB.of(Vl53l0x)

    def at(d: float) -> float:
        return float(vl53l0x_curve_mm(np.array([d]), g.curve_distance_mm, g.curve_reading_mm)[0])

    # by hand: 112 mm is 2/10 of the way from 110 mm (153.4) to 120 mm (174.4): 153.4 + 0.2·21.0 = 157.6
    assert at(112.0) == pytest.approx(157.6, abs=1e-12)
    # 180 mm is 10/26 of the way from 170 mm (268.3) to 196 mm (289.3): 268.3 + 21.0·10/26 = 276.376923…
    assert at(180.0) == pytest.approx(268.3 + 21.0 * 10.0 / 26.0, abs=1e-12)
    assert at(180.0) == pytest.approx(276.3769231, abs=1e-7)
    # not a smooth curve: PCHIP through the same points bends 1.3 mm above the chord at 180 mm (277.71)
    from scipy.interpolate import PchipInterpolator

    assert float(PchipInterpolator(DISTANCES_MM, MEANS_MM)(180.0)) - at(180.0) == pytest.approx(
        1.33, abs=0.01
    )
    # beyond the ends, the end segments go on: 0 mm reads 28.1 − 14·19.7/16 = 10.8625, 200 mm 289.3 + 4·21/26
    assert at(0.0) == pytest.approx(10.8625, abs=1e-12)
    assert at(200.0) == pytest.approx(289.3 + 4.0 * 21.0 / 26.0, abs=1e-12)
    # the chain reads it rounded: 112 mm → 158 mm
    quiet = OBB.with_overrides(QUIET)
    assert Vl53l0xChain(quiet, 0, x_m=_x_at(quiet, 112.0)).reading_v == 158.0


@pytest.mark.quick
def test_the_software_reads_the_curve_backwards() -> None:
    """``position_of`` inverts the same broken line: each mean reads back its true distance's x, 157.6 mm
    reads 112 mm's; OBB's own sketch fits a degree-5 polynomial (reading → position) to these points instead."""
    x_of = vl53l0x_position_of(OBB)
    for d, mean in zip(DISTANCES_MM, MEANS_MM, strict=True):
        assert x_of(mean) == pytest.approx(_x_at(OBB, d), abs=1e-12), d
    assert x_of(157.6) == pytest.approx(_x_at(OBB, 112.0), abs=1e-12)
    assert x_of(10.8625) == pytest.approx(_x_at(OBB, 0.0), abs=1e-12)
    assert math.isnan(x_of(8190.0))
    # without a curve: the law's inverse, mount − r − (range + crosstalk)/1000, as before
    plain = Parameters().with_overrides({"vl53l0x.crosstalk_offset_mm": 5.0})
    assert vl53l0x_position_of(plain)(100.0) == pytest.approx(0.333 - plain.ball.radius_m - 0.105, abs=1e-15)


@pytest.mark.quick
def test_without_a_curve_or_a_floor_the_law_is_todays_bit_for_bit() -> None:
    rng = np.random.default_rng(3)
    d = rng.uniform(0.0, 1500.0, 400)
    z = rng.standard_normal(400)
    wrong = rng.uniform(size=400) < 0.2
    present = rng.uniform(size=400) < 0.9
    k, budget, xt, bg, top = 0.04, 0.02, 7.0, 900.0, 1200.0
    now = vl53l0x_range_mm(
        d,
        z,
        wrong,
        present,
        sigma_fraction=k,
        budget_s=budget,
        crosstalk_mm=xt,
        background_mm=bg,
        max_range_mm=top,
    )
    # the law as it stood before the curve and the floor, written out here
    target = np.where(wrong | ~present, bg, d)
    before = np.maximum(np.rint(target - xt + k * target * np.sqrt(0.033 / budget) * z), 0.0)
    assert np.array_equal(now, np.where(target > top, 8190.0, before))
    assert Parameters().of(Vl53l0x).curve_distance_mm == () and Parameters().of(Vl53l0x).sigma_floor_mm == 0.0


@pytest.mark.quick
def test_a_wrong_return_reads_the_background_by_the_law_not_the_curve() -> None:
    # the curve is the ball's; a wall 800 mm away reads 800 − crosstalk: the curve (extended) would read ~760
    p = OBB.with_overrides({"vl53l0x.background_mm": 800.0, "vl53l0x.crosstalk_offset_mm": 3.0})
    g = p.of(Vl53l0x)
    out = vl53l0x_range_mm(
        np.array([105.0, 105.0]),
        np.zeros(2),
        np.array([False, True]),
        np.array([True, True]),
        sigma_fraction=0.0,
        budget_s=0.02,
        crosstalk_mm=3.0,
        background_mm=800.0,
        max_range_mm=1200.0,
        curve_mm=vl53l0x_curve_mm(np.array([105.0, 105.0]), g.curve_distance_mm, g.curve_reading_mm),
    )
    assert out.tolist() == [142.0, 797.0]


@pytest.mark.quick
@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (
            {"vl53l0x.curve_distance_mm": [10.0, 20.0], "vl53l0x.curve_reading_mm": [1.0, 2.0, 3.0]},
            r"vl53l0x.curve_reading_mm has 3 values but vl53l0x.curve_distance_mm has 2",
        ),
        (
            {"vl53l0x.curve_distance_mm": [10.0, 10.0], "vl53l0x.curve_reading_mm": [1.0, 2.0]},
            r"vl53l0x.curve_distance_mm\[1\] = 10.0 mm is impossible: it must increase strictly",
        ),
        (
            {"vl53l0x.curve_distance_mm": [10.0, 20.0], "vl53l0x.curve_reading_mm": [5.0, 4.0]},
            r"vl53l0x.curve_reading_mm\[1\] = 4.0 mm is impossible: it must increase strictly",
        ),
        (
            {"vl53l0x.curve_distance_mm": [-1.0, 20.0], "vl53l0x.curve_reading_mm": [5.0, 6.0]},
            r"vl53l0x.curve_distance_mm\[0\] = -1.0 mm is impossible: it must be >= 0.0",
        ),
        (
            {"vl53l0x.curve_distance_mm": [10.0], "vl53l0x.curve_reading_mm": [5.0]},
            r"vl53l0x.curve_distance_mm has 1 values: a curve needs at least 2 points \(or none\)",
        ),
        ({"vl53l0x.sigma_floor_mm": -1.0}, r"vl53l0x.sigma_floor_mm = -1.0 mm is impossible"),
    ],
    ids=["lengths", "distances", "readings", "negative", "one-point", "floor"],
)
def test_a_bad_curve_is_refused_naming_the_field(overrides: dict[str, object], message: str) -> None:
    with pytest.raises(ParameterError, match=message):
        Parameters().with_overrides(overrides)


# --- the noise floor ----------------------------------------------------------------------------------------------


@pytest.mark.quick
def test_the_noise_floor_fitted_from_the_18_deviations() -> None:
    """σ = max(σ₀, k·d·√(33 ms/B)). The 18 sample deviations (1.79 … 3.07 mm) show no growth with distance:
    a least-squares slope of sd on d of −0.02 ± 0.16 mm per 100 mm. A constant holds them: pooled over the
    18 × 19 degrees of freedom σ = 2.583 mm, the reduced χ² of sd/σ − 1 (relative standard error
    1/√(2·19)) 0.63 within its 95 % limit. The board's whole mm add 1/12 mm² to a reading's variance: the
    sensor's floor is √(2.583² − 1/12) = 2.567 mm (the preset's). The proportional law is not seen: any
    k ≤ σ₀/(196 mm·√(33/20)) = 0.0102 stays under the floor over the table, and the preset sets k = 0."""
    d = np.array(DISTANCES_MM)
    assert SDS_MM.min() == pytest.approx(1.789, abs=1e-3) and SDS_MM.max() == pytest.approx(3.068, abs=1e-3)
    slope, _ = np.polyfit(d, SDS_MM, 1)
    resid = SDS_MM - np.polyval(np.polyfit(d, SDS_MM, 1), d)
    se = math.sqrt(np.sum(resid**2) / (d.size - 2) / np.sum((d - d.mean()) ** 2))
    assert slope * 100 == pytest.approx(-0.0235, abs=5e-4) and se * 100 == pytest.approx(0.162, abs=1e-3)
    assert abs(slope) < se  # no growth within one standard error
    pooled = math.sqrt(np.sum(19 * SDS_MM**2) / (18 * 19))
    assert pooled == pytest.approx(2.5829, abs=1e-4)
    chi2 = float(np.sum(2 * 19 * (SDS_MM / pooled - 1.0) ** 2) / 17)
    assert chi2 == pytest.approx(0.634, abs=1e-3) and chi2 < stats.chi2.ppf(0.95, 17) / 17
    floor = math.sqrt(pooled**2 - 1.0 / 12.0)
    assert floor == pytest.approx(2.5667, abs=1e-4)
    g = OBB.of(Vl53l0x)
    assert g.sigma_floor_mm == round(floor, 3) and g.sigma_fraction == 0.0
    assert floor / (196.0 * math.sqrt(0.033 / 0.020)) == pytest.approx(0.0102, abs=1e-4)
    # the law: the floor below, the proportional part above where k·d·√(33/B) passes it
    sig = vl53l0x_sigma_mm(np.array([10.0, 100.0, 1000.0]), 0.01, 0.033, 2.567)
    assert sig.tolist() == [2.567, 2.567, 10.0]


def test_the_twins_readings_spread_as_obbs_at_both_ends_of_the_track() -> None:
    """4000 runs of the preset's sensor, each its own seed, the ball held at 14 mm and at 196 mm (wrong returns
    off): the readings' sample deviation is √(σ₀² + 1/12) = 2.583 mm at both (its standard error
    2.58/√8000 = 0.03 mm), their mean the curve's 28.1 and 289.3 mm (standard error 0.04 mm)."""
    p = OBB.with_overrides({"vl53l0x.wrong_return_probability": 0.0})
    n = 4000
    for d, mean in ((14.0, 28.1), (196.0, 289.3)):
        batch = Vl53l0xBatch(p, np.arange(n), np.full(n, _x_at(p, d)), 0.0)
        r = batch.readings
        assert np.all(r == np.rint(r))
        assert float(np.std(r, ddof=1)) == pytest.approx(2.583, abs=0.12), d
        assert float(np.mean(r)) == pytest.approx(mean, abs=0.2), d


# --- batch = single ------------------------------------------------------------------------------------------------


@pytest.mark.quick
def test_a_batch_with_the_curve_reads_each_runs_bits_alone() -> None:
    """The part's batch form (twin.parts.ranging: a ball rolling past, 12 blocks of 20 ms) on the preset with
    wrong returns often and a wall within range; half the runs with the curve and half without in one batch:
    every reading and the output bit for bit equal to the run alone."""
    base = OBB.with_overrides({"vl53l0x.wrong_return_probability": 0.3, "vl53l0x.background_mm": 600.0})
    names = ("vl53l0x.mount_x_m", "vl53l0x.sigma_floor_mm", "ball.radius_m")
    params, rows = form_inputs(base, names)(np.random.default_rng(11), 24)
    plain = {"vl53l0x.curve_distance_mm": [], "vl53l0x.curve_reading_mm": []}
    other = {"vl53l0x.curve_reading_mm": [1.05 * r for r in MEANS_MM]}  # a second curve in the same batch
    params = [
        p if i % 4 == 0 else p.with_overrides(other) if i % 4 == 2 else p.with_overrides(plain)
        for i, p in enumerate(params)
    ]
    assert [p.of(Vl53l0x).has_curve for p in params[:2]] == [True, False]
    single = form_single(lambda p, seed: Vl53l0xChain(p, seed))
    one = np.array([single(p, row) for p, row in zip(params, rows, strict=True)])
    many = form_batch(Vl53l0xBatch)(params, rows)
    assert one.shape == many.shape == (24, 13)
    assert np.array_equal(one, many)
    # both kinds of range: the ball's (on its curve, under 300 mm) and the wall's 600 mm (wrong returns, or the
    # ball off the track's 105 mm: these starts and speeds take many past its ends)
    assert np.count_nonzero(np.abs(one - 600.0) < 12.0) > 5 and np.count_nonzero(one < 300.0) > 5
    assert VL53L0X.batch.home == "twin.parts.vl53l0x.Vl53l0xBatch"


def test_the_presets_runs_batched_equal_their_single_runs() -> None:
    """run_batch against run_closed_loop (tests/test_batch_parts.py's check: every log array and the verdict bit
    for bit) on the open-ball-and-beam preset, rig-lqg holding the ball, three starts, noise on."""
    x0 = np.array([0.05, -0.06, 0.02])
    params = [OBB.with_overrides({"vl53l0x.sigma_floor_mm": 2.0 + 0.5 * i}) for i in range(3)]
    runs = _check(Catalogue(rig_lqg), x0, np.zeros(3), np.array([0, 1, 2]), params, duration_s=2.0)
    assert not any(r.verdict.ball_lost for r in runs)


# --- calibrate-static writes it back -----------------------------------------------------------------------------


@pytest.mark.quick
def test_calibrate_static_writes_the_curve_and_floor_the_twin_loads(tmp_path: Path) -> None:
    from twin.app.cli import main

    table = tmp_path / "obb.csv"
    lines = ["distance_mm,reading_mm"]
    lines += [f"{d},{r}" for d, readings in OBB_READINGS_MM.items() for r in readings]
    table.write_text("\n".join(lines) + "\n", "utf-8")
    out = tmp_path / "vl53l0x.toml"
    budget = tmp_path / "budget.toml"
    budget.write_text('[ball_sensor]\npart = "vl53l0x"\ntiming_budget_s = 0.02\n', "utf-8")
    args = [
        "calibrate-static",
        str(table),
        "--sensor",
        "vl53l0x",
        "--rig-file",
        str(budget),
        "--out",
        str(out),
    ]
    assert main(args) == 0
    rig = rig_from_text(out.read_text("utf-8"), origin=str(out))
    g = rig.of(Vl53l0x)
    assert rig.parts.ball_sensor == "vl53l0x"
    assert g.curve_distance_mm == tuple(DISTANCES_MM)
    assert g.curve_reading_mm == pytest.approx(MEANS_MM, abs=1e-12)
    assert g.sigma_floor_mm == pytest.approx(2.5667, abs=1e-4)
    assert g.crosstalk_offset_mm == 0.0  # the offset-only fit's −47 mm is not written beside the curve
    quiet = rig.with_overrides({**QUIET, "vl53l0x.mount_x_m": OBB.of(Vl53l0x).mount_x_m})
    for d, mean in zip(DISTANCES_MM, MEANS_MM, strict=True):
        assert Vl53l0xChain(quiet, 0, x_m=_x_at(quiet, d)).reading_v == float(np.rint(mean))


@pytest.mark.quick
def test_a_table_the_law_holds_or_whose_readings_fold_writes_no_curve() -> None:
    from calib.sensor_static import fit_static, ruler_table, table_from_readings

    # range = d − 12 mm exactly, σ = 0.05·d: the offset-only law holds, nothing else is written
    rng = np.random.default_rng(0)
    d = np.arange(40.0, 401.0, 20.0)
    held = table_from_readings(
        d,
        [np.rint(x - 12.0 + rng.normal(0.0, 0.05 * x, 30)) for x in d],
        quantity="distance",
        reading_unit="mm",
    )
    fit = fit_static("vl53l0x", held, Parameters().with_overrides({"vl53l0x.timing_budget_s": 0.020}))
    assert fit.adequate and "vl53l0x.curve_distance_mm" not in fit.overrides
    # a reading that falls back at 60 mm (a fold): the law misses, no inverse, so no curve
    folded = ruler_table(
        [20, 40, 60, 80],
        [40, 70, 65, 120],
        quantity="distance",
        reading_unit="mm",
        sd=[2, 2, 2, 2],
        n=[20] * 4,
    )
    fit = fit_static("vl53l0x", folded)
    assert "vl53l0x.curve_distance_mm" not in fit.overrides
    assert "none is written: the mean readings do not increase strictly" in fit.notes[-1]


@pytest.mark.quick
def test_the_software_reads_the_broken_line_at_one_float_with_the_arrays_bits() -> None:
    """The tick's scalar lookup (``_broken_line_at``, plain Python) is the array form's arithmetic: the same bits
    at 20 000 random readings, inside, between and beyond the knots, and at every knot."""
    from twin.parts.vl53l0x import _broken_line, _broken_line_at

    rng = np.random.default_rng(7)
    knots, values = np.sort(rng.uniform(0, 300, 18)), np.sort(rng.uniform(0, 300, 18))
    xs = np.concatenate([rng.uniform(-50, 400, 20_000), knots])
    scalar = np.array([_broken_line_at(float(x), list(knots), list(values)) for x in xs])
    assert np.array_equal(scalar, _broken_line(xs, knots, values))
