"""A linear subproblem as matrices times fields: a step that costs little more than its solve.

The residual of a linear subproblem (one exact Newton step solves it) is affine in
its unknown x, and often in other fields it reads too.  Split it once, from its UFL
form:

    F(x) = sum_c B_c c + R,      B_c = dF/dc for every field c whose derivative reads no field,

where c runs over x itself (B_x = J, a constant Jacobian), its value at the start of the
step, a solid velocity, another species that enters linearly, and R (what is left, e.g. a
reaction nonlinear in another field or a time-dependent load) is assembled at every solve,
or never when nothing is left (several subproblems' R together, as one form, when they can:
:mod:`primordia.coupling.batched`).  Each B_c is assembled once, and again only when a UFL
constant it reads changes value (dt in an adaptive run); a diagonal one (lumped, vertex
quadrature) is kept as a vector and applied pointwise.  A Jacobian that reads fields but is
diagonal (a lumped reaction) is assembled as a vector, never as a matrix: the solve is then a
division.  A lumped remainder or diagonal whose integrand has one value at each vertex (the
explicit reactions) is not assembled at all but evaluated at the nodes
(:mod:`primordia.coupling.nodal`).  The physics is still stated once, in UFL: these are its
own derivatives.
"""

from __future__ import annotations

import numpy as np
import ufl
from petsc4py import PETSc
from ufl.algorithms import expand_derivatives

from primordia.coupling.constant_load import ConstantLoad
from primordia.coupling.nodal import NodalGroup, nodal_form, nodal_part
from primordia.coupling.p1_advection import P1Advection
from primordia.coupling.p1_gradient_load import P1GradientLoad

_UNDECIDED = object()  # a closed form not yet looked for

#: What evaluates a linear form without cell-by-cell assembly, tried in this order (each reads the form's UFL
#: and passes a check against assembly before its first use, or declines).
CLOSED_FORMS = (P1Advection, P1GradientLoad, ConstantLoad)


def closed_form(backend, form):
    """The first of :data:`CLOSED_FORMS` that evaluates ``form`` (a linear form), or None: assemble it.

    The one place the choice is made, for a subproblem's own remainder (:class:`AffineResidual`) and for
    several remainders assembled as one form (:class:`~primordia.coupling.batched.RemainderBatch`).  It is
    collective: every rank must ask, with the same form.
    """
    for kind in CLOSED_FORMS:
        evaluator = kind.recognise(backend, form)
        if evaluator is not None:
            return evaluator
    return None


def _constants_state(constants) -> tuple:
    """The values of UFL constants (to see whether a matrix assembled with them is stale)."""
    return tuple(np.array(constant.value, dtype=float).tobytes() for constant in constants)


def structurally_diagonal(form) -> bool:
    """A bilinear form on one P1 scalar space, integrated at the vertices only (lumped): its matrix is diagonal."""
    test, trial = form.arguments()
    space = test.ufl_function_space()
    element = space.ufl_element()
    if trial.ufl_function_space() != space or element.value_shape() != () or element.degree() != 1:
        return False
    return bool(form.integrals()) and all(
        integral.integral_type() == "cell" and integral.metadata().get("quadrature_rule") == "vertex"
        for integral in form.integrals())


def _without_stored_zeros(matrix):
    """``matrix`` on the pattern of its non-zero values only, when that saves at least a quarter.

    A backend assembles a form on the sparsity pattern of its whole space: the part of
    linear Biot's residual that multiplies u^n (the fluid equation's alpha div u^n and
    the storage of p^n) fills 55% of the (u, p) pattern and the one that multiplies the
    rate 22%, so a product with the assembled matrix spends most of its time on zeros.
    """
    indptr, columns, values = matrix.getValuesCSR()
    kept = values != 0.0
    if kept.sum() > 0.75 * len(values):
        return matrix
    rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))[kept]
    new_indptr = np.zeros(len(indptr), dtype=PETSc.IntType)
    np.cumsum(np.bincount(rows, minlength=len(indptr) - 1), out=new_indptr[1:])
    compact = PETSc.Mat().createAIJ(matrix.getSizes(), csr=(new_indptr, columns[kept].astype(PETSc.IntType), values[kept]),
                                    comm=matrix.getComm())
    compact.assemble()
    return compact


