"""FEniCSx (dolfinx 0.5, Debian bookworm) behind the common assembly interface.

UFL forms are JIT-compiled by FFCx on first use (cached in ``~/.cache/fenics``)
and assembled with ``dolfinx.fem.petsc`` into PETSc objects; meshes are
distributed over MPI ranks by dolfinx, with named boundaries carried as facet
tags.  Nothing physical lives here.
"""

from __future__ import annotations

import gc
import logging
import os
import weakref
from collections.abc import Sequence

import numpy as np
import ufl

from primordia.core import reductions
from primordia.core.atomic_files import reason_of, refusal_to_write
from primordia.core.backend import Backend, BoundaryCondition, FormCache, index_set, is_p1_scalar, sub_elements
from primordia.core.errors import ConfigError, MeshError
from primordia.core.mesh_data import MeshData

import dolfinx  # noqa: E402  (import after the neutral modules: fails loudly if missing)
import dolfinx.fem.petsc as fem_petsc
from dolfinx import cpp as _cpp
from dolfinx import fem
from petsc4py import PETSc

logger = logging.getLogger(__name__)


#: The environment variable that sets PT-SCOTCH's threads (SCOTCH 7); see FenicsxBackend.create_mesh.
SCOTCH_THREADS = "SCOTCH_PTHREAD_NUMBER"


def _lifting_adds(handles, state) -> bool:
    """Whether the lifting b -= J (g - x) adds anything on this rank: g - x is not 0 at some fixed DOF
    the rank holds (owned or ghost, the cells it assembles).

    Once Newton's first update has put the prescribed values in, it never does, and assembling the
    tangent on the boundary cells (its coefficients packed over the whole mesh) is wasted: 12 of the
    58 ms of a residual of example 2a at 171 x 171 squares.  Local: ``apply_lifting`` is too.
    """
    shift = np.zeros_like(state.x.array)
    _cpp.fem.set_bc(shift, handles, state.x.array, 1.0)  # g - x at the fixed DOFs, ghosts included
    return bool(np.any(shift))


def basix_reference_vertices(cell_name: str) -> np.ndarray:
    """Vertices of the reference cell (basix numbering), the points where extrema are sampled."""
    import basix

    return np.asarray(basix.geometry(basix.cell.string_to_type(cell_name)), dtype=float)


