"""The controller a command runs: a name from the registry, the user's own ``MODULE:CLASS``, or another host's
value (a firmware image, a controller FMU): ``twin.app.hosts`` is the table of hosts and its parser; here are the
Python rows' import and construction and the catalogue that carries one controller more.

``twin.app.hosts.catalogue_for(spec, params)`` is the catalogue (``twin.engine.Catalogue``) in which ``spec``
names a controller; worker processes rebuild it from the same text, so a user's controller runs there too. Failures
are ``ParameterError``s naming the ``--controller`` value (one line, no traceback). Imports stay lazy:
``ballbeam --help`` must not load python-control.
"""

from __future__ import annotations

import importlib
import inspect
import os
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Mapping

    from twin.engine import Catalogue, CatalogueEntry, StateLaw
    from twin.firmware import Firmware
    from twin.guard import Fault, Guard
    from twin.interface import Controller
    from twin.parameters import Parameters

__all__ = [
    "WithController",
    "construct",
    "one_line",
    "user_controller",
    "with_user_controller",
]


def one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _first_call_guard(timeout_s: float | None) -> Guard:
    from twin.guard import Guard, first_call_budget_s

    return Guard(first_budget_s=first_call_budget_s(timeout_s))


def _what(fault: Fault) -> str:
    """What went wrong in a guarded import or construction, in one line."""
    from twin.guard import fault_text

    return fault_text(fault)


class ProcessExit(Exception):
    """A user's module called ``os._exit`` while it was imported: the process would end with no report."""


def _import_keeping_the_process(name: str) -> Any:
    """``importlib.import_module(name)`` with ``os._exit`` refused while it runs: a module that calls it at
    import (no exception, no cleanup: the process would just end, with exit code 0 for ``os._exit(0)``) raises
    ``ProcessExit`` instead, which the guard reports like any other failed import."""
    real_exit = os._exit

    def refuse(code: int) -> None:
        raise ProcessExit(f"os._exit({code!r}) called while importing: the process would have ended silently")

    os._exit = refuse  # type: ignore[assignment]
    try:
        return importlib.import_module(name)
    finally:
        os._exit = real_exit


def _looks_like_a_path(name: str) -> bool:
    """A file path or a relative module name where a dotted module name belongs (importlib would raise a
    ``TypeError`` for a leading dot, or look for a module named with slashes)."""
    return name.startswith(".") or "/" in name or os.sep in name or name.endswith(".py")


def _dotted(path: str) -> str:
    """The dotted module name a relative file path would have from the current folder (``mypkg/mod.py`` →
    ``mypkg.mod``), for the message; a path outside it keeps only its file's name."""
    parts = [p for p in path.replace(os.sep, "/").removesuffix(".py").split("/") if p not in ("", ".")]
    if path.startswith("/") or ".." in parts:
        parts = parts[-1:]
    return ".".join(parts).lstrip(".") or "mod"


def user_controller(spec: str, timeout_s: float | None = None) -> Callable[..., Controller] | None:
    """The class named by ``MODULE:CLASS`` (a ``Controller`` subclass) or the function named by
    ``MODULE:FUNCTION`` (one that builds a ``Controller``: a trained policy's ``PolicyController``, say), or
    None for a registry name (checked against the registry).
    Whatever the import raises (``SystemExit`` included) or an import that does not return within
    ``twin.guard.first_call_budget_s(timeout_s)`` is a ``ParameterError``."""
    from twin.parameters import ParameterError

    if ":" not in spec:
        from controllers import registry

        if spec not in registry.NAMES and _looks_like_a_path(spec):
            raise ParameterError(
                f"--controller {spec}: a file path, not a controller: give MODULE:CLASS, the module's dotted "
                f"name as Python imports it from the current folder ({os.getcwd()}) and the class, "
                f"e.g. {_dotted(spec)}:MyController"
            )
        if spec not in registry.NAMES:
            raise ParameterError(
                f"--controller {spec!r}: unknown controller; known: {', '.join(registry.NAMES)}, "
                "or MODULE:CLASS for your own"
            )
        return None
    from twin.guard import Fault
    from twin.interface import Controller

    module_name, _, qualname = spec.partition(":")
    if not module_name or not qualname:
        raise ParameterError(f"--controller {spec!r}: expected MODULE:CLASS, e.g. mypkg.mod:MyController")
    if _looks_like_a_path(module_name):
        raise ParameterError(
            f"--controller {spec}: {module_name!r} is a file path or a relative name; MODULE is the module's "
            f"dotted name as Python imports it from the current folder ({os.getcwd()}), "
            f"e.g. {_dotted(module_name)}:{qualname}"
        )
    cwd = os.getcwd()
    if "" not in sys.path and cwd not in sys.path:  # as `python -m`: the user's modules where they are
        sys.path.insert(0, cwd)
    guard = _first_call_guard(timeout_s)
    try:
        module = guard.call(_import_keeping_the_process, module_name, guard.first_budget_s)
    except Fault as fault:
        exc = fault.exc
        if isinstance(exc, ModuleNotFoundError) and exc.name:
            if module_name == exc.name or module_name.startswith(exc.name + "."):
                raise ParameterError(f"--controller {spec}: no module named {exc.name!r}") from None
        raise ParameterError(f"--controller {spec}: importing {module_name} failed: {_what(fault)}") from None
    obj: Any = module
    for part in qualname.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise ParameterError(f"--controller {spec}: module {module_name} has no {qualname!r}") from None
    if isinstance(obj, type):
        if not issubclass(obj, Controller):
            raise ParameterError(
                f"--controller {spec}: {qualname} is not a subclass of twin.interface.Controller "
                "(a hardware controller: raw blocks in, a DAC command out)"
            )
        return obj
    if not callable(obj):
        raise ParameterError(
            f"--controller {spec}: {qualname} is neither a twin.interface.Controller class nor a function "
            "that builds one"
        )
    return obj


