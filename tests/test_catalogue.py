"""The controller catalogue as data: each entry's flags are true to the object it builds, the names have one
home, importing the registry loads no design code, and the user's controller is one more entry."""

import subprocess
import sys
from pathlib import Path

import pytest

from controllers import registry
from controllers.batch import batched
from controllers.loop import TrueStateLaw
from twin.app.catalogue import with_user_controller
from twin.engine import CatalogueEntry
from twin.interface import Controller, DaqSample, Setpoint
from twin.parameters import Parameters

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.quick
def test_names_are_the_entries_keys_in_order() -> None:
    assert registry.NAMES == tuple(registry.ENTRIES)
    assert len(set(registry.NAMES)) == len(registry.NAMES)
    for name, entry in registry.ENTRIES.items():
        assert isinstance(entry, CatalogueEntry) and entry.name == name
        assert entry.description and "\n" not in entry.description
        assert registry.describe(name) == entry.description
        assert registry.simulation_only(name) == entry.simulation_only


@pytest.mark.quick
@pytest.mark.parametrize("name", registry.NAMES)
def test_flags_are_true_to_the_built_controller(name: str) -> None:
    entry = registry.ENTRIES[name]
    built = entry.build(Parameters())
    assert built.name == name
    assert type(registry.make(name)) is type(built)
    assert entry.simulation_only == isinstance(built, TrueStateLaw)
    assert entry.simulation_only != isinstance(built, Controller)
    assert entry.setpoint == isinstance(built, Setpoint)
    # batched: make_batch gives a batch controller exactly when the flag says so, and the flag hides none
    # (a second instance of the same design batches with the first when a batched version exists).
    assert (registry.make_batch(name, Parameters(), n=2) is not None) == entry.batched
    assert (batched([built, entry.build(Parameters())]) is not None) == entry.batched


@pytest.mark.quick
@pytest.mark.parametrize("name", [n for n in registry.NAMES if registry.ENTRIES[n].setpoint])
def test_a_declared_setpoint_is_the_law_reference(name: str) -> None:
    built = registry.make(name)
    assert isinstance(built, Setpoint)
    assert built.setpoint_m == 0.0
    built.setpoint_m = 0.07
    assert built.law.ref_x_m == 0.07 and built.setpoint_m == 0.07  # type: ignore[union-attr]


def test_importing_the_registry_loads_no_design_code() -> None:
    """``ballbeam --help`` lists the registry's names: importing it must not load numpy, python-control, scipy
    or MuJoCo (the builders do); reading ENTRIES designs lqr (its description's figure) and loads numpy,
    python-control and scipy, but not MuJoCo: a design needs no plant, and the loop (twin.engine) no rig."""
    code = (
        "import sys\n"
        "import controllers.registry as r\n"
        "heavy = ('numpy', 'control', 'scipy', 'mujoco', 'twin.engine', 'controllers.design')\n"
        "print('BEFORE', [m for m in heavy if m in sys.modules], len(r.NAMES))\n"
        "r.ENTRIES\n"
        "print('AFTER', [m for m in heavy if m in sys.modules])\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout
    assert f"BEFORE [] {len(registry.NAMES)}" in out, out
    assert "AFTER ['numpy', 'control', 'scipy', 'twin.engine', 'controllers.design']" in out, out


def test_the_appendix_controllers_load_no_python_control() -> None:
    """A sweep of a fixed-gain controller (the appendix's, one by one or in a batch) pays no python-control
    import (1.6 s here); the first design computed loads it."""
    code = (
        "import sys\n"
        "from controllers import registry as r\n"
        "from twin.parameters import Parameters\n"
        "for name in ('appendix-sf', 'appendix-clp'):\n"
        "    r.make(name, Parameters()); r.make_batch(name, Parameters(), n=3)\n"
        "print('FIXED', 'control' in sys.modules)\n"
        "r.make('sf', Parameters())\n"
        "print('DESIGNED', 'control' in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout
    assert "FIXED False" in out and "DESIGNED True" in out, out


@pytest.mark.quick
def test_unknown_names_are_refused_by_every_reader() -> None:
    for call in (registry.make, registry.describe, registry.simulation_only):
        with pytest.raises(KeyError, match="unknown controller 'pid'"):
            call("pid")
    with pytest.raises(KeyError, match="unknown controller 'pid'"):
        registry.make_batch("pid", Parameters(), n=2)


class _Plain(Controller):
    """Holds the command at zero."""

    def start(self, sample: DaqSample) -> None:
        pass

    def update(self, sample: DaqSample) -> float:
        return 2.5


class _WithSetpoint(_Plain):
    def __init__(self) -> None:
        super().__init__()
        self.setpoint_m = 0.0


@pytest.mark.quick
@pytest.mark.parametrize(("cls", "setpoint"), [(_Plain, False), (_WithSetpoint, True)])
def test_the_users_controller_is_one_more_entry(cls: type[Controller], setpoint: bool) -> None:
    spec = f"tests.test_catalogue:{cls.__name__}"
    catalogue = with_user_controller(registry, spec, cls)
    assert catalogue.NAMES == (*registry.NAMES, spec) == tuple(catalogue.ENTRIES)
    entry = catalogue.ENTRIES[spec]
    assert (entry.simulation_only, entry.batched, entry.setpoint) == (False, False, setpoint)
    assert isinstance(entry.build(Parameters()), cls) and isinstance(catalogue.make(spec), cls)
    assert entry.description.startswith(f"your controller {spec}")
    assert catalogue.ENTRIES["lqr"] is registry.ENTRIES["lqr"]
