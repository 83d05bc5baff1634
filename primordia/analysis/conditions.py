"""Instability conditions and the special cases of seed sections 3.2-3.6.

What the conditions can and cannot say
--------------------------------------
P(phi) = P_1 + P_2 P_3 has a positive leading coefficient (rho C_0, or
((2mu + lambda) C_0 + alpha_BW) k^2 if rho = 0) and constant term d_0 = a_0 c_0 + b_0
(a_0 c_0 when uncoupled, c_0 > 0).  Hence

* d_0(K) < 0 at some K > 0  =>  a real positive root: a stationary (Turing)
  instability.  This is the criterion the seed follows ("we restrict the
  discussion to the conditions that break a_0 > 0"); it is sufficient, not
  necessary: an even number of positive real roots, or a complex pair with
  positive real part (oscillatory, which the seed sets aside in its footnote),
  leave d_0 > 0.  :func:`patterning_region` evaluates it exactly.
* a_0 = K (alpha K^2 + X K + Y) and, after correction 3 of
  :mod:`primordia.analysis.polynomials`, d_0 = (kappa/eta)(2mu + lambda) K^3
  (alpha K^2 + X_c K + Y_c).  With alpha > 0 the quadratic is negative for
  some K > 0 exactly when ``Y < 0  or  (X < 0 and X^2 > 4 alpha Y)``.

The seed's conditions (3.7a)-(3.7c) are ``X < 0``, ``Y < 0`` and ``4X^2 - 12 alpha Y > 0``
(the discriminant of a_0'(K), i.e. a_0 has a local minimum at real K).  Read
as "((3.7a) or (3.7b)) and (3.7c)" they are necessary for a_0 < 0 but not
sufficient: between X^2 = 3 alpha Y and X^2 = 4 alpha Y (X < 0 < Y) a_0 has a
positive local minimum.  The region they bound (:attr:`Conditions.seed_region`)
therefore contains the true one (:attr:`Conditions.region`) with a thin band to
spare; the tests assert both facts.

For the coupled system the seed applies the Routh-Hurwitz conditions (3.8a)-(3.8c)
and a discriminant (3.9) to the cubic d_0'(K)/K = theta_4 K^3 + theta_3 K^2 +
theta_2 K + theta_1.  All roots of that cubic in the left half plane means
d_0' > 0 for K > 0, so d_0 > 0: a violated (3.8a)-(3.8c) is necessary for d_0 < 0; that
is how :attr:`Conditions.seed_region` reads it.  With the corrected theta_1 = 0
those conditions degenerate (see correction 4), and the conditions that do
describe d_0 are (3.7a)-(3.7c) with X, Y replaced by X_c, Y_c (equivalently
theta_3 < 0, theta_2 < 0 and theta_3^2 - 4 theta_4 theta_2 > 0, the
discriminant of d_0'/K^2).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize

from primordia.analysis.dispersion import (
    default_wavenumbers,
    fastest_growing_mode,
    growth_rates,
    longitudinal_rates,
    max_growth_of_kind,
)
from primordia.analysis.linearisation import _as_coefficients, linearise, matrix_pencil, wave_vectors
from primordia.analysis.polynomials import (
    a0_quadratic,
    chemotaxis_coefficients,
    d0_quadratic,
    mechanics_coefficients,
    theta,
)
from primordia.core.errors import ConfigError
from primordia.core.parameters import CONSTRAINTS


# -- Routh-Hurwitz -------------------------------------------------------------------
def routh_hurwitz_cubic(coefficients):
    """Seed eq. (3.5): for alpha_3 phi^3 + ... + alpha_0 with alpha_i > 0, alpha_2 alpha_1 - alpha_3 alpha_0 > 0.

    Returns ``(holds, alpha_2 alpha_1 - alpha_3 alpha_0)``; ``coefficients`` ascending.
    """
    a0, a1, a2, a3 = coefficients
    determinant = a2 * a1 - a3 * a0
    holds = (a0 > 0) & (a1 > 0) & (a2 > 0) & (a3 > 0) & (determinant > 0)
    return holds, determinant


def routh_hurwitz_quartic(coefficients) -> dict:
    """Seed eq. (3.6) for a_4 phi^4 + ... + a_0: every expression > 0 <=> all roots have Re < 0.

    Returns the expressions by name (``a_0`` ... ``a_4``, ``a2a3-a1a4``,
    ``a1a2a3-a0a3^2-a1^2a4``) and ``holds``, their conjunction.
    """
    a0, a1, a2, a3, a4 = coefficients
    out = {f"a_{i}": a for i, a in enumerate(coefficients)}
    out["a2a3-a1a4"] = a2 * a3 - a1 * a4
    out["a1a2a3-a0a3^2-a1^2a4"] = a1 * a2 * a3 - a0 * a3**2 - a1**2 * a4
    holds = True
    for value in out.values():
        holds = holds & (value > 0)
    out["holds"] = holds
    return out


# -- the d_0 / a_0 criterion -----------------------------------------------------------
def _negative_somewhere(alpha, X, Y):
    """alpha K^2 + X K + Y < 0 for some K > 0 (alpha > 0)."""
    return (Y < 0) | ((X < 0) & (X**2 > 4.0 * alpha * Y))


def quadratic_minimum(alpha, X, Y):
    """(min over K > 0 of alpha K^2 + X K + Y, the K where it is reached (0: as K -> 0))."""
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = np.where(X < 0, -X / (2.0 * alpha), 0.0)
    return np.where(X < 0, Y - X**2 / (4.0 * alpha), Y), vertex


def most_negative_k_squared(alpha, X, Y):
    """A K > 0 where alpha K^2 + X K + Y is most negative (the vertex if X < 0, else half its positive root).

    Where the quadratic is negative nowhere, the vertex (or 1) is returned; always finite and > 0.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        root = (-X + np.sqrt(np.maximum(X**2 - 4.0 * alpha * Y, 0.0))) / (2.0 * alpha)
        K = np.where(X < 0, -X / (2.0 * alpha), 0.5 * root)
    return np.where(np.isfinite(K) & (K > 0), K, 1.0)


