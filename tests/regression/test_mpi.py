"""The fenicsx backend under MPI gives the serial answer (2 ranks vs 1)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ARGS = ["run", str(ROOT / "examples/ex01a.toml"), "--set", "mesh.cells=[24,24]", "--set", "time.t_final=10",
        "--set", "output.times=[10]", "--set", "output.pictures=false", "--no-progress"]
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}


def _run(tmp_path, ranks: int, name: str = "", extra: tuple = ()) -> dict:
    out = tmp_path / f"np{ranks}{name}"
    command = [sys.executable, "-m", "primordia.cli", *ARGS, *extra, "--out", str(out)]
    if ranks > 1:
        command = ["mpirun", "-n", str(ranks), *command]
    done = subprocess.run(command, env=ENV, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads((out / "summary.json").read_text())


@pytest.mark.mpi
def test_two_ranks_reproduce_the_serial_run(tmp_path):
    serial, parallel = _run(tmp_path, 1), _run(tmp_path, 2)
    assert parallel["mpi_ranks"] == 2 and parallel["steps"] == serial["steps"] == 50
    for name, stats in serial["final"].items():
        for key in ("integral", "min", "max"):
            assert parallel["final"][name][key] == pytest.approx(stats[key], rel=1e-10, abs=1e-12), (name, key)


@pytest.mark.mpi
def test_the_same_command_on_two_ranks_gives_the_same_numbers_each_time(tmp_path):
    """The mesh's partition is the same at every run (PT-SCOTCH on one thread per rank), so the Krylov
    iterates are too: with SCOTCH's threads, three runs of this command partitioned the mesh three ways
    and agreed only to the solvers' tolerance."""
    runs = [_run(tmp_path, 2, f"-{index}") for index in range(3)]
    for other in runs[1:]:
        assert other["final"] == runs[0]["final"]
        assert other["mean_linear_iterations"] == runs[0]["mean_linear_iterations"]


@pytest.mark.mpi
def test_pictures_shared_out_over_two_ranks_are_all_written(tmp_path):
    """Rank 0 gathers the fields and hands rank 1 some of the pictures (Pictures, _draw_shared): each
    snapshot's PNG of m and f, at the end their grids and final_fields.png, all whole PNG files."""
    _run(tmp_path, 2, extra=("--set", "output.pictures=true", "--set", "output.times=[4, 10]",
                             "--set", 'output.snapshot_fields=["m", "f"]'))
    out = tmp_path / "np2"
    expected = {"m_t0004.00.png", "m_t0010.00.png", "f_t0004.00.png", "f_t0010.00.png", "m_snapshots.png",
                "f_snapshots.png", "final_fields.png"}
    assert {path.name for path in out.glob("*.png")} == expected
    for name in expected:
        data = (out / name).read_bytes()
        assert data.startswith(b"\x89PNG\r\n\x1a\n") and data.endswith(b"IEND\xaeB`\x82"), name
    assert not [path.name for path in out.iterdir() if ".tmp-" in path.name]  # no picture left half-written
