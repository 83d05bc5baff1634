"""Closed-form dispersion relation vs the numerical determinant of M (seed eqs. (3.3)-(3.4), Definitions 3.1-3.2).

Each correction to the seed's printed coefficients is checked where the printed
and corrected forms differ, so each test fails if the correction is undone.
"""

import numpy as np
import pytest

from primordia.analysis.linearisation import dispersion_matrix, linearise, wave_vectors
from primordia.analysis.polynomials import (
    a0,
    a0_quadratic,
    characteristic_determinant,
    chemotaxis_coefficients,
    coupling_coefficients,
    d0,
    d0_quadratic,
    evaluate,
    mechanics_coefficients,
    theta,
    transverse_coefficients,
)
from primordia.physics.seed_parameters import seed_parameters

from stability_support import random_parameters


def longitudinal_determinant(c, phi, k):
    """det of the d = 1 matrix (u along k): P_1 + P_2 P_3 without the transverse factor."""
    return np.linalg.det(dispersion_matrix(c, phi, wave_vectors(np.asarray(k, dtype=float), 1)))


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("seed", range(4))
def test_det_M_equals_closed_form_at_random_phi_and_k(d, seed):
    rng = np.random.default_rng(100 * d + seed)
    c = linearise(random_parameters(rng))
    for k in (0.3, 1.0, 2.7):
        direction = rng.normal(size=d)
        phi = complex(rng.normal(), rng.normal())
        numeric = np.linalg.det(dispersion_matrix(c, phi, k * direction / np.linalg.norm(direction)))
        closed = characteristic_determinant(c, phi, k, d)
        assert numeric == pytest.approx(closed, rel=1e-9)


def test_transverse_factor_is_B_to_the_d_minus_1():
    c = linearise(seed_parameters(rho=0.7))
    phi, k = 0.4 + 0.9j, 1.3
    ratio = np.linalg.det(dispersion_matrix(c, phi, k * np.array([0.6, 0.0, 0.8]))) / longitudinal_determinant(
        c, phi, k)
    assert ratio == pytest.approx(evaluate(transverse_coefficients(c, k), phi) ** 2, rel=1e-10)


def seed_printed_P2(c, k):
    """P_2 from the a_i exactly as printed in Definition 3.2 (the symbol delta_B, = 1 in Table 3.1)."""
    K, Ae, E, dB = k**2, c.A_e, c.chemotactic_coefficient, 1.0
    Dm, Df = c.D_m, c.D_f
    a = [
        Dm * Df * Ae * K**3 + ((Dm * dB + Dm * Df) * Ae - E * c.A_m) * K**2
        + (Dm * dB * Ae + E * c.H_3 * c.A_b - E * c.A_m) * K,
        Dm * Df * K**3 + ((Dm * Df + Dm + Df) * Ae + Dm * dB + Dm * Df) * K**2
        + ((Dm * dB + dB + Dm + Df) * Ae + Dm * dB - E * c.A_m) * K + dB * Ae,
        (Dm * Df + Dm + Df) * K**2 + (Dm * dB + (Dm + Df + 1) * Ae + dB + Dm + Df) * K + (dB + 1) * Ae + dB,
        (Dm + Df + 1) * K + dB + Ae + 1,
        1.0,
    ]
    return a


def chemistry_determinant(c, phi, k):
    """det M_22 (the (m, e, f, b) block) numerically."""
    M = dispersion_matrix(c, phi, wave_vectors(np.asarray(k, dtype=float), 1))
    return np.linalg.det(M[2:, 2:])


def test_a_i_printed_delta_B_is_delta_F():
    """Correction 2: the printed a_i hold at delta_F = 1 only; the implemented ones at any delta_F."""
    phi, k = 0.3 - 0.2j, 1.7
    table = linearise(seed_parameters())
    assert evaluate(seed_printed_P2(table, k), phi) == pytest.approx(chemistry_determinant(table, phi, k), rel=1e-12)
    changed = linearise(seed_parameters(delta_F=2.0))
    exact = chemistry_determinant(changed, phi, k)
    assert evaluate(chemotaxis_coefficients(changed, k), phi) == pytest.approx(exact, rel=1e-12)
    assert abs(evaluate(seed_printed_P2(changed, k), phi) - exact) > 1e-3 * abs(exact)
    # the documented difference: printed a_0 - true a_0 = D_m A_e (k^4 + k^2)(1 - delta_F)
    K = k**2
    printed_a0 = seed_printed_P2(changed, k)[0]
    assert printed_a0 - a0(changed, k) == pytest.approx(changed.D_m * changed.A_e * (K**2 + K) * (1 - 2.0))


