"""Conditions (3.6)-(3.9), critical values, patterning spaces and the verdicts of seed sections 3.2-3.6.

What is asserted is what the theory guarantees:
* a_0 (d_0) < 0 at some k  =>  a real positive growth rate (P has positive leading coefficient), so the
  region from the conditions lies inside the region from the eigenvalues, cell by cell;
* Routh-Hurwitz (3.6) fails at k  <=>  P_2 has a root with Re >= 0 at k (exact, both directions);
* the seed's (3.7a)-(3.7c) are necessary, not sufficient: their region contains the exact one, strictly.
The converse of the first point (no other stationary instability) is not a theorem; for the seed's
three parameter planes it is checked to hold up to one grid cell along the boundary.
"""

import numpy as np
import pytest

from primordia.analysis.conditions import (
    coupled_conditions,
    critical_value,
    epithelium_verdict,
    homogeneous_verdict,
    quadratic_minimum,
    routh_hurwitz_quartic,
    uncoupled_conditions,
    uncoupled_verdict,
    zero_chemotaxis_verdict,
)
from primordia.analysis.dispersion import fastest_growing_mode, longitudinal_rates, max_growth_of_kind
from primordia.analysis.linearisation import linearise
from primordia.analysis.patterning import boundary_agreement, patterning_space
from primordia.analysis.polynomials import a0_quadratic, chemotaxis_coefficients, d0_quadratic
from primordia.physics.seed_parameters import seed_parameters

SEED_PLANES = [
    ("m0:0.05:6:25", "alpha:0:12:25", False, {}),
    ("kappa_1:0.0005:0.1:25", "kappa_4:0.01:100:25", False, {}),
    ("m0:0.05:6:25", "alpha:0:12:25", True, {}),
    ("kappa_1:0.001:0.3:25", "kappa_4:0.01:20:25", True, {"tau": 5.0}),
    ("tau:-200:200:25", "xi_f:-1:1:25", True, {}),
]


@pytest.mark.parametrize("x, y, coupled, overrides", SEED_PLANES)
def test_patterning_space_from_conditions_matches_the_eigenvalues(x, y, coupled, overrides):
    ds = patterning_space(x, y, params=seed_parameters(**overrides), coupled=coupled, nk=24)
    predicted = ds["unstable_conditions"].values.astype(bool)
    numerical = ds["unstable_numerical"].values.astype(bool)
    assert 0 < predicted.mean() < 1, "the window must contain a boundary for the test to mean something"
    assert np.all(numerical[predicted]), "a_0/d_0 < 0 somewhere must give a real positive growth rate"
    assert boundary_agreement(ds)["off_boundary"] == 0


def test_seed_conditions_are_necessary_not_sufficient():
    """((3.7a) or (3.7b)) and (3.7c) contains {a_0 < 0 somewhere}; between X^2 = 3 alpha Y and 4 alpha Y it is wrong."""
    ds = patterning_space("m0:0.05:6:41", "alpha:0:12:41", coupled=False, nk=24)
    exact = ds["unstable_conditions"].values.astype(bool)
    seed = ds["seed_conditions"].values.astype(bool)
    assert np.all(seed[exact]) and seed.sum() > exact.sum()
    # a parameter set inside the seed's region but stable: bisect m0 onto the band 3 alpha Y < X^2 < 4 alpha Y
    m0 = None
    for candidate in np.linspace(4.70, 4.95, 251):
        alpha, X, Y = a0_quadratic(linearise(seed_parameters(m0=candidate)))
        if X < 0 < Y and 3 * alpha * Y < X**2 < 4 * alpha * Y:
            m0 = candidate
            break
    assert m0 is not None
    params = seed_parameters(m0=m0, xi_f=0.0)
    found = uncoupled_conditions(params)
    assert bool(found.seed_region) and not bool(found.region)
    assert not fastest_growing_mode(params, coupled=False).unstable


