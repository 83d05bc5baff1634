"""Symbolic check of seed section 3 against det M (needs sympy; not used at run time).

    python -m primordia.analysis.derivation

expands det M(phi, k) of Definition 3.1 (built from seed eq. (3.1), with every
parameter the seed scales to 1 kept general), factors out the transverse
B^(d-1), and compares

* the closed forms P_1, P_2, P_3 of :mod:`primordia.analysis.polynomials`
  (must agree identically), and
* every coefficient printed in Definition 3.2 and section 3.6 (a_0..a_3,
  b_0..b_3, c_0..c_3, theta_1..theta_4, the k = 0 polynomial of section 3.2),
  under the seed's scaling D_b = delta_B = kappa_F = kappa_B = 1,

and prints "printed - det M = ..." for each coefficient that differs.  The
output is the evidence behind the corrections listed in
:mod:`primordia.analysis.polynomials`.  Coefficient symbols follow the seed:
A_m, A_e = k_on + k_off, A_b, H_3, E = alpha m0 exp(-gamma m0), s = active-stress
slope, kappa_eta = kappa/eta; K = k^2.
"""

from __future__ import annotations

import sympy as sp

phi, K = sp.symbols("phi K")
k1, k2, k3 = sp.symbols("k1 k2 k3", real=True)
(mu, lam, rho, C0, kappa_eta, alpha_BW, s, D_m, D_f, D_b, E, A_m, A_e, A_b, H_3,
 kappa_F, kappa_B, delta_F, delta_B, xi_f) = sp.symbols(
    "mu lambda rho C_0 kappa_eta alpha_BW s D_m D_f D_b E A_m A_e A_b H_3 "
    "kappa_F kappa_B delta_F delta_B xi_f")
SEED_SCALING = {D_b: 1, delta_B: 1, kappa_F: 1, kappa_B: 1}


def matrix(d: int, printed_typo: bool = False) -> sp.Matrix:
    """M(phi, k) of Definition 3.1 from seed eq. (3.1); ``printed_typo`` puts A_1 k_2 in the last u-row."""
    kv = [k1, k2, k3][:d]
    Ksum = sum(x**2 for x in kv)
    n = d + 5
    M = sp.zeros(n, n)
    B = rho * phi**2 + mu * Ksum
    P, m, e, f, b = range(d, d + 5)
    for i in range(d):
        for j in range(d):
            row = 0 if (printed_typo and i == d - 1 and j == 1 and d > 2) else i
            M[i, j] = (mu + lam) * kv[row] * kv[j] + (B if i == j else 0)
        M[i, P] = sp.I * kv[i]
        M[i, m] = -sp.I * s * kv[i]
        M[P, i] = sp.I * alpha_BW * phi * kv[i]
        M[f, i] = sp.I * xi_f * kv[i]
    M[P, P] = C0 * phi + kappa_eta * Ksum
    M[m, m] = phi + D_m * Ksum
    M[m, f] = -E * Ksum
    M[e, m], M[e, e], M[e, b] = -A_m, phi + A_e, A_b
    M[f, e], M[f, f] = -kappa_F, phi + D_f * Ksum + delta_F
    M[b, m], M[b, b] = -kappa_B * H_3, phi + D_b * Ksum + delta_B
    return M


def longitudinal_determinant() -> sp.Expr:
    """det of the d = 1 matrix (u along k), as a polynomial in phi and K."""
    det = sp.expand(matrix(1).det(method="berkowitz"))
    return sp.expand(det.subs(k1**2, K).subs(k1, sp.sqrt(K)))


def closed_forms() -> dict:
    """P_1, P_2, P_3, B as implemented in :mod:`primordia.analysis.polynomials` (general parameters)."""
    x1, x2, x3, x4 = D_m * K, A_e, D_f * K + delta_F, D_b * K + delta_B
    return {
        "P_2": (phi + x1) * (phi + x2) * (phi + x3) * (phi + x4) - E * kappa_F * A_m * K * (phi + x4)
        + E * kappa_F * kappa_B * H_3 * A_b * K,
        "P_3": (rho * phi**2 + (2 * mu + lam) * K) * (C0 * phi + kappa_eta * K) + alpha_BW * K * phi,
        "P_1": -xi_f * s * E * K**2 * (C0 * phi + kappa_eta * K) * (phi + x2) * (phi + x4),
        "B": rho * phi**2 + mu * K,
    }


