"""The advection of P1 fields by a P1 velocity from its closed form (coupling/p1_advection.py) equals assembly."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import ufl
from mpi4py import MPI

from primordia.backends.fenicsx import FenicsxBackend
from primordia.backends.skfem import SkfemBackend
from primordia.core.meshes import box, rectangle
from primordia.coupling.p1_advection import P1Advection

BACKENDS = {"fenicsx": lambda: FenicsxBackend(MPI.COMM_WORLD), "skfem": lambda: SkfemBackend()}
MESHES = {2: lambda: rectangle([0.0, 0.0], [2.0, 1.5], [7, 5], diagonal="crossed"),
          3: lambda: box([0.0, 0.0, 0.0], [1.0, 1.2, 0.8], [3, 4, 2])}


def _problem(backend, dimension: int, **options):
    """Example 1b's shape: species advected by the P1 displacement rate of a mixed (u, p) field."""
    mesh = backend.create_mesh(MESHES[dimension]())
    cell = mesh.ufl_cell()
    velocity_element = ufl.VectorElement("Lagrange", cell, options.get("degree", 1))
    mixed = backend.function_space(mesh, ufl.MixedElement([velocity_element, ufl.FiniteElement("Lagrange", cell, 1)]))
    rate = backend.function(mixed, "rate")
    species = [backend.function(backend.function_space(mesh, ufl.FiniteElement("Lagrange", cell, 1)), name)
               for name in "mfb"]
    rng = np.random.default_rng(5)
    for field in (rate, *species):
        backend.local_array(field)[:] = rng.uniform(-1.0, 1.0, backend.local_array(field).shape)
        backend.update_ghosts(field)
    blocked = backend.function_space(mesh, ufl.VectorElement("Lagrange", cell, 1, dim=3))
    w = ufl.TestFunction(blocked)
    velocity = ufl.as_vector([rate[i] for i in range(dimension)])
    dx = options["dx"](mesh) if "dx" in options else ufl.dx(domain=mesh)
    form = sum(scale * w[k] * ufl.dot(velocity, ufl.grad(c)) * dx
               for k, (scale, c) in enumerate(zip((1.0, -2.5, 0.5), species)))
    return form + options["extra"](mesh) * w[0] * dx if "extra" in options else form


@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("name", list(BACKENDS))
def test_the_closed_form_equals_the_assembled_vector(name, dimension):
    backend = BACKENDS[name]()
    form = _problem(backend, dimension)
    closed = P1Advection.recognise(backend, form)
    assert closed is not None, "the three advection terms are recognised"
    assembled = backend.assemble_vector(form).getArray().copy()
    mine = closed.assemble().getArray()
    assert np.abs(assembled).max() > 1e-3
    np.testing.assert_allclose(mine, assembled, rtol=0, atol=1e-13 * np.abs(assembled).max())


@pytest.mark.parametrize("name", list(BACKENDS))
def test_what_is_not_a_p1_advection_is_assembled(name):
    backend = BACKENDS[name]()
    assert P1Advection.recognise(backend, _problem(backend, 2, degree=2)) is None, "u in P2"
    assert P1Advection.recognise(backend, _problem(backend, 2, dx=lambda mesh: ufl.dx(domain=mesh, degree=1))) is None
    assert P1Advection.recognise(backend, _problem(backend, 2, extra=lambda mesh: ufl.SpatialCoordinate(mesh)[0])) \
        is None, "another term"
    assert P1Advection.recognise(backend, _problem(backend, 2)) is not None


@pytest.mark.parametrize("name", list(BACKENDS))
def test_positions_that_do_not_match_the_assembly_are_caught_before_use(name, monkeypatch):
    """The check against assembly guards the closed form: DOF positions out of vertex order fail it."""
    backend = BACKENDS[name]()
    form = _problem(backend, 2)
    right = backend.p1_cell_dofs
    monkeypatch.setattr(backend, "p1_cell_dofs", lambda space, component=None: np.roll(right(space, component), 1, axis=1)
                        if component is None else right(space, component))  # the species' vertices rotated
    assert P1Advection.recognise(backend, form) is None


@pytest.mark.mpi
def test_the_closed_form_equals_assembly_on_two_ranks():
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    done = subprocess.run(["mpirun", "-n", "2", sys.executable, str(Path(__file__).resolve())], env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip() == "agree on 2 ranks", done.stdout


if __name__ == "__main__":  # under mpirun: each rank's owned rows, ghost contributions summed to their owners
    for dimension in (2, 3):
        backend = FenicsxBackend(MPI.COMM_WORLD)
        form = _problem(backend, dimension)
        closed = P1Advection.recognise(backend, form)
        assert closed is not None
        assembled = backend.assemble_vector(form).getArray().copy()
        mine = closed.assemble().getArray()
        scale = MPI.COMM_WORLD.allreduce(np.abs(assembled).max(), op=MPI.MAX)
        assert MPI.COMM_WORLD.allreduce(np.abs(mine - assembled).max(), op=MPI.MAX) <= 1e-13 * scale
    if MPI.COMM_WORLD.rank == 0:
        print(f"agree on {MPI.COMM_WORLD.size} ranks")
