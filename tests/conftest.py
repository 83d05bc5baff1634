"""Fixtures shared by the test tiers: the real ``primordia`` command, small configs, plugin distributions."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from small_config import SMALL_CONFIG

#: The console script installed next to this interpreter (the CLI a user runs).
PRIMORDIA = Path(sys.executable).parent / "primordia"


@pytest.fixture
def primordia_cli():
    """``primordia_cli(*args, env=..., cwd=...)`` runs the installed ``primordia`` command."""
    assert PRIMORDIA.is_file(), f"the primordia console script is not installed at {PRIMORDIA}"

    def run(*args, env: dict | None = None, cwd: Path | None = None, timeout: float = 120):
        return subprocess.run([str(PRIMORDIA), *map(str, args)], capture_output=True, text=True,
                              env=env, cwd=cwd, timeout=timeout)

    return run


@pytest.fixture
def small_config(tmp_path):
    """``small_config(text=..., name=...)`` writes a config file and returns its path.

    ``small_config.text`` is the default: :data:`SMALL_CONFIG`.
    """

    def write(text: str = SMALL_CONFIG, name: str = "small.toml") -> Path:
        path = tmp_path / name
        path.write_text(text)
        return path

    write.text = SMALL_CONFIG  # the default text, for tests that vary it
    return write


@pytest.fixture
def plugin_distribution(tmp_path):
    """Install a plugin distribution the way pip would, into a directory for ``PYTHONPATH``.

    ``plugin_distribution(name, version, modules={module: source}, entry_points={entry: target})``
    writes the modules and ``<name>-<version>.dist-info/{METADATA, entry_points.txt}``
    (group ``primordia``) into one directory and returns an environment for
    ``subprocess`` with that directory on ``PYTHONPATH``.  Calls accumulate.
    """
    site = tmp_path / "site-packages"
    site.mkdir()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(site), os.environ.get("PYTHONPATH")]))}

    def install(name: str, version: str, modules: dict[str, str], entry_points: dict[str, str]) -> dict:
        for module, source in modules.items():
            (site / f"{module}.py").write_text(textwrap.dedent(source))
        dist_info = site / f"{name.replace('-', '_')}-{version}.dist-info"
        dist_info.mkdir()
        (dist_info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
        lines = "".join(f"{entry} = {target}\n" for entry, target in entry_points.items())
        (dist_info / "entry_points.txt").write_text(f"[primordia]\n{lines}")
        return env

    return install
