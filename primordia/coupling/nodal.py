"""A lumped linear form evaluated at the nodes instead of assembled cell by cell.

For a P1 test function v and vertex quadrature (``backend.lumped_dx``: weight |K|/(d+1) at
each vertex of a cell K), the linear form

    L(v) = sum_K int_K g v dX    (vertex quadrature)

has the entries L_i = sum_{K ni x_i} |K|/(d+1) g|_K(x_i).  When the integrand g has one value
at each vertex, whichever cell it is read from (it reads P1 fields, constants and the
coordinates, and no derivative of them; a conditional of those is fine), g|_K(x_i) = g(x_i)
in every cell, so

    L_i = (M_L)_ii g(x_i),     M_L the lumped mass matrix (assembled once).

That is what the reactions of the implicit-explicit species are (seed (2.3b)-(2.3d): the
explicit production, the lumped loss rate on the diagonal of a Jacobian), and it turns a
cell-by-cell assembly, with its packing of coefficients, into a few array operations on
the owned DOFs: no ghost exchange, the same on every backend.  The integrand is still the
physics' UFL, evaluated by the backend-neutral interpreter of the scikit-fem backend
(:mod:`primordia.backends.ufl_numpy`) with one "entity" per DOF and one point.

:func:`nodal_form` returns ``None`` for any form it cannot evaluate this way (an integrand
with a gradient, a P2 or mixed field, a geometric quantity other than the coordinates, a
boundary integral, a measure other than vertex quadrature): the caller then assembles.
:func:`nodal_part` splits a form into the integrals that can be evaluated this way and the
rest.  Forms needed at the same state (a solve's remainder and its Jacobian's diagonal)
share a :class:`NodalGroup`: one evaluation for all, equal subexpressions once.
"""

from __future__ import annotations

import numpy as np
import ufl
from ufl import classes as uc
from ufl.algorithms.apply_algebra_lowering import apply_algebra_lowering
from ufl.algorithms.apply_derivatives import apply_derivatives
from ufl.corealg.traversal import unique_pre_traversal

from primordia.backends.ufl_numpy import UnsupportedUFL, evaluate_integrand, post_order
from primordia.core.backend import is_p1_scalar
from primordia.coupling.nodal_program import NodalProgram, constant_value

#: Node types an integrand single-valued at the vertices may not contain (after lowering).
_NOT_NODAL = (uc.Derivative, uc.GeometricQuantity, uc.Argument, uc.Restricted, uc.ExprList, uc.ExprMapping)


def _is_p1_scalar(space) -> bool:
    return is_p1_scalar(space.ufl_element())


def _vertex_integrals(form) -> bool:
    return bool(form.integrals()) and all(
        integral.integral_type() == "cell" and integral.subdomain_id() == "everywhere"
        and integral.subdomain_data() is None
        and integral.metadata().get("quadrature_rule") == "vertex" for integral in form.integrals())


def nodal_form(backend, form, group: NodalGroup | None = None) -> NodalForm | None:
    """A :class:`NodalForm` of ``form``, or ``None`` when it is not a lumped P1 form of nodal values.

    ``group``: forms needed together at the same field values (:class:`NodalGroup`); a form on
    another space than the group's is evaluated on its own.
    """
    split = _split(backend, form)
    if split is None or split[1] or not split[0]:
        return None
    return _build(backend, form, split[0], group)


def nodal_part(backend, form, group: NodalGroup | None = None) -> tuple[NodalForm | None, object]:
    """``form`` split into its integrals evaluated at the nodes (a :class:`NodalForm`) and the
    rest (a UFL form to assemble); either may be ``None``.

    A species' explicit terms mix both: its lumped reactions are nodal, the advection by
    the solid velocity (u_t . grad c, Gauss quadrature) is not.
    """
    split = _split(backend, form)
    if split is None:
        return None, form
    terms, rest = split
    return (_build(backend, form, terms, group) if terms else None), (ufl.Form(rest) if rest else None)


