"""Growth rates phi(k): every root of det M(phi, k) = 0, as a polynomial eigenvalue problem.

M(phi, k) = M0 + phi M1 + phi^2 M2 (seed Definition 3.1, built in
:mod:`primordia.analysis.linearisation`) is quadratic in phi, and only the
displacement rows carry phi^2 (``M2 = rho I`` on u).  Writing ``v = phi u``
gives the first-order (companion) linearisation of size n + d, n = d + 5::

    [ -M0  0 ] [w]         [ M1   rho E_u ] [w]
    [  0   I ] [v]  = phi  [ E_u^T   0    ] [v]        (E_u selects u from w)

whose generalised eigenvalues are exactly the roots of det M (the full
2n companion form would add d + 5 spurious infinite eigenvalues; introducing
``phi w`` only where M2 != 0 avoids them).  The pencil is made real first (u
-> -i u, :func:`~primordia.analysis.linearisation.real_pencil`), so rates come
in exact conjugate pairs.  It is solved

* by QZ (``scipy.linalg.eig(A, B)``, ``method="qz"``), which needs no inverse and
  copes with rho = 0 or C_0 = 0 (B singular: infinite eigenvalues are dropped);
* or, for the many small problems of a patterning space, as the standard
  batched problem B^-1 A (``method="standard"``, valid when rho C_0 > 0, which
  makes B invertible).

No polynomial is expanded by hand on the way; the closed forms of
:mod:`primordia.analysis.polynomials` serve as an independent check.

The 2(d - 1) roots of the transverse factor B(phi)^(d-1) = (rho phi^2 + mu K)^(d-1)
(shear waves, purely imaginary: neutral) are identified among the computed
roots and reported separately; the remaining roots, those of P_1 + P_2 P_3, do
not depend on d.  Units: phi is a rate in the seed's dimensionless time,
k a wavenumber in its dimensionless length (section 2 scaling).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np
import scipy.linalg
import scipy.optimize

from primordia.analysis.linearisation import (
    LinearisedCoefficients,
    _as_coefficients,
    matrix_pencil,
    real_pencil,
    wave_vectors,
)
from primordia.analysis.polynomials import a0_quadratic, d0_quadratic

#: Degree of P_1 + P_2 P_3 in phi when rho C_0 > 0 (4 chemical + 3 poroelastic roots).
LONGITUDINAL_DEGREE = 7
#: Generalised eigenvalues with |alpha/beta| above this are treated as infinite (B singular).
INFINITE = 1e12


def first_order_pencil(M0, M1, rho, d: int):
    """(A, B) of the linearisation A z = phi B z, z = (w, phi u), of M0 + phi M1 + phi^2 rho E_u E_u^T."""
    n = M0.shape[-1]
    shape = np.broadcast_shapes(M0.shape[:-2], np.shape(rho))
    A = np.zeros(shape + (n + d, n + d))
    B = np.zeros_like(A)
    A[..., :n, :n] = -M0
    B[..., :n, :n] = M1
    rho = np.broadcast_to(np.asarray(rho, dtype=float), shape)
    for i in range(d):
        A[..., n + i, n + i] = 1.0  # v_i ...
        B[..., n + i, i] = 1.0  # ... = phi u_i
        B[..., i, n + i] = rho  # rho phi^2 u_i = phi (rho v_i)
    return A, B


def balance_pencil(A, B, sweeps: int = 12):
    """Row and column scalings by powers of 2 that equilibrate the pencil (A, B) (exact in floating point).

    The pencil mixes stiffnesses ~1e4 K with storage ~1e-3 and mobilities
    ~1e-3 K; unbalanced, QZ loses up to 8 digits on the slow chemical
    rates.  Scaling rows and columns alternately by the (rounded) largest
    entry of A and B brings it back to ~1e-12 relative accuracy.  Generalised
    eigenvalues are unchanged: (D_1 A D_2) z = phi (D_1 B D_2) z.
    """
    A, B = np.array(A, dtype=float), np.array(B, dtype=float)
    for _ in range(sweeps):
        for axis in (-1, -2):  # rows (max over columns), then columns
            size = np.sqrt(np.max(np.abs(A), axis=axis) ** 2 + np.max(np.abs(B), axis=axis) ** 2)
            size = np.where(size > 0, 2.0 ** np.round(np.log2(np.where(size > 0, size, 1.0))), 1.0)
            scale = size[..., :, None] if axis == -1 else size[..., None, :]
            A /= scale
            B /= scale
    return A, B


def _qz_eigenvalues(A, B, size: int):
    """Finite generalised eigenvalues of each (A, B), NaN-padded to ``size``."""
    A, B = balance_pencil(A, B)
    batch = A.shape[:-2]
    out = np.full(batch + (size,), np.nan, dtype=complex)
    for index in np.ndindex(*batch):
        (alpha, beta) = scipy.linalg.eig(A[index], B[index], right=False, homogeneous_eigvals=True)
        finite = np.abs(beta) * INFINITE > np.abs(alpha)
        values = alpha[finite] / beta[finite]
        out[index][: values.size] = values[:size]
    return out


def _standard_eigenvalues(A, B):
    # LAPACK's geev balances B^-1 A itself; measured against 40-digit roots of the
    # closed form this path is accurate to ~1e-12 relative without balance_pencil.
    return np.linalg.eigvals(np.linalg.solve(B, A))


def pencil_roots(M0, M1, rho, d: int, method: str, size: int):
    """Every root phi of det(M0 + phi M1 + phi^2 rho E_u E_u^T) = 0, E_u the first ``d`` unknowns (real pencil).

    ``method`` "standard" (B invertible) or "qz"; QZ results are NaN-padded to ``size``.
    """
    A, B = first_order_pencil(M0, M1, rho, d)
    if method == "standard":
        return _standard_eigenvalues(A, B)
    return _qz_eigenvalues(A, B, size)


def _choose_method(c: LinearisedCoefficients, method: str) -> str:
    invertible = bool(np.all(np.asarray(c.rho) > 0) and np.all(np.asarray(c.C_0) > 0))
    return choose_method(invertible, method)


def choose_method(invertible: bool, method: str) -> str:
    """"auto" -> "standard" when the first-order pencil's B is invertible (rho C_0 > 0), else "qz"."""
    if method == "auto":
        return "standard" if invertible else "qz"
    if method == "standard" and not invertible:
        raise ValueError("method='standard' needs rho > 0 and C_0 > 0; use method='qz'")
    if method not in ("standard", "qz"):
        raise ValueError(f"method must be 'auto', 'standard' or 'qz', got {method!r}")
    return method


