r"""Edge-averaged exponentially fitted transport (Scharfetter-Gummel / EAFE) for P1.

For the flux J = -D grad c + chi c grad a (a species c climbing the gradient of
an attractant a), the operator A with

    A_ij = -w_ij D B(Pe_ij),       A_ii = sum_j w_ij D B(-Pe_ij),
    Pe_ij = chi_ij (a_j - a_i) / D,     B(x) = x / (exp(x) - 1),

is built from the P1 stiffness matrix S of the mesh (w_ij = -S_ij, the
"cotangent" edge weights) and vertex values of the species c and of a, with
chi_ij = chi((c_i + c_j)/2), the sensitivity at the edge midpoint.  A has non-positive off-diagonals and zero column sums, so
M_L/dt + A is an M-matrix on meshes with w_ij >= 0: the transported density
stays non-negative and its integral is conserved exactly.  For |Pe| << 1,
B(x) ~ 1 - x/2 and A reduces to the central (second-order) discretisation
(Xu & Zikatanov, Math. Comp. 68 (1999) 1429-1446).

The construction is row-local on the assembled PETSc matrix (global column
indices, ghost values gathered), so it runs unchanged on every backend and in
parallel.  The operator applies itself (:meth:`AlgebraicOperator.apply`): the
solver layer adds its matrix and its action without knowing what it is.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import ufl
from petsc4py import PETSc
from scipy.sparse import csr_matrix as _csr

from primordia.core import compiled
from primordia.core.petsc_library import BlockPlaces, update_mpiaij_values
from primordia.core.reductions import largest, smallest
from primordia.physics.base import AlgebraicOperator
from primordia.physics.discretisation import Discretisation


def bernoulli(x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """B(x) = x / (exp(x) - 1), with B(0) = 1, accurate near 0 and for large |x|; into ``out`` if given.

    expm1 keeps its relative accuracy as x -> 0, so x / expm1(x) is within about 2 ulps of B(x)
    for every x != 0 (no switch to a series is needed); only x = 0 (0/0) is set apart.
    """
    x = np.asarray(x, dtype=float)
    flat = x.reshape(-1)
    if out is not None and (out.shape != flat.shape or not out.flags.writeable):
        raise ValueError(f"bernoulli: out must be a writeable array of shape {flat.shape}, got {out.shape}")
    result = np.empty_like(flat) if out is None else out
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # x >> 1: expm1 overflows, B(x) -> 0
        np.expm1(flat, out=result)
        np.divide(flat, result, out=result)
    zero = flat == 0.0
    if zero.any():
        result[zero] = 1.0
    if out is not None:
        return out
    return result.reshape(x.shape) if x.ndim else result[0]


class ExponentiallyFittedFlux(AlgebraicOperator):
    """A(chi(c^n), a^n) for the species ``species`` climbing ``attractant``.

    ``sensitivity`` maps vertex values of ``c^n`` to chi (numpy); the state read
    is the start-of-step value (``disc.previous``), as the IMEX scheme requires.
    """

    def __init__(self, disc: Discretisation, species: str, attractant: str, diffusivity: float,
                 sensitivity: Callable[[np.ndarray], np.ndarray], metric=None, quadrature_degree: int | None = None):
        self.disc, self.species, self.attractant = disc, species, attractant
        self.diffusivity = float(diffusivity)
        self.sensitivity = sensitivity
        space = disc.field(species).ufl_function_space()
        trial, test = ufl.TrialFunction(space), ufl.TestFunction(space)
        gradient = ufl.grad(trial) if metric is None else ufl.dot(metric, ufl.grad(trial))
        self._stiffness_form = ufl.inner(gradient, ufl.grad(test)) * disc.dx_degree(quadrature_degree)
        self._moving = metric is not None  # the metric follows the deformation: reassemble at every update
        self.negative_weights = 0  # edges with w_ij < 0 at the last update (0: an M-matrix)
        self.most_negative_weight = 0.0  # the most negative w_ij relative to the largest one (<= 0)
        stiffness = disc.assemble_matrix(self._stiffness_form)
        self._stiffness = stiffness.duplicate(copy=True) if self._moving else None
        self._A = stiffness
        self._prepare_edges(stiffness)
        self._prepare_gather(disc.previous_vector(species))
        self._prepare_pairs()
        self._in_place = self._share_values(stiffness)
        self._by_rows = not self._in_place and self._rows_of_values(stiffness)
        self._shifted = False  # whether the values hold the diagonal of shifted(), until the next update
        self._shift = None  # that diagonal (a Vec, made once)
        self._compiled = None  # the compiled loops, False for numpy's (decided at the first update, collectively)
        self._midpoints = None  # the species at the edge midpoints, for the compiled loops
        self._row_places = self._block_places = None  # their positions (_in_rows, _in_blocks)
        self._blocks = None  # on several processes with the compiled loops: the blocks' places of the values

    def _prepare_edges(self, stiffness):
        indptr, columns, values = stiffness.getValuesCSR()
        start = stiffness.getOwnershipRange()[0]
        rows_global = np.repeat(np.arange(len(indptr) - 1) + start, np.diff(indptr))
        self._indptr, self._columns = indptr, columns
        self._diagonal = columns == rows_global
        self._row = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))  # local row of each entry
        self._diag_positions = np.flatnonzero(self._diagonal)
        if len(self._diag_positions) != len(indptr) - 1:
            raise ValueError("the stiffness matrix lacks diagonal entries")
        self._set_weights(values)

    def _set_weights(self, values):
        """Edge weights w_ij = -S_ij (scaled by D), and how many are negative (not an M-matrix)."""
        weights = np.where(self._diagonal, 0.0, -values)
        comm = self.disc.comm
        scale = largest(comm, float(np.abs(values).max(initial=0.0)))
        self.negative_weights = comm.allreduce(int((weights < -1e-12 * scale).sum())) // 2  # each edge twice
        heaviest = largest(comm, float(weights.max(initial=0.0)))
        self.most_negative_weight = smallest(comm, float(weights.min(initial=0.0))) / heaviest
        self._scaled_weights = weights * self.diffusivity  # w_ij D (0 on the diagonal)

    def _prepare_gather(self, template):
        """A scatter bringing the values at every column of the local rows to this rank.

        A matrix row may reference DOFs that are neither owned nor ghosts here (cells
        sharing only a vertex with this rank's cells), so ghost values are not enough.
        """
        needed, self._entry_column = np.unique(self._columns, return_inverse=True)
        # the species' and the attractant's gathered values, in arrays of this object's own
        self._gathered_values = {name: np.zeros(len(needed)) for name in (self.species, self.attractant)}
        self._gathered_vectors = {name: PETSc.Vec().createWithArray(values, comm=PETSc.COMM_SELF)
                                  for name, values in self._gathered_values.items()}
        self._gathered = self._gathered_vectors[self.species]
        index_set = PETSc.IS().createGeneral(needed.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
        self._scatter = PETSc.Scatter().create(template, index_set, self._gathered, None)
        # the gathered position of the row DOF of each entry (its row's diagonal entry's column)
        self._entry_row = self._entry_column[self._diag_positions][self._row]

    def _prepare_pairs(self):
        """The edge of each entry, so that the costly functions are evaluated once per edge.

        An edge {i, j} appears as the entries (i, j) and (j, i), whose Peclet numbers are
        opposite: both B(Pe_ij) and B(-Pe_ij) follow from B at the edge's Peclet number by
        B(-x) = B(x) + x.  An update is then sparse products with matrices fixed by the mesh:
        the edge midpoints and differences of the gathered vertex values (``_midpoint``,
        ``_difference``), and the entries of A from the per-edge table [B(Pe), B(Pe) + Pe]
        (``_entries``: -w_ij D at B(Pe_ij) for an off-diagonal entry, w_ij D at each B(-Pe_ij)
        of its row for a diagonal one).  Gathered positions are ordered like global indices.
        Those matrices are made from the edges' ends (``_edge_ends``) at the numpy branch's first
        update (:meth:`_numpy_products`); the compiled loops read the ends and ``_edge_positions``.
        """
        off = ~self._diagonal
        i, j = self._entry_row[off], self._entry_column[off]
        size = self._gathered_size()
        low, high = np.minimum(i, j), np.maximum(i, j)
        edges, edge_of = np.unique(low.astype(np.int64) * size + high, return_inverse=True)
        edge_low, edge_high = edges // size, edges % size
        n_edges, n_entries = len(edges), len(self._columns)
        self._edge_ends = tuple(np.ascontiguousarray(end, dtype=np.int64) for end in (edge_low, edge_high))
        self._midpoint = self._difference = None  # the numpy branch's (_numpy_products)
        forward = i < j  # entry (i, j) runs from the edge's low end to its high end
        toward = edge_of + n_edges * ~forward  # B(Pe_ij) in the table
        away = edge_of + n_edges * forward  # B(-Pe_ij) in the table
        entries = np.flatnonzero(off)
        self._entry_pattern = (np.r_[entries, self._diag_positions[self._row[entries]]], np.r_[toward, away])
        # for the compiled loops: per edge, the positions of its two entries and of its ends' diagonal entries
        # (-1: a row of another process)
        positions = {key: np.full(n_edges, -1, dtype=np.int64) for key in ("forward", "backward", "low", "high")}
        for direction, end, chosen in (("forward", "low", forward), ("backward", "high", ~forward)):
            positions[direction][edge_of[chosen]] = entries[chosen]
            positions[end][edge_of[chosen]] = self._diag_positions[self._row[entries[chosen]]]
        self._edge_positions = (positions["forward"], positions["backward"], positions["low"], positions["high"],
                                np.ascontiguousarray(self._diag_positions, dtype=np.int64))
        self._entries = None
        self._table = np.zeros(2 * n_edges)
        self._values = np.zeros(n_entries)
        # PETSc views of the two: the entry product writes the operator's values in place
        self._values_vector = PETSc.Vec().createWithArray(self._values, comm=PETSc.COMM_SELF)
        self._table_vector = PETSc.Vec().createWithArray(self._table, comm=PETSc.COMM_SELF)

    def _gathered_size(self) -> int:
        return max(len(self._gathered_values[self.species]), 1)

    def _numpy_products(self) -> None:
        """The numpy branch's sparse matrices of the edges' midpoints and differences over D (the Peclet
        number without another pass over the edges), from ``_edge_ends``, and its entry matrix."""
        low, high = self._edge_ends
        n_edges, size = len(low), self._gathered_size()
        rows, ones = np.arange(n_edges), np.ones(n_edges)
        self._midpoint = _csr((np.r_[ones, ones] / 2, (np.r_[rows, rows], np.r_[low, high])), (n_edges, size))
        self._difference = _csr((np.r_[ones, -ones] / self.diffusivity, (np.r_[rows, rows], np.r_[high, low])),
                                (n_edges, size))
        self._entries = self._entry_matrix()

    def _entry_matrix(self):
        """``_entries`` for the current weights (see :meth:`_prepare_pairs`), a serial PETSc matrix whose
        product writes into the operator's values (``_values_vector`` wraps them) without a copy.

        Its pattern is fixed by the mesh: made once, with the order that takes the entries'
        values (-w_ij for the off-diagonal entries, then w_ij for the diagonal ones) into it.
        On a moving mesh (the metric follows the deformation) an update only rewrites the values
        through :meth:`_refresh_entries`, where PETSc reads them.
        """
        rows, columns = self._entry_pattern
        order = np.lexsort((columns, rows))  # CSR: by row, columns sorted in each row, as PETSc expects
        rows, columns = rows[order], columns[order]
        if np.any((np.diff(rows) == 0) & (np.diff(columns) == 0)):
            raise ValueError("an edge appears twice in a row of the fitted operator")
        shape = (len(self._values), len(self._table))
        indptr = np.searchsorted(rows, np.arange(shape[0] + 1)).astype(PETSc.IntType)
        self._entry_order = order
        self._entry_values = np.empty(len(order))
        self._entries_csr = (indptr, columns.astype(PETSc.IntType), self._entry_values)
        self._write_entry_values()
        entries, self._entries_shared = _aij_over(shape, self._entries_csr, PETSc.COMM_SELF)
        return entries

    def _write_entry_values(self) -> None:
        weights = self._scaled_weights[self._entry_pattern[0][: len(self._entry_pattern[0]) // 2]]
        np.take(np.concatenate((-weights, weights)), self._entry_order, out=self._entry_values)

    def _refresh_entries(self) -> None:
        """New weights (a moving mesh): the entry matrix's values rewritten in place."""
        self._write_entry_values()
        if not self._entries_shared:
            self._entries.setValuesCSR(*self._entries_csr)
        self._entries.assemble()

    def _share_values(self, stiffness) -> bool:
        """On one process, make the operator a matrix over this object's own CSR arrays.

        An update then writes the entries where PETSc reads them, without a copy
        (``setValuesCSR`` costs as much as the rest of an update); several processes
        take their values row by row instead (:meth:`_rows_of_values`), as PETSc copies arrays into a
        parallel matrix.
        """
        if stiffness.getComm().getSize() != 1 or self._moving:
            return False
        self._indptr = self._indptr.astype(PETSc.IntType)
        self._columns = self._columns.astype(PETSc.IntType)
        self._A, shared = _aij_over(stiffness.getSizes(), (self._indptr, self._columns, self._values),
                                    stiffness.getComm())
        return shared

    def _rows_of_values(self, stiffness) -> bool:
        """On several processes, make the operator a parallel matrix from this object's CSR rows, whose values
        an update then copies in row by row (:func:`~primordia.core.petsc_library.update_mpiaij_values`).

        ``setValuesCSR`` looks every entry up: 1.1 ms of a 16 ms step of example 1a at 171^2 on 2 ranks,
        where the one-process operator writes PETSc's own arrays.  The copy by rows needs each row's
        columns sorted, as PETSc's rows are; if any rank's are not, all keep ``setValuesCSR``.
        """
        comm = stiffness.getComm()
        if comm.getSize() == 1:
            return False
        same_row = np.diff(self._row) == 0
        ordered = bool(np.all(np.diff(self._columns)[same_row] > 0))
        if not all(comm.tompi4py().allgather(ordered)):
            return False
        self._A = PETSc.Mat().createAIJWithArrays(
            stiffness.getSizes(), (self._indptr.astype(PETSc.IntType), self._columns.astype(PETSc.IntType), self._values),
            comm=comm)
        self._A.assemble()
        # every later change (the update's rows, shifted()'s diagonal) is to this rank's own rows: an assembly
        # then skips PETSc's reduction over the ranks for entries to send (two a step of example 1a)
        self._A.setOption(PETSc.Mat.Option.NO_OFF_PROC_ENTRIES, True)
        return True

    def _gather(self, name: str) -> np.ndarray:
        """The start-of-step values of ``name`` at every column of the local rows (this object's array)."""
        self._scatter.scatter(self.disc.previous_vector(name), self._gathered_vectors[name],
                              addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return self._gathered_values[name]

    def update(self) -> None:
        if self._moving:
            self.disc.assemble_matrix(self._stiffness_form, A=self._stiffness)
            self._set_weights(self._stiffness.getValuesCSR()[2])
        if self._compiled is None:
            self._compiled = compiled.kernels(self.disc.comm) or False
            if self._by_rows and self._compiled:  # collective, as the decision above; the loops write there
                self._blocks = BlockPlaces.of(self._A, self._columns)
        c, a = self._gather(self.species), self._gather(self.attractant)
        if self._compiled and self._blocks is not None:  # straight into PETSc's blocks
            with self._blocks.blocks() as (diagonal, off_diagonal):
                self._compiled_values(c, a, self._in_blocks(), diagonal, off_diagonal)
        elif self._compiled:
            self._compiled_values(c, a, self._in_rows(), compiled.address(self._values), None)
        else:
            if self._entries is None:
                self._numpy_products()
            elif self._moving:
                self._refresh_entries()
            chi = self.sensitivity(self._midpoint @ c)  # at the edge midpoint, as quadrature would
            peclet = chi * (self._difference @ a)  # Pe from the low end to the high end
            n_edges = len(peclet)
            bernoulli(peclet, out=self._table[:n_edges])
            np.add(self._table[:n_edges], peclet, out=self._table[n_edges:])  # B(-x) = B(x) + x
            # A_ij = -w_ij D B(Pe_ij), A_ii = sum_j w_ij D B(-Pe_ij)
            self._entries.mult(self._table_vector, self._values_vector)
        self._shifted = False  # every value was just rewritten
        if self._blocks is None:  # otherwise the loops wrote into PETSc's blocks
            if self._by_rows:
                update_mpiaij_values(self._A, self._values)
            elif not self._in_place:
                self._A.setValuesCSR(self._indptr, self._columns, self._values)
        self._A.assemble()  # also marks the matrix changed, for the solver's preconditioner

    def _compiled_values(self, c: np.ndarray, a: np.ndarray, places: tuple, values_at: int, other_at) -> None:
        """The operator's values by the compiled loops (:mod:`primordia.core.compiled`): the same operations
        as the numpy branch of :meth:`update`, without its temporaries, with libmvec's exp and expm1 (within
        4 ulps of numpy's), and the entries written edge by edge instead of by a product with the entry
        matrix (the same sums, in the same order): 2.9-3.0 -> 1.3-1.7 ms an update at 171^2 (88k edges, 206k
        entries; the best of 7 x 100 updates, twice each).

        ``places``: the addresses of the entries' weights, the edges' entry positions and the diagonal
        positions, then the split (:meth:`_in_rows`, :meth:`_in_blocks`); the values go to ``values_at``, and
        positions at or past the split to ``other_at``.
        """
        library, (low, high) = self._compiled, self._edge_ends
        n_edges = len(low)
        if self._midpoints is None:  # the arrays below live as long as this object
            self._midpoints = np.empty(n_edges)
            self._edge_addresses = (compiled.address(low, np.int64), compiled.address(high, np.int64),
                                    compiled.address(self._midpoints), compiled.address(self._table))
        low_at, high_at, midpoints_at, table_at = self._edge_addresses
        library.primordia_edge_midpoints(n_edges, compiled.address(c), low_at, high_at, midpoints_at)
        chi = np.asarray(self.sensitivity(self._midpoints), dtype=float)  # at the edge midpoint
        if chi.shape != (n_edges,) or not chi.flags.c_contiguous:
            chi = np.ascontiguousarray(np.broadcast_to(chi, (n_edges,)))
        library.primordia_edge_bernoulli(n_edges, compiled.address(chi), compiled.address(a), low_at, high_at,
                                         1.0 / self.diffusivity, table_at)
        weights_at, *positions_at, split = places
        library.primordia_edge_entries(n_edges, len(self._diag_positions), table_at, weights_at, *positions_at,
                                       split, values_at, other_at)

    def _in_rows(self) -> tuple:
        """The compiled loops' places for values in the rows' order (``_values``): the positions as they are."""
        if self._row_places is None:
            self._row_places = tuple(compiled.address(positions, np.int64) for positions in self._edge_positions)
        return (compiled.address(self._scaled_weights), *self._row_places, len(self._values))

    def _in_blocks(self) -> tuple:
        """The compiled loops' places for values written straight into the parallel matrix's diagonal and
        off-diagonal blocks (:class:`~primordia.core.petsc_library.BlockPlaces`): every position renumbered
        once, and the weights into the same numbering whenever they change (a moving mesh's every update).

        Saves copying the values into the blocks after the loops (0.11 ms a step of example 1a at 171^2 on 2
        ranks, of 7.0)."""
        if self._block_places is None or self._block_places["blocks"] is not self._blocks:
            place, split = self._blocks.place, self._blocks.split
            renumbered = tuple(np.where(positions >= 0, place[np.maximum(positions, 0)], -1)
                               for positions in self._edge_positions)
            if any(np.any(renumbered[k] >= split) for k in (2, 3, 4)):  # low, high and every diagonal entry
                raise ValueError("a diagonal entry of the fitted operator is outside the diagonal block")
            weights = np.empty(len(place))
            self._block_places = {"blocks": self._blocks, "place": place, "weights": weights, "of": None,
                                  "renumbered": renumbered,  # kept alive: the loops read them by address
                                  "addresses": (compiled.address(weights), *(compiled.address(positions, np.int64)
                                                                             for positions in renumbered), split)}
        places = self._block_places
        if places["of"] is not self._scaled_weights:  # new weights: into the blocks' numbering
            places["weights"][places["place"]] = self._scaled_weights
            places["of"] = self._scaled_weights
        return places["addresses"]

    def matrix(self):
        if self._shifted:  # A again, without the diagonal of shifted()
            self._shift.scale(-1.0)
            self._A.setDiagonal(self._shift, addv=PETSc.InsertMode.ADD_VALUES)
            self._shifted = False
            self._A.assemble()
        return self._A

    def shifted(self, diagonal):
        """A + diag(d) in the operator's PETSc matrix: the lumped mass of the cell density's step added
        without copying the matrix.

        PETSc adds the diagonal (MatDiagonalSet finds each row's diagonal entry itself): 58 us at
        171^2, against 145 for numpy's ``values[diagonal positions] += d``, the same numbers.  On any
        number of processes: every :meth:`update` rewrites all the values (PETSc's own arrays on one
        process, a copy by rows or ``setValuesCSR`` on several), so the shift lasts until the next
        update or :meth:`matrix`.  On 2 ranks this spares the solver a copy of the matrix at every step.
        """
        if self._shifted:
            self.matrix()
        if self._shift is None:
            self._shift = diagonal.duplicate()
        diagonal.copy(self._shift)
        self._shifted = True
        self._A.setDiagonal(self._shift, addv=PETSc.InsertMode.ADD_VALUES)
        self._A.assemble()  # marks the matrix changed
        return self._A


def _aij_over(shape, csr: tuple, comm) -> tuple:
    """A PETSc AIJ matrix over the CSR arrays ``csr``, and whether it reads their values in place.

    PETSc copies arrays of another type than its own: the sharing is checked once, and a
    matrix that does not share is given the values by ``setValuesCSR``.
    """
    matrix = PETSc.Mat().createAIJWithArrays(shape, csr, comm=comm)
    matrix.assemble()
    values = csr[2]
    if len(values) == 0:
        return matrix, True
    kept, values[0] = values[0], np.nan  # a value no assembly gives
    shared = bool(np.isnan(matrix.getValuesCSR()[2][0]))
    values[0] = kept
    if not shared:
        matrix.setValuesCSR(*csr)
        matrix.assemble()
    return matrix, shared


