"""Formulas written in a config, evaluated as UFL or as numpy.

Boundary values and spatially varying coefficients are given as strings such as
``"s0 * sin(pi * t / t_hat)"`` or ``"1e-4 * (1 + 0.5 * x[0] / 20)"``.  They are
parsed once with :mod:`ast` against a whitelist (numbers, ``x[i]``, ``t``,
named constants, + - * / **, and the functions below), so a config cannot run
arbitrary code, and a mistake is reported naming the formula.

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
        self.constants = {"pi": math.pi, **(constants or {})}
        if isinstance(text, (int, float)) and not isinstance(text, bool):
            text = repr(float(text))
        if not isinstance(text, str):
            raise ConfigError(f"{where} must be a number or a formula string, got {text!r}")
        self.text = text
        try:
            self.tree = ast.parse(text.strip(), mode="eval").body
        except SyntaxError:
            raise ConfigError(f"{where}: cannot parse formula {text!r}") from None
        self._check(self.tree)

    def _check(self, node):
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            return
        if isinstance(node, ast.Name):
            if node.id not in ("x", "t") and node.id not in self.constants:
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
                and isinstance(node.slice, ast.Constant) and node.slice.value in (0, 1, 2):
            return
        raise ConfigError(f"{self.where}: {self.text!r} uses something a formula may not contain "
                          f"({ast.dump(node)[:40]}...)")

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
        return x[node.slice.value]  # ast.Subscript x[i]

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

    def numpy(self, x: np.ndarray, t: float) -> np.ndarray:
        return np.stack([c.numpy(x, t) for c in self.components])
