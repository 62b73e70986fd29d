"""Screen with the fast engine, confirm with MuJoCo: a map that is MuJoCo's map at a fraction of its cost.

The fast engine (``run_batch(plant="reference")``: the analytic plant in the compiled kernel under the twin's
full sensor chain, DAQ schedule, amplifier and laws) decides every start of every map. Where the two engines
could disagree, MuJoCo decides:

1. the **band**: every start within ``band`` grid steps (along either axis, diagonals included) of a start
   of another class is run on MuJoCo, and every start whose fast run is kept with an offset within its
   margin of its band (``near_offset_band``: a held/not-held verdict speckled by noise has no spatial boundary
   to find) or whose ball starts within its radius of a track end (``near_track_end``: the reference model has
   no wire ends);
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
from twin.rigs.backends import ENGINES

__all__ = [
    "ASSUMPTION",
    "DEFAULT_AUDIT",
    "DEFAULT_BAND",
    "ENGINE_NAMES",
    "Job",
    "ScreenStats",
    "Screening",
    "verdict_class",
]

ENGINE_NAMES = ENGINES  # --engine's words (twin.rigs.backends.engine_policy maps them onto backends)
# (map, start) pairs to run, and the wave's progress (runs done of these) → (records, complete).
Job = Callable[[list[tuple[int, int]], Progress | None], tuple[list[dict[str, Any] | None], bool]]


def verdict_class(record: dict[str, Any]) -> str:
    """What a map shows of a start: 'failed' (the controller), 'lost', 'held' or 'kept' (not held)."""
    if record.get("failed"):
        return "failed"
    if record["ball_lost"]:
        return "lost"
    return "held" if record["held"] else "kept"


DEFAULT_BAND = 1  # grid steps around a class change that MuJoCo decides
DEFAULT_AUDIT = 32  # starts per map decided by the fast engine alone that MuJoCo re-runs anyway
ASSUMPTION = (
    "a start further than the band from every class change of the map, whose offsets are further than their "
    "margins from their bands, has the same class on MuJoCo as on the fast engine (the two engines' "
    "disagreements sit at class changes and at marginal runs; measured in docs/validation/engines.md's agreement table)"
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
    the class that must agree (``verdict_class``); ``marginal``: the fast records MuJoCo decides wherever
    they are (``map_marginal``), described by ``marginal_text`` in the summary. After ``run()``:
    ``record(m, k)``, ``stats``, ``complete``."""

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
        marginal: Callable[[dict[str, Any]], bool] | None = None,
        marginal_text: str = "",
    ) -> None:
        if isinstance(band, bool) or not isinstance(band, int) or band < 1:
            raise ValueError(f"band = {band!r}: a whole number of grid steps ≥ 1")
        if isinstance(audit, bool) or not isinstance(audit, int) or audit < 0:
            raise ValueError(f"audit = {audit!r}: a whole number of starts ≥ 0")
        self.nx, self.nt, self.maps, self.band, self.audit, self.seed = nx, nt, maps, band, audit, seed
        self.fast_job, self.mujoco_job, self.progress = fast_job, mujoco_job, progress
        self.classify, self.marginal = classify, marginal
        self.marginal_text = marginal_text
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
        marginal = [
            {k for k, r in self.fast[m].items() if self.marginal is not None and self.marginal(r)}
            for m in range(self.maps)
        ]
        while self.complete:  # the band, until MuJoCo decides every start near a class change
            wave = [
                (m, k)
                for m in range(self.maps)
                for k in sorted(
                    set(np.flatnonzero(self.near_change(self.classes(m)).ravel()).tolist()) | marginal[m]
                )
                if k not in self.mujoco[m]
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
            self.stats.audited = self._run(self.mujoco_job, picks, self.mujoco)
            for m, k in picks:  # each drawn from the starts MuJoCo had not run
                if k in self.mujoco[m]:
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
            "confirmed": f"every start within {self.band} grid step(s) of a class change"
            + self.marginal_text,
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


# How far the fast engine's held metrics may sit from MuJoCo's: about twice the largest difference measured over
# 1000 rigs of docs/examples/spread.toml (appendix-sf from (−0.2 m, 0.3 rad), 10 s, noise on; docs/design.md):
# steady x 0.75 mm, steady θ 0.68 mrad, limit cycle x 3.2 mm and θ 11 mrad peak to peak.
HELD_MARGINS = {
    "steady_x_m": ("offset_band_m", 0.0015),
    "steady_theta_rad": ("offset_band_rad", 0.0015),
    "limit_cycle_x_pp_m": ("limit_cycle_band_m", 0.0065),
    "limit_cycle_theta_pp_rad": ("limit_cycle_band_rad", 0.022),
}


# The held metrics a map's screening also confirms by margin: the offsets, quasi-static and alike on both engines
# (every held/not-held miss of the spatial band seen was an offset within a millimetre of its band: one start of a
# 50-rig robust map); the limit cycles' disagreements sit at the map's class changes, where the band has them
# (both appendix maps screened equal brute force without them, while with them appendix-clp's beam limit cycle,
# tens of mrad near its 35 mrad band, sent 74 % of its map to MuJoCo).
OFFSETS = ("steady_x_m", "steady_theta_rad")


def near_held_band(
    record: dict[str, Any], criteria: Any = None, metrics: tuple[str, ...] = tuple(HELD_MARGINS)
) -> bool:
    """Whether a run kept on the track could be classed the other way on MuJoCo by one of ``metrics``: held with
    one of them within ``HELD_MARGINS`` of its band, or not held with every failing metric one of them and
    within its margin beyond its band (``twin.verdict.Criteria``: held is every metric within its band)."""
    from twin.verdict import Criteria

    if record.get("failed") or record.get("ball_lost"):
        return False
    c = criteria or Criteria()
    values = {
        metric: (abs(v), getattr(c, band), margin)
        for metric, (band, margin) in HELD_MARGINS.items()
        if (v := record.get(metric)) is not None
    }
    if record["held"]:
        return any(v > b - d for m, (v, b, d) in values.items() if m in metrics)
    failing = {m: (v, b, d) for m, (v, b, d) in values.items() if v > b}
    return bool(failing) and all(m in metrics and v <= b + d for m, (v, b, d) in failing.items())


def near_offset_band(record: dict[str, Any]) -> bool:
    """``near_held_band`` by the offsets alone: the marginal runs a map's screening gives MuJoCo."""
    return near_held_band(record, metrics=OFFSETS)


def near_track_end(record: dict[str, Any], params: Any) -> bool:
    """Whether a run starts with its ball within one ball radius of a track end: there the twin's ball rests on
    the wires' rounded ends, which the reference model does not have (a 50-rig robust map's only disagreement
    with brute force: a ball 3 mm from the end, lost at 0.04 s on MuJoCo, held on the fast engine)."""
    return abs(record["x0_m"]) > params.track.half_length_m - params.ball.radius_m


# What ``map_marginal`` confirms, in a screening's summary.
MAP_MARGINAL = (
    "; every start kept with an offset within its margin of its band or with its ball within its radius of a "
    "track end"
)


def map_marginal(params: Any) -> Callable[[dict[str, Any]], bool]:
    """The runs a map's screening gives MuJoCo wherever they are (``MAP_MARGINAL``)."""
    return lambda record: near_offset_band(record) or near_track_end(record, params)


def near_class_change(record: dict[str, Any], criteria: Any = None) -> bool:
    """Whether MuJoCo must decide a run of a list: the fast engine did not hold it, or held it within
    ``HELD_MARGINS`` of a band."""
    return verdict_class(record) != "held" or near_held_band(record, criteria)


# A job over a list of runs: run these indices → (records, complete).
ListJob = Callable[[list[int]], tuple[list[dict[str, Any] | None], bool]]


def confirm_list(
    fast: list[dict[str, Any] | None],
    mujoco_job: ListJob,
    *,
    confirm: list[int],
    audit: int,
    seed: int,
    classify: Callable[[dict[str, Any]], Hashable] = verdict_class,
) -> tuple[list[dict[str, Any] | None], dict[str, Any], bool]:
    """Runs without a grid (a Monte Carlo): the fast engine's records, MuJoCo's for the runs ``confirm`` names
    (``near_class_change``) and for ``audit`` others drawn at random (seeded). Returns the
    records as decided (each naming its engine), the summary (as ``Screening.summary``'s) and whether every
    run finished."""
    rest = [i for i, r in enumerate(fast) if r is not None and i not in set(confirm)]
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x53435245]))  # "SCRE"
    picks = (
        sorted(rng.choice(rest, size=min(audit, len(rest)), replace=False).tolist()) if rest and audit else []
    )
    todo = sorted(set(confirm) | set(picks))
    records, complete = mujoco_job(todo) if todo else ([], True)
    by_run = dict(zip(todo, records, strict=True))
    out: list[dict[str, Any] | None] = [None if r is None else {**r, "engine": "fast"} for r in fast]
    changed: list[dict[str, Any]] = []
    mismatches: list[dict[str, Any]] = []
    for i, r in by_run.items():
        if r is None:
            continue
        f = fast[i]
        if f is not None and classify(f) != classify(r):
            (mismatches if i in picks else changed).append(
                {"run": i, "fast": classify(f), "mujoco": classify(r)}
            )
        out[i] = {**r, "engine": "mujoco"}  # a run MuJoCo made is MuJoCo's
    decided = sum(1 for r in out if r is not None and r["engine"] == "mujoco")
    summary = {
        "fast_runs": sum(r is not None for r in fast),
        "mujoco_runs": decided,
        "mujoco_fraction": round(decided / len(fast), 4) if fast else 0.0,
        "decided_by_fast": len(fast) - decided,
        "confirmed": "every run the fast engine did not hold, or held with a metric within its margin of its band",
        "margins": {metric: margin for metric, (_, margin) in HELD_MARGINS.items()},
        "band_disagreements": changed,
        "audit": {"checked": len([i for i in picks if by_run.get(i) is not None]), "mismatches": mismatches},
        "assumption": "a run the fast engine holds with every held metric further than its margin from its band "
        "is held on MuJoCo too (the audit tests it)",
    }
    return out, summary, complete


