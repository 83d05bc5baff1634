"""Evaluate UFL integrands with numpy at quadrature points (for the scikit-fem backend).

The scikit-fem backend assembles the very UFL forms that the FEniCSx backend
hands to FFCx.  A form is first preprocessed the way FFCx 0.5 does it, with
``ufl.algorithms.compute_form_data`` (algebra lowering, ``apply_derivatives`` so
that ``ufl.derivative`` Newton tangents work, removal of complex nodes, grouping
of integrals and estimation of their polynomial degree), but without function
pullbacks or geometry lowering: integrands stay in physical space and are
evaluated by a recursive interpreter over UFL node types
(:func:`evaluate_integrand`; :func:`integrate_integrand` also sums over the
quadrature points, term by term and factor by factor).

Array layout
------------
Every node evaluates to one numpy array with the axes ::

    (test, trial, *shape, *free_indices, entity, point)

``test`` and ``trial`` run over the local basis functions of the form's
arguments (size 1 when the node does not depend on that argument), ``shape`` is
the node's ``ufl_shape``, the free-index axes follow the node's
``ufl_free_indices`` order, ``entity`` runs over the cells (or facets) of a chunk
and ``point`` over the quadrature points.  The argument, entity and point axes
may have size 1 and broadcast; shape and free-index axes always have full size.
One evaluation of an integrand thus yields all element tensors of a chunk.

Quadrature
----------
To agree with dolfinx entry by entry even for integrands that are not
polynomials, an integral uses the degree FFCx would use (the
``quadrature_degree`` metadata, else UFL's estimate from the same
``compute_form_data`` pass) and the same points and weights
(``basix.make_quadrature``, FFCx's default scheme, when basix is importable;
scikit-fem's own rules otherwise, except a collapsed Gauss rule for
tetrahedra above degree 4, where scikit-fem 12's rules are inexact).  ``quadrature_rule="vertex"`` puts the points
at the vertices with equal weights: for P1 fields this is mass lumping.

What the evaluator needs from a backend is stated in :class:`QuadratureContext`.
"""

from __future__ import annotations

import math
import string
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import ufl
from ufl import classes as uc
from ufl.algorithms import compute_form_data

from primordia.core.errors import PrimordiaError

#: UFL integral types the evaluator handles, with the measure a user writes.
SUPPORTED_INTEGRALS = {"cell": "dx", "exterior_facet": "ds"}
MEASURE_NAMES = {"cell": "dx", "exterior_facet": "ds", "interior_facet": "dS", "vertex": "dP"}

#: Reference cells of basix / FFCx (and scikit-fem: the same vertices).
REFERENCE_VERTICES = {
    "interval": np.array([[0.0], [1.0]]),
    "triangle": np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]),
    "tetrahedron": np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
}
REFERENCE_VOLUMES = {"interval": 1.0, "triangle": 0.5, "tetrahedron": 1.0 / 6.0}


class UnsupportedUFL(PrimordiaError):
    """A UFL construct the scikit-fem backend cannot evaluate."""


def unsupported(what: str) -> UnsupportedUFL:
    return UnsupportedUFL(f"ufl {what!r} is not supported by the scikit-fem backend")


# ---------------------------------------------------------------------------------------
# Preprocessing and quadrature
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class IntegralPlan:
    """One integrand of a preprocessed form and the quadrature it is integrated with.

    ``subdomain_ids`` is ``None`` for the whole domain (all exterior facets for
    ``ds``), else the boundary tags (``MeshData.boundary_ids``) it covers.
    """

    integral_type: str
    subdomain_ids: tuple[int, ...] | None
    integrand: ufl.core.expr.Expr
    degree: int
    rule: str


