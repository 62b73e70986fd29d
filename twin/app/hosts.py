"""Controller hosts, registered: what a ``--controller`` value names, read in one place.

A value is one of the rows of ``HOSTS``, keyed by scheme: ``SCHEME:REST`` for a prefixed row (``avr:`` a
firmware image on a simulated microcontroller, ``fmu:`` a controller FMU in a process of its own), else
``MODULE:CLASS`` (your own Python code) or, without a colon, one of the catalogue's names
(``controllers.registry``). ``host_of`` is the one parser. Each row says

* its kind: a ``controller`` (a hardware controller or a law on the true state, in this process or a host's)
  or ``firmware`` on a board (``twin.firmware.Firmware``: it drives the simulated rig through its pins);
* the file it reads (``image``): what a replay hashes (``twin.app.replay.controller_identity``) and what no
  output may replace (``twin.app.commands.common.inputs``);
* how it is built (``build``: one for a rig, checked; ``catalogue``: the registry plus it, for the many-run
  jobs and the live view; ``log_replay``: fresh hardware controllers to replay logs with; ``wire``: what runs
  against a rig over the wire), each with its refusals (``ParameterError``s naming the ``--controller`` value).

A new host is one row: ``controller_host`` makes a controller's row from its loader alone (``register`` adds
it). The avr and fmu rows import twin.avr and twin.fmi lazily: ``ballbeam --help`` loads neither.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from twin.app.catalogue import (
    WithController,
    construct,
    one_line,
    user_controller,
    with_user_controller,
)

if TYPE_CHECKING:
    from twin.avr.firmware import AvrFirmware
    from twin.engine import Catalogue, CatalogueEntry, StateLaw
    from twin.firmware import Firmware
    from twin.interface import Controller
    from twin.parameters import Parameters

__all__ = [
    "AVR",
    "FMU",
    "HOSTS",
    "MODULE",
    "NAME",
    "Host",
    "HostKind",
    "build",
    "catalogue_for",
    "controller_host",
    "firmware",
    "fmu_controller",
    "host_of",
    "register",
]

HostKind = Literal["controller", "firmware"]


@dataclass(frozen=True)
class Host:
    """One row: a kind of ``--controller`` value (module doc). Every callable takes the whole value."""

    scheme: str  # a prefixed row's values start with ``scheme:``
    kind: HostKind
    form: str  # how a value is written, for messages: avr:FILE.elf
    image: Callable[[str], Path | None]  # the file it reads (None: none, or a module not found)
    build: Callable[[str, Parameters, float | None], Controller | StateLaw | Firmware]
    catalogue: Callable[[Catalogue, str, Parameters, float | None], Catalogue]
    log_replay: Callable[[str, Parameters], Callable[[], Controller]]
    wire: Callable[[str], Callable[[Parameters], object]]
    help: str = ""  # what --controller's help adds for it (prefixed rows)
    prefixed: bool = True


def _rest(spec: str) -> str:
    """What follows a prefixed value's scheme."""
    return spec.partition(":")[2]


def _with_one(
    base: Catalogue,
    spec: str,
    make: Callable[[Parameters], Controller | StateLaw | Firmware],
    description: str,
    simulation_only: bool,
) -> WithController:
    """The registry plus one controller that ``make`` builds (no batched form, no setpoint)."""

    def entry() -> CatalogueEntry:
        from twin.engine import CatalogueEntry

        return CatalogueEntry(
            name=spec,
            build=make,
            description=description,
            simulation_only=simulation_only,
            batched=False,
            setpoint=False,
        )

    return WithController(base, spec, make, entry)


def _close(made: object) -> None:
    """Close what a loader made, when it holds something (a process, a file)."""
    close = getattr(made, "close", None)
    if callable(close):
        close()


def controller_host(
    scheme: str,
    form: str,
    load: Callable[[str, Parameters], Controller],
    describe: Callable[[str], str],
    image: Callable[[str], Path | None],
    help: str = "",
) -> Host:
    """The row of a host of hardware controllers from its loader alone: ``load(spec, params)`` builds one for a
    rig (a ``ParameterError`` naming the value when it cannot); a job loads it once before any work (a bad one
    is refused there) and then once per run; ``describe(spec)`` is its line in the catalogue."""

    def catalogue(base: Catalogue, spec: str, params: Parameters, timeout_s: float | None) -> Catalogue:
        _close(load(spec, params))
        return _with_one(base, spec, lambda p: load(spec, p), describe(spec), False)

    def log_replay(spec: str, params: Parameters) -> Callable[[], Controller]:
        _close(load(spec, params))
        return lambda: load(spec, params)

    return Host(
        scheme=scheme,
        kind="controller",
        form=form,
        image=image,
        build=lambda spec, params, timeout_s: load(spec, params),
        catalogue=catalogue,
        log_replay=log_replay,
        wire=lambda spec: lambda params: load(spec, params),
        help=help,
    )


