"""Closed-form dispersion relation: seed eq. (3.2), Definition 3.2 and section 3.6.

With ``K = |k|^2`` (every coefficient below is a polynomial in K)::

    det M(phi, k) = B(phi)^(d-1) [P_1(phi) + P_2(phi) P_3(phi)]                  seed eq. (3.3)

    B   = rho phi^2 + mu K                        transverse (shear) waves: roots +-i k sqrt(mu/rho)
    P_2 = sum a_i phi^i = det M_22                the chemotaxis block (m, e, f, b)
        = (phi + D_m K)(phi + A_e)(phi + D_f K + delta_F)(phi + D_b K + delta_B)
          - E kappa_F A_m K (phi + D_b K + delta_B) + E kappa_F kappa_B H_3 A_b K
    P_3 = sum c_i phi^i                           longitudinal poroelastic waves (u.k, p)
        = (rho phi^2 + (2 mu + lambda) K)(C_0 phi + (kappa/eta) K) + alpha_BW K phi
    P_1 = sum b_i phi^i                           the mechano-chemical loop u -> f -> m -> u
        = -xi_f s E K^2 (C_0 phi + (kappa/eta) K)(phi + A_e)(phi + D_b K + delta_B)

``E = alpha m0 exp(-gamma m0)`` and ``s`` (active-stress slope) are defined in
:mod:`primordia.analysis.linearisation`.  These forms keep ``gamma, kappa_F,
kappa_B, delta_B, D_b`` general (the seed sets them to 1); with those equal to 1
they reduce to the seed's Definition 3.2 after the corrections below.  They
are checked against the numerical determinant of M in
``tests/unit/test_stability_polynomials.py`` at random complex phi, random
admissible parameters (all five scaling constants != 1), k in 2-D and 3-D.

Corrections to the seed's printed formulas
------------------------------------------
Each was found by expanding det M symbolically (``python -m
primordia.analysis.derivation`` prints every difference) and is asserted
numerically in the tests, at parameter values where the printed and the
corrected forms differ.

1. **Definition 3.1, last displacement row.** Printed ``A_d k_1, A_1 k_2, ...``;
   the momentum balance gives ``(mu + lambda) k_d k_j`` in column j, i.e.
   ``A_d k_2``.  (Invisible for k along a coordinate axis.)
2. **delta_B -> delta_F in a_0, a_1, a_2, a_3, and the bare ``delta`` in a_2.**
   Definition 3.1 writes the BMP row as ``phi + k^2 + 1`` (``D_b = delta_B = 1``
   substituted) but keeps ``delta_F`` in the FGF row; the determinant of that
   matrix contains ``delta_F`` wherever Definition 3.2 prints ``delta_B``
   (e.g. a_0 = ... + (D_m delta_F A_e + E H_3 A_b - E A_m) k^2).  Invisible at
   Table 3.1 (delta_F = delta_B = 1), visible at delta_F = 2: the printed a_0
   then differs from det M's by D_m A_e (k^4 + k^2) (delta_F - 1).
   The same holds for conditions (3.7a)-(3.7b), the theta_i and the k = 0 cubic
   of section 3.2, whose constant term ``delta (k_on + k_off)`` is
   ``delta_F delta_B A_e``: that cubic is (phi + A_e)(phi + delta_F)(phi + delta_B).
3. **b_i carry k^4, not k^2.**  Printed ``b_i = -(xi_f s E k^2) b^_i``; the
   loop u -> f -> m -> u multiplies ``i xi_f k`` (FGF sink), ``E k^2``
   (chemotaxis) and ``i s k`` (active stress), so ``b_i = -(xi_f s E k^4) b^_i``
   with the printed b^_i (which are right).  Symbolically
   det M_long - P_2 P_3 = -xi_f s E K^2 (C_0 phi + kappa/eta K)(phi + A_e)(phi + K + 1);
   numerically the printed P_1 misses det M by a factor k^2 at every k != 1.
4. **theta_i of section 3.6** (coefficients of d_0'(K) / (kappa/eta), d_0 =
   a_0 c_0 + b_0).  With correction 3, ``d_0 = (kappa/eta)(2mu + lambda) K^3
   (alpha K^2 + X_c K + Y_c)``, so

   ``theta_1 = 0`` (printed -2 xi_f s E A_e),
   ``theta_2 = 3 [(2mu + lambda) Y - xi_f s E A_e delta_B]`` (as printed),
   ``theta_3 = 4 [(2mu + lambda) X - xi_f s E A_e D_b]`` (printed without the
   xi_f term), ``theta_4 = 5 (2mu + lambda) D_m D_f D_b A_e`` (as printed),

   where ``a_0 = K (alpha K^2 + X K + Y)`` (:func:`a0_quadratic`).  The coupled
   problem's d_0 criterion is therefore the uncoupled one with X and Y shifted
   by ``xi_f s E A_e / (2mu + lambda)`` times D_b and delta_B respectively.
5. **The printed discriminant (3.9)** is not the discriminant of the cubic
   d_0'(K)/K = theta_4 K^3 + theta_3 K^2 + theta_2 K + theta_1 (that is
   18 t4 t3 t2 t1 - 4 t3^3 t1 + t3^2 t2^2 - 4 t4 t2^3 - 27 t4^2 t1^2); its terms
   carry extra powers of theta_1.  Both are provided
   (:mod:`primordia.analysis.conditions`); with theta_1 = 0 both conditions
   (3.8a) on theta_1, (3.8c) and the printed (3.9) vanish identically.

Everything broadcasts over arrays of K and of parameter values; coefficient
tuples are in ascending powers of phi.
"""

