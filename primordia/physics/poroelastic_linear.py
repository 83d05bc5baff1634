r"""Linear Biot poroelasticity with inertia (seed eqs. (2.1a)-(2.1c), (2.2)).

Unknowns: the skeleton displacement u (vector, P1 as in the seed or P2 for a
Taylor-Hood pair) and the pore pressure p (P1), solved together:

    d/dt (C_0 p + alpha_BW div u) - div( (kappa/eta) grad p ) = 0        (2.1a)
    rho d^2u/dt^2 - div sigma = 0                                       (2.1c)
    sigma = lambda (div u) I + 2 mu eps(u) - p I  [+ sigma_act]           (2.1b), (2.2)

with the Lame constants from (E, nu) or given directly (options
``shear_modulus`` / ``lame_lambda``), a hydraulic conductivity kappa that may
vary in space (option ``conductivity``, a formula of x), and boundary
conditions per named boundary (:mod:`primordia.physics.boundary_conditions`).
Note that, as in the seed, the pressure enters the stress with coefficient 1
while the Biot-Willis coefficient weights the volumetric term of the mass balance.

Time discretisation: backward Euler for both, with the inertial term
rho (u^{n+1} - u^n - dt v^n) / dt^2, v^n = (u^n - u^{n-1}) / dt the solid
velocity of the last step (``disc.rate("u")``, also the velocity that advects
the species).  The system is linear: one exact Newton step per time step, with
a constant matrix (assembled and factorised once: PETSc's LU in serial, MUMPS in
parallel, MUMPS also whenever the unpivoted factorisation meets a zero pivot).

Active stress, the FGF sink and the advection of species are couplings declared
in :mod:`primordia.physics.active_stress` and :mod:`primordia.physics.mechanochemical`.
"""

from __future__ import annotations

import ufl

from primordia.core.errors import ConfigError
from primordia.core.expressions import Formula
from primordia.core.validation import number
from primordia.physics.base import GATHERED_RANKS, FieldSpec, Physics, Subproblem, jacobian_is_constant
from primordia.physics.boundary_conditions import conditions_from_config, refuse_free_rigid_motions
from primordia.physics.kinematics import Kinematics
from primordia.physics.seed_parameters import POROELASTICITY, lame

GROUP = "poroelasticity"


# -- the terms of seed eqs. (2.1a)-(2.1c), each a UFL integrand --------------------------------
def strain(u):
    """eps(u) = (grad u + grad u^T) / 2, infinitesimal strain."""
    return ufl.sym(ufl.grad(u))


def poroelastic_stress(u, p, mu, lmbda):
    """sigma_poroelast = lambda (div u) I + 2 mu eps(u) - p I (seed eq. (2.2))."""
    identity = ufl.Identity(len(u))
    return lmbda * ufl.div(u) * identity + 2.0 * mu * strain(u) - p * identity


def inertia(rho, u, u_previous, velocity_previous, w, dt, dx):
    """rho d^2u/dt^2 (seed eq. (2.1c)), backward Euler on (u, v)."""
    return rho * ufl.inner(u - u_previous - dt * velocity_previous, w) / dt**2 * dx


def stress_divergence(sigma, w, dx):
    """-div sigma in weak form: sigma : grad w (seed eq. (2.1c))."""
    return ufl.inner(sigma, ufl.grad(w)) * dx


def fixed_stress(beta, p, q, dx):
    """beta p q: the fixed-stress term (Kim, Tchelepi & Juanes 2011; beta = alpha_BW / (K_dr dt) here, where
    the pressure enters the stress with coefficient 1).  Added to the pressure block of the tangent in the
    preconditioning matrix, it makes that block a sparse approximation of the Schur complement."""
    return beta * p * q * dx


def storage(C_0, alpha_BW, p, p_previous, u, u_previous, q, dt, dx):
    """d/dt (C_0 p + alpha_BW div u) (seed eq. (2.1a)), backward Euler."""
    return (C_0 * (p - p_previous) + alpha_BW * ufl.div(u - u_previous)) / dt * q * dx


