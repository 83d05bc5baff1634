r"""The linear stability analysis of whatever model is composed, derived from its own equations.

Seed section 3 linearises one model, typed in by hand (:mod:`.linearisation`).
Here the same analysis is derived for a composed :class:`~primordia.model.Model`
(physics modules + kinetics + parameters), so that ``primordia stability CONFIG``
analyses exactly the model ``primordia run CONFIG`` runs:

1. **the homogeneous steady state**, from the kinetics: its homogeneous form
   (:meth:`Kinetics.homogeneous`; painter2018: the priming wave saturated,
   w = omega_1) starting from its initial state; a species that does not react
   is conserved and held at its initial value, the others are relaxed to R = 0
   by backward-Euler steps of the well-mixed kinetics with growing time steps
   (pseudo-transient continuation: it ends as Newton's method).  For painter2018
   this is seed eq. (2.6);
2. **the reaction Jacobian** dR/dc, from the kinetics' own ``rates`` evaluated on
   dual numbers (:mod:`.autodiff`): the code the simulation runs, differentiated;
3. **one Fourier symbol per physics module present** (plane waves
   exp(i k.x + phi t), seed Proposition 3.1: grad -> i k, d/dt -> phi),
   ``K = |k|^2``:

   ===============  ===========================================================================
   chemotaxis       each species row: (phi + D_s K) c_s - sum_j dR_s/dc_j c_j, and
                    - chi(c_0) c_0 K c_a for a species climbing attractant a (seed (2.3a)-(2.3d));
                    D_s and the attractants from the kinetics' species declarations
   poroelasticity   u_i: (rho phi^2 + mu K) u_i + (mu + lambda) k_i k.u + i k_i p   (2.1c), (2.2)
                    p:   i alpha_BW phi k.u + (C_0 phi + (kappa/eta) K) p             (2.1a)
                    with the module's own Lame constants (options ``shear_modulus``,
                    ``lame_lambda`` honoured)
   active_stress    u_i: - i s k_i m, s = d sigma_act / dm at m_0 (2.5), by UFL
                    differentiation of the module's ``active_stress``
   mechanochemical  + i xi_f k.u in the rows of the species the kinetics declares
                    ``volume_sink`` (FGF: (2.3c)); the advection u_t . grad c is a product
                    of two perturbations about a homogeneous state: no linear term
   ===============  ===========================================================================

   A third party's module gives its own (:meth:`~primordia.physics.base.Physics.fourier_symbol`),
   possibly with unknowns of its own after the species.
   No mechanics in the model: no u, p rows.  A module with no Fourier symbol
   (here or its own), a spatially varying conductivity, or finite strain (``poroelastic_growth``:
   a growing tissue has no steady state to linearise about, seed section 6) is
   refused in one line; ``chemistry_only=True`` analyses the chemistry alone.

The growth rates phi(k) are the roots of det M(phi, k), M = M0 + phi M1 +
phi^2 M2, by the eigenvalue machinery of :mod:`.dispersion`.  For painter2018
the derived M equals the hand-derived matrix of seed Definition 3.1
(:func:`seed_cross_check`), which stays as the independent check.

From Python::

    from primordia import Model
    from primordia.analysis import linearise_model

    linear = linearise_model(Model.from_file("examples/ex01a.toml"))
    linear.steady_state.values                     # {'m': 0.75, 'e': ..., 'f': ..., 'b': ...}
    mode = linear.fastest_mode(kind="stationary")  # k_max, wavelength, growth_rate
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from primordia.analysis.autodiff import DUAL, Dual, seeded, value_and_gradient
from primordia.analysis.dispersion import (
    FastestMode,
    GrowthRates,
    checked_wavenumbers,
    choose_method,
    fastest_mode_of,
    max_growth_of_kind,
    pencil_roots,
    sort_by_growth,
    split_transverse,
)
from primordia.analysis.linearisation import made_real, wave_vectors
from primordia.core.errors import ConfigError, PluginError, PrimordiaError
from primordia.physics.kinetics.base import Kinetics, kinetics_code

#: Largest number of pseudo-transient steps towards the steady state.
STEADY_STATE_STEPS = 200
#: |R| below this times the reaction scale |dR/dc| (1 + |c|) is a steady state.
STEADY_STATE_TOLERANCE = 1e-13


# -- the steady state and the reaction Jacobian -------------------------------------------------------
#: What the analysis tells of a kinetics' code itself: primordia's one-line errors, and arithmetic that fails with
#: the parameters (:func:`homogeneous_steady_state` blames them); anything else is the kinetics' bug, in one line.
ANALYSED_ERRORS = (PrimordiaError, ArithmeticError)


def reaction_jacobian(kinetics, state: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """(R, dR/dc) at ``state``: the kinetics' own ``rates`` on dual numbers (species order, t = 0)."""
    names = kinetics.species_names
    with kinetics_code(kinetics, "split_rates on dual numbers", ANALYSED_ERRORS):
        rates = kinetics.rates(seeded(state, names), 0.0, DUAL)
    R, J = np.empty(len(names)), np.empty((len(names), len(names)))
    for i, name in enumerate(names):
        R[i], J[i] = value_and_gradient(rates[name], (), len(names))
    return R, J