class CoefficientPacker:
    """dolfinx's ``pack_coefficients`` of a form over cells and exterior facets, as one numpy gather per integral.

    dolfinx writes each coefficient's DOFs into its columns of an integral's (cells or facets, stride)
    table in turn: strided writes, one pass over the table per coefficient.  Here the coefficients'
    arrays are copied side by side and each table is gathered at once, contiguously, through indices
    found once (the dofmaps do not change).  On this session's machine, whose memory is slow, example
    1b's batched advection at 171 x 171 squares (m, f, b and the (u, p) rate: 58,482 x 18 values) took
    11-15 ms, 2 here; example 2a's growth residual (58,482 x 60, and its Robin facets) 78 ms.  A packer
    whose first tables differ from dolfinx's by a bit is not used (:meth:`for_form` returns None), nor
    one for a form with interior-facet integrals, a coefficient whose element transforms its DOFs, or
    tables of more than ``MAX_ENTRIES`` values.
    """

    #: Largest tables kept (their values and as many indices: 64 MiB).
    MAX_ENTRIES = 1 << 22

    #: The integrals packed: each row of a table is one cell's DOFs (an exterior facet's: its cell's).
    INTEGRALS = (_cpp.fem.IntegralType.cell, _cpp.fem.IntegralType.exterior_facet)

    def __init__(self, compiled):
        self._sources, base, size = [], [], 0
        starts = {}
        for function in compiled.coefficients:
            values = function.x.array
            pointer = values.__array_interface__["data"][0]
            if pointer not in starts:  # sub-functions of one mixed function share its array: copied once
                starts[pointer] = size
                self._sources.append((function, size))
                size += values.size
            base.append(starts[pointer])
        self._gathered = np.empty(size)
        self._tables = []  # (key, indices, table)
        for key in self.keys(compiled):
            cells = self.rows(compiled, key)
            columns = []
            for function, start in zip(compiled.coefficients, base):
                dofmap = function.function_space.dofmap
                dofs = dofmap.list().array.reshape(-1, dofmap.dof_layout.num_dofs)[cells]
                columns.append((start + dofs[:, :, None] * dofmap.bs + np.arange(dofmap.bs)).reshape(
                    len(cells), dofs.shape[1] * dofmap.bs))  # no rows: (0, stride), as dolfinx's
            indices = np.concatenate(columns, axis=1).astype(np.intp)
            self._tables.append((key, indices.reshape(-1), np.empty(indices.shape)))

    @staticmethod
    def keys(compiled) -> list[tuple]:
        """The form's integrals, as dolfinx keys its tables: (integral type, subdomain id)."""
        return [(kind, i) for kind in compiled.integral_types for i in compiled.integral_ids(kind)]

    @staticmethod
    def rows(compiled, key) -> np.ndarray:
        """The cells whose DOFs fill the rows of integral ``key``'s table, in order."""
        domains = np.asarray(compiled.domains(*key))
        return domains if key[0] == _cpp.fem.IntegralType.cell else domains.reshape(-1, 2)[:, 0]

    @classmethod
    def for_form(cls, compiled) -> "CoefficientPacker | None":
        """A packer of ``compiled`` that gives dolfinx's tables to the bit, or None (dolfinx packs)."""
        if not compiled.coefficients or any(kind not in cls.INTEGRALS for kind in compiled.integral_types):
            return None
        elements = [f.function_space.element for f in compiled.coefficients]
        if any(e.needs_dof_transformations for e in elements):
            return None
        rows = sum(len(cls.rows(compiled, key)) for key in cls.keys(compiled))
        if rows * sum(e.space_dimension for e in elements) > cls.MAX_ENTRIES:
            return None
        try:
            packer = cls(compiled)
            packed = packer.pack()
        except (ValueError, IndexError) as error:  # on one rank only, an error would leave the others waiting
            logger.debug("coefficients of a form left to dolfinx: %s", error)
            return None
        reference = _cpp.fem.pack_coefficients(compiled)
        if set(reference) != set(packed) or not all(
                np.array_equal(packed[key], reference[key], equal_nan=True) for key in reference):
            return None
        return packer

    def pack(self) -> dict:
        """The coefficients' tables, as dolfinx's assemblers take them (the same arrays every call)."""
        for function, start in self._sources:
            values = function.x.array
            self._gathered[start:start + values.size] = values
        for _, indices, table in self._tables:
            # "clip" writes into ``out`` directly ("raise" buffers a copy); the indices were checked at the first pack
            np.take(self._gathered, indices, out=table.reshape(-1), mode="clip")
        return {key: table for key, _, table in self._tables}


class _QuietBuild(logging.Filter):
    """Drop the compiler chatter setuptools logs at INFO while FFCx JIT-compiles."""

    def filter(self, record):
        return record.levelno >= logging.WARNING


def _silence_jit_logging():
    root = logging.getLogger()
    for handler in root.handlers:
        if not any(isinstance(f, _QuietBuild) for f in handler.filters):
            handler.addFilter(_QuietBuild())


def jit_parameters() -> dict:
    """FFCx's C compiler at ``-O3``, unless the user's dolfinx JIT configuration sets the compiler flags
    (to any value, dolfinx's own ``-O2`` included).

    dolfinx 0.5 compiles its kernels at ``-O2``; at ``-O3`` GCC vectorises the loops over the
    quadrature points.  Measured alone at 171 x 171 squares (example 1b) and 86 x 86 (2a):
    1b's active-stress load (six points a cell, a division at each) 4.3-4.6 -> 3.0-3.4 ms, to
    the same bits; 2a's Jacobian unchanged (85 ms), its residual slower, 9.4 -> 10.3 ms (0.1% of
    a step).  Compiling takes about 30% longer, once.  Portable code (no ``-march``): a cache
    shared by a cluster's nodes stays valid on each.  The flags are part of the cache key.
    A flag set in ``~/.config/dolfinx/dolfinx_jit_parameters.json`` or the working directory's
    ``dolfinx_jit_parameters.json`` wins.
    """
    from dolfinx import jit

    user, working_directory = jit._load_parameters()  # the two files, as dolfinx 0.5 reads them (cached)
    if "cffi_extra_compile_args" in user or "cffi_extra_compile_args" in working_directory:
        return {}
    return {"cffi_extra_compile_args": ["-O3", "-g0"]}