def _split(backend, form):
    """(the nodal integrands of ``form`` by measure, its other integrals), or None when ``form`` is not
    a linear form on a P1 space whose DOFs this backend can show are its vertices."""
    arguments = form.arguments()
    space = arguments[0].ufl_function_space() if len(arguments) == 1 else None
    # a backend that cannot tell whether DOFs are vertices (Backend.shares_dofs) assembles
    if space is None or not _is_p1_scalar(space) or not backend.shares_dofs(space, space):
        return None
    terms: dict[tuple, tuple[object, object]] = {}  # by measure: (an integral of it, the sum of its values)
    rest = []
    for integral in form.integrals():
        value = _nodal_value(integral, arguments[0], backend, space)
        if value is None:
            rest.append(integral)
            continue
        key = tuple(sorted(integral.metadata().items()))
        first, total = terms.get(key, (integral, None))
        terms[key] = (first, value if total is None else total + value)
    return terms, rest


def _build(backend, form, terms, group) -> NodalForm:
    test = form.arguments()[0]
    space = test.ufl_function_space()
    if group is None or not group.accepts(space):
        group = NodalGroup(backend, space)
    return NodalForm(backend, space, group, [(integral.reconstruct(integrand=test), value)
                                             for integral, value in terms.values()])


def _nodal_value(integral, test, backend, space):
    """The integrand g of ``integral`` = int g v (vertex quadrature), if it is single-valued at the vertices; else None."""
    if not _vertex_integrals(ufl.Form([integral])):
        return None
    integrand = apply_derivatives(apply_algebra_lowering(integral.integrand()))
    if not _linear_in(integrand, test):
        return None
    value = ufl.replace(integrand, {test: ufl.as_ufl(1.0)})
    return value if _nodal(value, backend, space) else None


def _linear_in(integrand, test) -> bool:
    """Whether ``test`` enters ``integrand`` only by value (never differentiated, restricted, ...)."""
    for node in unique_pre_traversal(integrand):
        if isinstance(node, uc.Derivative) and test in _terminals(node):
            return False
    return True


def _terminals(expression):
    return {node for node in unique_pre_traversal(expression) if not node.ufl_operands}


def _nodal(value, backend, space) -> bool:
    """Whether ``value`` is single-valued at the vertices and readable at the DOFs of ``space``."""
    spatial = (uc.SpatialCoordinate,)
    for node in unique_pre_traversal(value):
        if isinstance(node, _NOT_NODAL) and not isinstance(node, spatial):
            return False
        if isinstance(node, uc.Coefficient) and not isinstance(node, uc.Constant):
            if not _is_p1_scalar(node.ufl_function_space()):
                return False
            if not backend.shares_dofs(node.ufl_function_space(), space):
                return False
    return True


class _NodeContext:
    """The interpreter's quadrature context with one entity per owned DOF and one point."""

    def __init__(self, backend, space):
        self.backend = backend
        self.coordinates = backend.owned_dof_coordinates(space)  # (gdim, n_owned)
        self.gdim = self.coordinates.shape[0]
        self.size = self.coordinates.shape[1]

    def coefficient(self, function, derivatives: int) -> np.ndarray:
        if derivatives:
            raise UnsupportedUFL("a derivative at the nodes")
        return self.backend.petsc_vector(function).getArray(readonly=True)[:, None]

    def constant(self, constant) -> np.ndarray:
        return constant_value(constant)

    def field(self, function) -> np.ndarray:
        """A P1 field's values at the owned DOFs (a view, read-only)."""
        return self.backend.petsc_vector(function).getArray(readonly=True)

    def geometry(self, quantity: str) -> np.ndarray | None:
        return self.coordinates[:, :, None] if quantity == "SpatialCoordinate" else None


def _shared_subexpressions(expression, canonical: dict):
    """``expression`` with structurally equal subexpressions made one node, so the interpreter
    evaluates each once (it keeps a value by node identity).  ``canonical`` maps an expression to
    its representative and is shared by every expression evaluated together.

    Reactions repeat themselves: the Hill function m^2/(1 + m^2) of (2.1c) enters the e
    production, its loss and the Jacobian's diagonal, each written out by the kinetics.
    """
    mapped: dict[int, object] = {}  # by the id of a node of ``expression``: its representative
    for node in post_order(expression, mapped):
        operands = tuple(mapped[id(op)] for op in node.ufl_operands)
        rebuilt = node
        if any(new is not old for new, old in zip(operands, node.ufl_operands)):
            rebuilt = node._ufl_expr_reconstruct_(*operands)
        mapped[id(node)] = canonical.setdefault(rebuilt, rebuilt)
    return mapped[id(expression)]