def conserved_species(kinetics, state: Mapping[str, float]) -> tuple[str, ...]:
    """Species whose split rate is the plain (0, 0): no reaction, conserved."""
    names = kinetics.species_names
    with kinetics_code(kinetics, "split_rates on dual numbers", ANALYSED_ERRORS):
        split = kinetics.split_rates(seeded(state, names), 0.0, DUAL)
    return tuple(name for name in names
                 if not any(isinstance(part, Dual) or part != 0 for part in split[name]))


@dataclass(frozen=True)
class SteadyState:
    """The homogeneous steady state of a kinetics (dimensionless concentrations)."""

    values: dict  #: species -> concentration at rest
    conserved: tuple  #: species that do not react, held at their initial value
    steps: int  #: pseudo-transient steps taken from the initial state (0: it was at rest)
    residual: float  #: max |R| at the state

    def __str__(self) -> str:
        return ", ".join(f"{name} = {value:.6g}" for name, value in self.values.items())


def homogeneous_steady_state(kinetics) -> SteadyState:
    """The state the well-mixed kinetics rests at, from its initial state (see the module docstring).

    Parameters its rates cannot be evaluated with (a Hill exponent P_2 = 2000 overflows K_2^P_2 in
    Python's floats) are one ConfigError naming the kinetics, not a traceback."""
    try:
        return _homogeneous_steady_state(kinetics)
    except ArithmeticError as error:
        reason = "they overflow" if isinstance(error, OverflowError) else f"{type(error).__name__}: {error}"
        raise ConfigError(f"kinetics {kinetics.name}: its rates cannot be evaluated at its initial state with these "
                          f"parameters ({reason})") from None


def _homogeneous_steady_state(kinetics) -> SteadyState:
    names = kinetics.species_names
    with kinetics_code(kinetics, "initial_state on dual numbers", ANALYSED_ERRORS):
        start = kinetics.initial_state(0.0, DUAL)
    state = np.array([float(np.asarray(start[name])) for name in names])
    conserved = conserved_species(kinetics, dict(zip(names, state)))
    free = np.array([name not in conserved for name in names])
    dt, previous, steps = None, None, 0
    while True:
        R, J = reaction_jacobian(kinetics, dict(zip(names, state)))
        residual = float(np.max(np.abs(R[free]), initial=0.0))
        scale = float(np.max(np.abs(J), initial=0.0)) * (1.0 + float(np.max(np.abs(state))))
        if residual <= STEADY_STATE_TOLERANCE * max(scale, 1e-300):
            return SteadyState(dict(zip(names, state.tolist())), conserved, steps, residual)
        if steps == STEADY_STATE_STEPS or not np.isfinite(residual):
            raise ConfigError(f"kinetics {kinetics.name}: no homogeneous steady state reached from its initial "
                              f"state ({', '.join(names)}) in {steps} steps (max |R| = {residual:.3g})")
        free_jacobian = J[np.ix_(free, free)]
        # backward Euler of dc/dt = R(c), the time step growing as the residual falls (SER)
        dt = 1.0 / max(float(np.max(np.abs(free_jacobian))), 1e-12) if dt is None \
            else min(dt * previous / residual, 1e16)
        step = np.linalg.solve(np.eye(free.sum()) / dt - free_jacobian, R[free])
        state[free] += step
        previous, steps = residual, steps + 1


# -- the Fourier symbols of the physics modules --------------------------------------------------------
class FourierSystem:
    """M(phi, k) = M0 + phi M1 + phi^2 M2 being assembled, for wave vectors ``k`` (shape ``batch + (d,)``).

    Unknowns: the displacement u_1..u_d and the pressure p when the model has
    mechanics, then the species in the kinetics' order, then the fields third-party
    modules add (``extra``, see :meth:`~primordia.physics.base.Physics.fourier_symbol`).
    """

    def __init__(self, species: tuple[str, ...], mechanics: bool, k_vector, extra: tuple[str, ...] = ()):
        self.k = np.asarray(k_vector, dtype=float)
        self.d = self.k.shape[-1]
        self.K = np.sum(self.k**2, axis=-1)
        self.displacement = tuple(f"u_{i + 1}" for i in range(self.d)) if mechanics else ()
        self.names = self.displacement + (("p",) if mechanics else ()) + tuple(species) + tuple(extra)
        self._index = {name: i for i, name in enumerate(self.names)}
        n = len(self.names)
        self.M = tuple(np.zeros(self.K.shape + (n, n), dtype=complex) for _ in range(3))

    def add(self, order: int, row: str, column: str, value) -> None:
        """M_order[row, column] += value (broadcast over the wave vectors)."""
        self.M[order][..., self._index[row], self._index[column]] += value