def _refuse_an_unwritable_jit_cache(parameters: dict) -> None:
    """One line when dolfinx's JIT cache (``~/.cache/fenics``, or ``$XDG_CACHE_HOME/fenics``) cannot be written.

    FFCx writes every kernel it compiles there: a read-only home (a cluster's compute nodes) was a traceback
    of FFCx's from the first function space, on every rank.
    """
    from dolfinx import jit

    cache = jit.get_parameters(parameters)["cache_dir"]
    try:
        cache.mkdir(parents=True, exist_ok=True)
        refusal = refusal_to_write(cache)
    except OSError as error:
        refusal = error
    if refusal is not None:
        raise ConfigError(f"dolfinx's JIT cache {cache} cannot be written ({reason_of(refusal)}): set XDG_CACHE_HOME "
                          f"to a writable folder (the kernels are compiled into XDG_CACHE_HOME/fenics)")


#: The fenicsx backends made in this process, in order, each with its communicators' keepers (``_petsc_comms``).
_RUNS: list[tuple[weakref.ref, dict]] = []


def _clean_up_after_earlier_runs(comm) -> None:
    """Free the PETSc objects of the runs whose backends are gone, and let their communicators go.

    A run's objects dropped after its last step, with its Simulation, wait in the garbage of dolfinx's
    communicators, which only a cleanup of each frees: a loop of runs in one process kept every earlier
    run's matrices and vectors (3.5 MB a run at 86^2 squares, 13 MB at 172^2).  Collective, as making a
    backend is: gc.collect() first, and what is gone on every rank only is freed.
    """
    gc.collect()
    gone = [run[0]() is None for run in _RUNS]
    if comm.size > 1:  # only what is gone on every rank: a script holding a run on one rank would hang the free
        every = comm.allgather(gone)
        gone = [all(flags) for flags in zip(*every)] if len({len(flags) for flags in every}) == 1 else []
    for run in [run for run, free in zip(list(_RUNS), gone) if free]:
        for keeper in run[1].values():
            PETSc.garbage_cleanup(keeper.getComm())
            keeper.destroy()  # the communicator goes with its last object
        _RUNS.remove(run)