# --- avr: a firmware image on a simulated microcontroller (twin.avr) ---------------------------------------


def firmware(spec: str, params: Parameters, *, check: bool = False) -> AvrFirmware:
    """The firmware image ``avr:[MCU:]FILE.elf`` names, for a rig of ``params``; a ``ParameterError`` naming the
    ``--controller`` value when the image cannot be read, is no AVR ELF or, with ``check``, simavr cannot load it
    (a core is started once) or the co-simulation cannot be built here."""
    from twin.avr.core import AvrError, AvrUnavailable
    from twin.avr.firmware import AvrFirmware, image_spec
    from twin.parameters import ParameterError

    mcu, path = image_spec(_rest(spec))
    if not path.name:
        raise ParameterError(f"--controller {spec!r}: expected avr:FILE.elf or avr:MCU:FILE.elf")
    try:
        made = AvrFirmware(path, params, mcu=mcu, name=spec)
        if check:
            made.core().close()
    except (AvrError, AvrUnavailable, OSError) as exc:
        raise ParameterError(f"--controller {spec}: {one_line(exc)}") from None
    return made


def _avr_image(spec: str) -> Path:
    from twin.avr.firmware import image_spec

    return image_spec(_rest(spec))[1]


def _avr_catalogue(base: Catalogue, spec: str, params: Parameters, timeout_s: float | None) -> Catalogue:
    """The registry plus a firmware image, which is loaded once here (a bad image is refused before any run)."""
    made = firmware(spec, params, check=True)
    text = f"your firmware {spec} on a simulated {made.mcu} at {made.clock_hz / 1e6:g} MHz"
    return _with_one(base, spec, lambda p: firmware(spec, p), text, True)


def _avr_log_replay(spec: str, params: Parameters) -> Callable[[], Controller]:
    from twin.parameters import ParameterError

    raise ParameterError(
        f"--controller {spec}: a firmware image drives the simulated rig through its pins; a log is replayed "
        "with a hardware controller (raw volts in, DAC volts out)"
    )


def _avr_wire(spec: str) -> Callable[[Parameters], object]:
    raise ValueError(
        f"--controller {spec}: a firmware image drives the simulated rig through its pins, not "
        "a rig over the wire (flash it to drive the rig itself)"
    )


AVR = Host(
    scheme="avr",
    kind="firmware",
    form="avr:FILE.elf",
    image=_avr_image,
    build=lambda spec, params, timeout_s: firmware(spec, params, check=True),
    catalogue=_avr_catalogue,
    log_replay=_avr_log_replay,
    wire=_avr_wire,
    help="; or avr:FILE.elf (avr:MCU:FILE.elf), a firmware image run on a simulated microcontroller against the "
    "twin (docs/firmware.md: Firmware in the loop)",
)


# --- fmu: a controller FMU in a process of its own (twin.fmi) ----------------------------------------------


def fmu_controller(spec: str, params: Parameters) -> Controller:
    """The controller FMU ``fmu:FILE.fmu`` names, in a process of its own, stepping at the rig's period; a
    ``ParameterError`` naming the ``--controller`` value when it cannot be loaded (not an FMU, not co-simulation,
    a variable of the convention missing, an instantiation that failed)."""
    from twin.fmi.controller import FmuController, FmuError
    from twin.parameters import ParameterError

    path = _rest(spec)
    if not path:
        raise ParameterError(f"--controller {spec!r}: expected fmu:FILE.fmu")
    try:
        return FmuController(path, params.period_s)
    except (FmuError, OSError) as exc:
        raise ParameterError(f"--controller {spec}: {one_line(exc)}") from None


FMU = controller_host(
    "fmu",
    "fmu:FILE.fmu",
    lambda spec, params: fmu_controller(spec, params),  # looked up when called: tests wrap it
    lambda spec: f"your controller FMU {spec} (its own process)",
    lambda spec: Path(_rest(spec)),
    help="; or fmu:FILE.fmu, a co-simulation FMU with inputs ball_v, angle_v and output dac_v, run in a process "
    "of its own (docs/firmware.md: Controllers as FMUs)",
)


# --- Python: MODULE:CLASS, and the catalogue's names -------------------------------------------------------


def module_file(spec: str) -> Path | None:
    """The module file of a ``MODULE:CLASS``: the imported module's, else as the import would find it (the
    current folder first, as ``user_controller``), located without running anything (no package's
    ``__init__`` is executed); None for a module that cannot be found."""
    module = spec.partition(":")[0]
    imported = getattr(sys.modules.get(module), "__file__", None)
    if imported:
        return Path(imported)
    parts = module.split(".")
    if not all(p.isidentifier() for p in parts):
        return None
    cwd = os.getcwd()
    if "" not in sys.path and cwd not in sys.path:  # as user_controller: the user's modules where they are
        sys.path.insert(0, cwd)
    try:
        found = importlib.util.find_spec(parts[0])  # a top-level name: its finder only looks, runs nothing
        for depth in range(1, len(parts)):
            if found is None or found.submodule_search_locations is None:
                return None
            found = importlib.machinery.PathFinder.find_spec(
                ".".join(parts[: depth + 1]), list(found.submodule_search_locations)
            )
    except (ImportError, ValueError):
        return None
    if found is None or not found.has_location or found.origin is None:
        return None
    return Path(found.origin)