@dataclass(frozen=True)
class SpeciesTransport:
    """chemotaxis: accumulation, diffusion, chemotaxis and linearised reactions of each species (2.3a)-(2.3d)."""

    species: tuple  #: names, in the kinetics' order
    diffusivity: dict  #: species -> D (0 for immobile species)
    chemotactic: tuple  #: (species, attractant, chi(c_0) c_0) for each climbing species
    jacobian: np.ndarray  #: dR/dc at the steady state

    def add_to(self, system: FourierSystem) -> None:
        for i, name in enumerate(self.species):
            system.add(1, name, name, 1.0)  # dc/dt
            system.add(0, name, name, self.diffusivity[name] * system.K)  # -div(D grad c)
            for j, other in enumerate(self.species):
                system.add(0, name, other, -self.jacobian[i, j])  # -R(c), linearised
        for name, attractant, coefficient in self.chemotactic:
            system.add(0, name, attractant, -coefficient * system.K)  # +div(chi(c_0) c_0 grad a)


@dataclass(frozen=True)
class PoroelasticWaves:
    """poroelasticity: momentum (2.1c) with stress (2.2), and fluid mass (2.1a)."""

    mu: float
    lam: float
    rho: float
    C_0: float
    mobility: float  #: kappa / eta
    alpha_BW: float

    def add_to(self, system: FourierSystem) -> None:
        k, u = system.k, system.displacement
        for i, row in enumerate(u):
            system.add(2, row, row, self.rho)  # rho u_tt
            system.add(0, row, row, self.mu * system.K)  # -div(2 mu eps(u)) ...
            for j, column in enumerate(u):
                system.add(0, row, column, (self.mu + self.lam) * k[..., i] * k[..., j])  # ... - grad(lambda div u)
            system.add(0, row, "p", 1j * k[..., i])  # grad p
            system.add(1, "p", row, 1j * self.alpha_BW * k[..., i])  # d/dt alpha_BW div u
        system.add(1, "p", "p", self.C_0)  # d/dt C_0 p
        system.add(0, "p", "p", self.mobility * system.K)  # -div((kappa/eta) grad p)


@dataclass(frozen=True)
class ActiveStressCoupling:
    """active_stress: -div(sigma_act) linearised, - i s k_i m (2.5)."""

    species: str
    slope: float  #: d sigma_act / dm at the steady state

    def add_to(self, system: FourierSystem) -> None:
        for i, row in enumerate(system.displacement):
            system.add(0, row, self.species, -1j * self.slope * system.k[..., i])


@dataclass(frozen=True)
class VolumeSink:
    """mechanochemical: + xi_f div u in the balance of each sink species (2.3c); advection has no linear term."""

    species: tuple
    xi_f: float

    def add_to(self, system: FourierSystem) -> None:
        for name in self.species:
            for j, column in enumerate(system.displacement):
                system.add(0, name, column, 1j * self.xi_f * system.k[..., j])


@dataclass(frozen=True)
class _Context:
    """What the Fourier symbols of the modules are built from."""

    kinetics: object
    steady_state: SteadyState
    jacobian: np.ndarray
    params: Mapping


def _transport(module, context: _Context) -> SpeciesTransport:
    kinetics, rest = context.kinetics, context.steady_state.values
    with kinetics_code(kinetics, "sensitivity on dual numbers"):
        chemotactic = tuple(
            (s.name, s.attractant, float(kinetics.sensitivity(s.name, rest[s.name], DUAL)) * rest[s.name])
            for s in kinetics.species if s.attractant is not None)
    return SpeciesTransport(
        species=kinetics.species_names,
        diffusivity={s.name: float(context.params[s.diffusivity]) if s.mobile else 0.0 for s in kinetics.species},
        chemotactic=chemotactic, jacobian=context.jacobian)


def _poroelastic(module, context: _Context) -> PoroelasticWaves:
    if module.settings.get("conductivity") is not None:
        raise ConfigError("physics.poroelasticity.conductivity varies in space: the plane-wave analysis "
                          "needs a uniform hydraulic conductivity kappa")
    mu, lam = module.lame()
    p = module.params
    return PoroelasticWaves(mu=float(mu), lam=float(lam), rho=p["rho"], C_0=p["C_0"],
                            mobility=p["kappa"] / p["eta"], alpha_BW=p["alpha_BW"])


