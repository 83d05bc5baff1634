"""scikit-fem behind the common assembly interface: serial, pip-installable.

The same UFL forms the FEniCSx backend compiles with FFCx are evaluated here
with numpy at FFCx's quadrature points (:mod:`primordia.backends.ufl_numpy`),
on scikit-fem meshes, elements and DOF numberings, and assembled into PETSc
objects.  No dolfinx is needed (basix is used for FFCx's quadrature points when
present).  Nothing physical lives here.

DOF numbering
-------------
A space's DOFs are numbered by scikit-fem (:class:`skfem.assembly.Dofs` of the
scikit-fem element matching the UFL element: ``ElementTriP1``...,
``ElementVector`` for vector/tensor elements, ``ElementComposite`` for mixed
ones).  Consequences: P1 DOFs are the MeshData vertices in their order; a
vector P1 DOF is ``vertex * dim + component`` (dolfinx's blocked layout); P2
DOFs list vertices first, then edges; mixed spaces interleave their parts
entity by entity.  Internally each space is split into *blocks*, one per scalar
component (component index in the flattened value shape, scalar scikit-fem
element, and its cell -> DOF map), which is all the evaluator needs.

Geometry is affine: Jacobians come from the MeshData cells in their own vertex
order, the same order dolfinx keeps, so quadrature points coincide with FFCx's.
"""

from __future__ import annotations

import functools
import os
import weakref
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import skfem
import ufl
from petsc4py import PETSc
from scipy.sparse import csr_matrix

from primordia.backends.ufl_numpy import (
    REFERENCE_VERTICES,
    REFERENCE_VOLUMES,
    ArgumentBlock,
    IntegralPlan,
    UnsupportedUFL,
    cell_quantities,
    evaluate_integrand,
    forget_analyses,
    integrate_blocks,
    preprocess_form,
    reference_quadrature,
    unsupported,
)
from primordia.core.backend import Backend, BoundaryCondition, FormCache, index_set, sub_elements
from primordia.core.errors import MeshError, PrimordiaError
from primordia.core.mesh_data import MeshData

CELL_NAMES = {2: "triangle", 3: "tetrahedron"}
FACET_NAMES = {"triangle": "interval", "tetrahedron": "triangle"}
_SKFEM_MESHES = {"triangle": skfem.MeshTri1, "tetrahedron": skfem.MeshTet1}
_LAGRANGE = {
    ("triangle", 1): skfem.ElementTriP1, ("triangle", 2): skfem.ElementTriP2,
    ("tetrahedron", 1): skfem.ElementTetP1, ("tetrahedron", 2): skfem.ElementTetP2,
}
_PIECEWISE_CONSTANT = {"triangle": skfem.ElementTriP0, "tetrahedron": skfem.ElementTetP0}


def _facet_vertices(tdim: int) -> np.ndarray:
    """Local vertices of each local facet: facet ``i`` is opposite vertex ``i`` (basix / FFCx numbering)."""
    return np.array([[v for v in range(tdim + 1) if v != i] for i in range(tdim + 1)])


def _reference_normals(tdim: int) -> np.ndarray:
    """Outward normals (not normalised) of the reference cell's facets, same numbering."""
    return np.vstack([np.ones((1, tdim)), -np.eye(tdim)])


#: Cells per chunk are chosen so that the element tensors (cells x test x trial) and an array
#: of test x trial values per point, but at most _POINT_VALUES (a node of a tangent's integrand
#: holds test x trial directions x a tensor, about as many), stay below this (32 MB).
_CHUNK_VALUES = 2 ** 22
_POINT_VALUES = 256

#: Preprocessed forms kept (a physics module reuses a handful of forms at every step).
_CACHED_FORMS = 256


class _SerialComm:
    """Stands in for ``MPI.COMM_WORLD`` when mpi4py is not installed."""

    rank = 0
    size = 1

    def allreduce(self, value, op=None):
        return value

    def gather(self, value, root=0):
        return [value]

    def allgather(self, value):
        return [value]

    def bcast(self, value, root=0):
        return value

    def Barrier(self):
        pass


# ---------------------------------------------------------------------------------------
# Mesh
# ---------------------------------------------------------------------------------------


class _FieldValues:
    """Fields interpolated to the quadrature points of a run of cells, kept across forms while the
    field's DOF values stay the same.

    Every form that reads a field interpolates it anew (0.5-1 ms per field and derivative order
    on the 58,482 cells of the seed's 2D mesh), and the forms of one step read the same fields:
    in example 1b the solid velocity and its gradient enter the advection of m, f and b, and 100
    of 190 interpolations in its first 10 steps had been done before on the same values.  An
    entry is used only while the field's DOF values equal the copy kept with it: they are
    compared, not tracked, since solvers write into the same memory through PETSc.  The entries
    used longest ago go once all hold more than :attr:`LIMIT` bytes.  Values handed out are
    read-only: a form that reads them must not change them for the next.
    """

    LIMIT = 256 * 2 ** 20

    def __init__(self):
        self._entries: OrderedDict[tuple, tuple] = OrderedDict()
        self._bytes = 0

    def get(self, function: "SkfemFunction", derivatives: int, rule: "_Rule", cells: slice, compute,
            components: tuple[int, int] | None = None) -> np.ndarray:
        """The values ``compute()`` gives for ``function`` (or its flat value ``components``, first and stop)
        on ``cells`` at ``rule``'s points, reused when current."""
        key = (id(function), derivatives, id(rule), cells.start, cells.stop, components)
        entry = self._entries.get(key)
        if entry is not None and entry[0] is function and entry[1] is rule and np.array_equal(entry[2], function.array):
            self._entries.move_to_end(key)
            return entry[3]
        if entry is not None:
            self._drop(key)
        values = compute()
        values.flags.writeable = False
        snapshot = function.array.copy()
        self._entries[key] = (function, rule, snapshot, values)
        self._bytes += snapshot.nbytes + values.size * values.itemsize
        while self._bytes > self.LIMIT and len(self._entries) > 1:
            self._drop(next(iter(self._entries)))
        return values

    def _drop(self, key: tuple) -> None:
        _, _, snapshot, values = self._entries.pop(key)
        self._bytes -= snapshot.nbytes + values.size * values.itemsize

    def __len__(self) -> int:
        return len(self._entries)


