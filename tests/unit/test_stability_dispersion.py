"""Growth rates from the linearised eigenproblem: roots of det M, special cases of seed sections 3.2-3.4."""

import numpy as np
import pytest

from primordia.analysis.composed import linearise_seed
from primordia.analysis.dispersion import (
    fastest_growing_mode,
    growth_rates,
    longitudinal_rates,
    max_growth_of_kind,
)
from primordia.analysis.linearisation import dispersion_matrix, linearise, matrix_pencil, wave_vectors
from primordia.analysis.polynomials import dispersion_coefficients
from primordia.core.ops import NUMPY
from primordia.physics.kinetics.painter2018 import Painter2018
from primordia.physics.seed_parameters import seed_parameters

from stability_support import random_parameters

try:
    import mpmath
except ImportError:  # pragma: no cover - mpmath comes with sympy; without it the check is in double precision
    mpmath = None


def reference_roots(c, k):
    """40-digit roots of the closed-form P_1 + P_2 P_3 (an independent check, not the method)."""
    coefficients = dispersion_coefficients(c, k)
    coefficients = coefficients[: np.flatnonzero(coefficients)[-1] + 1]
    if mpmath is None:
        return np.roots(coefficients[::-1])
    with mpmath.workdps(40):
        roots = mpmath.polyroots([mpmath.mpf(float(x)) for x in coefficients[::-1]], maxsteps=800, extraprec=400)
    return np.array([complex(r) for r in roots])


def assert_same_roots(computed, expected, rtol):
    computed = computed[np.isfinite(computed)]
    assert computed.size == expected.size
    for root in expected:  # every expected root has a computed partner, and vice versa (sizes equal)
        assert np.min(np.abs(computed - root)) <= rtol * max(1.0, abs(root))


@pytest.mark.parametrize("method", ["qz", "standard"])
def test_rates_are_the_roots_of_the_closed_form(method):
    c = linearise(seed_parameters(delta_F=1.5))  # delta_F != delta_B avoids a near-double root
    k = np.array([1e-3, 0.05, 0.7, 4.0, 60.0])
    rates = longitudinal_rates(c, k, method=method)
    for i, kk in enumerate(k):
        assert_same_roots(rates[i], reference_roots(c, kk), rtol=1e-9)


@pytest.mark.parametrize("d", [2, 3])
def test_every_root_makes_M_singular_and_transverse_roots_are_shear_waves(d):
    c = linearise(random_parameters(np.random.default_rng(d)))
    k = np.array([0.3, 1.0, 3.0])
    result = growth_rates(c, k, d=d)
    assert result.rates.shape == (3, 7) and result.transverse.shape == (3, 2 * (d - 1))
    speed = np.sqrt(c.mu / c.rho)
    for i, kk in enumerate(k):
        expected = np.array([1j, -1j] * (d - 1)) * kk * speed
        assert np.sort_complex(result.transverse[i]) == pytest.approx(np.sort_complex(expected), rel=1e-8)
        for phi in result.all_roots[i]:  # smallest singular value of M(phi) relative to its size
            M = dispersion_matrix(c, phi, wave_vectors(kk, d))
            singular = np.linalg.svd(M, compute_uv=False)
            assert singular[-1] <= 1e-9 * singular[0]
        assert_same_roots(result.rates[i], reference_roots(c, kk), rtol=1e-8)


def test_full_matrix_and_longitudinal_block_agree():
    c = linearise(seed_parameters(m0=0.75))
    k = np.logspace(-2, 1.5, 15)
    full = growth_rates(c, k, d=3).rates
    block = longitudinal_rates(c, k, method="standard")
    assert full == pytest.approx(block, rel=1e-7, abs=1e-10)


def test_quasi_static_and_incompressible_limits_drop_roots():
    """rho = 0: no inertia, degree 5, no transverse roots; C_0 = 0: degree 6 (QZ drops infinite eigenvalues)."""
    for override, degree, transverse in (({"rho": 0.0}, 5, 0), ({"C_0": 0.0}, 6, 2)):
        c = linearise(seed_parameters(**override))
        result = growth_rates(c, np.array([0.5, 2.0]), d=2)
        assert np.sum(np.isfinite(result.rates[0])) == degree
        assert np.sum(np.isfinite(result.transverse[0])) == transverse
        assert_same_roots(result.rates[1], reference_roots(c, 2.0), rtol=1e-8)


