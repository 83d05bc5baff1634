"""What the tests of the closed-form assemblies (coupling/p1_advection.py, coupling/p1_gradient_load.py) share:
the backends, the meshes, and the same check on two ranks (each rank's owned rows, ghost contributions summed
to their owners)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
from mpi4py import MPI

from primordia.backends.fenicsx import FenicsxBackend
from primordia.backends.skfem import SkfemBackend
from primordia.core.meshes import box, rectangle

BACKENDS = {"fenicsx": lambda: FenicsxBackend(MPI.COMM_WORLD), "skfem": lambda: SkfemBackend()}
MESHES = {2: lambda: rectangle([0.0, 0.0], [2.0, 1.5], [7, 5], diagonal="crossed"),
          3: lambda: box([0.0, 0.0, 0.0], [1.0, 1.2, 0.8], [3, 4, 2])}


def assert_equal_to_assembly(backend, form, closed) -> None:
    """``closed.assemble()`` is ``form``'s assembled vector to 1e-13 of its largest entry (over the ranks)."""
    assembled = backend.assemble_vector(form).getArray().copy()
    mine = closed.assemble().getArray()
    scale = backend.comm.allreduce(np.abs(assembled).max(initial=0.0), op=MPI.MAX)
    assert scale > 1e-3
    assert backend.comm.allreduce(np.abs(mine - assembled).max(initial=0.0), op=MPI.MAX) <= 1e-13 * scale


def rotate_scalar_cell_dofs(backend, monkeypatch) -> None:
    """The backend's ``p1_cell_dofs`` of scalar spaces with every cell's vertices rotated (out of vertex order);
    those of a component of a vector or mixed space as they are."""
    right = backend.p1_cell_dofs
    monkeypatch.setattr(backend, "p1_cell_dofs", lambda space, component=None: right(space, component)
                        if component is not None else np.roll(right(space, component), 1, axis=1))


def run_on_two_ranks(script) -> None:
    """Run ``script`` (a test file whose ``__main__`` calls :func:`check_on_ranks`) under ``mpirun -n 2``."""
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    done = subprocess.run(["mpirun", "-n", "2", sys.executable, str(script)], env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip() == "agree on 2 ranks", done.stdout


def check_on_ranks(problem, recognise) -> None:
    """In 2D and 3D on the FEniCSx backend over this communicator: ``recognise(backend, problem(backend, d))``
    is found and equals assembly; prints the line :func:`run_on_two_ranks` expects."""
    for dimension in (2, 3):
        backend = FenicsxBackend(MPI.COMM_WORLD)
        form = problem(backend, dimension)
        closed = recognise(backend, form)
        assert closed is not None
        assert_equal_to_assembly(backend, form, closed)
    if MPI.COMM_WORLD.rank == 0:
        print(f"agree on {MPI.COMM_WORLD.size} ranks")