def preprocess_form(form: ufl.Form) -> list[IntegralPlan]:
    """Lower ``form`` like FFCx 0.5 and return its integrals with their quadrature.

    The flags follow ``ffcx.analysis._analyze_form`` except that pullbacks,
    integral scaling and geometry lowering are left out: degrees are estimated
    before those steps anyway, so they come out identical.
    """
    for integral in form.integrals():
        itype = integral.integral_type()
        if itype not in SUPPORTED_INTEGRALS:
            raise unsupported(f"{MEASURE_NAMES.get(itype, itype)} ({itype} integral)")
        if itype == "cell" and integral.subdomain_id() != "everywhere":
            raise unsupported("dx with a subdomain id (cell tags)")
    if form.empty():
        return []
    form_data = compute_form_data(
        form,
        do_apply_function_pullbacks=False,
        do_apply_integral_scaling=False,
        do_apply_geometry_lowering=False,
        do_apply_default_restrictions=True,
        do_apply_restrictions=True,
        do_estimate_degrees=True,
        do_append_everywhere_integrals=False,  # as FFCx: ds does not include ds(i)
        complex_mode=False,
    )
    plans = []
    for integral_data in form_data.integral_data:
        subdomain = integral_data.subdomain_id
        if subdomain == "otherwise":
            ids = None
        else:
            ids = tuple(int(i) for i in (subdomain if isinstance(subdomain, tuple) else (subdomain,)))
        for integral in integral_data.integrals:
            metadata = integral.metadata()
            degree = metadata.get("quadrature_degree", -1)
            if degree == -1:
                degree = int(np.max(metadata["estimated_polynomial_degree"]))
            plans.append(IntegralPlan(integral_data.integral_type, ids, integral.integrand(), int(degree),
                                      metadata.get("quadrature_rule", "default")))
    return plans


def reference_quadrature(cellname: str, degree: int, rule: str = "default") -> tuple[np.ndarray, np.ndarray]:
    """Points (n_points, tdim) and weights on a reference cell, as FFCx chooses them."""
    if rule == "vertex":
        vertices = REFERENCE_VERTICES[cellname]
        return vertices.copy(), np.full(len(vertices), REFERENCE_VOLUMES[cellname] / len(vertices))
    try:
        import basix
    except ImportError:
        basix = None
    if basix is not None:
        try:
            scheme = basix.quadrature.string_to_type(rule)
        except Exception:
            raise unsupported(f"quadrature_rule={rule}") from None
        points, weights = basix.make_quadrature(scheme, basix.cell.string_to_type(cellname), degree)
        return np.asarray(points, dtype=float), np.asarray(weights, dtype=float)
    if rule != "default":
        raise unsupported(f"quadrature_rule={rule} (without basix)")
    if cellname == "tetrahedron" and degree > 4:
        return _collapsed_tetrahedron_rule(degree)  # scikit-fem 12's tetrahedron rules above 4 are inexact
    from skfem.quadrature import get_quadrature
    from skfem.refdom import RefLine, RefTet, RefTri

    refdom = {"interval": RefLine, "triangle": RefTri, "tetrahedron": RefTet}[cellname]
    points, weights = get_quadrature(refdom, max(int(degree), 1))
    return np.ascontiguousarray(points.T), np.asarray(weights, dtype=float)


