"""Scalar integrands at the nodes as a straight-line program of numpy operations.

:class:`~primordia.coupling.nodal.NodalGroup` evaluates the lumped reactions of the species
(seed (2.3b)-(2.3d)) at the owned DOFs every solve.  The UFL interpreter
(:mod:`primordia.backends.ufl_numpy`) does that correctly for any integrand, but at a cost that
dominates here: it walks the tree each time (about 40 nodes for the e solve of example 1a),
carries the test, trial and point axes that a nodal value does not have, and allocates every
intermediate array.  At the seed's 171^2 mesh the e solve's remainder and Jacobian diagonal
took 1.06 ms a step that way, most of it neither arithmetic nor memory traffic.

:meth:`NodalProgram.compile` turns the integrands once into a list of numpy calls:

* the tree is walked once; subexpressions made one node (``_shared_subexpressions``) are one
  instruction;
* what reads only literals is folded; what reads only the coordinates and literals (the
  priming wave's ``x[1] / omega_3``) is computed once, as the interpreter's coordinates are
  fixed too; what reads constants but no array (``c_0``, the time) stays a scalar;
* every array instruction writes into a buffer of its own kind, reused once its value is no
  longer read (liveness over the straight-line program);
* ``a ** 2.0`` becomes ``np.square``, as numpy's ``**`` does for the interpreter: the same
  numbers, without ``np.power``'s general loop (ten times slower at this size);
* UFL's ``a - b``, which it writes ``a + (-1 b)``, is one subtraction, and ``-(-a)`` is ``a``:
  exact in IEEE arithmetic (e's program of example 1a: 30 -> 25 instructions).

The results equal the interpreter's bit for bit: the same operations in the same order, on
the same float64 values.  An integrand with a node this program does not know (anything
with a shape or free indices, a derivative, an argument) gives ``None`` from ``compile``, and
the caller keeps the interpreter.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from ufl import classes as uc

from primordia.backends.ufl_numpy import _CONDITIONS, _MATH_FUNCTIONS, post_order

#: How a node's value is known: at compile time, per run as a scalar, or per run as an array.
FOLDED, SCALAR, ARRAY = "folded", "scalar", "array"


class _Unsupported(Exception):
    """A node the program cannot evaluate; :meth:`NodalProgram.compile` returns None."""


def _power(exponent: float) -> Callable:
    """``base ** exponent`` for a literal exponent, with numpy's own fast cases of ``**``."""
    special = {2.0: np.square, 0.5: np.sqrt, -1.0: np.reciprocal}
    if exponent in special:
        ufunc = special[exponent]
        return lambda base, out=None: ufunc(base, out=out)
    if exponent == 1.0:
        return lambda base, out=None: np.positive(base, out=out)
    if exponent == 0.0:
        return lambda base, out=None: np.power(base, 0.0, out=out)
    return lambda base, out=None: np.power(base, exponent, out=out)


def _conditional(mask, yes, no, out=None):
    if out is None:
        return yes if mask else no
    np.copyto(out, no)
    np.copyto(out, yes, where=mask)
    return out


_BINARY = {uc.Sum: np.add, uc.Product: np.multiply, uc.Division: np.divide, uc.Atan2: np.arctan2,
           uc.MinValue: np.minimum, uc.MaxValue: np.maximum, **_CONDITIONS}
_UNARY = {**_MATH_FUNCTIONS, uc.Abs: np.absolute, uc.NotCondition: np.logical_not}

#: The "operation" of a node whose value is one of its operands' (-(-a), Conj, Real, Variable): no instruction.
_ALIAS = object()


def _operation_of(node) -> tuple:
    """(the numpy function, its operands) that compute an operator node, or (``_ALIAS``, (a,)) when the
    node's value is a's.  The one place that says what each operator is: the operands to compile first and
    the instruction both come from here."""
    inner = _negated(node)
    if inner is not None and _negated(inner) is not None:
        return _ALIAS, (_negated(inner),)  # -(-a): a itself
    if isinstance(node, (uc.Conj, uc.Real, uc.Variable)):  # the identity on real scalars (a Variable's label aside)
        return _ALIAS, node.ufl_operands[:1]
    if isinstance(node, uc.Sum) and _difference(node) is not None:
        return np.subtract, _difference(node)  # a + (-1 b): a - b, the same number
    if isinstance(node, uc.Power):
        base, exponent = node.ufl_operands
        if isinstance(exponent, uc.ScalarValue) and not isinstance(exponent, uc.ComplexValue):
            return _power(float(exponent.value())), (base,)
        return np.power, node.ufl_operands
    if isinstance(node, uc.Erf):
        from scipy.special import erf  # a ufunc, as the interpreter's; imported only when an integrand needs it

        return erf, node.ufl_operands
    if isinstance(node, uc.Conditional):
        return _conditional, node.ufl_operands
    function = _UNARY.get(type(node)) or _BINARY.get(type(node))
    if function is None:
        raise _Unsupported(type(node).__name__)
    return function, node.ufl_operands


