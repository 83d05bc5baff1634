"""The common assembly interface every finite element backend implements.

Physics modules state their weak forms once, in UFL, on objects a backend hands
out: function spaces are ``ufl.FunctionSpace`` instances, fields are
``ufl.Coefficient`` instances, constants are ``ufl.Constant`` instances and
measures are ``ufl.Measure`` objects carrying the backend's boundary tags.  A
backend's only job is then to turn UFL forms into assembled PETSc objects on
its own mesh and spaces, and to move DOF values in and out:

    UFL form --(backend.assemble_matrix / assemble_vector)--> PETSc Mat / Vec
                                                                   |
                                        one petsc4py solver layer (coupling/solvers.py)

Newton tangents come from ``ufl.derivative`` of the residual, never from a
hand-written second copy, so a backend needs no knowledge of any physics.

Conventions shared by all backends
----------------------------------
* DOF vectors are PETSc ``Vec`` objects of the owned DOFs (``petsc_vector``);
  ``local_array`` is a writeable numpy view of owned + ghost values.
* Dirichlet conditions follow dolfinx's convention: ``assemble_matrix`` zeroes
  constrained rows and columns and puts ``diagonal`` on them;
  ``assemble_residual`` applies lifting so that the Newton update
  ``x <- x - J^{-1} F`` lands exactly on the prescribed values.
* ``vertex_values`` returns, on rank 0, values at the vertices of the
  :class:`~primordia.core.mesh_data.MeshData` the mesh was built from, in its vertex
  order (``None`` on other ranks), so outputs do not depend on the backend.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import ufl

from primordia.core.mesh_data import MeshData

#: A callable giving values at points: ``values = fn(x)`` with ``x`` of shape
#: (gdim, n_points) and values of shape (n_points,) or (value_size, n_points).
PointFunction = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class BoundaryCondition:
    """A backend's Dirichlet condition (opaque ``handle``) and the DOFs it fixes."""

    handle: Any
    space: Any
    boundary: str


