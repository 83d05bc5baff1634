"""The assembled remainders of several linear subproblems as one form.

A species' explicit terms that must be assembled cell by cell (the advection by the solid
velocity, u_t . grad c^n, seed (2.3a), (2.3c), (2.3d); the FGF sink of (2.3c)) are
assembled at every step, one form per species, and each assembly packs the coefficients
it reads anew: the solid velocity three times for m, f and b.  With every member's test
function replaced by one component of a blocked P1 space,

    L(w) = sum_k R_k(w_k),     w = (w_1, ..., w_K),

is one assembly whose component k is R_k's vector: every coefficient is packed once and
each cell computes the K rows in one pass.  The physics is the members' own UFL.  Example
1b at 171^2 (``benchmarks/bench_solvers.py --share ex01b --sizes 171 --backends fenicsx skfem
--steps 40 --warmup 1 --clock wall``, two alternating pairs with and without): fenicsx 77.8 and
78.2 against 78.4 and 79.9 ms/step; skfem unchanged (104.8-105.1 against 104.7-104.9), whose
kept field values already spared the velocity's interpolation per species.

When the merged form has a closed form (every member the advection of a P1 field by a P1
velocity, as example 1b's m, f and b: :mod:`primordia.coupling.p1_advection`), the batch is
evaluated from it instead of assembled, chosen as a lone remainder's is
(:func:`~primordia.coupling.affine.closed_form`, checked against assembly before its first use).

Members share a P1 scalar space's DOFs.  The batch is assembled when its first member asks
(each pass over the solvers asks in their order, the first member first) and serves the
others from it; :func:`batch_remainders` admits a member only when no solve between the
first member's and its own changes a field its remainder reads.
"""

from __future__ import annotations

import functools
import operator

import numpy as np
import ufl

from primordia.coupling.affine import closed_form
from primordia.coupling.nodal import _is_p1_scalar


class RemainderBatch:
    """The assembled remainders of ``members`` (:class:`~primordia.coupling.affine.AffineResidual`) as one form."""

    def __init__(self, backend, form, positions: list[np.ndarray]):
        self.backend = backend
        self._form = form  # the members' remainders, each on its component of a blocked P1 space
        self._positions = positions  # per member: where its owned DOFs sit in the blocked vector's owned array
        self._vector = None
        self._values = None
        self.closed_form = closed_form(backend, form)  # e.g. P1 advection terms only: their closed form

    @classmethod
    def build(cls, backend, remainders: list):
        """A batch of ``remainders`` (linear forms on spaces that share a P1 space's DOFs), or None."""
        tests = [form.arguments()[0] for form in remainders]
        space = tests[0].ufl_function_space()
        element = ufl.VectorElement("Lagrange", space.ufl_domain().ufl_cell(), 1, dim=len(remainders))
        blocked = backend.function_space(space.mesh, element)
        test = ufl.TestFunction(blocked)
        merged = functools.reduce(operator.add, (ufl.replace(form, {argument: test[k]})
                                                 for k, (form, argument) in enumerate(zip(remainders, tests))))
        positions = _component_positions(backend, blocked, space, len(remainders))
        if not all(backend.comm.allgather(positions is not None)):  # every rank batches, or none
            return None
        return cls(backend, merged, positions)

    def evaluate(self) -> None:
        """Assemble the merged form (the first member's solve)."""
        if self.closed_form is not None:
            self._vector = self.closed_form.assemble(self._vector)
        else:
            self._vector = self.backend.assemble_vector(self._form, b=self._vector)
        self._values = self._vector.getArray(readonly=True)

    def vector(self, index: int, b):
        """Member ``index``'s remainder into ``b`` (a Vec of its space); the first member assembles the batch."""
        if index == 0 or self._values is None:
            self.evaluate()
        b.setArray(self._values[self._positions[index]])
        return b


def _component_positions(backend, blocked, space, count: int) -> list[np.ndarray] | None:
    """Per component of ``blocked``: the positions in its owned array of ``space``'s owned DOFs, in their order.

    Found from the nodes (P1: one DOF per vertex): the blocked space is given each component's
    index and the coordinates, and its owned positions are matched to ``space``'s owned DOF
    coordinates.  None when they do not match (another partition of the DOFs).
    """
    coordinates = backend.owned_dof_coordinates(space)                       # (gdim, n)
    gdim, owned = coordinates.shape
    probe = backend.function(blocked, "batch_probe")
    backend.interpolate(probe, lambda x: np.tile(np.arange(count, dtype=float)[:, None], (1, x.shape[1])))
    component = backend.petsc_vector(probe).getArray(readonly=True).copy()
    at = []
    for d in range(gdim):
        backend.interpolate(probe, lambda x, d=d: np.tile(x[d], (count, 1)))
        at.append(backend.petsc_vector(probe).getArray(readonly=True).copy())
    at = np.array(at)                                                        # (gdim, count * n)
    mine = np.lexsort(coordinates[::-1])                                     # space's DOFs by coordinates
    positions = []
    for k in range(count):
        where = np.flatnonzero(component == k)
        if len(where) != owned:
            return None
        order = where[np.lexsort(at[:, where][::-1])]                        # component k's positions by coordinates
        if not np.allclose(at[:, order], coordinates[:, mine], rtol=0.0, atol=1e-12 * max(1.0, np.abs(coordinates).max(initial=0.0))):
            return None
        placed = np.empty(owned, dtype=np.int64)
        placed[mine] = order
        positions.append(placed)
    return positions


def batch_remainders(backend, solvers: list) -> list:
    """Put the assembled remainders of ``solvers`` (a list solved in this order) that can be assembled together
    into :class:`RemainderBatch` es; returns the batches made.

    A member's remainder must be a linear form on a P1 scalar space sharing the first member's
    DOFs, and read no unknown of a solver from the first member's on to its own (those solves
    run between the batch's assembly and its use).
    """
    candidates = []
    for position, solver in enumerate(solvers):
        affine = getattr(solver, "_affine", None)
        if affine is None or not affine.available or affine.batch is not None or affine.assembled_remainder is None:
            continue
        space = affine.assembled_remainder.arguments()[0].ufl_function_space()
        if _is_p1_scalar(space):
            candidates.append((position, solver, space))
    if len(candidates) < 2:
        return []
    first_position, _, first_space = candidates[0]
    members = [candidates[0]]
    for position, solver, space in candidates[1:]:
        reads = solver._affine.assembled_remainder.coefficients()
        between = [other.sub.unknown for other in solvers[first_position:position]]
        if backend.shares_dofs(space, first_space) and not any(unknown in reads for unknown in between):
            members.append((position, solver, space))
    chosen = [position for position, _, _ in members]
    if len(members) < 2 or any(other != chosen for other in backend.comm.allgather(chosen)):
        return []  # every rank batches the same members, or none
    batch = RemainderBatch.build(backend, [solver._affine.assembled_remainder for _, solver, _ in members])
    if batch is None:
        return []
    for index, (_, solver, _) in enumerate(members):
        solver._affine.batch = (batch, index)
    return [batch]