def _collapsed_tetrahedron_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre points on the cube, collapsed onto the tetrahedron (Duffy); exact to ``degree``."""
    s, w = np.polynomial.legendre.leggauss(int(np.ceil((degree + 3) / 2)))
    s, w = (s + 1) / 2, w / 2
    a, b, c = (g.ravel() for g in np.meshgrid(s, s, s, indexing="ij"))
    wa, wb, wc = (g.ravel() for g in np.meshgrid(w, w, w, indexing="ij"))
    points = np.column_stack([a * (1 - b) * (1 - c), b * (1 - c), c])
    return points, wa * wb * wc * (1 - b) * (1 - c) ** 2


# ---------------------------------------------------------------------------------------
# The evaluator
# ---------------------------------------------------------------------------------------


class QuadratureContext(Protocol):
    """What :func:`evaluate_integrand` asks of a backend, on one chunk of entities.

    ``E`` is the number of entities (cells or facets) of the chunk and ``Q`` the
    number of quadrature points; either may be 1 in a returned array (broadcast).
    """

    gdim: int

    def argument(self, space, derivatives: int) -> np.ndarray:
        """Basis functions of ``space``: (n_local, *value_shape, *(gdim,) * derivatives, E, Q)."""

    def coefficient(self, function, derivatives: int) -> np.ndarray:
        """Values or derivatives of a field: (*value_shape, *(gdim,) * derivatives, E, Q)."""

    def constant(self, constant) -> np.ndarray:
        """The value of a ``ufl.Constant``, of shape ``constant.ufl_shape``."""

    def geometry(self, quantity: str) -> np.ndarray | None:
        """A geometric quantity by UFL class name (``"SpatialCoordinate"``: (gdim, E, Q),
        ``"FacetNormal"``, ``"CellVolume"``: (E, Q), ...), ``None`` when not provided."""


def evaluate_integrand(integrand: ufl.core.expr.Expr, context: QuadratureContext) -> np.ndarray:
    """Values of a scalar integrand: an array (test, trial, entity, point), broadcastable."""
    with np.errstate(all="ignore"):  # both branches of a conditional are evaluated
        return _Evaluator(context).value(integrand)


def integrate_integrand(integrand: ufl.core.expr.Expr, context: QuadratureContext,
                        weights: np.ndarray) -> np.ndarray:
    """Element tensors ``sum_q integrand * weights``: an array (entity, test, trial), broadcastable.

    ``weights`` (entity, point) are the quadrature weights times the Jacobian
    determinant.  Sums are integrated term by term and products factor by
    factor, so that e.g. ``exp(-m) * u * div(v)`` never builds the full
    (test, trial, entity, point) product before summing over the points.
    """
    with np.errstate(all="ignore"):
        return _Evaluator(context).integrate(integrand, weights)


_ARGS, _POINTS = "AB", "YZ"

#: Below this many (test x trial x summed index x point) products per entity, one
#: broadcast einsum beats a matrix product per entity.
_CONTRACTION_MIN_SIZE = 2048
_INDEX_LETTERS = string.ascii_lowercase + "CDEFGHIJKLMNOPQRSTUVWX"


class _Evaluator:
    """Recursive evaluation of one integrand on one chunk, memoised per node."""

    def __init__(self, context: QuadratureContext):
        self.context = context
        self._memo: dict[int, tuple[object, np.ndarray]] = {}

    def value(self, o) -> np.ndarray:
        hit = self._memo.get(id(o))
        if hit is not None:
            return hit[1]
        result = _handler(type(o))(self, o)
        self._memo[id(o)] = (o, result)  # keep o alive: ids stay unique
        return result

    def integrate(self, o, weights: np.ndarray) -> np.ndarray:
        if isinstance(o, uc.Sum):
            return sum(self.integrate(term, weights) for term in o.ufl_operands)
        factors = []
        _collect_factors(o, factors)
        contractions = [f for f in factors if isinstance(f, uc.IndexSum) and id(f) not in self._memo]
        q_varying, q_constant = [], []
        for factor in factors:
            if len(contractions) == 1 and factor is contractions[0]:
                continue
            value = self.value(factor)
            if value.shape[0] == 1 and value.shape[1] == 1:
                weights = weights * value[0, 0]       # no argument: fold into the weights
            elif value.shape[-1] == 1:
                q_constant.append(value[..., 0])      # constant over the points: apply after the sum
            else:
                q_varying.append(value)
        if len(contractions) == 1:
            if not q_varying and not q_constant:
                result = self._contract(contractions[0], weights)
                if result is not None:
                    return result
            value = self.value(contractions[0])
            (q_constant if value.shape[-1] == 1 else q_varying).append(value[..., 0] if value.shape[-1] == 1
                                                                       else value)
        uniform = [v for v in q_varying if v.shape[2] == 1]  # same on every entity: multiply first, it is small
        if len(uniform) > 1:
            q_varying = [v for v in q_varying if v.shape[2] != 1] + [_product(uniform)]
        if q_varying:
            terms = ",".join("abeq" for _ in q_varying)
            result = np.einsum(f"{terms},eq->eab", *q_varying, weights)
        else:
            result = weights.sum(axis=-1)[:, None, None]
        for value in q_constant:
            result = result * np.moveaxis(value, -1, 0)
        return result

    def _contract(self, o, weights: np.ndarray) -> np.ndarray | None:
        """``sum_{indices, points} a * b * weights`` for ``o`` = IndexSum(s) of Product(a, b).

        With ``a`` depending on the test function only and ``b`` on the trial
        function only (or on none), this is one matrix product per entity, over
        the summed indices and the points at once: no (test, trial, ..., point)
        temporary.  Returns ``None`` when the pattern does not apply or is too
        small to gain.
        """
        node = o
        while isinstance(node, uc.IndexSum):
            node = node.ufl_operands[0]
        if o.ufl_free_indices or not isinstance(node, uc.Product):
            return None
        a, b = node.ufl_operands
        first, second = self._scalar_operands(node)
        if first.shape[1] > 1 or second.shape[0] > 1:
            first, second = second, first
        if first.shape[1] > 1 or second.shape[0] > 1:
            return None                                  # an operand depends on both arguments
        free = np.broadcast_shapes(first.shape[2:-2], second.shape[2:-2])
        n_test, n_trial = first.shape[0], second.shape[1]
        entities, points = weights.shape
        if n_test * n_trial * int(np.prod(free)) * points < _CONTRACTION_MIN_SIZE:
            return None
        test_part = np.broadcast_to(first[:, 0], (n_test,) + free + (entities, points))
        trial_part = np.broadcast_to(second[0], (n_trial,) + free + (entities, points)) * weights
        test_part = np.moveaxis(test_part, -2, 0).reshape(entities, n_test, -1)
        trial_part = np.moveaxis(trial_part, -2, 0).reshape(entities, n_trial, -1)
        return np.matmul(test_part, trial_part.transpose(0, 2, 1))

    # -- helpers -----------------------------------------------------------------------
    @staticmethod
    def _align(array: np.ndarray, free: tuple, target: tuple) -> np.ndarray:
        """Insert size-1 axes so a scalar's free-index axes line up with ``target`` (a superset)."""
        if free == target:
            return array
        sizes = dict(zip(free, array.shape[2: 2 + len(free)]))
        return array.reshape(array.shape[:2] + tuple(sizes.get(i, 1) for i in target) + array.shape[-2:])

    def _scalar_operands(self, o):
        """Operand values aligned to ``o``'s free indices (operators of scalars)."""
        return [self._align(self.value(op), op.ufl_free_indices, o.ufl_free_indices) for op in o.ufl_operands]

    # -- terminals ----------------------------------------------------------------------
    def argument(self, o, derivatives=0):
        number = o.number()
        if number > 1:
            raise unsupported(f"Argument number {number}")
        basis = self.context.argument(o.ufl_function_space(), derivatives)
        return basis[:, None] if number == 0 else basis[None, :]

    def coefficient(self, o, derivatives=0):
        return self.context.coefficient(o, derivatives)[None, None]

    def grad(self, o):
        derivatives, terminal = 0, o
        while isinstance(terminal, uc.Grad):
            derivatives, terminal = derivatives + 1, terminal.ufl_operands[0]
        if isinstance(terminal, uc.Argument):
            return self.argument(terminal, derivatives)
        if isinstance(terminal, uc.Coefficient):
            return self.coefficient(terminal, derivatives)
        raise unsupported(f"Grad of {type(terminal).__name__}")

    def constant(self, o):
        value = np.asarray(self.context.constant(o), dtype=float)
        return value.reshape((1, 1) + o.ufl_shape + (1, 1))

    def geometric_quantity(self, o):
        value = self.context.geometry(type(o).__name__)
        if value is None:
            raise unsupported(type(o).__name__)
        return value[None, None]

    def scalar_value(self, o):
        if isinstance(o, uc.ComplexValue):
            raise unsupported("ComplexValue")
        return np.full((1, 1, 1, 1), float(o.value()))

    def zero(self, o):
        return np.zeros((1, 1) + o.ufl_shape + tuple(o.ufl_index_dimensions) + (1, 1))

    def identity(self, o):
        d = o.ufl_shape[0]
        return np.eye(d).reshape(1, 1, d, d, 1, 1)

    def permutation_symbol(self, o):
        d = o.ufl_shape[0]
        eps = np.zeros((d,) * d)
        for perm in _permutations(d):
            eps[perm] = _parity(perm)
        return eps.reshape((1, 1) + eps.shape + (1, 1))

    # -- tensor algebra in index notation ----------------------------------------------------
    def indexed(self, o):
        expression, multiindex = o.ufl_operands
        array = self.value(expression)
        slicer = [slice(None)] * array.ndim
        kept = []
        for position, index in enumerate(multiindex):
            if isinstance(index, uc.FixedIndex):
                slicer[2 + position] = int(index)
            else:
                kept.append(index.count())
        array = array[tuple(slicer)]
        kept, free, out = _subscripts(kept, expression.ufl_free_indices, o.ufl_free_indices)
        inputs, output = _ARGS + kept + free + _POINTS, _ARGS + out + _POINTS
        return array if inputs == output else np.einsum(f"{inputs}->{output}", array)

    def component_tensor(self, o):
        expression, multiindex = o.ufl_operands
        array = self.value(expression)
        free, shape, out = _subscripts(expression.ufl_free_indices, [i.count() for i in multiindex],
                                       o.ufl_free_indices)
        return np.einsum(f"{_ARGS}{free}{_POINTS}->{_ARGS}{shape}{out}{_POINTS}", array)

    def index_sum(self, o):
        summand, multiindex = o.ufl_operands
        summed = multiindex[0].count()
        rank = len(summand.ufl_shape)
        if isinstance(summand, uc.Product) and id(summand) not in self._memo:
            # a[i] * b[i] summed over i: one contraction, no (..., i, ...) temporary
            a, b = summand.ufl_operands
            first, second, out = _subscripts(a.ufl_free_indices, b.ufl_free_indices, o.ufl_free_indices)
            return np.einsum(f"{_ARGS}{first}{_POINTS},{_ARGS}{second}{_POINTS}->{_ARGS}{out}{_POINTS}",
                             self.value(a), self.value(b))
        array = self.value(summand)
        axis = 2 + rank + summand.ufl_free_indices.index(summed)
        return array.sum(axis=axis)

    def list_tensor(self, o):
        parts = np.broadcast_arrays(*(self.value(op) for op in o.ufl_operands))
        return np.stack(parts, axis=2)

    # -- arithmetic ---------------------------------------------------------------------
    def sum(self, o):
        a, b = (self.value(op) for op in o.ufl_operands)
        return a + b

    def product(self, o):
        a, b = self._scalar_operands(o)
        return a * b

    def division(self, o):
        a, b = self._scalar_operands(o)
        return a / b

    def power(self, o):
        base, exponent = o.ufl_operands
        if isinstance(exponent, uc.ScalarValue) and not isinstance(exponent, uc.ComplexValue):
            return self._align(self.value(base), base.ufl_free_indices, o.ufl_free_indices) ** float(exponent.value())
        a, b = self._scalar_operands(o)
        return np.power(a, b)

    def abs(self, o):
        return np.abs(self.value(o.ufl_operands[0]))

    def math_function(self, o):
        return _MATH_FUNCTIONS[type(o)](self.value(o.ufl_operands[0]))

    def erf(self, o):
        try:
            from scipy.special import erf
        except ImportError:
            raise unsupported("Erf (needs scipy)") from None
        return erf(self.value(o.ufl_operands[0]))

    def atan2(self, o):
        a, b = self._scalar_operands(o)
        return np.arctan2(a, b)

    def min_value(self, o):
        a, b = self._scalar_operands(o)
        return np.minimum(a, b)

    def max_value(self, o):
        a, b = self._scalar_operands(o)
        return np.maximum(a, b)

    def real_part(self, o):  # Conj and Real are the identity for real scalars
        return self.value(o.ufl_operands[0])

    def imag_part(self, o):
        return np.zeros_like(self.value(o.ufl_operands[0]))

    def variable(self, o):
        return self.value(o.ufl_operands[0])

    # -- conditionals -------------------------------------------------------------------
    def condition(self, o):
        a, b = (self.value(op) for op in o.ufl_operands)
        return _CONDITIONS[type(o)](a, b)

    def not_condition(self, o):
        return np.logical_not(self.value(o.ufl_operands[0]))

    def conditional(self, o):
        condition, true_value, false_value = o.ufl_operands
        mask = self.value(condition)
        extra = len(o.ufl_shape) + len(o.ufl_free_indices)
        mask = mask.reshape(mask.shape[:2] + (1,) * extra + mask.shape[2:])
        return np.where(mask, self.value(true_value), self.value(false_value))