def checked_wavenumbers(k) -> np.ndarray:
    """``k`` as a 1-D float array of finite wavenumbers >= 0, or a ValueError naming what is wrong."""
    k = np.atleast_1d(np.asarray(k, dtype=float))
    if k.ndim != 1 or not np.all(np.isfinite(k)) or np.any(k < 0):
        raise ValueError(f"wavenumbers must be a 1-D list of finite numbers >= 0, "
                         f"got {np.array2string(k, threshold=8)}")
    return k


def sort_by_growth(rates):
    """Descending real part, then descending imaginary part; NaN last.

    Real parts are compared to 12 significant digits (relative to the
    largest root) so that the two members of a conjugate pair, whose real
    parts may differ in the last bit, always come out as (+Im, -Im).
    """
    rates = np.asarray(rates, dtype=complex)
    finite = np.isfinite(rates)
    scale = 1.0 + np.max(np.where(finite, np.abs(rates), 0.0), axis=-1, keepdims=True)
    real_key = np.where(finite, -np.round(rates.real / scale, 12), np.inf)
    imag_key = np.where(finite, -rates.imag, np.inf)
    order = np.lexsort((imag_key, real_key), axis=-1)
    return np.take_along_axis(rates, order, axis=-1)


def _uncouple(c: LinearisedCoefficients) -> LinearisedCoefficients:
    return replace(c, xi_f=0.0 * np.asarray(c.xi_f))


