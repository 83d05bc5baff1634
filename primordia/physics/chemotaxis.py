r"""Transport of the species of a kinetics: diffusion, chemotaxis, reaction (seed eqs. (2.3a)-(2.3d)).

The species, their diffusivities and which one climbs which gradient are
declared by the kinetics plugin (:class:`~primordia.physics.kinetics.base.Species`);
this module states their balance laws once, for whatever species it is given.
For the built-in ``painter2018`` (the seed's m, e, f, b) in the dimensionless
form of seed section 2 (D_b = delta_B = kappa_F = kappa_B = gamma = 1 by
default) they are

    dm/dt = div( D_m grad m - chi(m) m grad f ),  chi(m) = alpha exp(-gamma m)   (2.3a)
    de/dt = R_e(m, e, b, x, t)                                                (2.3b)
    df/dt = div( D_f grad f ) + R_f(e, f)                                     (2.3c)
    db/dt = div( D_b grad b ) + R_b(m, b)                                     (2.3d)

and in general, for each species c with diffusivity D (none: immobile) and
attractant a (none: no chemotaxis), dc/dt = div(D grad c - chi(c) c grad a) + R_c,
with zero-flux boundaries (2.7a) and the kinetics' initial state (seed (2.6) for
painter2018) plus a seeded perturbation of the species declared ``perturbed``
(``perturbation`` x c_0 x U(-1, 1) at each vertex, or a cosine mode).  Couplings
to a moving solid (advection by u_t, the FGF sink xi_f div u) are not stated
here: the module that declares the coupling adds them (``disc.contribute``).

Time discretisation (implicit-explicit, one linear solve per species)
-----------------------------------------------------------------------
Each reaction is split by the kinetics as R_s = P_s - L_s c_s with P_s, L_s >= 0;
production is explicit, loss implicit: P_s and L_s read c_s at the start of its solve
(and the other species as they stand), so each solve is linear and c_s stays >= 0 for
any dt.  With M_L the lumped P1 mass matrix (vertex quadrature) and S the P1
stiffness matrix, one step t_n -> t_{n+1}
solves the species in the kinetics' order (Gauss-Seidel: each solve sees the
species already updated); for painter2018:

    (M_L/dt + A_chi(m^n, f^n)) m^{n+1}               = M_L m^n / dt
    M_L (e^{n+1} - e^n)/dt = M_L [P_e - L_e e^{n+1}]   at (m^{n+1}, b^n, t_{n+1})
    (M_L/dt + D_f S + delta_F M_L) f^{n+1}           = M_L (f^n/dt + kappa_F e^{n+1})
    (M_L/dt + D_b S + delta_B M_L) b^{n+1}           = M_L (b^n/dt + kappa_B h_3(m^{n+1}) m^{n+1})

A_chi is the transport operator of a species that climbs a gradient (the cells).
With ``flux_scheme = "exponential_fitting"`` (default) it is the edge-averaged
exponentially fitted (Scharfetter-Gummel, "EAFE", Xu & Zikatanov 1999)
discretisation of the flux D_m grad m - chi m grad f, chi = chi(m^n) from the
kinetics (alpha exp(-gamma m^n) for painter2018): for every edge ij with stiffness weight
w_ij = -S_ij and Peclet number Pe_ij = chi_ij (f_j - f_i)/D_m, with
chi_ij = chi((m_i + m_j)/2) the sensitivity at the edge midpoint (the mean of
the vertex values of chi over-sharpens steep stripes and keeps them from breaking
into spots), the flux from i to j is
w_ij D_m [B(-Pe_ij) m_i - B(Pe_ij) m_j], B(x) = x/(e^x - 1).
The matrix M_L/dt + A_chi then has non-positive off-diagonals and zero column
sums of A_chi, i.e. it is an M-matrix whenever w_ij >= 0 (weakly acute meshes,
such as squares split in two): m^{n+1} >= 0 for any dt, and the integral of m
(sum of M_L m) is conserved to round-off.  For small Peclet numbers B(x) =
1 - x/2 + O(x^2), the central scheme, so smooth solutions converge at second
order in L2.  ``flux_scheme = "galerkin"`` uses the plain Galerkin form
D_m grad m . grad v - chi m grad f . grad v instead (second order, but m can go
negative: a P1 Galerkin run of seed example 1a reached min m = -0.19 by t = 160).

Because every species solve is linear in its unknown, it is one exact Newton
step on the UFL residual; the f and b matrices are constant and factorised once.
"""

