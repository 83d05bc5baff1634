"""Growth laws (seed section 4): the factors of (4.13), (4.14), F_g as printed after (4.12), the fluid
source ell = ell_0 sum_i d gamma_i/dt (4.15), the regularised roots, and how a config chooses a law."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import ufl
from ufl.algorithms import expand_derivatives

from primordia.core.errors import ConfigError, PluginError
from primordia.core.meshes import box, rectangle
from primordia.core.parameters import ParameterSet
from primordia.core.plugins import registry
from primordia.model import Model
from primordia.physics.growth_laws import Seed2D, Seed3D, fluid_source, positive_sqrt


def law(cls, **overrides):
    return cls(ParameterSet(cls.parameters, overrides))


def value(expression) -> np.ndarray:
    """A UFL expression built from numbers only, evaluated."""
    expression = expand_derivatives(ufl.as_ufl(expression))
    if expression.ufl_shape:
        return np.array([[float(expression[i, j]) for j in range(expression.ufl_shape[1])]
                         for i in range(expression.ufl_shape[0])])
    return float(expression)


def test_the_built_in_laws_are_registered():
    laws = registry("growth_laws")
    assert {"seed2d", "seed3d"} <= set(laws)
    assert laws["seed2d"][0] is Seed2D and laws["seed3d"][0] is Seed3D


def test_seed2d_is_eq_4_14_and_its_growth_tensor_takes_the_roots():
    m, t = 0.75, 520.0
    seed = law(Seed2D, delta_2=0.15, delta_3=0.045)
    gamma = 0.15 * t + 0.045 * m / (1 + m**2)
    assert [value(g) for g in seed.factors({"m": m}, t, None, 2)] == pytest.approx([gamma, gamma])
    F_g = value(seed.growth_tensor({"m": m}, t, None, 2))
    np.testing.assert_allclose(F_g, (1 + np.sqrt(gamma)) * np.eye(2), rtol=1e-14)
    # read literally, (4.14) stretches the tissue about 9.8 times by t = 520 (EQUATIONS.md)
    assert F_g[0, 0] == pytest.approx(9.83, abs=0.01)


def test_seed3d_is_eq_4_13_and_gamma_3_enters_without_a_root():
    m, t = 1.3, 10.0
    seed = law(Seed3D, delta_1=1 / 52, delta_2=0.01, delta_3=1 / 104)
    gammas = [value(g) for g in seed.factors({"m": m}, t, None, 3)]
    assert gammas == pytest.approx([t / 52, t / 52, 0.01 * t + m / (1 + m**2) / 104])
    F_g = value(seed.growth_tensor({"m": m}, t, None, 3))
    np.testing.assert_allclose(np.diag(F_g), [1 + np.sqrt(gammas[0]), 1 + np.sqrt(gammas[1]), 1 + gammas[2]])
    assert np.count_nonzero(F_g - np.diag(np.diag(F_g))) == 0


def test_growth_directions_rotate_the_frame_and_must_be_orthonormal():
    c, s = np.cos(0.3), np.sin(0.3)
    seed = Seed2D(ParameterSet(Seed2D.parameters), directions=[[c, s], [-s, c]])
    F_g = value(seed.growth_tensor({"m": 0.5}, 2.0, None, 2))
    np.testing.assert_allclose(F_g, F_g[0, 0] * np.eye(2), atol=1e-14)  # isotropic in-plane: frame-free
    with pytest.raises(ConfigError, match="orthonormal"):
        Seed2D(ParameterSet(Seed2D.parameters), directions=[[1.0, 0.0], [1.0, 1.0]])
    with pytest.raises(ConfigError, match="2 vectors of 2 numbers"):  # seed2d is a 2D law, whatever was given
        Seed2D(ParameterSet(Seed2D.parameters), directions=[[1.0, 0.0, 0.0]])
    with pytest.raises(ConfigError, match="2 vectors of 2 numbers"):  # 3D directions on a 2D mesh
        Seed2D(ParameterSet(Seed2D.parameters), directions=np.eye(3).tolist()).frame(2)


@pytest.mark.parametrize("directions", [[], "x", [1.0, 0.0, 0.0], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]],
                         ids=["none", "a-word", "one-flat-vector", "two-3d-vectors"])
def test_directions_without_a_dimension_are_checked_against_the_mesh(directions):
    """A law written for 2D and 3D cannot tell from these which the frame is for: the mesh's dimension says it."""
    import growth_test_laws

    with growth_test_laws.registered(), pytest.raises(ConfigError) as failure:
        Model(physics=["poroelastic_growth"], growth_law={"name": "test_uniform", "directions": directions},
              mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1, t_final=0.2, output={"pictures": False})
    assert "growth_law.directions must be 2 vectors of 2 numbers" in str(failure.value), failure.value
    assert "in 2D" in str(failure.value) and "\n" not in str(failure.value)