def active_stress_slope(m0: float, mu: float, lam: float, tau: float, zeta: float) -> float:
    """d sigma_act / dm at m0: the module's own ``active_stress`` (seed (2.5)) differentiated by UFL."""
    import ufl
    from ufl.algorithms import expand_derivatives

    from primordia.physics.active_stress import active_stress

    m = ufl.variable(ufl.as_ufl(float(m0)))
    sigma = active_stress(m, mu, lam, tau, zeta, 1)
    return float(expand_derivatives(ufl.diff(sigma[0, 0], m)))


def _active_stress(module, context: _Context, mechanics: PoroelasticWaves) -> ActiveStressCoupling:
    species = "m"  # the module reads the cell density m (primordia.physics.active_stress)
    if species not in context.steady_state.values:
        raise ConfigError(f"active_stress reads the cell density m, which kinetics {context.kinetics.name} "
                          f"does not declare ({', '.join(context.steady_state.values)})")
    p = module.params
    return ActiveStressCoupling(species, active_stress_slope(context.steady_state.values[species], mechanics.mu,
                                                             mechanics.lam, p["tau"], p["zeta"]))


def _volume_sink(module, context: _Context, mechanics) -> VolumeSink:
    return VolumeSink(tuple(s.name for s in context.kinetics.species if s.volume_sink), module.params["xi_f"])


#: The physics modules the analysis knows, and how each contributes.  The mechanical couplings
#: (active stress, volume sink) also need the poroelastic module's Lame constants.
CHEMISTRY = {"chemotaxis": _transport}
MECHANICS = {"poroelasticity": _poroelastic}
COUPLINGS = {"active_stress": _active_stress, "mechanochemical": _volume_sink}


