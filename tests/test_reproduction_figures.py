"""Closed-loop figure reproduction (controllers/reproduction/figures.py), quick mode."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import thesis_numbers as T
from controllers.reproduction import VERDICTS, Entry
from controllers.reproduction import figures as F
from twin.parameters import Parameters

CLAIMS = {
    "§7 claim SMC torque",
    "§7 claim CLP torque lower",
    "§7 SF redesign spec",
    "§7 claim SF settling",
    "§7 claim CLP settling",
    "§7 claim SF range",
    "§7 claim CLP range",
    "§7 claim CLP range larger",
}


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    out = tmp_path_factory.mktemp("figs")
    es = F.entries(out, quick=True)
    return out, es, None


@pytest.fixture(scope="module")
def by_id(result):
    return {e.id: e for e in result[1]}


def test_ids_and_pngs(result, by_id):
    out, es, _ = result
    assert all(isinstance(e, Entry) and e.verdict in VERDICTS for e in es)
    assert len(by_id) == len(es), "duplicate entry ids"
    assert set(by_id) == set(F.FIGURE_IDS) | CLAIMS
    for fid in F.FIGURE_IDS:
        png = out / F._png_name(fid)
        assert png.exists() and png.stat().st_size > 5000, fid
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert {p.name for p in out.glob("*.png")} == {F._png_name(f) for f in F.FIGURE_IDS}
    for e in es:
        e.as_dict()  # JSON-ready


def test_state_feedback_continuous_settles_as_printed(by_id):
    for fid, lo, hi in (("Fig 4.4", 2.4, 2.5), ("Fig 4.5", 2.9, 3.0)):
        rec = by_id[fid].recomputed
        assert by_id[fid].verdict == "agrees"
        assert lo <= rec["thesis_model"]["settling_time_s"] <= hi
        assert lo <= rec["twin"]["settling_time_s"] <= hi
        assert rec["twin"]["ball_kept"]
    assert by_id["§7 claim SF settling"].verdict == "holds"


def test_sliding_mode_fails_on_the_thesis_model_too(by_id):
    for fid in ("Fig 4.11", "Fig 4.12"):
        e = by_id[fid]
        assert e.verdict == "fails"
        model = e.recomputed["thesis_model"]
        # the reference plant's stops are inelastic: the beam is on its stop within 0.1 s, the ball then leaves
        assert model["hit_stops"] and model["stop_time_s"] < 0.1
        assert not model["ball_kept"] and model["left_track"]
        assert not e.recomputed["twin"]["ball_kept"]
        assert e.recomputed["S_bar_B"] < 0  # switching pushes away from the surface
        assert max(v if isinstance(v, float) else v[0] for v in e.recomputed["eig(A - B K_eq_printed)"]) > 700
    assert by_id["§7 claim SMC torque"].verdict == "fails"


def test_control_law_partitioning_continuous(by_id):
    # the linearised loop's slow pair (−0.164 ± 0.54j) rules out 6–7 s settling
    eig = by_id["Fig 4.8"].recomputed["closed_loop_eigenvalues_thesis_model"]
    slow = min(abs(v[0]) if isinstance(v, list) else abs(v) for v in eig)
    assert slow == pytest.approx(0.164, abs=0.01)
    # from (−0.2, 0.3) the ball passes the track end on the thesis model and is lost on the twin
    rec = by_id["Fig 4.9"].recomputed
    assert rec["thesis_model"]["left_track"] and not rec["twin"]["ball_kept"]
    assert by_id["Fig 4.9"].verdict == "fails"


def test_torque_claims(by_id):
    cmp = by_id["§7 claim CLP torque lower"].recomputed
    # the first command acts at release (thesis model): SF's peak is the plant's k_τ·|K·x0| at rest (0.2714 N·m;
    # 0.2718 with the printed k_τ = 0.0164 the old private integrator used)
    k_tau = Parameters().motor.torque_per_volt_nm_per_v
    assert cmp["(0.2, -0.3)"]["sf_peak_nm"] == pytest.approx(
        k_tau * abs((T.SF_CONT_K @ np.array([0.2, -0.3, 0.0, 0.0]))[0]), rel=2e-3
    )
    assert cmp["(0.2, -0.3)"]["clp_peak_nm"] < cmp["(0.2, -0.3)"]["sf_peak_nm"]
    assert cmp["(0.2, 0.3)"]["clp_peak_nm"] > cmp["(0.2, 0.3)"]["sf_peak_nm"]
    assert by_id["§7 claim CLP torque lower"].verdict == "fails"
    spec = by_id["§7 SF redesign spec"]
    assert spec.verdict == "misprint"
    assert spec.recomputed["t_s = 4/(ζ·ω_n) with ζ = 1"] == pytest.approx(6.0, abs=0.01)
    readings = by_id["Fig 7.7"].recomputed["readings"]
    assert not readings["all-at-0.666"]["ball_kept_thesis_model"]
    assert readings[F.PRIMARY_READING]["ball_kept_thesis_model"]
    assert readings[F.PRIMARY_READING]["ratio_to_clp_after_0.1s"] == pytest.approx(1.0, abs=0.3)
    assert by_id["Fig 7.7"].verdict == "holds"


def test_printed_chapter5_state_feedback_fails(by_id):
    for fid in ("Fig 5.3", "Fig 5.4", "Fig 5.5"):
        assert by_id[fid].verdict == "fails"
        assert max(by_id[fid].recomputed["observer_error_pole_magnitudes"]) > 1.0
    for fid in ("Fig 5.3", "Fig 5.4"):
        rec = by_id[fid].recomputed
        assert not rec["thesis_model"]["ball_kept"] and not rec["twin"]["ball_kept"]
        assert rec["appendix-sf_thesis_model"]["ball_kept"] and rec["appendix-sf_twin"]["ball_kept"]
    assert max(by_id["Fig 5.10"].recomputed["observer_error_pole_magnitudes"]) < 0.25
    assert by_id["§7 claim SF range"].verdict == "fails"


def test_ranges(by_id):
    table = by_id["§7 claim CLP range"].recomputed["table"]
    # 0.33 m is beyond the track end: the twin starts at 0.32 m and says so
    assert table["(+0.33 m, +0.70 rad)"]["twin_start_clamped_to_m"] == pytest.approx(0.32)
    assert table["(+0.33 m, +0.70 rad)"]["thesis_model"]["thesis-clp"].startswith("kept")
    # from (−0.25, 0.3) the ball runs past the −0.323 m track end (thesis model) / is lost (twin)
    assert "past track end" in table["(-0.25 m, +0.30 rad)"]["thesis_model"]["thesis-clp"]
    assert table["(-0.25 m, +0.30 rad)"]["twin"]["thesis-clp"].startswith("lost")
    assert by_id["§7 claim CLP range"].verdict == "fails"


def test_zeroing_error_shifts_equilibrium_monotonically(by_id):
    e = by_id["Fig 7.20"]
    assert e.verdict == "holds"
    errs = e.recomputed["zeroing_error_rad"]
    for label, v in e.recomputed["final"].items():
        x = np.array(v["final_x_m"])
        assert np.all(np.diff(x) < 0), label  # a positive zeroing error moves the ball to −x
        assert abs(x[errs.index(0.0)]) < 0.01, label
        assert np.max(np.abs(v["final_theta_rad"])) < 0.01, label  # the true beam ends level
