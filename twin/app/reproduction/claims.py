"""A claim of the thesis as data, and the one rule that turns it into an entry of the report.

A ``Claim`` says where the thesis prints something, what it prints, how the project's own models recompute
it and how the two are compared (a ``Check``). ``evaluate`` applies the check element by element; where it
fails, the claim's diagnostic ``Hypothesis`` records, each recomputed, say which elements they explain and
with which verdict. The verdict is therefore computed, never typed:

* every element passes the check → the claim's ``confirmed`` verdict (``AGREES`` for a number, ``HOLDS`` for
  a statement about behaviour);
* some failing elements are explained by hypotheses → the most severe of their verdicts (misprint <
  inconsistent < fails); elements no hypothesis explains are listed as such in the entry;
* none explained → the claim's ``otherwise`` verdict (``UNEXPLAINED`` for a number, ``FAILS`` for a design
  or a statement about behaviour).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

__all__ = [
    "AGREES",
    "FAILS",
    "HOLDS",
    "INCONSISTENT",
    "MISPRINT",
    "UNEXPLAINED",
    "VERDICTS",
    "Check",
    "Claim",
    "Close",
    "Entry",
    "Hypothesis",
    "Outcome",
    "Predicate",
    "Within",
    "evaluate",
    "range_error",
    "rel_error",
    "to_jsonable",
]

AGREES = "agrees"
MISPRINT = "misprint"
INCONSISTENT = "inconsistent"
FAILS = "fails"
HOLDS = "holds"
UNEXPLAINED = "unexplained"

# verdict → (heading of its section in the report, what it means)
VERDICTS: dict[str, tuple[str, str]] = {
    AGREES: ("Agreements", "the recomputed value passes the claim's check (tolerance or printed rounding)"),
    HOLDS: ("Confirmed statements", "a statement about behaviour that the recomputation confirms"),
    MISPRINT: ("Misprints", "a typo or transcription slip; a stated hypothesis, recomputed, shows it"),
    INCONSISTENT: (
        "Inconsistencies",
        "does not follow from the thesis's own model; a stated hypothesis, recomputed, shows how it was obtained",
    ),
    FAILS: ("Printed designs and claims that fail", "a design or statement the recomputation contradicts"),
    UNEXPLAINED: ("Unexplained", "differs from the recomputation and no stated hypothesis explains it"),
}
SEVERITY = (MISPRINT, INCONSISTENT, FAILS)


# --- checks -----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Outcome:
    passed: np.ndarray  # one bool per element
    rel_error: float | None


class Check(Protocol):
    @property
    def describe(self) -> str: ...

    def __call__(self, printed: Any, recomputed: Any) -> Outcome: ...


def _complex(value: Any) -> np.ndarray:
    return np.asarray(value, dtype=complex).ravel()


def _printed_decimals(value: complex) -> int:
    """Decimal places of a printed number as the thesis wrote it (shortest repr of each part)."""
    places = []
    for part in (value.real, value.imag):
        text = repr(float(part))
        mantissa, _, exponent = text.partition("e")
        places.append(len(mantissa.partition(".")[2].rstrip("0")) - (int(exponent) if exponent else 0))
    return max(places)


def rel_error(printed: Any, recomputed: Any, floor: float = 1e-12) -> float:
    """max |recomputed − printed| / |printed| over the elements (a printed zero compares absolutely)."""
    p, r = _complex(printed), _complex(recomputed)
    if p.shape != r.shape:
        raise ValueError(f"shapes differ: printed {p.shape}, recomputed {r.shape}")
    scale = np.where(np.abs(p) > floor, np.abs(p), 1.0)
    return float(np.max(np.abs(r - p) / scale))


@dataclass(frozen=True)
class Close:
    """Element by element: |r − p| ≤ rel·|p|, or within the printed rounding (``decimals``: a number of
    decimal places, or ``"printed"`` for each element's own as written); a printed zero needs |r| ≤ ``zero``."""

    rel: float = 0.01
    decimals: int | str | None = None
    zero: float = 1e-9

    @property
    def describe(self) -> str:
        parts = [f"relative error ≤ {self.rel:.3g}"]
        if self.decimals == "printed":
            parts.append("or within the rounding of the printed digits")
        elif self.decimals is not None:
            parts.append(f"or within the rounding of {self.decimals} decimals")
        return " ".join(parts)

    def __call__(self, printed: Any, recomputed: Any) -> Outcome:
        p, r = _complex(printed), _complex(recomputed)
        if p.shape != r.shape:
            raise ValueError(f"shapes differ: printed {p.shape}, recomputed {r.shape}")
        diff = np.abs(r - p)
        ok = np.where(np.abs(p) > 0, diff <= self.rel * np.abs(p), diff <= self.zero)
        if self.decimals is not None:
            places = (
                np.array([_printed_decimals(v) for v in p])
                if self.decimals == "printed"
                else np.full(p.shape, int(self.decimals))
            )
            ok |= diff <= 0.5 * 10.0 ** (-places.astype(float)) * (1 + 1e-9)
        return Outcome(ok, rel_error(p, r))


def range_error(value: float | None, lo: float, hi: float) -> float | None:
    """0 inside [lo, hi], else the distance to the nearer bound relative to it; None for no value."""
    if value is None:
        return None
    return (
        0.0 if lo <= value <= hi else abs(value - (lo if value < lo else hi)) / abs(lo if value < lo else hi)
    )


@dataclass(frozen=True)
class Within:
    """The printed value is a range (lo, hi); every recomputed element lies in it, widened by ``slack``
    (relative, for ranges read off a plot); ``None`` (e.g. no settling time) never does."""

    slack: float = 0.0

    @property
    def describe(self) -> str:
        return f"recomputed value inside the printed range (widened by {self.slack:.0%})"

    def __call__(self, printed: Any, recomputed: Any) -> Outcome:
        lo, hi = printed
        values = list(recomputed) if isinstance(recomputed, (list, tuple, np.ndarray)) else [recomputed]
        errors = [range_error(v, lo, hi) for v in values]
        ok = np.array([e is not None and e <= self.slack for e in errors])
        return Outcome(
            ok, None if any(e is None for e in errors) else max(e for e in errors if e is not None)
        )


@dataclass(frozen=True)
class Predicate:
    """A statement judged by a function of (printed, recomputed); one element."""

    describe: str
    test: Callable[[Any, Any], bool]

    def __call__(self, printed: Any, recomputed: Any) -> Outcome:
        return Outcome(np.array([bool(self.test(printed, recomputed))]), None)


# --- hypotheses and claims --------------------------------------------------------------------------------
@dataclass(frozen=True)
class Hypothesis:
    """A diagnosis of a difference, recomputed. ``value(model)`` is what the printed value would be if the
    statement were true (compared with the printed value by ``check``, else the claim's); ``test(model)``, if
    given, must also be true. The elements it explains are those the comparison passes."""

    statement: str
    verdict: str
    value: Callable[[Any], Any] | None = None
    test: Callable[[Any], bool] | None = None
    check: Check | None = None
    whole: bool = False

    def explains(self, model: Any, claim: Claim, n: int) -> np.ndarray:
        if self.test is not None and not self.test(model):
            return np.zeros(n, dtype=bool)
        if self.value is None:
            return np.ones(n, dtype=bool)
        passed = (self.check or claim.check)(claim.printed, self.value(model)).passed
        return np.full(n, bool(passed.all())) if self.whole else passed


def _no_prose(model: Any, value: Any) -> str:
    return ""


@dataclass(frozen=True)
class Claim:
    """One printed claim of the thesis: where, what, the printed value, its recomputation and its check."""

    id: str
    quantity: str
    printed: Any
    recompute: Callable[[Any], Any]
    check: Check = field(default_factory=Close)
    hypotheses: tuple[Hypothesis, ...] = ()
    explain: Callable[[Any, Any], str] = _no_prose
    elements: tuple[str, ...] = ()
    confirmed: str = AGREES
    otherwise: str = UNEXPLAINED
    display: Callable[[Any], Any] | None = None  # the recomputed value as reported (default: as computed)
    scenarios: tuple[Any, ...] = ()  # closed-loop runs the recomputation uses (declared, run once, cached)

    @property
    def where(self) -> str:
        """Where the thesis prints it: the place the id starts with (eq 3.2.8, §4.2, Table 3.1, Fig 4.4, …)."""
        found = re.match(r"(?:eq|Fig|Table)\s\S+|§\d+(?:\.\d+)*|appendix \w", self.id)
        return found.group(0) if found else self.id

    def element_names(self, n: int) -> list[str]:
        if self.elements:
            return list(self.elements)
        shape = np.shape(np.asarray(self.printed, dtype=complex)) if isinstance(self.check, Close) else ()
        if len(shape) == 2:
            return [f"[{i + 1},{j + 1}]" for i in range(shape[0]) for j in range(shape[1])]
        return [f"[{i + 1}]" for i in range(n)]


@dataclass
class Entry:
    id: str
    where: str
    quantity: str
    thesis: Any
    recomputed: Any
    rel_error: float | None
    verdict: str
    check: str
    findings: list[dict[str, Any]]
    unexplained: list[str]
    explanation: str

    def __post_init__(self) -> None:
        if self.verdict not in VERDICTS:
            raise ValueError(f"verdict {self.verdict!r} of {self.id} is not one of {tuple(VERDICTS)}")

    def as_dict(self) -> dict[str, Any]:
        return {k: to_jsonable(v) for k, v in self.__dict__.items()}


def _severest(verdicts: Sequence[str]) -> str:
    return max(verdicts, key=SEVERITY.index)


def evaluate(claim: Claim, model: Any) -> Entry:
    """Recompute ``claim`` on ``model``, check it, try its hypotheses on the failing elements: its entry."""
    value = claim.recompute(model)
    outcome = claim.check(claim.printed, value)
    failing = ~outcome.passed
    names = claim.element_names(failing.size)
    explained = np.zeros(failing.shape, dtype=bool)
    findings: list[dict[str, Any]] = []
    for hyp in claim.hypotheses if failing.any() else ():
        new = hyp.explains(model, claim, failing.size) & failing & ~explained
        if new.any():
            explained |= new
            elements = [n for n, hit in zip(names, new, strict=True) if hit]
            findings.append({"verdict": hyp.verdict, "hypothesis": hyp.statement, "elements": elements})
    if not failing.any():
        verdict = claim.confirmed
    elif findings:
        verdict = _severest([f["verdict"] for f in findings])
    else:
        verdict = claim.otherwise
    left = [n for n, bad in zip(names, failing & ~explained, strict=True) if bad]
    prose = [claim.explain(model, value)]
    if len(names) > 1 and failing.any():
        passed = [n for n, ok in zip(names, outcome.passed, strict=True) if ok]
        prose.append(f"Passing the check: {', '.join(passed) or 'none'}.")
    prose += [
        f"{f['verdict'].capitalize()}: {f['hypothesis']} ({', '.join(f['elements'])})." for f in findings
    ]
    if left and findings:
        prose.append(f"Not explained by any stated hypothesis: {', '.join(left)}.")
    tried = [h.statement for h in claim.hypotheses if h.statement not in {f["hypothesis"] for f in findings}]
    if tried and failing.any():
        prose.append(f"Tried without explaining a failing element: {'; '.join(tried)}.")
    return Entry(
        id=claim.id,
        where=claim.where,
        quantity=claim.quantity,
        thesis=claim.printed,
        recomputed=claim.display(value) if claim.display else value,
        rel_error=outcome.rel_error,
        verdict=verdict,
        check=claim.check.describe,
        findings=findings,
        unexplained=left,
        explanation=" ".join(p for p in prose if p),
    )


def to_jsonable(value: Any) -> Any:
    """numpy arrays, complex numbers and nested containers → JSON-ready values (complex as [re, im])."""
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, (complex, np.complexfloating)):
        z = complex(value)
        return float(z.real) if abs(z.imag) < 1e-12 else [float(z.real), float(z.imag)]
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value