class SkfemMesh(ufl.Mesh):
    """A ``ufl.Mesh`` carrying the scikit-fem mesh, its MeshData and affine cell geometry."""

    def __init__(self, data: MeshData):
        self.cellname = CELL_NAMES[data.gdim]
        super().__init__(ufl.VectorElement("Lagrange", ufl.Cell(self.cellname), 1))
        self.mesh_data = data
        self.tdim = self.gdim = data.gdim
        # sort_t=False keeps the MeshData vertex order inside each cell (as dolfinx does)
        self.skfem = _SKFEM_MESHES[self.cellname](data.points.T.copy(), data.cells.T.copy(), sort_t=False)
        vertices = data.points[data.cells]                         # (C, tdim + 1, gdim)
        self.origin = vertices[:, 0, :]                            # (C, gdim)
        self.jacobian = np.swapaxes(vertices[:, 1:, :] - vertices[:, :1, :], 1, 2)  # (C, gdim, tdim)
        self.inverse_jacobian = np.linalg.inv(self.jacobian)       # (C, tdim, gdim)
        # (tdim, gdim, C): contiguous over cells, for gradients of basis functions
        self.inverse_jacobian_by_cell = np.ascontiguousarray(np.moveaxis(self.inverse_jacobian, 0, -1))
        self.determinant = np.linalg.det(self.jacobian)            # (C,)
        if np.any(self.determinant == 0.0):
            raise MeshError("the mesh has degenerate (zero-volume) cells")
        self._index_facets(data)
        self.cell_weights: dict[tuple, tuple] = {}  # (rule, weights) by run of cells: see _Chunk.weights
        self.field_values = _FieldValues()  # fields at the points, kept across forms: see _Chunk.coefficient
        self._gradient_operators: dict[tuple, csr_matrix] = {}  # see constant_gradient_operator

    def constant_gradient_operator(self, block: "_Block", cells: slice, table: np.ndarray) -> csr_matrix:
        """The sparse matrix (gdim * E, DOFs) from a block's DOF values to their physical gradient on each of
        the run of cells ``cells`` (E of them), where that gradient is one value per cell (P1, affine cells).

        ``table`` (n, tdim, 1, 1) is the element's reference gradients, the same at every point; with K the
        cells' inverse Jacobians, row ``a * E + e`` holds sum_r K[r, a, e] table[i, r] at the cell's i-th DOF.  One product with the DOF values then replaces their gather, a reference product and its
        mapping (0.67 against 1.33 ms a field in a step of example 1b at 171 x 171 squares).  Kept while
        the block's DOF layout lives (the mesh does not move under its forms), and no longer.
        """
        key = (type(block.element), id(block.cell_dofs), cells.start, cells.stop)
        operator = self._gradient_operators.get(key)
        if operator is None:
            dofs = block.cell_dofs[cells]                                             # (E, n)
            inverse = self.inverse_jacobian_by_cell[:, :, cells]                      # (tdim, gdim, E)
            entries = np.einsum("rae,ir->aei", inverse, table[:, :, 0, 0])            # (gdim, E, n)
            gdim, count, n = entries.shape
            indices = np.broadcast_to(dofs, entries.shape).reshape(-1)                # a copy: the layout is not held
            operator = self._gradient_operators[key] = csr_matrix(
                (entries.reshape(-1), indices, np.arange(0, entries.size + 1, n)),
                shape=(gdim * count, int(block.cell_dofs.max()) + 1))
            # the entry goes with the layout's array, before its id can name another
            weakref.finalize(block.cell_dofs, self._gradient_operators.pop, key, None)
        return operator

    def ufl_domain(self):
        return self

    def _index_facets(self, data: MeshData):
        """Exterior facets as (cell, local facet) with their boundary tags; named facets located."""
        tdim, ncells = self.tdim, data.num_cells
        local = _facet_vertices(tdim)
        cell_facets = np.sort(data.cells[:, local], axis=2).reshape(-1, tdim)   # slot = cell * (tdim+1) + lf
        names = list(data.boundaries)
        named = [np.sort(data.boundaries[n], axis=1) for n in names]
        rows = np.vstack([cell_facets] + named) if named else cell_facets
        _, facet_ids = np.unique(rows, axis=0, return_inverse=True)
        facet_ids = facet_ids.ravel()
        slot_ids, named_ids = facet_ids[: len(cell_facets)], facet_ids[len(cell_facets):]
        count = np.bincount(slot_ids, minlength=facet_ids.max() + 1)
        first_slot = np.full(count.size, -1, dtype=np.int64)
        first_slot[slot_ids[::-1]] = np.arange(len(slot_ids))[::-1]
        slot_cells = np.repeat(np.arange(ncells), tdim + 1)
        slot_local = np.tile(np.arange(tdim + 1), ncells)

        tags = np.zeros(count.size, dtype=np.int64)
        self.boundary_facets: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        offset = 0
        for name, facets in zip(names, named):
            ids = named_ids[offset: offset + len(facets)]
            offset += len(facets)
            if np.any(count[ids] == 0):
                raise MeshError(f"boundary '{name}' lists facets that are not facets of any cell")
            tags[ids] = data.boundary_ids[name]
            slots = first_slot[ids]
            self.boundary_facets[name] = (slot_cells[slots], slot_local[slots])
        exterior = count[slot_ids] == 1
        self.exterior_cells = slot_cells[exterior]
        self.exterior_local = slot_local[exterior]
        self.exterior_tags = tags[slot_ids[exterior]]

    def exterior_facets(self, tags: tuple[int, ...] | None) -> tuple[np.ndarray, np.ndarray]:
        """(cells, local facets) of the exterior facets carrying one of ``tags`` (all if ``None``)."""
        if tags is None:
            return self.exterior_cells, self.exterior_local
        keep = np.isin(self.exterior_tags, tags)
        return self.exterior_cells[keep], self.exterior_local[keep]


# ---------------------------------------------------------------------------------------
# Spaces, fields, constants
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Block:
    """One scalar component of a space: where its DOFs sit among the element's DOFs."""

    component: int           # index in the flattened value shape
    element: skfem.Element   # scalar scikit-fem element
    local: np.ndarray        # (n_scalar_local,) positions among the full element's local DOFs
    cell_dofs: np.ndarray    # (n_cells, n_scalar_local) global DOFs


def _scalar_element(element, cellname: str) -> skfem.Element:
    family, degree = element.family(), element.degree()
    if family in ("Lagrange", "P", "CG") and (cellname, degree) in _LAGRANGE:
        return _LAGRANGE[(cellname, degree)]()
    if family in ("Discontinuous Lagrange", "DG", "DP") and degree == 0:
        return _PIECEWISE_CONSTANT[cellname]()
    raise unsupported(f"{family} element of degree {degree} on {cellname}s")