def _homogeneous_rates(c: LinearisedCoefficients, size: int):
    """Roots of det M(phi, 0): every coupling term carries k, so M is block diagonal.

    The mechanics (rho phi^2 u = 0, C_0 phi p = 0) contributes only phi = 0;
    the chemistry the eigenvalues of -M22(0, 0).  (With rho = 0 or C_0 = 0,
    det M(phi, 0) vanishes identically; the chemical roots are still these.)
    """
    M0, _, _ = matrix_pencil(c, np.zeros((1,)))
    chemistry = np.linalg.eigvals(-M0[..., 2:, 2:])  # d = 1: rows u, p come first
    zeros = np.zeros(chemistry.shape[:-1] + (size - 4,), dtype=complex)
    return sort_by_growth(np.concatenate([chemistry.astype(complex), zeros], axis=-1))


def longitudinal_rates(params_or_coefficients, k, coupled: bool = True, method: str = "auto",
                       paired: bool = False):
    """Roots of P_1 + P_2 P_3 (the d-independent part of det M), shape ``batch + k.shape + (7,)``.

    Computed from the d = 1 matrix (the longitudinal block of Definition 3.1:
    u along k, p, m, e, f, b).  ``coupled=False`` drops the mechano-chemical
    loop (xi_f = 0, i.e. P_1 = 0).  Sorted by descending real part, NaN-padded
    where the degree is lower (rho = 0 or C_0 = 0).  With ``paired=True``, ``k``
    has the parameters' batch shape and is matched element by element
    (shape ``broadcast(batch, k.shape) + (7,)``).
    """
    c = _as_coefficients(params_or_coefficients)
    if not coupled:
        c = _uncouple(c)
    k = np.asarray(k, dtype=float)
    cc = c if paired else _expand(c, k.ndim)
    shape = np.broadcast_shapes(cc.shape, k.shape)
    M0, M1, _ = real_pencil(cc, wave_vectors(k, 1))
    rates = sort_by_growth(pencil_roots(M0, M1, cc.rho, 1, _choose_method(c, method), LONGITUDINAL_DEGREE))
    at_rest = np.broadcast_to(k == 0, shape)
    if np.any(at_rest):
        rates = np.where(at_rest[..., None], _homogeneous_rates(cc, LONGITUDINAL_DEGREE), rates)
    return rates


def _expand(c: LinearisedCoefficients, ndim: int) -> LinearisedCoefficients:
    """Append ``ndim`` unit axes to every coefficient, so it broadcasts against k."""
    if ndim == 0:
        return c
    values = {}
    for f in fields(c):
        value = np.asarray(getattr(c, f.name), dtype=float)
        values[f.name] = value.reshape(value.shape + (1,) * ndim)
    return LinearisedCoefficients(**values)


@dataclass(frozen=True)
class GrowthRates:
    """All roots phi of det M(phi, k) = 0 at each wavenumber, for one parameter set.

    ``rates[i]`` are the 7 roots of P_1 + P_2 P_3 at ``k[i]`` (descending real
    part); ``transverse[i]`` the 2(d-1) roots of B^(d-1), +-i k sqrt(mu/rho),
    identified among the computed roots.  Dimensionless rates.
    """

    k: np.ndarray
    rates: np.ndarray
    transverse: np.ndarray
    d: int

    @property
    def max_real(self) -> np.ndarray:
        """max Re phi at each k over the non-transverse roots."""
        return np.nanmax(self.rates.real, axis=-1)

    @property
    def all_roots(self) -> np.ndarray:
        return np.concatenate([self.rates, self.transverse], axis=-1)