def _rate(seed, dimension, m, m_dot, t):
    """ell / ell_0 from fluid_source, with m a UFL variable so its rate enters through d gamma / d m."""
    m_symbol = ufl.variable(ufl.as_ufl(m))
    return value(fluid_source(seed, 1.0, {"m": m_symbol}, {"m": m_dot}, ufl.as_ufl(t), None, dimension))


def test_the_fluid_source_of_the_3d_law_is_eq_4_15_without_the_second_delta_3():
    d1, d2, d3, m, m_dot, t = 1 / 52, 0.02, 1 / 104, 0.8, 0.3, 5.0
    seed = law(Seed3D, delta_1=d1, delta_2=d2, delta_3=d3)
    dgamma3_dm = d3 * (1 - m**2) / (1 + m**2) ** 2  # d_m(gamma_3): it carries delta_3 already
    assert _rate(seed, 3, m, m_dot, t) == pytest.approx(2 * d1 + d2 + dgamma3_dm * m_dot, rel=1e-14)
    literal = 2 * d1 + d2 + d3 * dgamma3_dm * m_dot  # (4.15) as printed: delta_3 twice
    assert _rate(seed, 3, m, m_dot, t) != pytest.approx(literal, rel=1e-6)


def test_the_fluid_source_of_the_2d_law_counts_both_factors():
    d2, d3, m, m_dot = 0.15, 0.045, 0.75, -0.2
    seed = law(Seed2D, delta_2=d2, delta_3=d3)
    expected = 2 * (d2 + d3 * (1 - m**2) / (1 + m**2) ** 2 * m_dot)
    assert _rate(seed, 2, m, m_dot, 3.0) == pytest.approx(expected, rel=1e-14)


def test_roots_of_non_positive_factors_are_never_nan_and_have_finite_slopes():
    gammas = np.array([-1.0, -1e-6, 0.0, 1e-14, 1e-6, 0.5, 78.0])
    roots = positive_sqrt(gammas, np)
    assert np.all(np.isfinite(roots)) and np.all(roots >= 0)
    np.testing.assert_allclose(roots[-3:], np.sqrt(gammas[-3:]), rtol=1e-12)
    assert roots[0] < 1e-11 and roots[2] < 1e-5
    variable = ufl.variable(ufl.as_ufl(0.0))
    slope = value(ufl.diff(positive_sqrt(variable), variable))
    assert np.isfinite(slope)
    assert not np.isnan(value(positive_sqrt(ufl.as_ufl(-3.0))))


def test_a_law_refuses_a_mesh_of_the_wrong_dimension():
    # refused when the model is composed (so --dry-run refuses it too), not only at the run's set-up
    with pytest.raises(ConfigError, match="seed3d is written for 3D, the mesh is 2D"):
        Model(physics=["chemotaxis", "poroelastic_growth"], growth_law="seed3d",
              mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1, t_final=0.2, output={"pictures": False})


@pytest.mark.parametrize("mesh", [{"type": "box", "upper": [2.0, 2.0, 1.0], "cells": [2, 2, 1]},
                                  box((0, 0, 0), (2, 2, 1), (2, 2, 1))], ids=["table", "MeshData"])
def test_a_2d_law_on_a_3d_mesh_is_refused_for_its_dimension_before_the_3d_laws_parameters(mesh):
    """Example 4 with its law switched to seed2d was told to remove delta_1 (seed3d's), and once that was done,
    that seed2d is written for 2D: the dimension is the mistake, and is said first."""
    with pytest.raises(ConfigError, match="seed2d is written for 2D, the mesh is 3D"):
        Model(physics=["chemotaxis", "poroelastic_growth"], growth_law="seed2d", parameters={"delta_1": 0.02},
              mesh=mesh, dt=0.1, t_final=0.2, output={"pictures": False})


GROWTH_MODEL = dict(physics=["poroelastic_growth"], mesh=box((0, 0, 0), (1, 1, 1), (1, 1, 1)), dt=0.1, t_final=0.2)


@pytest.mark.parametrize("growth_law, error, message", [
    (None, ConfigError, "needs a growth law: add [growth_law] name"),
    ("seed4d", PluginError, "unknown growth law 'seed4d' (registered: "),  # installed plugins add theirs
    ({"name": "seed2d", "rate": 2.0}, ConfigError, "growth law seed2d: unknown option 'rate'"),
    ({"directions": [[1, 0], [0, 1]]}, ConfigError, "[growth_law] must be a table with a name"),
    ({"name": 5}, ConfigError, "growth_law.name must be the name of a growth law, got 5"),  # was "a table with a name"
])
def test_a_bad_growth_law_table_is_one_line(growth_law, error, message):
    with pytest.raises(error) as failure:
        Model(**GROWTH_MODEL, growth_law=growth_law)
    assert message in str(failure.value) and "\n" not in str(failure.value)


