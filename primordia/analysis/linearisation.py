"""The linearised poro-mechano-chemical system of the seed, by hand (seed eq. (3.1), Definition 3.1).

This is the seed's model typed in: the independent cross-check of the analysis
derived from a composed model (:mod:`primordia.analysis.composed`), and what the
closed forms, conditions and patterning spaces of seed section 3 are built on.

The homogeneous steady state (seed eq. (2.6), priming wave saturated,
``w = omega_1``) is perturbed by plane waves ``exp(i k.x + phi t)``; with
Proposition 3.1 (grad -> i k, Laplacian -> -k^2, d/dt -> phi) seed eq. (3.1)
becomes the linear system ``M(phi, k) w = 0`` for ``w = (u_1..u_d, p, m, e, f, b)``.

Derived from the equations, the rows of M read (``K = |k|^2``)::

    u_i:  (mu + lambda) k_i k_j u_j + (rho phi^2 + mu K) u_i + i k_i p - i s k_i m     (momentum)
    p:    i alpha_BW phi k_j u_j + (C_0 phi + (kappa/eta) K) p                           (fluid mass)
    m:    (phi + D_m K) m - E K f                                                      (cells)
    e:    -A_m m + (phi + A_e) e + A_b b                                               (epithelium)
    f:    i xi_f k_j u_j - kappa_F e + (phi + D_f K + delta_F) f                       (FGF)
    b:    -kappa_B H_3 m + (phi + D_b K + delta_B) b                                   (BMP)

with the coefficients of :class:`LinearisedCoefficients`.  This is the seed's
Definition 3.1 with its row ``A_d k_1, A_1 k_2, ...`` read as ``A_d k_2`` (a
typo: the momentum balance gives ``(mu + lambda) k_i k_j`` in every row), and with
the parameters the seed scales to 1 (``gamma, kappa_F, kappa_B, delta_B, D_b``)
kept general, exactly as the simulation's equations keep them.

Everything here broadcasts: a parameter may be a numpy array (a grid of
parameter values for a patterning space), and the wavenumbers an array.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from primordia.core.ops import NUMPY
from primordia.physics.kinetics.painter2018 import Painter2018
from primordia.physics.seed_parameters import lame

#: Order of the unknowns after the d displacement components (rows and columns of M).
SCALAR_UNKNOWNS = ("p", "m", "e", "f", "b")


@dataclass(frozen=True)
class LinearisedCoefficients:
    """Coefficients of seed eq. (3.1) at the steady state (2.6); all dimensionless.

    Values are floats or arrays of one common broadcast shape.
    """

    # steady state (seed eq. (2.6) with w = omega_1)
    m0: np.ndarray  #: cell density at rest
    e0: np.ndarray  #: epithelium activation at rest
    f0: np.ndarray  #: FGF at rest, kappa_F e0 / delta_F
    b0: np.ndarray  #: BMP at rest, kappa_B h_3(m0) m0 / delta_B
    k_on: np.ndarray  #: activation rate kappa_1 omega_1 h_1(m0) + kappa_2 h_2(m0)
    k_off: np.ndarray  #: inactivation rate (1 - h_1(m0)) (kappa_3 + kappa_4 b0)
    # chemistry (Definition 3.1)
    A_m: np.ndarray  #: d/dm of the epithelium source: k_on'(m0)(1 - e0) + h_1'(m0)(kappa_3 + kappa_4 b0) e0
    A_e: np.ndarray  #: k_on + k_off, the relaxation rate of e
    A_b: np.ndarray  #: (1 - h_1(m0)) kappa_4 e0, BMP-driven inactivation
    H_3: np.ndarray  #: d/dm [h_3(m) m] at m0
    chemotactic_coefficient: np.ndarray  #: alpha m0 exp(-gamma m0), the seed's E
    D_m: np.ndarray
    D_f: np.ndarray
    D_b: np.ndarray
    delta_F: np.ndarray
    delta_B: np.ndarray
    kappa_F: np.ndarray
    kappa_B: np.ndarray
    # mechanics
    mu: np.ndarray  #: shear modulus
    lam: np.ndarray  #: Lame's first parameter lambda
    rho: np.ndarray  #: solid density
    C_0: np.ndarray  #: specific storage
    hydraulic_mobility: np.ndarray  #: kappa / eta
    alpha_BW: np.ndarray  #: Biot-Willis coefficient
    #: d sigma_act / dm at m0: (lambda + 2 mu/3) tau (1 - zeta m0^2)/(1 + zeta m0^2)^2
    active_stress_slope: np.ndarray
    xi_f: np.ndarray  #: FGF sink per unit volume change

    @property
    def p_wave_modulus(self):
        """2 mu + lambda, the stiffness of longitudinal (compressional) strain."""
        return 2.0 * self.mu + self.lam

    @property
    def coupling_strength(self):
        """xi_f s E: the product of the three couplings closing the mechano-chemical loop.

        A dilation consumes FGF (xi_f), FGF gradients move cells (E), cells
        push the tissue (s).  Every coupled term of det M carries it.
        """
        return self.xi_f * self.active_stress_slope * self.chemotactic_coefficient

    @property
    def shape(self) -> tuple[int, ...]:
        return np.broadcast_shapes(*(np.shape(getattr(self, f.name)) for f in fields(self)))


def hill_derivative(m, threshold, exponent):
    """d/dm of seed eq. (2.4)'s h(m) = m^P/(K^P + m^P): P K^P m^(P-1)/(K^P + m^P)^2."""
    return exponent * threshold**exponent * m ** (exponent - 1.0) / (threshold**exponent + m**exponent) ** 2