def _quadratic(c, coupled: bool):
    return d0_quadratic(c) if coupled else a0_quadratic(c)


def patterning_region(params, coupled: bool = True):
    """True where d_0 (coupled) or a_0 (uncoupled) is negative for some k > 0.

    Sufficient for a stationary (Turing) instability; see the module docstring.
    """
    return _negative_somewhere(*_quadratic(_as_coefficients(params), coupled))


@dataclass(frozen=True)
class Conditions:
    """Values of the seed's conditions at one parameter set or a grid of them.

    ``values[name]`` is the expression whose zero level is the boundary
    curve; ``satisfied[name]`` the inequality the seed states.  ``region`` is
    the exact "d_0 (or a_0) < 0 somewhere" criterion; ``seed_region`` the
    region the seed's conditions describe (necessary, see the module docstring).
    """

    coupled: bool
    values: dict
    satisfied: dict
    region: np.ndarray
    seed_region: np.ndarray
    notes: dict = field(default_factory=dict)


def uncoupled_conditions(params) -> Conditions:
    """Seed conditions (3.7a)-(3.7c) on a_0 (corrected: delta_F where printed delta_B)."""
    alpha, X, Y = a0_quadratic(_as_coefficients(params))
    values = {"3.7a": X, "3.7b": Y, "3.7c": 4.0 * X**2 - 12.0 * alpha * Y}
    satisfied = {"3.7a": X < 0, "3.7b": Y < 0, "3.7c": values["3.7c"] > 0}
    return Conditions(
        coupled=False,
        values=values,
        satisfied=satisfied,
        region=_negative_somewhere(alpha, X, Y),
        seed_region=(satisfied["3.7a"] | satisfied["3.7b"]) & satisfied["3.7c"],
        notes={"3.7a": "X < 0 (k^4 coefficient of a_0/k^2)", "3.7b": "Y < 0 (k^2 coefficient of a_0/k^2)",
               "3.7c": "4X^2 - 12 alpha Y > 0 (a_0' has real roots)"},
    )


def seed_discriminant_as_printed(t1, t2, t3, t4):
    """The left side of seed (3.9) exactly as printed (see correction 5)."""
    return (-27 * t4**2 * t1**4 + 18 * t4 * t3 * t2 * t1**3 - 4 * t4 * t2**3 * t1**3
            - 4 * t3**3 * t1**3 + t3**2 * t2**2 * t1**2)


def cubic_discriminant(t1, t2, t3, t4):
    """Discriminant of t4 K^3 + t3 K^2 + t2 K + t1 (> 0: three distinct real roots)."""
    return 18 * t4 * t3 * t2 * t1 - 4 * t3**3 * t1 + t3**2 * t2**2 - 4 * t4 * t2**3 - 27 * t4**2 * t1**2


