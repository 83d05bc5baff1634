r"""Finite-strain poroelasticity with growth (seed section 4, eqs. (4.5), (4.11), (4.12a)-(4.12c), (4.16a)-(4.16b)).

Unknowns on the reference configuration Omega_0 (Taylor-Hood, seed section 5.1):
the displacement u (P2 vector), the solid pressure psi (P1, the Lagrange
multiplier of J_e = 1) and the fluid pressure p (P1), solved together by
Newton's method (PETSc SNES):

    rho u_tt - Div(P_e + P_f) = 0                                             (4.12a)
    d/dt (C_0 p + alpha_BW (tr C - d)) - (1/J) Div((kappa/eta) J C^-1 Grad p) = ell   (4.12b)
    J_e = 1                                                                   (4.12c)

with F = I + Grad u, C = F^T F, J = det F, the Lee decomposition F = F_e F_g
(4.5), J_e = J / J_g, the neo-Hookean effective stress and the fluid stress

    P_e = J (mu B_e - psi I) F^-T,   B_e = F_e F_e^T                          (4.11)
    P_f = -alpha_BW J p F^-T                                                  (after (4.12c))

F_g and the fluid source ell = ell_0 sum_i d gamma_i/dt come from a growth-law
plugin (:mod:`primordia.physics.growth_laws`, ``[growth_law] name``): growth
driven by the cell density m is declared there, where it couples.  Boundary
conditions per named boundary of Omega_0 (:mod:`primordia.physics.boundary_conditions`):
the springs of (4.16a) (``robin``), u . N_0 = 0 (``normal_displacement``),
p = p_D (``fluid_pressure``), no fluid flux (the natural condition).

Discretisation in time (backward Euler) and weak forms
-------------------------------------------------------
* momentum: rho (u - u^n - dt v^n)/dt^2 . w + (P_e + P_f) : Grad w (v^n the velocity
  of the last step, as in the linear model);
* fluid mass, in conservative form and multiplied by J:
  J [(C_0 p + alpha_BW (tr C - d)) - (C_0 p^n + alpha_BW (tr C^n - d))]/dt q
  + (kappa/eta) J C^-1 Grad p . Grad q - J ell q;
* constraint: -(J - J_g) phi, i.e. J_e = 1 multiplied by J_g > 0, which makes the
  (u, psi) blocks of the tangent each other's transpose.
Integrals use a fixed quadrature degree (option ``quadrature_degree``, default 3:
6 points per triangle, 5 per tetrahedron; the inertia's P2 mass matrix is
integrated exactly, at degree 4): the integrands are rational in Grad u, and
FFCx's own estimate picks hundreds of points per cell.  The manufactured-solution
study keeps the optimal rates at degree 3 (and even 2); on tetrahedra degree 3
costs a third of degree 4 (14 points).  Degree 2 (3 points per triangle) halves
the 2D cost but made Newton stall on the first step of coarse example 2a.

Initial state
-------------
Under the seed's 2D law (4.14) F_g(0) != I (gamma(0) = delta_3 m_0 / (1 + m_0^2)),
so u = 0 is not an equilibrium.  Before the first step the module solves the
static problem (no inertia, p = 0 as in (2.6)) for (u, psi) with the growth
ramped in ``initial_load_steps`` stages, F_g(s) = I + s (F_g(0) - I),
s = 1/N, ..., 1, and then the velocity with which that equilibrium follows the
growth over the first step (one linear solve of the linearised static problem): the run
starts from the equilibrium of its initial growth, moving with it, and p(0) = 0
(option ``initial_equilibrium = false`` skips both).  The seed's u_t(0) = 0 would
have to be accelerated to the growth's rate at once: Newton then fails on the first
step for faster growth (delta_2 = 0.5), at every dt.

The kinematics this module provides to the transport equations
(:mod:`primordia.physics.kinematics`): J, J C^-1, tr C - d, no advecting
velocity (seed (4.17a)-(4.17d)).
"""

from __future__ import annotations

import numpy as np
import ufl

