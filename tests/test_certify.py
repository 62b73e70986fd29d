"""``ballbeam certify`` (twin.app.certify): the exact binomial run count, a pass stated over what it is over, a
violation ending the job with a counterexample that replays bit for bit, a requirement within the sensor noise
of violation inconclusive, the same seed the same runs."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from twin.app.certify import CertifySettings, certify, runs_needed
from twin.app.cli import main
from twin.app.montecarlo import load_spread
from twin.parameters import Parameters
from twin.requirements import Spec, parse_requirements

ROOT = Path(__file__).parents[1]
SPREAD = ROOT / "docs" / "examples" / "spread.toml"


def _spec(**formulas: str) -> Spec:
    return Spec(parse_requirements({"requirements": formulas}, "t"), {}, "test")


@pytest.mark.quick
def test_runs_needed_is_the_exact_binomial_bound_with_no_failure() -> None:
    assert runs_needed(0.99, 0.99) == 459  # 0.99^459 = 0.00995 ≤ 0.01 < 0.99^458 = 0.01005
    assert runs_needed(0.95, 0.95) == 59
    rng = np.random.default_rng(0)
    for p, c in rng.uniform(0.5, 0.999, (200, 2)):
        n = runs_needed(float(p), float(c))
        assert p**n <= 1 - c < p ** (n - 1)
    with pytest.raises(ValueError, match="strictly"):
        runs_needed(1.0, 0.9)


def test_a_pass_states_what_it_is_over_and_the_same_seed_gives_the_same_runs() -> None:
    p = Parameters()
    spread = load_spread(SPREAD, p)
    spec = _spec(on_track="always (abs(x_m) <= 0.323 and lost < 0.5)")
    settings = CertifySettings("appendix-sf", (-0.1, 0.1), (-0.2, 0.2), 0.7, 0.8, duration_s=3.0, batch=3)
    a = certify(settings, p, spec, spread)
    assert a.outcome == "pass" and len(a.runs) == runs_needed(0.7, 0.8) == 5
    text = a.statement()
    assert "probability ≥ 0.7 at confidence 0.8" in text and "docs/examples/spread.toml" in text
    assert "x0 ∈ [-0.1, 0.1] m" in text
    on_track = a.requirements["on_track"]
    assert on_track["least_robustness"] == min(r["requirements"]["on_track"] for r in a.runs)
    assert len(on_track["noise_reruns"]) == 8 and on_track["least_robustness"] > 3 * on_track["noise_sd"]
    b = certify(settings, p, spec, spread, workers=2)
    ja, jb = a.to_json(), b.to_json()
    ja.pop("wall_s"), jb.pop("wall_s")
    assert ja == jb


def test_a_violation_ends_the_job_with_a_counterexample_that_replays(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = tmp_path / "tight.toml"
    spec.write_text('[requirements]\nnear_centre = "always (abs(x_m) <= 0.05)"\n')
    out = tmp_path / "cert"
    argv = ["certify", "--controller", "appendix-sf", "--spec", str(spec), "--spread", str(SPREAD)]
    argv += ["--duration", "2", "--batch", "4", "--out", str(out)]
    assert main(argv) == 1
    data = json.loads((out / "certify.json").read_text())
    assert data["outcome"] == "fail" and data["runs_spent"] == 4  # the first batch has one
    cx = data["counterexample"]
    first = next(r for r in data["runs"] if r["requirements"]["near_centre"] < 0)
    assert cx["robustness"] == first["requirements"] and cx["x0_m"] == first["x0_m"]
    assert data["runs"].index(first) + 1 == data["runs_to_first_violation"]
    assert data["statement"].startswith(
        f"FAIL: run {data['runs_to_first_violation']} of 4 run violates near_centre"
    )
    capsys.readouterr()
    assert main(["run", "--replay", str(out / "certify.json"), "--json"]) == 1
    summary = json.loads(capsys.readouterr().out)
    assert summary["replayed"]["same"] and summary["requirements"]["near_centre"] < 0


def test_a_requirement_within_the_noise_of_violation_is_inconclusive() -> None:
    p = Parameters()
    spread = load_spread(SPREAD, p)
    settings = CertifySettings("appendix-sf", (0.05, 0.1), (0.0, 0.1), 0.7, 0.8, duration_s=2.0, batch=5)
    # the worst gap between measured and true ball position, then a bound just above it
    wide = certify(settings, p, _spec(reads="always (abs(x_meas_m - x_m) <= 0.05)"), spread)
    gap = 0.05 - wide.requirements["reads"]["least_robustness"]
    bound = gap + 1e-6
    tight = certify(settings, p, _spec(reads=f"always (abs(x_meas_m - x_m) <= {bound!r})"), spread)
    reads = tight.requirements["reads"]
    assert math.isclose(reads["least_robustness"], 1e-6, abs_tol=1e-9)
    assert tight.outcome in ("inconclusive", "fail") and reads["status"] == "inconclusive"
    assert reads["noise_sd"] > 0