def growth_rates(params, k, d: int = 2, coupled: bool = True, method: str = "qz", direction=None) -> GrowthRates:
    """Every root of det M(phi, k) = 0 for d = 2 or 3, by the linearised generalised eigenproblem.

    ``k`` is an array of wavenumber magnitudes (>= 0), ``direction`` the wave
    direction (e_1 by default; the model is isotropic).  The full
    (d+5) x (d+5) matrix of Definition 3.1 is used; the transverse factor's
    roots are then identified as the 2(d-1) computed roots nearest to
    +-i k sqrt(mu/rho) (none when rho = 0) and returned separately.
    """
    if d not in (2, 3):
        raise ValueError(f"d must be 2 or 3, got {d}")
    c = _as_coefficients(params)
    if c.shape != ():
        raise ValueError("growth_rates takes one parameter set; use max_growth_rate for grids")
    if not coupled:
        c = _uncouple(c)
    k = checked_wavenumbers(k)
    M0, M1, _ = real_pencil(c, wave_vectors(k, d, direction))
    n_transverse = 2 * (d - 1) if float(c.rho) > 0 else 0
    roots = pencil_roots(M0, M1, c.rho, d, _choose_method(c, method), LONGITUDINAL_DEGREE + n_transverse)
    rates, transverse = split_transverse(roots, _shear_speed(c), k, d, n_transverse, LONGITUDINAL_DEGREE)
    at_rest = k == 0
    if np.any(at_rest):
        rates[at_rest] = _homogeneous_rates(c, LONGITUDINAL_DEGREE)
        transverse[at_rest] = 0.0
    return GrowthRates(k=k, rates=rates, transverse=transverse, d=d)


def _shear_speed(c: LinearisedCoefficients) -> float:
    return float(np.sqrt(c.mu / c.rho)) if float(c.rho) > 0 else np.inf


def split_transverse(roots, speed, k, d, n_transverse, keep):
    """Remove the roots of B^(d-1) (each of +-i k speed, d-1 times) by nearest match.

    Returns (the other roots sorted by growth, the first ``keep`` of them; the
    transverse roots), ``speed`` = sqrt(mu / rho), the shear-wave speed.
    """
    remaining = roots.copy()
    found = np.full(k.shape + (n_transverse,), np.nan, dtype=complex)
    if n_transverse:
        targets = [sign * 1j * k * speed for sign in (1, -1) for _ in range(d - 1)]
        for column, target in enumerate(targets):
            distance = np.abs(remaining - target[:, None])
            distance = np.where(np.isnan(distance), np.inf, distance)
            nearest = np.argmin(distance, axis=-1)
            rows = np.arange(k.size)
            found[rows, column] = remaining[rows, nearest]
            remaining[rows, nearest] = np.nan
    kept = sort_by_growth(remaining)[..., :keep]  # NaN (removed) sort last
    return kept, found


def max_growth_rate(params_or_coefficients, k, coupled: bool = True, method: str = "auto"):
    """max Re phi over the roots of P_1 + P_2 P_3, shape ``batch + k.shape`` (rounding-level values set to 0)."""
    return max_growth_of_kind(longitudinal_rates(params_or_coefficients, k, coupled, method), "any")


def default_wavenumbers(params_or_coefficients, n: int = 241, coupled: bool = True) -> np.ndarray:
    """A log-spaced k grid from 1e-3 to past the end of the predicted unstable band (>= 10).

    The band where a_0 (or d_0) < 0 ends at the larger root of its quadratic
    factor (:func:`~primordia.analysis.polynomials.a0_quadratic`); the grid
    reaches 3 times its square root.  Over a parameter grid, the widest band wins.
    """
    c = _as_coefficients(params_or_coefficients)
    alpha, X, Y = d0_quadratic(c) if coupled else a0_quadratic(c)
    with np.errstate(invalid="ignore", divide="ignore"):
        root = (-X + np.sqrt(np.maximum(X**2 - 4 * alpha * Y, 0.0))) / (2 * alpha)
    root = np.where(np.isfinite(root) & (root > 0), root, 0.0)
    k_high = max(10.0, 3.0 * float(np.sqrt(np.max(root))))
    return np.logspace(-3.0, np.log10(k_high), n)