def _subscripts(*groups) -> list[str]:
    """einsum letters for groups of UFL index counts, one letter per distinct index."""
    letters: dict[int, str] = {}
    for group in groups:
        for count in group:
            if count not in letters:
                if len(letters) == len(_INDEX_LETTERS):
                    raise unsupported("operation on more than 48 free indices at once")
                letters[count] = _INDEX_LETTERS[len(letters)]
    return ["".join(letters[count] for count in group) for group in groups]


def _product(values):
    result = values[0]
    for value in values[1:]:
        result = result * value
    return result


def _collect_factors(o, factors: list) -> None:
    """The factors of a chain of scalar products without free indices."""
    if isinstance(o, uc.Product) and not o.ufl_free_indices:
        for operand in o.ufl_operands:
            _collect_factors(operand, factors)
    else:
        factors.append(o)


def _permutations(d):
    import itertools

    return itertools.permutations(range(d))


def _parity(perm) -> int:
    sign, perm = 1, list(perm)
    for i in range(len(perm)):
        while perm[i] != i:
            j = perm[i]
            perm[i], perm[j] = perm[j], perm[i]
            sign = -sign
    return sign


_MATH_FUNCTIONS = {
    uc.Sqrt: np.sqrt, uc.Exp: np.exp, uc.Ln: np.log, uc.Cos: np.cos, uc.Sin: np.sin, uc.Tan: np.tan,
    uc.Cosh: np.cosh, uc.Sinh: np.sinh, uc.Tanh: np.tanh, uc.Acos: np.arccos, uc.Asin: np.arcsin,
    uc.Atan: np.arctan,
}