def _skfem_element(element, cellname: str):
    """The scikit-fem element for a UFL element, and per local DOF (component, scalar element, scalar index)."""
    if isinstance(element, (ufl.VectorElement, ufl.TensorElement)):
        if isinstance(element, ufl.TensorElement) and element.symmetry():
            raise unsupported("symmetric TensorElement")
        scalar = _scalar_element(element.sub_elements()[0], cellname)
        size = int(np.prod(element.value_shape()))
        nlocal = len(scalar.doflocs)
        layout = [(i % size, scalar, i // size) for i in range(size * nlocal)]
        return skfem.ElementVector(scalar, size), layout
    if isinstance(element, ufl.MixedElement):
        parts = []
        for sub in element.sub_elements():
            if isinstance(sub, ufl.MixedElement) and not isinstance(sub, (ufl.VectorElement, ufl.TensorElement)):
                raise unsupported("nested MixedElement")
            parts.append(_skfem_element(sub, cellname))
        composite = skfem.ElementComposite(*(p[0] for p in parts))
        offsets = np.cumsum([0] + [int(np.prod(s.value_shape())) for s in element.sub_elements()])
        layout = []
        for i in range(sum(len(p[1]) for p in parts)):
            part, index = composite._deduce_bfun(i)  # scikit-fem's own local numbering of the composite
            component, scalar, scalar_index = parts[part][1][index]
            layout.append((int(offsets[part]) + component, scalar, scalar_index))
        return composite, layout
    if isinstance(element, ufl.FiniteElement):
        scalar = _scalar_element(element, cellname)
        return scalar, [(0, scalar, i) for i in range(len(scalar.doflocs))]
    raise unsupported(type(element).__name__)


def _evaluate_at_dofs(field, space) -> np.ndarray:
    """A scalar ``field`` evaluated at every DOF node of ``space`` (same mesh), cell by cell.

    Each target node is evaluated in a cell that holds it, from the source element's
    basis at the node's reference coordinates: cost linear in the mesh size.
    """
    source = field.function_space.blocks[0]
    values = np.empty(space.num_dofs)
    for block in space.blocks:
        nodes = block.element.doflocs.T  # (tdim, n_local) reference coordinates of the target nodes
        basis = np.array([source.element.lbasis(nodes, j)[0] for j in range(source.cell_dofs.shape[1])])
        values[block.cell_dofs] = field.array[source.cell_dofs] @ basis
    return values


class SkfemFunctionSpace(ufl.FunctionSpace):
    """A ``ufl.FunctionSpace`` holding the scikit-fem element, DOF numbering and blocks."""

    def __init__(self, mesh: SkfemMesh, element: ufl.FiniteElementBase):
        super().__init__(mesh, element)
        self.mesh = mesh
        self.skfem_element, layout = _skfem_element(element, mesh.cellname)
        self.dofs = skfem.assembly.Dofs(mesh.skfem, self.skfem_element)
        self.num_dofs = int(self.dofs.N)
        self.cell_dofs = np.ascontiguousarray(self.dofs.element_dofs.T.astype(np.int64))  # (C, n_local)
        self._scatter: dict[tuple, np.ndarray] = {}  # scatter_indices of runs of cells, by block layout
        self.value_shape = tuple(element.value_shape())
        self.value_size = int(np.prod(self.value_shape))
        self.blocks = []
        for component in range(self.value_size):
            entries = sorted((scalar_index, i, scalar) for i, (c, scalar, scalar_index) in enumerate(layout)
                             if c == component)
            local = np.array([i for _, i, _ in entries])
            self.blocks.append(_Block(component, entries[0][2], local, self.cell_dofs[:, local]))

    def sub_space(self, path: int | Sequence[int] | None) -> tuple[range, tuple[int, ...]]:
        """Flat components and value shape of a sub-space, like dolfinx's ``V.sub(i).sub(j)``.

        ``path`` is an index or a path of indices through nested sub-elements:
        ``(0, 1)`` is the y-component of the first field of a mixed space.
        """
        path = () if path is None else (path,) if isinstance(path, (int, np.integer)) else tuple(path)
        element, start = self.ufl_element(), 0
        for index in path:
            parts = element.sub_elements() if isinstance(element, ufl.MixedElement) else []
            if not 0 <= index < len(parts):
                raise PrimordiaError(f"component {path} does not exist in a space with elements {self.ufl_element()}")
            start += sum(int(np.prod(part.value_shape())) for part in parts[:index])
            element = parts[index]
        shape = tuple(element.value_shape())
        return range(start, start + int(np.prod(shape))), shape

    def scatter_indices(self, cells: np.ndarray | slice, rows: list[np.ndarray]) -> np.ndarray:
        """The global DOFs that element vectors on ``cells`` add to, block by block (the local DOFs ``rows``
        of each block), flattened as the vectors' values are.

        Kept for runs of cells (every form over the whole mesh): a form assembled at every step adds
        to the same DOFs, and building this array (a gather and a concatenation, 2-3 ms for example
        1b's forms at 171 x 171 squares) cost as much as the sum itself.
        """
        if not isinstance(cells, slice):
            dofs = self.cell_dofs[cells]
            return _flat([dofs[:, local] for local in rows])
        key = (cells.start, cells.stop, tuple(local.tobytes() for local in rows))
        hit = self._scatter.get(key)
        if hit is None:
            dofs = self.cell_dofs[cells]
            hit = self._scatter[key] = _flat([dofs[:, local] for local in rows])
            hit.flags.writeable = False
        return hit

    @cached_property
    def basis(self) -> skfem.CellBasis:
        """scikit-fem's own basis of this space (same DOF numbering), for scikit-fem tools."""
        return skfem.CellBasis(self.mesh.skfem, self.skfem_element, dofs=self.dofs)

    @cached_property
    def dof_coordinates(self) -> np.ndarray:
        """Coordinates (gdim, n_dofs) of the Lagrange node of each DOF."""
        coordinates = np.empty((self.num_dofs, self.mesh.gdim))
        for block in self.blocks:
            nodes = self.mesh.origin[:, None, :] + np.einsum("cak,ik->cia", self.mesh.jacobian,
                                                               block.element.doflocs)
            coordinates[block.cell_dofs] = nodes
        return coordinates.T.copy()

    @cached_property
    def dof_component(self) -> np.ndarray:
        """Flat value component of each DOF."""
        component = np.empty(self.num_dofs, dtype=np.int64)
        for block in self.blocks:
            component[block.cell_dofs] = block.component
        return component

    def vertex_local_dofs(self, block: _Block) -> np.ndarray:
        """Local index (within the block) of the DOF at each reference vertex."""
        reference = REFERENCE_VERTICES[self.mesh.cellname]
        locations = block.element.doflocs
        local = []
        for vertex in reference:
            hit = np.flatnonzero(np.all(np.isclose(locations, vertex), axis=1))
            if hit.size != 1:
                raise PrimordiaError("vertex values need a continuous Lagrange field (P1 or P2)")
            local.append(int(hit[0]))
        return np.array(local)

    @cached_property
    def vertex_dofs(self) -> dict[int, np.ndarray]:
        """Each block's DOFs at the mesh vertices, each once, by the block's component."""
        return {block.component: np.unique(block.cell_dofs[:, self.vertex_local_dofs(block)])
                for block in self.blocks}

    def facet_local_dofs(self, block: _Block) -> list[np.ndarray]:
        """Local DOFs (within the block) on each local facet: barycentric coordinate lf is zero."""
        locations = block.element.doflocs
        barycentric = np.column_stack([1.0 - locations.sum(axis=1), locations])
        return [np.flatnonzero(np.abs(barycentric[:, lf]) < 1e-12) for lf in range(self.mesh.tdim + 1)]


class SkfemFunction(ufl.Coefficient):
    """A ``ufl.Coefficient`` owning its DOF array and a PETSc Vec sharing that memory."""

    def __init__(self, space: SkfemFunctionSpace, name: str = "f"):
        super().__init__(space)
        self.name = name
        self._array = np.zeros(space.num_dofs)
        self._vector = PETSc.Vec().createWithArray(self._array, comm=PETSc.COMM_SELF)

    @property
    def array(self) -> np.ndarray:
        """The DOF values (write into it; it is shared with :attr:`vector`)."""
        return self._array

    @property
    def vector(self):
        """The PETSc Vec viewing :attr:`array`."""
        return self._vector

    @property
    def function_space(self) -> SkfemFunctionSpace:
        return self.ufl_function_space()


class SkfemConstant(ufl.Constant):
    """A ``ufl.Constant`` whose ``value`` can change between assemblies."""

    def __init__(self, mesh: SkfemMesh, value):
        value = np.asarray(value, dtype=float)
        super().__init__(mesh, shape=value.shape)
        self._value = value

    @property
    def value(self) -> np.ndarray:
        return self._value

    @value.setter
    def value(self, value):
        value = np.asarray(value, dtype=float)
        if value.shape != self.ufl_shape:
            raise PrimordiaError(f"a constant of shape {self.ufl_shape} cannot take a value of shape {value.shape}")
        self._value = value


# ---------------------------------------------------------------------------------------
# Quadrature on a chunk of cells or facets
# ---------------------------------------------------------------------------------------


class _Rule:
    """Reference points of one integral (per local facet for ``ds``) and their weights."""

    def __init__(self, mesh: SkfemMesh, plan: IntegralPlan):
        tdim = mesh.tdim
        self.facet = plan.integral_type == "exterior_facet"
        if not self.facet:
            points, self.weights = reference_quadrature(mesh.cellname, plan.degree, plan.rule)
            self.points = points.T                                          # (tdim, Q)
        else:
            facet_points, self.weights = reference_quadrature(FACET_NAMES[mesh.cellname], plan.degree, plan.rule)
            vertices = REFERENCE_VERTICES[mesh.cellname]
            per_facet = []
            for corners in _facet_vertices(tdim):
                # as ffcx map_facet_points: v0 + sum_j (v_j - v0) s_j
                edges = vertices[corners[1:]] - vertices[corners[0]]        # (tdim - 1, tdim)
                per_facet.append((vertices[corners[0]] + facet_points @ edges).T)
            self.points = np.stack(per_facet)                               # (tdim + 1, tdim, Q)
        self.num_points = len(self.weights)
        self._tables: dict[tuple, np.ndarray] = {}

    def table(self, element: skfem.Element, derivatives: int) -> np.ndarray:
        """Reference basis values / gradients / Hessians at the points.

        Cells: (n_local, *(tdim,) * derivatives, Q); facets: one more leading axis
        for the local facet.  Hessians come from central differences of the
        gradients, exact for the degree <= 2 elements supported here.
        """
        key = (type(element), derivatives)
        if key not in self._tables:
            points = self.points if self.facet else self.points[None]
            tables = [_reference_table(element, x, derivatives) for x in points]
            self._tables[key] = np.stack(tables) if self.facet else tables[0]
        return self._tables[key]


def _reference_table(element: skfem.Element, points: np.ndarray, derivatives: int) -> np.ndarray:
    nlocal = len(element.doflocs)
    if derivatives == 0:
        return np.array([element.lbasis(points, i)[0] for i in range(nlocal)])
    if derivatives == 1:
        return np.array([element.lbasis(points, i)[1] for i in range(nlocal)])
    if derivatives == 2:
        tdim = points.shape[0]
        step = 0.5
        hessian = np.empty((nlocal, tdim, tdim, points.shape[1]))
        for k in range(tdim):
            shift = np.zeros((tdim, 1))
            shift[k] = step
            for i in range(nlocal):
                forward = element.lbasis(points + shift, i)[1]
                backward = element.lbasis(points - shift, i)[1]
                hessian[i, :, k] = (forward - backward) / (2 * step)
        return hessian
    raise unsupported(f"derivatives of order {derivatives}")


class _Chunk:
    """Quadrature data on a chunk of cells (or exterior facets): a QuadratureContext."""

    def __init__(self, mesh: SkfemMesh, rule: _Rule, cells: np.ndarray | slice, local_facets: np.ndarray | None):
        """``cells``: the cell of each entity, as indices or (for whole runs of cells) a slice."""
        self.mesh, self.rule, self.cells, self.local_facets = mesh, rule, cells, local_facets
        self.gdim = mesh.gdim
        self.inverse_jacobian = mesh.inverse_jacobian[cells]                   # (E, tdim, gdim)
        self.num_entities = len(self.inverse_jacobian)
        self._factor_cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        self._field_cache: dict[tuple, np.ndarray] = {}
        self._geometry_cache: dict[str, np.ndarray | None] = {}

    # -- integration weights ------------------------------------------------------------
    @cached_property
    def weights(self) -> np.ndarray:
        """Quadrature weights times the Jacobian of the map to the entity: (E, Q), a view of point-major
        (Q, E) data as the evaluator multiplies them (an (E, Q) array transposed costs it a strided pass).

        A run of cells keeps its weights on the mesh (its geometry never changes): forms assembled at
        every step do not compute them again.
        """
        if self.rule.facet:
            return np.ascontiguousarray((self._facet_scale[:, None] * self.rule.weights).T).T
        key = (id(self.rule), self.cells.start, self.cells.stop) if isinstance(self.cells, slice) else None
        hit = self.mesh.cell_weights.get(key) if key is not None else None
        if hit is None or hit[0] is not self.rule:
            weights = (self.rule.weights[:, None] * np.abs(self.mesh.determinant[self.cells])[None, :]).T
            if key is None:
                return weights
            hit = self.mesh.cell_weights[key] = (self.rule, weights)
        return hit[1]

    @cached_property
    def _facet_scale(self) -> np.ndarray:
        corners = self.mesh.mesh_data.points[self._facet_corner_vertices]    # (E, tdim, gdim)
        edges = corners[:, 1:] - corners[:, :1]
        if self.mesh.tdim == 2:
            return np.linalg.norm(edges[:, 0], axis=1)
        return np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1)

    @cached_property
    def _facet_corner_vertices(self) -> np.ndarray:
        local = _facet_vertices(self.mesh.tdim)[self.local_facets]            # (E, tdim)
        return np.take_along_axis(self.mesh.mesh_data.cells[self.cells], local, axis=1)

    # -- basis functions ----------------------------------------------------------------
    def argument_blocks(self, space: SkfemFunctionSpace) -> list[ArgumentBlock]:
        self._check_space(space)
        return [ArgumentBlock(block.component, block.local, functools.partial(self._factors, block.element))
                for block in space.blocks]

    def _factors(self, element: skfem.Element, derivatives: int) -> tuple[np.ndarray, np.ndarray]:
        """Reference table (n_local, tdim ** k, E or 1, Q or 1) and reference-to-physical map of a scalar element."""
        key = (type(element), derivatives)
        if key not in self._factor_cache:
            table = self.rule.table(element, derivatives)
            if derivatives and derivatives >= element.maxdeg:  # affine cells: constant over the points
                table = table[..., :1]
            if self.rule.facet:
                table = np.moveaxis(table[self.local_facets], 0, -2)            # (n, ..., E, Q)
            else:
                table = table[..., None, :]
            table = table.reshape(table.shape[:1] + (-1,) + table.shape[-2:])
            self._factor_cache[key] = table, self._derivative_map(derivatives)
        return self._factor_cache[key]

    def _derivative_map(self, derivatives: int) -> np.ndarray:
        """(tdim ** k, *(gdim,) * k, E, 1): k-th physical derivatives from reference ones (affine cells)."""
        if derivatives == 0:
            return np.ones((1, 1, 1))
        K = self.mesh.inverse_jacobian_by_cell[:, :, self.cells]                # (tdim, gdim, E)
        if derivatives == 1:
            return K[..., None]
        if derivatives == 2:
            tdim = K.shape[0]
            return np.einsum("kae,lbe->klabe", K, K).reshape((tdim * tdim,) + K.shape[1:2] * 2 + K.shape[2:])[..., None]
        raise unsupported(f"derivatives of order {derivatives}")

    def coefficient(self, function, derivatives: int) -> np.ndarray:
        if not isinstance(function, SkfemFunction):
            raise unsupported(f"{type(function).__name__} (a coefficient not made by the skfem backend)")
        self._check_space(function.function_space)
        return self._kept_values(function, derivatives, None)

    def coefficient_components(self, function, derivatives: int, components: slice) -> np.ndarray | None:
        """A run of a field's flat value components, (n, *(gdim,) * k, E, Q): only their blocks are
        interpolated (a form that reads u of a (u, p) field does not interpolate p).  Sliced from the
        whole field's values when this chunk holds them already."""
        if not isinstance(function, SkfemFunction):
            return None
        space = function.function_space
        self._check_space(space)
        whole = self._field_cache.get((id(function), derivatives, None))
        if whole is not None:
            return whole.reshape((-1,) + whole.shape[len(space.value_shape):])[components]
        return self._kept_values(function, derivatives, (components.start, components.stop))

    def _kept_values(self, function, derivatives: int, components: tuple[int, int] | None) -> np.ndarray:
        """:meth:`_field_values` of the field (or of its flat ``components``, first and stop), kept for the
        chunk's other nodes and, over a run of cells (as every form over the whole mesh has), on the mesh
        for the other forms while the field's DOF values stay."""
        key = (id(function), derivatives, components)
        if key not in self._field_cache:
            compute = functools.partial(self._field_values, function, derivatives,
                                        None if components is None else slice(*components))
            if isinstance(self.cells, slice):
                self._field_cache[key] = self.mesh.field_values.get(function, derivatives, self.rule, self.cells,
                                                                    compute, components)
            else:
                self._field_cache[key] = compute()
        return self._field_cache[key]

    def _field_values(self, function, derivatives: int, components: slice | None = None) -> np.ndarray:
        """(*value_shape, *(gdim,) * k, E, Q or 1): the field's k-th derivatives at the points, a view of
        point-major data; with ``components``, those flat components only, (n, *(gdim,) * k, E, Q or 1)."""
        space = function.function_space
        first, stop = (0, space.value_size) if components is None else (components.start, components.stop)
        blocks = [block for block in space.blocks if first <= block.component < stop]
        if len(blocks) != stop - first:
            raise PrimordiaError(f"components {first} to {stop - 1} of a field with {space.value_size}")
        parts = [self._interpolate(function.array, block, derivatives) for block in blocks]
        if len(parts) == 1 and (components is not None or not space.value_shape):  # one part: no copy
            part = np.swapaxes(parts[0], -1, -2)
            return part if components is None else part[None]
        points = max(part.shape[-2] for part in parts)
        values = np.empty((stop - first,) + parts[0].shape[:-2] + (points, self.num_entities))
        for block, part in zip(blocks, parts):
            values[block.component - first] = part
        shape = space.value_shape if components is None else (stop - first,)
        return np.swapaxes(values.reshape(shape + values.shape[1:]), -1, -2)

    def _interpolate(self, values: np.ndarray, block: _Block, derivatives: int) -> np.ndarray:
        """(*(gdim,) * k, Q or 1, E): k-th derivatives of the block's component of a field with DOF ``values``.

        Point-major, like the evaluator's arrays (the context's arrays are views of it, swapped).
        """
        table, mapping = self._factors(block.element, derivatives)
        if derivatives == 1 and table.shape[2:] == (1, 1) and isinstance(self.cells, slice):
            operator = self.mesh.constant_gradient_operator(block, self.cells, table)
            return (operator @ values[: operator.shape[1]]).reshape(-1, 1, self.num_entities)
        dofs = values[block.cell_dofs[self.cells]]                                 # (E, n)
        if table.shape[2] == 1:  # the same reference table on every cell: one matrix product
            reference = (table[:, :, 0].reshape(len(table), -1).T @ dofs.T).reshape(len(mapping), -1, len(dofs))
        else:
            reference = np.einsum("ei,ireq->rqe", dofs, table)                     # (R, Q, E)
        if derivatives == 0:
            return reference[0]  # values map to themselves
        mapping = np.swapaxes(mapping, -1, -2)
        return sum(mapping[r] * reference[r] for r in range(len(mapping)))

    def constant(self, constant) -> np.ndarray:
        if not isinstance(constant, SkfemConstant):
            raise unsupported(f"{type(constant).__name__} (a constant not made by the skfem backend)")
        return constant.value

    def _check_space(self, space):
        if not isinstance(space, SkfemFunctionSpace):
            raise unsupported(f"{type(space).__name__} (a function space not made by the skfem backend)")
        if space.mesh is not self.mesh:
            raise PrimordiaError("a form mixes fields on different meshes")

    # -- geometry -----------------------------------------------------------------------
    def geometry(self, quantity: str) -> np.ndarray | None:
        if quantity not in self._geometry_cache:
            compute = _GEOMETRY.get(quantity)
            self._geometry_cache[quantity] = None if compute is None else compute(self)
        return self._geometry_cache[quantity]

    def spatial_coordinate(self) -> np.ndarray:
        """(gdim, E, Q), a view of point-major data."""
        jacobian = self.mesh.jacobian[self.cells]                                   # (E, gdim, tdim)
        if self.rule.facet:
            mapped = np.einsum("eak,ekq->aqe", jacobian, self.rule.points[self.local_facets])
        else:
            mapped = np.ascontiguousarray(np.tensordot(jacobian, self.rule.points, axes=([2], [0])).transpose(1, 2, 0))
        return np.swapaxes(self.mesh.origin[self.cells].T[:, None, :] + mapped, 1, 2)

    def facet_normal(self) -> np.ndarray | None:
        if not self.rule.facet:
            return None
        reference = _reference_normals(self.mesh.tdim)[self.local_facets]       # (E, tdim)
        normal = np.einsum("eka,ek->ae", self.inverse_jacobian, reference)
        return (normal / np.linalg.norm(normal, axis=0))[:, :, None]

    def facet_area(self) -> np.ndarray | None:
        if not self.rule.facet:
            return None
        return (self._facet_scale * REFERENCE_VOLUMES[FACET_NAMES[self.mesh.cellname]])[:, None]

    @cached_property
    def cell_quantities(self) -> dict[str, np.ndarray]:
        return cell_quantities(self.mesh.mesh_data.points[self.mesh.mesh_data.cells[self.cells]])


def _cell_quantity(name: str):
    return lambda chunk: chunk.cell_quantities[name][:, None]


#: Geometric quantities by UFL class name: arrays (*shape, E, Q or 1).
_GEOMETRY = {
    "SpatialCoordinate": _Chunk.spatial_coordinate,
    "FacetNormal": _Chunk.facet_normal,
    "FacetArea": _Chunk.facet_area,
    "Jacobian": lambda chunk: np.moveaxis(chunk.mesh.jacobian[chunk.cells], 0, -1)[..., None],
    "JacobianInverse": lambda chunk: np.moveaxis(chunk.inverse_jacobian, 0, -1)[..., None],
    "JacobianDeterminant": lambda chunk: chunk.mesh.determinant[chunk.cells][:, None],
    **{name: _cell_quantity(name) for name in
       ("CellVolume", "Circumradius", "CellDiameter", "MinCellEdgeLength", "MaxCellEdgeLength")},
}


# ---------------------------------------------------------------------------------------
# Boundary conditions
# ---------------------------------------------------------------------------------------


class _Dirichlet:
    """Constrained DOFs of one condition and their prescribed values (mutable handle)."""

    def __init__(self, dofs: np.ndarray, components: range):
        self.dofs = dofs
        self.components = components
        self.values = np.zeros(len(dofs))


# ---------------------------------------------------------------------------------------
# Sparsity pattern
# ---------------------------------------------------------------------------------------


class _Pattern:
    """CSR pattern of all cell couplings between a test and a trial space, and each
    element-matrix entry's position in its values (``positions``: (cells, n_test, n_trial))."""

    def __init__(self, test: SkfemFunctionSpace, trial: SkfemFunctionSpace):
        self.test, self.trial = test, trial
        keys = test.cell_dofs[:, :, None] * trial.num_dofs + trial.cell_dofs[:, None, :]
        unique, positions = np.unique(keys.ravel(), return_inverse=True)
        self.row, self.col = np.divmod(unique, trial.num_dofs)
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(self.row, minlength=test.num_dofs))]
                                     ).astype(PETSc.IntType)
        self.indices = self.col.astype(PETSc.IntType)
        self.positions = positions.reshape(keys.shape).astype(np.int32 if len(unique) < 2 ** 31 else np.int64)
        self._runs: dict[tuple, tuple[np.ndarray, np.ndarray, list]] = {}

    def add(self, data: np.ndarray, cells: np.ndarray | slice, blocks: list) -> None:
        """``data[positions[cells]] += tensors`` for the (rows, columns, tensors) of each block pair,
        entries at the same position summed.

        A run of cells (a slice) goes through the distinct positions its blocks touch,
        found once and kept: its cost is that of the run, not a pass over ``data``.
        """
        values = _flat([tensors for *_, tensors in blocks])
        if not isinstance(cells, slice):
            positions = self.positions[cells]
            data += np.bincount(_flat([positions[:, rows[:, None], columns] for rows, columns, _ in blocks]),
                                weights=values, minlength=len(data))
            return
        key = (cells.start, cells.stop) + tuple((id(rows), id(columns)) for rows, columns, _ in blocks)
        run = self._runs.get(key)
        if run is None:
            positions = self.positions[cells]
            unique, inverse = np.unique(_flat([positions[:, rows[:, None], columns] for rows, columns, _ in blocks]),
                                        return_inverse=True)
            locals_ = [(rows, columns) for rows, columns, _ in blocks]  # keeps the ids of the key unique
            run = self._runs[key] = (unique, inverse.astype(self.positions.dtype), locals_)
        unique, inverse, _ = run
        data[unique] += np.bincount(inverse, weights=values, minlength=len(unique))


