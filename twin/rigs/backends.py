"""The physics backends, registered: one row per backend, and the screening policy over them.

Each row names a backend (``--plant``'s choice), its single-run implementation (``twin.physics.PhysicsBackend``),
its batch implementation (``twin.physics.BatchPhysics``), whether it is **exact** (bit-identical to the twin: its
runs may judge) or screening only, and a line for the help:

    twin       the MuJoCo twin (``twin.plant.Plant``; batch ``twin.plant_batch.MujocoBatchPhysics``), exact
    reference  the analytic reference model (``twin.reference.ReferencePlant``; batch the compiled kernel,
               ``twin.screen.plant.ReferenceBatchPhysics``), screening only; the commands run it with ideal
               converters

A new backend is one module implementing the two protocols and one ``register(Backend(...))``. The makers
import their modules when called, so that reading the table (``--help``) loads no physics.

Screening is a ``ScreeningPolicy``: a screening backend runs every run first and a confirming one re-runs
those near a class change (``twin.app.screening``). The command line's ``--engine screen|fast|mujoco`` maps
onto it here, in ``engine_policy``, and nowhere else.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, TypeAlias

if TYPE_CHECKING:  # the table is read by --help: it loads neither numpy nor any physics
    import numpy as np

    from twin.parameters import Parameters
    from twin.physics import BatchFactory, BatchPhysics, PhysicsBackend, SingleFactory

__all__ = [
    "DEFAULT_PLANT",
    "ENGINES",
    "PlantKind",
    "Backend",
    "BackendError",
    "ScreeningPolicy",
    "backend",
    "engine_policy",
    "label_backend",
    "plant_choices",
    "register",
    "stand_in_refusal",
    "unregister",
]

DEFAULT_PLANT = "twin"
# The built-in rows' names, the type ``twin.rigs`` has always exported; the rigs take any registered name (str).
PlantKind: TypeAlias = Literal["twin", "reference"]
# The engine's words on the command line (``--engine``): see ``engine_policy``.
ENGINES = ("screen", "fast", "mujoco")


class BackendError(ValueError):
    """A backend or engine name that is not registered, or a policy the backends cannot run."""


@dataclass(frozen=True)
class Backend:
    """One registered physics backend (see the module)."""

    name: str  # --plant's choice
    single: SingleFactory  # one run from its parameters
    batch: BatchFactory  # N runs: (params, x0_m, theta0_rad, nthread)
    exact: bool  # bit-identical to the twin: its runs may judge (else screening only)
    summary: str  # one line for --plant's help
    label: str  # what a run record's "engine" says of a run it decided as the plant asked for
    ideal_converters: bool = False  # the commands run it with ideal converters (no I/O chain of its own)
    stand_in: str | None = None  # the screening backend that stands in for it (--engine screen or fast)
    # why its batch cannot run a rig (the part it has no form for, by its field), None if it can; None: any rig
    refusal: Callable[[Parameters], str | None] | None = None


def _twin_single(params: Parameters) -> PhysicsBackend:
    from twin.plant import Plant

    return Plant(params)


def _twin_batch(
    params: Sequence[Parameters], x0: np.ndarray, theta0: np.ndarray, nthread: int
) -> BatchPhysics:
    from twin.plant_batch import MujocoBatchPhysics

    return MujocoBatchPhysics(params, x0, theta0, nthread)


def _reference_single(params: Parameters) -> PhysicsBackend:
    from twin.reference import ReferencePlant

    return ReferencePlant(params)


def _reference_batch(
    params: Sequence[Parameters], x0: np.ndarray, theta0: np.ndarray, nthread: int
) -> BatchPhysics:
    from twin.screen.plant import ReferenceBatchPhysics  # numba is imported when the fast engine is asked for

    return ReferenceBatchPhysics(params, x0, theta0, nthread)


def _reference_refusal(params: Parameters) -> str | None:
    from twin.screen.plant import kernel_refusal

    return kernel_refusal(params)


def stand_in_refusal(plant: str, params: Parameters | None) -> str | None:
    """Why ``plant``'s stand-in (the fast engine) cannot run the rig ``params`` names (a part it has no form
    for, by its field: ``twin.screen.plant.kernel_refusal``), None if it can, if the plant has none, or if no
    rig is given."""
    stand_in = backend(plant).stand_in
    if params is None or stand_in is None:
        return None
    refusal = backend(stand_in).refusal
    return None if refusal is None else refusal(params)


# The fast engine's label in run records: the reference plant's runs standing in for the twin's.
SCREEN_LABEL = "fast"

_REGISTRY: dict[str, Backend] = {}


def register(row: Backend) -> None:
    """Add a backend (refused if its name or label is taken, or its stand-in is not registered)."""
    if row.name in _REGISTRY:
        raise BackendError(f"backend {row.name!r} is registered already")
    if row.label == SCREEN_LABEL or any(b.label == row.label for b in _REGISTRY.values()):
        raise BackendError(f"backend {row.name!r}: label {row.label!r} is taken")
    if row.stand_in is not None:
        backend(row.stand_in)
    _REGISTRY[row.name] = row


def unregister(name: str) -> None:
    """Remove a backend added with ``register`` (the built-in rows stay)."""
    if name in (row.name for row in _BUILT_IN):
        raise BackendError(f"backend {name!r} is built in")
    backend(name)
    del _REGISTRY[name]


def plant_choices() -> tuple[str, ...]:
    """The registered backends' names, the default first (``--plant``'s choices)."""
    return (DEFAULT_PLANT, *sorted(set(_REGISTRY) - {DEFAULT_PLANT}))


def plant_help() -> str:
    """``--plant``'s help: each backend's name and line."""
    return "; ".join(f"'{name}': {_REGISTRY[name].summary}" for name in plant_choices())


def backend(name: object) -> Backend:
    """The backend named ``name`` (``BackendError`` naming the value and the choices otherwise)."""
    row = _REGISTRY.get(name) if isinstance(name, str) else None
    if row is None:
        choices = ", ".join(repr(c) for c in plant_choices())
        raise BackendError(f"plant = {name!r}: expected one of {choices}")
    return row


def label_backend(label: object) -> Backend:
    """The backend whose runs a record's ``"engine"`` label names (``SCREEN_LABEL``: the twin's stand-in)."""
    if label == SCREEN_LABEL:
        stand_in = backend(DEFAULT_PLANT).stand_in
        assert stand_in is not None
        return backend(stand_in)
    for row in _REGISTRY.values():
        if row.label == label:
            return row
    raise BackendError(f"engine = {label!r}: no backend's runs are labelled so")


@dataclass(frozen=True)
class ScreeningPolicy:
    """Who runs a many-run job's runs: ``screen`` (a screening backend, or None) runs every run first, and
    ``confirm`` (the backend asked for) re-runs those the screening cannot decide; ``confirms`` false: the
    screening backend's runs stand alone (labelled so), the confirming backend running only an audit where
    a command asks for one."""

    screen: str | None
    confirm: str
    confirms: bool = True

    @property
    def screened(self) -> bool:
        """The screening backend runs first and the confirming one re-runs the uncertain runs."""
        return self.screen is not None and self.confirms

    @property
    def stand_alone(self) -> bool:
        """The screening backend's runs stand alone, unconfirmed (``--engine fast``)."""
        return self.screen is not None and not self.confirms

    @property
    def decider(self) -> str:
        """The backend whose runs a job without screening runs: the screening one when it stands alone."""
        return self.screen if self.screen is not None and self.stand_alone else self.confirm

    def label(self, plant: str) -> str:
        """A run record's ``"engine"`` of a run on ``plant`` under this policy."""
        return SCREEN_LABEL if plant == self.screen else backend(plant).label

    def decider_label(self) -> str:
        return self.label(self.decider)