# -- the linearised model ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class LinearisedModel:
    """A composed model linearised about its homogeneous steady state: M(phi, k) and its roots phi(k)."""

    name: str
    physics: tuple  #: the modules analysed
    kinetics: str
    species: tuple
    steady_state: SteadyState
    reaction_jacobian: np.ndarray  #: dR/dc at the steady state (species order)
    terms: tuple  #: the Fourier symbols, one per module
    mechanics: PoroelasticWaves | None
    parameters: Mapping
    notes: tuple = field(default_factory=tuple)  #: what was left out, and why
    extra: tuple = ()  #: the unknowns third-party modules add, after the species

    # -- the matrix ----------------------------------------------------------------------
    def pencil(self, k_vector) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(M0, M1, M2), complex arrays ``batch + (n, n)`` for wave vectors ``batch + (d,)``."""
        system = FourierSystem(self.species, self.mechanics is not None, k_vector, self.extra)
        for term in self.terms:
            term.add_to(system)
        return system.M

    @property
    def third_party(self) -> tuple[str, ...]:
        """The modules analysed by their own Fourier symbols (:meth:`~primordia.physics.base.Physics.fourier_symbol`),
        which the seed's analysis does not describe."""
        return tuple(name for name in self.physics if name not in CHEMISTRY | MECHANICS | COUPLINGS)

    @property
    def coupled(self) -> bool:
        """Whether the mechano-chemical loop is closed: a volume sink (the chemistry feels the mechanics) and
        an active stress (the mechanics feels the chemistry), seed section 3.6; open otherwise (section 3.4)."""
        kinds = {type(term) for term in self.terms}
        return {VolumeSink, ActiveStressCoupling} <= kinds

    def unknowns(self, d: int) -> tuple[str, ...]:
        return FourierSystem(self.species, self.mechanics is not None, np.zeros(d), self.extra).names

    def matrix(self, phi, k_vector) -> np.ndarray:
        """M(phi, k) = M0 + phi M1 + phi^2 M2."""
        M0, M1, M2 = self.pencil(k_vector)
        phi = np.asarray(phi)[..., None, None]
        return M0 + phi * M1 + phi**2 * M2

    # -- its roots -------------------------------------------------------------------------
    def _method(self) -> str:
        if self.extra:
            return "qz"  # a third party's rows: M1 may be singular there (an equation without d/dt)
        if self.mechanics is None:
            return "standard"  # M1 = I: the eigenvalues of -M0
        return choose_method(self.mechanics.rho > 0 and self.mechanics.C_0 > 0, "auto")

    def _roots(self, k, d: int, direction=None):
        """Every root of det M at |k| = ``k`` (1-D array), wave vectors along ``direction``: (k.size, size)."""
        M0, M1, M2 = self.pencil(wave_vectors(k, d, direction))
        d_u = d if self.mechanics is not None else 0
        if d_u:
            M0, M1, M2 = made_real((M0, M1, M2), d_u)
        size = M0.shape[-1] + d_u
        roots = pencil_roots(M0.real, M1.real, self.mechanics.rho if d_u else 0.0, d_u, self._method(), size)
        roots = roots.astype(complex, copy=False)  # real where every root is: the kinetics' rates at k = 0 may not be
        at_rest = k == 0
        if np.any(at_rest):  # every coupling carries k: the kinetics' rates, and 0 for the mechanics
            chemistry = self._chemistry_at_rest()
            neutral = np.zeros(size - chemistry.size, dtype=complex)
            if self.mechanics is not None and not (self.mechanics.rho > 0 and self.mechanics.C_0 > 0):
                neutral[:] = np.nan  # the degree drops with rho or C_0
            roots[at_rest] = np.concatenate([chemistry, neutral])
        return roots

    def _chemistry_at_rest(self) -> np.ndarray:
        """The roots at k = 0 of the species' rows (the kinetics' rates) and of the fields third-party modules
        add, whose couplings to the mechanics carry k as the built-in ones do."""
        if not self.extra:
            return np.linalg.eigvals(self.reaction_jacobian).astype(complex)
        import scipy.linalg

        M0, M1, _ = self.pencil(np.zeros(1))
        rows = slice(2 if self.mechanics is not None else 0, None)  # u_1 and p at d = 1
        roots = scipy.linalg.eigvals(-M0[rows, rows], M1[rows, rows])
        return np.where(np.isfinite(roots), roots, np.nan).astype(complex)

    def rates(self, k) -> np.ndarray:
        """Roots of the longitudinal (d = 1) dispersion relation at each ``k``, shape ``k.shape + (n,)``.

        Sorted by descending real part; NaN where the degree is lower.  For an isotropic
        model these are every root but the neutral shear waves (see :meth:`growth_rates`).
        """
        k = np.asarray(k, dtype=float)
        return sort_by_growth(self._roots(k.ravel(), 1)).reshape(k.shape + (-1,))

    def growth_rates(self, k, d: int = 2, direction=None) -> GrowthRates:
        """Every root of det M for d = 1, 2, 3, the shear waves (+-i k sqrt(mu/rho), d-1 times) apart."""
        k = checked_wavenumbers(k)
        roots = self._roots(k, d, direction)
        mechanics = self.mechanics
        n_transverse = 2 * (d - 1) if mechanics is not None and mechanics.rho > 0 else 0
        keep = roots.shape[-1] - (2 * (d - 1) if mechanics is not None else 0)
        speed = np.sqrt(mechanics.mu / mechanics.rho) if n_transverse else np.inf
        rates, transverse = split_transverse(roots, speed, k, d, n_transverse, keep)
        transverse[k == 0] = 0.0
        return GrowthRates(k=k, rates=rates, transverse=transverse, d=d)

    def wavenumbers(self, n: int = 241) -> np.ndarray:
        """A log-spaced k grid from 1e-3 past the end of the unstable band.

        The band of a reaction-diffusion(-taxis) system ends near the k where the
        slowest diffusion outruns the fastest reaction, sqrt(max |dR/dc| / min D);
        the grid reaches 3 times that (at least 10), and grows until the top is stable.
        """
        transport = next((t for t in self.terms if isinstance(t, SpeciesTransport)), None)
        mobile = [D for D in (transport.diffusivity.values() if transport else ()) if D > 0]
        reaction = float(np.max(np.abs(self.reaction_jacobian), initial=0.0))
        k_high = max(10.0, 3.0 * np.sqrt(reaction / min(mobile))) if mobile else 10.0
        for _ in range(8):
            if max_growth_of_kind(self.rates(np.array([k_high])))[0] <= 0:
                break
            k_high *= 3.0
        return np.logspace(-3.0, np.log10(k_high), n)

    def fastest_mode(self, kind: str = "any", k=None) -> FastestMode:
        """k_max, growth rate, wavelength 2 pi / k_max (``kind``: "any", "stationary", "oscillatory")."""
        k = self.wavenumbers() if k is None else np.sort(np.asarray(k, dtype=float))
        return fastest_mode_of(self.rates, k, kind)

    def describe(self) -> str:
        mechanics = "with mechanics" if self.mechanics is not None else "no mechanics"
        own = f"; fields of {', '.join(self.third_party)}: {', '.join(self.extra)}" if self.extra else ""
        return (f"physics {', '.join(self.physics)}; kinetics {self.kinetics} (species {', '.join(self.species)})"
                f"{own}; {mechanics}")


#: The seed's full poro-mechano-chemical model (seed section 2): what a parameter set alone describes.
SEED_PHYSICS = ("chemotaxis", "poroelasticity", "active_stress", "mechanochemical")