def _flat(arrays: list[np.ndarray]) -> np.ndarray:
    """The arrays' entries one after the other (no copy for one contiguous array)."""
    return arrays[0].ravel() if len(arrays) == 1 else np.concatenate([array.ravel() for array in arrays])


# ---------------------------------------------------------------------------------------
# The backend
# ---------------------------------------------------------------------------------------


#: Environment variables by which a user sets the BLAS thread count themselves.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


def blas_on_one_thread() -> bool:
    """numpy's BLAS on one thread for this process, unless the user set a thread count; whether it was set.

    The evaluator's products are many and small (an element-tensor block: a chunk of cells
    times a few dozen reference values), too small for threads to share: with two threads
    (this machine's default) example 1b at 171 x 171 squares ran 100.4 ms/step against 99.2 on
    one, and 2a at 43 x 43 849 against 840 ms, while the second thread's waiting for the next
    product (OpenBLAS spins) doubled the CPU time (207 against 100 ms/step for 1b): a core
    taken from the other work of the machine.  Example 4 at 10 x 10 x 2 (P2 tetrahedra) was
    3% faster on two (3,039 against 3,140 ms/step): set ``OPENBLAS_NUM_THREADS`` (or
    ``OMP_NUM_THREADS``) to keep threads; this is then left alone.
    """
    if any(name in os.environ for name in BLAS_THREAD_VARIABLES):
        return False
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")
    return True