class _Matrix:
    """An assembled bilinear form, kept while the constants it reads keep their values.

    A lumped form (see :func:`structurally_diagonal`) without Dirichlet conditions is assembled
    as the vector of its diagonal only; any other form as a matrix, whose diagonal is also kept
    when the assembled matrix turns out diagonal.
    """

    def __init__(self, backend, form, bcs=(), nodal_group: NodalGroup | None = None, for_products: bool = False):
        self.backend, self.form, self.bcs = backend, form, bcs
        # only multiplied (a part B_c of the residual), never solved with: its stored zeros can go
        self.for_products = for_products
        self._assembled = None  # the matrix as assembled, on the form's whole sparsity pattern
        self._nodal_group = nodal_group  # evaluated with the forms needed at the same state
        expanded = expand_derivatives(form)  # before expansion a derivative still lists what it differentiates
        self.reads_fields = bool(expanded.coefficients())
        self._constants = expanded.constants()
        self.vector_only = structurally_diagonal(form) and not bcs
        self.matrix = None  # PETSc Mat (built from the diagonal when only that is assembled)
        self.diagonal = None  # PETSc Vec of the diagonal, when the matrix is diagonal
        self._diagonal_matrix = None  # whether an assembled matrix is diagonal (checked once)
        self._state = None
        self._ones = None
        self._nodal = None  # the row sums evaluated at the nodes, when they can be (vector_only)

    def invalidate(self) -> None:
        """Assemble at the next refresh, whatever the constants say."""
        self._state = None

    def refresh(self) -> bool:
        """Assemble again if needed; whether anything changed."""
        state = _constants_state(self._constants)
        if not self.reads_fields and state == self._state:
            return False
        self._state = state
        if self.vector_only:
            if self._nodal is None:
                self._nodal = nodal_form(self.backend, self._row_sums(), self._nodal_group) or False
            if self._nodal:
                self.diagonal = self._nodal.assemble(b=self.diagonal)
            else:
                self.diagonal = self.backend.assemble_vector(self._row_sums(), b=self.diagonal)
            return True
        self._assembled = self.backend.assemble_matrix(self.form, self.bcs, A=self._assembled)
        self.matrix = self._assembled
        # A form that reads fields may be diagonal at one state only: a third party's chemotaxis up a cue g,
        # -chi m grad g . grad v, has no off-diagonal entries while g is uniform (its first step).  Taken as
        # diagonal for good, the tangent lost the term once g varied: the cell mass drifted by 1.3e-6 in 6
        # steps and a restart changed the answer.  Asked again while it is diagonal (a cheap scan then).
        if self._diagonal_matrix is None or (self._diagonal_matrix and self.reads_fields):
            self._diagonal_matrix = self._is_diagonal(self.matrix)
        if self._diagonal_matrix:
            self.diagonal = self.matrix.getDiagonal(self.diagonal)
        else:
            self.diagonal = None
            if self.for_products:
                self.matrix = _without_stored_zeros(self._assembled)
        return True

    def as_matrix(self):
        """The matrix (for a Krylov solve); built from the diagonal when only that is assembled."""
        if self.vector_only:
            if self.matrix is None:
                sizes = self.diagonal.getSizes()
                self.matrix = PETSc.Mat().createAIJ((sizes, sizes), nnz=1, comm=self.diagonal.getComm())
            self.matrix.setDiagonal(self.diagonal)
            self.matrix.assemble()
        return self.matrix

    def _row_sums(self):
        """The form applied to a field equal to 1: its row sums, i.e. the diagonal of a diagonal matrix."""
        if self._ones is None:
            space = self.form.arguments()[1].ufl_function_space()
            unit = self.backend.function(space, "unit")
            self.backend.interpolate(unit, 1.0)
            self._ones = ufl.action(self.form, unit)
        return self._ones

    def _is_diagonal(self, matrix) -> bool:
        if matrix.getOwnershipRange() != matrix.getOwnershipRangeColumn():
            return False
        indptr, indices, values = matrix.getValuesCSR()
        start = matrix.getOwnershipRange()[0]
        row = np.repeat(np.arange(len(indptr) - 1) + start, np.diff(indptr))
        return self.backend.comm.allreduce(int(np.count_nonzero(values[indices != row]))) == 0

    def apply_add(self, x, y, scratch) -> None:
        """y += B x."""
        if self.diagonal is not None:
            scratch.pointwiseMult(self.diagonal, x)
            y.axpy(1.0, scratch)
        else:
            self.matrix.multAdd(x, y, y)