from __future__ import annotations

import numpy as np

from primordia.analysis.linearisation import LinearisedCoefficients, _as_coefficients


def _K(k):
    return np.asarray(k, dtype=float) ** 2


def transverse_coefficients(params_or_coefficients, k):
    """B(phi) = rho phi^2 + mu K as (B_0, B_1, B_2); its roots +-i k sqrt(mu/rho) are neutral."""
    c = _as_coefficients(params_or_coefficients)
    K = _K(k)
    return (c.mu * K, 0.0 * K, c.rho + 0.0 * K)


def chemotaxis_coefficients(params_or_coefficients, k):
    """(a_0, ..., a_4) of P_2 = det M_22 (Definition 3.2, corrected: delta_F where printed delta_B)."""
    c = _as_coefficients(params_or_coefficients)
    K = _K(k)
    Dm, Df, Db, dF, dB, Ae = c.D_m, c.D_f, c.D_b, c.delta_F, c.delta_B, c.A_e
    E_AmF = c.chemotactic_coefficient * c.kappa_F * c.A_m
    a4 = 1.0 + 0.0 * K
    a3 = (Dm + Df + Db) * K + Ae + dF + dB
    a2 = ((Dm * Df + Dm * Db + Df * Db) * K**2
          + ((Dm + Df + Db) * Ae + Dm * (dF + dB) + Df * dB + Db * dF) * K
          + (dF + dB) * Ae + dF * dB)
    a1 = (Dm * Df * Db * K**3
          + ((Dm * Df + Dm * Db + Df * Db) * Ae + Dm * (Df * dB + Db * dF)) * K**2
          + ((Dm * (dF + dB) + Df * dB + Db * dF) * Ae + Dm * dF * dB - E_AmF) * K
          + Ae * dF * dB)
    alpha, X, Y = a0_quadratic(c)
    a0 = K * (alpha * K**2 + X * K + Y)
    return (a0, a1, a2, a3, a4)


def a0_quadratic(params_or_coefficients):
    """(alpha, X, Y) with a_0 = K (alpha K^2 + X K + Y) (Definition 3.2, corrected).

    ``X`` is the left side of seed condition (3.7a), ``Y`` that of (3.7b), and
    ``4 X^2 - 12 alpha Y`` that of (3.7c); with the seed's scaling
    alpha = D_m D_f A_e, X = (D_m delta_F + D_m D_f) A_e - E A_m,
    Y = D_m delta_F A_e + E H_3 A_b - E A_m.
    """
    c = _as_coefficients(params_or_coefficients)
    E = c.chemotactic_coefficient
    alpha = c.D_m * c.D_f * c.D_b * c.A_e
    X = c.D_m * c.A_e * (c.D_f * c.delta_B + c.D_b * c.delta_F) - E * c.kappa_F * c.A_m * c.D_b
    Y = (c.D_m * c.A_e * c.delta_F * c.delta_B - E * c.kappa_F * c.A_m * c.delta_B
         + E * c.kappa_F * c.kappa_B * c.H_3 * c.A_b)
    return alpha, X, Y


def mechanics_coefficients(params_or_coefficients, k):
    """(c_0, ..., c_3) of P_3, the longitudinal poroelastic block (Definition 3.2, as printed)."""
    c = _as_coefficients(params_or_coefficients)
    K = _K(k)
    return (
        c.hydraulic_mobility * c.p_wave_modulus * K**2,
        (c.C_0 * c.p_wave_modulus + c.alpha_BW) * K,
        c.rho * c.hydraulic_mobility * K,
        c.rho * c.C_0 + 0.0 * K,
    )


