"""The reproduction's claims (twin/app/reproduction): verdicts computed by one rule, prose formatted from values.

Each number claim is a test id. The committed docs/reproduction/reproduction.json is what the code computed
when it was generated; a claim whose verdict differs now means the docs are stale (regenerate them with
scripts/reproduce_thesis.py).
"""

from __future__ import annotations

import ast
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from controllers import thesis_numbers as tn
from twin.app.reproduction import numbers
from twin.app.reproduction.claims import (
    AGREES,
    MISPRINT,
    SEVERITY,
    UNEXPLAINED,
    VERDICTS,
    Claim,
    Close,
    Hypothesis,
    evaluate,
)
from twin.app.reproduction.models import Model
from twin.parameters import Parameters

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "twin" / "app" / "reproduction"
COMMITTED = {
    e["id"]: e for e in json.loads((ROOT / "docs/reproduction/reproduction.json").read_text("utf-8"))
}


@pytest.fixture(scope="module")
def nominal() -> dict[str, object]:
    model = Model()
    return {c.id: evaluate(c, model) for c in numbers.CLAIMS}


def printed_r_star() -> Parameters:
    """The rig with r* back at Table 3.1's printed 4.264 mm: the wires' spacing that gives it."""
    r = Parameters().ball.radius_m
    spacing = 2 * math.sqrt(r * r - tn.R_STAR_PRINTED_M**2)
    return Parameters().with_overrides({"track.contact_spacing_m": spacing})


@pytest.fixture(scope="module")
def perturbed() -> dict[str, object]:
    model = Model(printed_r_star())
    assert model.rolling_radius_m == pytest.approx(tn.R_STAR_PRINTED_M, rel=1e-12)
    return {c.id: evaluate(c, model) for c in numbers.CLAIMS}


@pytest.mark.parametrize("claim", numbers.CLAIMS, ids=lambda c: c.id)
def test_number_claim(claim: Claim, nominal) -> None:
    entry = nominal[claim.id]
    assert entry.verdict in VERDICTS
    json.dumps(entry.as_dict())
    # the verdict follows from the check: all elements pass ⇔ the confirmed verdict
    passed = claim.check(claim.printed, claim.recompute(Model())).passed
    assert passed.all() == (entry.verdict == claim.confirmed)
    if not passed.all():  # else the hypotheses that explained failing elements, or the claim's otherwise
        found = [f["verdict"] for f in entry.findings]
        assert entry.verdict == (max(found, key=SEVERITY.index) if found else claim.otherwise)
    assert COMMITTED[claim.id]["verdict"] == entry.verdict, "docs/reproduction is stale"


@pytest.mark.quick
def test_claim_ids_are_unique_and_cover_the_committed_report() -> None:
    from twin.app.reproduction.closed_loop import CLAIMS as CLOSED

    ids = [c.id for c in (*numbers.CLAIMS, *CLOSED)]
    assert len(ids) == len(set(ids))
    assert set(ids) == set(COMMITTED)


@pytest.mark.quick
def test_r_star_back_at_the_printed_value_changes_the_verdicts_that_depend_on_it(nominal, perturbed) -> None:
    changed = {i for i in nominal if nominal[i].verdict != perturbed[i].verdict}
    assert {"Table 3.1 r*", "eq 3.2.8 A ẍ row", "eq 3.2.9 B"} <= changed, changed
    # r* then agrees with itself; B3 is no longer explained by the missing 2r²/(5r*) term
    assert perturbed["Table 3.1 r*"].verdict == AGREES
    assert "B3" not in nominal["eq 3.2.9 B"].unexplained and "B3" in perturbed["eq 3.2.9 B"].unexplained
    # claims about the printed intermediate results alone do not move
    for fixed in ("eq 3.2.11 TF", "eq 3.4.8 Φ", "§4.2 K", "§3.5 det Q_C"):
        assert fixed not in changed


