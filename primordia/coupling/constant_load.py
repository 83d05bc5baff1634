r"""Loads that read no field: a few vectors assembled once, combined with numbers each step.

Example 1b's traction on its top edge, t = (0, s0 sin(pi t / t_hat)) (seed section 5.3), changes
only with the time, yet it was assembled at every step: at 171^2 0.15 ms on FEniCSx, on
scikit-fem about 1 ms alone in the backend's interpreter and 3 ms a step in a profile of the run.  An integrand that reads no field, no coordinate,
no geometric quantity (a facet normal) and no derivative of the test function w is, being
linear in w,

    sum_a g_a(constants) w[a],

so the form's vector is sum_a g_a(c) B_a, where B_a assembles w[a] over the same measure (with
the integral's own metadata) once.  g_a is the integrand with w replaced by the a-th unit
vector, indices expanded (components it does not read become UFL's Zero and are left out),
and is evaluated as a scalar by :class:`~primordia.coupling.nodal_program.NodalProgram`.
:meth:`ConstantLoad.recognise` gives None for anything else, which is assembled as before.
Before its first use the result is checked against the backend's assembly with every
constant set to a value of its own (then restored), so that a load zero at t = 0 is not
checked against zero.
"""

from __future__ import annotations

import logging

import numpy as np
import ufl
from ufl.algorithms import expand_derivatives, expand_indices
from ufl.algorithms.apply_algebra_lowering import apply_algebra_lowering
from ufl.algorithms.remove_complex_nodes import remove_complex_nodes
from ufl.classes import Derivative, GeometricQuantity, Zero
from ufl.corealg.traversal import unique_pre_traversal

from primordia.coupling.nodal_program import NodalProgram
from primordia.core.reductions import largest

logger = logging.getLogger(__name__)

#: Largest difference, relative to the largest entry, the check allows between this and assembly.
CHECK_TOLERANCE = 1e-12


class ConstantLoad:
    """Assembles a linear form whose integrands read only constants, as sum_a g_a(c) B_a (module docstring)."""

    def __init__(self, backend, form, program, vectors):
        self.backend, self.form = backend, form
        self._program, self._vectors = program, vectors  # g_a as one program, and the B_a

    @classmethod
    def recognise(cls, backend, form) -> "ConstantLoad | None":
        """The evaluation of ``form`` (a linear form) from vectors assembled once, or None where it does not apply."""
        if len(form.arguments()) != 1 or not form.integrals() or form.coefficients():
            return None
        test = form.arguments()[0]
        if len(test.ufl_shape) > 1 or any(isinstance(node, (Derivative, GeometricQuantity))
                                          for integral in form.integrals()
                                          for node in unique_pre_traversal(integral.integrand())):
            return None
        count = test.ufl_shape[0] if test.ufl_shape else None
        roots, vectors = [], []
        for integral in form.integrals():
            for a in range(count or 1):
                unit = ufl.as_vector([1.0 if k == a else 0.0 for k in range(count)]) if count else ufl.as_ufl(1.0)
                g = expand_indices(remove_complex_nodes(expand_derivatives(apply_algebra_lowering(
                    ufl.replace(integral.integrand(), {test: unit})))))
                if isinstance(g, Zero):
                    continue
                roots.append(g)
                vectors.append(backend.assemble_vector(ufl.Form([integral.reconstruct(
                    integrand=test[a] if count else test)])))
        gdim = test.ufl_function_space().ufl_domain().geometric_dimension()
        program = NodalProgram.compile(roots, np.zeros((gdim, 1)), _no_field, constant_value) if roots else None
        if program is None:
            return None
        load = cls(backend, form, program, vectors)
        return load if load._agrees_with_assembly() else None

    def assemble(self, b=None):
        """The form's vector, owned rows (``b`` is reused; its ghost rows are not written)."""
        if b is None:
            b = self._vectors[0].duplicate()
        b.zeroEntries()
        for g, vector in zip(self._program.run()[:, 0], self._vectors):
            if g != 0.0:
                b.axpy(float(g), vector)
        return b

    def _agrees_with_assembly(self) -> bool:
        """Both ways with each constant set to a value of its own (then restored): the same owned rows to
        CHECK_TOLERANCE."""
        backend = self.backend
        constants = self.form.constants()
        kept = [np.array(constant.value, dtype=float, copy=True) for constant in constants]
        try:
            for number, constant in enumerate(constants):
                constant.value = 0.37 + 0.61 * number + 0.13 * np.arange(kept[number].size).reshape(kept[number].shape)
            assembled = backend.assemble_vector(self.form).getArray(readonly=True).copy()
            mine = self.assemble().getArray(readonly=True)
            size = max(float(largest(backend.comm, np.abs(assembled).max(initial=0.0))), 1e-300)
            difference = float(largest(backend.comm, np.abs(mine - assembled).max(initial=0.0)))
        finally:
            for constant, value in zip(constants, kept):
                constant.value = value
        agrees = difference <= CHECK_TOLERANCE * size and size > 1e-300
        if not agrees:
            logger.debug("the constant load differs from assembly by %.3g of %.3g: assembled", difference, size)
        return agrees


def _no_field(function):
    raise AssertionError(f"a constant load read the field {function}")  # recognise() admits no coefficient


def constant_value(constant) -> np.ndarray:
    """A UFL constant's value as NodalProgram reads it (both backends' constants carry ``value``)."""
    return np.asarray(constant.value, dtype=float)