def coupling_coefficients(params_or_coefficients, k):
    """(b_0, ..., b_3) of P_1 = -xi_f s E K^2 (C_0 phi + kappa/eta K)(phi + A_e)(phi + D_b K + delta_B).

    Definition 3.2 corrected: the prefactor is xi_f s E k^4 (printed k^2).
    """
    c = _as_coefficients(params_or_coefficients)
    K = _K(k)
    mob, C0, Ae = c.hydraulic_mobility, c.C_0, c.A_e
    bmp = c.D_b * K + c.delta_B
    hat = (
        mob * K * Ae * bmp,
        C0 * Ae * bmp + mob * K * (Ae + bmp),
        C0 * (Ae + bmp) + mob * K,
        C0 + 0.0 * K,
    )
    prefactor = -c.coupling_strength * K**2
    return tuple(prefactor * h for h in hat)


def _poly_mul(p, q):
    out = [0.0] * (len(p) + len(q) - 1)
    for i, pi in enumerate(p):
        for j, qj in enumerate(q):
            out[i + j] = out[i + j] + pi * qj
    return out


def dispersion_coefficients(params_or_coefficients, k, coupled: bool = True):
    """Coefficients (ascending in phi, degree 7) of P_1 + P_2 P_3 (or P_2 P_3 if uncoupled).

    Its roots are the growth rates of longitudinal modes; stacked on the first axis.
    """
    c = _as_coefficients(params_or_coefficients)
    product = _poly_mul(chemotaxis_coefficients(c, k), mechanics_coefficients(c, k))
    if coupled:
        for i, b in enumerate(coupling_coefficients(c, k)):
            product[i] = product[i] + b
    return np.stack(np.broadcast_arrays(*product))


def evaluate(coefficients, phi):
    """sum_i coefficients[i] phi^i (Horner), broadcasting."""
    value = 0.0
    for coefficient in reversed(list(coefficients)):
        value = value * phi + coefficient
    return value


def characteristic_determinant(params_or_coefficients, phi, k, d: int):
    """The closed form of det M: B^(d-1) (P_1 + P_2 P_3) at (phi, |k| = k) (seed eq. (3.3))."""
    c = _as_coefficients(params_or_coefficients)
    B = evaluate(transverse_coefficients(c, k), phi)
    return B ** (d - 1) * evaluate(dispersion_coefficients(c, k), phi)


def d0_quadratic(params_or_coefficients):
    """(alpha, X_c, Y_c) with d_0 = a_0 c_0 + b_0 = (kappa/eta)(2mu + lambda) K^3 (alpha K^2 + X_c K + Y_c).

    Section 3.6 with correction 3: the coupling shifts X by -sigma D_b and Y by
    -sigma delta_B, sigma = xi_f s E A_e / (2mu + lambda).
    """
    c = _as_coefficients(params_or_coefficients)
    alpha, X, Y = a0_quadratic(c)
    sigma = c.coupling_strength * c.A_e / c.p_wave_modulus
    return alpha, X - sigma * c.D_b, Y - sigma * c.delta_B


def d0(params_or_coefficients, k):
    """d_0(K) = P(0; K) of the coupled P_1 + P_2 P_3 (section 3.6)."""
    c = _as_coefficients(params_or_coefficients)
    K = _K(k)
    alpha, Xc, Yc = d0_quadratic(c)
    return c.hydraulic_mobility * c.p_wave_modulus * K**3 * (alpha * K**2 + Xc * K + Yc)


def a0(params_or_coefficients, k):
    """a_0(K) = P_2(0; K) (Definition 3.2, corrected)."""
    alpha, X, Y = a0_quadratic(params_or_coefficients)
    K = _K(k)
    return K * (alpha * K**2 + X * K + Y)


def theta(params_or_coefficients, variant: str = "corrected"):
    """(theta_1, ..., theta_4) of section 3.6: d_0'(K)/(kappa/eta) = theta_4 K^4 + ... + theta_1 K.

    ``variant="corrected"`` derives them from det M (theta_1 = 0, see
    correction 4); ``variant="seed"`` is the seed's printed formula (from its
    b_0 with the k^2 prefactor), kept to draw the seed's boundary curves.
    """
    c = _as_coefficients(params_or_coefficients)
    modulus = c.p_wave_modulus
    loop = c.coupling_strength * c.A_e  # xi_f s E A_e
    alpha, X, Y = a0_quadratic(c)
    theta_4 = 5.0 * modulus * alpha
    if variant == "corrected":
        return (0.0 * loop, 3.0 * (modulus * Y - loop * c.delta_B), 4.0 * (modulus * X - loop * c.D_b), theta_4)
    if variant == "seed":
        return (-2.0 * loop, 3.0 * (modulus * Y - loop), 4.0 * modulus * X, theta_4)
    raise ValueError(f"theta variant must be 'corrected' or 'seed', got {variant!r}")


__all__ = [
    "LinearisedCoefficients",
    "a0",
    "a0_quadratic",
    "characteristic_determinant",
    "chemotaxis_coefficients",
    "coupling_coefficients",
    "d0",
    "d0_quadratic",
    "dispersion_coefficients",
    "evaluate",
    "mechanics_coefficients",
    "theta",
    "transverse_coefficients",
]