def construct(
    cls: Callable[..., Controller], spec: str, params: Parameters, timeout_s: float | None = None
) -> Controller:
    """``cls(software)`` if the constructor (or factory function) has a parameter ``software``, else
    ``cls()``; whatever it raises, a call that does not return within ``twin.guard.first_call_budget_s(
    timeout_s)``, a factory's result that is not a ``Controller`` or a ``period_s`` that is not a positive
    number of seconds is a ``ParameterError``."""
    from twin.guard import Fault
    from twin.parameters import ParameterError

    try:
        software = inspect.signature(cls).parameters.get("software")
    except (TypeError, ValueError):  # no signature to read: call it without arguments
        software = None
    call = f"{getattr(cls, '__name__', 'the factory')}({'' if software is None else 'software'})"
    if software is None:
        make: Callable[[Any], Controller] = lambda _: cls()  # noqa: E731
    elif software.kind is inspect.Parameter.POSITIONAL_ONLY:
        make = cls
    else:
        make = lambda sw: cls(software=sw)  # noqa: E731
    guard = _first_call_guard(timeout_s)
    try:
        controller = guard.call(make, params.software, guard.first_budget_s)
    except Fault as fault:
        raise ParameterError(f"--controller {spec}: {call} failed: {_what(fault)}") from None
    from twin.engine import ControllerError, check_period_s
    from twin.interface import Controller

    if not isinstance(controller, Controller):
        raise ParameterError(
            f"--controller {spec}: {call} returned {type(controller).__name__}, not a twin.interface.Controller"
        )
    try:
        check_period_s(controller)
    except ControllerError as exc:
        raise ParameterError(f"--controller {spec}: {exc}") from None
    return controller


class WithController:
    """The registry plus one controller more (the user's ``MODULE:CLASS`` or a firmware image), as a catalogue
    for the live view and the workers."""

    # The base's entries and the extra one, built when first read (as the registry's: reading them costs the
    # designs, building the parser or a worker must not).
    ENTRIES: Mapping[str, CatalogueEntry]

    def __init__(
        self,
        base: Catalogue,
        spec: str,
        build: Callable[[Parameters], Controller | StateLaw | Firmware],
        entry: Callable[[], CatalogueEntry],
    ) -> None:
        self.base, self.spec, self._build, self._entry = base, spec, build, entry
        self.NAMES: tuple[str, ...] = (*base.NAMES, spec)

    def __getattr__(self, name: str) -> Any:
        if name != "ENTRIES":
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        self.ENTRIES = {**self.base.ENTRIES, self.spec: self._entry()}
        return self.ENTRIES

    def make(self, name: str, params: Parameters | None = None) -> Controller | StateLaw | Firmware:
        from twin.parameters import Parameters

        if name == self.spec:
            return self._build(params or Parameters())
        return self.base.make(name, params)


def with_user_controller(
    base: Catalogue, spec: str, cls: Callable[..., Controller], timeout_s: float | None = None
) -> WithController:
    """The registry plus the user's ``MODULE:CLASS`` controller; its setpoint flag read from a built one (what
    it declares)."""

    def entry() -> CatalogueEntry:
        from twin.engine import CatalogueEntry
        from twin.interface import Setpoint
        from twin.parameters import Parameters

        doc = (cls.__doc__ or "").strip().splitlines()
        return CatalogueEntry(
            name=spec,
            build=lambda params: construct(cls, spec, params),
            description=f"your controller {spec}" + (f": {doc[0]}" if doc else ""),
            simulation_only=False,
            batched=False,
            setpoint=isinstance(construct(cls, spec, Parameters()), Setpoint),
        )

    return WithController(base, spec, lambda params: construct(cls, spec, params, timeout_s), entry)
