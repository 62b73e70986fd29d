"""Screen with the fast engine, confirm with MuJoCo: a map that is MuJoCo's map at a fraction of its cost.

The fast engine (``run_batch(plant="reference")``: the analytic plant in the compiled kernel under the twin's
full sensor chain, DAQ schedule, amplifier and laws) decides every start of every map. Where the two engines
could disagree, MuJoCo decides:

1. the **band**: every start within ``band`` grid steps (along either axis, diagonals included) of a start
   of another class is run on MuJoCo;
2. the band follows MuJoCo: with MuJoCo's classes put in, the map's band is taken again, and every start of it
   not yet run on MuJoCo is run, until each start within ``band`` steps of a class change was decided by
   MuJoCo (a boundary MuJoCo moves is followed as far as it goes; the rule of ``--refine``'s trace);
3. the **audit**: ``audit`` starts of each map decided by the fast engine alone, drawn at random (seeded),
   are run on MuJoCo too; each disagreement is listed and fails the command.

Every record says which engine decided it (``"engine": "mujoco"`` or ``"fast"``); a start MuJoCo ran carries
MuJoCo's record with its brute-force seed, so the map equals MuJoCo's brute force on every start MuJoCo ran.
What is assumed of the others is ``ASSUMPTION``; the audit tests it.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from twin.app.fanout import Progress
from twin.app.sweep import ENGINE_NAMES, Job, verdict_class

__all__ = ["ASSUMPTION", "DEFAULT_AUDIT", "DEFAULT_BAND", "ENGINES", "Screening", "ScreenStats"]

ENGINES = ENGINE_NAMES
DEFAULT_BAND = 1  # grid steps around a class change that MuJoCo decides
DEFAULT_AUDIT = 32  # starts per map decided by the fast engine alone that MuJoCo re-runs anyway
ASSUMPTION = (
    "a start further than the band from every class change of the map has the same class on MuJoCo as on the "
    "fast engine (the two engines' disagreements sit at class changes; measured in the README's agreement table)"
)


@dataclass
class ScreenStats:
    """What the screening ran, per map summed: fast runs, MuJoCo runs (band, audit) and the disagreements."""

    fast: int = 0
    confirmed: int = 0  # MuJoCo runs of the band (and its growth)
    waves: int = 0
    changed: list[dict[str, Any]] = field(default_factory=list)  # band starts MuJoCo classed otherwise
    audited: int = 0
    audit_mismatches: list[dict[str, Any]] = field(default_factory=list)


class Screening:
    """``maps`` maps of one nx × nt grid (one per rig of a robust sweep), screened and confirmed.

    ``fast_job`` and ``mujoco_job`` run (map, start index) pairs (``twin.app.sweep.Job``); ``classify`` is
    the class that must agree (``verdict_class``). After ``run()``: ``records[m][k]`` each start's record
    (with ``engine``), ``stats``, ``complete``."""

    def __init__(
        self,
        nx: int,
        nt: int,
        maps: int,
        fast_job: Job,
        mujoco_job: Job,
        *,
        band: int = DEFAULT_BAND,
        audit: int = DEFAULT_AUDIT,
        seed: int = 0,
        progress: Progress | None = None,
        classify: Callable[[dict[str, Any]], Hashable] = verdict_class,
    ) -> None:
        if isinstance(band, bool) or not isinstance(band, int) or band < 1:
            raise ValueError(f"band = {band!r}: a whole number of grid steps ≥ 1")
        if isinstance(audit, bool) or not isinstance(audit, int) or audit < 0:
            raise ValueError(f"audit = {audit!r}: a whole number of starts ≥ 0")
        self.nx, self.nt, self.maps, self.band, self.audit, self.seed = nx, nt, maps, band, audit, seed
        self.fast_job, self.mujoco_job, self.progress, self.classify = (
            fast_job,
            mujoco_job,
            progress,
            classify,
        )
        self.fast: list[dict[int, dict[str, Any]]] = [{} for _ in range(maps)]
        self.mujoco: list[dict[int, dict[str, Any]]] = [{} for _ in range(maps)]
        self.stats = ScreenStats()
        self.complete = True

    # --- the runs ----------------------------------------------------------------------------------------
    def _run(self, job: Job, requests: list[tuple[int, int]], into: list[dict[int, dict[str, Any]]]) -> int:
        todo = sorted({(m, k) for m, k in requests if k not in into[m]})
        if not todo or not self.complete:
            return 0
        label = "the fast engine, every start" if job is self.fast_job else "MuJoCo near class changes"
        progress = self.progress

        def within(done: int, total: int, stage: str = "") -> None:
            if progress is not None:
                progress(done, total, label)

        records, done = job(todo, within if self.progress is not None else None)
        ran = 0
        for (m, k), r in zip(todo, records, strict=True):
            if r is not None:
                into[m][k] = r
                ran += 1
        self.complete = self.complete and done
        return ran

    # --- the maps ----------------------------------------------------------------------------------------
    def classes(self, m: int) -> np.ndarray:
        """Map m's classes now (nx, nt): MuJoCo's where it ran, the fast engine's elsewhere."""
        out = np.empty(self.nx * self.nt, dtype=object)
        for k in range(self.nx * self.nt):
            r = self.mujoco[m].get(k, self.fast[m].get(k))
            out[k] = None if r is None else self.classify(r)
        return out.reshape(self.nx, self.nt)

    def near_change(self, classes: np.ndarray) -> np.ndarray:
        """The starts within ``band`` steps (Chebyshev) of a start of another class: a boolean (nx, nt)."""
        nx, nt, b = self.nx, self.nt, self.band
        near = np.zeros((nx, nt), dtype=bool)
        for di in range(-b, b + 1):
            for dj in range(-b, b + 1):
                if di == dj == 0:
                    continue
                a = classes[max(0, -di) : nx - max(0, di), max(0, -dj) : nt - max(0, dj)]
                c = classes[max(0, di) : nx - max(0, -di), max(0, dj) : nt - max(0, -dj)]
                near[max(0, -di) : nx - max(0, di), max(0, -dj) : nt - max(0, dj)] |= a != c
        return near

    def run(self) -> None:
        every = [(m, k) for m in range(self.maps) for k in range(self.nx * self.nt)]
        self.stats.fast = self._run(self.fast_job, every, self.fast)
        while self.complete:  # the band, until MuJoCo decides every start near a class change
            wave = [
                (m, int(k))
                for m in range(self.maps)
                for k in np.flatnonzero(self.near_change(self.classes(m)).ravel())
                if int(k) not in self.mujoco[m]
            ]
            if not wave:
                break
            self.stats.confirmed += self._run(self.mujoco_job, wave, self.mujoco)
            self.stats.waves += 1
        for m in range(self.maps):
            for k in sorted(self.mujoco[m]):
                self._compare(m, k, self.stats.changed)
        if self.audit and self.complete:
            rng = np.random.default_rng(np.random.SeedSequence([self.seed, 0x53435245]))  # "SCRE"
            picks = []
            for m in range(self.maps):
                alone = [k for k in range(self.nx * self.nt) if k not in self.mujoco[m]]
                if alone:
                    chosen = rng.choice(alone, size=min(self.audit, len(alone)), replace=False)
                    picks += [(m, int(k)) for k in sorted(chosen.tolist())]
            before = [dict(d) for d in self.mujoco]
            self.stats.audited = self._run(self.mujoco_job, picks, self.mujoco)
            for m, k in picks:
                if k in self.mujoco[m] and k not in before[m]:
                    self._compare(m, k, self.stats.audit_mismatches)

    def _compare(self, m: int, k: int, into: list[dict[str, Any]]) -> None:
        fast, mujoco = self.classify(self.fast[m][k]), self.classify(self.mujoco[m][k])
        if fast != mujoco:
            i, j = divmod(k, self.nt)
            into.append({"map": m, "i": i, "j": j, "fast": fast, "mujoco": mujoco})

    def record(self, m: int, k: int) -> dict[str, Any] | None:
        """Start k of map m as decided: MuJoCo's record where it ran, else the fast engine's (labelled)."""
        if k in self.mujoco[m]:
            return {**self.mujoco[m][k], "engine": "mujoco"}
        if k in self.fast[m]:
            return {**self.fast[m][k], "engine": "fast"}
        return None

    def summary(self) -> dict[str, Any]:
        s, n = self.stats, self.maps * self.nx * self.nt
        decided = sum(len(d) for d in self.mujoco)
        return {
            "band_steps": self.band,
            "fast_runs": s.fast,
            "mujoco_runs": decided,
            "mujoco_band_runs": s.confirmed,
            "mujoco_fraction": round(decided / n, 4) if n else 0.0,
            "decided_by_fast": n - decided,
            "waves": s.waves,
            "band_disagreements": s.changed,
            "audit": {"checked": s.audited, "mismatches": s.audit_mismatches},
            "assumption": ASSUMPTION,
        }
