"""Recomputation of the thesis's numbers and figures (scripts/reproduce_thesis.py).

Every result is an ``Entry``: what the thesis prints, what it recomputes to from first principles, the
relative error, a verdict and the likely cause of any difference.

Verdicts:
    agrees        within 1 % or within the printed rounding
    misprint      a typo or transcription error; the rest of the thesis uses the right value
    inconsistent  does not follow from the thesis's own model or equations (cause explained)
    fails         a printed design that does not do what the thesis says on the model or the twin
    holds         a claim that the recomputation confirms
    unexplained   differs, cause not found
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = ["Entry", "VERDICTS", "rel_error", "to_jsonable"]

VERDICTS = ("agrees", "misprint", "inconsistent", "fails", "holds", "unexplained")


@dataclass
class Entry:
    id: str  # e.g. "eq 3.2.8", "Fig 4.4", "§7 claim SF range"
    quantity: str  # what it is, in words
    thesis: Any  # as printed (number, list, nested list, string)
    recomputed: Any
    rel_error: float | None
    verdict: str
    explanation: str

    def __post_init__(self) -> None:
        if self.verdict not in VERDICTS:
            raise ValueError(f"verdict {self.verdict!r} of {self.id} is not one of {VERDICTS}")

    def as_dict(self) -> dict[str, Any]:
        return to_jsonable(asdict(self))


def rel_error(printed: Any, recomputed: Any, floor: float = 1e-12) -> float:
    """max |recomputed − printed| / max(|printed|, floor) over the entries (matrices compared elementwise
    where the printed entry is non-zero; a printed zero compares absolutely)."""
    p = np.asarray(printed, dtype=complex)
    r = np.asarray(recomputed, dtype=complex)
    if p.shape != r.shape:
        raise ValueError(f"shapes differ: printed {p.shape}, recomputed {r.shape}")
    scale = np.where(np.abs(p) > floor, np.abs(p), 1.0)
    return float(np.max(np.abs(r - p) / scale))


def to_jsonable(value: Any) -> Any:
    """numpy arrays, complex numbers and nested containers → JSON-ready values (complex as [re, im])."""
    if isinstance(value, dict):
        return {k: to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, (complex, np.complexfloating)):
        if abs(value.imag) < 1e-12:
            return float(value.real)
        return [float(value.real), float(value.imag)]
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value