from primordia.core.errors import ConfigError
from primordia.core.parameters import Parameter
from primordia.core.validation import flag, number, numbers
from primordia.physics.base import Diagnostic, FieldSpec, Physics, Subproblem
from primordia.physics.boundary_conditions import conditions_from_config, encloses, refuse_free_rigid_motions
from primordia.physics.growth_laws import fluid_source
from primordia.physics.kinematics import deformation_gradient, finite_strain_kinematics, right_cauchy_green
from primordia.physics.poroelastic_linear import inertia, stress_divergence
from primordia.physics.seed_parameters import POROELASTICITY

GROUP = "poroelastic_growth"


# -- kinematics and stresses of seed section 4 -----------------------------------------------
def elastic_stress(F, F_g, psi, mu):
    """P_e = J (mu B_e - psi I) F^-T, B_e = F_e F_e^T, F_e = F F_g^-1 (seed eqs. (4.5), (4.11))."""
    F_e = F * ufl.inv(F_g)
    B_e = F_e * F_e.T
    return ufl.det(F) * (mu * B_e - psi * ufl.Identity(F.ufl_shape[0])) * ufl.inv(F).T


def fluid_stress(F, p, alpha_BW):
    """P_f = -alpha_BW J p F^-T (seed, after eq. (4.12c))."""
    return -alpha_BW * ufl.det(F) * p * ufl.inv(F).T


# -- the terms of seed eqs. (4.12b), (4.12c), each a UFL integrand ----------------------------
def fluid_content(C_0, alpha_BW, p, C):
    """C_0 p + alpha_BW (tr C - d): what (4.12b) differentiates in time."""
    return C_0 * p + alpha_BW * (ufl.tr(C) - C.ufl_shape[0])


def storage(content, content_previous, J, q, dt, dx):
    """J d/dt (C_0 p + alpha_BW (tr C - d)) (seed eq. (4.12b) times J), backward Euler on the content."""
    return J * (content - content_previous) / dt * q * dx


def darcy_flux(conductivity, eta, J, C, p, q, dx):
    """-Div((kappa/eta) J C^-1 Grad p) in weak form (seed eq. (4.12b) times J)."""
    return conductivity / eta * J * ufl.inner(ufl.inv(C) * ufl.grad(p), ufl.grad(q)) * dx


def growth_source(ell, J, q, dx):
    """-J ell (seed eq. (4.12b) times J): the fluid source that accompanies growth."""
    return -J * ell * q * dx


def incompressibility(J, J_g, phi, dx):
    """J_e = 1 (seed eq. (4.12c)) as -(J - J_g) phi: J_e - 1 times J_g > 0, symmetric with the psi term of P_e."""
    return -(J - J_g) * phi * dx


def fixed_stress_stabilisation(beta_s, beta_f, mu, psi, psi_test, p, p_test, dx):
    """-(beta_s / mu) psi psi* + beta_f p p*: the seed's stabilisation (section 5.2, beta_s = 1, beta_f = 0.1).

    Added to the (psi, p) block of the tangent in the preconditioning matrix, it makes that
    block a sparse approximation of the block's Schur complement (a fixed-stress type splitting,
    Borregales et al. 2018) on which AMG acts.  The psi term carries the sign and the 1/mu scale
    of this formulation: with the constraint written -(J - J_g) psi* the tangent is a symmetric
    saddle point, whose Schur complement in psi is about -M/mu (M the mass matrix); the seed's
    +beta_s psi psi* made GMRES stall here (example 2a at 43 x 43: no convergence in 500 iterations
    where -psi psi*/mu takes 28).
    """
    return (-beta_s / mu * psi * psi_test + beta_f * p * p_test) * dx


def _parameters(*names):
    return tuple(p for p in POROELASTICITY if p.name in names)


