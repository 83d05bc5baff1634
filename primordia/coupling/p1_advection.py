r"""The advection of P1 fields by a P1 velocity, assembled from its closed form.

Example 1b's species are advected by the solid velocity, u_t . grad c^n (seed (2.3a),
(2.3c), (2.3d)), an explicit term assembled at every step.  With r, c and the test
function w_i all P1 on an affine simplex K of dimension d, grad c is constant on K and

    int_K (r . grad c) w_i = grad c_K . sum_j r_j int_K w_j w_i
                           = |K| / ((d + 1)(d + 2)) grad c_K . (sum_j r_j + r_i),

which quadrature of degree 2 (what the form's degree estimate gives) integrates
exactly.  A loop over the cells (:mod:`primordia.core.compiled`) evaluates it from the
cells' hat-function gradients, kept for the run.  The physics stays the members' UFL:
:meth:`P1Advection.recognise` reads it from the form, a sum of terms

    s * w[k] * dot(r, grad(c)) * dx        (s a number, r a P1 vector or P1 components)

and anything else (another factor, a subdomain, a quadrature degree below 2, another
element, a backend without :meth:`~primordia.core.backend.Backend.p1_cell_dofs`, no C
compiler) is assembled as before.  Before its first use the closed form is checked
against the backend's assembly of the same form on smooth fields set for the check.
"""

from __future__ import annotations

import ctypes

import numpy as np
from ufl.classes import Coefficient, Dot, FixedIndex, Grad, Indexed, Inner, ListTensor, Product, ScalarValue

from primordia.backends.ufl_numpy import cell_quantities
from primordia.core import compiled
from primordia.coupling.closed_forms import agrees_with_assembly, flattened, hat_gradients, write_local


class P1Advection:
    """Assembles a sum of P1 advection terms (see the module docstring) into the test space's vector."""

    def __init__(self, backend, form, library, terms, coordinates):
        self.backend, self.form, self._library = backend, form, library
        self._terms = terms            # (scale, out dofs, c, c dofs, [(r coefficient, component)], r dofs)
        self._gradients = hat_gradients(coordinates)  # (cells, nv, gdim)
        d = coordinates.shape[2]
        self._weights = np.ascontiguousarray(cell_quantities(coordinates)["CellVolume"] / ((d + 1) * (d + 2)))
        self._groups, self._positions = _by_velocity(terms)  # the loop's arguments; the arrays they address

    @classmethod
    def recognise(cls, backend, form) -> "P1Advection | None":
        """The closed form of ``form`` (a linear form), or None where it does not apply."""
        library = compiled.kernels(backend.comm)
        parsed = _terms(form) if library is not None else None
        if parsed is None:
            return None
        mesh = form.arguments()[0].ufl_function_space().mesh
        coordinates = backend.p1_cell_coordinates(mesh)
        test_space = form.arguments()[0].ufl_function_space()
        terms = []
        for scale, component, c, velocity in parsed:
            out = backend.p1_cell_dofs(test_space, component)
            c_dofs = backend.p1_cell_dofs(c.ufl_function_space())
            r_dofs = [backend.p1_cell_dofs(r.ufl_function_space(), part) for r, part in velocity]
            if (coordinates is None or out is None or c_dofs is None or any(d is None for d in r_dofs)
                    or len(velocity) != coordinates.shape[2]):
                return None
            terms.append((scale, out, c, c_dofs, velocity, np.ascontiguousarray(np.stack(r_dofs))))
        if not terms or coordinates.shape[1] != coordinates.shape[2] + 1:
            return None
        evaluator = cls(backend, form, library, terms, coordinates)
        return evaluator if evaluator._agrees_with_assembly(coordinates) else None

    def assemble(self, b=None):
        """The form's vector (a backend vector of the test space; ``b`` is reused): owned and ghost rows summed."""
        if b is None:
            b = self.backend.assemble_vector(self.form)  # the layout only: its values are overwritten
        return write_local(b, self._add)

    def _add(self, values: np.ndarray) -> None:
        address, local_array = compiled.address, self.backend.local_array
        n, _, gdim = self._gradients.shape
        for velocity, r_dofs, scales, outs, c_dofs, species in self._groups:
            r = (ctypes.c_void_p * gdim)(*[address(local_array(f)) for f, _ in velocity])
            c = (ctypes.c_void_p * len(species))(*[address(local_array(f)) for f in species])
            self._library.primordia_p1_advection(
                n, gdim, len(species), address(scales), address(self._gradients), address(self._weights),
                ctypes.addressof(outs), ctypes.addressof(c_dofs), address(r_dofs, np.int32),
                ctypes.addressof(c), ctypes.addressof(r), address(values))

    def _agrees_with_assembly(self, coordinates: np.ndarray) -> bool:
        """The check against assembly, every part read a smooth function of its nodes (the same on every
        rank), each its own."""
        x, y = coordinates[..., 0], coordinates[..., -1]
        settings = []
        for number, (_, _, c, c_dofs, velocity, r_dofs) in enumerate(self._terms):
            settings.append((c, c_dofs, np.sin((1.0 + 0.3 * number) * x + 0.3) * np.cos(0.7 * y)))
            settings += [(r, r_dofs[d], np.cos((0.5 + 0.4 * part) * x - 0.2 * y) + 0.1 * part)
                         for d, (r, part) in enumerate(velocity)]
        return agrees_with_assembly(self, settings, "the closed-form advection")


