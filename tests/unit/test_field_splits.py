"""The backends' field index sets (``Backend.field_index_sets``): what PETSc's fieldsplit is handed.

Checked on both backends with a Taylor-Hood (u, psi, p) space, in 2D and 3D: one sorted index set
per field, disjoint, covering every DOF, the displacement's with the block size of its components,
and each holding exactly the DOFs of its field (a field set to a known value is read back through
its index set).  ``tests/regression/test_mpi_solvers.py`` runs the same checks on two ranks.
"""

from __future__ import annotations

import pytest
import ufl

from primordia.core.meshes import rectangle

from field_splits import BACKENDS, check_field_index_sets, taylor_hood_with_pressure


@pytest.mark.parametrize("gdim", [2, 3])
@pytest.mark.parametrize("name", list(BACKENDS))
def test_taylor_hood_fields_have_sorted_disjoint_index_sets_holding_their_values(name, gdim):
    check_field_index_sets(BACKENDS[name](), gdim)


@pytest.mark.parametrize("name", list(BACKENDS))
def test_a_space_that_is_not_mixed_is_one_field(name):
    backend = BACKENDS[name]()
    mesh = backend.create_mesh(rectangle((0.0, 0.0), (1.0, 1.0), (3, 3)))
    vector_space = backend.function_space(mesh, ufl.VectorElement("Lagrange", mesh.ufl_cell(), 1))
    (index_set,) = backend.field_index_sets(vector_space)
    assert index_set.getSize() == backend.num_dofs(vector_space) == 32
    assert index_set.getBlockSize() == 2
    scalar_space = backend.function_space(mesh, ufl.FiniteElement("Lagrange", mesh.ufl_cell(), 2))
    (index_set,) = backend.field_index_sets(scalar_space)
    assert index_set.getSize() == backend.num_dofs(scalar_space) and index_set.getBlockSize() == 1


def test_both_backends_split_the_same_numbers_of_dofs():
    sizes = {}
    for name, make in BACKENDS.items():
        backend = make()
        sizes[name] = [s.getSize() for s in backend.field_index_sets(taylor_hood_with_pressure(backend, 2)[2])]
    assert sizes["fenicsx"] == sizes["skfem"]