def linearise_seed(params: Mapping, chemistry_only: bool = False, uncoupled: bool = False) -> LinearisedModel:
    """The linearisation of the seed's full model (painter2018 and :data:`SEED_PHYSICS`) at ``params``."""
    from primordia.core.plugins import lookup

    kinetics = lookup("kinetics", "painter2018")(params)
    modules = [lookup("physics", name)(params, kinetics=kinetics) for name in SEED_PHYSICS]
    return linearise_composition(modules, kinetics, params, name="seed", chemistry_only=chemistry_only,
                                 uncoupled=uncoupled)


def linearise_model(model, chemistry_only: bool = False, uncoupled: bool = False) -> LinearisedModel:
    """The linearisation of a :class:`~primordia.model.Model` (see the module docstring).

    ``chemistry_only``: the kinetics and the transport of its species alone, whatever
    mechanics the model has.  ``uncoupled``: drop the volume sink (xi_f = 0, seed section 3.4).
    """
    return linearise_composition(model.physics_objects, model.kinetics_object, model.parameters,
                                 name=model.name, chemistry_only=chemistry_only, uncoupled=uncoupled)


def linearise_composition(modules, kinetics, params: Mapping, name: str = "", chemistry_only: bool = False,
                          uncoupled: bool = False) -> LinearisedModel:
    """The linearisation of physics ``modules`` (instances) with ``kinetics`` at ``params``."""
    if kinetics is None or not any(module.name in CHEMISTRY for module in modules):
        raise ConfigError("the linear stability analysis linearises reacting, moving species: "
                          "the model needs chemotaxis and a kinetics")
    notes = []
    if chemistry_only:
        dropped = [module.name for module in modules if module.name not in CHEMISTRY]
        modules = [module for module in modules if module.name in CHEMISTRY]
        if dropped:
            notes.append(f"chemistry only: {', '.join(dropped)} left out")
    for module in modules:
        if module.finite_strain:
            raise ConfigError(
                f"{name or 'this model'} grows at finite strain ({module.name}): a growing tissue has no "
                f"homogeneous steady state, so the linear analysis of seed section 3 does not apply (seed "
                f"section 6); --chemistry-only analyses the chemistry alone")
    with kinetics_code(kinetics, "homogeneous"):  # a third party's: one line naming it, as its rates are
        homogeneous = kinetics.homogeneous()
    if not isinstance(homogeneous, Kinetics) or homogeneous.species_names != kinetics.species_names:
        raise PluginError(f"kinetics {kinetics.name}: homogeneous() must return a kinetics of the same species "
                          f"({', '.join(kinetics.species_names)}) for the analysis to linearise, got {homogeneous!r}")
    if homogeneous is not kinetics:  # the steady state printed is not the run's initial state: say which it is
        notes.append(f"kinetics {kinetics.name} linearised where its forcing has settled, not at a run's initial "
                     f"state: {_settled(homogeneous)}")
    rest = homogeneous_steady_state(homogeneous)
    _, jacobian = reaction_jacobian(homogeneous, rest.values)
    context = _Context(homogeneous, rest, jacobian, params)

    terms, mechanics, extra = [], None, ()
    for module in modules:
        if module.name not in CHEMISTRY | MECHANICS | COUPLINGS:
            term = _third_party_symbol(module, context)
            extra += _new_unknowns(module, term, homogeneous.species_names + extra)
            terms.append(term)
        elif module.name in CHEMISTRY:
            terms.append(CHEMISTRY[module.name](module, context))
        elif module.name in MECHANICS:
            mechanics = MECHANICS[module.name](module, context)
            terms.append(mechanics)
    for module in modules:
        if module.name not in COUPLINGS:
            continue
        if mechanics is None:
            raise ConfigError(f"{module.name} couples the species to a solid, but the model has no mechanics "
                              f"(add poroelasticity)")
        if module.name == "mechanochemical" and uncoupled:
            notes.append("uncoupled: the volume sink xi_f div u left out (xi_f = 0)")
            continue
        terms.append(COUPLINGS[module.name](module, context, mechanics))
    if not _lame_from_E_and_nu(mechanics, params):
        notes.append(f"Lame constants from physics.poroelasticity options: mu = {mechanics.mu:g}, "
                     f"lambda = {mechanics.lam:g} (E and nu unused)")
    if uncoupled and "mechanochemical" not in [module.name for module in modules]:
        notes.append("uncoupled: the model has no mechano-chemical loop to cut")
    linear = LinearisedModel(name=name, physics=tuple(module.name for module in modules), kinetics=kinetics.name,
                             species=homogeneous.species_names, steady_state=rest, reaction_jacobian=jacobian,
                             terms=tuple(terms), mechanics=mechanics, parameters=params, notes=tuple(notes),
                             extra=extra)
    if linear.third_party:
        _check_real(linear)
    return linear