def test_routh_hurwitz_3_3_fails_exactly_where_P2_has_an_unstable_root():
    params = seed_parameters(xi_f=0.0, m0=3.0)
    c = linearise(params)
    k = np.logspace(-2, 1.3, 120)
    routh = routh_hurwitz_quartic(chemotaxis_coefficients(c, k))
    growth = max_growth_of_kind(longitudinal_rates(c, k, coupled=False))
    assert not np.all(routh["holds"]) and np.any(routh["holds"])
    assert np.array_equal(~routh["holds"], growth > 0)


@pytest.mark.parametrize("name, coupled", [("m0", False), ("kappa_4", False), ("m0", True), ("tau", True),
                                           ("xi_f", True)])
def test_critical_value_is_where_the_eigenvalues_change_sign(name, coupled):
    params = seed_parameters()
    critical = critical_value(params, name, coupled=coupled)
    assert critical is not None
    quadratic = d0_quadratic if coupled else a0_quadratic
    at = params.replace(**{name: critical.value})
    minimum, vertex = quadratic_minimum(*quadratic(linearise(at)))
    alpha, X, Y = quadratic(linearise(at))
    assert abs(minimum) <= 1e-9 * (abs(X) * vertex + abs(Y))  # a_0 (d_0) touches zero ...
    assert critical.k_c == pytest.approx(np.sqrt(vertex))  # ... at k_c, where its derivative vanishes
    growth = []
    for factor in (1 - 1e-3, 1 + 1e-3):
        trial = seed_parameters(**(dict(params) | {name: critical.value * factor}))
        k = np.array([critical.k_c])
        growth.append(max_growth_of_kind(longitudinal_rates(linearise(trial), k, coupled=coupled), "stationary")[0])
    assert growth[0] * growth[1] < 0  # the growth rate at k_c changes sign across the critical value


def test_coupled_conditions_seed_theta_degenerate_once_corrected():
    params = seed_parameters(m0=0.9)
    corrected = coupled_conditions(params, "corrected")
    printed = coupled_conditions(params, "seed")
    for name in ("3.8a:theta_1", "3.8c", "3.9"):
        assert corrected.values[name] == 0.0 and printed.values[name] != 0.0
    # with theta_1 = 0 the d_0 criterion is the uncoupled one on (X_c, Y_c): the corrected (3.8a)-(3.8c) curves are its
    alpha, Xc, Yc = d0_quadratic(linearise(params))
    assert corrected.values["3.8a:theta_3"] == pytest.approx(4 * linearise(params).p_wave_modulus * Xc)
    assert corrected.values["3.8a:theta_2"] == pytest.approx(3 * linearise(params).p_wave_modulus * Yc)


def test_verdicts_of_the_special_cases():
    params = seed_parameters()
    assert not homogeneous_verdict(params).patterns
    chemotaxis = zero_chemotaxis_verdict(params)
    assert not chemotaxis.patterns and chemotaxis.details["chemical_rates_real_negative"]
    uncoupled = uncoupled_verdict(params)
    assert uncoupled.patterns and uncoupled.details["fastest_mode"].k_max == pytest.approx(4.494, rel=1e-3)


@pytest.mark.parametrize("case", ["no_activation", "no_inactivation", "neither"])
def test_epithelium_cases_pattern_exactly_above_the_sharp_threshold(case):
    """Seed section 3.5: the seed's sign condition xi_f s > 0 is necessary; xi_f s E > (2mu+lambda) D_m delta_F decides."""
    base = seed_parameters(tau=-60.0)  # s > 0 at m0 = 2: the seed's condition holds
    c = linearise(base)
    threshold_xi = c.p_wave_modulus * c.D_m * c.delta_F / (c.active_stress_slope * c.chemotactic_coefficient)
    below = epithelium_verdict(base.replace(xi_f=0.8 * threshold_xi), case)
    above = epithelium_verdict(base.replace(xi_f=1.25 * threshold_xi), case)
    assert below.details["seed_condition"] and above.details["seed_condition"]
    assert not below.patterns and not below.details["sharp_condition"]
    assert above.patterns and above.details["sharp_condition"]
    wrong_sign = epithelium_verdict(seed_parameters(), case)  # tau = 60: s < 0, no patterns
    assert not wrong_sign.details["seed_condition"] and not wrong_sign.patterns