@pytest.mark.quick
def test_the_rule_computes_every_verdict() -> None:
    """A ×10 slip found by its hypothesis, nothing found without one, a pass is the confirmed verdict."""
    slip = Hypothesis("a ×10 slip", MISPRINT, value=lambda m: 10 * m)
    for value, hyps, want in ((0.5, (slip,), MISPRINT), (0.5, (), UNEXPLAINED), (5.0, (slip,), AGREES)):
        claim = Claim("x", "a number", 5.0, lambda m: m, Close(), hyps)
        assert evaluate(claim, value).verdict == want
    vector = Claim("v", "two numbers", [5.0, 7.0], lambda m: m, Close(), (slip,))
    entry = evaluate(vector, np.array([0.5, 1.0]))
    assert entry.verdict == MISPRINT and entry.unexplained == ["[2]"]


# --- the prose carries no typed-in verdict or number ------------------------------------------------------
REFERENCE = re.compile(
    r"(?:\b(?:eqs?|Figs?|Tables?|chapter|§)\s*|§)\d+(?:\.\d+)*(?:\s*(?:/|,|and|–)\s*\d+(?:\.\d+)+)*|\d+\.\d+\.\d+"
)
NUMBER = re.compile(r"(?<![\w.])(?:\d+\.\d+|\d{2,})")
VERDICT_WORD = re.compile(r"\b(?:" + "|".join(VERDICTS) + r")\b", re.IGNORECASE)
QUOTES = {"CAPTIONS"}  # the thesis's own captions, as printed
NOT_PROSE = {"Claim": (0, 2), "_figure": (0, 2)}  # positional id and printed value (data, not prose)
NOT_PROSE_KEYWORDS = {"id", "printed"}


def _prose_strings(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text("utf-8"))
    skip: set[int] = set()
    for node in ast.walk(tree):
        if (
            isinstance(node, (ast.Module, ast.FunctionDef, ast.ClassDef))
            and ast.get_docstring(node) is not None
        ):
            skip.add(id(node.body[0].value))  # type: ignore[attr-defined]
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id in QUOTES for t in node.targets
        ):
            skip.update(id(n) for n in ast.walk(node.value))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in NOT_PROSE:
            for i in NOT_PROSE[node.func.id]:
                if i < len(node.args):
                    skip.update(id(n) for n in ast.walk(node.args[i]))
            for kw in node.keywords:
                if kw.arg in NOT_PROSE_KEYWORDS:
                    skip.update(id(n) for n in ast.walk(kw.value))
        if isinstance(node, ast.FormattedValue) and node.format_spec is not None:
            skip.update(id(n) for n in ast.walk(node.format_spec))
        if isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None:
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names = {t.id for t in targets if isinstance(t, ast.Name)}
            definitions = {"VERDICTS", *(v.upper() for v in VERDICTS)} if path.name == "claims.py" else set()
            if names & (definitions | {"__all__"}):
                skip.update(id(n) for n in ast.walk(node.value))
    return [
        (n.lineno, n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in skip
    ]


@pytest.mark.parametrize("path", sorted(PACKAGE.glob("*.py")), ids=lambda p: p.name)
def test_prose_has_no_typed_number_or_verdict(path: Path) -> None:
    """Every string of the reproduction except docstrings, claim ids, places and printed values (the thesis's
    words) and the captions: no decimal number or number of two digits or more outside references (eq 3.2.8,
    Fig 4.4, §4.2, Table 3.1), and no verdict word outside the verdicts' definition in claims.py."""
    bad = []
    for line, text in _prose_strings(path):
        stripped = REFERENCE.sub("", text)
        if NUMBER.search(stripped) or VERDICT_WORD.search(text):
            bad.append(f"line {line}: {text!r}")
    assert not bad, "\n".join(bad)


def test_the_prose_check_sees_a_typed_number(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text('EXPLAIN = "the slow pair gives 4/0.164 ≈ 24 s, so it fails"\n')
    (text,) = [t for _, t in _prose_strings(bad)]
    assert NUMBER.search(REFERENCE.sub("", text)) and VERDICT_WORD.search(text)
    assert not NUMBER.search(REFERENCE.sub("", "see eq 3.2.8, Figs 4.8/4.9 and §4.2 for A31"))