class PoroelasticGrowth(Physics):
    """Seed eqs. (4.11), (4.12a)-(4.12c) with a growth-law plugin and boundary conditions (4.16a)-(4.16b)."""

    name = "poroelastic_growth"
    parameters = _parameters("C_0", "kappa", "alpha_BW", "eta", "rho") + (
        Parameter("ell_0", 1e-3, "fluid source per unit growth rate (seed eq. (4.15))", constraint="nonnegative",
                  source="seed section 5.4"),
    )
    needs_growth_law = True
    finite_strain = True
    # 3D: example 4 took 125-128 kB per tetrahedron (4.9 GB at 40 x 40 x 4 boxes, 16.3 GB at 60 x 60 x 6, README
    # "3D under mpirun -n 2"); 80 x 80 x 8 passed the mesh's 4 kB floor and --dry-run, and would need about 38 GB
    min_bytes_per_cell = {3: 100_000}
    options = {"shear_modulus": 4.0, "quadrature_degree": 3, "initial_equilibrium": True, "initial_load_steps": 4,
               "boundary": [], "preconditioner": "auto", "stabilisation": [1.0, 0.1]}

    def __init__(self, params, kinetics=None, growth_law=None, **given):
        super().__init__(params, kinetics=kinetics, growth_law=growth_law, **given)
        self.requires = tuple(growth_law.requires) if growth_law is not None else ()

    def validate_options(self):
        where = f"physics.{self.name}"
        number(self.settings["shear_modulus"], f"{where}.shear_modulus", above=0)
        for key in ("quadrature_degree", "initial_load_steps"):
            number(self.settings[key], f"{where}.{key}", at_least=1, integer=True)
        if self.settings["quadrature_degree"] < 2:  # one point per cell: the P2 displacement's tangent is singular
            raise ConfigError(f"{where}.quadrature_degree = 1 integrates at one point per cell, where the P2 "
                              f"displacement's stiffness is singular (modes that strain no point): at least 2 (the "
                              f"default, 3, keeps the optimal convergence rates)")
        flag(self.settings["initial_equilibrium"], f"{where}.initial_equilibrium")
        if self.settings["preconditioner"] not in PRECONDITIONERS:
            raise ConfigError(f"{where}.preconditioner must be one of {', '.join(PRECONDITIONERS)}, "
                              f"got {self.settings['preconditioner']!r}")
        # [beta_s, beta_f] of seed section 5.2: a psi block of zero, or of the wrong sign, is no preconditioner
        beta_s, beta_f = numbers(self.settings["stabilisation"], f"{where}.stabilisation", length=2)
        number(beta_s, f"{where}.stabilisation[0] (beta_s)", above=0)
        number(beta_f, f"{where}.stabilisation[1] (beta_f)", at_least=0)
        if self.growth_law is None:
            raise ConfigError("physics poroelastic_growth needs a growth law ([growth_law] name = \"...\")")

    def inert_options(self, modules, gdim, solver) -> dict[str, str]:
        """The initial equilibrium's ramp without an initial equilibrium; the Schur split's stabilisation when no
        solve of this module is a fieldsplit (the direct solve factorises the tangent itself: NewtonSolver)."""
        inert = {}
        if not self.settings["initial_equilibrium"]:
            inert["initial_load_steps"] = "initial_equilibrium = false (no initial solve to ramp)"
        direct = self.settings["preconditioner"] == "lu" or (self.settings["preconditioner"] == "auto" and gdim == 2)
        tables = (f"{self.name}", f"{self.name}_initial", "monolithic")
        if direct and not any(_pc_type(solver.get(name)) == "fieldsplit" for name in tables):
            inert["stabilisation"] = ("it preconditions the Schur split's (psi, p) block; the preconditioner here is "
                                      "a direct solve of the tangent (preconditioner = \"schur\" uses it)")
        return inert

    def inert_solver_tables(self) -> dict[str, str]:
        """The initial state's solves under initial_equilibrium = false, which has none."""
        if self.settings["initial_equilibrium"]:
            return {}
        return {f"{self.name}_{initial}": "initial_equilibrium = false (the initial state is not solved)"
                for initial in ("initial", "initial_velocity")}

    def check_composition(self, modules) -> None:
        """The fields the growth law reads are provided by the model's modules (its ``requires``)."""
        provided = {spec.name for module in modules for spec in module.fields()}
        missing = [name for name in self.growth_law.requires if name not in provided]
        if missing:
            raise ConfigError(f"growth law {self.growth_law.name} reads {', '.join(missing)}, which no physics module "
                              f"of this model provides (fields: {', '.join(sorted(provided))})")

    def check_inputs(self, mesh_data, times) -> None:
        """Also the growth law against the mesh's dimension, so that ``--dry-run`` refuses what the set-up would."""
        super().check_inputs(mesh_data, times)
        self.growth_law.check_dimension(mesh_data.gdim)
        if self.growth_law.settings.get("directions") is not None:  # d vectors of d numbers, d the mesh's
            self.growth_law.frame(mesh_data.gdim)
        static = [why for why, holds in (("rho = 0", self.params["rho"] == 0),
                                         ("the initial equilibrium is static", self.settings["initial_equilibrium"]))
                  if holds]
        refuse_free_rigid_motions(f"physics.{self.name}", self.settings["boundary"], mesh_data, times, static,
                                  "momentum balance (seed (4.12a))")
        self._refuse_a_free_pressure_constant(mesh_data)

    def _refuse_a_free_pressure_constant(self, mesh_data) -> None:
        """C_0 = 0 with nothing holding p: (p + c, psi - alpha_BW c) solves (4.12a)-(4.12c) as (p, psi) does, since p
        enters (4.12b) then through Grad p alone and P_e + P_f through psi + alpha_BW p.  The tangent is singular at
        every dt: example 2a with C_0 = 0 was halved down to dt_min, "Newton did not converge"."""
        if self.params["C_0"] != 0:
            return
        conditions = conditions_from_config(self.settings["boundary"], mesh_data, mesh_data.gdim)
        if any(condition.field == "p" and condition.kind != "fluid_flux" for condition in conditions):
            return
        raise ConfigError(f"physics.{self.name}: parameter C_0 = 0 with no fluid_pressure condition leaves the fluid "
                          f"pressure fixed only up to a constant (p + c and psi - alpha_BW c solve seed (4.12a)-(4.12c) "
                          f"as p and psi do); give C_0 > 0 or hold p on a boundary (type = \"fluid_pressure\")")

    def fields(self):
        return [FieldSpec("u", degree=2, vector=True, group=GROUP, displacement=True,
                          description="displacement (reference configuration)"),
                FieldSpec("psi", degree=1, group=GROUP, description="solid pressure (multiplier of J_e = 1)"),
                FieldSpec("p", degree=1, group=GROUP, description="fluid pressure")]

    # -- setup: kinematics, growth, conditions -----------------------------------------------------
    def setup(self, disc):
        self.disc = disc
        self.growth_law.check_dimension(disc.gdim)
        self.dx = disc.dx_degree(self.settings["quadrature_degree"])
        self.dx_inertia = disc.dx_degree(4)  # the P2 mass matrix, exactly
        self.conditions = conditions_from_config(self.settings["boundary"], disc.mesh_data, disc.gdim)
        # why a solve may have no solution, found once (the subproblems are made again at every checkpoint and
        # rejected step, and ``encloses`` took 1.1 s on example 4 at 129,600 tetrahedra)
        self.failure_hint = "; ".join(hint for hint in (_enclosed_hint(self.conditions, disc.mesh_data),
                                                        self._thin_cells_hint(disc.mesh_data)) if hint) or None
        self.velocity = disc.rate("u")
        u, u_previous = disc.field("u"), disc.previous("u")
        kinematics = finite_strain_kinematics(u, u_previous, self.settings["quadrature_degree"])  # (4.17a-d)
        disc.provide_kinematics(kinematics, self.name)
        self.F, self.J = kinematics.deformation_gradient, kinematics.volume_ratio  # the same F, J as the chemistry's
        self.C, self.C_previous = right_cauchy_green(self.F), right_cauchy_green(deformation_gradient(u_previous))
        self.ramp = disc.constant(1.0)  # growth continuation of the initial solve

    def _thin_cells_hint(self, mesh_data) -> str | None:
        """Why the Schur split may fail where a direct solve does not: cells far longer than they are thick (a
        slab thin for its cells).  Example 4 at 4 x 4 x 2 boxes on (0, 10)^2 x (0, 0.01), edges up to 707-fold
        apart, stopped at its initial velocity with GMRES's "DIVERGED_BREAKDOWN" and only "try other options";
        preconditioner = "lu" runs it."""
        split = self.settings["preconditioner"] == "schur" or (self.settings["preconditioner"] == "auto"
                                                                and mesh_data.gdim == 3)
        ratio = _edge_ratio(mesh_data) if split else 0.0  # every cell's edges: only where the hint may apply
        if ratio < THIN_CELLS:
            return None
        return (f"the cells' edges differ up to {ratio:.0f}-fold in length (a slab thin for its cells), where the "
                f"Schur split, 3D's default, can fail: physics.{self.name}.preconditioner = \"lu\" solves directly, "
                f"or use cells closer to even")

    def growth_tensor(self, ramp=None, time=None):
        """F_g of the growth law at the current fields and time (or ``time``); I + s (F_g - I) with a ramp s."""
        disc = self.disc
        fields = {name: disc.field(name) for name in self.growth_law.requires}
        F_g = self.growth_law.growth_tensor(fields, disc.t if time is None else time, disc.x, disc.gdim)
        return F_g if ramp is None else ufl.Identity(disc.gdim) + ramp * (F_g - ufl.Identity(disc.gdim))

    def fluid_source(self):
        """ell = ell_0 sum_i d gamma_i/dt through t and the fields the law reads (seed eq. (4.15))."""
        disc = self.disc
        fields = {name: disc.field(name) for name in self.growth_law.requires}
        # each field's rate over its own last sub-step (disc.span): under strang the chemistry has moved m over
        # dt / 2 when the mechanics runs, and (m - m^n) / dt halved dm/dt in (4.15)
        rates = {name: (disc.field(name) - disc.previous(name)) / disc.span(name) for name in fields}
        return fluid_source(self.growth_law, self.params["ell_0"], fields, rates, disc.t, disc.x, disc.gdim)

    def initialise(self, disc):
        """psi = mu: the stress-free value when F_e = I; u, p start at 0 (seed eq. (2.6)), then the initial solve."""
        disc.interpolate("psi", float(self.settings["shear_modulus"]))

    # -- the balance laws --------------------------------------------------------------------------
    def _stress_terms(self, F_g):
        """(P_e + P_f) : Grad w and the constraint, for a given growth tensor."""
        disc, prm = self.disc, self.params
        u_test, psi_test = disc.test("u"), disc.test("psi")
        P = (elastic_stress(self.F, F_g, disc.field("psi"), self.settings["shear_modulus"])     # (4.11)
             + fluid_stress(self.F, disc.field("p"), prm["alpha_BW"]))                     # P_f of (4.12a)
        return (stress_divergence(P, u_test, self.dx)                                      # (4.12a)
                + incompressibility(self.J, ufl.det(F_g), psi_test, self.dx))              # (4.12c)

    def subproblems(self):
        disc, prm = self.disc, self.params
        u, p = disc.field("u"), disc.field("p")
        u_test, p_test = disc.test("u"), disc.test("p")
        momentum = inertia(prm["rho"], u, disc.previous("u"), self.velocity, u_test, disc.dt, self.dx_inertia)  # (4.12a)
        content = fluid_content(prm["C_0"], prm["alpha_BW"], p, self.C)
        content_previous = fluid_content(prm["C_0"], prm["alpha_BW"], disc.previous("p"), self.C_previous)
        mass = (storage(content, content_previous, self.J, p_test, disc.dt, self.dx)               # (4.12b)
                + darcy_flux(prm["kappa"], prm["eta"], self.J, self.C, p, p_test, self.dx)          # (4.12b)
                + growth_source(self.fluid_source(), self.J, p_test, self.dx))                   # (4.12b), (4.15)
        residual = momentum + self._stress_terms(self.growth_tensor()) + mass + self.conditions.terms(disc)
        for name in ("u", "psi", "p"):
            for term in disc.contributions(name, disc.test(name)):
                residual += term
        unknown = disc.unknown("u")
        return [Subproblem(name=self.name, unknown=unknown, residual=residual,
                           jacobian=ufl.derivative(residual, unknown), bcs=self.conditions.dirichlet(disc), linear=False,
                           **self._solver(), failure_hint=self.failure_hint)]

    def _solver(self) -> dict:
        """Solver defaults, the fields of the unknown and the preconditioning form (seed section 5.2)."""
        disc = self.disc
        beta_s, beta_f = self.settings["stabilisation"]
        stabilisation = fixed_stress_stabilisation(beta_s, beta_f, self.settings["shear_modulus"], disc.trial("psi"),
                                                   disc.test("psi"), disc.trial("p"), disc.test("p"), self.dx)
        return {"petsc_options": _solver_defaults(self.settings["preconditioner"], disc.gdim), "fields": disc.unknown_fields("u"),
                "rigid_body": "u", "preconditioner": stabilisation}

    def initial_subproblems(self):
        """The static equilibrium of the initial growth (no inertia, p = 0), reached by growth continuation.

        None with ``initial_equilibrium = false``: the fields then start as initialised
        (u = 0, psi = mu, p = 0, or as another module set them, e.g. a manufactured solution).
        """
        if not self.settings["initial_equilibrium"]:
            return []
        disc = self.disc
        unknown = disc.unknown("u")
        static = self._static_residual(self.growth_tensor(self.ramp))
        equilibrium = Subproblem(name=f"{self.name}.initial", unknown=unknown, residual=static,
                                 jacobian=ufl.derivative(static, unknown), bcs=self.conditions.dirichlet(disc), linear=False,
                                 continuation=(self.ramp, self.settings["initial_load_steps"]),
                                 **self._solver(), failure_hint=self.failure_hint)
        return [equilibrium, self._initial_velocity()]

    def _static_residual(self, F_g):
        """The static problem of the initial state: no inertia, p = 0 (seed (2.6)).

        The conditions' terms on u only (tractions, springs): a fluid flux belongs to (4.12b), which p = 0
        replaces here (with it, p(0) was the flux on its boundary, and int p dX kept that offset for good).
        """
        disc = self.disc
        return (self._stress_terms(F_g)
                + disc.field("p") * disc.test("p") * self.dx                                 # p(0) = 0 (2.6)
                + self.conditions.terms(disc, "u"))

    def _initial_velocity(self) -> Subproblem:
        """The velocity with which the initial equilibrium follows the growth over the first step.

        The seed's u_t(0) = 0 (2.6) is inconsistent with growth at a finite rate: J_e = 1 makes the
        volume follow J_g at once, so a tissue at rest would have to be accelerated instantly, with a
        solid pressure growing like 1/dt^2 as the step shrinks (Newton then fails on the first step
        for the faster rates, at every dt).  The static equilibrium R(u, psi; t) = 0, linearised,
        moves with dR/d(u, psi) [v, psi_t] = -(R(t_0 + dt) - R(t_0)) / dt at fixed (u, psi): one
        linear solve for the initial rate of the (u, psi, p) group.  The growth's secant over the
        first step, not its derivative at t_0: the laws' in-plane stretches grow like sqrt(t),
        infinitely fast at t = 0 (u_t at fixed cells: the chemistry's own rate is not known yet;
        p_t = 0 as p = 0 holds).  On a boundary with a time-dependent Dirichlet value the rate is
        that value's secant over the first step, as the growth's is.
        """
        disc = self.disc
        unknown, rate = disc.unknown("u"), disc.rate_function("u")
        static = self._static_residual(self.growth_tensor())
        advanced = self._static_residual(self.growth_tensor(time=disc.t + disc.dt))
        residual = ufl.derivative(static, unknown, rate) + (1.0 / disc.dt) * (advanced - static)
        solver = self._solver()
        # One linear solve, not an inexact Newton step: the seed's GMRES rtol 1e-2 would leave the
        # starting velocity, and so the whole run, with two digits.
        solver["petsc_options"].update(ksp_rtol=1e-10, ksp_atol=1e-14, ksp_max_it=2000)
        return Subproblem(name=f"{self.name}.initial_velocity", unknown=rate, residual=residual,
                          jacobian=ufl.derivative(residual, rate), linear=True,
                          bcs=self.conditions.rates(disc, disc.time, float(np.asarray(disc.dt.value))),
                          **solver, failure_hint=self.failure_hint)

    def before_step(self, t, dt):
        self.conditions.update(self.disc, t)

    def diagnostics(self):
        """Current area/volume, the range of J and the constraint residual J_e - 1 (seed (4.12c))."""
        J_g = ufl.det(self.growth_tensor())
        return [Diagnostic("current_volume", "integral", self.J * self.dx,
                           "area (2D) or volume (3D) of the current configuration, int J dX"),
                Diagnostic("J", "extrema", self.J, "volume ratio det F"),
                Diagnostic("J_e_minus_1", "extrema", self.J / J_g - 1.0,
                           "residual of the constraint J_e = 1 (seed eq. (4.12c))")]


