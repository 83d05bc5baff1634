"""Checking a backend's field index sets (``Backend.field_index_sets``) on a Taylor-Hood (u, psi, p) space.

Shared by ``tests/unit/test_field_splits.py`` (serial) and ``tests/regression/test_mpi_solvers.py``
(two ranks, in a subprocess that finds this module through ``PYTHONPATH``).
"""

from __future__ import annotations

import numpy as np
import ufl
from mpi4py import MPI

from primordia.backends.fenicsx import FenicsxBackend
from primordia.backends.skfem import SkfemBackend
from primordia.core.meshes import box, rectangle

BACKENDS = {"fenicsx": lambda: FenicsxBackend(MPI.COMM_WORLD), "skfem": lambda: SkfemBackend()}


def taylor_hood_with_pressure(backend, gdim: int):
    data = rectangle((0.0, 0.0), (2.0, 1.0), (4, 3)) if gdim == 2 else box((0.0, 0.0, 0.0), (2.0, 1.0, 1.0), (2, 2, 2))
    mesh = backend.create_mesh(data)
    cell = mesh.ufl_cell()
    element = ufl.MixedElement([ufl.VectorElement("Lagrange", cell, 2), ufl.FiniteElement("Lagrange", cell, 1),
                                ufl.FiniteElement("Lagrange", cell, 1)])
    return data, mesh, backend.function_space(mesh, element)


def check_field_index_sets(backend, gdim: int) -> None:
    """Every property of the index sets of (u, psi, p); runs on any number of ranks."""
    data, mesh, space = taylor_hood_with_pressure(backend, gdim)
    index_sets = backend.field_index_sets(space)
    assert len(index_sets) == 3
    state = backend.function(space, "state")
    vector = backend.petsc_vector(state)
    start, stop = vector.getOwnershipRange()
    local = [index_set.getIndices() for index_set in index_sets]
    for indices in local:
        assert np.all(np.diff(indices) > 0), "sorted, no repeats"
        assert np.all((indices >= start) & (indices < stop)), "owned DOFs only"
    owned = np.concatenate(local)
    assert len(owned) == len(np.unique(owned)) == stop - start, "disjoint and covering this rank's DOFs"
    p2_nodes = data.num_vertices + _num_edges(data)
    assert [index_set.getSize() for index_set in index_sets] == [gdim * p2_nodes, data.num_vertices,
                                                                 data.num_vertices]
    assert [index_set.getBlockSize() for index_set in index_sets] == [gdim, 1, 1]
    # each index set holds its field: u = (1, 2[, 3]), psi = 7, p = -5 read back through the sets
    backend.interpolate_component(state, 0, lambda x: np.outer(np.arange(1.0, gdim + 1.0), np.ones(x.shape[1])))
    backend.interpolate_component(state, 1, 7.0)
    backend.interpolate_component(state, 2, -5.0)
    values = vector.getArray(readonly=True)
    u = values[local[0] - start].reshape(-1, gdim)
    np.testing.assert_array_equal(u, np.broadcast_to(np.arange(1.0, gdim + 1.0), u.shape))
    np.testing.assert_array_equal(values[local[1] - start], 7.0)
    np.testing.assert_array_equal(values[local[2] - start], -5.0)


def _num_edges(data) -> int:
    cells = data.cells
    pairs = [(i, j) for i in range(cells.shape[1]) for j in range(i + 1, cells.shape[1])]
    edges = np.sort(np.vstack([cells[:, [i, j]] for i, j in pairs]), axis=1)
    return len(np.unique(edges, axis=0))