def coupled_conditions(params, theta_variant: str = "corrected") -> Conditions:
    """Seed conditions (3.8a)-(3.8c) and (3.9) on the theta_i, and the d_0 analogues of (3.7a)-(3.7c).

    ``theta_variant`` selects the corrected theta_i or the seed's printed ones
    (to draw the seed's boundary curves).  Keys, by the seed's printed numbers:
    ``3.8a:theta_1``, ``3.8a:theta_2``, ``3.8a:theta_3``, ``3.8b``, ``3.8c``, ``3.9``
    (as printed), ``discriminant`` (of the cubic), and ``3.7a:d0``, ``3.7b:d0``,
    ``3.7c:d0``, the uncoupled conditions read on d_0 (X_c < 0, Y_c < 0,
    16 X_c^2 - 60 alpha Y_c > 0: the discriminant of d_0'/K^2).

    ``seed_region``: with the seed's theta, "(3.8a)-(3.8c) violated" (the cubic
    d_0'/K has a root with Re >= 0, necessary for d_0 < 0); with the corrected
    theta (theta_1 = 0, so the cubic always has the root 0), the same reading
    of d_0'/K^2: "(theta_3 < 0 or theta_2 < 0) and theta_3^2 > 4 theta_4 theta_2",
    i.e. ((3.7a) or (3.7b)) and (3.7c) on d_0, necessary like (3.7a)-(3.7c).
    """
    c = _as_coefficients(params)
    t1, t2, t3, t4 = theta(c, theta_variant)
    alpha, Xc, Yc = d0_quadratic(c)
    values = {
        "3.8a:theta_1": t1,
        "3.8a:theta_2": t2,
        "3.8a:theta_3": t3,
        "3.8b": t2 * t3 - t1 * t4,
        "3.8c": t1 * t2 * t3 - t1**2 * t4,
        "3.9": seed_discriminant_as_printed(t1, t2, t3, t4),
        "discriminant": cubic_discriminant(t1, t2, t3, t4),
        "3.7a:d0": Xc,
        "3.7b:d0": Yc,
        "3.7c:d0": 16.0 * Xc**2 - 60.0 * alpha * Yc,
    }
    satisfied = {name: value > 0 for name, value in values.items()}
    for name in ("3.7a:d0", "3.7b:d0"):
        satisfied[name] = values[name] < 0
    if theta_variant == "seed":  # (3.8a)-(3.8c) violated: d_0'(K)/K has a root outside the left half plane
        seed_region = ~(satisfied["3.8a:theta_1"] & satisfied["3.8a:theta_2"] & satisfied["3.8a:theta_3"]
                        & satisfied["3.8b"] & satisfied["3.8c"])
    else:  # theta_1 = 0: the same logic on d_0'/K^2 = theta_4 K^2 + theta_3 K + theta_2
        seed_region = (satisfied["3.7a:d0"] | satisfied["3.7b:d0"]) & satisfied["3.7c:d0"]
    return Conditions(
        coupled=True,
        values=values,
        satisfied=satisfied,
        region=_negative_somewhere(alpha, Xc, Yc),
        seed_region=seed_region,
        notes={"theta_variant": theta_variant},
    )


def instability_conditions(params, coupled: bool = True, theta_variant: str = "corrected") -> Conditions:
    """:func:`coupled_conditions` or :func:`uncoupled_conditions`."""
    return coupled_conditions(params, theta_variant) if coupled else uncoupled_conditions(params)


# -- critical wavenumber and critical parameter value ------------------------------------
@dataclass(frozen=True)
class CriticalValue:
    """theta_c where min over k of a_0 (or d_0) touches zero, and the k where it does."""

    name: str
    value: float
    k_c: float  #: critical wavenumber (0: the instability sets in at long waves, Y = 0)
    coupled: bool
    base_value: float  #: the parameter's value in the parameter set it was found from

    @property
    def wavelength(self) -> float:
        return 2 * np.pi / self.k_c if self.k_c > 0 else np.inf


def critical_wavenumber(params, coupled: bool = True) -> float:
    """k_c: where a_0'(k^2) = 0 (or d_0') at the minimum of a_0/k^2 (d_0/k^6); 0 if that is k -> 0."""
    _, vertex = quadratic_minimum(*_quadratic(_as_coefficients(params), coupled))
    return float(np.sqrt(vertex)) if np.ndim(vertex) == 0 else np.sqrt(vertex)


