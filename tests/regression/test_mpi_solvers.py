"""The solver layer under MPI: field index sets on two ranks, and the 3D growth example with the seed's
block preconditioner on 1, 2 and 3 ranks giving the same answer (to the solvers' tolerance), whatever
the partition."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
       "PYTHONPATH": str(ROOT / "tests" / "support")}  # the field-split checker


def mpirun(ranks: int, *command: str, timeout: float = 600) -> subprocess.CompletedProcess:
    full = ["mpirun", "--oversubscribe", "-n", str(ranks), *command] if ranks > 1 else list(command)
    done = subprocess.run(full, env=ENV, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, done.stderr[-3000:]
    return done


@pytest.mark.mpi
def test_field_index_sets_on_two_ranks():
    script = ("from field_splits import check_field_index_sets, BACKENDS\n"
              "for gdim in (2, 3):\n"
              "    check_field_index_sets(BACKENDS['fenicsx'](), gdim)\n"
              "from mpi4py import MPI\n"
              "sizes = MPI.COMM_WORLD.gather(MPI.COMM_WORLD.size)\n"
              "if MPI.COMM_WORLD.rank == 0: print('ranks', sizes)\n")  # one writer: ranks' prints interleave
    done = mpirun(2, sys.executable, "-c", script)
    assert done.stdout.strip() == "ranks [2, 2]"


# example 4 at 4 x 4 x 2 boxes, two steps, the Schur fieldsplit (the 3D default) with tight Newton tolerances
EX04 = ["run", str(ROOT / "examples/ex04_small.toml"), "--set", "mesh.cells=[4,4,2]", "--set", "time.t_final=1.0",
        "--set", "output.times=[1.0]", "--set", "output.pictures=false", "--set", "coupling.tolerance=1e-10",
        "--set", "solver.poroelastic_growth.snes_rtol=1e-11", "--set", "solver.poroelastic_growth.snes_atol=1e-12",
        "--no-progress"]


def _run_ex04(tmp_path, ranks: int) -> dict:
    out = tmp_path / f"np{ranks}"
    mpirun(ranks, sys.executable, "-m", "primordia.cli", *EX04, "--out", str(out))
    return json.loads((out / "summary.json").read_text())


@pytest.mark.mpi
def test_3d_growth_with_the_block_preconditioner_does_not_depend_on_the_ranks(tmp_path):
    runs = {ranks: _run_ex04(tmp_path, ranks) for ranks in (1, 2, 3)}
    serial = runs[1]
    assert serial["mean_linear_iterations"]["poroelastic_growth"] > 3 * serial["mean_newton_iterations"][
        "poroelastic_growth"], "the fieldsplit iterates (it is not a direct solve)"
    for ranks in (2, 3):
        parallel = runs[ranks]
        assert parallel["mpi_ranks"] == ranks and parallel["steps"] == serial["steps"] == 2
        for name, stats in serial["final"].items():
            for key in ("integral", "min", "max"):
                assert parallel["final"][name][key] == pytest.approx(stats[key], rel=1e-7, abs=1e-10), \
                    (ranks, name, key)


@pytest.mark.mpi
def test_the_fitted_operator_takes_its_values_by_rows_on_two_ranks(tmp_path):
    """Example 1a's fitted cell-transport operator on 2 ranks: a matrix made from its CSR rows, whose values an
    update copies in (MatUpdateMPIAIJWithArray), equal, entry by entry, to the values the update computed."""
    script = f"""
import numpy as np
from primordia import Model
from primordia.core.config import apply_overrides, load_config
config = apply_overrides(load_config({str(ROOT / "examples/ex01a.toml")!r}),
                         ["mesh.cells=[12,12]", "time.t_final=0.4", "output.times=[0.4]", "output.pictures=false"])
sim = Model.from_config(config).run(backend="fenicsx", out={str(tmp_path / "out")!r})
(operator,) = sim.model.physics_objects[0]._fitted_operators.values()
assert operator._by_rows, "2 ranks: the operator is a matrix made from its rows"
in_blocks = operator._blocks  # the compiled loops' writes straight into the blocks (test_mpi.py)
operator._blocks = None  # the values computed into _values, then copied in by rows
operator.update()
indptr, columns, values = operator.matrix().getValuesCSR()
np.testing.assert_array_equal(indptr, operator._indptr)
np.testing.assert_array_equal(columns, operator._columns)
np.testing.assert_array_equal(values, operator._values)
assert np.abs(values).max() > 0
if in_blocks is not None:
    operator._blocks = in_blocks
    operator.update()
    np.testing.assert_array_equal(operator.matrix().getValuesCSR()[2], values)
from mpi4py import MPI
if MPI.COMM_WORLD.rank == 0: print("checked on", MPI.COMM_WORLD.size, "ranks")
"""
    done = mpirun(2, sys.executable, "-c", script)
    assert done.stdout.strip() == "checked on 2 ranks"


@pytest.mark.mpi
def test_vertex_extrema_on_two_ranks_are_those_of_the_gathered_vertex_values():
    """The series' min and max are reduced over each rank's own vertices: on 2 ranks they must be the
    extrema of the whole field gathered on rank 0, for a P1 field and both parts of a Taylor-Hood one."""
    script = """
import numpy as np, ufl
from mpi4py import MPI
from primordia.backends.fenicsx import FenicsxBackend
from primordia.core.meshes import rectangle
backend = FenicsxBackend()
mesh = backend.create_mesh(rectangle((0, 0), (1, 1), (9, 7)))
cell = mesh.ufl_domain().ufl_cell()
scalar = backend.function(backend.function_space(mesh, ufl.FiniteElement("Lagrange", cell, 1)), "s")
backend.interpolate(scalar, lambda x: np.sin(7 * x[0]) * x[1])
mixed = backend.function(backend.function_space(mesh, ufl.MixedElement(
    [ufl.VectorElement("Lagrange", cell, 2), ufl.FiniteElement("Lagrange", cell, 1)])), "w")
backend.interpolate_component(mixed, 0, lambda x: np.stack([np.cos(5 * x[0]), x[1] - 3 * x[0]]))
backend.interpolate_component(mixed, 1, lambda x: x[0] * x[1] - 0.25)
comm = MPI.COMM_WORLD
wrong = []  # every rank runs every collective, then all report: an assertion on one rank would hang the other
for function, component in [(scalar, None), (mixed, 0), (mixed, 1)]:
    values = backend.vertex_values(function, component)
    whole = comm.bcast((values.min(), values.max()) if comm.rank == 0 else None)
    extrema = backend.vertex_extrema(function, component)
    if extrema != whole:
        wrong.append((component, extrema, whole))
    owned = function.function_space.dofmap.index_map.size_local
    if comm.allreduce(owned) == owned:
        wrong.append("the vertices are not split between the ranks")
wrong = comm.gather(wrong)
if comm.rank == 0: print("checked on", comm.size, "ranks", wrong)
"""
    done = mpirun(2, sys.executable, "-c", script)
    assert done.stdout.strip() == "checked on 2 ranks [[], []]"
