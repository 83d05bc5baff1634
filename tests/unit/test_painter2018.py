"""Painter et al. (2018) kinetics (primordia.physics.kinetics.painter2018) against seed eqs. (2.3)-(2.6).

The reference formulas below are written from the seed, independently of the
module under test.
"""

from __future__ import annotations

import numpy as np
import pytest

from primordia.core.errors import ConfigError, PluginError
from primordia.core.ops import NUMPY
from primordia.physics.kinetics.base import Species
from primordia.physics.kinetics.painter2018 import Painter2018, hill
from primordia.physics.seed_parameters import seed_parameters


def kinetics(priming_wave: bool = True, **overrides) -> Painter2018:
    return Painter2018(seed_parameters(**overrides), priming_wave=priming_wave)


def seed_reactions(p, m, e, f, b, w):
    """Seed eqs. (2.3b)-(2.3d) reaction terms, with h_i of eq. (2.4)."""
    h = {i: m ** p[f"P_{i}"] / (p[f"K_{i}"] ** p[f"P_{i}"] + m ** p[f"P_{i}"]) for i in (1, 2, 3)}
    return {
        "m": 0.0 * m,
        "e": (p["kappa_1"] * w * h[1] + p["kappa_2"] * h[2]) * (1 - e) - (1 - h[1]) * (p["kappa_3"] + p["kappa_4"] * b) * e,
        "f": p["kappa_F"] * e - p["delta_F"] * f,
        "b": p["kappa_B"] * h[3] * m - p["delta_B"] * b,
    }


def seed_wave(p, x2, t):
    """Seed eq. (2.4): w = omega_1/2 [1 + tanh(omega_2 (t - x_2/omega_3))]."""
    return 0.5 * p["omega_1"] * (1 + np.tanh(p["omega_2"] * (t - x2 / p["omega_3"])))


# -- Hill functions (seed eq. (2.4)) ---------------------------------------------------------


def test_hill_function_values():
    m = np.linspace(0.0, 50.0, 2001)
    for threshold, exponent in [(1.0, 2.0), (2.0, 2.0), (5.0, 3.0), (0.5, 1.0)]:
        h = hill(m, threshold, exponent)
        assert h[0] == 0.0
        assert hill(threshold, threshold, exponent) == pytest.approx(0.5, abs=1e-15)
        assert hill(2 * threshold, threshold, exponent) == pytest.approx(2**exponent / (1 + 2**exponent), rel=1e-14)
        assert np.all(np.diff(h) > 0) and np.all((0 <= h) & (h < 1))
        np.testing.assert_allclose(1 - h[-1], threshold**exponent / (threshold**exponent + 50.0**exponent),
                                   rtol=1e-9)


def test_h_i_read_their_own_threshold_and_exponent():
    k = kinetics()
    for i, (threshold, exponent) in {1: (1.0, 2.0), 2: (2.0, 2.0), 3: (5.0, 2.0)}.items():
        assert k.h(i, threshold) == pytest.approx(0.5)
        assert k.h(i, 3.0) == pytest.approx(3.0**exponent / (threshold**exponent + 3.0**exponent))
    assert kinetics(K_3=4.0, P_3=3.0).h(3, 2.0) == pytest.approx(8.0 / (64.0 + 8.0))


# -- the priming wave ------------------------------------------------------------------------------


def test_priming_wave_is_seed_eq_2_4():
    k, p = kinetics(), seed_parameters()
    x2 = np.linspace(0.0, 20.0, 41)
    for t in (0.0, 100.0, 250.0, 520.0):
        x = (np.zeros_like(x2), x2)
        np.testing.assert_allclose(k.priming_wave(t, NUMPY.at(x)), seed_wave(p, x2, t), rtol=1e-14, atol=0)
    # half height on the front x_2 = omega_3 t, saturated behind it, absent ahead of it
    front = NUMPY.at((np.zeros(3), np.array([4.0 - 1.0, 4.0, 4.0 + 1.0])))
    behind, on, ahead = k.priming_wave(100.0, front)
    assert on == pytest.approx(0.5) and behind == pytest.approx(1.0) and ahead < 1e-12