def _scan_values(value: float, constraint: str, n: int) -> np.ndarray:
    """1/100 to 100 times |value| (both signs unless the parameter must be >= 0), within its constraint."""
    magnitudes = np.logspace(-2, 2, n) * (abs(value) if value != 0 else 1.0)
    if constraint in ("positive", "nonnegative"):
        return magnitudes
    scan = np.concatenate([-magnitudes[::-1], magnitudes])
    admissible = [bool(CONSTRAINTS[constraint][1](v)) for v in scan]
    return scan[admissible]


def critical_value(params, name: str, coupled: bool = True, bracket=None, n_scan: int = 801):
    """The critical value of parameter ``name`` (solving min_k a_0 = 0, or d_0, as in seed section 3.4/3.6).

    The other parameters stay as in ``params``.  Without ``bracket`` the
    parameter is scanned over 1/100 to 100 times its value (both signs if it
    may be negative) and the sign change of min_k a_0 nearest to the current
    value is refined by Brent's method.  Returns a :class:`CriticalValue`, or
    None when a_0 (d_0) keeps its sign over the scanned range.
    """
    base = dict(params)
    if name not in base:
        if hasattr(params, "declaration"):
            params.declaration(name)  # raises the one-line ConfigError with suggestions
        raise ConfigError(f"unknown parameter '{name}'")
    value = float(base[name])

    def minimum(v):
        trial = dict(base)
        trial[name] = v
        return np.broadcast_to(quadratic_minimum(*_quadratic(linearise(trial), coupled))[0], np.shape(v))

    if bracket is None:
        constraint = params.declaration(name).constraint if hasattr(params, "declaration") else "any"
        scan = _scan_values(value, constraint, n_scan)
        signs = np.sign(minimum(scan))
        changes = np.flatnonzero(signs[:-1] * signs[1:] < 0)
        if changes.size == 0:
            return None
        left = scan[changes]
        if value != 0:  # nearest in ratio, same sign first
            distance = np.abs(np.log(np.abs(left) / abs(value))) + 1e3 * (np.sign(left) != np.sign(value))
        else:
            distance = np.abs(left)
        i = changes[np.argmin(distance)]
        bracket = (scan[i], scan[i + 1])
    lo, hi = bracket
    if np.sign(minimum(lo)) == np.sign(minimum(hi)):
        return None
    root = scipy.optimize.brentq(lambda v: float(minimum(v)), lo, hi, xtol=1e-12 * max(abs(lo), abs(hi)),
                                 rtol=1e-12)
    trial = dict(base)
    trial[name] = root
    return CriticalValue(name=name, value=float(root), k_c=critical_wavenumber(trial, coupled), coupled=coupled,
                         base_value=value)


# -- verdicts of seed sections 3.2-3.6 ----------------------------------------------------
@dataclass(frozen=True)
class Verdict:
    """The conclusion of one special case, in one sentence, with the numbers behind it."""

    case: str
    patterns: bool
    statement: str
    details: dict = field(default_factory=dict)

    def __str__(self) -> str:
        return f"{self.case}: {self.statement}"


def _stationary_and_oscillatory(rates):
    return max_growth_of_kind(rates, "stationary").max(), max_growth_of_kind(rates, "oscillatory").max()


def homogeneous_verdict(params) -> Verdict:
    """Seed section 3.2: at k = 0 the steady state is stable for every parameter set.

    At k = 0 every coupling carries a factor k, so det M = rho^d C_0 phi^(2d+2)
    (phi + A_e)(phi + delta_F)(phi + delta_B): neutral modes (conserved cells,
    rigid motion, uniform pressure) and three negative rates.
    """
    c = _as_coefficients(params)
    rates = growth_rates(c, np.array([0.0]), d=2).rates[0]
    nonzero = rates[np.abs(rates) > 1e-12 * (1.0 + np.max(np.abs(rates)))]
    holds, determinant = routh_hurwitz_cubic(
        (c.A_e * c.delta_F * c.delta_B, c.A_e * (c.delta_F + c.delta_B) + c.delta_F * c.delta_B,
         c.A_e + c.delta_F + c.delta_B, 1.0))
    stable = bool(np.all(nonzero.real < 0))
    listing = ", ".join(f"{r.real:.4g}" for r in nonzero)
    return Verdict(
        case="homogeneous perturbations (k = 0, seed section 3.2)",
        patterns=not stable,
        statement=(f"{'stable' if stable else 'NOT stable'}: rates {listing} (-A_e, -delta_F, -delta_B) "
                   f"and phi = 0 (conserved cells, rigid motion); Routh-Hurwitz (3.5) "
                   f"{'holds' if holds else 'fails'} ({float(determinant):.4g})"),
        details={"rates": rates, "routh_hurwitz": float(determinant)},
    )