def test_a_growth_law_without_a_growing_physics_is_refused():
    with pytest.raises(ConfigError, match="no physics module of this model grows"):
        Model(physics=["chemotaxis"], growth_law="seed2d", mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1,
              t_final=0.2)


def test_active_stress_refuses_to_join_finite_strain_growth():
    with pytest.raises(ConfigError) as failure:
        Model(physics=["chemotaxis", "poroelastic_growth", "active_stress", "mechanochemical"], growth_law="seed2d",
              mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1, t_final=0.2)
    message = str(failure.value)
    assert "active_stress" in message and "poroelastic_growth" in message and "(2.5)" in message
    assert "\n" not in message


def test_the_growth_law_parameters_join_the_models_parameters():
    held = {"poroelastic_growth": {"boundary": [{"boundary": "left", "type": "clamped"}]}}
    model = Model(physics=["chemotaxis", "poroelastic_growth"], growth_law="seed2d",
                  parameters={"delta_2": 0.2, "ell_0": 0.0}, mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1,
                  t_final=0.2, physics_options=held)
    assert model.parameters["delta_2"] == 0.2 and model.parameters["delta_3"] == 0.045
    assert model.resolved_config()["growth_law"] == {"name": "seed2d"}
    with pytest.raises(ConfigError, match="parameter delta_3 must be >= 0"):
        Model(physics=["chemotaxis", "poroelastic_growth"], growth_law="seed2d", parameters={"delta_3": -1.0},
              mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1, t_final=0.2)


def test_a_plugin_written_for_contract_1_1_still_reads_its_options_as_opts(capsys):
    """Contract 1.2 renamed ``self.opts`` to ``self.settings``; the old name reads the same dict, with a warning."""
    from primordia.core.hookspecs import CONTRACT_VERSION
    from primordia.physics.growth_laws import Seed2D

    law = Seed2D({}, directions=[[0.0, 1.0], [-1.0, 0.0]])
    assert CONTRACT_VERSION[0] == 1 and CONTRACT_VERSION >= (1, 2)
    assert law.opts is law.settings and law.opts["directions"] == [[0.0, 1.0], [-1.0, 0.0]]
    assert capsys.readouterr().err.count("renamed self.settings") == 1


def test_a_negative_in_plane_growth_rate_of_the_3d_law_is_one_line():
    """gamma_1 = delta_1 t is the square of a stretch: delta_1 < 0 took the root of a negative number (NaN)."""
    with pytest.raises(ConfigError, match="parameter delta_1 must be >= 0"):
        Model.from_file(Path(__file__).resolve().parents[2] / "examples" / "ex04_small.toml", ["parameters.delta_1=-0.1"])


class _Broken(Seed2D):
    """A third party's law overriding the methods docs/plugins.md says a law may override, wrongly."""

    name = "broken_frame"
    answer = None

    def directions_at(self, X, dimension):
        return self.answer(X, dimension) if callable(self.answer) else super().directions_at(X, dimension)


class _BrokenStretches(Seed2D):
    name = "broken_stretches"

    def stretches(self, gammas):
        return [positive_sqrt(gammas[0])]  # forgot the second direction


@pytest.mark.parametrize("cls, answer, message", [
    (_Broken, lambda X, d: [][d], "growth law broken_frame: directions_at failed: IndexError: list index out of "
                                  "range (at "),
    (_Broken, lambda X, d: None, "growth law broken_frame: directions_at must return 2 vectors of 2 components in "
                                 "2D (one per direction k_i), got None"),
    (_Broken, lambda X, d: [ufl.as_vector([1.0, 0.0]), 1.0], "growth law broken_frame: directions_at must return "
                                                            "vectors of 2 components, got 1.0 for k_2"),
    (_BrokenStretches, None, "growth law broken_stretches: stretches must return 2 scalars in 2D (one per "
                             "direction k_i), got ["),
])
def test_a_bug_in_an_overridden_frame_or_stretch_is_one_line_naming_the_law(cls, answer, message):
    """directions_at and stretches were called bare: a law's bug there was a traceback, and a list one direction
    short was zipped away, a growth tensor without that direction's growth."""
    broken = law(cls)
    broken.answer = answer
    with pytest.raises(PluginError) as failure:
        broken.growth_tensor({"m": 0.75}, 1.0, None, 2)
    assert str(failure.value).startswith(message)