def linearise(params: Mapping) -> LinearisedCoefficients:
    """Coefficients of seed eq. (3.1) from a parameter set (seed names, Table 3.1).

    ``params`` is a :class:`~primordia.core.parameters.ParameterSet` or any
    mapping of seed names to floats or arrays.  The steady state is the
    simulation's own (:meth:`Painter2018.initial_state` with the wave off).
    With neither activation nor inactivation (``k_on = k_off = 0``) every
    ``e`` is at rest; ``e0 = 0`` is taken, and ``A_m = A_e = 0`` regardless.
    """
    m0 = np.asarray(params["m0"], dtype=float)
    p = {**params, "m0": m0}  # an array: k_on = k_off = 0 gives e0 = nan (then 0), not ZeroDivisionError
    kinetics = Painter2018(p, priming_wave=False)
    with np.errstate(divide="ignore", invalid="ignore"):
        rest = kinetics.initial_state(0.0, NUMPY)
    e0 = np.where(np.isfinite(rest["e"]), rest["e"], 0.0)
    b0 = np.asarray(rest["b"], dtype=float)
    k_on = kinetics.activation(m0, 0.0, NUMPY)
    k_off = kinetics.inactivation(m0, b0)

    h1 = kinetics.h(1, m0)
    dh1 = hill_derivative(m0, p["K_1"], p["P_1"])
    dh2 = hill_derivative(m0, p["K_2"], p["P_2"])
    dh3 = hill_derivative(m0, p["K_3"], p["P_3"])
    dk_on = p["kappa_1"] * p["omega_1"] * dh1 + p["kappa_2"] * dh2
    dk_off_dm = -dh1 * (p["kappa_3"] + p["kappa_4"] * b0)
    dk_off_db = (1.0 - h1) * p["kappa_4"]

    mu, lam = lame(p)
    zeta_m2 = p["zeta"] * m0**2
    return LinearisedCoefficients(
        m0=m0,
        e0=e0,
        f0=p["kappa_F"] * e0 / p["delta_F"],
        b0=b0,
        k_on=k_on,
        k_off=k_off,
        # seed eq. (3.1), e-row: linearise k_on(m)(1 - e) - k_off(m, b) e
        A_m=dk_on * (1.0 - e0) - dk_off_dm * e0,
        A_e=k_on + k_off,
        A_b=dk_off_db * e0,
        H_3=kinetics.h(3, m0) + m0 * dh3,
        chemotactic_coefficient=p["alpha"] * m0 * np.exp(-p["gamma"] * m0),
        D_m=p["D_m"], D_f=p["D_f"], D_b=p["D_b"],
        delta_F=p["delta_F"], delta_B=p["delta_B"],
        kappa_F=p["kappa_F"], kappa_B=p["kappa_B"],
        mu=mu, lam=lam, rho=p["rho"], C_0=p["C_0"],
        hydraulic_mobility=p["kappa"] / p["eta"],
        alpha_BW=p["alpha_BW"],
        # seed eq. (2.5) linearised: d/dm [tau m / (1 + zeta m^2)]
        active_stress_slope=(lam + 2.0 * mu / 3.0) * p["tau"] * (1.0 - zeta_m2) / (1.0 + zeta_m2) ** 2,
        xi_f=p["xi_f"],
    )


def _as_coefficients(params_or_coefficients) -> LinearisedCoefficients:
    if isinstance(params_or_coefficients, LinearisedCoefficients):
        return params_or_coefficients
    return linearise(params_or_coefficients)


def wave_vectors(k, d: int, direction=None) -> np.ndarray:
    """Wave vectors ``|k| * direction`` (shape ``k.shape + (d,)``); direction e_1 by default."""
    if direction is None:
        direction = np.eye(d)[0]
    direction = np.asarray(direction, dtype=float)
    if direction.shape != (d,):
        raise ValueError(f"direction must have {d} components, got shape {direction.shape}")
    direction = direction / np.linalg.norm(direction)
    return np.asarray(k, dtype=float)[..., None] * direction


