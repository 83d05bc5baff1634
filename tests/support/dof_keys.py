"""Matching DOFs between backends: each DOF keyed by (value component, node coordinates)."""

import numpy as np
import ufl


def dolfinx_dof_keys(space, gdim: int) -> np.ndarray:
    """(component, node coordinates) of each DOF of a dolfinx space."""
    size = space.dofmap.index_map.size_local * space.dofmap.index_map_bs
    keys = np.empty((size, 1 + gdim))
    leaves = []

    def visit(sub, element):
        if isinstance(element, ufl.MixedElement):  # vector, tensor and mixed elements
            for i, sub_element in enumerate(element.sub_elements()):
                visit(sub.sub(i), sub_element)
        else:
            leaves.append(sub)

    visit(space, space.ufl_element())
    for component, leaf in enumerate(leaves):
        collapsed, parent = (space, np.arange(size)) if leaf is space else leaf.collapse()
        parent = np.asarray(parent)
        keys[parent, 0] = component
        keys[parent, 1:] = collapsed.tabulate_dof_coordinates()[:, :gdim]
    return keys


def skfem_dof_keys(space) -> np.ndarray:
    return np.column_stack([space.dof_component, space.dof_coordinates.T])


def dof_keys(backend_name: str, space, gdim: int) -> np.ndarray:
    """(value component, node coordinates) of every DOF of a space, in the backend's numbering."""
    return skfem_dof_keys(space) if backend_name == "skfem" else dolfinx_dof_keys(space, gdim)
