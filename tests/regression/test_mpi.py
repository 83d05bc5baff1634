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


SHIFTED = """
import numpy as np, scipy.sparse
from mpi4py import MPI
from primordia.backends.fenicsx import FenicsxBackend
from primordia.core.meshes import rectangle
from primordia.physics.base import FieldSpec
from primordia.physics.discretisation import Discretisation
from primordia.physics.edge_flux import ExponentiallyFittedFlux

disc = Discretisation(FenicsxBackend(MPI.COMM_WORLD), rectangle((0.0, 0.0), (2.0, 1.0), (14, 8)))
for name in ("m", "f"):
    disc.add_group(name, [FieldSpec(name)], owners={name: "test"})
disc.backend.interpolate(disc.previous("m"), lambda x: 2.0 + np.sin(3.0 * x[0]) * np.cos(2.0 * x[1]))
disc.backend.interpolate(disc.previous("f"), lambda x: 1.5 + np.cos(5.0 * x[0] + x[1]))
operator = ExponentiallyFittedFlux(disc, "m", "f", diffusivity=0.05, sensitivity=lambda m: 4.0 * np.exp(-m))
operator.update()

def rows(matrix):  # this rank's rows, all columns
    indptr, columns, values = matrix.getValuesCSR()
    return scipy.sparse.csr_matrix((values, columns, indptr), shape=(matrix.getLocalSize()[0], matrix.getSize()[1])).toarray()

A = rows(operator.matrix())
diagonal = operator.matrix().createVecLeft()
diagonal.setArray(np.linspace(1.0, 2.0, diagonal.getLocalSize()))
start, end = operator.matrix().getOwnershipRange()
expected = A.copy()
expected[np.arange(end - start), np.arange(start, end)] += diagonal.getArray()
shifted = operator.shifted(diagonal)
assert shifted is not None
assert np.allclose(rows(shifted), expected, rtol=1e-15, atol=0.0)
assert np.allclose(rows(operator.matrix()), A, rtol=1e-15, atol=1e-15)
operator.shifted(diagonal)
operator.update()  # rewrites every value: no shift left
assert np.allclose(rows(operator.matrix()), A, rtol=1e-15, atol=1e-15)
ranks = MPI.COMM_WORLD.gather(MPI.COMM_WORLD.size)
if MPI.COMM_WORLD.rank == 0:
    print("ranks", ranks)
"""


@pytest.mark.mpi
def test_the_fitted_operator_is_shifted_in_place_on_two_ranks():
    """On several ranks too, ``shifted(d)`` adds the cell density's lumped mass to the operator's own
    parallel matrix (no copy for the solver); ``matrix()`` is A again, and so is the next update."""
    done = subprocess.run(["mpirun", "-n", "2", sys.executable, "-c", SHIFTED], env=ENV, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "ranks [2, 2]"


BY_RUNS = """
import numpy as np
from mpi4py import MPI
from primordia.backends.fenicsx import FenicsxBackend
from primordia.core.meshes import rectangle
from primordia.physics.base import FieldSpec
from primordia.physics.discretisation import Discretisation
from primordia.physics.edge_flux import ExponentiallyFittedFlux

disc = Discretisation(FenicsxBackend(MPI.COMM_WORLD), rectangle((0.0, 0.0), (2.0, 1.0), (14, 8)))
for name in ("m", "f"):
    disc.add_group(name, [FieldSpec(name)], owners={name: "test"})
operator = ExponentiallyFittedFlux(disc, "m", "f", diffusivity=0.05, sensitivity=lambda m: 4.0 * np.exp(-m))
runs = None
for shift in (0.0, 0.7, 1.3):
    disc.backend.interpolate(disc.previous("m"), lambda x: 2.0 + np.sin(3.0 * x[0] + shift) * np.cos(2.0 * x[1]))
    disc.backend.interpolate(disc.previous("f"), lambda x: 1.5 + np.cos(5.0 * x[0] + x[1] - shift))
    operator._blocks = runs
    operator.update()
    runs = operator._blocks
    assert runs is not None, "the values were not written into the blocks"
    indptr, columns, by_runs = operator.matrix().getValuesCSR()
    operator._blocks = None  # MatUpdateMPIAIJWithArray, as before
    operator.update()
    assert np.array_equal(operator.matrix().getValuesCSR()[2], by_runs)
    assert np.array_equal(by_runs, operator._values) and np.abs(by_runs).max() > 0
    operator._blocks = runs  # straight into the blocks again: every value rewritten, _values not read
    operator._values[:] = np.nan
    operator.update()
    assert np.array_equal(operator.matrix().getValuesCSR()[2], by_runs)
    assert np.isnan(operator._values).all(), "the values went through _values, not straight into the blocks"
    operator._scaled_weights = operator._scaled_weights * (1.0 + shift)  # new weights, as a moving mesh's
    operator.update()
    by_blocks = operator.matrix().getValuesCSR()[2]
    operator._blocks = None
    operator.update()
    assert np.array_equal(operator.matrix().getValuesCSR()[2], by_blocks)
    assert shift == 0.0 or not np.allclose(by_blocks, by_runs)
ranks = MPI.COMM_WORLD.gather(MPI.COMM_WORLD.size)
if MPI.COMM_WORLD.rank == 0:
    print("ranks", ranks)
"""


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_the_fitted_operator_s_values_reach_the_parallel_matrix_s_blocks(ranks):
    """On several ranks each update writes the fitted operator's values straight into PETSc's diagonal and
    off-diagonal blocks, at the places ``BlockPlaces`` numbers: the same matrix as ``MatUpdateMPIAIJWithArray``
    gave, update after update, and after the weights change."""
    done = subprocess.run(["mpirun", "--oversubscribe", "-n", str(ranks), sys.executable, "-c", BY_RUNS], env=ENV,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == f"ranks {[ranks] * ranks}"


@pytest.mark.mpi
def test_a_first_run_with_an_empty_jit_cache_runs_on_two_ranks(tmp_path):
    """FFCx replaced the mesh's coordinate element by an equispaced one in each form it compiled: on rank 0
    alone when the JIT cache lacked the form (the other ranks then read it from the cache), so the forms built
    after it differed between the ranks and the run was refused, "chemotaxis.m: its equations differ between
    MPI ranks", at a batch job's first run with its own XDG_CACHE_HOME or with a growth parameter never run."""
    env = {**ENV, "XDG_CACHE_HOME": str(tmp_path / "empty_cache"),
           "PRIMORDIA_CACHE_DIR": os.environ.get("PRIMORDIA_CACHE_DIR") or str(Path.home() / ".cache/primordia")}
    command = ["mpirun", "-n", "2", sys.executable, "-m", "primordia.cli", *ARGS, "--set", "mesh.cells=[4,4]",
               "--set", "time.t_final=0.4", "--set", "output.times=[0.4]", "--out", str(tmp_path / "out")]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["status"] == "completed"