def matrix_pencil(params_or_coefficients, k_vector) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M0, M1, M2) with M(phi, k) = M0 + phi M1 + phi^2 M2 (Definition 3.1, corrected).

    ``k_vector`` has shape ``(..., d)``; the coefficients broadcast against
    ``k_vector[..., 0]``.  Returns complex arrays of shape ``(..., d+5, d+5)``.
    """
    c = _as_coefficients(params_or_coefficients)
    kv = np.asarray(k_vector, dtype=float)
    d = kv.shape[-1]
    K = np.sum(kv**2, axis=-1)
    shape = np.broadcast_shapes(K.shape, c.shape)
    n = d + 5
    M0 = np.zeros(shape + (n, n), dtype=complex)
    M1 = np.zeros_like(M0)
    M2 = np.zeros_like(M0)
    P, M, E, F, B = range(d, d + 5)  # rows/columns of p, m, e, f, b

    def put(matrix, i, j, value):
        matrix[..., i, j] = np.broadcast_to(value, shape)

    for i in range(d):
        for j in range(d):
            # momentum: -div(lambda div u I + 2 mu eps(u)) -> mu K u_i + (mu + lambda) k_i k_j u_j
            put(M0, i, j, (c.mu + c.lam) * kv[..., i] * kv[..., j] + (c.mu * K if i == j else 0.0))
            put(M1, P, j, 1j * c.alpha_BW * kv[..., j])  # d/dt alpha_BW div u
            put(M0, F, j, 1j * c.xi_f * kv[..., j])  # seed eq. (2.3c): FGF sink xi_f div u
        put(M2, i, i, c.rho)  # rho d_tt u
        put(M0, i, P, 1j * kv[..., i])  # grad p
        put(M0, i, M, -1j * c.active_stress_slope * kv[..., i])  # -div(sigma_act^lin)
    put(M1, P, P, c.C_0)  # d/dt C_0 p
    put(M0, P, P, c.hydraulic_mobility * K)  # -div(kappa/eta grad p)
    for row in (M, E, F, B):
        put(M1, row, row, 1.0)  # d/dt of each species
    put(M0, M, M, c.D_m * K)
    put(M0, M, F, -c.chemotactic_coefficient * K)  # div(alpha m0 e^{-gamma m0} grad f)
    put(M0, E, M, -c.A_m)
    put(M0, E, E, c.A_e)
    put(M0, E, B, c.A_b)
    put(M0, F, E, -c.kappa_F)
    put(M0, F, F, c.D_f * K + c.delta_F)
    put(M0, B, M, -c.kappa_B * c.H_3)
    put(M0, B, B, c.D_b * K + c.delta_B)
    return M0, M1, M2


def dispersion_matrix(params_or_coefficients, phi, k_vector) -> np.ndarray:
    """M(phi, k) of Definition 3.1 (seed eq. (3.1) in Fourier space), complex ``(..., d+5, d+5)``."""
    M0, M1, M2 = matrix_pencil(params_or_coefficients, k_vector)
    phi = np.asarray(phi)[..., None, None]
    return M0 + phi * M1 + phi**2 * M2


def real_pencil(params_or_coefficients, k_vector):
    """The pencil of :func:`matrix_pencil` made real by ``u -> -i u`` (same determinant), see :func:`made_real`."""
    return made_real(matrix_pencil(params_or_coefficients, k_vector), np.shape(k_vector)[-1])


def made_real(pencil, d: int):
    """A pencil (M0, M1, M2) whose first ``d`` unknowns are the displacement, made real by ``u -> -i u``.

    Scaling the displacement unknowns by -i and their rows by i is a
    similarity with determinant 1 that removes every imaginary unit (all of
    them sit on a displacement row or column), so the eigenvalues come in
    exact conjugate pairs and real LAPACK routines apply.  A ValueError when an
    imaginary part is left (beyond round-off): a term that couples a field to the
    displacement without the i k of a first derivative, or with it where none belongs.
    """
    n = pencil[0].shape[-1]
    row = np.ones(n, dtype=complex)
    col = np.ones(n, dtype=complex)
    row[:d], col[:d] = 1j, -1j
    out = []
    for matrix in pencil:
        scaled = row[:, None] * matrix * col[None, :]
        if not np.all(np.abs(scaled.imag) <= 1e-14 * (1.0 + np.abs(scaled).max(initial=0.0))):  # NaN too
            raise ValueError("the pencil is not real after u -> -i u")
        out.append(np.ascontiguousarray(scaled.real))
    return tuple(out)