def darcy_flux(conductivity, eta, p, q, dx):
    """-div((kappa/eta) grad p) in weak form (seed eq. (2.1a))."""
    return conductivity / eta * ufl.inner(ufl.grad(p), ufl.grad(q)) * dx


class LinearPoroelasticity(Physics):
    """Seed eqs. (2.1a)-(2.1c) with (2.2) and boundary conditions (2.7b)-(2.7c)."""

    name = "poroelasticity"
    provides = ("lame_constants",)  # read by active_stress
    parameters = POROELASTICITY
    options = {"displacement_degree": 1, "shear_modulus": None, "lame_lambda": None,
               "conductivity": None, "boundary": [], "preconditioner": "lu"}

    def validate_options(self):
        if self.settings["displacement_degree"] not in (1, 2):
            raise ConfigError("physics.poroelasticity.displacement_degree must be 1 (P1-P1, the seed's) "
                              "or 2 (Taylor-Hood P2-P1)")
        for key in ("shear_modulus", "lame_lambda"):
            if self.settings[key] is not None:
                number(self.settings[key], f"physics.poroelasticity.{key}", above=0)
        if self.settings["preconditioner"] not in PRECONDITIONERS:
            raise ConfigError(f"physics.poroelasticity.preconditioner must be one of {', '.join(PRECONDITIONERS)}, "
                              f"got {self.settings['preconditioner']!r}")
        if self.settings["conductivity"] is not None:
            Formula(self.settings["conductivity"], dict(self.params), "physics.poroelasticity.conductivity")

    def check_inputs(self, mesh_data, times) -> None:
        """Also refuse rho = 0 when the displacement conditions let a rigid-body motion through: without the
        inertia of (2.1c) the momentum balance then fixes u only up to that motion (a singular matrix)."""
        super().check_inputs(mesh_data, times)
        refuse_free_rigid_motions(f"physics.{self.name}", self.settings["boundary"], mesh_data, times,
                                  ["rho = 0"] if self.params["rho"] == 0 else [],
                                  "quasi-static momentum balance (seed (2.1c))", remedy=" or give rho > 0")

    def lame(self) -> tuple[float, float]:
        """(mu, lambda): given directly, or from E and nu."""
        mu, lmbda = lame(self.params)
        mu = self.settings["shear_modulus"] if self.settings["shear_modulus"] is not None else mu
        lmbda = self.settings["lame_lambda"] if self.settings["lame_lambda"] is not None else lmbda
        return mu, lmbda

    def fields(self):
        return [FieldSpec("u", degree=self.settings["displacement_degree"], vector=True, group=GROUP, displacement=True,
                          description="skeleton displacement"),
                FieldSpec("p", degree=1, group=GROUP, description="pore pressure")]

    def setup(self, disc):
        self.disc = disc
        self.conditions = conditions_from_config(self.settings["boundary"], disc.mesh_data, disc.gdim)
        self.velocity = disc.rate("u")
        disc.provide("lame_constants", self.lame(), self.name)
        # small strain: the species are advected by u_t and the FGF sink reads div u (seed (2.3a), (2.3c))
        disc.provide_kinematics(Kinematics(volume_change=ufl.div(disc.field("u")), velocity=self.velocity),
                                self.name)

    def conductivity(self):
        """kappa(x): the parameter, or the formula of option ``conductivity``."""
        if self.settings["conductivity"] is None:
            return self.params["kappa"]
        return Formula(self.settings["conductivity"], dict(self.params), "conductivity").ufl(self.disc.x, self.disc.t)

    def initialise(self, disc):
        """Seed eq. (2.6): u = 0, du/dt = 0, p = 0 (fields start at zero)."""

    def subproblems(self):
        disc, prm = self.disc, self.params
        u, p = disc.field("u"), disc.field("p")
        u_n, p_n = disc.previous("u"), disc.previous("p")
        w, q = disc.test("u"), disc.test("p")
        mu, lmbda = self.lame()
        momentum = (inertia(prm["rho"], u, u_n, self.velocity, w, disc.dt, disc.dx)               # (2.1c)
                    + stress_divergence(poroelastic_stress(u, p, mu, lmbda), w, disc.dx))       # (2.1c), (2.2)
        mass = (storage(prm["C_0"], prm["alpha_BW"], p, p_n, u, u_n, q, disc.dt, disc.dx)         # (2.1a)
                + darcy_flux(self.conductivity(), prm["eta"], p, q, disc.dx))                   # (2.1a)
        residual = momentum + mass + self.conditions.terms(disc)                                # (2.7b), (2.7c)
        for name, test in (("u", w), ("p", q)):
            for term in disc.contributions(name, test):
                residual += term
        bcs = self.conditions.dirichlet(disc)
        unknown = disc.unknown("u")
        jacobian = ufl.derivative(residual, unknown)
        constant = jacobian_is_constant(jacobian, disc)
        return [Subproblem(name=self.name, unknown=unknown, residual=residual, jacobian=jacobian, bcs=bcs,
                           linear=True, constant_jacobian=constant,
                           petsc_options=_solver_defaults(self.settings["preconditioner"], disc.ranks, disc.gdim,
                                                          constant=constant),
                           fields=disc.unknown_fields("u"), rigid_body="u",
                           preconditioner=fixed_stress(prm["alpha_BW"] / (self.drained_bulk_modulus() * disc.dt),
                                                       disc.trial("p"), q, disc.dx))]

    def drained_bulk_modulus(self) -> float:
        """K_dr = lambda + 2 mu / d: the skeleton's bulk modulus with the fluid free to drain."""
        mu, lmbda = self.lame()
        return lmbda + 2.0 * mu / self.disc.gdim

    def before_step(self, t, dt):
        self.conditions.update(self.disc, t)


