"""Parameter declarations and validated parameter sets (primordia.core.parameters, seed_parameters)."""

from __future__ import annotations

import math

import pytest

from primordia.core.errors import ConfigError
from primordia.core.parameters import Parameter, ParameterSet
from primordia.physics.seed_parameters import lame, seed_parameters

DECLARED = (
    Parameter("D_m", 0.01, "cell diffusivity"),
    Parameter("D_f", 0.1, "FGF diffusivity"),
    Parameter("alpha", 4.0, "chemotactic sensitivity", constraint="nonnegative"),
    Parameter("tau", 60.0, "active stress", constraint="any"),
    Parameter("nu", 0.4, "Poisson ratio", constraint="poisson"),
)


def test_defaults_and_overrides():
    params = ParameterSet(DECLARED, {"D_m": 0.03, "alpha": 0})
    assert params["D_m"] == 0.03 and params.D_m == 0.03
    assert params["D_f"] == 0.1
    assert params["alpha"] == 0.0 and isinstance(params["alpha"], float)
    assert set(params) == {"D_m", "D_f", "alpha", "tau", "nu"} and len(params) == 5


def test_a_parameter_set_is_read_only_by_attribute_too():
    """params.D_m = 0.05 was taken: params.D_m read 0.05 back while params["D_m"], and a model's run, its
    config.toml and its linear analysis, kept 0.03 (a notebook's "change a parameter, run again" did nothing)."""
    params = ParameterSet(DECLARED, {"D_m": 0.03})
    with pytest.raises(AttributeError, match=r"^parameters are read-only: to change D_m, build a new Model with "
                                             r"parameters=model\.parameters\.replace\(D_m=\.\.\.\)$"):
        params.D_m = 0.05
    with pytest.raises(AttributeError, match="parameters are read-only"):
        params.unknown = 1.0
    assert params.D_m == params["D_m"] == 0.03
    assert params.replace(D_m=0.05).D_m == 0.05  # the way to another value


@pytest.mark.parametrize("name, value, phrase", [
    ("D_m", 0.0, "must be > 0"),
    ("D_m", -1.0, "must be > 0"),
    ("alpha", -1e-9, "must be >= 0"),
    ("nu", 0.5, "must lie in (-1, 0.5)"),
    ("nu", -1.0, "must lie in (-1, 0.5)"),
])
def test_wrong_sign_is_one_line_naming_the_parameter(name, value, phrase):
    with pytest.raises(ConfigError) as error:
        ParameterSet(DECLARED, {name: value})
    message = str(error.value)
    assert message.startswith(f"parameter {name} {phrase}") and "\n" not in message
    assert f"got {value:g}" in message


@pytest.mark.parametrize("value", [0.0, -1e6, 1e6])
def test_any_sign_accepts_everything_finite(value):
    assert ParameterSet(DECLARED, {"tau": value})["tau"] == value


@pytest.mark.parametrize("value", [True, "0.1", None, [0.1]])
def test_non_numbers_are_rejected(value):
    with pytest.raises(ConfigError, match="parameter D_f must be a number"):
        ParameterSet(DECLARED, {"D_f": value})


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
def test_non_finite_values_are_rejected(value):
    with pytest.raises(ConfigError, match="parameter tau must be a number, got -?(inf|nan)"):
        ParameterSet(DECLARED, {"tau": value})


def test_unknown_name_suggests_close_ones():
    with pytest.raises(ConfigError, match=r"^unknown parameter 'D_n' \(did you mean .*D_m.*\?\)$"):
        ParameterSet(DECLARED, {"D_n": 0.1})
    with pytest.raises(ConfigError) as error:
        ParameterSet(DECLARED, {"zzz": 1.0})
    assert str(error.value) == "unknown parameter 'zzz'"
    with pytest.raises(ConfigError, match="unknown parameter 'alpah'.*alpha"):
        ParameterSet(DECLARED)["alpah"]
    with pytest.raises(AttributeError):
        ParameterSet(DECLARED).alpah


def test_replace_validates_and_leaves_the_original():
    params = ParameterSet(DECLARED)
    changed = params.replace(D_m=0.5)
    assert changed["D_m"] == 0.5 and params["D_m"] == 0.01
    with pytest.raises(ConfigError, match="parameter D_m must be > 0"):
        params.replace(D_m=-0.5)


def test_sets_are_read_only():
    params = ParameterSet(DECLARED)
    with pytest.raises(TypeError):
        params["D_m"] = 1.0  # type: ignore[index]


def test_declarations_must_agree():
    same = ParameterSet(DECLARED + (Parameter("D_m", 0.01, "again"),))
    assert same["D_m"] == 0.01
    with pytest.raises(ValueError, match="D_m declared twice with different defaults"):
        ParameterSet(DECLARED + (Parameter("D_m", 0.02, "conflicting"),))
    with pytest.raises(ValueError, match="unknown constraint"):
        Parameter("x", 1.0, "x", constraint="odd")


def test_seed_defaults_are_table_3_1():
    """Seed Table 3.1 (tab:LAparams), value by value, plus the scaling constants fixed to 1."""
    table_3_1 = {
        "m0": 2.0, "D_m": 0.01, "D_f": 0.1, "alpha": 4.0, "kappa_1": 0.05, "kappa_2": 0.025, "kappa_3": 1.0,
        "kappa_4": 1.0, "K_1": 1.0, "K_2": 2.0, "K_3": 5.0, "P_1": 2.0, "P_2": 2.0, "P_3": 2.0, "delta_F": 1.0,
        "omega_1": 1.0, "omega_2": 5.0, "omega_3": 0.04, "E": 3e4, "nu": 0.4, "C_0": 1e-3, "kappa": 1e-4,
        "alpha_BW": 0.1, "tau": 60.0, "eta": 0.1, "xi_f": 0.15, "rho": 1.0, "zeta": 1.0,
    }
    scaling = {"gamma": 1.0, "D_b": 1.0, "kappa_F": 1.0, "kappa_B": 1.0, "delta_B": 1.0}
    params = seed_parameters()
    for name, value in {**table_3_1, **scaling}.items():
        assert params[name] == value, name
    assert set(params) == set(table_3_1) | set(scaling)


def test_seed_parameters_validate_overrides():
    assert seed_parameters(m0=0.75)["m0"] == 0.75
    with pytest.raises(ConfigError, match="parameter nu must lie in"):
        seed_parameters(nu=0.5)
    with pytest.raises(ConfigError, match="did you mean kappa_1"):
        seed_parameters(kapa_1=1.0)


def test_lame_constants():
    mu, lam = lame(seed_parameters())
    E, nu = 3e4, 0.4
    assert mu == pytest.approx(E / (2 * (1 + nu)))
    assert lam == pytest.approx(E * nu / ((1 + nu) * (1 - 2 * nu)))
    # back to Young's modulus: E = mu (3 lambda + 2 mu) / (lambda + mu)
    assert mu * (3 * lam + 2 * mu) / (lam + mu) == pytest.approx(E)