#: Re phi <= GROWTH_TOLERANCE (1 + |phi|) is rounding, not growth (rates are accurate to ~1e-12 relative).
GROWTH_TOLERANCE = 1e-11
#: |Im phi| <= REAL_TOLERANCE (1 + |phi|): a real root, i.e. a stationary (Turing) mode.
REAL_TOLERANCE = 1e-7
#: What a growth rate may be asked of: every root, the real (stationary, Turing) ones, the complex (oscillatory) ones.
GROWTH_KINDS = ("any", "stationary", "oscillatory")


def growth_of_kind(rates, kind: str = "any"):
    """Re phi of the roots of one kind (stationary: real roots; oscillatory: complex), -inf elsewhere.

    Roots whose real part is within rounding of zero are set to 0 (neutral).
    """
    if kind not in GROWTH_KINDS:
        raise ValueError(f"kind must be one of {', '.join(GROWTH_KINDS)}, got {kind!r}")
    rates = np.asarray(rates, dtype=complex)
    size = 1.0 + np.abs(rates)
    growth = np.where(np.abs(rates.real) <= GROWTH_TOLERANCE * size, 0.0, rates.real)
    growth = np.where(np.isfinite(rates), growth, -np.inf)
    if kind == "any":
        return growth
    real = np.abs(rates.imag) <= REAL_TOLERANCE * size
    return np.where(real if kind == "stationary" else ~real, growth, -np.inf)


def max_growth_of_kind(rates, kind: str = "any"):
    """max over the last axis (the roots) of :func:`growth_of_kind`."""
    return np.max(growth_of_kind(rates, kind), axis=-1)


@dataclass(frozen=True)
class FastestMode:
    """The fastest-growing wavenumber of a parameter set (dimensionless)."""

    k_max: float  #: wavenumber of the largest Re phi
    growth_rate: float  #: Re phi at k_max (> 0: the steady state is unstable)
    frequency: float  #: |Im phi| of that root (0 for a stationary Turing mode)
    band: tuple[float, float]  #: (lowest, highest) k with Re phi > 0: the grid's outermost unstable k, each
    #: refined by bisection towards its stable neighbour (the grid's last k stays; below its first the band is
    #: bisected towards k = 0, and is 0 when it reaches there, e.g. beside a conserved species' root 0; a band
    #: between two k of the grid is bisected out from k_max); NaN if none
    at_edge: bool  #: the maximum sits at an end of the k range: widen it (k_max = 0, the homogeneous mode, is no edge)
    kind: str = "any"  #: which roots were searched: "any", "stationary" or "oscillatory"

    @property
    def unstable(self) -> bool:
        return self.growth_rate > 0

    @property
    def stationary(self) -> bool:
        return self.frequency == 0.0

    @property
    def wavelength(self) -> float:
        """2 pi / k_max, in the seed's dimensionless length."""
        return 2.0 * np.pi / self.k_max if self.k_max > 0 else np.inf


def fastest_growing_mode(params, k=None, coupled: bool = True, kind: str = "any") -> FastestMode:
    """k_max, its growth rate and wavelength 2 pi / k_max, refined past the k grid by Brent's method.

    ``kind="stationary"`` looks only at real roots (Turing patterns, what a
    simulation shows as spots); ``"oscillatory"`` only at complex ones; the
    default at all roots.  Returns ``growth_rate = -inf`` if no root of that kind exists.
    """
    c = _as_coefficients(params)
    k = default_wavenumbers(c, coupled=coupled) if k is None else np.sort(np.asarray(k, dtype=float))
    return fastest_mode_of(lambda kk: longitudinal_rates(c, kk, coupled, method="qz"), k, kind)