#: The seed's block preconditioner (section 5.2): GMRES, lower Schur factorisation u | (psi, p), AMG (GAMG,
#: with the rigid-body near-nullspace) on u, AMG on the (psi, p) block of the tangent plus the
#: stabilisation (the Schur complement approximation), and the seed's inexact Newton (rtol 1e-2, atol 1e-12).
SCHUR_FIELDSPLIT = {
    "ksp_type": "gmres", "ksp_rtol": 1e-2, "ksp_atol": 1e-12, "ksp_max_it": 500, "ksp_gmres_restart": 100,
    "ksp_pc_side": "right",
    "pc_type": "fieldsplit", "splits": [["u"], ["psi", "p"]],
    "pc_fieldsplit_type": "schur", "pc_fieldsplit_schur_fact_type": "lower",
    "pc_fieldsplit_schur_precondition": "a11",
    "fieldsplit_u": {"ksp_type": "preonly", "pc_type": "gamg"},
    "fieldsplit_psi_p": {"ksp_type": "preonly", "pc_type": "hypre"},
    # the AMG hierarchies are kept over Newton and time steps until GMRES needs more than 3 iterations above
    # the most a Newton step needed with them fresh (NewtonSolver).  Kept at all: example 4 at 20 x 20 x 2,
    # 12 steps, 5.1 -> 4.1 s/step.  Relative, not the fixed 25 it was: fresh hierarchies need more on finer
    # meshes (18.3, 20.5, 21.3 a Newton step at 20, 30, 40 boxes a side), and over 8 steps (two alternating
    # repeats) 3,029-3,104 against 3,125-3,495 ms/step at 20 boxes, 11,266-11,334 against 11,671-11,912 at 30
    "rebuild_preconditioner_after": "fresh+3",
    # not read by the fieldsplit: the package of a factorisation of the whole system, should [solver.*] make one
    # (pc_type = "lu"): the zero psi block stops PETSc's unpivoted LU (solver_options.combine keeps it)
    "pc_factor_mat_solver_type": "mumps",
}