def _settled(homogeneous) -> str:
    """What :meth:`Kinetics.homogeneous` returned, in the words of its docstring's first line."""
    summary = (type(homogeneous).homogeneous.__doc__ or "").strip().split("\n")[0].rstrip(".")
    return summary[:1].lower() + summary[1:] if summary else "its homogeneous, autonomous form (Kinetics.homogeneous)"


def _third_party_symbol(module, context: _Context):
    """A third party's module's Fourier symbol (:meth:`~primordia.physics.base.Physics.fourier_symbol`), or
    one line refusing the model when it has none."""
    from primordia.physics.base import module_code

    answer = getattr(module, "fourier_symbol", None)
    if answer is not None:
        with module_code(module, "fourier_symbol"):
            term = answer(context)
    if answer is None or term is None:
        raise ConfigError(f"physics {module.name} has no Fourier symbol (Physics.fourier_symbol): the analysis "
                          f"would not be the model that runs; --chemistry-only (chemistry_only=True) analyses "
                          f"the chemistry alone")
    if not callable(getattr(term, "add_to", None)):
        raise ConfigError(f"physics {module.name}: fourier_symbol() must return an object with add_to(system), "
                          f"got {term!r}")
    return _PluginSymbol(module, term)


class _PluginSymbol:
    """A third party's Fourier symbol, whose ``add_to`` is the plugin's code: an exception there, an entry of
    no order 0-2, of no unknown of the model or not finite, or a declared unknown left without a row, is one
    line naming the module.  They were a RuntimeError, KeyError or IndexError traceback from ``add_to``, a NaN
    refused as "not a real pencil ... without the factor i k", and a matplotlib ValueError traceback once the
    dispersion relation of a singular pencil had been printed."""

    def __init__(self, module, term):
        self.module, self.term = module, term
        self.unknowns = tuple(getattr(term, "unknowns", ()))

    def add_to(self, system: FourierSystem) -> None:
        from primordia.physics.base import module_code

        with module_code(self.module, "fourier_symbol's add_to"):
            self.term.add_to(_CheckedSystem(system, self.module.name))
        for name in self.unknowns:
            row = system.names.index(name) if name in system.names else None
            if row is not None and not any(np.any(M[..., row, :] != 0) for M in system.M):
                raise ConfigError(f"physics {self.module.name}: its Fourier symbol declares the unknown {name!r} "
                                  f"but adds no term to its row (system.add(order, {name!r}, column, value))")


class _CheckedSystem:
    """The :class:`FourierSystem` as a third party's ``add_to`` sees it: ``add`` checks each entry."""

    def __init__(self, system: FourierSystem, module: str):
        self._system, self._module = system, module

    def __getattr__(self, name):
        return getattr(self._system, name)

    def add(self, order: int, row: str, column: str, value) -> None:
        where = f"physics {self._module}: its Fourier symbol"
        if order not in (0, 1, 2):
            raise ConfigError(f"{where} adds a term of order {order!r} (the power of phi: 0, 1 or 2)")
        for which, name in (("row", row), ("column", column)):
            if name not in self._system.names:
                raise ConfigError(f"{where} adds to the {which} {name!r}, no unknown of this model (its unknowns: "
                                  f"{', '.join(self._system.names)}; the module's own go in its unknowns)")
        if not np.all(np.isfinite(value)):
            raise ConfigError(f"{where} adds a value that is not finite at ({row}, {column}), order {order}")
        self._system.add(order, row, column, value)


def _new_unknowns(module, term, taken: tuple[str, ...]) -> tuple[str, ...]:
    """The unknowns ``term`` adds, each a name no species, displacement, pressure or other module has."""
    unknowns = tuple(getattr(term, "unknowns", ()))
    for name in unknowns:
        mechanics = name == "p" or str(name).startswith("u_")
        if not isinstance(name, str) or name in taken or mechanics or unknowns.count(name) > 1:
            raise ConfigError(f"physics {module.name}: its Fourier symbol adds the unknown {name!r}, which is taken "
                              f"or no name (the species: {', '.join(taken)}; u_1..u_d and p: the mechanics)")
    return unknowns


def _check_real(linear: LinearisedModel) -> None:
    """The pencil with a third party's terms stays real after u -> -i u (:func:`.linearisation.made_real`, which
    the roots are found through): else one line, when the model is linearised."""
    try:
        made_real(linear.pencil(np.array([0.7, 0.4])), 2 if linear.mechanics is not None else 0)
    except ValueError:
        raise ConfigError(f"the Fourier symbols of {', '.join(linear.physics)} do not make a real pencil: a "
                          f"term coupling a field to the displacement or pressure without the factor i k of a "
                          f"first derivative (or with it where none belongs)") from None