class AffineResidual:
    """F(x) = sum_c B_c c + R for a linear subproblem (see the module docstring).

    ``available`` is False when the split would not pay (nothing but x enters linearly
    with a constant matrix) or cannot be used (Dirichlet conditions on an unknown whose
    Jacobian reads fields): the solver then assembles the residual as a whole.
    """

    def __init__(self, backend, subproblem):
        self.backend, self.sub = backend, subproblem
        residual, unknown = subproblem.residual, subproblem.unknown
        self.parts: list[tuple[object, _Matrix]] = []
        constant_fields = []
        for coefficient in residual.coefficients():
            derivative = expand_derivatives(ufl.derivative(
                residual, coefficient, ufl.TrialFunction(coefficient.ufl_function_space())))
            if derivative.empty() or derivative.coefficients():
                continue
            constant_fields.append(coefficient)
            if coefficient is not unknown:
                self.parts.append((coefficient, _Matrix(backend, derivative, for_products=True)))
        self.constant_jacobian = unknown in constant_fields
        remainder = ufl.replace(residual, {c: ufl.zero(*c.ufl_shape) for c in constant_fields})
        self.remainder = remainder if remainder.integrals() else None
        # the remainder and the Jacobian's diagonal at the same state, their common subexpressions once
        self._nodal_group = NodalGroup(backend)
        # the remainder's integrals evaluated at the nodes (lumped reactions), and the ones assembled
        self._nodal_remainder, self._assembled_remainder = (
            nodal_part(backend, remainder, self._nodal_group) if self.remainder is not None else (None, None))
        self._nodal_vector = None
        self.available = (bool(self.parts) or self.constant_jacobian) and (self.constant_jacobian or not subproblem.bcs)
        self.jacobian = _Matrix(backend, subproblem.jacobian, subproblem.bcs, self._nodal_group)
        # the Jacobian without Dirichlet rows, for F(x) = J x + ... (only with conditions)
        self.full_jacobian = _Matrix(backend, subproblem.jacobian) if subproblem.bcs else self.jacobian
        self._scratch = self._shifted = self._lift = None
        #: (batch, index) when the assembled remainder is assembled with other subproblems' (batched.py)
        self.batch = None
        # the remainder evaluated without cell-by-cell assembly (closed_form); None: assembled
        self._closed_remainder = _UNDECIDED

    @property
    def assembled_remainder(self):
        """The part of the remainder assembled cell by cell (a linear form), or None."""
        return self._assembled_remainder

    def invalidate(self) -> None:
        """Assemble every matrix again at the next solve (dt changed, say)."""
        for _, part in self.parts:
            part.invalidate()
        self.jacobian.invalidate()
        self.full_jacobian.invalidate()

    def residual(self, x, b):
        """b = F(x) with the backend's Dirichlet convention (lifted, x - g on fixed rows); returns b."""
        backend, sub = self.backend, self.sub
        b = self._without_unknown(x, b)
        if self.constant_jacobian:
            self.full_jacobian.refresh()
            shifted = x
            if sub.bcs:  # F(x~) with x~ = x but for the prescribed values (the lifting of the Newton residual)
                if self._shifted is None:
                    self._shifted = x.duplicate()
                x.copy(self._shifted)
                backend.set_dirichlet(self._shifted, sub.bcs)
                shifted = self._shifted
            self.full_jacobian.apply_add(shifted, b, self._scratch)
            if sub.bcs:
                backend.set_dirichlet(b, sub.bcs, x0=x, scale=-1.0)
        return b

    def right_hand_side(self, x, b):
        """For a constant Jacobian: b with J x_new = b, the solution itself rather than a Newton increment.

        F(x) = J_full x + F(0), so b = -F(0) - J_full g on the free rows (the lifting of the
        prescribed values g, left out when they are all zero) and g on the fixed ones: with
        J's fixed rows and columns the identity, this is the step's exact solution.  It spares
        the product J x of :meth:`residual` and the update x - dx.
        """
        backend, sub = self.backend, self.sub
        if not self.constant_jacobian:
            raise ValueError(f"{sub.name}: the Jacobian reads fields, so the residual is not split as J x + F(0)")
        b = self._without_unknown(x, b)
        if sub.bcs:
            if self._lift is None:
                self._lift = x.duplicate()
            self._lift.zeroEntries()
            backend.set_dirichlet(self._lift, sub.bcs)  # g on the fixed rows, 0 elsewhere
            if self._lift.norm(PETSc.NormType.NORM_INFINITY) > 0:
                self.full_jacobian.refresh()
                self.full_jacobian.apply_add(self._lift, b, self._scratch)
        b.scale(-1.0)
        if sub.bcs:
            backend.set_dirichlet(b, sub.bcs)
        return b

    def _without_unknown(self, x, b):
        """b = F(x) - J x: the remainder and the parts that read other fields (``F(0)`` for a constant J)."""
        backend = self.backend
        self._nodal_group.expire()  # a new solve: the fields have moved since the last evaluation
        for _, part in self.parts:
            part.refresh()
        if self._assembled_remainder is not None:
            if self.batch is None:
                if self._closed_remainder is _UNDECIDED:  # decided at the first solve, on every rank alike
                    self._closed_remainder = closed_form(backend, self._assembled_remainder)
                if self._closed_remainder is not None:
                    b = self._closed_remainder.assemble(b)
                else:
                    b = backend.assemble_vector(self._assembled_remainder, b=b)
            else:
                batch, index = self.batch
                b = batch.vector(index, b if b is not None else x.duplicate())
            if self._nodal_remainder is not None:
                self._nodal_vector = self._nodal_remainder.assemble(b=self._nodal_vector)
                b.axpy(1.0, self._nodal_vector)
        elif self._nodal_remainder is not None:
            b = self._nodal_remainder.assemble(b=b)
        elif b is None:
            b = x.duplicate()
            b.zeroEntries()
        else:
            b.zeroEntries()
        if self._scratch is None:
            self._scratch = x.duplicate()
        for coefficient, part in self.parts:
            part.apply_add(backend.petsc_vector(coefficient), b, self._scratch)
        return b