#: GMRES preconditioned by a MUMPS LU factorisation kept over Newton iterations and time steps while it
#: works: it is factorised again only after a Newton step needed more than 10 GMRES iterations
#: (``rebuild_preconditioner_after``, NewtonSolver).  Each Newton step is solved inexactly (rtol 1e-3):
#: the kept factorisation is close to the tangent, so Newton still converges in a few iterations, and
#: the SNES tolerances (1e-7 on the residual) decide the accuracy.  Example 2a at 86 x 86: 1.64 s/step
#: against 2.15 s with rtol 1e-8 (1e-2: 2.02, 1e-4: 1.75), with a factorisation every 10 Newton steps.
#: GMRES applies the tangent matrix-free (``snes_mf_operator``): with the kept factorisation it needs
#: about 4 iterations, a residual each, where assembling the P2-P1-P1 tangent costs 8 residuals on
#: fenicsx; the tangent is assembled only to factorise it again.  Example 2a at 171 x 171 on fenicsx:
#: 6.08 against 7.21 s/step, the same Newton and GMRES iterations, fields equal to 1e-11 (86 x 86: 1.64
#: against 1.92 s).  On skfem, whose residuals cost more against its tangents, it is 4% slower at 43 x 43
#: (950 against 912 ms/step): set ``snes_mf_operator = false`` under ``[solver.poroelastic_growth]``.
REUSED_LU = {
    "ksp_type": "gmres", "ksp_rtol": 1e-3, "ksp_atol": 1e-14, "ksp_max_it": 300, "ksp_gmres_restart": 100,
    "pc_type": "lu", "pc_factor_mat_solver_type": "mumps",
    "rebuild_preconditioner_after": 10, "snes_mf_operator": True,
}


