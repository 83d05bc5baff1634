"""Formulas written in a config, evaluated as UFL or as numpy.

Boundary values and spatially varying coefficients are given as strings such as
``"s0 * sin(pi * t / t_hat)"`` or ``"1e-4 * (1 + 0.5 * x[0] / 20)"``.  They are
parsed once with :mod:`ast` against a whitelist (numbers, ``x[i]``, ``t``,
named constants, + - * / **, and the functions below), so a config cannot run
arbitrary code, and a mistake is reported naming the formula.  Constants must be
finite numbers that do not shadow ``x``, ``t`` or a function; the parts of a
formula that depend on neither ``x`` nor ``t`` are evaluated when it is read
(``1/0``, ``exp(1000)``), and :meth:`Formula.check` evaluates the whole formula
where and when it will be used (a component of ``x`` the mesh lacks, a division
by zero on the boundary, an overflow at a later time) before any assembly.

The same :class:`Formula` evaluates to a UFL expression (for weak forms:
``x`` = SpatialCoordinate, ``t`` = the run's time constant) or to numpy arrays
(for Dirichlet values: ``x`` of shape (gdim, n), ``t`` a float).
"""

from __future__ import annotations

import ast
import math
from collections.abc import Mapping, Sequence

import numpy as np
import ufl

from primordia.core.errors import ConfigError
from primordia.core.validation import is_number, number

_UFL_FUNCTIONS = {"sin": ufl.sin, "cos": ufl.cos, "tan": ufl.tan, "exp": ufl.exp, "ln": ufl.ln, "log": ufl.ln,
                  "sqrt": ufl.sqrt, "tanh": ufl.tanh, "atan": ufl.atan, "abs": abs}
_NUMPY_FUNCTIONS = {"sin": np.sin, "cos": np.cos, "tan": np.tan, "exp": np.exp, "ln": np.log, "log": np.log,
                    "sqrt": np.sqrt, "tanh": np.tanh, "atan": np.arctan, "abs": np.abs}
_OPERATORS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
              ast.Div: lambda a, b: a / b, ast.Pow: lambda a, b: a ** b}