def _band_edge(growth_at, unstable: float, stable: float, steps: int = 40) -> float:
    """The edge of an unstable band between an unstable and a stable k, by bisection (relative 1e-12)."""
    for _ in range(steps):
        middle = 0.5 * (unstable + stable)
        if abs(stable - unstable) <= 1e-12 * abs(middle):
            break
        if growth_at(middle)[0] > 0:
            unstable = middle
        else:
            stable = middle
    return float(unstable)


def fastest_mode_of(rates_at, k, kind: str = "any") -> FastestMode:
    """The fastest mode of a dispersion relation ``rates_at(k) -> roots (k.shape + (n,))`` over a sorted k grid.

    The grid's best k is refined by a bounded Brent search between its neighbours.
    """

    def growth_at(kk):
        return max_growth_of_kind(rates_at(np.atleast_1d(kk)), kind)

    k = checked_wavenumbers(k)
    if k.size == 0:
        raise ValueError("the fastest mode needs at least one wavenumber, got none")
    growth = growth_at(k)
    best = int(np.argmax(growth))
    at_edge = best in (0, k.size - 1)
    k_max = float(k[best])
    if best == 0 and k[0] > 0 and growth_at(0.0)[0] > max(growth[0], 0.0):
        # the homogeneous mode itself grows fastest (e.g. a Hopf instability of the kinetics): k = 0 is no edge
        k_max, at_edge = 0.0, False
    elif not at_edge and np.isfinite(growth[best]):
        found = scipy.optimize.minimize_scalar(
            lambda kk: -float(growth_at(kk)[0]), bounds=(k[best - 1], k[best + 1]), method="bounded",
            options={"xatol": 1e-8 * k[best]})
        if -found.fun >= growth[best]:
            k_max = float(found.x)
    roots = rates_at(np.array([k_max]))[0]
    of_kind = growth_of_kind(roots, kind)
    leading = roots[np.argmax(of_kind)]
    rate = float(np.max(of_kind))
    frequency = float(abs(leading.imag)) if np.abs(leading.imag) > REAL_TOLERANCE * (1 + abs(leading)) else 0.0
    grows = growth > 0
    band = (np.nan, np.nan)
    if np.any(grows):  # the grid's outermost unstable k, refined towards its stable neighbour
        first, last = int(np.argmax(grows)), int(k.size - 1 - np.argmax(grows[::-1]))
        if first > 0:
            low = _band_edge(growth_at, k[first], k[first - 1])
        elif k[0] > 0 and growth_at(0.0)[0] > 1e-10 * abs(rate):  # k = 0 itself grows (beyond the roots' round-off,
            low = 0.0  # below): no edge to seek, where bisecting towards it halved k[0] 40 times and said 9.09e-16
        elif k[0] > 0 and k_max > 0:  # below the grid: ex01a's band is (0, 5.44], its conserved m's root 0 at k = 0
            low = _band_edge(growth_at, k[0], 0.0)  # by bisection towards 0, so also a band that starts above it
            # below it the rate is round-off of the roots (ex01a's ~ 0.086 k^2: ~ 1e-11 at k = 1e-5): it reaches 0
            low = 0.0 if abs(growth_at(0.5 * low)[0]) <= 1e-10 * abs(rate) else low
        else:
            low = min(k_max, float(k[0]))
        band = (low, _band_edge(growth_at, k[last], k[last + 1]) if last < k.size - 1 else float(k[last]))
    elif rate > 0:  # a band narrower than the grid's steps, just past onset: only the refined k_max grows
        band = (_band_edge(growth_at, k_max, k[best - 1]) if best > 0 else k_max,
                _band_edge(growth_at, k_max, k[best + 1]) if best < k.size - 1 else k_max)
    return FastestMode(k_max=k_max, growth_rate=rate, frequency=frequency, band=band, at_edge=at_edge, kind=kind)