# -- the cross-check with the hand-derived seed analysis -------------------------------------------------
def seed_cross_check(linear: LinearisedModel, k=(0.0, 0.3, 1.0, 2.7, 8.0), phi=(0.0, 0.7, -1.3 + 0.4j),
                     d: int = 2) -> float | None:
    """max |M_derived - M_seed| / max |M_seed| over ``k``, ``phi`` (wave vectors off the axes, in ``d`` dims).

    M_seed is seed Definition 3.1 as typed in by hand (:mod:`.linearisation`), at the
    model's parameters with xi_f = 0 where the model has no volume sink and tau = 0
    where it has no active stress; without mechanics, its species block.  None when
    the seed's matrix does not describe the model: another kinetics, a third party's
    module, or Lame constants given as options (the seed reads them from E and nu).
    """
    from primordia.analysis.linearisation import linearise, matrix_pencil

    if linear.kinetics != "painter2018" or linear.third_party:
        return None
    values = seed_values(linear.parameters)
    if not _lame_from_E_and_nu(linear.mechanics, values):
        return None
    seed = linearise(seed_model_values(linear)[0])
    direction = np.arange(1.0, d + 1.0) / np.linalg.norm(np.arange(1.0, d + 1.0))
    k_vector = np.asarray(k, dtype=float)[:, None] * direction
    blocks = slice(None) if linear.mechanics is not None else slice(d + 1, None)
    derived = linear.pencil(k_vector)
    hand = [matrix[..., blocks, blocks] for matrix in matrix_pencil(seed, k_vector)]
    worst, scale = 0.0, 0.0
    for value in np.asarray(phi, dtype=complex):
        M_derived = derived[0] + value * derived[1] + value**2 * derived[2]
        M_seed = hand[0] + value * hand[1] + value**2 * hand[2]
        worst = max(worst, float(np.max(np.abs(M_derived - M_seed))))
        scale = max(scale, float(np.max(np.abs(M_seed))))
    return worst / scale


def seed_model_values(linear: LinearisedModel):
    """(the seed's parameters of ``linear``'s model, whether its mechano-chemical loop is closed).

    The seed's model (:data:`SEED_PHYSICS`) read as the composed one: xi_f = 0 where the model
    has no volume sink and tau = 0 where it has no active stress (the loop is then open, seed
    section 3.4), rather than Table 3.1's xi_f = 0.15 and tau = 60 for couplings it does not have.
    A ConfigError when the seed's model does not describe ``linear``'s: another kinetics, a third party's module,
    Lame constants given as options (the seed's model reads E and nu: a map of it, or a sweep's overlay, was
    computed with Table 3.1's E and nu whatever the model's ``shear_modulus`` and ``lame_lambda``).
    """
    if linear.kinetics != "painter2018":
        raise ConfigError(f"{linear.name or 'the model'} uses kinetics {linear.kinetics}: the seed's model "
                          f"(kinetics painter2018) does not describe it")
    if linear.third_party:
        raise ConfigError(f"{linear.name or 'the model'} has physics {', '.join(linear.third_party)}: the seed's "
                          f"model does not describe it")
    kinds = {type(term) for term in linear.terms}
    values = seed_values(linear.parameters)
    if not _lame_from_E_and_nu(linear.mechanics, values):
        raise ConfigError(f"{linear.name or 'the model'} sets its Lame constants by physics.poroelasticity options "
                          f"(mu = {linear.mechanics.mu:g}, lambda = {linear.mechanics.lam:g}): the seed's model reads "
                          f"them from E and nu; give E and nu instead")
    values = values.replace(xi_f=values["xi_f"] if VolumeSink in kinds else 0.0,
                            tau=values["tau"] if ActiveStressCoupling in kinds else 0.0)
    return values, linear.coupled


def _lame_from_E_and_nu(mechanics: PoroelasticWaves | None, params: Mapping) -> bool:
    """Whether the Lame constants of ``mechanics`` are those of E and nu in ``params`` (or there is no mechanics)."""
    from primordia.physics.seed_parameters import lame

    return mechanics is None or np.allclose((mechanics.mu, mechanics.lam), lame(params), rtol=1e-14, atol=0)


def seed_values(params: Mapping):
    """Table 3.1 overridden by the values of ``params`` the seed's model has (others, e.g. growth's, left out)."""
    from primordia.physics.seed_parameters import seed_parameters

    known = seed_parameters()
    names = {declaration.name for declaration in known.declarations()}
    return known.replace(**{name: value for name, value in params.items() if name in names})