def zero_chemotaxis_verdict(params, k=None) -> Verdict:
    """Seed section 3.3: with alpha = 0 every rate has Re < 0 (P_1 = 0, P_2 factorises).

    The chemical rates are -D_m K, -A_e, -(D_f K + delta_F), -(D_b K + delta_B)
    (real, negative); P_3 satisfies Routh-Hurwitz (3.5) since c_2 c_1 - c_3 c_0
    = rho (kappa/eta) alpha_BW K^2 > 0, so the poroelastic waves are damped
    (neutral if alpha_BW = 0).  ``params`` is evaluated with alpha set to 0.
    """
    base = dict(params)
    base["alpha"] = 0.0
    c = linearise(base)
    k = default_wavenumbers(c, 121) if k is None else np.asarray(k, dtype=float)
    growth = float(max_growth_of_kind(longitudinal_rates(c, k, method="qz")).max())
    M0, _, _ = matrix_pencil(c, wave_vectors(k, 1))
    chemistry = np.linalg.eigvals(-M0[..., 2:, 2:])  # roots of P_2: the (m, e, f, b) block alone
    chemistry_real_negative = bool(np.all(np.abs(chemistry.imag) <= 1e-12 * np.abs(chemistry))
                                   and np.all(chemistry.real < 0))
    mechanics_ok, _ = routh_hurwitz_cubic(mechanics_coefficients(c, k))
    patterns = growth > 0
    return Verdict(
        case="zero chemotaxis (alpha = 0, seed section 3.3)",
        patterns=bool(patterns),
        statement=(f"{'patterns' if patterns else 'no patterns'}: chemical rates "
                   f"{'real and negative' if chemistry_real_negative else 'NOT all real negative'}, "
                   f"poroelastic waves {'damped' if bool(np.all(mechanics_ok)) else 'undamped'}; "
                   f"max Re phi = {growth:.3g} over k in [{k.min():.3g}, {k.max():.3g}]"),
        details={"max_growth_rate": growth, "chemical_rates": chemistry,
                 "chemical_rates_real_negative": chemistry_real_negative},
    )


def uncoupled_verdict(params, k=None) -> Verdict:
    """Seed section 3.4: tau = 0 or xi_f = 0, P_1 = 0; instability only from P_2.

    Its Routh-Hurwitz conditions are (3.6); the seed's conditions for a_0 < 0, (3.7a)-(3.7c).
    """
    base = dict(params)
    base["xi_f"] = 0.0
    c = linearise(base)
    found = uncoupled_conditions(c)
    k = default_wavenumbers(c, 241, coupled=False) if k is None else np.asarray(k, dtype=float)
    routh = routh_hurwitz_quartic(chemotaxis_coefficients(c, k))
    violated = k[~routh["holds"] & (k > 0)]
    mode = fastest_growing_mode(c, k, coupled=False)
    predicted = bool(found.region)
    band = (f"k in [{violated.min():.3g}, {violated.max():.3g}] (of {k.size} sampled k)" if violated.size
            else f"none of {k.size} sampled k")
    return Verdict(
        case="uncoupled (xi_f = 0 or tau = 0, seed section 3.4)",
        patterns=bool(mode.unstable),
        statement=(f"{'patterns' if mode.unstable else 'no patterns'}: Routh-Hurwitz (3.6) fails for {band}; "
                   f"a_0 < 0 somewhere: {'yes' if predicted else 'no'} "
                   f"((3.7a) {_yes(found.satisfied['3.7a'])}, (3.7b) {_yes(found.satisfied['3.7b'])}, "
                   f"(3.7c) {_yes(found.satisfied['3.7c'])}); "
                   + (f"k_max = {mode.k_max:.4g}, wavelength {mode.wavelength:.4g}" if mode.unstable else "")),
        details={"conditions": found, "fastest_mode": mode, "routh_hurwitz_fails_for": violated},
    )