def _by_velocity(terms) -> tuple[list, list]:
    """The terms grouped by their velocity, for the loop that reads it once a cell for every term of a group:
    [(velocity, r dofs (cells, nv, gdim), scales, out pointers, c-dof pointers, c fields)] and the index
    arrays the pointers address (to keep alive).  Positions are int32 (dolfinx's own index type) and equal
    arrays are one array, read once a cell too."""
    groups, arrays = {}, []

    def one(positions):
        positions = np.ascontiguousarray(positions, dtype=np.int32)
        for known in arrays:
            if known.shape == positions.shape and np.array_equal(known, positions):
                return known
        arrays.append(positions)
        return positions

    for scale, out, c, c_dofs, velocity, r_dofs in terms:
        key = tuple((id(f), part) for f, part in velocity)
        group = groups.setdefault(key, (velocity, one(np.moveaxis(r_dofs, 0, -1)), [], [], [], []))
        for items, item in zip(group[2:], (scale, one(out), one(c_dofs), c)):
            items.append(item)

    def pointers(items):
        return (ctypes.c_void_p * len(items))(*[compiled.address(a, np.int32) for a in items])

    made = [(velocity, r_dofs, np.array(scales, dtype=np.float64), pointers(outs), pointers(c_dofs), species)
            for velocity, r_dofs, scales, outs, c_dofs, species in groups.values()]
    return made, arrays


def _terms(form) -> list | None:
    """[(scale, test component, c, [(r, flat component) per dimension])] of each integral, or None."""
    if len(form.arguments()) != 1:
        return None
    test = form.arguments()[0]
    terms = []
    for integral in form.integrals():
        degree = integral.metadata().get("quadrature_degree")
        if (integral.integral_type() != "cell" or integral.subdomain_id() not in ("everywhere", "otherwise")
                or (degree is not None and degree < 2)
                or integral.ufl_domain().ufl_cell().cellname() not in ("triangle", "tetrahedron")):
            return None
        term = _term(integral.integrand(), test)
        if term is None:
            return None
        terms.append(term)
    return terms


def _term(expression, test):
    """(scale, test component or None, c, velocity parts) of s * w[k] * dot(r, grad(c)), or None."""
    scale, tested, component, advection = 1.0, False, None, None
    for factor in flattened(expression, Product):
        if isinstance(factor, ScalarValue):
            scale *= float(factor)
        elif factor == test and not test.ufl_shape and not tested:
            tested = True
        elif (isinstance(factor, Indexed) and factor.ufl_operands[0] == test and len(test.ufl_shape) == 1
              and _fixed_index(factor) is not None and not tested):
            tested, component = True, _fixed_index(factor)
        elif isinstance(factor, (Dot, Inner)) and advection is None:
            advection = _advection(*factor.ufl_operands)
            if advection is None:
                return None
        else:
            return None
    return (scale, component, *advection) if tested and advection is not None else None


def _fixed_index(indexed) -> int | None:
    """k of ``v[k]`` (one fixed index), else None."""
    indices = indexed.ufl_operands[1]
    return int(indices[0]) if len(indices) == 1 and isinstance(indices[0], FixedIndex) else None


def _advection(left, right):
    """(c, [(r, component)]) of dot(r, grad(c)) in either order, or None."""
    for velocity, gradient in ((left, right), (right, left)):
        if (isinstance(gradient, Grad) and isinstance(gradient.ufl_operands[0], Coefficient)
                and not gradient.ufl_operands[0].ufl_shape):
            parts = _components(velocity)
            if parts is not None:
                return gradient.ufl_operands[0], parts
    return None


def _components(velocity):
    """[(coefficient, flat component)] of a vector: a vector coefficient or a list of its scalar components."""
    if isinstance(velocity, Coefficient) and len(velocity.ufl_shape) == 1:
        if velocity.ufl_function_space().ufl_element().value_shape() != velocity.ufl_shape:
            return None
        return [(velocity, i) for i in range(velocity.ufl_shape[0])]
    if isinstance(velocity, ListTensor):
        parts = []
        for item in velocity.ufl_operands:
            if not (isinstance(item, Indexed) and isinstance(item.ufl_operands[0], Coefficient)
                    and len(item.ufl_operands[0].ufl_shape) == 1 and _fixed_index(item) is not None):
                return None
            parts.append((item.ufl_operands[0], _fixed_index(item)))
        return parts
    return None
