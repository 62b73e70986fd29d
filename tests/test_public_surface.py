"""The public surface (README, "Using the twin from Python"): each package's ``__init__`` names what a user
may import, every name there resolves to an object of the module the docstring names, the packages are typed
(``py.typed``), and importing the hardware contract through the top package loads no MuJoCo."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("twin", "controllers", "calib", "twin.app", "twin.rigs", "twin.wire", "twin.serving")


@pytest.mark.quick
@pytest.mark.parametrize("package", PACKAGES)
def test_every_public_name_resolves_and_is_documented(package: str) -> None:
    module = importlib.import_module(package)
    names = module.__all__
    assert names and len(set(names)) == len(names)
    doc = module.__doc__ or ""
    for name in names:
        obj = getattr(module, name)
        assert obj is not None
        assert name in doc, f"{package}.{name} is exported but its docstring does not name it"
        home = getattr(obj, "__module__", None)
        # a constant (NAMES) or a type alias (PlantKind) has no home of its own
        if home is not None and home != "typing" and not isinstance(obj, tuple):
            assert home.split(".")[0] == package.split(".")[0], (package, name, home)


@pytest.mark.quick
def test_an_unknown_name_is_an_attribute_error() -> None:
    import twin

    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        twin.nothing  # noqa: B018


@pytest.mark.quick
@pytest.mark.parametrize("package", ("twin", "controllers", "calib"))
def test_the_packages_are_typed(package: str) -> None:
    assert (ROOT / package / "py.typed").is_file()


@pytest.mark.quick
def test_the_contract_through_the_top_package_loads_no_mujoco() -> None:
    code = (
        "import sys, twin\n"
        "assert twin.Rig.__name__ == 'Rig' and twin.Controller.__name__ == 'Controller'\n"
        "print('mujoco' in sys.modules, 'numpy.linalg' in sys.modules or 'scipy' in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=60, check=True
    )
    assert out.stdout.split()[0] == "False", out.stdout


@pytest.mark.quick
def test_a_lazy_export_imports_its_module_on_first_read() -> None:
    from twin.exports import lazy_exports

    get = lazy_exports("pkg", {"sqrt": "math"})
    assert get("sqrt")(4.0) == 2.0
    with pytest.raises(AttributeError, match="module 'pkg' has no attribute 'nope'"):
        get("nope")