#: Values of option ``preconditioner``: "auto" is "lu" in 2D and "schur" in 3D.
PRECONDITIONERS = ("auto", "lu", "schur")


#: Cells whose edges differ more than this many-fold in length are named when a Schur-split solve fails
#: (:meth:`PoroelasticGrowth._thin_cells_hint`): example 4's slab on 4 x 4 x 2 boxes ran at 71 (a thickness of
#: 0.1) and at 141 on 10 x 10 x 2 (0.02), and stopped at 707 (0.01), which the direct solve runs.
THIN_CELLS = 100.0


def _edge_ratio(mesh_data) -> float:
    """The largest ratio of a cell's longest edge to its shortest, over the mesh."""
    corners = mesh_data.points[mesh_data.cells]
    pairs = [(i, j) for i in range(corners.shape[1]) for j in range(i + 1, corners.shape[1])]
    lengths = np.stack([np.linalg.norm(corners[:, i] - corners[:, j], axis=1) for i, j in pairs], axis=1)
    return float(np.max(lengths.max(axis=1) / lengths.min(axis=1))) if len(lengths) else 1.0


def _enclosed_hint(conditions, mesh_data) -> str | None:
    """Why a solve may have no solution, or no unique one: the boundary values of a tissue held on all sides fix
    its volume (not always that of Omega_0: a ``displacement`` may move it) and leave a constant psi free."""
    if not encloses(conditions, mesh_data):
        return None
    return ("every boundary holds the normal displacement, so the boundary values fix the current volume (that of "
            "Omega_0 under u . N_0 = 0) and psi only up to a constant, while J_e = 1 (seed (4.12c)) asks J = J_g: "
            "unless int J_g dX is that volume the growth cannot be accommodated, and if it is the solution is not "
            "unique; free a boundary or hold it with robin springs")


def _solver_defaults(preconditioner: str, gdim: int) -> dict:
    """The solver of the growth system: a reused direct factorisation, or the seed's block preconditioner.

    ``lu``: GMRES on each Newton step, preconditioned by a MUMPS LU factorisation
    kept for up to 10 Newton iterations, across time steps (the tangent changes
    slowly as the tissue grows).  The saddle point (the zero psi block) rules out
    PETSc's unpivoted LU.  ``schur``: :data:`SCHUR_FIELDSPLIT`, whose cost grows
    linearly with the unknowns, where a factorisation's grows faster (in 3D, much).
    """
    if preconditioner == "auto":
        preconditioner = "lu" if gdim == 2 else "schur"
    return dict(REUSED_LU if preconditioner == "lu" else SCHUR_FIELDSPLIT)


def _pc_type(table) -> str | None:
    """The top-level ``pc_type`` a ``[solver.*]`` table gives (PETSc reads option names in any case), if any."""
    if not isinstance(table, dict):
        return None
    return next((str(value) for key, value in table.items() if str(key).lstrip("-").lower() == "pc_type"), None)