class FenicsxBackend(Backend):
    """dolfinx 0.5.2: MPI-parallel assembly of UFL forms into PETSc objects."""

    name = "fenicsx"

    def __init__(self, comm=None):
        from mpi4py import MPI

        super().__init__(comm if comm is not None else MPI.COMM_WORLD)
        self._compiled = FormCache()  # compiled forms and expressions
        self._packers = FormCache(size=64)  # CoefficientPacker (or None) of the compiled forms last assembled
        self._vertex_maps: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._p1_spaces: dict[tuple, object] = {}
        self._components: dict[tuple, tuple] = {}
        self._petsc_comms: dict[int, object] = {}  # communicator -> an empty vector keeping it alive
        _clean_up_after_earlier_runs(self.comm)
        _RUNS.append((weakref.ref(self), self._petsc_comms))
        self._jit = jit_parameters()
        _refuse_an_unwritable_jit_cache(self._jit)
        _silence_jit_logging()

    # -- mesh, spaces, fields -----------------------------------------------------------
    def create_mesh(self, data: MeshData):
        # dolfinx partitions the cells with PT-SCOTCH, whose threads make the partition, and with it the
        # Krylov iterates, differ from run to run of the same command (example 1a at 171 x 171 squares:
        # 9 or 10 GMRES iterations of the cell density on 2 ranks); one thread per rank makes a run
        # reproducible.  Read by SCOTCH when it partitions; a user's own setting wins
        os.environ.setdefault(SCOTCH_THREADS, "1")
        gdim = data.gdim
        cell = ufl.triangle if gdim == 2 else ufl.tetrahedron
        # equispaced, as FFCx makes the coordinate element of a form it compiles: it replaced the mesh's own
        # in place, on the rank that compiled (rank 0, when the JIT cache lacked the form; the others read the
        # cache), and the forms built after it differed between the ranks, refused as a plugin's doing
        domain = ufl.Mesh(ufl.VectorElement(ufl.FiniteElement("Lagrange", cell, 1, variant="equispaced")))
        on_root = self.comm.rank == 0
        cells = data.cells if on_root else np.empty((0, gdim + 1), dtype=np.int64)
        points = data.points if on_root else np.empty((0, gdim))
        mesh = dolfinx.mesh.create_mesh(self.comm, cells, points, domain)
        self._refuse_ranks_without_cells(mesh, len(data.cells))
        mesh.mesh_data = data
        mesh.facet_tags = self._facet_tags(mesh, data)
        return mesh

    def _refuse_ranks_without_cells(self, mesh, num_cells: int) -> None:
        """A rank that owns no cell is refused on every rank: dolfinx 0.5.2 cannot work there (collapsing a
        vector field's component crashes the process), and a mesh of fewer cells than ranks leaves one."""
        owned = mesh.topology.index_map(mesh.topology.dim).size_local
        empty = [rank for rank, count in enumerate(self.comm.allgather(owned)) if count == 0]
        if empty:
            raise MeshError(f"the mesh has {num_cells} cells: on {self.comm.size} ranks, {len(empty)} own none "
                            f"(dolfinx cannot solve on a rank without cells); run it on fewer ranks")

    def _facet_tags(self, mesh, data: MeshData):
        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim - 1, tdim)
        if self.comm.rank == 0 and data.boundaries:
            facets = np.vstack(list(data.boundaries.values()))
            values = np.concatenate(
                [np.full(len(f), data.boundary_ids[name], dtype=np.int32) for name, f in data.boundaries.items()]
            )
        else:
            facets = np.empty((0, tdim), dtype=np.int64)
            values = np.empty((0,), dtype=np.int32)
        local_facets, local_values = _cpp.io.distribute_entity_data(mesh._mesh, tdim - 1, facets, values)
        adjacency = _cpp.graph.AdjacencyList_int32(local_facets)
        return dolfinx.mesh.meshtags_from_entities(mesh, tdim - 1, adjacency, local_values.astype(np.int32))

    def function_space(self, mesh, element):
        return fem.FunctionSpace(mesh, element)

    def function(self, space, name: str):
        function = fem.Function(space, name=name)
        self._track(function.vector)
        return function

    def _track(self, petsc_object):
        """Remember the communicator of ``petsc_object`` for :meth:`collect_garbage`; returns the object.

        PETSc frees a communicator with the last object on it, and cleaning a freed one aborts the
        run: an empty vector kept on it keeps it alive (made collectively, as the object was).
        """
        comm = petsc_object.getComm()
        key = comm.tompi4py().py2f()
        if key not in self._petsc_comms:
            self._petsc_comms[key] = PETSc.Vec().createMPI(0, comm=comm)
        return petsc_object

    def constant(self, mesh, value):
        return fem.Constant(mesh, PETSc.ScalarType(value) if np.isscalar(value) else np.asarray(value, float))

    def measure(self, integral_type: str, mesh, metadata=None):
        subdomain_data = mesh.facet_tags if integral_type == "ds" else None
        return ufl.Measure(integral_type, domain=mesh, subdomain_data=subdomain_data, metadata=metadata or {})

    # -- assembly -----------------------------------------------------------------------
    def _form(self, form: ufl.Form):
        return self._compiled.get(form, lambda: fem.form(form, jit_params=self._jit))

    def _coefficients(self, compiled) -> dict | None:
        """The packed coefficients of ``compiled`` (:class:`CoefficientPacker`), or None: dolfinx packs them."""
        packer = self._packers.get(compiled, lambda: CoefficientPacker.for_form(compiled))
        return None if packer is None else packer.pack()

    def assemble_matrix(self, form, bcs: Sequence[BoundaryCondition] = (), A=None, diagonal: float = 1.0):
        compiled = self._form(form)
        handles = [bc.handle for bc in bcs]
        coefficients = self._coefficients(compiled)
        if A is None:
            A = self._track(fem_petsc.assemble_matrix(compiled, bcs=handles, diagonal=diagonal, coeffs=coefficients))
        else:
            A.zeroEntries()
            fem_petsc.assemble_matrix(A, compiled, bcs=handles, diagonal=diagonal, coeffs=coefficients)
        A.assemble()
        return A

    def assemble_vector(self, form, b=None):
        compiled = self._form(form)
        if b is None:
            b = self._track(fem_petsc.assemble_vector(compiled, coeffs=self._coefficients(compiled)))
        else:
            with b.localForm() as local:
                local.set(0.0)
            fem_petsc.assemble_vector(b, compiled, coeffs=self._coefficients(compiled))
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        return b

    def assemble_scalar(self, form) -> float:
        return self.comm.allreduce(fem.assemble_scalar(self._form(form)))

    def extrema(self, expression, mesh) -> tuple[float, float]:
        compiled = self._compiled.get(
            expression, lambda: fem.Expression(expression, basix_reference_vertices(mesh.topology.cell_name()),
                                                jit_params=self._jit))
        cells = np.arange(mesh.topology.index_map(mesh.topology.dim).size_local, dtype=np.int32)
        values = compiled.eval(cells)
        low = float(values.min()) if values.size else np.inf
        high = float(values.max()) if values.size else -np.inf
        return reductions.extrema(self.comm, low, high)

    def assemble_residual(self, residual, jacobian, bcs, state, b=None):
        compiled = self._form(residual)
        if b is None:
            b = self._track(fem_petsc.create_vector(compiled))
        with b.localForm() as local:
            local.set(0.0)
        fem_petsc.assemble_vector(b, compiled, coeffs=self._coefficients(compiled))
        handles = [bc.handle for bc in bcs]
        if handles and _lifting_adds(handles, state):
            fem_petsc.apply_lifting(b, [self._form(jacobian)], bcs=[handles], x0=[state.vector], scale=-1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if handles:
            fem_petsc.set_bc(b, handles, state.vector, -1.0)
        return b

    def dirichlet_bc(self, space, boundary: str, value, component=None):
        mesh = space.mesh
        tdim = mesh.topology.dim
        facets = mesh.facet_tags.indices[mesh.facet_tags.values == mesh.mesh_data.boundary_id(boundary)]
        target = space
        for index in (component,) if isinstance(component, int) else (component or ()):
            target = target.sub(index)
        component = None if target is space else component
        collapsed = target.collapse()[0] if component is not None else space
        prescribed = fem.Function(collapsed)
        self._set_value(prescribed, value)
        if component is None:
            dofs = fem.locate_dofs_topological(space, tdim - 1, facets)
            handle = fem.dirichletbc(prescribed, dofs)
        else:
            dofs = fem.locate_dofs_topological((target, collapsed), tdim - 1, facets)
            handle = fem.dirichletbc(prescribed, dofs, target)
        bc = BoundaryCondition(handle=handle, space=space, boundary=boundary)
        object.__setattr__(bc, "_prescribed", prescribed)
        return bc

    def update_dirichlet_bc(self, bc: BoundaryCondition, value) -> None:
        self._set_value(bc._prescribed, value)

    def _set_value(self, function, value):
        if callable(value):
            self.interpolate(function, value)
        else:
            value = np.atleast_1d(np.asarray(value, dtype=float))
            bs = function.function_space.dofmap.index_map_bs
            function.x.array.reshape(-1, bs)[:] = value if value.size == bs else value[0]

    # -- DOF values ---------------------------------------------------------------------
    def petsc_vector(self, function):
        return function.vector

    def local_array(self, function) -> np.ndarray:
        return function.x.array

    def update_ghosts(self, function) -> None:
        function.x.scatter_forward()

    def interpolate(self, function, values) -> None:
        if isinstance(values, fem.Function):
            function.interpolate(values)
        elif callable(values):
            gdim = function.function_space.mesh.geometry.dim
            function.interpolate(lambda x: values(x[:gdim]))
        else:
            self._set_value(function, values)
        function.x.scatter_forward()

    def interpolate_component(self, function, index: int, values) -> None:
        part, dofs = self._component(function, index)
        self.interpolate(part, values)
        function.x.array[dofs] = part.x.array
        function.x.scatter_forward()

    def _component(self, function, index: int):
        """A scratch function in the collapsed sub-space ``index`` and its DOFs in the parent.

        Collapsing builds a new space, so it is done once per (space, index): the
        outputs ask for the components of a mixed field at every recorded time.
        """
        key = (id(function.function_space), index)
        if key not in self._components:
            sub_space, dofs = function.function_space.sub(index).collapse()
            self._components[key] = (function.function_space, fem.Function(sub_space), np.asarray(dofs))
        _, part, dofs = self._components[key]
        return part, dofs

    def _vertex_map(self, space):
        """(local P1 DOF -> original MeshData vertex index) for a P1 space."""
        key = id(space)
        if key not in self._vertex_maps:
            mesh = space.mesh
            nodes_per_cell = mesh.geometry.dofmap.links(0).size
            cell_dofs = space.dofmap.list.array.reshape(-1, nodes_per_cell)
            cell_nodes = mesh.geometry.dofmap.array.reshape(-1, nodes_per_cell)
            dof_to_node = np.empty(space.dofmap.index_map.size_local + space.dofmap.index_map.num_ghosts,
                                   dtype=np.int64)
            dof_to_node[cell_dofs.ravel()] = cell_nodes.ravel()
            original = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)[dof_to_node]
            self._vertex_maps[key] = (space, original)
        return self._vertex_maps[key][1]

    def _p1_space(self, space):
        """The P1 space of the same value shape (for vertex output of P2/mixed fields)."""
        element = space.ufl_element()
        if element.family() in ("Lagrange", "Q", "P") and element.degree() == 1:
            return space
        shape = element.value_shape()
        key = (id(space.mesh), shape)
        if key not in self._p1_spaces:
            cell = space.mesh.ufl_cell()
            p1 = (ufl.FiniteElement("Lagrange", cell, 1) if shape == ()
                  else ufl.VectorElement("Lagrange", cell, 1, dim=shape[0]))
            self._p1_spaces[key] = fem.FunctionSpace(space.mesh, p1)
        return self._p1_spaces[key]

    def set_vertex_values(self, function, values: np.ndarray) -> None:
        original = self._vertex_map(function.function_space)
        bs = function.function_space.dofmap.index_map_bs
        function.x.array.reshape(-1, bs)[:] = np.asarray(values).reshape(len(values), bs)[original]

    def _owned_vertex_values(self, function, component=None):
        """(P1 space, values at this rank's own vertices (n_owned, block size)) of a field or its component."""
        if component is not None:
            part, dofs = self._component(function, component)
            part.x.array[:] = function.x.array[dofs]
            function = part
        space = self._p1_space(function.function_space)
        if space is not function.function_space:
            p1 = fem.Function(space)
            p1.interpolate(function)
            function = p1
        bs = space.dofmap.index_map_bs
        return space, function.x.array.reshape(-1, bs)[:space.dofmap.index_map.size_local]

    def vertex_values(self, function, component=None):
        space, values = self._owned_vertex_values(function, component)
        original = self._vertex_map(space)[:len(values)]
        gathered = self.comm.gather((original, values.copy()), root=0)
        if self.comm.rank != 0:
            return None
        bs = values.shape[1]
        n_vertices = space.mesh.mesh_data.num_vertices
        result = np.empty((n_vertices, bs))
        for indices, vals in gathered:
            result[indices] = vals
        return result[:, 0] if bs == 1 else result

    def vertex_extrema(self, function, component=None) -> tuple[float, float]:
        values = self._owned_vertex_values(function, component)[1]
        low = float(values.min()) if values.size else np.inf
        high = float(values.max()) if values.size else -np.inf
        return reductions.extrema(self.comm, low, high)

    def collect_garbage(self) -> None:
        super().collect_garbage()
        # dolfinx's objects live on duplicates of the communicator (the mesh's, each function
        # space's index map's), and PETSc keys its garbage by its own communicator of each: the
        # ones seen on the objects made here, in the same order on every rank (made collectively)
        for keeper in self._petsc_comms.values():
            PETSc.garbage_cleanup(keeper.getComm())

    # -- sizes --------------------------------------------------------------------------
    def num_cells(self, mesh) -> int:
        return mesh.topology.index_map(mesh.topology.dim).size_global

    def num_dofs(self, space) -> int:
        return space.dofmap.index_map.size_global * space.dofmap.index_map_bs

    # -- DOF layout -----------------------------------------------------------------------
    def owned_dof_coordinates(self, space) -> np.ndarray:
        owned = space.dofmap.index_map.size_local
        return space.tabulate_dof_coordinates()[:owned, : space.mesh.geometry.dim].T.copy()

    def shares_dofs(self, space, other) -> bool:
        if space is other:
            return True
        if space.mesh is not other.mesh or space.ufl_element() != other.ufl_element():
            return False
        return (space.dofmap.index_map.size_local == other.dofmap.index_map.size_local
                and np.array_equal(space.dofmap.list.array, other.dofmap.list.array))

    def p1_cell_dofs(self, space, component=None):
        part, element = space, space.ufl_element()
        if component is not None:  # the sub-space path of a flat component: dolfinx's V.sub(i).sub(j)
            rest = component
            while isinstance(element, ufl.MixedElement):
                for index, sub in enumerate(element.sub_elements()):
                    size = int(np.prod(sub.value_shape()))
                    if rest < size:
                        part, element = part.sub(index), sub
                        break
                    rest -= size
                else:
                    return None
        if not is_p1_scalar(element) or part.dofmap.bs != 1 or space.mesh.geometry.cmap.degree != 1:
            return None
        cells = space.mesh.topology.index_map(space.mesh.topology.dim).size_local
        dofs = part.dofmap.list.array.reshape(-1, part.dofmap.cell_dofs(0).size)[:cells]
        return np.ascontiguousarray(dofs, dtype=np.int64)

    def p1_cell_coordinates(self, mesh):
        geometry = mesh.geometry
        cells = mesh.topology.index_map(mesh.topology.dim).size_local
        nodes = geometry.dofmap.array.reshape(-1, geometry.dofmap.links(0).size)[:cells]
        return np.ascontiguousarray(geometry.x[nodes][:, :, : geometry.dim])

    # -- field splits ---------------------------------------------------------------------
    def field_index_sets(self, space):
        index_map, bs = space.dofmap.index_map, space.dofmap.index_map_bs
        start, owned = index_map.local_range[0] * bs, index_map.size_local * bs
        fields = sub_elements(space.ufl_element())
        if len(fields) == 1:
            components = np.tile(np.arange(bs), index_map.size_local)
            return [index_set(self.comm, start + np.arange(owned), components, bs)]
        return [index_set(self.comm, *self._owned_field_dofs(space.sub(i), owned, start),
                          value_size=int(np.prod(element.value_shape())))
                for i, element in enumerate(fields)]

    @staticmethod
    def _owned_field_dofs(sub_space, owned: int, start: int) -> tuple[np.ndarray, np.ndarray]:
        """Global indices of the owned DOFs of one field of a mixed space, and the component of each."""
        dofs, components = [], []
        size = sub_space.num_sub_spaces
        for component, part in enumerate([sub_space.sub(c) for c in range(size)] if size else [sub_space]):
            local = np.asarray(part.collapse()[1])
            local = local[local < owned]
            dofs.append(start + local)
            components.append(np.full(len(local), component))
        return np.concatenate(dofs), np.concatenate(components)

    def set_dirichlet(self, vector, bcs, x0=None, scale: float = 1.0) -> None:
        fem_petsc.set_bc(vector, [bc.handle for bc in bcs], x0, scale)