class SkfemBackend(Backend):
    """scikit-fem 12: serial assembly of UFL forms (evaluated with numpy) into PETSc objects."""

    name = "skfem"

    def __init__(self, comm=None):
        if comm is None:
            try:
                from mpi4py import MPI
                comm = MPI.COMM_WORLD
            except ImportError:
                comm = _SerialComm()
        if comm.size > 1 or PETSc.COMM_WORLD.getSize() > 1:
            raise PrimordiaError("the skfem backend is serial: run it without mpirun "
                                 "(or choose --backend fenicsx for parallel runs)")
        super().__init__(comm)
        blas_on_one_thread()
        forget_analyses()  # an earlier run's integrands, which hold its mesh and spaces
        self._plans = FormCache(_CACHED_FORMS)
        self._rules: dict[tuple, _Rule] = {}
        self._patterns: dict[tuple[int, int], _Pattern] = {}

    # -- mesh, spaces, fields -----------------------------------------------------------
    def create_mesh(self, data: MeshData) -> SkfemMesh:
        return SkfemMesh(data)

    def function_space(self, mesh, element) -> SkfemFunctionSpace:
        return SkfemFunctionSpace(mesh, element)

    def function(self, space, name: str) -> SkfemFunction:
        return SkfemFunction(space, name)

    def constant(self, mesh, value) -> SkfemConstant:
        return SkfemConstant(mesh, value)

    def measure(self, integral_type: str, mesh, metadata=None) -> ufl.Measure:
        if integral_type not in ("dx", "ds", "cell", "exterior_facet"):
            raise unsupported(f"measure {integral_type}")
        return ufl.Measure(integral_type, domain=mesh, metadata=metadata or {})

    # -- integration --------------------------------------------------------------------
    def _form_plans(self, form: ufl.Form) -> list[IntegralPlan]:
        """The preprocessed integrals of ``form``, kept for the most recently used forms."""
        return self._plans.get(form, lambda: preprocess_form(form))

    def _rule(self, mesh: SkfemMesh, plan: IntegralPlan) -> _Rule:
        key = (mesh.cellname, plan.integral_type, plan.degree, plan.rule)
        if key not in self._rules:
            self._rules[key] = _Rule(mesh, plan)
        return self._rules[key]

    @staticmethod
    def _form_mesh(form: ufl.Form) -> SkfemMesh:
        mesh = form.ufl_domain()
        if not isinstance(mesh, SkfemMesh):
            raise PrimordiaError("the form is not defined on a mesh made by the skfem backend")
        return mesh

    @staticmethod
    def _form_spaces(form: ufl.Form) -> list[SkfemFunctionSpace]:
        spaces = [a.ufl_function_space() for a in sorted(form.arguments(), key=lambda a: a.number())]
        for space in spaces:
            if not isinstance(space, SkfemFunctionSpace):
                raise PrimordiaError("the form's arguments are not on spaces made by the skfem backend")
        return spaces

    def _element_tensors(self, form: ufl.Form, cell_mask: np.ndarray | None = None):
        """Yield (cells, blocks) chunk by chunk over all integrals, ``blocks`` the (test local DOFs,
        trial local DOFs, element tensors (E, n_test_block, n_trial_block)) of each block pair.

        Linear forms give trial local DOFs ``[0]``, functionals test ones too.
        ``cell_mask`` restricts integration to the marked cells (used for lifting).
        """
        mesh = self._form_mesh(form)
        spaces = self._form_spaces(form)
        sizes = [s.cell_dofs.shape[1] for s in spaces] + [1] * (2 - len(spaces))
        for plan in self._form_plans(form):
            if plan.integral_type == "cell":
                cells, local_facets = np.arange(mesh.mesh_data.num_cells), None
            else:
                cells, local_facets = mesh.exterior_facets(plan.subdomain_ids)
            if cell_mask is not None:
                keep = cell_mask[cells]
                cells = cells[keep]
                local_facets = None if local_facets is None else local_facets[keep]
            if len(cells) == 0:
                continue
            rule = self._rule(mesh, plan)
            per_point = min(sizes[0] * sizes[1], _POINT_VALUES)
            chunk = max(1, _CHUNK_VALUES // max(sizes[0] * sizes[1], per_point * rule.num_points))
            whole = local_facets is None and cell_mask is None  # chunks are runs of cells: slice them
            for start in range(0, len(cells), chunk):
                part = slice(start, min(start + chunk, len(cells)))
                entities = part if whole else cells[part]
                context = _Chunk(mesh, rule, entities, None if local_facets is None else local_facets[part])
                blocks = integrate_blocks(plan.integrand, context, context.weights)
                if blocks:
                    yield entities, blocks

    def _pattern(self, test: SkfemFunctionSpace, trial: SkfemFunctionSpace) -> _Pattern:
        key = (id(test), id(trial))
        hit = self._patterns.get(key)
        if hit is None or hit.test is not test or hit.trial is not trial:
            hit = self._patterns[key] = _Pattern(test, trial)
        return hit

    # -- assembly -----------------------------------------------------------------------
    def assemble_matrix(self, form, bcs: Sequence[BoundaryCondition] = (), A=None, diagonal: float = 1.0):
        test, trial = self._form_spaces(form)
        pattern = self._pattern(test, trial)
        indptr, indices, row, col = pattern.indptr, pattern.indices, pattern.row, pattern.col
        # a matrix made here on this pattern holds our arrays (createAIJWithArrays): write its values in place
        csr = None if A is None else A.getAttr("__csr__")
        in_place = csr is not None and csr[0] is indptr and csr[1] is indices
        data = csr[2] if in_place else np.zeros(len(indices))
        data[:] = 0.0
        for cells, blocks in self._element_tensors(form):
            pattern.add(data, cells, blocks)
        row_fixed = self._constrained(bcs, test)
        col_fixed = self._constrained(bcs, trial)
        if row_fixed is not None or col_fixed is not None:
            zero = np.zeros(len(data), dtype=bool)
            if row_fixed is not None:
                zero |= row_fixed[row]
            if col_fixed is not None:
                zero |= col_fixed[col]
            data[zero] = 0.0
            if test is trial and row_fixed is not None:
                data[zero & (row == col) & row_fixed[row]] = diagonal
        if A is None:
            A = PETSc.Mat().createAIJWithArrays((test.num_dofs, trial.num_dofs), (indptr, indices, data),
                                                comm=PETSc.COMM_SELF)
            A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)  # re-assembly keeps the pattern
        elif not in_place:
            A.zeroEntries()
            A.setValuesCSR(indptr, indices, data)
        A.assemble()  # also marks changed values, so that solvers factorise again
        return A

    @staticmethod
    def _constrained(bcs, space) -> np.ndarray | None:
        """Mask of the DOFs of ``space`` fixed by ``bcs`` (``None`` if none applies)."""
        mask = None
        for bc in bcs:
            if bc.space == space:
                if mask is None:
                    mask = np.zeros(space.num_dofs, dtype=bool)
                mask[bc.handle.dofs] = True
        return mask

    def _assemble_array(self, form) -> np.ndarray:
        (test,) = self._form_spaces(form)
        values = np.zeros(test.num_dofs)
        for cells, blocks in self._element_tensors(form):
            values += np.bincount(test.scatter_indices(cells, [rows for rows, _, _ in blocks]),
                                  weights=_flat([tensors[:, :, 0] for *_, tensors in blocks]), minlength=test.num_dofs)
        return values

    def assemble_vector(self, form, b=None):
        values = self._assemble_array(form)
        if b is None:
            return PETSc.Vec().createWithArray(values, comm=PETSc.COMM_SELF)
        b.array[:] = values
        return b

    def assemble_scalar(self, form) -> float:
        if form.arguments():
            raise PrimordiaError("assemble_scalar needs a functional (a form without test or trial functions)")
        return float(sum(tensors.sum() for _, blocks in self._element_tensors(form) for *_, tensors in blocks))

    def assemble_residual(self, residual, jacobian, bcs, state, b=None):
        values = self._assemble_array(residual)
        x = state.array
        if bcs:
            test, trial = self._form_spaces(jacobian)
            # lifting as dolfinx apply_lifting(b, [J], [bcs], x0=[x], scale=-1): b += J (g - x) on fixed columns,
            # on the cells where g - x is not 0 (none once Newton's first update has put g in)
            shift = np.zeros(trial.num_dofs)
            for bc in bcs:
                if bc.space == trial:
                    shift[bc.handle.dofs] = bc.handle.values - x[bc.handle.dofs]
            if shift.any():
                touched = (shift != 0.0)[trial.cell_dofs].any(axis=1)
                for cells, blocks in self._element_tensors(jacobian, cell_mask=touched):
                    test_dofs, trial_dofs = test.cell_dofs[cells], trial.cell_dofs[cells]
                    local = [np.einsum("eij,ej->ei", tensors, shift[trial_dofs[:, columns]])
                             for _, columns, tensors in blocks]
                    values += np.bincount(_flat([test_dofs[:, rows] for rows, _, _ in blocks]), weights=_flat(local),
                                          minlength=test.num_dofs)
            # as dolfinx set_bc(b, bcs, x, scale=-1): b = -(g - x) on fixed rows
            for bc in bcs:
                if bc.space == test:
                    values[bc.handle.dofs] = x[bc.handle.dofs] - bc.handle.values
        if b is None:
            return PETSc.Vec().createWithArray(values, comm=PETSc.COMM_SELF)
        b.array[:] = values
        return b

    # -- Dirichlet conditions -------------------------------------------------------------
    def dirichlet_bc(self, space, boundary: str, value, component=None):
        mesh = space.mesh
        mesh.mesh_data.boundary_id(boundary)  # one-line MeshError for unknown names
        cells, local_facets = mesh.boundary_facets[boundary]
        components, _ = space.sub_space(component)
        dofs = []
        for block in space.blocks:
            if block.component not in components:
                continue
            on_facet = space.facet_local_dofs(block)
            for lf in range(mesh.tdim + 1):
                which = local_facets == lf
                dofs.append(block.cell_dofs[np.ix_(cells[which], on_facet[lf])].ravel())
        handle = _Dirichlet(np.unique(np.concatenate(dofs)) if dofs else np.empty(0, dtype=np.int64), components)
        bc = BoundaryCondition(handle=handle, space=space, boundary=boundary)
        self.update_dirichlet_bc(bc, value)
        return bc

    def update_dirichlet_bc(self, bc: BoundaryCondition, value) -> None:
        handle, space = bc.handle, bc.space
        position = space.dof_component[handle.dofs] - handle.components.start
        handle.values = self._values_at(space, handle.dofs, position, len(handle.components), value)

    @staticmethod
    def _values_at(space, dofs: np.ndarray, position: np.ndarray, size: int, value) -> np.ndarray:
        """Values of ``value`` (number, sequence, fn(x) or a scalar field) at ``dofs``, of components ``position``."""
        if isinstance(value, SkfemFunction):  # a field on the same mesh: evaluate it at the DOF points
            if value.function_space.value_size != 1 or size != 1:
                raise PrimordiaError("interpolating one field into another needs scalar fields on the skfem backend")
            return _evaluate_at_dofs(value, space)[dofs]
        if callable(value):
            result = np.asarray(value(space.dof_coordinates[:, dofs]), dtype=float)
            if result.ndim == 1 and size == 1:
                return np.broadcast_to(result, (len(dofs),)).copy()
            result = np.broadcast_to(result, (size, len(dofs))) if result.ndim == 2 else None
            if result is None:
                raise PrimordiaError(f"an interpolated function must return an array of shape ({size}, n)")
            return result[position, np.arange(len(dofs))]
        value = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
        return value[position] if value.size == size else np.full(len(dofs), value[0])

    # -- DOF values ---------------------------------------------------------------------
    def petsc_vector(self, function):
        return function.vector

    def local_array(self, function) -> np.ndarray:
        return function.array

    def update_ghosts(self, function) -> None:
        """Nothing to do: a serial run has no ghosts."""

    def interpolate(self, function, values) -> None:
        space = function.function_space
        dofs = np.arange(space.num_dofs)
        function.array[:] = self._values_at(space, dofs, space.dof_component, space.value_size, values)

    def interpolate_component(self, function, index: int, values) -> None:
        space = function.function_space
        components, _ = space.sub_space(index)
        dofs = np.flatnonzero(np.isin(space.dof_component, components))
        position = space.dof_component[dofs] - components.start
        function.array[dofs] = self._values_at(space, dofs, position, len(components), values)

    def set_vertex_values(self, function, values: np.ndarray) -> None:
        space = function.function_space
        if any(block.element.maxdeg != 1 for block in space.blocks):
            raise PrimordiaError("set_vertex_values needs a P1 field")
        values = np.asarray(values, dtype=float).reshape(space.mesh.mesh_data.num_vertices, space.value_size)
        cells = space.mesh.mesh_data.cells
        for block in space.blocks:
            local = space.vertex_local_dofs(block)
            function.array[block.cell_dofs[:, local]] = values[cells, block.component]

    def vertex_values(self, function, component=None) -> np.ndarray:
        """Values at the vertices: the vertex DOFs (a P2 field's P1 interpolant), in MeshData order."""
        space = function.function_space
        components, shape = space.sub_space(component)
        data = space.mesh.mesh_data
        result = np.empty((data.num_vertices, len(components)))
        for block in space.blocks:
            if block.component in components:
                local = space.vertex_local_dofs(block)
                result[data.cells, block.component - components.start] = function.array[block.cell_dofs[:, local]]
        return result[:, 0] if shape == () else result

    def vertex_extrema(self, function, component=None) -> tuple[float, float]:
        """Of the vertex DOFs' values themselves, without building :meth:`vertex_values`' array (which goes
        through every cell's vertices: 1 ms a field at 171^2, 0.05-0.2 ms this way)."""
        space = function.function_space
        components, _ = space.sub_space(component)
        values = np.concatenate([function.array[dofs] for c, dofs in space.vertex_dofs.items() if c in components])
        return float(values.min()), float(values.max())

    def extrema(self, expression, mesh) -> tuple[float, float]:
        from ufl.algorithms.apply_algebra_lowering import apply_algebra_lowering
        from ufl.algorithms.apply_derivatives import apply_derivatives

        plan = IntegralPlan("cell", None, apply_derivatives(apply_algebra_lowering(expression)), 1, "vertex")
        rule = self._rule(mesh, plan)
        low, high = np.inf, -np.inf
        chunk = max(1, _CHUNK_VALUES // rule.num_points)
        for start in range(0, mesh.mesh_data.num_cells, chunk):
            context = _Chunk(mesh, rule, slice(start, min(start + chunk, mesh.mesh_data.num_cells)), None)
            values = evaluate_integrand(plan.integrand, context)
            low, high = min(low, float(values.min())), max(high, float(values.max()))
        return low, high

    # -- sizes --------------------------------------------------------------------------
    def num_cells(self, mesh) -> int:
        return mesh.mesh_data.num_cells

    def p1_cell_dofs(self, space, component=None):
        index = 0 if component is None else component
        if (component is None and space.value_size != 1) or not 0 <= index < space.value_size:
            return None
        block = space.blocks[index]
        if block.element.maxdeg != 1 or len(block.element.doflocs) != space.mesh.mesh_data.gdim + 1:
            return None
        return np.ascontiguousarray(block.cell_dofs[:, space.vertex_local_dofs(block)], dtype=np.int64)

    def p1_cell_coordinates(self, mesh):
        data = mesh.mesh_data
        return np.ascontiguousarray(data.points[data.cells], dtype=float)

    def num_dofs(self, space) -> int:
        return space.num_dofs

    # -- DOF layout -----------------------------------------------------------------------
    def owned_dof_coordinates(self, space) -> np.ndarray:
        return space.dof_coordinates

    def shares_dofs(self, space, other) -> bool:
        # a space's DOFs are numbered from its mesh and element alone (SkfemFunctionSpace)
        return space is other or (space.mesh is other.mesh and space.ufl_element() == other.ufl_element())

    # -- field splits ---------------------------------------------------------------------
    def field_index_sets(self, space):
        fields = sub_elements(space.ufl_element())
        index_sets = []
        for index in range(len(fields)):
            components, _ = space.sub_space(index if len(fields) > 1 else None)
            dofs = np.flatnonzero(np.isin(space.dof_component, components))
            index_sets.append(index_set(self.comm, dofs, space.dof_component[dofs] - components.start,
                                        len(components)))
        return index_sets

    def set_dirichlet(self, vector, bcs, x0=None, scale: float = 1.0) -> None:
        values = vector.getArray()
        for bc in bcs:
            dofs = bc.handle.dofs
            values[dofs] = scale * (bc.handle.values - (x0.getArray(readonly=True)[dofs] if x0 is not None else 0.0))


__all__ = ["SkfemBackend", "SkfemMesh", "SkfemFunctionSpace", "SkfemFunction", "SkfemConstant", "UnsupportedUFL"]