from __future__ import annotations

import numpy as np
import ufl

from primordia.core import compiled
from primordia.core.errors import ConfigError, is_third_party, place_in, warn
from primordia.core.ops import NUMPY, UFL
from primordia.core.validation import number, numbers
from primordia.physics.base import GATHERED_RANKS, Diagnostic, FieldSpec, Physics, Subproblem, jacobian_is_constant
from primordia.physics.edge_flux import ExponentiallyFittedFlux
from primordia.physics.kinetics.base import Species, checked_evaluation, kinetics_code

FLUX_SCHEMES = ("exponential_fitting", "galerkin")
EDGE_OPS = compiled.numpy_ops()  # the sensitivity at every edge at every step: exp by the compiled loop
ACCUMULATIONS = ("material", "conservative")
PERTURBATION_SHAPES = ("random", "cosine")
#: ``solve``: one linear solve per species (IMEX, Gauss-Seidel), or all species in one Newton system.
SOLVES = ("split", "coupled")
#: ``preconditioner`` of the coupled system: a direct solve, or the seed's block Jacobi (section 5.2).
COUPLED_PRECONDITIONERS = ("block_jacobi", "lu")


# -- the terms of seed eqs. (2.3a)-(2.3d) / (4.17a)-(4.17d), each a UFL integrand ---------------
# J (volume ratio) and K (metric J C^-1) come from the kinematics the mechanics provides
# (primordia.physics.kinematics): J = 1 and K = None (identity) without finite strain, so the
# small-strain forms are exactly the terms of (2.3a)-(2.3d).
def accumulation(c, c_previous, test, dt, dx_lumped, volume_ratio=1, volume_ratio_previous=None):
    """d c / d t by backward Euler, lumped, on the reference configuration.

    ``volume_ratio_previous`` None: J (c - c^n)/dt v, the seed's (4.17a) times J (material form:
    c is carried with the tissue and keeps its value as the tissue grows); otherwise
    (J c - J^n c^n)/dt v, the conservative form (the amount J c is what is balanced).
    """
    if volume_ratio_previous is None:
        return _times(volume_ratio, c - c_previous) / dt * test * dx_lumped
    return (volume_ratio * c - volume_ratio_previous * c_previous) / dt * test * dx_lumped


def diffusive_flux(diffusivity, c, test, dx, metric=None):
    """-div(D grad c) in weak form: D grad c . grad v (seed (2.3a)); D J C^-1 Grad c . Grad v (4.17a)."""
    return diffusivity * ufl.inner(_pulled_back(metric, ufl.grad(c)), ufl.grad(test)) * dx


def chemotactic_flux(sensitivity, c, attractant, test, dx, metric=None):
    """+div(chi c grad f) in weak form (seed (2.3a)): -chi c grad f . grad v; with J C^-1 in (4.17a)."""
    return -sensitivity * c * ufl.inner(_pulled_back(metric, ufl.grad(attractant)), ufl.grad(test)) * dx


def reaction(production, loss_rate, c, test, dx_lumped, volume_ratio=1):
    """-R = -(P - L c), lumped (seed (2.3b)-(2.3d)); times J on the reference configuration (4.17b-d)."""
    return -_times(volume_ratio, production - loss_rate * c) * test * dx_lumped


def _pulled_back(metric, gradient):
    """K grad c, or grad c itself when the metric is the identity (``None``)."""
    return gradient if metric is None else ufl.dot(metric, gradient)


def _times(factor, expression):
    """``factor * expression``, leaving the expression untouched for the identity factor 1."""
    return expression if isinstance(factor, (int, float)) and factor == 1 else factor * expression


