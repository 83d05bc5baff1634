"""The Makefile's commands as the README states them: ``make demo`` can be run again."""

from __future__ import annotations

import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _recipe(target: str) -> list[list[str]]:
    """The commands ``make TARGET`` would run (``make -n``: printed, not run), split into words."""
    printed = subprocess.run(["make", "-n", "-s", target], cwd=ROOT, capture_output=True, text=True, check=True)
    return [shlex.split(line) for line in printed.stdout.splitlines() if line.strip()]


@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
def test_make_demo_runs_again_into_the_folder_its_last_run_filled(primordia_cli, tmp_path):
    """The README: both commands "are idempotent". A second ``make demo`` found out/ex01a holding the
    first one's run and stopped with exit status 2 (a run into a folder holding one is refused without
    --overwrite). The demo's own command, on a coarse mesh, twice in the same folder."""
    runs = [words for words in _recipe("demo") if words[:2] == [".venv/bin/primordia", "run"]]
    assert len(runs) == 1, runs
    args = [str(ROOT / word) if word.endswith(".toml") else word for word in runs[0][1:]]
    coarse = ["--set", "mesh.cells=[4,4]", "--set", "time.t_final=0.4", "--set", "output.times=[0.4]",
              "--set", "output.pictures=false", "--no-progress"]
    for attempt in ("first", "second"):
        result = primordia_cli(*args, *coarse, cwd=tmp_path)
        assert result.returncode == 0, (attempt, result.stderr)
    assert (tmp_path / "out" / "ex01a" / "summary.json").is_file()


@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
def test_make_help_lists_every_target_with_what_it_does():
    phony = next(line for line in (ROOT / "Makefile").read_text().splitlines() if line.startswith(".PHONY:"))
    listed = subprocess.run(["make", "-s", "help"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    described = {line.split()[1]: line.split(None, 2)[2] for line in listed.splitlines()}
    assert set(described) == set(phony.split()[1:]), listed
    assert all(text.strip() for text in described.values()), listed