def test_zero_chemotaxis_gives_real_negative_chemical_rates():
    """Seed section 3.3: alpha = 0 -> P_1 = 0 and P_2 = (phi + D_m K)(phi + A_e)(phi + D_f K + delta_F)(phi + D_b K + delta_B)."""
    params = dict(random_parameters(np.random.default_rng(3)))
    params["alpha"] = 0.0
    c = linearise(params)
    k = np.array([0.2, 1.0, 5.0])
    rates = growth_rates(c, k, d=2).rates
    for i, kk in enumerate(k):
        K = kk**2
        chemical = [-c.D_m * K, -c.A_e, -(c.D_f * K + c.delta_F), -(c.D_b * K + c.delta_B)]
        for value in chemical:
            assert np.min(np.abs(rates[i] - value)) <= 1e-9 * max(1, abs(value))
        assert np.all(rates[i].real < 0)  # the poroelastic roots are damped too (alpha_BW > 0)


@pytest.mark.parametrize("seed", range(20))
def test_homogeneous_perturbations_are_stable(seed):
    """Seed section 3.2: at k = 0, rates 0 (conserved modes) and -A_e, -delta_F, -delta_B, for any parameters."""
    c = linearise(random_parameters(np.random.default_rng(1000 + seed)))
    rates = growth_rates(c, np.array([0.0]), d=3).rates[0]
    assert np.all(rates.real <= 0)
    nonzero = np.sort(rates[np.abs(rates) > 1e-12].real)
    assert nonzero == pytest.approx(np.sort([-c.A_e, -c.delta_F, -c.delta_B]), rel=1e-10)


def test_uncoupled_rates_contain_the_chemotaxis_block():
    """tau = 0: det M = B^(d-1) P_2 P_3, so the rates of M_22 alone are among the rates of the full system."""
    c = linearise(random_parameters(np.random.default_rng(11), tau=0.0))
    k = np.array([0.3, 1.2, 4.0])
    rates = growth_rates(c, k, d=2).rates
    M0, _, _ = matrix_pencil(c, wave_vectors(k, 1))
    chemistry = np.linalg.eigvals(-M0[:, 2:, 2:])  # the (m, e, f, b) block: M_22 = phi I + M0_22
    for i in range(k.size):
        for value in chemistry[i]:
            assert np.min(np.abs(rates[i] - value)) <= 1e-9 * max(1.0, abs(value))
    coupled = growth_rates(linearise(random_parameters(np.random.default_rng(11), tau=40.0)), k, d=2).rates
    assert np.max([np.min(np.abs(coupled[1] - value)) for value in chemistry[1]]) > 1e-6


def test_linearised_kinetics_match_finite_differences_of_the_simulation_kinetics():
    """A_m, A_e, A_b, H_3 are the Jacobian of Painter2018.rates at its own steady state (w = omega_1)."""
    params = seed_parameters(kappa_F=1.3, kappa_B=0.7, delta_B=1.4, omega_1=0.8)
    c = linearise(params)
    kinetics = Painter2018(params, priming_wave=False)
    state = kinetics.initial_state(0.0, NUMPY)
    rates = kinetics.rates(state, 0.0, NUMPY)
    assert all(abs(value) < 1e-12 for value in rates.values())  # it is a steady state
    h = 1e-6

    def derivative(species, wrt):
        up, down = dict(state), dict(state)
        up[wrt] += h
        down[wrt] -= h
        return (kinetics.rates(up, 0.0, NUMPY)[species] - kinetics.rates(down, 0.0, NUMPY)[species]) / (2 * h)

    assert derivative("e", "m") == pytest.approx(c.A_m, rel=1e-7)
    assert derivative("e", "e") == pytest.approx(-c.A_e, rel=1e-7)
    assert derivative("e", "b") == pytest.approx(-c.A_b, rel=1e-7)
    assert derivative("b", "m") == pytest.approx(c.kappa_B * c.H_3, rel=1e-7)
    assert derivative("f", "e") == pytest.approx(c.kappa_F, rel=1e-7)


def test_fastest_growing_mode_is_the_maximum_of_the_dispersion_curve():
    params = seed_parameters(xi_f=0.0)  # uncoupled Table 3.1: Turing-unstable
    mode = fastest_growing_mode(params, kind="stationary")
    assert mode.unstable and mode.stationary and not mode.at_edge
    assert mode.wavelength == pytest.approx(2 * np.pi / mode.k_max)
    dense = np.linspace(0.5 * mode.k_max, 1.5 * mode.k_max, 2001)
    growth = max_growth_of_kind(longitudinal_rates(linearise(params), dense), "stationary")
    assert mode.growth_rate >= growth.max() - 1e-12
    assert mode.k_max == pytest.approx(dense[np.argmax(growth)], abs=2 * (dense[1] - dense[0]))
    assert mode.band[0] < mode.k_max < mode.band[1]


