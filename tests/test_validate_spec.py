"""``validate --spec`` (twin.app.validate with a requirements file): docs/examples/requirements.toml is validate's
checks in signal temporal logic, run for run; a bad ``[validate]`` table is refused naming the file."""

from __future__ import annotations

from pathlib import Path

import pytest
from cli_checks import refused

from twin.parameters import ParameterError, Parameters

EXAMPLE = Path(__file__).parents[1] / "docs" / "examples" / "requirements.toml"


@pytest.mark.parametrize(
    "controller",
    ["appendix-sf", pytest.param("appendix-clp", marks=pytest.mark.study)],  # each ~1 min
)
def test_the_example_requirements_give_the_default_validations_verdicts_run_for_run(controller: str) -> None:
    """docs/examples/requirements.toml is validate's checks in STL: over every run of the default validation
    (its Monte Carlo and robust rigs fewer, ``FEWER``: they judge with the same requirements as the runs
    below), each run meets the file's held requirements exactly when its verdict held, kept exactly when the
    ball was kept, saturation exactly when its share of ticks at the rails is within the bound; and the checks
    pass and fail as without the file."""
    from twin.app.validate import SPEC_CHECKS, ValidationCriteria, validate
    from twin.requirements import load_spec

    spec = load_spec(EXAMPLE, SPEC_CHECKS)
    fewer = ValidationCriteria(montecarlo_runs=30, robust_rigs=12, min_success_lower_bound=0.7)
    report = validate(controller, Parameters(), fewer, spec=spec, workers=2)
    held_names = spec.checks["nominal"]
    runs = [
        r for check in report.checks if check.name.startswith(("nominal", "sensitivity")) for r in check.rows
    ]
    assert len(runs) == 18 + 28
    for r in runs:
        margins = r["requirements"]
        assert all(margins[n] >= 0 for n in held_names) == r["held"], r
        assert (margins["saturation"] >= 0) == (r["saturated_fraction"] <= 0.2), r
    assert report.region is not None and len(report.region.points) == 255
    for p in report.region.points:
        assert (p["requirements"]["kept"] >= 0) == (not p["ball_lost"]), p
    lost = sum(p["ball_lost"] for p in report.region.points)
    assert 0 < lost < 255  # both classes occur: the comparison can fail
    plain = validate(controller, Parameters(), fewer, workers=2)
    assert [(c.name, c.passed) for c in report.checks] == [(c.name, c.passed) for c in plain.checks]
    assert report.to_json()["spec"] == str(EXAMPLE)


@pytest.mark.quick
def test_a_bad_validate_table_is_refused_naming_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from twin.app.validate import SPEC_CHECKS
    from twin.requirements import load_spec

    path = tmp_path / "spec.toml"
    for text, needle in (
        (
            '[requirements]\nkept = "always (lost < 0.5)"\n[validate]\nnominl = ["kept"]\n',
            "'nominl' is not a check",
        ),
        (
            '[requirements]\nkept = "always (lost < 0.5)"\n[validate]\nregion = ["held"]\n',
            "no requirement 'held'",
        ),
        (
            '[requirements]\nkept = "always (lost < 0.5)"\n[validate]\nregion = "kept"\n',
            "a list of requirement names",
        ),
        ('[requirements]\nkept = "always (lost < 0.5)"\n[checks]\n', "unknown table 'checks'"),
    ):
        path.write_text(text)
        with pytest.raises(ParameterError, match=needle):
            load_spec(path, SPEC_CHECKS)
        refused(capsys, ["validate", "--controller", "appendix-sf", "--spec", str(path)], str(path), needle)
    spec = load_spec(EXAMPLE, SPEC_CHECKS)
    assert [r.name for r in spec.asked("region")] == ["kept"]
    assert len(spec.asked("nominal")) == 5 and len(spec.requirements) == 6