def test_priming_wave_off_is_omega_1_everywhere():
    k = kinetics(priming_wave=False, omega_1=0.7)
    assert k.priming_wave(0.0, NUMPY.at((np.zeros(2), np.array([0.0, 20.0])))) == 0.7


def test_unknown_kinetics_option_is_rejected():
    with pytest.raises(ConfigError, match="kinetics painter2018: unknown option 'wave'"):
        Painter2018(seed_parameters(), wave=False)


# -- reactions (seed eqs. (2.3b)-(2.3d)) ---------------------------------------------------------


@pytest.mark.parametrize("priming_wave", [True, False])
def test_rates_are_the_seed_reactions(priming_wave):
    rng = np.random.default_rng(7)
    n = 200
    state = {"m": rng.uniform(0, 6, n), "e": rng.uniform(0, 1, n), "f": rng.uniform(0, 2, n),
             "b": rng.uniform(0, 3, n)}
    x = (rng.uniform(0, 20, n), rng.uniform(0, 20, n))
    t = 180.0
    overrides = {"kappa_F": 1.3, "kappa_B": 0.7, "delta_B": 1.9, "delta_F": 0.8}  # beyond the seed's scaling
    k, p = kinetics(priming_wave, **overrides), seed_parameters(**overrides)
    w = seed_wave(p, x[1], t) if priming_wave else p["omega_1"]
    expected = seed_reactions(p, w=w, **state)
    rates = k.rates(state, t, NUMPY.at(x))
    for species in ("m", "e", "f", "b"):
        np.testing.assert_allclose(rates[species], expected[species], rtol=1e-12, atol=1e-14, err_msg=species)


def test_split_rates_are_production_minus_loss_with_both_non_negative():
    """The IMEX contract of primordia.physics.kinetics.base: R = P - L c, P >= 0, L >= 0."""
    rng = np.random.default_rng(11)
    n = 500
    state = {"m": rng.uniform(0, 10, n), "e": rng.uniform(0, 1, n), "f": rng.uniform(0, 5, n),
             "b": rng.uniform(0, 5, n)}
    x = (rng.uniform(0, 20, n), rng.uniform(0, 20, n))
    split = kinetics().split_rates(state, 150.0, NUMPY.at(x))
    for species, (production, loss) in split.items():
        assert np.all(np.asarray(production) >= 0) and np.all(np.asarray(loss) >= 0), species
    assert split["m"] == (0.0, 0.0)  # seed eq. (2.3a): cells only move


# -- the rest state (seed eq. (2.6)) --------------------------------------------------------------


@pytest.mark.parametrize("m0", [0.75, 1.0, 2.0, 5.0])
def test_initial_state_is_seed_eq_2_6(m0):
    p = seed_parameters(m0=m0)
    k = kinetics(priming_wave=False, m0=m0)
    state = k.initial_state(0.0, NUMPY)
    h1, h2, h3 = (k.h(i, m0) for i in (1, 2, 3))
    b0 = h3 * m0  # seed (2.6), kappa_B = delta_B = 1
    k_on = p["kappa_1"] * p["omega_1"] * h1 + p["kappa_2"] * h2
    e0 = k_on / (k_on + (1 - h1) * (p["kappa_3"] + p["kappa_4"] * b0))
    assert state["m"] == m0
    assert state["b"] == pytest.approx(b0, rel=1e-14)
    assert state["e"] == pytest.approx(e0, rel=1e-14)
    assert state["f"] == pytest.approx(e0 / p["delta_F"], rel=1e-14)