def test_the_unstable_band_ends_where_the_growth_rate_crosses_zero():
    """The band was the outermost unstable k of the log-spaced grid: [0.001, 11.9] for uncoupled
    Table 3.1, where Re phi changes sign at k = 12.40 (4% grid steps)."""
    params = seed_parameters(xi_f=0.0)
    mode = fastest_growing_mode(params, kind="stationary")
    c = linearise(params)
    below, above = max_growth_of_kind(longitudinal_rates(c, np.array([mode.band[1] * (1 - 1e-6),
                                                                         mode.band[1] * (1 + 1e-6)])), "stationary")
    assert below > 0 >= above
    assert mode.band[1] == pytest.approx(12.4046, abs=1e-3)  # a dense scan of the 4 x 4 chemistry alone


def test_table_3_1_coupled_has_only_a_weak_oscillatory_instability():
    """At Table 3.1 the active stress (s < 0 at m0 = 2) stabilises the Turing mode of the uncoupled system;
    what remains is a slow (Re phi ~ 6e-6) growth of long elastic waves, which is not a Turing pattern."""
    params = seed_parameters()
    turing = fastest_growing_mode(params, kind="stationary")
    anything = fastest_growing_mode(params)
    assert not turing.unstable
    assert anything.unstable and not anything.stationary
    assert 0 < anything.growth_rate < 1e-4 and anything.k_max < 0.1


@pytest.mark.parametrize("k, problem", [
    ([], "needs at least one wavenumber"),
    ([1.0, np.nan, 2.0], "finite numbers >= 0"),
    ([-1.0, 2.0, 3.0], "finite numbers >= 0"),
])
def test_a_wavenumber_list_without_a_usable_k_is_one_clear_error(k, problem):
    """Before: an empty list failed in argmax or reshape, a NaN in LAPACK ("Array must not contain infs
    or NaNs", or "the pencil is not real"), and a negative k gave the band (-1, 3)."""
    params = seed_parameters(m0=0.75, D_m=0.03)
    with pytest.raises(ValueError, match=problem):
        fastest_growing_mode(params, k=k, coupled=False)
    chemistry = linearise_seed(params, chemistry_only=True)
    with pytest.raises(ValueError, match=problem):
        chemistry.fastest_mode(k=k)
    if k:
        with pytest.raises(ValueError, match="finite numbers >= 0"):
            growth_rates(params, k)
        with pytest.raises(ValueError, match="finite numbers >= 0"):
            chemistry.growth_rates(k)


@pytest.mark.parametrize("onset, low", [(0.0, 0.0), (5e-4, 5e-4)], ids=["reaches k = 0", "starts below the grid"])
def test_a_band_below_the_grids_first_k_is_followed_down(onset, low):
    """The band's lower end was the grid's first k (ex01a printed "unstable band k in [0.001, 5.44]" for
    (0, 5.44]: its conserved m has the root 0 at k = 0, and growth ~ k^2 above it)."""
    from primordia.analysis.dispersion import fastest_mode_of

    def rates_at(k):  # one root, k (k - onset) (5 - k): zero at k = 0 and at the onset, negative between
        return (k * (k - onset) * (5.0 - k)).astype(complex)[:, None]

    mode = fastest_mode_of(rates_at, np.linspace(1e-3, 10.0, 1000))
    # rates within round-off of 0 count as 0 (dispersion.REAL_TOLERANCE): the onset to 1e-5 of itself
    assert mode.band[0] == pytest.approx(low, rel=1e-5, abs=1e-15) and mode.band[1] == pytest.approx(5.0, rel=1e-9)


def test_a_band_that_holds_k_0_itself_starts_at_0():
    """An oscillatory instability whose band holds k = 0 (the homogeneous mode grows too) printed "unstable band k in
    [9.09e-16, ...]": the bisection towards 0 halved the grid's first k 40 times, every middle growing."""
    from primordia.analysis.dispersion import fastest_mode_of

    def rates_at(k):  # 0.1 + k^2 - k^4 +- i: every k up to 1.05 grows, oscillating, the fastest at k^2 = 1/2
        real = 0.1 + k ** 2 - k ** 4
        return np.stack([real + 1j, real - 1j], axis=-1)

    mode = fastest_mode_of(rates_at, np.linspace(1e-3, 10.0, 1000))
    assert mode.k_max == pytest.approx(np.sqrt(0.5), rel=1e-6) and mode.band[0] == 0.0
    assert mode.band[1] == pytest.approx(np.sqrt((1.0 + np.sqrt(1.4)) / 2.0), rel=1e-9)
