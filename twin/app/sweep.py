"""Region of attraction: one controller over a grid of initial states, each point judged by the engine's
verdict, and the thesis's chapter 7 region claims checked against the map.

``run_sweep`` runs the grid through the batch engine in chunks (``twin.app.fanout``: this process, local
processes or a Dask cluster). Every point has its own noise seed derived from (seed, point index), so the
result does not depend on how the grid is chunked or where a chunk runs: a sweep is bit-identical locally,
with workers and on a cluster. Ctrl-C stops the sweep and keeps the points already done (the result says
it is incomplete).

``twin.app.sweep_render.write_sweep`` writes ``sweep.json`` (one record per point: ``x0_m``, ``theta0_rad``,
``seed`` and every field of the verdict; the claims; the settings) and ``map.png`` into a directory,
atomically. Nothing here imports matplotlib or the renderer: the renderer imports this module.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Hashable, Sequence
from dataclasses import asdict, dataclass, field, replace
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np

from controllers import thesis_numbers as T
from twin.app.fanout import Progress, Runs, Served, run_starts
from twin.app.options import MAX_LOCATE
from twin.app.screening import ENGINE_NAMES, MAP_MARGINAL, Job, Screening, map_marginal, verdict_class
from twin.outputs import JobFiles
from twin.parameters import ParameterError, Parameters
from twin.physics import beam_travel_rad, check_initial_state
from twin.rigs.backends import DEFAULT_PLANT, ScreeningPolicy, backend, engine_policy

if TYPE_CHECKING:
    from twin.requirements import Requirement

__all__ = [
    "CLAIMS",
    "OUTPUT_FILES",
    "Grid",
    "RegionClaim",
    "SweepResult",
    "SweepSettings",
    "parse_range",
    "point_seeds",
    "rig_grids",
    "run_sweep",
]


@dataclass(frozen=True)
class Grid:
    """A closed range ``lo … hi`` in ``n`` points (``n`` = 1: just ``lo``)."""

    lo: float
    hi: float
    n: int

    def values(self) -> np.ndarray:
        return np.linspace(self.lo, self.hi, self.n) if self.n > 1 else np.array([self.lo])


# What write_sweep (twin.app.sweep_render) puts into its folder (checked before the sweep runs).
OUTPUT_FILES = JobFiles("sweep", ("sweep.json", "map.png"))
# The thesis's chapter 7 grid: the whole track (|x| ≤ 0.323 m) and nearly the whole stroke (|θ| ≤ 43.4°).
DEFAULT_X0 = Grid(-0.32, 0.32, 41)
DEFAULT_THETA0 = Grid(-0.7, 0.7, 41)
MAX_POINTS = 250_000  # a grid beyond this is a typing error, not a study (about 3 h per 10 s runs here)


def rig_box(params: Parameters) -> tuple[tuple[float, float], tuple[float, float]]:
    """The starts a rig of other parts is mapped and validated over (one home: ``rig_grids`` and validate's
    ``default_criteria``): its whole track less the ball's radius, ±(``track.half_length_m`` − ``ball.radius_m``:
    where the track ends in a holder, the ball's centre stops a radius short of it), by its beam's travel
    (``twin.physics.beam_travel_rad``: its stops narrowed to its drive's reach, which a lever makes lopsided)."""
    half = params.track.half_length_m - params.ball.radius_m
    return (-half, half), beam_travel_rad(params)


def rig_grids(params: Parameters, n: int = 41) -> tuple[Grid, Grid]:
    """A map's axes on the rig ``params`` when none are given: the chapter 7 grid (``DEFAULT_X0``,
    ``DEFAULT_THETA0``) where it lies on the rig (the thesis's), else ``n`` starts over ``rig_box`` each way."""
    (x_lo, x_hi), (low, high) = rig_box(params)
    on_track = params.track.half_length_m >= DEFAULT_X0.hi  # the thesis's range: to 3 mm of its wires' ends
    if on_track and low <= -DEFAULT_THETA0.hi and DEFAULT_THETA0.hi <= high:
        return DEFAULT_X0, DEFAULT_THETA0
    return Grid(x_lo, x_hi, n), Grid(low, high, n)


def parse_range(option: str, text: str) -> Grid:
    """``LO:HI:N`` (N ≥ 1 points, LO ≤ HI) or a single value."""
    parts = text.split(":")
    try:
        if len(parts) == 1:
            value = float(parts[0])
            grid = Grid(value, value, 1)
        elif len(parts) == 3:
            grid = Grid(float(parts[0]), float(parts[1]), int(parts[2]))
        else:
            raise ValueError
    except ValueError:
        raise ParameterError(f"{option} {text!r}: expected LO:HI:N (e.g. -0.3:0.3:31) or one value") from None
    if not (math.isfinite(grid.lo) and math.isfinite(grid.hi)) or grid.lo > grid.hi or grid.n < 1:
        raise ParameterError(f"{option} {text!r}: LO and HI finite with LO ≤ HI, and N ≥ 1")
    return grid


def point_seeds(seed: int, n: int) -> np.ndarray:
    """The noise seed of each point: a function of (seed, point index) only, so that any chunking of the
    grid, on any machine, gives every point the same seed."""
    return np.array(
        [int(np.random.SeedSequence([seed, i]).generate_state(1, dtype=np.uint32)[0]) for i in range(n)],
        dtype=np.int64,
    )


@dataclass(frozen=True)
class RegionClaim:
    """A chapter 7 statement that the ball stays on the beam for every start in a rectangle of initial
    states, with the two corner states the thesis simulated (its figures)."""

    family: str  # the controllers it is about
    source: str
    x0_m: tuple[float, float]
    theta0_rad: tuple[float, float]
    corners: tuple[tuple[float, float], ...]
    applies_to: tuple[str, ...]


def _claim(
    family: str, source: str, corners: tuple[tuple[float, float], ...], names: tuple[str, ...]
) -> RegionClaim:
    (x_lo, th_lo), (x_hi, th_hi) = corners
    return RegionClaim(family, source, (x_lo, x_hi), (th_lo, th_hi), corners, names)


CLAIMS = (
    _claim(
        "state feedback with observer (discrete)",
        "chapter 7, Discrete Time Controllers; Figures 7.8–7.13",
        T.SF_DISC_RANGE,
        ("thesis-sf", "appendix-sf", "sf"),
    ),
    _claim(
        "control law partitioning with observer (discrete)",
        "chapter 7, Discrete Time Controllers; Figures 7.14–7.19 (the figures start at −0.26 m)",
        T.CLP_DISC_RANGE,
        ("thesis-clp", "appendix-clp", "clp"),
    ),
)


@dataclass(frozen=True)
class SweepSettings:
    """Everything a sweep's result depends on (written into its JSON)."""

    controller: str
    x0: Grid = DEFAULT_X0
    theta0: Grid = DEFAULT_THETA0
    duration_s: float = 10.0
    noise: bool = True
    plant: str = DEFAULT_PLANT
    ideal_sensors: bool = False
    seed: int = 0
    refine: int = 0  # boundary refinement: the coarse grid's step in grid intervals (0: every start is run)
    audit: int = 0  # with refine: inferred starts run anyway, at random, to check the assumption
    locate: int = 0  # bisections of every grid edge the boundary crosses (0: the boundary to a grid step)
    # Who decides each start (twin.app.screening): "screen" (the fast engine, MuJoCo near every class change and
    # on an audit sample), "fast" (the fast engine alone) or "mujoco" (MuJoCo alone). The twin plant only.
    engine: str = "mujoco"
    band: int = 1  # screen: grid steps around a class change that MuJoCo decides
    screen_audit: int = 32  # screen: starts decided by the fast engine alone that MuJoCo runs anyway

    def starts(self) -> np.ndarray:
        """The grid's starts (n, 2: x0, θ0), x0 by x0 and θ0 within: start k is (k // nt, k % nt)."""
        xs, ths = self.x0.values(), self.theta0.values()
        return np.array([(x, th) for x in xs for th in ths], dtype=float)

    def runs(self, params: Parameters, *, fast: bool | None = None) -> Runs:
        """The job every start of this sweep is a run of (``fanout.Runs``), on the rig of ``params``; ``fast``:
        on the fast engine (the reference plant compiled, the twin's sensor chain) rather than MuJoCo
        (default: as ``engine`` says when it names one engine)."""
        if fast is None:
            plant = self.policy.decider
        else:  # the plant's stand-in, or the plant
            plant = (backend(self.plant).stand_in or self.plant) if fast else self.plant
        return Runs(
            controller=self.controller,
            params=params,
            duration_s=self.duration_s,
            noise=self.noise,
            plant=plant,
            ideal_sensors=self.ideal_sensors,
        )

    @property
    def screened(self) -> bool:
        """Whether the fast engine screens and MuJoCo confirms (``twin.app.screening``)."""
        return self.policy.screened

    @property
    def policy(self) -> ScreeningPolicy:
        """``engine`` for ``plant`` as the backends' policy (a plant no backend stands in for runs alone)."""
        return engine_policy(self.engine, self.plant, strict=False)

    def engine_label(self) -> str:
        """What decided a start run as asked: "mujoco", "fast" or the plant asked for (``twin.rigs.backends``)."""
        return self.policy.decider_label()


@dataclass
class SweepResult:
    settings: SweepSettings
    points: list[dict[str, Any]]  # in grid order (x0 outer, θ0 inner); None-free only when complete
    complete: bool
    corners: list[dict[str, Any]] = field(default_factory=list)  # the claims' named starts
    claims: list[dict[str, Any]] = field(default_factory=list)
    wall_s: float = 0.0
    served: dict[str, Any] | None = None  # a served job: where, and the clients (fanout.Served.to_json)
    refinement: dict[str, Any] | None = None  # what --refine ran, inferred and audited
    boundary: dict[str, Any] | None = None  # --locate: each boundary crossing to a fraction of a grid step
    screening: dict[str, Any] | None = None  # --engine screen: what each engine ran, the audit

    def to_json(self) -> dict[str, Any]:
        s = self.settings
        return {
            "settings": {**asdict(s), "x0": asdict(s.x0), "theta0": asdict(s.theta0)},
            **({"served": self.served} if self.served is not None else {}),
            **({"refinement": self.refinement} if self.refinement is not None else {}),
            **({"boundary": self.boundary} if self.boundary is not None else {}),
            **({"screening": self.screening} if self.screening is not None else {}),
            "complete": self.complete,
            "summary": summarize(self.points),
            "claims": self.claims,
            "corners": self.corners,
            "points": self.points,
        }


def summarize(points: Sequence[dict[str, Any]]) -> dict[str, int]:
    done = [p for p in points if p]
    inferred = sum(bool(p.get("inferred")) for p in done)  # --refine: from a cell's agreeing corners
    return {
        "points": len(points),
        "done": len(done),
        "held": sum(bool(p["held"]) for p in done),
        "lost": sum(bool(p["ball_lost"]) for p in done),
        "not_held": sum(not p["held"] and not p["ball_lost"] for p in done),
        "failed": sum(bool(p.get("failed")) for p in done),  # the controller raised or gave no command
        **({"inferred": inferred} if inferred else {}),
    }


def run_sweep(
    settings: SweepSettings,
    params: Parameters | None = None,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    nthread: int | None = None,
    progress: Progress | None = None,
    serve: Served | None = None,
    requirements: tuple[Requirement, ...] = (),
) -> SweepResult:
    """Run the grid (and the claims' corner states) and judge the claims; ``requirements``: each point's record
    gains their robustness. ``workers`` local processes
    (1: this process), or a Dask ``scheduler`` address; ``nthread``: rollout threads per batch (default:
    the cores, divided among the local workers); ``serve``: every start a session to a client over the
    wire (``fanout.run_served``; ``settings.controller`` names what the client runs)."""
    p = params or Parameters()
    grid = settings.starts()
    if len(grid) > MAX_POINTS:
        raise ParameterError(f"the grid has {len(grid)} points; at most {MAX_POINTS}")
    for x, th in (
        (grid[:, 0].min(), 0.0),
        (grid[:, 0].max(), 0.0),
        (0.0, grid[:, 1].min()),
        (0.0, grid[:, 1].max()),
    ):
        try:
            check_initial_state(p, float(x), float(th), 0.0, 0.0)
        except ValueError as exc:
            raise ParameterError(f"the grid leaves the rig: {exc}") from None
    corners = _corner_starts(settings.controller, p)
    starts = np.vstack([grid, np.array([c[:2] for c in corners], dtype=float).reshape(-1, 2)])
    seeds = point_seeds(settings.seed, len(starts))
    if serve is not None and (settings.refine or settings.locate):
        raise ParameterError("--refine and --locate run here or on workers, not as served sessions")
    if not 0 <= settings.locate <= MAX_LOCATE:
        raise ParameterError(f"--locate {settings.locate}: at most {MAX_LOCATE} bisections of a grid step")
    if settings.engine not in ENGINE_NAMES:
        raise ParameterError(f"--engine {settings.engine!r}: one of {', '.join(ENGINE_NAMES)}")
    if settings.screened and (serve is not None or settings.refine):
        raise ParameterError(
            "--engine screen runs here or on workers, without --refine: give --engine mujoco (or fast) with "
            "--serve or --refine"
        )

    def batch_of(fast: bool | None) -> Batch:
        runs = replace(settings.runs(p, fast=fast), requirements=requirements)
        label = settings.policy.label(runs.plant)

        def run_batch(
            batch: np.ndarray, batch_seeds: np.ndarray, progress: Progress | None = None
        ) -> tuple[list[dict[str, Any] | None], bool]:
            records, complete = run_starts(
                runs,
                batch,
                batch_seeds,
                workers=workers,
                scheduler=scheduler,
                nthread=nthread,
                progress=progress,
                serve=serve,  # None with --refine or --locate (refused above)
            )
            return [None if r is None else {**r, "engine": label} for r in records], complete

        return run_batch

    run_batch = batch_of(False if settings.screened else None)  # the screen's confirmations are MuJoCo's
    if settings.screened:
        result = _screened_sweep(
            settings, p, grid, starts, seeds, corners, run_batch, batch_of(True), progress
        )
    elif settings.refine:
        result = _refined_sweep(settings, p, grid, starts, seeds, corners, run_batch, progress)
    else:
        result = _brute_sweep(settings, p, grid, starts, seeds, corners, run_batch, progress)
        result.served = serve.to_json() if serve is not None else None
    if settings.locate and result.complete:
        start = time.perf_counter()
        result.boundary, result.complete = locate_boundary(settings, grid, result.points, run_batch)
        result.wall_s += time.perf_counter() - start
    return result


def _brute_sweep(
    settings: SweepSettings,
    p: Parameters,
    grid: np.ndarray,
    starts: np.ndarray,
    seeds: np.ndarray,
    corners: list[tuple[float, float, str, str]],
    run_batch: Batch,
    progress: Progress | None,
) -> SweepResult:
    """Every start of the grid run, and the claims' corner states."""
    start = time.perf_counter()
    results, complete = run_batch(starts, seeds, progress)
    points = [r or {} for r in results[: len(grid)]]
    corner_records = [
        {**(results[len(grid) + i] or {}), "claim": claim, "note": note}
        for i, (_, _, claim, note) in enumerate(corners)
    ]
    result = SweepResult(settings, points, complete, corner_records, wall_s=time.perf_counter() - start)
    result.claims = [_judge(claim, result, p) for claim in CLAIMS if settings.controller in claim.applies_to]
    return result


def _screened_sweep(
    settings: SweepSettings,
    p: Parameters,
    grid: np.ndarray,
    starts: np.ndarray,
    seeds: np.ndarray,
    corners: list[tuple[float, float, str, str]],
    run_mujoco: Batch,
    run_fast: Batch,
    progress: Progress | None,
) -> SweepResult:
    """Every start on the fast engine; MuJoCo near every class change and on an audit sample
    (``twin.app.screening.Screening``); the claims' corner states on MuJoCo. Each start has its brute-force
    seed, so a start MuJoCo ran has its brute-force record."""
    nx, nt = settings.x0.n, settings.theta0.n
    start = time.perf_counter()

    def job(run: Batch) -> Job:
        def run_job(
            requests: list[tuple[int, int]], within: Progress | None
        ) -> tuple[list[dict[str, Any] | None], bool]:
            todo = [k for _, k in requests]
            return run(starts[todo], seeds[todo], within)

        return run_job

    screen = Screening(
        nx, nt, 1, job(run_fast), job(run_mujoco), band=settings.band, audit=settings.screen_audit,
        seed=settings.seed, progress=progress, marginal=map_marginal(p), marginal_text=MAP_MARGINAL,
    )  # fmt: skip
    screen.run()
    points = [screen.record(0, k) or {} for k in range(nx * nt)]
    corner_records, complete = _corner_runs(run_mujoco, starts, seeds, nx * nt, corners, screen.complete)
    result = SweepResult(
        settings, points, complete and all(points), corner_records, wall_s=time.perf_counter() - start
    )
    result.screening = screen.summary()
    result.claims = [_judge(claim, result, p) for claim in CLAIMS if settings.controller in claim.applies_to]
    return result


def _corner_runs(
    run: Batch,
    starts: np.ndarray,
    seeds: np.ndarray,
    first: int,
    corners: list[tuple[float, float, str, str]],
    complete: bool,
) -> tuple[list[dict[str, Any]], bool]:
    """The claims' corner states (``starts[first:]``) once the grid is complete: their records, and whether
    every run finished."""
    idx = list(range(first, len(starts)))
    if not idx or not complete:
        return [], complete
    records, done = run(starts[idx], seeds[idx], None)
    return [
        {**(r or {}), "claim": claim, "note": note}
        for r, (_, _, claim, note) in zip(records, corners, strict=True)
    ], done


def _inferred(
    x0_m: float, theta0_rad: float, seed: int, cls: str, box: tuple[int, int, int, int]
) -> dict[str, Any]:
    """The record of a start --refine did not run: its class from the agreeing run starts around its region
    of starts not run (``box``: the region's bounding box)."""
    from dataclasses import fields

    from twin.verdict import Verdict

    i0, i1, j0, j1 = box
    return {
        "x0_m": x0_m,
        "theta0_rad": theta0_rad,
        "seed": seed,
        "failed": False,
        **{f.name: None for f in fields(Verdict)},
        "held": cls == "held",
        "ball_lost": cls == "lost",
        "hit_stops": None,
        "inferred": True,
        "reason": f"inferred ({cls}): every start run around its region (within x0[{i0}:{i1}] × θ0[{j0}:{j1}]) "
        f"is {cls}",
    }


# What --refine assumes, in the JSON and the README.
ASSUMPTION = (
    "every boundary between two classes crosses a coarse-grid line between coarse starts of different classes "
    "(no island or inlet of another class slips between coarse starts)"
)
Box = tuple[int, int, int, int]  # i0, i1, j0, j1: grid indices, inclusive
Point = tuple[int, int]  # (i, j): x0 index, θ0 index
# Runs of these starts with these seeds → (records, complete): fanout.run_starts on the sweep's job.
Batch = Callable[[np.ndarray, np.ndarray, Progress | None], tuple[list[dict[str, Any] | None], bool]]


class Refinement:
    """Boundary refinement of ``maps`` maps of one nx × nt grid at once (one map per rig of a robust sweep),
    by tracing each boundary at the grid's resolution:

    1. the coarse grid: every ``step``-th start along each axis, and the last;
    2. each coarse line's segments between coarse starts of different classes are bisected down to the two
       neighbouring starts where the class changes;
    3. from there the boundary is followed cell by cell (a cell: four neighbouring starts): a cell whose
       corners disagree is crossed by a boundary, which leaves it through each edge whose two ends disagree,
       so the cell across that edge is run next;
    4. every start not run lies in a region of starts not run whose neighbours were all run: it takes their
       class when they agree; where they do not (a boundary the trace missed), the region's rim is traced
       too, until every region's neighbours agree.

    Each wave of runs, all maps' together, is one job (``run_job((map, index) pairs, progress) → (records,
    complete)``), so the batches stay large; ``progress`` is told the runs known, also within a wave.
    ``known[m]``: the records run; ``claims[m]``: the inferred starts' (class, the bounding box of their
    region). ``classify``: the class that must agree (``verdict_class``). The assumption: every boundary
    crosses a coarse line between coarse starts of different classes (no island or inlet of another class
    that slips between coarse starts)."""

    def __init__(
        self,
        nx: int,
        nt: int,
        step: int,
        maps: int,
        run_job: Job,
        progress: Progress | None = None,
        classify: Callable[[dict[str, Any]], Hashable] = verdict_class,
    ) -> None:
        self.nx, self.nt, self.step, self.maps = nx, nt, step, maps
        self.run_job, self.progress, self.classify = run_job, progress, classify
        self.known: list[dict[int, dict[str, Any]]] = [{} for _ in range(maps)]
        self.claims: list[dict[int, tuple[Any, Box]]] = [{} for _ in range(maps)]
        self.complete = True
        self.ran = self.waves = self.rim_runs = 0

    def run(self, requests: list[tuple[int, int]]) -> None:
        todo = sorted({(m, k) for m, k in requests if k not in self.known[m]})
        if not todo or not self.complete:
            return
        progress, before, runs = self.progress, sum(map(len, self.known)), self.maps * self.nx * self.nt

        def within(done: int, total: int, stage: str = "") -> None:
            if progress is not None:
                progress(before + done, runs)

        records, done = self.run_job(todo, within if progress is not None else None)
        for (m, k), r in zip(todo, records, strict=True):
            if r is not None:
                self.known[m][k] = r
        self.ran += len(todo)
        self.waves += 1
        self.complete = self.complete and done
        if self.progress is not None:
            self.progress(sum(map(len, self.known)), self.maps * self.nx * self.nt)

    def _at(self, p: Point) -> int:
        return p[0] * self.nt + p[1]

    def _class(self, m: int, p: Point) -> Hashable:
        return self.classify(self.known[m][self._at(p)])

    @staticmethod
    def _corners(cell: Point) -> tuple[Point, Point, Point, Point]:
        i, j = cell
        return (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)

    def _cells_of_edge(self, p: Point, q: Point) -> list[Point]:
        """The (one or two) cells that share the edge between neighbouring starts p and q."""
        (i0, j0), (i1, j1) = sorted((p, q))
        if i0 == i1:  # an edge along θ0
            return [(i, j0) for i in (i0 - 1, i0) if 0 <= i < self.nx - 1]
        return [(i0, j) for j in (j0 - 1, j0) if 0 <= j < self.nt - 1]

    def refine(self) -> None:
        def lines(n: int) -> list[int]:
            return sorted(set(range(0, n, self.step)) | {n - 1})

        xi, tj = lines(self.nx), lines(self.nt)
        maps = range(self.maps)
        self.run([(m, self._at((i, j))) for m in maps for i in xi for j in tj])
        segments = [(m, (a, j), (b, j)) for m in maps for j in tj for a, b in itertools.pairwise(xi)]
        segments += [(m, (i, a), (i, b)) for m in maps for i in xi for a, b in itertools.pairwise(tj)]
        edges: list[tuple[int, Point, Point]] = []
        while segments and self.complete:  # bisection along the coarse lines
            halves, middles = [], []
            for m, p, q in segments:
                if self._class(m, p) == self._class(m, q):
                    continue
                if abs(q[0] - p[0]) + abs(q[1] - p[1]) == 1:
                    edges.append((m, p, q))
                    continue
                mid = ((p[0] + q[0]) // 2, (p[1] + q[1]) // 2)
                middles.append((m, self._at(mid)))
                halves += [(m, p, mid), (m, mid, q)]
            self.run(middles)
            segments = halves
        seen: list[set[Point]] = [set() for _ in maps]
        self._trace([(m, c) for m, p, q in edges for c in self._cells_of_edge(p, q)], seen)
        for m in maps:
            while self.complete:
                rims = self._infer(m)
                if not rims:
                    break
                before = self.ran
                self._trace([(m, c) for c in rims], seen)
                self.rim_runs += self.ran - before
                if self.ran == before:  # nothing left to run (cannot happen: a rim cell has a corner not run)
                    break

    def _trace(self, start: list[tuple[int, Point]], seen: list[set[Point]]) -> None:
        """Follow the boundaries from these cells: run a wave's corners, then the cells across each edge
        of a disagreeing cell whose ends disagree."""
        wave: list[tuple[int, Point]] = []

        def push(m: int, cells: list[Point]) -> None:
            for c in cells:
                if c not in seen[m]:
                    seen[m].add(c)
                    wave.append((m, c))

        for m, c in start:
            push(m, [c])
        while wave and self.complete:
            cells, wave = wave, []
            self.run([(m, self._at(p)) for m, c in cells for p in self._corners(c)])
            if not self.complete:
                return
            for m, c in cells:
                a, b, d, e = self._corners(c)  # (i, j), (i+1, j), (i, j+1), (i+1, j+1)
                for p, q in ((a, b), (d, e), (a, d), (b, e)):
                    if self._class(m, p) != self._class(m, q):
                        push(m, self._cells_of_edge(p, q))

    def _infer(self, m: int) -> list[Point]:
        """Claim each region of starts not run (4-neighbours) whose run neighbours agree; return the rim
        cells of the regions whose neighbours disagree (none: every start is run or claimed)."""
        known, nx, nt = self.known[m], self.nx, self.nt
        region_of: dict[int, int] = {}
        claims: dict[int, tuple[Any, Box]] = {}
        rims: list[Point] = []
        for first in range(nx * nt):
            if first in known or first in region_of:
                continue
            region_of[first] = first
            members, frontier, around = [first], [first], set()
            while frontier:
                k = frontier.pop()
                i, j = divmod(k, nt)
                for a, b in ((i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)):
                    if 0 <= a < nx and 0 <= b < nt:
                        v = a * nt + b
                        if v in known:
                            around.add(v)
                        elif v not in region_of:
                            region_of[v] = first
                            members.append(v)
                            frontier.append(v)
            classes = {self.classify(known[v]) for v in around}
            if len(classes) == 1:
                cls = classes.pop()
                ii, jj = [k // nt for k in members], [k % nt for k in members]
                box = (min(ii), max(ii), min(jj), max(jj))
                claims.update((k, (cls, box)) for k in members)
            else:  # a boundary runs through the region: trace from its rim
                inside = set(members)
                for k in members:
                    i, j = divmod(k, nt)
                    for c in ((i - 1, j - 1), (i, j - 1), (i - 1, j), (i, j)):
                        if 0 <= c[0] < nx - 1 and 0 <= c[1] < nt - 1:
                            if any(self._at(p) not in inside for p in self._corners(c)):
                                rims.append(c)
        if not rims:
            self.claims[m] = claims
        return rims


def _refined_sweep(
    settings: SweepSettings,
    p: Parameters,
    grid: np.ndarray,
    starts: np.ndarray,
    seeds: np.ndarray,
    corners: list[tuple[float, float, str, str]],
    run_batch: Batch,
    progress: Progress | None,
) -> SweepResult:
    """Boundary refinement (``Refinement``: the coarse grid, bisection along its lines, each boundary
    traced cell by cell); every start not run takes the class of the run starts around its region
    (``_inferred``). Each start that runs has its brute-force seed, so its record is the brute-force record.
    The assumption: ``ASSUMPTION``. ``settings.audit`` inferred starts (seeded) are run anyway and
    compared."""
    nx, nt = settings.x0.n, settings.theta0.n
    step = settings.refine
    if isinstance(step, bool) or not isinstance(step, int) or step < 2:
        raise ParameterError(f"--refine {step!r}: the coarse step, a whole number of grid intervals ≥ 2")
    start = time.perf_counter()

    def run_job(
        requests: list[tuple[int, int]], within: Progress | None
    ) -> tuple[list[dict[str, Any] | None], bool]:
        todo = [k for _, k in requests]
        return run_batch(starts[todo], seeds[todo], within)

    ref = Refinement(nx, nt, step, 1, run_job, progress)
    ref.refine()
    known, claims, complete = ref.known[0], ref.claims[0], ref.complete

    def run(indices: list[int]) -> None:
        ref.run([(0, k) for k in indices])

    inferred = [k for k in claims if k not in known]
    audit: dict[str, Any] = {"checked": 0, "mismatches": []}
    if settings.audit and inferred and complete:
        rng = np.random.default_rng(np.random.SeedSequence([settings.seed, 0x415544]))  # "AUD"
        picks = sorted(rng.choice(inferred, size=min(settings.audit, len(inferred)), replace=False).tolist())
        before = dict(known)
        run(picks)
        complete = ref.complete
        for k in picks:
            if k in known and k not in before:
                audit["checked"] += 1
                got = verdict_class(known[k])
                if got != claims[k][0]:
                    audit["mismatches"].append(
                        {
                            "x0_m": float(grid[k, 0]),
                            "theta0_rad": float(grid[k, 1]),
                            "inferred": claims[k][0],
                            "run": got,
                        }
                    )
    points: list[dict[str, Any]] = []
    for k in range(nx * nt):
        if k in known:
            points.append(known[k])
        elif k in claims:
            cls, cell = claims[k]
            points.append(_inferred(float(grid[k, 0]), float(grid[k, 1]), int(seeds[k]), cls, cell))
        else:
            points.append({})
    corner_records, complete = _corner_runs(run_batch, starts, seeds, nx * nt, corners, complete)
    result = SweepResult(
        settings, points, complete and all(points), corner_records, wall_s=time.perf_counter() - start
    )
    result.refinement = {
        "coarse_step": step,
        "waves": ref.waves,
        "run": ref.ran,
        "inferred": sum(bool(q.get("inferred")) for q in points),
        "run_fraction": round(ref.ran / (nx * nt), 4),
        "rim_run": ref.rim_runs,
        "audit": audit,
        "assumption": ASSUMPTION,
    }
    result.claims = [_judge(claim, result, p) for claim in CLAIMS if settings.controller in claim.applies_to]
    return result


# --- the boundary to a fraction of a grid step (--locate) ------------------------------------------------


def boundary_edges(points: Sequence[dict[str, Any]], nx: int, nt: int) -> list[tuple[int, int]]:
    """The grid edges a boundary crosses: neighbouring starts (k, k + nt along x0; k, k + 1 along θ0) of
    different classes (``verdict_class``), in start order."""
    classes = [verdict_class(q) if q else None for q in points]
    edges = []
    for k in range(nx * nt):
        i, j = divmod(k, nt)
        for n in ([k + nt] if i + 1 < nx else []) + ([k + 1] if j + 1 < nt else []):
            if classes[k] is not None and classes[n] is not None and classes[k] != classes[n]:
                edges.append((k, n))
    return edges


def locate_seed(seed: int, k: int, n: int, t: Fraction) -> int:
    """The noise seed of the start a fraction ``t`` of the way from grid start k to its neighbour n: a
    function of (seed, edge, t) alone, so a deeper --locate repeats a shallower one's runs."""
    state = np.random.SeedSequence([seed, 0x4C4F43, k, n, t.numerator, t.denominator])  # "LOC"
    return int(state.generate_state(1, dtype=np.uint32)[0])


def locate_boundary(
    settings: SweepSettings, grid: np.ndarray, points: Sequence[dict[str, Any]], run_batch: Batch
) -> tuple[dict[str, Any], bool]:
    """Bisect every grid edge a boundary crosses ``settings.locate`` times, all edges' midpoints of a
    bisection as one batch: each crossing is then known to 1/2^locate of a grid step. A midpoint whose class
    differs from the edge's first end becomes the second end, else the first (with three classes on one
    edge, it follows one of the changes). Returns the JSON's ``boundary`` and whether every run finished."""
    nx, nt, depth = settings.x0.n, settings.theta0.n, settings.locate
    edges = boundary_edges(points, nx, nt)
    lo = [Fraction(0)] * len(edges)
    hi = [Fraction(1)] * len(edges)
    cls_lo = [verdict_class(points[k]) for k, _ in edges]
    cls_hi = [verdict_class(points[n]) for _, n in edges]

    def state(e: int, t: Fraction) -> np.ndarray:
        k, n = edges[e]
        return np.asarray(grid[k] + float(t) * (grid[n] - grid[k]))

    complete, ran = True, 0
    for _ in range(depth if edges else 0):
        mids = [(a + b) / 2 for a, b in zip(lo, hi, strict=True)]
        batch = np.array([state(e, t) for e, t in enumerate(mids)], dtype=float)
        seeds = np.array(
            [locate_seed(settings.seed, *edges[e], t) for e, t in enumerate(mids)], dtype=np.int64
        )
        records, complete = run_batch(batch, seeds, None)
        if not complete:
            break
        ran += len(edges)
        for e, (t, r) in enumerate(zip(mids, records, strict=True)):
            assert r is not None
            if verdict_class(r) != cls_lo[e]:
                hi[e], cls_hi[e] = t, verdict_class(r)
            else:
                lo[e] = t
    step_x = (settings.x0.hi - settings.x0.lo) / (nx - 1) if nx > 1 else 0.0
    step_t = (settings.theta0.hi - settings.theta0.lo) / (nt - 1) if nt > 1 else 0.0
    crossings = [
        {
            "along": "x0" if n - k == nt else "theta0",
            "grid_starts": [k, n],
            "classes": [cls_lo[e], cls_hi[e]],
            "t": [float(lo[e]), float(hi[e])],
            "between": [state(e, lo[e]).tolist(), state(e, hi[e]).tolist()],
            "at": state(e, (lo[e] + hi[e]) / 2).tolist(),
        }
        for e, (k, n) in enumerate(edges)
    ]
    return {
        "bisections": depth,
        "resolution": {"x0_m": step_x / 2**depth, "theta0_rad": step_t / 2**depth},
        "edges": len(edges),
        "run": ran,
        "crossings": crossings,
    }, complete


def _corner_starts(controller: str, params: Parameters) -> list[tuple[float, float, str, str]]:
    """The claims' corner states that lie on this rig (a corner off the track is noted, not run)."""
    out = []
    for claim in CLAIMS:
        if controller not in claim.applies_to:
            continue
        for x, th in claim.corners:
            try:
                check_initial_state(params, x, th, 0.0, 0.0)
            except ValueError:
                continue
            out.append((x, th, claim.source, ""))
    return out


def _judge(claim: RegionClaim, result: SweepResult, params: Parameters) -> dict[str, Any]:
    """The claim against the map: the grid points inside its rectangle that keep the ball (and that hold),
    and each corner state, run or noted off the track."""
    (xlo, xhi), (tlo, thi) = claim.x0_m, claim.theta0_rad
    inside = [p for p in result.points if p and xlo <= p["x0_m"] <= xhi and tlo <= p["theta0_rad"] <= thi]
    kept = [p for p in inside if not p["ball_lost"]]
    held = [p for p in inside if p["held"]]
    corners = []
    for x, th in claim.corners:
        try:
            check_initial_state(params, x, th, 0.0, 0.0)
        except ValueError as exc:
            corners.append({"x0_m": x, "theta0_rad": th, "kept": None, "note": f"not on this rig: {exc}"})
            continue
        run = next(
            (c for c in result.corners if c and c.get("x0_m") == x and c.get("theta0_rad") == th), None
        )
        corners.append(
            {
                "x0_m": x,
                "theta0_rad": th,
                "kept": None if not run else not run["ball_lost"],
                "held": None if not run else run["held"],
                "note": "",
            }
        )
    verdict = "holds" if inside and len(kept) == len(inside) else ("fails" if inside else "untested")
    return {
        "source": claim.source,
        "family": claim.family,
        "statement": (
            f"the ball stays on the beam for every start in x0 ∈ [{xlo:g}, {xhi:g}] m, "
            f"θ0 ∈ [{tlo:g}, {thi:g}] rad"
        ),
        "grid_points_inside": len(inside),
        "kept": len(kept),
        "held": len(held),
        "lost_at": [(p["x0_m"], p["theta0_rad"]) for p in inside if p["ball_lost"]][:50],
        "corners": corners,
        "verdict": verdict,
    }