def engine_policy(
    engine: str, plant: str = DEFAULT_PLANT, *, strict: bool = True, params: Parameters | None = None
) -> ScreeningPolicy:
    """``--engine``'s word as a policy for ``plant``: 'mujoco' the plant alone, 'screen' its stand-in
    confirmed by it, 'fast' its stand-in alone. A plant with no stand-in, or a rig (``params``) its stand-in
    refuses (``stand_in_refusal``: a part the fast engine has no form for): ``BackendError`` naming why
    (``strict``), or the plant alone whatever the word (a job's settings, which say the engine asked for)."""
    if engine not in ENGINES:
        raise BackendError(f"engine = {engine!r}: expected one of {', '.join(repr(e) for e in ENGINES)}")
    row = backend(plant)
    refusal = None if engine == "mujoco" else stand_in_refusal(plant, params)
    if engine == "mujoco" or ((row.stand_in is None or refusal is not None) and not strict):
        return ScreeningPolicy(None, row.name)
    if row.stand_in is None:
        raise BackendError(
            f"--engine {engine}: the fast engine stands in for the MuJoCo twin; not with --plant {row.name}"
        )
    if refusal is not None:
        raise BackendError(f"--engine {engine}: {refusal}; run this rig with --engine mujoco")
    return ScreeningPolicy(row.stand_in, row.name, confirms=engine == "screen")


# The built-in rows.
register(
    Backend(
        name="reference",
        single=_reference_single,
        batch=_reference_batch,
        exact=False,
        summary="the analytic reference model (always with ideal sensors)",
        label="reference",
        ideal_converters=True,
        refusal=_reference_refusal,
    )
)
register(
    Backend(
        name="twin",
        single=_twin_single,
        batch=_twin_batch,
        exact=True,
        summary="the MuJoCo twin (default)",
        label="mujoco",
        stand_in="reference",
    )
)
_BUILT_IN = tuple(_REGISTRY.values())
