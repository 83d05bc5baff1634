r"""Loads that read no field: a few vectors assembled once, combined with numbers each step.

Example 1b's traction on its top edge, t = (0, s0 sin(pi t / t_hat)) (seed section 5.3), changes
only with the time, yet it was assembled at every step: at 171^2 0.15 ms on FEniCSx, on
scikit-fem about 1 ms alone in the backend's interpreter and 3 ms a step in a profile of the
run.  An integrand that reads no field, no coordinate, no geometric quantity (a facet normal)
and no derivative of the test function w is, being linear in w,

    sum_a g_a(constants) w[a],

so the form's vector is sum_a g_a(c) B_a, where B_a assembles w[a] over the same measure (with
the integral's own metadata) once.  g_a is the integrand with w replaced by the a-th unit
vector, indices expanded (components it does not read become UFL's Zero and are left out),
and is evaluated as a scalar by :class:`~primordia.coupling.nodal_program.NodalProgram`.
:meth:`ConstantLoad.recognise` gives None for anything else, which is assembled as before.
Before its first use the result is checked against the backend's assembly with every
constant set to a value of its own (then restored, :func:`~primordia.coupling.closed_forms.
agrees_with_assembly`), so that a load zero at t = 0 is not checked against zero.
"""

from __future__ import annotations

import numpy as np
import ufl
from ufl.algorithms import expand_derivatives, expand_indices
from ufl.algorithms.apply_algebra_lowering import apply_algebra_lowering
from ufl.algorithms.remove_complex_nodes import remove_complex_nodes
from ufl.classes import Derivative, GeometricQuantity, Zero
from ufl.corealg.traversal import unique_pre_traversal

from primordia.coupling.closed_forms import agrees_with_assembly
from primordia.coupling.nodal_program import NodalProgram, constant_value


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
        roots, pieces = [], []  # g_a, and what B_a integrates: (integral, component or None)
        for integral in form.integrals():
            for a in range(count or 1):
                unit = ufl.as_vector([1.0 if k == a else 0.0 for k in range(count)]) if count else ufl.as_ufl(1.0)
                g = expand_indices(remove_complex_nodes(expand_derivatives(apply_algebra_lowering(
                    ufl.replace(integral.integrand(), {test: unit})))))
                if not isinstance(g, Zero):
                    roots.append(g)
                    pieces.append((integral, a if count else None))
        gdim = test.ufl_function_space().ufl_domain().geometric_dimension()
        program = NodalProgram.compile(roots, np.zeros((gdim, 1)), _no_field, constant_value) if roots else None
        if program is None:
            return None
        vectors = [backend.assemble_vector(ufl.Form([integral.reconstruct(integrand=test if a is None else test[a])]))
                   for integral, a in pieces]
        load = cls(backend, form, program, vectors)
        return load if agrees_with_assembly(load, (), "the constant load") else None

    def assemble(self, b=None):
        """The form's vector, owned rows (``b`` is reused; its ghost rows are not written)."""
        if b is None:
            b = self._vectors[0].duplicate()
        b.zeroEntries()
        for g, vector in zip(self._program.run()[:, 0], self._vectors):
            if g != 0.0:
                b.axpy(float(g), vector)
        return b


def _no_field(function):
    raise AssertionError(f"a constant load read the field {function}")  # recognise() admits no coefficient