def render_agreement(data: dict[str, Any]) -> str:
    """The agreement table of docs/validation/engines.md from ``scripts/screen_agreement.py``'s JSON (markdown)."""
    lines = [
        "| controller | start | noise | max Δx (mm) | RMS Δx (mm) | max Δθ (mrad) | RMS Δθ (mrad) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in data["trajectories"]:
        lines.append(
            f"| {r['controller']} | {r['start']} | {'on' if r['noise'] else 'off'} | {r['max_dx_mm']:.2f} | "
            f"{r['rms_dx_mm']:.2f} | {r['max_dtheta_mrad']:.2f} | {r['rms_dtheta_mrad']:.2f} |"
        )
    lines += [
        "",
        "| 41 × 41 map | noise | fast engine agrees | its disagreements (grid steps from a class change: "
        "starts) | screened = brute force | MuJoCo runs | audit differs | brute force | fast | screened |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for m in data["maps"]:
        where = (
            ", ".join(f"{d}: {k}" for d, k in m["disagreements_steps_from_a_class_change"].items()) or "none"
        )
        lines.append(
            f"| {m['controller']} | {'on' if m['noise'] else 'off'} | {m['fast_agrees']} of {m['starts']} "
            f"({100 * m['fast_agrees_share']:.1f} %) | {where} | {m['screened_equals_brute_force']} of "
            f"{m['starts']} | {m['screened_mujoco_runs']} | {m['screened_audit_mismatches']} | "
            f"{m['brute_force_s']:.1f} s | {m['fast_s']:.1f} s | {m['screened_s']:.1f} s "
            f"({m['screened_over_brute_force']:.2f}×) |"
        )
    return "\n".join(lines) + "\n"
