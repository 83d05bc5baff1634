r"""Loads read through the gradient of a P1 test function, assembled from the integrals of the cells.

Example 1b's active stress enters the momentum balance as sigma_act(m) : grad w (seed eq.
(2.5)), assembled at every step.  Lowered, such an integrand is a sum of terms

    G_t(fields) * grad(w)[a_t, b_t]        (w[a_t] a P1 test function, G_t free of w)

and on an affine simplex K the gradient of a hat function is constant, so

    int_K G_t d_b(phi_i) = d_b(phi_i)|_K * int_K G_t.

The integrals of G_t are taken with the rule the backend integrates the form with (FFCx's
degree estimate and scheme, which both backends use: :func:`~primordia.backends.ufl_numpy.
preprocess_form`), at the quadrature points of all cells at once: a P1 field there is its
vertex values times the barycentric coordinates, and the G_t are run there by the
straight-line program of the lumped reactions (:class:`~primordia.coupling.nodal_program.
NodalProgram`).  A sparse matrix made once spreads the cells' integrals onto the test DOFs
with the hat-function gradients.  What FFCx's kernels and the UFL interpreter spend on the
test axis (each cell's element vector and its scatter) is left out: example 1b's load at
171^2 took 4.4 ms a step on FEniCSx and 9.2 on scikit-fem.

The physics stays the modules' UFL.  :meth:`P1GradientLoad.recognise` takes a linear form's
cell integrals when every term has that shape and every field the G_t read is P1 scalar; the
form's other integrals (a traction on ds) are assembled by the backend as before (or, reading
only constants, combined from vectors assembled once: :mod:`primordia.coupling.constant_load`),
and a form that does not match is assembled whole.  Before its first use the result is checked against
the backend's assembly of the same form on smooth fields set for the check.
"""

from __future__ import annotations

import math

import numpy as np
import ufl
from scipy.sparse import csr_matrix
from ufl.algorithms.analysis import extract_arguments, extract_coefficients
from ufl.classes import Division, FixedIndex, Grad, Indexed, IntValue, Product, Sum

from primordia.backends.ufl_numpy import UnsupportedUFL, cell_quantities, preprocess_form, reference_quadrature
from primordia.coupling.closed_forms import agrees_with_assembly, flattened, hat_gradients, write_local
from primordia.coupling.constant_load import ConstantLoad
from primordia.coupling.nodal_program import NodalProgram, constant_value