class NodalGroup:
    """Nodal forms on one space needed at the same field values, evaluated in one pass.

    A linear solve needs its lumped remainder and its Jacobian's diagonal at the same
    state, and the two share most of their subexpressions (the diagonal is the remainder's
    derivative).  The group evaluates every member's integrands at once, common
    subexpressions once, when a member asks; later members take that evaluation.  An
    evaluation serves each member once: a member asking again, or :meth:`expire` (the start
    of a solve: the fields may have changed), triggers a new one.
    """

    def __init__(self, backend, space=None):
        self.backend, self.space = backend, space
        self._canonical: dict = {}  # representatives of the members' subexpressions
        self._integrands: list = []  # every member's, in order
        self._expression = None  # the same, as one vector
        self._context = None
        self._program = None  # the members' integrands compiled (NodalProgram); False: the interpreter's
        self._values = None  # (terms, owned DOFs) of the last evaluation
        self._served: set[int] = set()  # the members it served, by their first term

    def accepts(self, space) -> bool:
        """Whether a form on ``space`` can join (the first fixes the group's space)."""
        return self.space is None or self.backend.shares_dofs(space, self.space)

    def join(self, form: NodalForm, values: list) -> int:
        """Add ``form``'s integrands; returns the index of its first term."""
        if self.space is None:
            self.space = form.space
        first = len(self._integrands)
        self._integrands += [_shared_subexpressions(value, self._canonical) for value in values]
        self._expression = ufl.as_vector(self._integrands) if len(self._integrands) > 1 else self._integrands[0]
        self._values = None
        self._program = None
        return first

    def expire(self) -> None:
        """The fields may have changed: the next request evaluates again."""
        self._values = None

    def values(self, first: int, count: int) -> np.ndarray:
        """The values at the owned DOFs of a member's integrands (its ``first`` term and ``count`` terms), (count, n_owned)."""
        if self._values is None or first in self._served:
            if self._context is None:
                self._context = _NodeContext(self.backend, self.space)
            if self._program is None:
                context = self._context
                self._program = NodalProgram.compile(self._integrands, context.coordinates, context.field,
                                                     context.constant) or False
            if self._program:
                self._values = self._program.run()
            else:
                evaluated = evaluate_integrand(self._expression, self._context)  # a NaN shows, unwarned
                self._values = np.broadcast_to(np.reshape(evaluated, (len(self._integrands), -1)),
                                               (len(self._integrands), self._context.size))
            self._served = set()
        self._served.add(first)
        return self._values[first:first + count]


class NodalForm:
    """L_i = (M_L)_ii g(x_i) for a lumped linear form (module docstring); ``assemble`` replaces
    ``backend.assemble_vector(form)`` and gives the same vector to round-off.

    ``terms`` pairs the integral of v over each measure the form uses (its row sums, the
    diagonal of M_L, are assembled once) with the integrand g of that measure; the
    integrands are evaluated by ``group`` (:class:`NodalGroup`).
    """

    def __init__(self, backend, space, group: NodalGroup, terms):
        self.backend, self.space = backend, space
        masses = [backend.assemble_vector(ufl.Form([mass])) for mass, _ in terms]
        self._template = masses[0]
        self._masses = [mass.getArray(readonly=True).copy() for mass in masses]
        self._group = group
        self._first = group.join(self, [value for _, value in terms])
        # scratch of assemble for a form over several measures (one term at a time)
        self._term = np.empty_like(self._masses[0]) if len(self._masses) > 1 else None

    def assemble(self, b=None):
        """The assembled vector (PETSc Vec of the owned DOFs; ``b`` is filled when given)."""
        values = self._group.values(self._first, len(self._masses))
        if b is None:
            b = self._template.duplicate()
        total = b.getArray()  # written in place: no temporaries, no copy
        np.multiply(self._masses[0], values[0], out=total)
        for lumped_mass, value in zip(self._masses[1:], values[1:]):
            total += np.multiply(lumped_mass, value, out=self._term)
        return b