class Backend(ABC):
    """One finite element library behind the common assembly interface."""

    #: Name used in configs and on the command line (``--backend NAME``).
    name: ClassVar[str]

    def __init__(self, comm):
        self.comm = comm

    # -- mesh, spaces, fields -----------------------------------------------------------
    @abstractmethod
    def create_mesh(self, data: MeshData) -> Any:
        """The backend's mesh for ``data``; ``mesh.ufl_domain()`` is its UFL domain."""

    @abstractmethod
    def function_space(self, mesh, element: ufl.FiniteElementBase) -> ufl.FunctionSpace:
        """A function space (a ``ufl.FunctionSpace``) of ``element`` on ``mesh``.

        Supported at least: Lagrange P1/P2 scalars, vector elements and mixed
        elements of those (e.g. Taylor-Hood), on triangles and tetrahedra.
        """

    @abstractmethod
    def function(self, space, name: str) -> ufl.Coefficient:
        """A zero-initialised field in ``space`` (a ``ufl.Coefficient``)."""

    @abstractmethod
    def constant(self, mesh, value) -> ufl.Constant:
        """A ``ufl.Constant`` whose ``.value`` can be changed between assemblies."""

    @abstractmethod
    def measure(self, integral_type: str, mesh, metadata: dict | None = None) -> ufl.Measure:
        """``dx`` or ``ds`` on ``mesh``; ``ds(mesh_data.boundary_id(name))`` selects a boundary."""

    # -- assembly -----------------------------------------------------------------------
    @abstractmethod
    def assemble_matrix(self, form: ufl.Form, bcs: Sequence[BoundaryCondition] = (), A=None,
                        diagonal: float = 1.0):
        """Assemble a bilinear form into a PETSc Mat (into ``A`` when given, same pattern)."""

    @abstractmethod
    def assemble_vector(self, form: ufl.Form, b=None):
        """Assemble a linear form into a PETSc Vec of owned DOFs (into ``b`` when given)."""

    @abstractmethod
    def assemble_scalar(self, form: ufl.Form) -> float:
        """Assemble a functional, summed over all ranks."""

    @abstractmethod
    def extrema(self, expression, mesh) -> tuple[float, float]:
        """Minimum and maximum of a scalar UFL expression over the vertices of every cell, on all ranks.

        Evaluated cell by cell (so an expression discontinuous across cells, such
        as det(I + grad u), is sampled on each side of a vertex).
        """

    @abstractmethod
    def assemble_residual(self, residual: ufl.Form, jacobian: ufl.Form, bcs: Sequence[BoundaryCondition],
                          state, b=None):
        """The Newton right-hand side F(state) with lifting (see module docstring)."""

    @abstractmethod
    def dirichlet_bc(self, space, boundary: str, value: PointFunction | float | Sequence[float],
                     component: int | tuple[int, ...] | None = None) -> BoundaryCondition:
        """Fix ``space`` (or a sub-space of it) on the named boundary.

        ``component`` selects a sub-space: an int, or a path through nested
        sub-spaces, e.g. ``(0, 1)`` = the y-component of the first field of a
        mixed (u, p) space.  ``value`` is a number, a sequence (vector
        sub-spaces) or a point function of x (shape (gdim, n)).
        """

    @abstractmethod
    def update_dirichlet_bc(self, bc: BoundaryCondition, value) -> None:
        """Change the prescribed value of ``bc`` (time-dependent conditions)."""

    # -- DOF values ---------------------------------------------------------------------
    @abstractmethod
    def petsc_vector(self, function):
        """The PETSc Vec holding ``function``'s owned DOFs (shared memory)."""

    @abstractmethod
    def local_array(self, function) -> np.ndarray:
        """Writeable numpy view of owned + ghost DOF values of ``function``."""

    @abstractmethod
    def update_ghosts(self, function) -> None:
        """Refresh ghost values after the owned values changed."""

    @abstractmethod
    def interpolate(self, function, values) -> None:
        """Set ``function`` to the interpolant of ``values`` (Lagrange nodes).

        ``values``: a point function, a number, or a backend function of the same mesh.
        """

    @abstractmethod
    def interpolate_component(self, function, index: int, values) -> None:
        """Set sub-function ``index`` of a mixed ``function`` to the interpolant of ``values``.

        ``values``: a point function, a number, or a backend function of the same mesh.
        """

    @abstractmethod
    def set_vertex_values(self, function, values: np.ndarray) -> None:
        """Set a P1 ``function`` from values given at every MeshData vertex (global order)."""

    @abstractmethod
    def vertex_values(self, function, component: int | None = None) -> np.ndarray | None:
        """Values at all MeshData vertices, gathered on rank 0 (``None`` elsewhere).

        ``component`` selects one sub-function of a mixed function.  Scalars give
        shape (n_vertices,), vectors (n_vertices, value_size); higher-degree
        fields are interpolated to P1 first.
        """

    def vertex_extrema(self, function, component: int | None = None) -> tuple[float, float]:
        """The least and the largest of :meth:`vertex_values` (every component of a vector), on every rank
        (collective).

        This default gathers the values to rank 0; a parallel backend reduces each rank's own vertices
        instead, so that a row of the series does not move whole fields to one rank.
        """
        values = self.vertex_values(function, component)
        extrema = (float(np.min(values)), float(np.max(values))) if self.is_root() else None
        return self.comm.bcast(extrema, root=0) if self.comm.size > 1 else extrema

    # -- sizes --------------------------------------------------------------------------
    @abstractmethod
    def num_cells(self, mesh) -> int:
        """Global number of cells."""

    @abstractmethod
    def num_dofs(self, space) -> int:
        """Global number of DOFs of ``space`` (all components)."""

    # -- DOF layout (optional: contract 1.3) ------------------------------------------------
    def owned_dof_coordinates(self, space) -> np.ndarray:
        """Coordinates (gdim, n_owned) of the nodes of the DOFs this rank owns, in ``petsc_vector`` order.

        For a scalar Lagrange space (what nodal evaluation of lumped forms reads,
        :mod:`primordia.coupling.nodal`); only asked for when :meth:`shares_dofs` says True.
        """
        raise NotImplementedError(f"backend {self.name!r} gives no DOF coordinates")

    def shares_dofs(self, space, other) -> bool:
        """Whether the DOFs of two spaces are the same nodes in the same order (DOF arrays align).

        The default, False, is always safe: lumped reactions are then assembled cell by cell
        instead of evaluated at the nodes.
        """
        return False

    def p1_cell_dofs(self, space, component: int | None = None) -> np.ndarray | None:
        """Per cell this rank assembles over, the ``local_array`` positions of a P1 scalar part's DOFs at its
        vertices, (n_cells, tdim + 1), vertex by vertex in the order of :meth:`p1_cell_coordinates`.

        ``component`` is a flat value component of a vector or mixed space (``u[1]`` of a mixed
        (u, p) space is 1, p is 2). None when that part is not P1 Lagrange, or the backend cannot
        tell: the closed forms of :mod:`primordia.coupling.p1_advection` and
        :mod:`primordia.coupling.p1_gradient_load` are then not used.
        """
        return None

    def p1_cell_coordinates(self, mesh) -> np.ndarray | None:
        """The vertex coordinates (n_cells, tdim + 1, gdim) of the cells of :meth:`p1_cell_dofs`, or None."""
        return None

    # -- field splits ---------------------------------------------------------------------
    @abstractmethod
    def field_index_sets(self, space) -> list:
        """One PETSc ``IS`` per field of ``space``: the global indices of the DOFs this rank owns.

        For a mixed space, one index set per sub-element, in sub-element order (the fields of
        a group: e.g. u, psi, p); for any other space, one index set of all its owned DOFs.
        Indices are sorted, in the numbering of ``petsc_vector`` (so PETSc's ``fieldsplit``
        can take them as its splits).  A vector field whose components sit together node by
        node gets its value size as the block size of its index set (what AMG for
        elasticity reads).  Collective: every rank calls it.
        """

    @abstractmethod
    def set_dirichlet(self, vector, bcs: Sequence[BoundaryCondition], x0=None, scale: float = 1.0) -> None:
        """At the DOFs each condition fixes, ``vector = scale * (g - x0)`` (``scale * g`` without ``x0``).

        dolfinx's ``set_bc``: with the lifting of :meth:`assemble_residual`, what an algebraic
        residual (a matrix times a vector) needs to follow the Dirichlet convention.
        """

    # -- helpers every backend gets for free ----------------------------------------------
    def lumped_dx(self, mesh) -> ufl.Measure:
        """``dx`` with vertex quadrature: the lumped mass matrix for P1 fields."""
        return self.measure("dx", mesh, metadata={"quadrature_rule": "vertex", "quadrature_degree": 1})

    def is_root(self) -> bool:
        return self.comm.rank == 0

    def collect_garbage(self) -> None:
        """Destroy PETSc objects dropped on the run's communicators (collective).

        petsc4py (3.18) does not destroy an object when Python drops it: it defers that to
        ``garbage_cleanup`` of the object's communicator, the serial ``COMM_SELF`` included.
        Without it, every vector or matrix dropped in a time step stays allocated (a serial
        matrix rebuilt at every update grew example 2a at 171 x 171 squares by 18 MB a step,
        to 13 GB and an out-of-memory kill). ``COMM_SELF`` is every rank's own: cleaning it is
        local, and safe in parallel.
        """
        from petsc4py import PETSc

        PETSc.garbage_cleanup(self.comm)
        PETSc.garbage_cleanup(PETSc.COMM_SELF)


