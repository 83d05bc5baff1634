"""What the linear forms evaluated without cell-by-cell assembly share.

:mod:`~primordia.coupling.p1_advection`, :mod:`~primordia.coupling.p1_gradient_load` and
:mod:`~primordia.coupling.constant_load` each recognise a shape of linear form from its UFL and
evaluate it their own way.  They share the hat-function gradients of affine simplices, the
writing of per-cell contributions into a backend vector (owned and ghost rows, ghosts summed
to their owners), and the check against the backend's own assembly that every one of them
passes before its first use.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable

import numpy as np
from petsc4py import PETSc

from primordia.core.reductions import largest

logger = logging.getLogger(__name__)

#: Largest difference, relative to the largest entry, the check allows between an evaluation and assembly.
CHECK_TOLERANCE = 1e-12


def hat_gradients(coordinates: np.ndarray) -> np.ndarray:
    """Gradients (cells, nv, gdim) of the hat functions of affine simplices."""
    edges = coordinates[:, 1:, :] - coordinates[:, :1, :]          # (cells, d, d): rows x_j - x_0
    inverse = np.linalg.inv(edges)                                  # columns: gradients of lambda_1 .. lambda_d
    gradients = np.empty_like(coordinates)
    gradients[:, 1:, :] = np.swapaxes(inverse, 1, 2)
    gradients[:, 0, :] = -gradients[:, 1:, :].sum(axis=1)
    return np.ascontiguousarray(gradients)


def flattened(expression, kind) -> list:
    """The operands of a tree of ``kind`` nodes (UFL's binary Sum or Product) in order, as one list."""
    if isinstance(expression, kind):
        return [item for operand in expression.ufl_operands for item in flattened(operand, kind)]
    return [expression]


def write_local(b, fill):
    """``b`` with ``fill(values)`` written into its owned and ghost rows (zeroed first), the ghost rows then
    summed to their owners, as an assembly adds them (a serial Vec's local form is itself)."""
    with b.localForm() as local:
        values = local.getArray()
        values[:] = 0.0
        fill(values)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return b


def agrees_with_assembly(evaluator, settings: Iterable[tuple], what: str) -> bool:
    """Whether ``evaluator.assemble`` gives ``evaluator.form``'s assembled vector to CHECK_TOLERANCE of its
    largest entry, and that vector is not zero, with the fields set for the check and every constant of
    the form set to a value of its own (a load zero at t = 0 is not checked against zero); all restored.

    ``settings``: (function, local positions, values) to set, the same on every rank (collective).
    """
    backend, form = evaluator.backend, evaluator.form
    settings = list(settings)
    fields = {id(function): function for function, _, _ in settings}
    kept_fields = {key: backend.local_array(function).copy() for key, function in fields.items()}
    constants = form.constants()
    kept_constants = [np.array(constant.value, dtype=float, copy=True) for constant in constants]
    try:
        for function, positions, values in settings:
            backend.local_array(function)[positions] = values
        for number, (constant, value) in enumerate(zip(constants, kept_constants)):
            constant.value = 0.37 + 0.61 * number + 0.13 * np.arange(value.size).reshape(value.shape)
        vector = backend.assemble_vector(form)
        assembled = vector.getArray(readonly=True).copy()
        mine = evaluator.assemble(vector).getArray(readonly=True)  # into the same layout: no second assembly
        size = float(largest(backend.comm, np.abs(assembled).max(initial=0.0)))
        difference = float(largest(backend.comm, np.abs(mine - assembled).max(initial=0.0)))
    finally:
        for key, function in fields.items():
            backend.local_array(function)[:] = kept_fields[key]
        for constant, value in zip(constants, kept_constants):
            constant.value = value
    agrees = size > 0.0 and difference <= CHECK_TOLERANCE * size
    if not agrees:
        logger.debug("%s differs from assembly by %.3g of %.3g: assembled", what, difference, size)
    return agrees
