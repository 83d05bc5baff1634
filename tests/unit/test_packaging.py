"""What a user who ``pip install``s primordia (not editable, outside this repository) gets.

Every package the code imports is declared in its ``pyproject.toml`` (a dependency or an extra), or is one of
the system's that pip must not install (:data:`primordia.core.errors.SYSTEM_PACKAGES`, README "Backends"): an
import of a package declared nowhere works here, in the repository's venv that sees Debian's packages, and
fails in the user's environment.
"""

from __future__ import annotations

import ast
import importlib.metadata
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from primordia.core.errors import SYSTEM_PACKAGES

ROOT = Path(__file__).resolve().parents[2]


def canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def imported_packages(package: Path) -> dict[str, str]:
    """The top-level names of the third-party packages ``package``'s modules import (anywhere in a module, a
    function's body too), each with the first place that imports it."""
    own = {package.name, "primordia"}
    found: dict[str, str] = {}
    for path in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.partition(".")[0]
                if top not in sys.stdlib_module_names and top not in own:
                    found.setdefault(top, f"{path.relative_to(ROOT)}:{node.lineno}")
    return found


def declared_distributions(pyproject: Path) -> set[str]:
    """The distributions ``pyproject``'s dependencies and extras bring: their names, and those of the extras they
    ask for (``dask[distributed]`` brings distributed)."""
    project = tomllib.loads(pyproject.read_text())["project"]
    requirements = [Requirement(text) for text in project.get("dependencies", [])]
    requirements += [Requirement(text) for extra in project.get("optional-dependencies", {}).values()
                     for text in extra]
    names = {canonical(requirement.name) for requirement in requirements}
    for requirement in requirements:
        for extra in requirement.extras:
            for text in importlib.metadata.requires(requirement.name) or []:
                brought = Requirement(text)
                if brought.marker is not None and brought.marker.evaluate({"extra": extra}):
                    names.add(canonical(brought.name))
    return names


def undeclared(package: Path, pyproject: Path) -> list[str]:
    distributions = importlib.metadata.packages_distributions()
    declared = declared_distributions(pyproject)
    return [f"{name} (imported at {where})" for name, where in imported_packages(package).items()
            if name not in SYSTEM_PACKAGES
            and not {canonical(dist) for dist in distributions.get(name, [name])} & declared]


def test_every_package_primordia_imports_is_declared_or_the_systems():
    """h5py (every run's fields.xdmf, the mesh and run readers) was declared nowhere: not in pyproject.toml, not
    among the system packages the README names beside petsc4py and mpi4py.  pip cannot declare it (its wheel's
    own HDF5 fails beside dolfinx's), so it is the system's, and said so."""
    assert undeclared(ROOT / "primordia", ROOT / "pyproject.toml") == []
    assert "h5py" in SYSTEM_PACKAGES


PLUGINS = sorted(path.parent for path in (ROOT / "plugins").glob("*/pyproject.toml"))


@pytest.mark.parametrize("plugin", PLUGINS, ids=[path.name for path in PLUGINS])
def test_every_package_an_example_plugin_imports_is_declared(plugin):
    """The example plugins, "complete packages to copy" (docs/plugins.md), imported numpy, pluggy and ufl and
    declared only primordia: each was there only because primordia happens to depend on it too, which a plugin
    copied from them (or a later primordia) need not keep."""
    (package,) = tomllib.loads((plugin / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    assert undeclared(plugin / package, plugin / "pyproject.toml") == []


def test_the_wheel_holds_every_file_of_the_package(tmp_path):
    """A non-editable install has only what the wheel holds: primordia/analysis/README.md, which the
    package's docstring points to ("see README.md here"), was left out (setuptools ships modules only)."""
    tracked = subprocess.run(["git", "ls-files", "primordia"], cwd=ROOT, capture_output=True, text=True, check=True)
    source = tmp_path / "source"
    for name in ["pyproject.toml", "README.md", *tracked.stdout.split()]:
        (source / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(ROOT / name, source / name)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "--no-index",
                    "-w", tmp_path / "dist", source], capture_output=True, text=True, check=True, timeout=120)
    (wheel,) = (tmp_path / "dist").glob("primordia-*.whl")
    with zipfile.ZipFile(wheel) as archive:
        shipped = set(archive.namelist())
    assert [name for name in tracked.stdout.split() if name not in shipped] == []
    # the version is written once, in primordia.__version__ (it was written twice, in pyproject.toml too)
    import primordia

    assert wheel.name.startswith(f"primordia-{primordia.__version__}-"), wheel.name
