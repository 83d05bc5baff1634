"""Loads that read only constants, from vectors assembled once (coupling/constant_load.py), equal assembly."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import ufl

from primordia.coupling.constant_load import ConstantLoad

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "support"))  # also under mpirun
from closed_forms import (BACKENDS, MESHES, assert_equal_to_assembly, check_on_ranks,  # noqa: E402
                          run_on_two_ranks)


def _problem(backend, dimension: int, extra=None, time: float = 0.0):
    """(form, its time constant): example 1b's traction, t = (0, s0 sin(pi t / t_hat)) on ds of a mixed P1
    (u, p) test function (zero at t = 0), and a source on the pressure's test function over dx."""
    mesh = backend.create_mesh(MESHES[dimension]())
    cell = mesh.ufl_cell()
    mixed = backend.function_space(mesh, ufl.MixedElement([ufl.VectorElement("Lagrange", cell, 1),
                                                           ufl.FiniteElement("Lagrange", cell, 1)]))
    w, q = ufl.split(ufl.TestFunction(mixed))
    clock = backend.constant(mesh, time)
    traction = ufl.as_vector([0.0] * (dimension - 1) + [1500.0 * ufl.sin(np.pi * clock / 320.0)])
    form = ufl.inner(traction, w) * ufl.ds(domain=mesh) + (2.0 + clock**2) * q * ufl.dx(domain=mesh)
    if extra is not None:
        form += extra(mesh, w, q, clock)
    return form, clock


@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("name", list(BACKENDS))
def test_the_combined_vectors_equal_assembly_as_the_constants_change(name, dimension):
    backend = BACKENDS[name]()
    form, clock = _problem(backend, dimension, time=0.0)
    load = ConstantLoad.recognise(backend, form)
    assert load is not None
    assert float(clock.value) == 0.0, "the check restores the constants"
    for time in (37.0, 160.0, 301.5):
        clock.value = time
        assert_equal_to_assembly(backend, form, load)


@pytest.mark.parametrize("name", list(BACKENDS))
def test_what_reads_more_than_constants_is_assembled(name):
    backend = BACKENDS[name]()

    def field(mesh, w, q, clock):
        m = backend.function(backend.function_space(mesh, ufl.FiniteElement("Lagrange", mesh.ufl_cell(), 1)), "m")
        return m * q * ufl.dx(domain=mesh)

    others = {
        "a field": field,
        "a facet normal": lambda mesh, w, q, clock: clock * ufl.dot(ufl.FacetNormal(mesh), w) * ufl.ds(domain=mesh),
        "a coordinate": lambda mesh, w, q, clock: ufl.SpatialCoordinate(mesh)[0] * q * ufl.dx(domain=mesh),
        "the test function's gradient": lambda mesh, w, q, clock: clock * ufl.div(w) * ufl.dx(domain=mesh),
    }
    for what, extra in others.items():
        assert ConstantLoad.recognise(backend, _problem(backend, 2, extra)[0]) is None, what
    assert ConstantLoad.recognise(backend, _problem(backend, 2)[0]) is not None


@pytest.mark.mpi
def test_the_combined_vectors_equal_assembly_on_two_ranks():
    run_on_two_ranks(Path(__file__).resolve())


if __name__ == "__main__":  # under mpirun: each rank's owned rows
    check_on_ranks(lambda backend, dimension: _problem(backend, dimension, time=37.0)[0], ConstantLoad.recognise)
