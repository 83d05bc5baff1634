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
"""

from __future__ import annotations

import numpy as np
import ufl
from ufl import classes as uc
from ufl.algorithms.apply_algebra_lowering import apply_algebra_lowering
from ufl.algorithms.apply_derivatives import apply_derivatives
from ufl.corealg.traversal import unique_pre_traversal

from primordia.backends.ufl_numpy import UnsupportedUFL, evaluate_integrand

#: Node types an integrand single-valued at the vertices may not contain (after lowering).
_NOT_NODAL = (uc.Derivative, uc.GeometricQuantity, uc.Argument, uc.Restricted, uc.ExprList, uc.ExprMapping)


def _is_p1_scalar(space) -> bool:
    element = space.ufl_element()
    return (element.family() in ("Lagrange", "P", "Q", "CG") and element.degree() == 1
            and element.value_shape() == () and not element.sub_elements())


def _vertex_integrals(form) -> bool:
    return bool(form.integrals()) and all(
        integral.integral_type() == "cell" and integral.subdomain_id() == "everywhere"
        and integral.subdomain_data() is None
        and integral.metadata().get("quadrature_rule") == "vertex" for integral in form.integrals())


def nodal_form(backend, form) -> NodalForm | None:
    """A :class:`NodalForm` of ``form``, or ``None`` when it is not a lumped P1 form of nodal values."""
    arguments = form.arguments()
    if len(arguments) != 1 or not _is_p1_scalar(arguments[0].ufl_function_space()):
        return None
    if not _vertex_integrals(form):
        return None
    test = arguments[0]
    space = test.ufl_function_space()
    if not backend.shares_dofs(space, space):  # a backend that cannot tell (Backend.shares_dofs)
        return None
    terms: dict[tuple, tuple[object, object]] = {}  # by measure: (an integral of it, the sum of its values)
    for integral in form.integrals():
        integrand = apply_derivatives(apply_algebra_lowering(integral.integrand()))
        if not _linear_in(integrand, test):
            return None
        value = ufl.replace(integrand, {test: ufl.as_ufl(1.0)})
        if not _nodal(value, backend, space):
            return None
        key = tuple(sorted(integral.metadata().items()))
        first, total = terms.get(key, (integral, None))
        terms[key] = (first, value if total is None else total + value)
    return NodalForm(backend, space, [(integral.reconstruct(integrand=test), value)
                                      for integral, value in terms.values()])


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
        return np.asarray(constant.value, dtype=float)

    def geometry(self, quantity: str) -> np.ndarray | None:
        return self.coordinates[:, :, None] if quantity == "SpatialCoordinate" else None


class NodalForm:
    """L_i = (M_L)_ii g(x_i) for a lumped linear form (module docstring); ``assemble`` replaces
    ``backend.assemble_vector(form)`` and gives the same vector to round-off.

    ``terms`` pairs the integral of v over each measure the form uses (its row sums, the
    diagonal of M_L, are assembled once) with the integrand g of that measure.
    """

    def __init__(self, backend, space, terms):
        self.backend = backend
        masses = [backend.assemble_vector(ufl.Form([mass])) for mass, _ in terms]
        self._template = masses[0]
        self._terms = [(mass.getArray(readonly=True).copy(), value) for mass, (_, value) in zip(masses, terms)]
        self._context = _NodeContext(backend, space)

    def assemble(self, b=None):
        """The assembled vector (PETSc Vec of the owned DOFs; ``b`` is filled when given)."""
        with np.errstate(all="ignore"):  # as the interpreter: a NaN shows in the result, not as a warning
            total = None
            for lumped_mass, value in self._terms:
                term = lumped_mass * np.reshape(evaluate_integrand(value, self._context), -1)
                total = term if total is None else total + term
        if b is None:
            b = self._template.duplicate()
        b.setArray(np.broadcast_to(total, lumped_mass.shape))
        return b