def _negated(node):
    """``a`` when ``node`` is UFL's ``-a`` (the product of -1 and ``a``), else None."""
    if isinstance(node, uc.Product):
        factor, other = node.ufl_operands
        if isinstance(factor, uc.ScalarValue) and not isinstance(factor, uc.ComplexValue) and factor.value() == -1:
            return other
    return None


def _difference(node) -> tuple | None:
    """(a, b) when the sum ``node`` is UFL's ``a - b``, ``a + (-1 b)`` in either order, else None.

    In IEEE arithmetic a + (-b) is a - b exactly: one operation less, the same number.
    """
    first, second = node.ufl_operands
    if _negated_once(second) is not None:
        return first, _negated_once(second)
    if _negated_once(first) is not None:
        return second, _negated_once(first)
    return None


def _negated_once(node):
    """``a`` when ``node`` is ``-a`` and ``a`` is not itself a negation (``-(-a)`` is ``a``), else None."""
    inner = _negated(node)
    return inner if inner is not None and _negated(inner) is None else None


def constant_value(constant) -> np.ndarray:
    """A UFL constant's value, as a program reads it (both backends' constants carry ``value``)."""
    return np.asarray(constant.value, dtype=float)


class NodalProgram:
    """Scalar integrands evaluated at ``size`` nodes as one straight-line numpy program.

    ``read_field(function)`` gives a field's owned values (a 1D array of ``size``), and
    ``read_constant(constant)`` a constant's value (an array, indexed for a component); both
    are called at every :meth:`run`, so the program follows the fields and the time.
    """

    def __init__(self, roots: Sequence, coordinates: np.ndarray, read_field: Callable, read_constant: Callable):
        self.size = coordinates.shape[1]
        self._coordinates = coordinates
        self._read_field, self._read_constant = read_field, read_constant
        self._slots: dict[int, int] = {}  # node id -> register
        self._kinds: dict[int, str] = {}
        self._registers: list = []
        self._loads: list[tuple[int, Callable, object]] = []  # (register, reader, what): fields and constants
        self._code: list[tuple[Callable, int, tuple[int, ...], object]] = []  # (function, target, operands, buffer kind)
        for root in roots:
            self._compile(root)
        self._roots = [self._slots[id(root)] for root in roots]
        self._buffers = self._allocate()

    @classmethod
    def compile(cls, roots: Sequence, coordinates: np.ndarray, read_field: Callable,
                read_constant: Callable) -> NodalProgram | None:
        """The program of ``roots`` (scalar UFL integrands), or None when one has a node it cannot run."""
        try:
            return cls(roots, coordinates, read_field, read_constant)
        except _Unsupported:
            return None

    # -- compiling --------------------------------------------------------------------------
    def _register(self, node, kind: str, value=None) -> int:
        self._slots[id(node)] = len(self._registers)
        self._kinds[id(node)] = kind
        self._registers.append(value)
        return self._slots[id(node)]

    def _compile(self, root) -> None:
        for node in post_order(root, self._slots, self._operands):
            self._instruction(node)

    @staticmethod
    def _operands(node) -> tuple:
        if isinstance(node, uc.MultiIndex) or node.ufl_shape or node.ufl_free_indices:
            raise _Unsupported(type(node).__name__)
        if isinstance(node, (uc.Indexed, uc.Terminal)):
            return ()  # an Indexed is read whole (a component of a constant or of the coordinates)
        return _operation_of(node)[1]

    def _instruction(self, node) -> None:
        if isinstance(node, uc.ScalarValue) and not isinstance(node, uc.ComplexValue):
            self._register(node, FOLDED, np.float64(node.value()))
        elif isinstance(node, uc.Zero):
            self._register(node, FOLDED, np.float64(0.0))
        elif isinstance(node, uc.Constant):
            self._loads.append((self._register(node, SCALAR), self._constant_reader(()), node))
        elif isinstance(node, uc.Coefficient):
            self._loads.append((self._register(node, ARRAY), self._read_field, node))
        elif isinstance(node, uc.Indexed):
            self._component(node)
        elif isinstance(node, uc.Terminal):
            raise _Unsupported(type(node).__name__)
        else:
            function, operands = _operation_of(node)
            if function is _ALIAS:
                (inner,) = operands
                self._slots[id(node)], self._kinds[id(node)] = self._slots[id(inner)], self._kinds[id(inner)]
            else:
                self._operation(node, function, operands)

    def _constant_reader(self, index: tuple) -> Callable:
        read = self._read_constant
        return lambda constant: np.float64(np.asarray(read(constant), dtype=float)[index])

    def _component(self, node) -> None:
        expression, multiindex = node.ufl_operands
        if not all(isinstance(i, uc.FixedIndex) for i in multiindex):
            raise _Unsupported("Indexed by a free index")
        index = tuple(int(i) for i in multiindex)
        if isinstance(expression, uc.SpatialCoordinate) and len(index) == 1:
            self._register(node, FOLDED, np.ascontiguousarray(self._coordinates[index[0]], dtype=float))
        elif isinstance(expression, uc.Constant):
            self._loads.append((self._register(node, SCALAR), self._constant_reader(index), expression))
        else:
            raise _Unsupported(f"Indexed {type(expression).__name__}")

    def _operation(self, node, function: Callable, operands: Sequence) -> None:
        slots = tuple(self._slots[id(op)] for op in operands)
        kinds = {self._kinds[id(op)] for op in operands}
        is_array = ARRAY in kinds or any(isinstance(self._registers[s], np.ndarray) and self._registers[s].ndim
                                         for s in slots)
        if kinds == {FOLDED}:  # literals, and the coordinates: computed once, here
            with np.errstate(all="ignore"):
                self._register(node, FOLDED, function(*(self._registers[s] for s in slots)))
            return
        if not is_array:
            self._code.append((function, self._register(node, SCALAR), slots, None))
            return
        boolean = isinstance(node, uc.Condition)
        self._code.append((function, self._register(node, ARRAY), slots, bool if boolean else float))

    def _allocate(self) -> list:
        """A buffer for each array instruction: a row of the result for the integrands themselves, and
        otherwise one shared by instructions whose values do not overlap in time."""
        self._result = np.empty((len(self._roots), self.size))
        computed = {target for _, target, _, dtype in self._code if dtype is float}
        rows = {}  # register -> the row of the result it is computed into
        for index, slot in enumerate(self._roots):
            if slot in computed:
                rows.setdefault(slot, index)
        last_read = {}
        for position, (_, _, operands, _) in enumerate(self._code):
            for slot in operands:
                last_read[slot] = position
        free: dict[type, list[np.ndarray]] = {float: [], bool: []}
        held: dict[int, np.ndarray] = {}
        buffers = []
        for position, (_, target, operands, dtype) in enumerate(self._code):
            if dtype is None:
                buffers.append(None)
                continue
            if target in rows:
                buffers.append(self._result[rows[target]])
            else:
                # taken before the operands' buffers are given back: no instruction writes over what it
                # reads (a conditional copies one branch in, then the other)
                held[target] = free[dtype].pop() if free[dtype] else np.empty(self.size, dtype=dtype)
                buffers.append(held[target])
            for slot in set(operands):
                if last_read[slot] == position and slot in held:
                    released = held.pop(slot)
                    free[bool if released.dtype == bool else float].append(released)
        # what is not computed into its row (a field, a constant, a value read twice) is copied in
        self._copies = [(self._result[index], slot) for index, slot in enumerate(self._roots) if rows.get(slot) != index]
        return buffers

    # -- running ----------------------------------------------------------------------------
    def run(self) -> np.ndarray:
        """The integrands' values at the nodes, (number of integrands, size).

        The same array every time: the next run overwrites it.
        """
        registers = self._registers
        for slot, reader, what in self._loads:
            registers[slot] = reader(what)
        with np.errstate(all="ignore"):  # as the interpreter: a NaN shows in the result, not as a warning
            for (function, target, operands, _), buffer in zip(self._code, self._buffers):
                if buffer is None:
                    registers[target] = function(*[registers[s] for s in operands])
                else:
                    registers[target] = function(*[registers[s] for s in operands], out=buffer)
        for row, slot in self._copies:
            row[...] = registers[slot]
        return self._result