_CONDITIONS = {
    uc.EQ: np.equal, uc.NE: np.not_equal, uc.LT: np.less, uc.GT: np.greater, uc.LE: np.less_equal,
    uc.GE: np.greater_equal, uc.AndCondition: np.logical_and, uc.OrCondition: np.logical_or,
}

_HANDLER_NAMES = {
    uc.Argument: "argument", uc.Coefficient: "coefficient", uc.Grad: "grad", uc.Constant: "constant",
    uc.GeometricQuantity: "geometric_quantity", uc.ScalarValue: "scalar_value", uc.Zero: "zero",
    uc.Identity: "identity", uc.PermutationSymbol: "permutation_symbol", uc.Indexed: "indexed",
    uc.ComponentTensor: "component_tensor", uc.IndexSum: "index_sum", uc.ListTensor: "list_tensor",
    uc.Sum: "sum", uc.Product: "product", uc.Division: "division", uc.Power: "power", uc.Abs: "abs",
    uc.Erf: "erf", uc.Atan2: "atan2", uc.MinValue: "min_value", uc.MaxValue: "max_value",
    uc.Conj: "real_part", uc.Real: "real_part", uc.Imag: "imag_part", uc.Variable: "variable",
    uc.NotCondition: "not_condition", uc.Conditional: "conditional",
    **{cls: "math_function" for cls in _MATH_FUNCTIONS},
    **{cls: "condition" for cls in _CONDITIONS},
}
_HANDLERS: dict[type, object] = {}


