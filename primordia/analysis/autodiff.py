"""First derivatives of the simulation's own formulas: dual numbers and an ``ops`` namespace for them.

A kinetics is written once against an ``ops`` namespace (:mod:`primordia.core.ops`).
Evaluated with :data:`DUAL` on :class:`Dual` concentrations, the very code that
builds the weak forms returns each reaction rate together with its gradient with
respect to every species (forward-mode automatic differentiation): the reaction
Jacobian of the linear stability analysis, exact to rounding, with no formula
typed in twice.

A :class:`Dual` is ``value + sum_j grad[..., j] eps_j`` with ``eps_i eps_j = 0``.
Values broadcast like numpy arrays (a parameter may be an array); the
derivative axis is the last one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from primordia.core.errors import ConfigError
from primordia.core.ops import Ops


class Dual:
    """A value and its first derivatives with respect to n independent variables (last axis)."""

    __slots__ = ("value", "grad")
    __array_ufunc__ = None  # numpy arrays defer to the reflected operators below

    def __init__(self, value, grad):
        self.value = np.asarray(value, dtype=float)
        self.grad = np.asarray(grad, dtype=float)

    # -- arithmetic -----------------------------------------------------------------
    def __add__(self, other):
        if isinstance(other, Dual):
            return Dual(self.value + other.value, self.grad + other.grad)
        return Dual(self.value + other, self.grad)

    __radd__ = __add__

    def __neg__(self):
        return Dual(-self.value, -self.grad)

    def __pos__(self):
        return self

    def __sub__(self, other):
        return self + (-other)

    def __rsub__(self, other):
        return (-self) + other

    def __mul__(self, other):
        if isinstance(other, Dual):
            return Dual(self.value * other.value,
                        self.grad * other.value[..., None] + self.value[..., None] * other.grad)
        other = np.asarray(other, dtype=float)
        return Dual(self.value * other, self.grad * other[..., None])

    __rmul__ = __mul__

    def __truediv__(self, other):
        if isinstance(other, Dual):
            return self * other._reciprocal()
        other = np.asarray(other, dtype=float)
        return Dual(self.value / other, self.grad / other[..., None])

    def __rtruediv__(self, other):
        return self._reciprocal() * other

    def _reciprocal(self):
        return Dual(1.0 / self.value, -self.grad / (self.value**2)[..., None])

    def __pow__(self, exponent):
        if isinstance(exponent, Dual):
            return exp(exponent * log(self))
        exponent = np.asarray(exponent, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = np.where(exponent == 0.0, 0.0, exponent * self.value ** (exponent - 1.0))
        return Dual(self.value**exponent, slope[..., None] * self.grad)

    def __rpow__(self, base):
        return exp(self * np.log(np.asarray(base, dtype=float)))

    def __repr__(self) -> str:
        return f"Dual({self.value!r}, grad={self.grad!r})"


def _chain(function, derivative):
    """An elementary function applied to numbers or duals (chain rule for the latter)."""

    def apply(x):
        if isinstance(x, Dual):
            return Dual(function(x.value), derivative(x.value)[..., None] * x.grad)
        return function(x)

    apply.__name__ = function.__name__
    return apply


exp = _chain(np.exp, np.exp)
tanh = _chain(np.tanh, lambda v: 1.0 - np.tanh(v) ** 2)
sqrt = _chain(np.sqrt, lambda v: 0.5 / np.sqrt(v))
log = _chain(np.log, lambda v: 1.0 / v)


class _NoPosition:
    """``ops.x`` of a spatially homogeneous evaluation: reading it is a clear error."""

    def __getitem__(self, index):
        raise ConfigError("the kinetics reads the position x in its homogeneous form: the linear analysis "
                          "needs Kinetics.homogeneous() to return reactions that do not depend on x")

    def __len__(self):
        return 0


#: The ``ops`` namespace of dual numbers (no position: the analysis linearises homogeneous states).
DUAL = Ops(exp=exp, tanh=tanh, sqrt=sqrt, ln=log, x=_NoPosition())


def seeded(values: Mapping[str, object], names: Sequence[str]) -> dict[str, Dual]:
    """The variables ``names`` at ``values`` as duals, the j-th seeded with d/d(names[j]) = 1."""
    n = len(names)
    return {name: Dual(values[name], np.eye(n)[j]) for j, name in enumerate(names)}


def value_and_gradient(result, shape, n: int):
    """(value, gradient) of a dual, or of a plain number (zero gradient), broadcast to ``shape``."""
    if isinstance(result, Dual):
        return (np.broadcast_to(result.value, shape).astype(float),
                np.broadcast_to(result.grad, tuple(shape) + (n,)).astype(float))
    return np.broadcast_to(np.asarray(result, dtype=float), shape).copy(), np.zeros(tuple(shape) + (n,))