def _yes(flag) -> str:
    return "holds" if bool(flag) else "fails"


EPITHELIUM_CASES = {
    "no_activation": ("kappa_1", "kappa_2"),
    "no_inactivation": ("kappa_3", "kappa_4"),
    "neither": ("kappa_1", "kappa_2", "kappa_3", "kappa_4"),
}


def epithelium_verdict(params, case: str = "no_activation", k=None) -> Verdict:
    """Seed section 3.5: no activation (kappa_1 = kappa_2 = 0), no inactivation (kappa_3 = kappa_4 = 0), or neither.

    Then A_m = A_b = 0 and P_1 + P_2 P_3 = (phi + A_e)(phi + D_b K + delta_B) Q(phi)
    with Q(0) = (kappa/eta) K^3 [(2mu + lambda) D_m (D_f K + delta_F) - xi_f s E].
    The seed's condition, b_i < 0, is xi_f s > 0 (it prints "-s > 0" but lists
    the cases of s > 0); it is necessary.  The sharp stationary criterion is
    xi_f s E > (2mu + lambda) D_m delta_F (Q(0) < 0 for small k).
    """
    if case not in EPITHELIUM_CASES:
        raise ValueError(f"case must be one of {', '.join(EPITHELIUM_CASES)}, got {case!r}")
    base = dict(params)
    for name in EPITHELIUM_CASES[case]:
        base[name] = 0.0
    c = linearise(base)
    seed_condition = bool(c.xi_f * c.active_stress_slope > 0)
    threshold = float(c.p_wave_modulus * c.D_m * c.delta_F)
    sharp = bool(c.coupling_strength > threshold)
    k = default_wavenumbers(c, 241) if k is None else np.asarray(k, dtype=float)
    stationary, oscillatory = _stationary_and_oscillatory(longitudinal_rates(c, k, method="qz"))
    numerical = bool(np.max(stationary) > 0)
    return Verdict(
        case=f"epithelium {case.replace('_', ' ')} (seed section 3.5)",
        patterns=numerical,
        statement=(f"{'patterns' if numerical else 'no patterns'}: A_m = A_b = 0; seed condition xi_f s > 0 "
                   f"{_yes(seed_condition)}; xi_f s E = {float(c.coupling_strength) + 0.0:.4g} vs "  # + 0.0: no "-0"
                   f"(2mu + lambda) D_m delta_F = {threshold:.4g}: d_0 < 0 {'near k = 0' if sharp else 'nowhere'}; "
                   f"max real rate {float(np.max(stationary)):.3g}"),
        details={"seed_condition": seed_condition, "sharp_condition": sharp, "threshold": threshold,
                 "max_stationary_rate": float(np.max(stationary)),
                 "max_oscillatory_rate": float(np.max(oscillatory))},
    )


def coupled_verdict(params, k=None, theta_variant: str = "corrected") -> Verdict:
    """Seed section 3.6: the full system; d_0 criterion, conditions (3.8a)-(3.8c) and (3.9), numerical rates."""
    c = _as_coefficients(params)
    found = coupled_conditions(c, theta_variant)
    k = default_wavenumbers(c, 241) if k is None else np.asarray(k, dtype=float)
    stationary, oscillatory = _stationary_and_oscillatory(longitudinal_rates(c, k, method="qz"))
    turing = bool(np.max(stationary) > 0)
    waves = bool(np.max(oscillatory) > 0)
    statement = (f"{'Turing patterns' if turing else 'no Turing patterns'}: d_0 < 0 somewhere: "
                 f"{'yes' if bool(found.region) else 'no'}; max real rate {float(np.max(stationary)):.3g}")
    if waves:
        statement += f"; oscillatory instability, max Re phi {float(np.max(oscillatory)):.3g}"
    return Verdict(case="coupled (seed section 3.6)", patterns=turing, statement=statement,
                   details={"conditions": found, "max_stationary_rate": float(np.max(stationary)),
                            "max_oscillatory_rate": float(np.max(oscillatory))})


def verdicts(params: Mapping) -> list[Verdict]:
    """Every special case of seed sections 3.2-3.6 for one parameter set."""
    return [
        homogeneous_verdict(params),
        zero_chemotaxis_verdict(params),
        uncoupled_verdict(params),
        *(epithelium_verdict(params, case) for case in EPITHELIUM_CASES),
        coupled_verdict(params),
    ]