class Chemotaxis(Physics):
    """Diffusion, chemotaxis and reaction of the kinetics' species (seed eqs. (2.3a)-(2.3d), (2.6), (2.7a)).

    It reads no parameter of its own: diffusivities and sensitivities are the kinetics'.
    """

    name = "chemotaxis"
    needs_kinetics = True
    options = {"flux_scheme": "exponential_fitting", "perturbation": 0.01, "seed": 1,
               "perturbation_shape": "random", "wavenumber": [0.0, 0.0], "accumulation": "material",
               "solve": "split", "preconditioner": "block_jacobi"}

    def validate_options(self):
        where = f"physics.{self.name}"
        for key, allowed in (("flux_scheme", FLUX_SCHEMES), ("accumulation", ACCUMULATIONS),
                             ("perturbation_shape", PERTURBATION_SHAPES), ("solve", SOLVES),
                             ("preconditioner", COUPLED_PRECONDITIONERS)):
            if self.settings[key] not in allowed:
                raise ConfigError(f"{where}.{key} must be one of {', '.join(allowed)}, got {self.settings[key]!r}")
        number(self.settings["perturbation"], f"{where}.perturbation", at_least=0, below=1)
        number(self.settings["seed"], f"{where}.seed", at_least=0, integer=True)
        numbers(self.settings["wavenumber"], f"{where}.wavenumber", length=(1, 2, 3))
        if self.settings["solve"] == "coupled" and self.settings["flux_scheme"] == "exponential_fitting":
            raise ConfigError(f"{where}.solve = \"coupled\" needs flux_scheme = \"galerkin\" "
                              "(the exponentially fitted flux acts on the species as separate fields)")

    def inert_options(self, modules, gdim, solver) -> dict[str, str]:
        """What these settings leave unused: the coupled solve's preconditioner when the species are solved one by
        one, the perturbation's shape options where it has another shape or none, and the conservative
        accumulation on a tissue whose volume ratio J is 1 (no finite strain: J c - J^n c^n is c - c^n)."""
        settings, inert = self.settings, {}
        if settings["solve"] == "split":
            inert["preconditioner"] = ("it is the coupled solve's (solve = \"coupled\"); under solve = \"split\" "
                                       "each species' solver is [solver.chemotaxis_SPECIES]")
        if settings["perturbation"] == 0:
            for key in ("perturbation_shape", "seed", "wavenumber"):
                inert[key] = "perturbation = 0"
        elif settings["perturbation_shape"] == "random":
            inert["wavenumber"] = "it is the cosine perturbation's (perturbation_shape = \"random\")"
        else:
            inert["seed"] = "it seeds the random perturbation (perturbation_shape = \"cosine\")"
        if not any(module.finite_strain for module in modules):
            inert["accumulation"] = "the tissue's volume ratio J is 1 without finite strain, so both forms are one"
        return inert

    def inert_solver_tables(self) -> dict[str, str]:
        """The coupled solve's table under solve = "split", the species' own under solve = "coupled"."""
        if self.settings["solve"] == "split":
            return {self.name: "solve = \"split\" solves the species one by one ([solver.chemotaxis_SPECIES])"}
        return {f"{self.name}_{species.name}": f"solve = \"coupled\" solves the species together ([solver.{self.name}])"
                for species in self.species}

    def check_inputs(self, mesh_data, times) -> None:
        """Also the kinetics' initial state at the mesh's vertices at the first time: parameters it cannot be
        evaluated with (a Hill exponent P_2 = 2000 overflows K_2^P_2) are one line naming the kinetics, not a
        traceback at set-up (or a state of NaNs every step would be rejected for)."""
        super().check_inputs(mesh_data, times)
        wavenumber, gdim = self.settings["wavenumber"], mesh_data.points.shape[1]
        if self.settings["perturbation_shape"] == "cosine" and len(wavenumber) > gdim:
            raise ConfigError(f"physics.{self.name}.wavenumber has {len(wavenumber)} components (one per axis), "
                              f"the mesh is {gdim}D: k_{gdim + 1} would be ignored")
        where = f"kinetics {self.kinetics.name}"
        try:
            with np.errstate(all="ignore"):
                state, _ = checked_evaluation(self.kinetics, times[0], NUMPY.at(tuple(mesh_data.points.T)))
                bad = next((name for name in self.kinetics.species_names
                            if not np.all(np.isfinite(np.asarray(state[name], dtype=float)))), None)
        except (ArithmeticError, ValueError) as error:
            reason = "it overflows" if isinstance(error, OverflowError) else f"{type(error).__name__}: {error}"
            # a third party's kinetics: where in its files, as for its other errors (its bug, or the parameters)
            reason += place_in(error, type(self.kinetics)) if is_third_party(type(self.kinetics)) else ""
            raise ConfigError(f"{where}: the initial state cannot be evaluated with these parameters ({reason}); "
                              f"are they in the model's (dimensionless) units?") from None
        if bad is not None:
            raise ConfigError(f"{where}: the initial state of {bad} is not finite with these parameters; are "
                              f"they in the model's (dimensionless) units?")

    def check_scheme(self, scheme, modules) -> None:
        """Refuse the schemes this module's discretisation is wrong under, before anything is discretised.

        The exponentially fitted flux acts on a species and its attractant as separate fields: a scheme
        that solves either together with another field (``monolithic``) is refused here, so that
        ``primordia run --dry-run`` refuses it too, not only the run's set-up.
        """
        if self.settings["flux_scheme"] == "exponential_fitting":
            shared = {spec.name for specs in scheme.field_groups(modules).values() if len(specs) > 1 for spec in specs}
            if any(species.attractant and {species.name, species.attractant} & shared for species in self.species):
                raise ConfigError(f"flux_scheme = \"exponential_fitting\" needs the species as separate fields; "
                                  f"with the {scheme.name} scheme use physics.chemotaxis.flux_scheme = \"galerkin\"")

    @property
    def species(self) -> tuple[Species, ...]:
        """The transported species, in solve order: the kinetics' declaration."""
        return self.kinetics.species

    def fields(self):
        group = self.name if self.settings["solve"] == "coupled" else None  # coupled: one mixed function
        return [FieldSpec(s.name, degree=1, description=s.description, group=group) for s in self.species]

    def sensitivity(self, species: Species, density, ops):
        """chi(c): the chemotactic flux of ``species`` is chi(c) c grad a (seed eq. (2.3a)), from the kinetics."""
        with kinetics_code(self.kinetics, "sensitivity"):
            return self.kinetics.sensitivity(species.name, density, ops)

    def setup(self, disc):
        self.disc = disc  # the fitted flux's separate fields are checked when the scheme is made (check_scheme)
        self._fitted_operators = {}  # this run's, by species

    def initialise(self, disc):
        """The kinetics' initial state (seed eq. (2.6)), the perturbed species perturbed at the vertices."""
        t0 = disc.time
        for species in self.species:
            if species.perturbed:
                points = disc.mesh_data.points
                state = self.kinetics.initial_state(t0, NUMPY.at(tuple(points.T)))[species.name]
                disc.set_vertex_values(species.name, np.broadcast_to(state, len(points))
                                       * (1.0 + self.settings["perturbation"] * self._perturbation(points)))
            else:
                disc.interpolate(species.name, lambda x, name=species.name: np.broadcast_to(
                    self.kinetics.initial_state(t0, NUMPY.at(x))[name], x.shape[1:]).copy())

    def _perturbation(self, points: np.ndarray) -> np.ndarray:
        """Relative perturbation of the perturbed species at the vertices: U(-1, 1) noise, or prod_i cos(k_i x_i)."""
        if self.settings["perturbation_shape"] == "random":
            return np.random.default_rng(self.settings["seed"]).uniform(-1.0, 1.0, len(points))
        shape = np.ones(len(points))
        for axis, k in enumerate(self.settings["wavenumber"][: points.shape[1]]):
            shape *= np.cos(k * points[:, axis])
        return shape

    def _reactions(self, lagged: str | None = None):
        """Every species' (production, loss rate); ``lagged``: that species read at the start of its own solve.

        The split solve treats production explicitly and the loss implicitly (module docstring): a species'
        own production and loss rate must not read its unknown.  They did, through the current fields: the
        solve was then one Newton step of the fully implicit reaction (Schnakenberg's u^2 v, the activator's
        own production), whose matrix M_L (1/dt + L - dP/du) loses its diagonal once dt dP/du > 1 + dt L,
        and with it the non-negativity the split promises for any dt."""
        state = {s.name: self.disc.field(s.name) for s in self.species}
        if lagged is not None:
            state[lagged] = self.disc.previous(lagged)
        with kinetics_code(self.kinetics, "split_rates"):
            return self.kinetics.split_rates(state, self.disc.t, UFL.at(self.disc.x))

    def _balanced_volume_ratio(self, species: Species):
        """J where ``species`` was last balanced (J_b of the conservative accumulation J c - J_b c^n): J of the
        displacement as it stood at the end of the species' last sub-step, so that each volume change is
        counted once whatever the scheme (strang's half steps straddle the mechanics)."""
        motion, displacement = self.disc.kinematics, self.disc.displacement_field()
        if motion.volume_ratio_of is None or displacement is None:
            return motion.volume_ratio_previous
        return motion.volume_ratio_of(self.disc.at_balance(displacement, of=species.name))

    def species_residual(self, species: Species, reactions) -> ufl.Form:
        """The residual of one species: the terms of its balance law (+ contributed couplings).

        Read on the kinematics of the run (J, J C^-1: seed (4.17a)-(4.17d) multiplied by J), which
        are the identity without finite strain (seed (2.3a)-(2.3d)).
        """
        disc, motion = self.disc, self.disc.kinematics
        dx = disc.dx_degree(motion.quadrature_degree) if motion.moves else disc.dx
        c, c_previous, test = disc.field(species.name), disc.previous(species.name), disc.test(species.name)
        conservative = self.settings["accumulation"] == "conservative" and species.diffusivity is not None
        residual = accumulation(c, c_previous, test, disc.dt, disc.dx_lumped, motion.volume_ratio,
                                self._balanced_volume_ratio(species) if conservative else None)  # (2.3a-d), (4.17a-d)
        production, loss_rate = reactions[species.name]
        if production != 0 or loss_rate != 0:
            residual += reaction(production, loss_rate, c, test, disc.dx_lumped, motion.volume_ratio)  # (2.3b-d)
        if species.diffusivity is not None and not self._fitted(species):
            residual += diffusive_flux(self.params[species.diffusivity], c, test, dx, motion.metric)  # (2.3a,c,d)
        if species.attractant is not None and not self._fitted(species):
            chi = self.sensitivity(species, disc.previous(species.name), UFL)
            residual += chemotactic_flux(chi, c, disc.previous(species.attractant), test, dx,
                                         motion.metric)  # (2.3a)
        for term in disc.contributions(species.name, test):  # couplings, e.g. advection and the FGF sink
            residual += term
        return residual

    def diagnostics(self):
        """On a moving reference configuration: the cells it holds, int J m dX (lumped, as the accumulation)."""
        motion = self.disc.kinematics
        if not motion.finite_strain or "m" not in self.kinetics.species_names:
            return []
        diagnostics = [Diagnostic("cell_amount", "integral",
                                  motion.volume_ratio * self.disc.field("m") * self.disc.dx_lumped,
                                  "cells in the current configuration, int J m dX over the reference one")]
        for name, operator in self._fitted_operators.items():
            diagnostics += [Diagnostic(f"{name}_negative_edge_weights", "value",
                                       lambda operator=operator: operator.negative_weights,
                                       f"edges with a negative weight in the metric's stiffness: the "
                                       f"transport matrix of {name} is not an M-matrix there"),
                            Diagnostic(f"{name}_most_negative_edge_weight", "value",
                                       lambda operator=operator: operator.most_negative_weight,
                                       "the most negative edge weight relative to the largest (0: an M-matrix)")]
        return diagnostics

    def nonnegative_fields(self):
        """The chemotactic species whose balance law only this module states: the fitted flux makes their matrix
        an M-matrix at small strain (module docstring).  A term another module adds can break that (the solid's
        explicit advection of m in example 1b, :mod:`~primordia.physics.mechanochemical`): there m dips below zero
        on coarse meshes (min m -0.011, -0.005, -0.0025 on 16^2, 32^2, 64^2 over 2,600 steps; 4e-8 on the seed's
        171^2), a spatial artefact a smaller dt does not remove, which series.nc records.  So can a mesh whose
        stiffness has negative edge weights (obtuse angles opposite a boundary edge, or summing past 180 degrees
        opposite an inner one): its fitted operator warns of it, and the field is not promised either."""
        if self.disc.kinematics.metric is not None:
            return ()
        return tuple(species.name for species in self.species
                     if self._fitted(species) and not self.disc.contributors(species.name)
                     and not self._has_negative_weights(species))

    def _has_negative_weights(self, species: Species) -> bool:
        """Whether the species' fitted operator found edges of negative weight (not an M-matrix) at its last update."""
        operator = self._fitted_operators.get(species.name)
        return operator is not None and operator.negative_weights > 0

    def _fitted(self, species: Species) -> bool:
        return species.attractant is not None and self.settings["flux_scheme"] == "exponential_fitting"

    def subproblems(self):
        if self.settings["solve"] == "coupled":
            return [self._coupled(self._reactions())]
        problems = []
        for species in self.species:
            unknown = self.disc.unknown(species.name)
            residual = self.species_residual(species, self._reactions(lagged=species.name))
            jacobian = ufl.derivative(residual, unknown)
            operator = None
            if self._fitted(species):
                motion = self.disc.kinematics
                operator = ExponentiallyFittedFlux(  # (2.3a): D_m grad m - chi m grad f, fitted
                    self.disc, species.name, species.attractant,
                    diffusivity=self.params[species.diffusivity],
                    sensitivity=lambda c, species=species: self.sensitivity(species, c, EDGE_OPS),
                    metric=motion.metric, quadrature_degree=motion.quadrature_degree,
                )
                if species.name not in self._fitted_operators and motion.metric is None:  # once a run
                    _warn_of_negative_weights(species.name, operator, self.disc.mesh_data.gdim)
                self._fitted_operators = {**self._fitted_operators, species.name: operator}
            constant = jacobian_is_constant(jacobian, self.disc)
            problems.append(Subproblem(
                name=f"{self.name}.{species.name}", unknown=unknown, residual=residual, jacobian=jacobian,
                linear=True, constant_jacobian=constant,
                operator=operator, petsc_options=_solver_defaults(species, self.disc.ranks, constant=constant),
            ))
        return problems


    def _coupled(self, reactions) -> Subproblem:
        """All species in one Newton system: the reactions implicit in every species (seed section 5.1)."""
        first = self.species[0].name
        unknown = self.disc.unknown(first)
        residual = sum((self.species_residual(species, reactions) for species in self.species[1:]),
                       self.species_residual(self.species[0], reactions))
        return Subproblem(name=self.name, unknown=unknown, residual=residual,
                          jacobian=ufl.derivative(residual, unknown), linear=False,
                          fields=self.disc.unknown_fields(first),
                          petsc_options=_coupled_defaults(self.settings["preconditioner"], self.species))