@pytest.mark.parametrize("m0", [0.75, 2.0, 5.0])
def test_reactions_vanish_at_the_rest_state_with_w_omega_1(m0):
    for overrides in ({}, {"kappa_F": 1.3, "kappa_B": 0.7, "delta_B": 1.9, "delta_F": 0.8}):
        k = kinetics(priming_wave=False, m0=m0, **overrides)
        state = k.initial_state(0.0, NUMPY)
        rates = k.rates(state, 0.0, NUMPY)
        for species, rate in rates.items():
            assert abs(rate) < 1e-15, (species, rate, overrides)
        assert 0 < state["e"] < 1 and state["f"] > 0 and state["b"] > 0


def test_rest_state_with_the_wave_is_at_rest_at_t0_pointwise():
    """With the wave on, (2.6) evaluates w at (x, t0): every point starts at rest."""
    k = kinetics(priming_wave=True, m0=0.75)
    x = (np.zeros(5), np.array([0.0, 0.01, 0.02, 1.0, 20.0]))
    ops = NUMPY.at(x)
    state = {name: np.broadcast_to(value, 5) for name, value in k.initial_state(0.0, ops).items()}
    for species, rate in k.rates(state, 0.0, ops).items():
        np.testing.assert_allclose(rate, 0.0, atol=1e-15, err_msg=species)
    # and the wave then raises e where it arrives (x_2 = 0 first)
    later = k.rates(state, 2.0, ops)["e"]
    assert later[0] > 1e-3 and abs(later[-1]) < 1e-15


def test_homogeneous_form_is_the_kinetics_behind_the_wave():
    """The analysis linearises the saturated wave, w = omega_1 (seed section 3); without a wave, itself."""
    with_wave = kinetics(priming_wave=True, omega_1=0.8)
    behind = with_wave.homogeneous()
    assert behind.settings["priming_wave"] is False and type(behind) is Painter2018
    assert behind.priming_wave(0.0, NUMPY) == 0.8
    assert with_wave.settings["priming_wave"] is True  # the run's kinetics is untouched
    still = kinetics(priming_wave=False)
    assert still.homogeneous() is still


# -- the species it declares (read by the transport physics and the couplings) ---------------------


def test_species_are_the_seeds_m_e_f_b():
    k = kinetics()
    assert k.species_names == ("m", "e", "f", "b")
    by_name = {s.name: s for s in k.species}
    assert by_name["m"].diffusivity == "D_m" and by_name["m"].attractant == "f" and by_name["m"].perturbed
    assert by_name["e"].diffusivity is None and not by_name["e"].advected  # seed (2.3b): no transport
    assert [s.name for s in k.species if s.advected] == ["m", "f", "b"]  # seed (2.3a), (2.3c), (2.3d)
    assert [s.name for s in k.species if s.volume_sink] == ["f"]  # seed (2.3c): xi_f div u
    assert {p.name for p in Painter2018.parameters} >= {"m0", "D_m", "D_f", "D_b", "alpha", "gamma"}


def test_sensitivity_is_alpha_exp_minus_gamma_m():
    k = kinetics(alpha=3.0, gamma=0.7)
    m = np.linspace(0.0, 4.0, 9)
    np.testing.assert_allclose(k.sensitivity("m", m, NUMPY), 3.0 * np.exp(-0.7 * m), rtol=1e-15)


@pytest.mark.parametrize("species, message", [
    ((Species("m", "cells", diffusivity="D_x"),), "the diffusivity D_x of species m is not among its parameters"),
    ((Species("m", "cells", diffusivity="D_m", attractant="q"),), "climbs 'q', which is not another"),
    ((Species("m", "cells", attractant="m"),), "climbs 'm', which is not another"),
    ((Species("m", "cells"), Species("m", "again")), "declares a species twice"),
    ((), "declares no species"),
    ((Species("cell density", "cells"),), "a species is named 'cell density', not a name"),
    ((Species("m.1", "cells"),), "a species is named 'm.1', not a name"),
])
def test_an_inconsistent_species_declaration_is_refused(species, message):
    broken = type("Broken", (Painter2018,), {"name": "broken", "species": species})
    with pytest.raises(PluginError, match=message):
        broken(seed_parameters())
