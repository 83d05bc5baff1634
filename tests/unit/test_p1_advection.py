"""The advection of P1 fields by a P1 velocity from its closed form (coupling/p1_advection.py) equals assembly."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import ufl

from primordia.coupling.p1_advection import P1Advection

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "support"))  # also under mpirun
from closed_forms import (BACKENDS, MESHES, assert_equal_to_assembly, check_on_ranks,  # noqa: E402
                          rotate_scalar_cell_dofs, run_on_two_ranks)


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
    assert_equal_to_assembly(backend, form, closed)


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
    rotate_scalar_cell_dofs(backend, monkeypatch)  # the species' vertices rotated
    assert P1Advection.recognise(backend, form) is None


@pytest.mark.mpi
def test_the_closed_form_equals_assembly_on_two_ranks():
    run_on_two_ranks(Path(__file__).resolve())


if __name__ == "__main__":  # under mpirun: each rank's owned rows, ghost contributions summed to their owners
    check_on_ranks(_problem, P1Advection.recognise)