class P1GradientLoad:
    """Assembles a linear form whose cell integrals are loads G_t grad(w)[a_t, b_t] (module docstring)."""

    def __init__(self, backend, form, rest, roots, fields, terms, rule, coordinates):
        self.backend, self.form = backend, form
        self._rest = rest                  # the form's other integrals into a vector (b -> b), or None
        self._fields = fields              # id(function) -> (function, its cell dofs (cells, nv))
        barycentric, self._weights = rule  # (nq, nv) at the reference points, (nq,)
        self._barycentric_t = np.ascontiguousarray(barycentric.T)
        cells, nv, gdim = coordinates.shape
        points = np.einsum("qj,cjd->dcq", barycentric, coordinates).reshape(gdim, -1)
        self._program = NodalProgram.compile(roots, points, self._at_points, constant_value)
        self._shape = (len(roots), cells, len(self._weights))
        # the spreading matrix's entries: row = the test DOF, column = (root, cell), value = d_b phi_i |det J_K|
        scale = cell_quantities(coordinates)["CellVolume"] * math.factorial(nv - 1)
        gradients = hat_gradients(coordinates)
        self._entries = (
            np.concatenate([out.ravel() for _, out, _ in terms]),
            np.concatenate([np.repeat(root * cells + np.arange(cells), nv) for root, _, _ in terms]),
            np.concatenate([(gradients[:, :, direction] * scale[:, None]).ravel() for _, _, direction in terms]))
        self._spread = self._extra = None

    @classmethod
    def recognise(cls, backend, form) -> "P1GradientLoad | None":
        """The per-cell evaluation of ``form`` (a linear form), or None where it does not apply."""
        if len(form.arguments()) != 1:
            return None
        test = form.arguments()[0]
        mesh = test.ufl_function_space().mesh
        cellname = form.integrals()[0].ufl_domain().ufl_cell().cellname() if form.integrals() else None
        cell, rest = [], []
        for integral in form.integrals():
            whole = integral.integral_type() == "cell" and integral.subdomain_id() in ("everywhere", "otherwise")
            (cell if whole else rest).append(integral)
        coordinates = backend.p1_cell_coordinates(mesh)
        if (not cell or cellname not in ("triangle", "tetrahedron") or coordinates is None
                or coordinates.shape[1] != coordinates.shape[2] + 1):  # simplices of the space's own dimension
            return None
        try:
            plans = preprocess_form(ufl.Form(cell))
        except UnsupportedUFL:
            return None
        if len({(plan.degree, plan.rule) for plan in plans}) != 1:
            return None
        parsed = [_split(term, test) for plan in plans for term in flattened(plan.integrand, Sum)]
        if not parsed or any(p is None for p in parsed):
            return None
        roots = list(dict.fromkeys(g for _, _, g in parsed))  # each G once, in order
        fields = {}
        for function in (c for root in roots for c in extract_coefficients(root)):
            dofs = backend.p1_cell_dofs(function.ufl_function_space()) if not function.ufl_shape else None
            if dofs is None:
                return None
            fields[id(function)] = (function, dofs)
        terms = []
        for component, direction, g in parsed:
            out = backend.p1_cell_dofs(test.ufl_function_space(), component)
            if out is None:
                return None
            terms.append((roots.index(g), out, direction))
        points, weights = reference_quadrature(cellname, plans[0].degree, plans[0].rule)
        barycentric = np.column_stack([1.0 - points.sum(axis=1), points])
        rest = _assembler(backend, ufl.Form(rest)) if rest else None
        evaluator = cls(backend, form, rest, roots, fields, terms, (barycentric, weights), coordinates)
        if evaluator._program is None:
            return None
        return evaluator if evaluator._agrees_with_assembly(coordinates) else None

    # -- evaluating --------------------------------------------------------------------------------
    def _at_points(self, function) -> np.ndarray:
        """A P1 field at the quadrature points of every cell, (cells * nq,)."""
        _, dofs = self._fields[id(function)]
        return (self.backend.local_array(function)[dofs] @ self._barycentric_t).ravel()

    def integrals(self) -> np.ndarray:
        """Each root G summed over each cell's quadrature points with the reference weights, (roots * cells,):
        int_K G without the factor |det J_K|, which the spreading matrix holds."""
        return (self._program.run().reshape(self._shape) @ self._weights).ravel()

    def assemble(self, b=None):
        """The form's vector (a backend vector of the test space; ``b`` is reused): owned and ghost rows summed."""
        backend = self.backend
        if b is None:
            b = backend.assemble_vector(self.form)  # the layout only: its values are overwritten
        if self._rest is None:
            return write_local(b, self._add)
        b = self._rest(b)
        if self._extra is None:
            self._extra = b.duplicate()
        b.axpy(1.0, write_local(self._extra, self._add))
        return b

    def _add(self, values: np.ndarray) -> None:
        if self._spread is None:  # made at the first use, when the vector's local size is known
            rows, columns, entries = self._entries
            shape = (values.size, self._shape[0] * self._shape[1])
            self._spread = csr_matrix((entries, (rows, columns)), shape=shape)
            self._entries = None
        values[:] = self._spread @ self.integrals()

    def _agrees_with_assembly(self, coordinates: np.ndarray) -> bool:
        """The check against assembly, every field read a smooth positive function of its nodes, each its own."""
        x, y = coordinates[..., 0], coordinates[..., -1]
        settings = [(function, dofs, 1.0 + 0.25 * np.sin((1.0 + 0.3 * number) * x + 0.3) * np.cos(0.7 * y))
                    for number, (function, dofs) in enumerate(self._fields.values())]
        return agrees_with_assembly(self, settings, "the per-cell gradient load")


def _assembler(backend, form):
    """``form`` into a vector b -> b: from vectors assembled once when it reads only constants (a traction),
    else by the backend."""
    load = ConstantLoad.recognise(backend, form)
    return load.assemble if load is not None else lambda b: backend.assemble_vector(form, b=b)


def _split(term, test):
    """(test component or None, direction b, G) of a term G * grad(w)[a, b] (a product or a quotient with the
    test gradient in a numerator), or None."""
    found = _test_gradient(term, test)
    if found is not None:
        return (*found, IntValue(1))
    if not isinstance(term, (Product, Division)):
        return None
    left, right = term.ufl_operands
    tested = bool(extract_arguments(left)), bool(extract_arguments(right))
    if isinstance(term, Product) and tested == (False, True):
        left, right = right, left
    elif tested != (True, False):
        return None
    inner = _split(left, test)
    if inner is None:
        return None
    component, direction, g = inner
    return component, direction, (g * right if isinstance(term, Product) else g / right)


def _test_gradient(node, test):
    """(a, b) of grad(w)[a, b] of a vector test function, (None, b) of grad(w)[b] of a scalar one, else None."""
    if not (isinstance(node, Indexed) and isinstance(node.ufl_operands[0], Grad)
            and node.ufl_operands[0].ufl_operands[0] == test):
        return None
    indices = node.ufl_operands[1]
    if not all(isinstance(i, FixedIndex) for i in indices):
        return None
    indices = [int(i) for i in indices]
    if len(test.ufl_shape) == 1 and len(indices) == 2:
        return indices[0], indices[1]
    if not test.ufl_shape and len(indices) == 1:
        return None, indices[0]
    return None