class Formula:
    """A scalar formula of ``x``, ``t`` and named constants."""

    def __init__(self, text, constants: Mapping[str, float] | None = None, where: str = "formula"):
        self.where = where
        self.constants = {"pi": math.pi, **_checked_constants(constants, where)}
        if is_number(text):
            text = repr(float(text))
        if not isinstance(text, str):
            raise ConfigError(f"{where} must be a number or a formula string, got {text!r}")
        self.text = text
        try:
            self.tree = ast.parse(text.strip(), mode="eval").body
            self._check(self.tree)
            self._check_constant_parts(self.tree)
        except (SyntaxError, ValueError):
            raise ConfigError(f"{where}: cannot parse formula {text!r}") from None
        except (RecursionError, MemoryError):
            raise ConfigError(f"{where}: formula {text[:40]!r}... is nested too deeply to evaluate") from None

    def _check(self, node):
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            return  # True and False are ints to Python, not numbers to a formula
        if isinstance(node, ast.Name):
            if node.id == "x":  # a Subscript x[i] returns before reaching its Name
                raise ConfigError(f"{self.where}: {self.text!r} uses the point x as a number; "
                                  f"use its components x[0], x[1] (x[2] in 3D)")
            if node.id != "t" and node.id not in self.constants:
                raise ConfigError(f"{self.where}: unknown name '{node.id}' in {self.text!r} "
                                  f"(known: x, t, {', '.join(sorted(self.constants))})")
            return
        if isinstance(node, ast.BinOp) and type(node.op) in _OPERATORS:
            self._check(node.left)
            self._check(node.right)
            return
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            self._check(node.operand)
            return
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _UFL_FUNCTIONS \
                and len(node.args) == 1 and not node.keywords:
            self._check(node.args[0])
            return
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id == "x" \
                and isinstance(node.slice, ast.Constant) and type(node.slice.value) is int:
            if node.slice.value not in (0, 1, 2):
                raise ConfigError(f"{self.where}: {self.text!r} reads x[{node.slice.value}], "
                                  f"but x has only the components x[0], x[1] (and x[2] in 3D)")
            return
        raise ConfigError(f"{self.where}: {self.text!r} uses something a formula may not contain "
                          f"({ast.dump(node)[:40]}...)")

    def _check_constant_parts(self, node) -> None:
        """Evaluate every largest part free of ``x`` and ``t``: 1/0, exp(1000), 10**400 fail now, named."""
        if not any(isinstance(n, ast.Name) and n.id in ("x", "t") for n in ast.walk(node)):
            self._evaluate_checked(node, None, 0.0, "")
            return
        children = node.args if isinstance(node, ast.Call) else ast.iter_child_nodes(node)
        for child in children:
            if isinstance(child, ast.expr) and not isinstance(child, ast.Subscript):
                self._check_constant_parts(child)

    def _evaluate_checked(self, node, x, t, place: str):
        """The value of ``node``, or a ConfigError saying why it is not a finite number."""
        try:
            with np.errstate(all="raise"):
                value = self._evaluate(node, x, t, _NUMPY_FUNCTIONS)
        except (ZeroDivisionError, FloatingPointError, OverflowError) as error:
            raise ConfigError(f"{self.where}: {self.text!r} cannot be evaluated{place}: {_why(error)}") from None
        finite = np.isfinite(value)
        if not np.all(finite):
            raise ConfigError(f"{self.where}: {self.text!r} is not finite{place}")
        return value

    def check(self, points: np.ndarray, times) -> None:
        """Raise a ConfigError naming the formula unless it is finite at ``points`` (n, gdim) at every time."""
        points = np.asarray(points, dtype=float)
        gdim = points.shape[1]
        for node in ast.walk(self.tree):
            if isinstance(node, ast.Subscript) and node.slice.value >= gdim:
                raise ConfigError(f"{self.where}: {self.text!r} reads x[{node.slice.value}], "
                                  f"which does not exist in {gdim}D")
        for t in times:
            try:
                self._evaluate_checked(self.tree, points.T, float(t), f" at t = {float(t):g}")
            except ConfigError:
                self._name_the_point(points, float(t))
                raise

    def _name_the_point(self, points: np.ndarray, t: float) -> None:
        """Re-raise the failure of :meth:`check` at the first point where the formula fails."""
        for point in points:
            place = f" at x = ({', '.join(f'{c:g}' for c in point)}), t = {t:g}"
            self._evaluate_checked(self.tree, point[:, None], t, place)

    def depends_on_time(self) -> bool:
        return any(isinstance(n, ast.Name) and n.id == "t" for n in ast.walk(self.tree))

    def _evaluate(self, node, x, t, functions):
        if isinstance(node, ast.Constant):
            return float(node.value)
        if isinstance(node, ast.Name):
            return {"x": x, "t": t}.get(node.id, self.constants.get(node.id))
        if isinstance(node, ast.BinOp):
            return _OPERATORS[type(node.op)](self._evaluate(node.left, x, t, functions),
                                             self._evaluate(node.right, x, t, functions))
        if isinstance(node, ast.UnaryOp):
            value = self._evaluate(node.operand, x, t, functions)
            return -value if isinstance(node.op, ast.USub) else value
        if isinstance(node, ast.Call):
            return functions[node.func.id](self._evaluate(node.args[0], x, t, functions))
        index = node.slice.value  # ast.Subscript x[i]
        size = x.ufl_shape[0] if hasattr(x, "ufl_shape") else len(x)
        if index >= size:
            raise ConfigError(f"{self.where}: {self.text!r} reads x[{index}], which does not exist in {size}D")
        return x[index]

    def ufl(self, x, t):
        """The formula as a UFL expression (``x`` SpatialCoordinate, ``t`` a UFL constant)."""
        return self._evaluate(self.tree, x, t, _UFL_FUNCTIONS)

    def numpy(self, x: np.ndarray, t: float) -> np.ndarray:
        """The formula at points ``x`` (shape (gdim, n)) and time ``t``."""
        value = self._evaluate(self.tree, x, t, _NUMPY_FUNCTIONS)
        return np.broadcast_to(np.asarray(value, dtype=float), x.shape[1:]).copy()


class VectorFormula:
    """A vector of formulas, one per component (e.g. a traction)."""

    def __init__(self, texts, constants: Mapping[str, float] | None = None, where: str = "formula"):
        if not isinstance(texts, Sequence) or isinstance(texts, str):
            raise ConfigError(f"{where} must be a list of formulas, one per component")
        self.components = [Formula(text, constants, f"{where}[{i}]") for i, text in enumerate(texts)]

    def __len__(self):
        return len(self.components)

    def depends_on_time(self) -> bool:
        return any(c.depends_on_time() for c in self.components)

    def ufl(self, x, t):
        return ufl.as_vector([c.ufl(x, t) for c in self.components])

    def check(self, points: np.ndarray, times) -> None:
        for component in self.components:
            component.check(points, times)

    def numpy(self, x: np.ndarray, t: float) -> np.ndarray:
        return np.stack([c.numpy(x, t) for c in self.components])


def _checked_constants(constants, where: str) -> dict[str, float]:
    """Named constants of a formula: a table of finite numbers that shadow neither x, t nor a function."""
    if constants is None:
        return {}
    if not isinstance(constants, Mapping):
        raise ConfigError(f"{where}: constants must be a table of name = number, got {constants!r}")
    for name, value in constants.items():
        if name in ("x", "t") or name in _UFL_FUNCTIONS:
            what = "the coordinates" if name == "x" else "the time" if name == "t" else "a function"
            raise ConfigError(f"{where}: constant '{name}' would shadow {name}, {what} (choose another name)")
        number(value, f"{where}: constant '{name}'")
    return dict(constants)


def _why(error: Exception) -> str:
    """The arithmetic failure in words."""
    text = str(error)
    if isinstance(error, ZeroDivisionError) or "divide" in text:
        return "division by zero"
    if isinstance(error, OverflowError) or "overflow" in text:
        return "overflow"
    if "invalid" in text:
        return "invalid value (e.g. the log or the square root of a negative number)"
    return text
