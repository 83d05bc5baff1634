"""The fibre growth law, tested as its author ships it (run from the primordia checkout:
``pytest plugins/primordia-fibre-growth/tests``).  primordia's own suite checks the installed
plugin too: tests/unit/test_fibre_growth_plugin.py (entry point, F_g of a constant and of an
oblique fibre, example 2a on both backends growing more along the fibre).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import ufl
from ufl.algorithms import expand_derivatives

from primordia.core.errors import ConfigError
from primordia.core.parameters import ParameterSet
from primordia.model import Model
from primordia.physics.growth_laws import Seed2D, fluid_source
from primordia.testing import assert_backends_agree, run_on_backends
from primordia_fibre_growth import FibreGrowth

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "fibre.toml"
TWISTED = {"fibre": ["cos(q * x[1])", "sin(q * x[1])"], "constants": {"q": 0.3}}


def numbers(expression):
    """A UFL expression of numbers only (a tensor or a scalar), evaluated."""
    expression = expand_derivatives(ufl.as_ufl(expression))
    shape = expression.ufl_shape
    if not shape:
        return float(expression)
    return np.array([float(expression[index]) for index in np.ndindex(shape)]).reshape(shape)


def test_along_equals_across_is_the_seed_law_whatever_the_fibre():
    params = ParameterSet(Seed2D.parameters)
    point = ufl.as_vector([4.0, 11.0])      # a0 = (cos 3.3, sin 3.3): an oblique fibre
    fibre = FibreGrowth(params, along=1.0, across=1.0, **TWISTED).growth_tensor({"m": 1.2}, 7.0, point, 2)
    seed = Seed2D(params).growth_tensor({"m": 1.2}, 7.0, point, 2)
    np.testing.assert_allclose(numbers(fibre), numbers(seed), rtol=1e-14)


def test_the_fibre_follows_its_formula_and_the_frame_is_orthonormal():
    law = FibreGrowth(ParameterSet(Seed2D.parameters), **TWISTED)
    a0, across = (numbers(k) for k in law.directions_at(ufl.as_vector([4.0, 11.0]), 2))
    np.testing.assert_allclose(a0, [np.cos(3.3), np.sin(3.3)], rtol=1e-14)
    assert a0 @ across == pytest.approx(0.0, abs=1e-15) and across @ across == pytest.approx(1.0, rel=1e-15)


def test_the_fluid_source_is_derived_from_both_factors():
    """ell = ell_0 (along + across) (delta_2 + delta_3 (1 - m^2) / (1 + m^2)^2 dm/dt) (seed (4.15), general form)."""
    law = FibreGrowth(ParameterSet(Seed2D.parameters), along=0.8, across=0.3, **TWISTED)
    m, dm_dt = 0.9, 0.05
    ell = numbers(fluid_source(law, 1e-3, {"m": ufl.as_ufl(m)}, {"m": dm_dt}, ufl.as_ufl(2.0), None, 2))
    expected = 1e-3 * (0.8 + 0.3) * (0.15 + 0.045 * (1 - m**2) / (1 + m**2) ** 2 * dm_dt)
    assert ell == pytest.approx(expected, rel=1e-14)


@pytest.mark.parametrize("setting, message", [
    ('growth_law.fibre=["cos(x[1]", "1"]', "growth_law.fibre[0]: cannot parse formula 'cos(x[1]'"),
    ('growth_law.fibre=["1"]', "growth_law.fibre must be 2 formulas of x"),
    ('growth_law.fibre=["k * x[0]", "1"]', "growth_law.fibre[0]: unknown name 'k'"),
    ('growth_law.fibre=["t", "1"]', "growth_law.fibre is a direction of the reference configuration"),
    ("growth_law.across=-1", "growth_law.across must be a number >= 0"),
    ('growth_law.along="1"', "growth law fibre: option 'along' must be a number, got '1'"),
    ("growth_law.directions=[[1, 0], [0, 1]]", "growth_law.directions does not apply to the fibre law"),
])
def test_a_wrong_option_is_one_line_naming_it(setting, message):
    with pytest.raises(ConfigError, match=re.escape(message)) as error:
        Model.from_file(EXAMPLE, [setting])
    assert "\n" not in str(error.value)


def test_a_formula_for_a_missing_coordinate_is_refused_on_the_mesh_dimension():
    law = FibreGrowth(ParameterSet(Seed2D.parameters), fibre=["x[2]", "1"])
    with pytest.raises(ConfigError, match=r"growth_law.fibre\[0\]: 'x\[2\]' reads x\[2\], which does not exist in 2D"):
        law.check_dimension(2)


def test_the_example_runs_on_both_backends_and_they_agree(tmp_path):
    """The twisted fibres of examples/fibre.toml, 6 x 6 cells, 2 steps: both backends, one answer (1e-7: see
    tests/unit/test_fibre_growth_plugin.py for the margin), and the tissue grows."""
    overrides = ["mesh.cells=[6,6]", "time.t_final=0.4", "output.times=[0.4]", "output.pictures=false",
                 "coupling.tolerance=1e-10"]
    sims = run_on_backends(lambda: Model.from_file(EXAMPLE, overrides), tmp_path)
    assert_backends_agree(sims, fields=["m", "u", "psi", "p"], rtol=1e-7)
    assert sims["skfem"].diagnostic_values()["current_volume"] > 1.2 * 400.0