def seed_printed() -> dict:
    """The coefficients exactly as printed in Definition 3.2 and section 3.6 (delta_B as printed)."""
    Ae = A_e
    kk = K  # the seed's k^2
    printed = {
        "a_0": D_m * D_f * Ae * kk**3 + ((D_m * delta_B + D_m * D_f) * Ae - E * A_m) * kk**2
        + (D_m * delta_B * Ae + E * H_3 * A_b - E * A_m) * kk,
        "a_1": D_m * D_f * kk**3 + ((D_m * D_f + D_m + D_f) * Ae + D_m * delta_B + D_m * D_f) * kk**2
        + ((D_m * delta_B + delta_B + D_m + D_f) * Ae + D_m * delta_B - E * A_m) * kk + delta_B * Ae,
        # the printed bare "delta" in a_2 is written delta_B here
        "a_2": (D_m * D_f + D_m + D_f) * kk**2 + (D_m * delta_B + (D_m + D_f + 1) * Ae + delta_B + D_m + D_f) * kk
        + (delta_B + 1) * Ae + delta_B,
        "a_3": (D_m + D_f + 1) * kk + delta_B + Ae + 1,
        "a_4": sp.Integer(1),
        "c_0": kappa_eta * (2 * mu + lam) * kk**2,
        "c_1": (C0 * (2 * mu + lam) + alpha_BW) * kk,
        "c_2": rho * kappa_eta * kk,
        "c_3": rho * C0,
    }
    hats = [kappa_eta * Ae * (kk + 1) * kk,
            kappa_eta * kk**2 + ((C0 + kappa_eta) * Ae + kappa_eta) * kk + C0 * Ae,
            (C0 + kappa_eta) * kk + C0 * (Ae + 1),
            C0]
    for i, hat in enumerate(hats):
        printed[f"b_{i}"] = -(xi_f * s * E * kk) * hat
    loop = xi_f * s * E * Ae
    X = (D_m * delta_B + D_m * D_f) * Ae - E * A_m
    Y = D_m * delta_B * Ae + E * H_3 * A_b - E * A_m
    printed["theta_1"] = -2 * loop
    printed["theta_2"] = 3 * ((2 * mu + lam) * Y - loop)
    printed["theta_3"] = 4 * (2 * mu + lam) * X
    printed["theta_4"] = 5 * D_m * D_f * (2 * mu + lam) * Ae
    printed["k=0 cubic constant"] = delta_B * Ae  # printed "delta (k_on + k_off)"
    return printed


def det_coefficients() -> dict:
    """The same coefficients derived from det M (seed scaling substituted, delta_F kept)."""
    forms = {name: sp.expand(p.subs(SEED_SCALING)) for name, p in closed_forms().items()}
    out = {}
    for name, poly, degree in (("a", forms["P_2"], 4), ("c", forms["P_3"], 3), ("b", forms["P_1"], 3)):
        for i in range(degree + 1):
            out[f"{name}_{i}"] = sp.expand(poly.coeff(phi, i))
    d0 = sp.expand(out["a_0"] * out["c_0"] + out["b_0"])
    derivative = sp.expand(sp.diff(d0, K) / kappa_eta)
    for i in range(1, 5):
        out[f"theta_{i}"] = sp.expand(derivative.coeff(K, i))
    out["k=0 cubic constant"] = sp.expand((A_e + phi) * (delta_F + phi) * (1 + phi)).coeff(phi, 0)
    return out


def seed_corrected() -> dict:
    """The printed coefficients with the corrections of :mod:`primordia.analysis.polynomials` applied."""
    printed = seed_printed()
    corrected = {}
    for name, value in printed.items():
        value = value.subs(delta_B, delta_F)  # correction 2
        if name.startswith("b_"):
            value = value * K  # correction 3: xi_f s E k^4
        corrected[name] = value
    loop = xi_f * s * E * A_e
    X = (D_m * delta_F + D_m * D_f) * A_e - E * A_m
    Y = D_m * delta_F * A_e + E * H_3 * A_b - E * A_m
    corrected["theta_1"] = sp.Integer(0)  # correction 4
    corrected["theta_2"] = 3 * ((2 * mu + lam) * Y - loop)
    corrected["theta_3"] = 4 * ((2 * mu + lam) * X - loop)
    return corrected


def report() -> list[str]:
    lines = []
    full = longitudinal_determinant()
    forms = closed_forms()
    mismatch = sp.expand(full - (forms["P_1"] + forms["P_2"] * forms["P_3"]))
    lines.append(f"det M_longitudinal - (P_1 + P_2 P_3) = {mismatch}")
    coupling = sp.factor(sp.expand(full - sp.expand(forms["P_2"] * forms["P_3"])))
    lines.append(f"det M_longitudinal - P_2 P_3 = {coupling}")
    printed, derived = seed_printed(), det_coefficients()
    for name in printed:
        difference = sp.factor(sp.expand(printed[name].subs(SEED_SCALING) - derived[name]))
        verdict = "matches" if difference == 0 else f"printed - det M = {difference}"
        lines.append(f"{name}: {verdict}")
    corrected = seed_corrected()
    remaining = [name for name in corrected
                 if sp.expand(corrected[name].subs(SEED_SCALING) - derived[name]) != 0]
    lines.append("with corrections 2-4 applied, every coefficient matches det M"
                 if not remaining else f"still different after the corrections: {', '.join(remaining)}")
    return lines


def main() -> int:
    for line in report():
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