def _module_build(spec: str, params: Parameters, timeout_s: float | None) -> Controller:
    user = user_controller(spec, timeout_s)
    assert user is not None  # a value with a colon is never a catalogue name
    return construct(user, spec, params, timeout_s)


def _module_catalogue(base: Catalogue, spec: str, params: Parameters, timeout_s: float | None) -> Catalogue:
    """The registry plus the user's ``MODULE:CLASS`` (its constructor tried once here, so that a failing one is
    refused before any work)."""
    user = user_controller(spec, timeout_s)
    assert user is not None
    construct(user, spec, params, timeout_s)
    return with_user_controller(base, spec, user, timeout_s)


def _module_log_replay(spec: str, params: Parameters) -> Callable[[], Controller]:
    user = user_controller(spec)
    assert user is not None
    construct(user, spec, params)

    def own() -> Controller:
        return construct(user, spec, params)

    return own


def _module_wire(spec: str) -> Callable[[Parameters], object]:
    user = user_controller(spec)
    assert user is not None
    return lambda params: construct(user, spec, params)


MODULE = Host(
    scheme="MODULE",
    kind="controller",
    form="MODULE:CLASS",
    image=module_file,
    build=_module_build,
    catalogue=_module_catalogue,
    log_replay=_module_log_replay,
    wire=_module_wire,
    prefixed=False,
)


def _name_build(spec: str, params: Parameters, timeout_s: float | None) -> Controller | StateLaw | Firmware:
    from controllers import registry

    user_controller(spec, timeout_s)  # an unknown name is refused (naming the registry's)
    return registry.make(spec, params)


def _name_catalogue(base: Catalogue, spec: str, params: Parameters, timeout_s: float | None) -> Catalogue:
    user_controller(spec, timeout_s)
    return base


def _name_log_replay(spec: str, params: Parameters) -> Callable[[], Controller]:
    from controllers import registry
    from twin.parameters import ParameterError

    user_controller(spec)
    if registry.simulation_only(spec):
        raise ParameterError(
            f"--controller {spec}: a law on the true state (simulation only); a log is replayed with a "
            "hardware controller (raw volts in, DAC volts out)"
        )

    def named() -> Controller:
        from twin.interface import Controller

        made = registry.make(spec, params)
        if not isinstance(made, Controller):  # the registry's flag says so; the type checker cannot
            raise ParameterError(f"--controller {spec}: not a hardware controller")
        return made

    return named


def _name_wire(spec: str) -> Callable[[Parameters], object]:
    from controllers import registry

    user_controller(spec)
    return lambda params: registry.make(spec, params)


NAME = Host(
    scheme="NAME",
    kind="controller",
    form="NAME",
    image=lambda spec: None,
    build=_name_build,
    catalogue=_name_catalogue,
    log_replay=_name_log_replay,
    wire=_name_wire,
    prefixed=False,
)

# The table, keyed by scheme: the prefixed rows in the order --controller's help lists them, then the two
# Python rows a value without a registered scheme falls to.
HOSTS: dict[str, Host] = {row.scheme: row for row in (FMU, AVR, MODULE, NAME)}


def register(host: Host) -> None:
    """Add a prefixed row (a new host: one row); a scheme already taken is a ``ValueError``."""
    if not host.prefixed or not host.scheme.isidentifier() or host.scheme in HOSTS:
        raise ValueError(f"host scheme {host.scheme!r}: taken, or not a prefixed identifier")
    HOSTS[host.scheme] = host


def host_of(spec: str) -> Host:
    """The row a ``--controller`` value belongs to: its scheme's, else ``MODULE:CLASS`` with a colon, else a
    catalogue name."""
    scheme, colon, _ = spec.partition(":")
    row = HOSTS.get(scheme) if colon else None
    if row is not None and row.prefixed:
        return row
    return MODULE if colon else NAME


def build(spec: str, params: Parameters, timeout_s: float | None = None) -> Controller | StateLaw | Firmware:
    """One controller named by ``spec`` (any host's value) for a rig of ``params``: its row's ``build``."""
    return host_of(spec).build(spec, params, timeout_s)


def catalogue_for(spec: str, params: Parameters, timeout_s: float | None = None) -> Catalogue:
    """The registry, or the registry plus the controller ``spec`` names (its row's ``catalogue``: built or loaded
    once here, so that a failing one is refused before any work); worker processes rebuild it from the same
    text, so a user's controller runs there too. ``timeout_s``: the watchdog's budget (``twin.guard``)."""
    from controllers import registry

    return host_of(spec).catalogue(registry, spec, params, timeout_s)
