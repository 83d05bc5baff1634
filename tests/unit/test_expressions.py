"""Config formulas (primordia.core.expressions): what they evaluate to, and what they refuse in one line.

A formula is read once against a whitelist; its values come out as numpy arrays (Dirichlet
data, at points of shape (gdim, n)) or as UFL (weak forms), and both must say the same thing.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import ufl

from primordia.core.errors import ConfigError
from primordia.core.expressions import Formula, VectorFormula

#: Three points of the plane, as the numpy evaluation takes them: shape (gdim, n).
POINTS = np.array([[0.0, 1.0, 20.0], [0.0, -2.0, 0.5]])


def one_line_error(make, *args, **kwargs) -> str:
    """The ConfigError ``make(*args)`` raises, checked to be a single line."""
    with pytest.raises(ConfigError) as caught:
        make(*args, **kwargs)
    message = str(caught.value)
    assert "\n" not in message, message
    return message


# -- what a formula evaluates to -------------------------------------------------------------
@pytest.mark.parametrize("text, constants, expected", [
    ("s0 * sin(pi * t / t_hat)", {"s0": 2.0, "t_hat": 4.0}, [2.0, 2.0, 2.0]),  # at t = 2: s0 sin(pi / 2)
    ("1e-4 * (1 + 0.5 * x[0] / 20)", None, [1e-4, 1.025e-4, 1.5e-4]),
    ("-x[1] ** 2 + 3", None, [3.0, -1.0, 2.75]),
    ("exp(x[0]) - ln(1 + x[0]) + log(2)", None, [1.0 + math.log(2), math.e - math.log(2) + math.log(2),
                                                 math.exp(20) - math.log(21) + math.log(2)]),
    ("sqrt(x[0]) + abs(x[1]) + tanh(0) + atan(0) + cos(0) + tan(0)", None, [1.0, 4.0, math.sqrt(20) + 1.5]),
    (2, None, [2.0, 2.0, 2.0]),  # a number is a constant formula
    (0.25, None, [0.25, 0.25, 0.25]),
])
def test_numpy_values_at_points_and_time(text, constants, expected):
    values = Formula(text, constants).numpy(POINTS, 2.0)
    assert values.shape == (3,)
    np.testing.assert_allclose(values, expected, rtol=1e-14)


def test_a_constant_formula_is_one_value_per_point_and_a_copy():
    values = Formula("3").numpy(POINTS, 0.0)
    values[0] = -1.0  # the result is the caller's own array, not a broadcast view of one number
    np.testing.assert_array_equal(values, [-1.0, 3.0, 3.0])


def test_ufl_and_numpy_say_the_same():
    cell = ufl.triangle
    x = ufl.SpatialCoordinate(ufl.Mesh(ufl.VectorElement("Lagrange", cell, 1)))
    formula = Formula("a * x[0] + x[1] ** 2 * t - sin(pi * x[0])", {"a": 3.0})
    point = (0.5, 2.0)
    from_ufl = formula.ufl(x, ufl.as_ufl(2.0))(point)
    from_numpy = formula.numpy(np.array(point)[:, None], 2.0)[0]
    assert from_ufl == pytest.approx(3.0 * 0.5 + 4.0 * 2.0 - 1.0, rel=1e-14)
    assert from_numpy == pytest.approx(from_ufl, rel=1e-14)


def test_depends_on_time():
    assert Formula("sin(t) * x[0]").depends_on_time()
    assert not Formula("sin(x[0]) + c", {"c": 1.0}).depends_on_time()
    assert VectorFormula(["0", "t"]).depends_on_time()
    assert not VectorFormula(["x[1]", "0"]).depends_on_time()


def test_a_vector_formula_has_one_row_per_component():
    traction = VectorFormula(["0", "-s0 * t"], {"s0": 5.0}, where="traction")
    assert len(traction) == 2
    values = traction.numpy(POINTS, 0.5)
    np.testing.assert_array_equal(values, [[0.0, 0.0, 0.0], [-2.5, -2.5, -2.5]])
    x = ufl.SpatialCoordinate(ufl.Mesh(ufl.VectorElement("Lagrange", ufl.triangle, 1)))
    assert traction.ufl(x, ufl.as_ufl(0.5)).ufl_shape == (2,)


def test_check_accepts_a_formula_finite_everywhere_it_is_used():
    Formula("1 / (1 + x[0] ** 2) * exp(-t)").check(POINTS.T, [0.0, 1.0, 100.0])


# -- what a formula refuses, in one line naming it -------------------------------------------
@pytest.mark.parametrize("text, fragments", [
    ("y + 1", ["boundary value", "unknown name 'y'", "known: x, t, pi"]),
    ("x + 1", ["uses the point x as a number", "x[0], x[1]"]),
    ("x[3]", ["reads x[3]", "only the components"]),
    ("x[-1]", ["may not contain"]),
    ("x[1.0]", ["may not contain"]),
    ("__import__('os').system('true')", ["may not contain"]),
    ("(lambda: 1)()", ["may not contain"]),
    ("x[0] if t else 1", ["may not contain"]),
    ("'one'", ["may not contain"]),
    ("sin(x[0], 1)", ["may not contain"]),
    ("max(x[0], 1)", ["may not contain"]),
    ("1 +", ["cannot parse formula '1 +'"]),
    ("", ["cannot parse"]),
    ("1/0", ["'1/0' cannot be evaluated: division by zero"]),
    ("t + 1/(1 - 1)", ["cannot be evaluated: division by zero"]),  # a constant part is evaluated at once
    ("exp(1000) * x[0]", ["cannot be evaluated: overflow"]),
    ("10**400", ["overflow"]),
    ("sqrt(-1) + t", ["invalid value"]),
    ("-" * 100_000 + "1", ["nested too deeply"]),
])
def test_bad_formulas_are_refused_when_read(text, fragments):
    message = one_line_error(Formula, text, where="boundary value")
    assert message.startswith("boundary value"), message
    for fragment in fragments:
        assert fragment in message, message


def test_a_boolean_is_not_a_number_in_a_formula_either():
    one_line_error(Formula, "True")


@pytest.mark.parametrize("value", [True, None, [1.0], {"a": 1}])
def test_a_value_that_is_neither_number_nor_string(value):
    assert "must be a number or a formula string" in one_line_error(Formula, value, where="traction")


@pytest.mark.parametrize("constants, fragment", [
    ({"x": 1.0}, "constant 'x' would shadow x, the coordinates"),
    ({"t": 1.0}, "constant 't' would shadow t, the time"),
    ({"sin": 1.0}, "constant 'sin' would shadow sin, a function"),
    ({"a": "1"}, "constant 'a' must be a number"),
    ({"a": True}, "constant 'a' must be a number"),
    ({"a": math.inf}, "constant 'a' must be a number, got inf"),
    ({"a": math.nan}, "constant 'a' must be a number, got nan"),
    ([("a", 1.0)], "constants must be a table"),
])
def test_bad_constants(constants, fragment):
    assert fragment in one_line_error(Formula, "1", constants)


def test_a_vector_formula_must_be_a_list():
    assert "must be a list of formulas" in one_line_error(VectorFormula, "0, 1", where="traction")


def test_a_vector_formula_names_its_bad_component():
    assert one_line_error(VectorFormula, ["0", "y"], where="traction").startswith("traction[1]: unknown name 'y'")


# -- what only the points and times of use show ---------------------------------------------------
def test_check_names_the_point_where_a_formula_divides_by_zero():
    points = np.array([[1.0, 0.5], [0.0, 2.0], [3.0, 3.0]])
    message = one_line_error(Formula("1 / x[0]", where="flux").check, points, [0.5])
    assert message == "flux: '1 / x[0]' cannot be evaluated at x = (0, 2), t = 0.5: division by zero"


def test_check_names_the_time_of_an_overflow():
    message = one_line_error(Formula("exp(t) * (1 + x[0])").check, np.ones((2, 2)), [0.0, 1.0, 1000.0])
    assert "at x = (1, 1), t = 1000: overflow" in message


def test_a_component_the_mesh_lacks_is_refused_by_check_and_by_evaluation():
    formula = Formula("x[2]", where="u_Gamma")
    assert one_line_error(formula.check, np.zeros((4, 2)), [0.0]) == \
        "u_Gamma: 'x[2]' reads x[2], which does not exist in 2D"
    assert "does not exist in 2D" in one_line_error(formula.numpy, np.zeros((2, 4)), 0.0)
    np.testing.assert_array_equal(formula.numpy(np.ones((3, 4)), 0.0), np.ones(4))  # in 3D it exists
