"""Loads through the gradient of a P1 test function from the cells' integrals (coupling/p1_gradient_load.py)
equal assembly."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import ufl

from primordia.coupling.p1_gradient_load import P1GradientLoad
from primordia.physics.active_stress import active_stress

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "support"))  # also under mpirun
from closed_forms import (BACKENDS, MESHES, assert_equal_to_assembly, check_on_ranks,  # noqa: E402
                          rotate_scalar_cell_dofs, run_on_two_ranks)


def _problem(backend, dimension: int, **options):
    """Example 1b's momentum load: the active stress of m on a mixed P1 (u, p) test function, a traction
    on ds, and a load on grad q (the pressure's test function)."""
    mesh = backend.create_mesh(MESHES[dimension]())
    cell = mesh.ufl_cell()
    mixed = backend.function_space(mesh, ufl.MixedElement([
        ufl.VectorElement("Lagrange", cell, options.get("degree", 1)), ufl.FiniteElement("Lagrange", cell, 1)]))
    scalar = backend.function_space(mesh, ufl.FiniteElement("Lagrange", cell, options.get("m_degree", 1)))
    m, f = backend.function(scalar, "m"), backend.function(scalar, "f")
    rng = np.random.default_rng(7)
    for field in (m, f):
        backend.local_array(field)[:] = rng.uniform(0.2, 1.5, backend.local_array(field).shape)
        backend.update_ghosts(field)
    w, q = ufl.split(ufl.TestFunction(mixed))
    dx = options["dx"](mesh) if "dx" in options else ufl.dx(domain=mesh)
    x = ufl.SpatialCoordinate(mesh)
    sigma = active_stress(m, 2.0, 3.0, 0.7, 1.2, dimension)
    form = (ufl.inner(sigma, ufl.grad(w)) * dx
            + (1.0 + x[0]) * ufl.exp(-f) * m * q.dx(dimension - 1) * dx
            + ufl.inner(ufl.as_vector([0.0] * (dimension - 1) + [2.5]), w) * ufl.ds(domain=mesh))
    return form + options["extra"](m, w, q) * dx if "extra" in options else form


@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("name", list(BACKENDS))
def test_the_per_cell_load_equals_the_assembled_vector(name, dimension):
    backend = BACKENDS[name]()
    form = _problem(backend, dimension)
    load = P1GradientLoad.recognise(backend, form)
    assert load is not None, "the active stress and the load on grad q are recognised; the traction is assembled"
    assert_equal_to_assembly(backend, form, load)
    assembled = backend.assemble_vector(form).getArray()
    mine = load.assemble(load.assemble()).getArray()  # into a vector it wrote before: the same values
    np.testing.assert_allclose(mine, assembled, rtol=0, atol=1e-13 * np.abs(assembled).max())


@pytest.mark.parametrize("name", list(BACKENDS))
def test_a_quadrature_degree_of_the_form_is_kept(name):
    backend = BACKENDS[name]()
    form = _problem(backend, 2, dx=lambda mesh: ufl.dx(domain=mesh, degree=1))
    load = P1GradientLoad.recognise(backend, form)
    assert load is not None
    assert_equal_to_assembly(backend, form, load)


@pytest.mark.parametrize("name", list(BACKENDS))
def test_what_is_not_a_gradient_load_is_assembled(name):
    backend = BACKENDS[name]()
    assert P1GradientLoad.recognise(backend, _problem(backend, 2, degree=2)) is None, "u in P2"
    assert P1GradientLoad.recognise(backend, _problem(backend, 2, m_degree=2)) is None, "m in P2"
    assert P1GradientLoad.recognise(backend, _problem(backend, 2, extra=lambda m, w, q: m * w[0])) is None, \
        "a load on w itself"
    gradients = _problem(backend, 2, extra=lambda m, w, q: ufl.dot(ufl.grad(m), ufl.grad(q)))
    assert P1GradientLoad.recognise(backend, gradients) is None, "a field's gradient"


@pytest.mark.parametrize("name", list(BACKENDS))
def test_positions_that_do_not_match_the_assembly_are_caught_before_use(name, monkeypatch):
    """The check against assembly guards the evaluation: a field's DOF positions out of vertex order fail it."""
    backend = BACKENDS[name]()
    form = _problem(backend, 2)
    rotate_scalar_cell_dofs(backend, monkeypatch)  # m's and f's vertices rotated
    assert P1GradientLoad.recognise(backend, form) is None


@pytest.mark.mpi
def test_the_per_cell_load_equals_assembly_on_two_ranks():
    run_on_two_ranks(Path(__file__).resolve())


if __name__ == "__main__":  # under mpirun: each rank's owned rows, ghost contributions summed to their owners
    check_on_ranks(_problem, P1GradientLoad.recognise)