class FormCache:
    """What a backend made of a UFL form (or expression), for the ``size`` most recently used ones.

    Keyed by the object's identity, which the entry keeps alive (so that its id is not
    reused). Bounded: the solvers are made anew at every checkpoint and rejected step, with
    new forms, and an unbounded cache would keep every old compiled form for the whole run.
    """

    def __init__(self, size: int = 256):
        self.size = size
        self._entries: OrderedDict[int, tuple[Any, Any]] = OrderedDict()

    def get(self, key_object, make: Callable[[], Any]):
        """The cached result for ``key_object``, made by ``make()`` on a miss."""
        hit = self._entries.get(id(key_object))
        if hit is None or hit[0] is not key_object:
            hit = self._entries[id(key_object)] = (key_object, make())
            if len(self._entries) > self.size:
                self._entries.popitem(last=False)
        self._entries.move_to_end(id(key_object))
        return hit[1]

    def __len__(self) -> int:
        return len(self._entries)


def sub_elements(element) -> list:
    """The fields of a space's element: the sub-elements of a mixed element, else the element itself."""
    if isinstance(element, ufl.MixedElement) and not isinstance(element, (ufl.VectorElement, ufl.TensorElement)):
        return list(element.sub_elements())
    return [element]


def is_p1_scalar(element) -> bool:
    """Whether a UFL element is scalar P1 Lagrange (what nodal evaluation and the closed-form loads read)."""
    return (element.family() in ("Lagrange", "P", "Q", "CG") and element.degree() == 1
            and element.value_shape() == () and not element.sub_elements())


def index_set(comm, dofs: np.ndarray, components: np.ndarray | None = None, value_size: int = 1):
    """A sorted PETSc ``IS`` of the global indices ``dofs`` on the backend's ``comm``.

    Its block size is ``value_size`` when, on every rank, the sorted DOFs run through the
    components 0, 1, ..., value_size - 1 over and over (``components``: the component of
    each DOF; ``None`` for a scalar field): both backends number a node's components
    together, so each run is one node.
    """
    from petsc4py import PETSc

    order = np.argsort(dofs, kind="stable")
    dofs = np.asarray(dofs, dtype=PETSc.IntType)[order]
    result = PETSc.IS().createGeneral(dofs, comm=PETSc.COMM_SELF if comm.size == 1 else comm)
    if value_size > 1 and components is not None:
        components = np.asarray(components)[order]
        interleaved = (len(dofs) % value_size == 0 and np.array_equal(
            components.reshape(-1, value_size), np.broadcast_to(np.arange(value_size), (len(dofs) // value_size,
                                                                                        value_size))))
        if comm.allreduce(int(not interleaved)) == 0:
            result.setBlockSize(value_size)
    return result