#: Values of option ``preconditioner``.
PRECONDITIONERS = ("lu", "fixed_stress")


def _solver_defaults(preconditioner: str, ranks: int, gdim: int, *, constant: bool) -> dict:
    """A direct solve (the matrix is constant: factorised once), or GMRES with the fixed-stress Schur
    fieldsplit: AMG (GAMG with the rigid-body near-nullspace) on u, AMG on the pressure block plus the
    fixed-stress term.  In 2D the reused factorisation is cheaper; the fieldsplit's cost grows linearly.

    In 2D on up to ``GATHERED_RANKS`` ranks a constant matrix is gathered to one rank, which factorises it
    once and solves the whole system (``solve_on_one_rank``, as the species' constant matrices): MUMPS's
    distributed triangular solves cost more than the serial ones.  Example 1b at 171^2 on 2 ranks
    (``benchmarks/bench_solvers.py --share ex01b --sizes 171 --backends fenicsx --steps 100 --warmup 1
    --clock wall --ranks 2``): the (u, p) solves 36.2 ms a step with MUMPS, 20.2 on one rank; the step 53.8
    against 37.1 ms (40 in serial).  In 3D the whole factor on one rank would hold the memory of a serial run.
    """
    if preconditioner == "lu":
        direct = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_ordering_type": "nd"}
        if constant and gdim == 2 and 1 < ranks <= GATHERED_RANKS:
            direct["solve_on_one_rank"] = True
        return direct
    return {"ksp_type": "gmres", "ksp_rtol": 1e-10, "ksp_atol": 1e-14, "ksp_max_it": 500, "ksp_pc_side": "right",
            "pc_type": "fieldsplit", "pc_fieldsplit_type": "schur", "pc_fieldsplit_schur_fact_type": "lower",
            "pc_fieldsplit_schur_precondition": "a11",
            "fieldsplit_u": {"ksp_type": "preonly", "pc_type": "gamg"},
            "fieldsplit_p": {"ksp_type": "preonly", "pc_type": "hypre"}}