def _handler(node_type: type):
    """The evaluator method for a UFL node type (looked up along its MRO, cached)."""
    handler = _HANDLERS.get(node_type)
    if handler is None:
        for base in node_type.__mro__:
            name = _HANDLER_NAMES.get(base)
            if name is not None:
                handler = getattr(_Evaluator, name)
                break
        else:
            def handler(evaluator, o, name=node_type.__name__):
                raise unsupported(name)
        _HANDLERS[node_type] = handler
    return handler


def cell_quantities(vertices: np.ndarray) -> dict[str, np.ndarray]:
    """Size measures of simplices from their vertices (E, tdim + 1, gdim), each of shape (E,).

    ``Circumradius`` follows UFL's formulas (Heron-like for tetrahedra), which
    dolfinx evaluates through geometry lowering.
    """
    n = vertices.shape[1]
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    lengths = {p: np.linalg.norm(vertices[:, p[1]] - vertices[:, p[0]], axis=1) for p in pairs}
    stacked = np.stack(list(lengths.values()))
    edges = vertices[:, 1:] - vertices[:, :1]
    tdim = n - 1
    volume = np.abs(np.linalg.det(edges)) / math.factorial(tdim) if edges.shape[1] == edges.shape[2] else None
    if tdim == 2:
        circumradius = lengths[(0, 1)] * lengths[(1, 2)] * lengths[(0, 2)] / (4.0 * volume)
    else:
        # products of opposite edge lengths
        la = lengths[(0, 1)] * lengths[(2, 3)]
        lb = lengths[(0, 2)] * lengths[(1, 3)]
        lc = lengths[(0, 3)] * lengths[(1, 2)]
        circumradius = np.sqrt((la + lb + lc) * (-la + lb + lc) * (la - lb + lc) * (la + lb - lc)) / (24.0 * volume)
    return {
        "CellVolume": volume,
        "Circumradius": circumradius,
        "CellDiameter": stacked.max(axis=0),
        "MinCellEdgeLength": stacked.min(axis=0),
        "MaxCellEdgeLength": stacked.max(axis=0),
    }