def _warn_of_negative_weights(name: str, operator: ExponentiallyFittedFlux, gdim: int) -> None:
    """One warning when the fixed mesh's stiffness has edges of negative weight, where the fitted flux's matrix is
    not an M-matrix (module docstring): the run neither keeps ``name`` >= 0 there nor rejects a step for it."""
    if not operator.negative_weights:
        return
    count = operator.negative_weights
    cause, remedy = (("angles opposite an inner edge summing past 180 degrees, or an obtuse angle opposite a boundary "
                      "edge", "a Delaunay triangulation with no obtuse angle at the boundary has none") if gdim == 2
                     else ("obtuse dihedral angles opposite them", "a mesh with no obtuse dihedral angle, such as a "
                           "box's, has none"))
    warn(f"the mesh has {count} edge{'s' if count > 1 else ''} of negative stiffness weight ({cause}): the "
         f"exponentially fitted flux no longer keeps {name} >= 0, so a negative {name} is recorded (series.nc's "
         f"{name}_min), not rejected; {remedy}")


def _coupled_defaults(preconditioner: str, species: tuple[Species, ...]) -> dict:
    """The coupled species' solver: a direct solve, or the seed's block Jacobi (section 5.2).

    Block Jacobi: GMRES preconditioned additively by each species' diagonal block,
    AMG (BoomerAMG) on the transported ones (m, f, b) and Jacobi on the immobile
    ones (e, whose block is a lumped, diagonal matrix).
    """
    if preconditioner == "lu":
        return {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_ordering_type": "nd"}
    blocks = {f"fieldsplit_{s.name}": {"ksp_type": "preonly", "pc_type": "jacobi" if s.diffusivity is None else "hypre"}
              for s in species}
    return {"ksp_type": "gmres", "ksp_rtol": 1e-8, "ksp_atol": 1e-14, "pc_type": "fieldsplit",
            "pc_fieldsplit_type": "additive", **blocks}


def _solver_defaults(species: Species, ranks: int, *, constant: bool) -> dict:
    """Direct solves for constant symmetric matrices on few ranks, Krylov for the rest (overridable).

    A constant matrix is factorised once, so in serial each step costs two triangular
    solves.  On up to ``GATHERED_RANKS`` ranks the whole matrix is gathered to one rank,
    which factorises it once and solves the whole system (``solve_on_one_rank``); f and b,
    which do not read each other, are solved at once, f by rank 0 and b by rank 1
    (:func:`~primordia.coupling.solvers.solve_in_turn`), each rank holding one serial
    factorisation.  Measured on example 1a on 2 ranks (``benchmarks/bench_scaling.py
    --examples ex01a --steps 100 --repeats 3 --solves``): f and b 2.3 ms/step each at 171
    (4.3-4.4 in serial), 15.9 at 342 (29-31 in serial).  Before, every rank factorised both
    and solved both (``redundant``): 2.8, 13.4 and 60 ms each at 171, 342 and 684 cells per
    side, as in serial, against 12-15, 59-66 and 311-314 ms for CG with BoomerAMG to 1e-12
    (7 iterations), and about 21 ms at 171 for MUMPS's distributed triangular solves.  AMG
    is 4.4 to 5.4 times the redundant solve on 2 ranks; if it scaled perfectly it would catch
    up near 9 to 11 ranks, so from 9 ranks on the symmetric positive definite matrices of the diffusing
    species get CG with BoomerAMG (set up once, the matrix is constant).  A matrix that
    changes (a growing tissue's metric, example 2a) is mass-dominated at the seed's time
    steps, so on up to ``GATHERED_RANKS`` ranks it gets CG with an incomplete Cholesky
    factorisation of each rank's block, kept over solves while it works: a factorisation at
    every solve costs more, and so does AMG's set-up.  Example 2a, f and b linear-solve ms
    per step (``primordia run examples/ex02a.toml`` for 5-10 steps, ``summary.json``; session
    of 2026-12-03): at 171 x 171 squares 95 and 117 with BoomerAMG against 12 and 19 (on 2
    ranks 61 and 73 against 12 and 18); at 86 x 86 21 and 32 against 2.1 and 3.0; before,
    LU cost 316 and 304 at 171.  CG needs 6-9 iterations a solve in serial, twice that on 2
    ranks (additive Schwarz with overlap, symmetric, saves a fifth of them and no time).
    Example 4 (small, 20 x 20 x 2): 10.6 and 13.1 against 0.9 and 1.2.
    """
    if species.diffusivity is None:  # lumped mass + lumped reaction: a diagonal matrix
        return {"ksp_type": "preonly", "pc_type": "jacobi"}
    if species.attractant is not None:  # nonsymmetric M-matrix, rebuilt every step
        # ILU on each rank's rows; on several ranks additive Schwarz (one layer of overlap at first: per step
        # on 2 ranks at 171, 342, 684 cells per side 4.8, 33.9, 255 ms against 5.6, 39.8, 331 for block
        # Jacobi, whose iterations double on 2 ranks; GASM with three layers since, below).  On one rank
        # additive Schwarz is the same ILU with more overhead
        # (7.4 against 5.3 ms at 171), so serial keeps block Jacobi.  The preconditioner of an earlier
        # step's matrix is kept until a solve needs one iteration more than the first after its build
        # (f moves little in a step): additive Schwarz extracts its overlapping blocks and factorises them
        # at every build.  Example 1a at 171 over 200 steps (bench_scaling.py --steps 200 --repeats 3):
        # the solve 4.3 -> 3.8 ms/step in serial, 3.8 -> 2.8 on 2 ranks, 12 and 6-9 builds.  The ILU
        # works on a reverse Cuthill-McKee ordering of each block: in serial at 43, 86, 171, 342 cells per
        # side 4.0, 4.9, 6.7, 11.1 GMRES iterations against 4.9, 5.8, 7.7, 11.6 with the backend's DOF
        # order; the solve at 171 3.3 against 4.2 ms/step on fenicsx, 3.4 against 5.2 on skfem, and on 2
        # ranks 8.5 against 9.2 iterations.  Two layers of overlap: over 1,200 steps of example 1a at 171
        # on 2 ranks 7.52 GMRES iterations a solve against 8.47 with one (7.2 in serial), 2.83-2.97
        # against 3.21-3.30 ms/step; at 342 over 400 steps 11.3 against 12.3 iterations, 18.1-19.2
        # against 20.0-21.0 ms; three layers 7.36 iterations at 171, no faster.  One level of fill (ILU(1)):
        # example 1a in serial at 43, 86, 171, 342 cells per side 3.2, 4.0, 5.7, 8.3 GMRES iterations
        # against 4.0, 4.9, 6.8, 10.9 with ILU(0), the solve 0.20, 0.82, 4.2-4.3, 24.6 against 0.19, 0.85,
        # 4.6-4.9, 32.2 ms/step (skfem at 171 4.38 against 4.88); on 2 ranks at 171 6.2 against 7.5
        # iterations, 2.9-3.2 against 3.0-4.0 ms, at 342 8.5 against 10.9, 15.1 against 19.2 ms (the step
        # 37.9 against 47.8); peak memory the same to 1% (session of 2026-12-05, 40-1,000 steps a size).
        # On several ranks the additive Schwarz is PETSc's GASM, not ASM: the same restricted additive
        # Schwarz with one subdomain a rank (two layers of overlap gave the same 6.22 GMRES iterations at 171
        # on 2 ranks), with fewer copies an application (2.26 against 2.45-2.53 ms a step).  Three layers:
        # at 171 on 2 ranks over 1,000 steps 5.75 iterations (5.72 in serial) and 2.2 ms a step; at 342 over
        # 200 steps 8.6 (8.5 in serial), 12.7 against ASM's 18.0 ms (13.0 iterations with two layers, 12.95
        # with three); four layers no fewer (5.73, 8.54); ILU(0) and ILU(2) slower (2.54 and 2.33 ms at 171).
        # Example 1a's 2-rank speedup 1.52 -> 1.59 (bench_scaling.py --examples ex01a --solves --steps 1000
        # --repeats 3; AVX-512 EPYC, a later session of 2026-12-05), and 1.62-1.66 with --repeats 7 once the
        # fitted operator's values went straight into PETSc's blocks (edge_flux._in_blocks)
        if ranks > 1:
            preconditioner = {"pc_type": "gasm", "pc_gasm_overlap": 3}
        else:
            preconditioner = {"pc_type": "bjacobi"}
        return {"ksp_type": "gmres", **preconditioner, "ksp_rtol": 1e-12, "ksp_atol": 1e-14,
                "rebuild_preconditioner_after": "fresh+1", "sub_pc_factor_mat_ordering_type": "rcm",
                "sub_pc_factor_levels": 1}
    cg = {"ksp_type": "cg", "ksp_rtol": 1e-12, "ksp_atol": 1e-14}
    if ranks > GATHERED_RANKS:
        return {**cg, "pc_type": "hypre"}
    if not constant:
        return {**cg, "pc_type": "bjacobi", "sub_pc_type": "icc", "rebuild_preconditioner_after": "fresh+1"}
    direct = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_ordering_type": "nd"}
    return {**direct, "solve_on_one_rank": True} if ranks > 1 else direct