def test_b_i_carry_k_to_the_fourth():
    """Correction 3: det M - P_2 P_3 = P_1 with prefactor xi_f s E k^4; the printed k^2 is off by k^2."""
    c = linearise(seed_parameters())
    phi = 0.25 + 0.5j
    for k in (0.5, 2.0):
        coupling = longitudinal_determinant(c, phi, k) - evaluate(chemotaxis_coefficients(c, k), phi) * evaluate(
            mechanics_coefficients(c, k), phi)
        implemented = evaluate(coupling_coefficients(c, k), phi)
        assert coupling == pytest.approx(implemented, rel=1e-8)
        printed = implemented / k**2  # b_i = -(xi_f s E k^2) b^_i as printed
        assert abs(printed - coupling) > 0.5 * abs(coupling)


def test_definition_3_1_typo_in_last_row_changes_the_determinant():
    """Correction 1: with A_1 k_2 in the last displacement row (d = 3) det M is no longer isotropic."""
    c = linearise(seed_parameters())
    phi, kv = 0.3 + 0.1j, np.array([0.5, 0.7, 1.1])
    M = dispersion_matrix(c, phi, kv)
    typo = M.copy()
    typo[2, 1] = (c.mu + c.lam) * kv[0] * kv[1]
    exact = characteristic_determinant(c, phi, np.linalg.norm(kv), 3)
    assert np.linalg.det(M) == pytest.approx(exact, rel=1e-10)
    assert abs(np.linalg.det(typo) - exact) > 1e-6 * abs(exact)


def test_theta_are_the_coefficients_of_d0_prime():
    """Correction 4: the corrected theta_i (theta_1 = 0) reproduce d_0'(K) of the numerical det M at phi = 0."""
    c = linearise(seed_parameters(delta_F=1.5, D_b=0.8, delta_B=1.2, kappa_F=1.1, kappa_B=0.9))
    K = np.array([0.2, 0.9, 1.6, 2.5])
    h = 1e-5
    numeric = [(longitudinal_determinant(c, 0.0, np.sqrt(Ki + h)) - longitudinal_determinant(c, 0.0, np.sqrt(Ki - h)))
               .real / (2 * h) for Ki in K]
    numeric = np.array(numeric) / c.hydraulic_mobility
    t = theta(c, "corrected")
    assert t[0] == 0.0
    assert evaluate((0.0,) + tuple(t), K) == pytest.approx(numeric, rel=1e-5)
    printed = theta(c, "seed")
    assert np.all(np.abs(evaluate((0.0,) + tuple(printed), K) - numeric) > 1e-3 * np.abs(numeric))


def test_d0_factorises_as_K_cubed_times_a_quadratic():
    c = linearise(random_parameters(np.random.default_rng(7)))
    for k in (0.4, 1.1, 3.0):
        numeric = longitudinal_determinant(c, 0.0, k).real
        assert d0(c, k) == pytest.approx(numeric, rel=1e-9)
        alpha, Xc, Yc = d0_quadratic(c)
        K = k**2
        assert numeric == pytest.approx(c.hydraulic_mobility * c.p_wave_modulus * K**3 * (alpha * K**2 + Xc * K + Yc),
                                        rel=1e-9)
        alpha, X, Y = a0_quadratic(c)
        assert chemistry_determinant(c, 0.0, k).real == pytest.approx(K * (alpha * K**2 + X * K + Y), rel=1e-9)


def test_homogeneous_polynomial_of_section_3_2():
    """det M(phi, 0) = rho^d C_0 phi^(2d+2) (phi + A_e)(phi + delta_F)(phi + delta_B) (printed: delta -> delta_F delta_B)."""
    c = linearise(seed_parameters(delta_F=1.7, delta_B=0.6, rho=0.8, C_0=0.2))
    for d in (2, 3):
        for phi in (0.7, -0.35 + 0.4j):
            expected = c.rho**d * c.C_0 * phi ** (2 * d + 2) * (phi + c.A_e) * (phi + c.delta_F) * (phi + c.delta_B)
            assert np.linalg.det(dispersion_matrix(c, phi, np.zeros(d))) == pytest.approx(expected, rel=1e-10)


def test_mechanics_polynomial_is_routh_hurwitz_stable():
    """c_2 c_1 - c_3 c_0 = rho (kappa/eta) alpha_BW K^2 > 0 (seed section 3.3)."""
    c = linearise(seed_parameters())
    k = np.array([0.1, 1.0, 10.0])
    c0, c1, c2, c3 = mechanics_coefficients(c, k)
    assert c2 * c1 - c3 * c0 == pytest.approx(c.rho * c.hydraulic_mobility * c.alpha_BW * k**4, rel=1e-9)


def test_sympy_derivation_matches_after_corrections():
    from primordia.analysis.derivation import report

    lines = report()
    assert lines[0] == "det M_longitudinal - (P_1 + P_2 P_3) = 0"
    assert lines[-1] == "with corrections 2-4 applied, every coefficient matches det M"
    differing = {line.split(":")[0] for line in lines if "printed - det M" in line}
    assert differing == {"a_0", "a_1", "a_2", "a_3", "b_0", "b_1", "b_2", "b_3", "theta_1", "theta_2", "theta_3",
                         "k=0 cubic constant"}
