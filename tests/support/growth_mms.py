r"""Manufactured solutions of the finite-strain growth model (seed section 4), shared by its convergence tests.

Two problems, each an exact solution written once in UFL (on the reference
coordinates X) and a test-only physics module that adds the sources making it
solve the model, registered in the plugin manager like any third-party physics:

* :class:`GrowthProblem` -- seed eqs. (4.11), (4.12a)-(4.12c) for (u, psi, p),
  quasi-static (rho = 0) with a steady exact solution and a large time step, so
  that the spatial error is what remains.  Growth is incompatible (F_g = (1 + s(X)) I
  with s varying in space, from a test growth law registered through the
  ``primordia_growth_laws`` hook), so the stresses are not trivial.  u is fixed on
  ``left`` and ``bottom`` (the exact values), the exact traction P N_0 is applied
  on ``right`` and ``top`` (as a manufactured boundary source), p is fixed on the
  whole boundary; psi is then unique.
* :class:`ReferenceChemotaxisProblem` -- seed eqs. (4.17a)-(4.17d) multiplied by J,
  with the FGF sink xi_f J (tr C - d) and the boundary flux the exact species
  carry through the sheared boundary, on a tissue moving by a prescribed
  deformation (``prescribed_motion``, a test physics that owns u, sets it to the
  exact motion at every step and provides the finite-strain kinematics exactly as
  ``poroelastic_growth`` does).  The species are those of ``mms.py``.

The balance laws are written here again from the seed's equations, not taken
from the code under test.
"""

from __future__ import annotations

import contextlib
from types import SimpleNamespace

import numpy as np
import ufl
from ufl.algorithms import expand_derivatives

from mms import LUMPED, SPECIES, exact_solution, quadrature_dx
from primordia.core import ops as ops_
from primordia.core.plugins import get_plugin_manager, hookimpl
from primordia.physics.base import FieldSpec, Physics
from primordia.physics.growth_laws import GrowthLaw
from primordia.physics.kinematics import Kinematics

MU = 4.0  # the shear modulus of the runs (the option's default, seed section 5.4)
UFL_MATH = SimpleNamespace(sin=ufl.sin, cos=ufl.cos, exp=ufl.exp, pi=ufl.pi)
NUMPY_MATH = SimpleNamespace(sin=np.sin, cos=np.cos, exp=np.exp, pi=np.pi)


# -- exact fields, in one place for UFL and numpy --------------------------------------------------
def growth_stretch(X, math_):
    """s(X): F_g = (1 + s) I, so gamma_i = s^2 for the in-plane factors (roots as printed after (4.12))."""
    return 0.2 + 0.1 * math_.sin(math_.pi * X[0]) * math_.cos(math_.pi * X[1])


def exact_mechanics(X, math_) -> dict:
    """Steady u, psi, p on the unit square (moderate strains: |Grad u| < 0.4)."""
    sin, cos, pi = math_.sin, math_.cos, math_.pi
    u = [0.1 * sin(pi * X[0]) * (1.0 + X[1]), 0.08 * X[0] * X[1] * (1.0 - X[0]) + 0.05 * sin(pi * X[1])]
    return {"u": ufl.as_vector(u) if math_ is UFL_MATH else np.stack(np.broadcast_arrays(*u)),
            "psi": MU + 0.5 * cos(pi * X[0]) * X[1],
            "p": 0.1 + 0.3 * sin(pi * X[0] * X[1])}


class StretchLaw(GrowthLaw):
    """A test growth law: gamma_1 = gamma_2 = s(X)^2, time-independent (no fluid source)."""

    name = "test_mms_stretch"
    requires = ()
    dimensions = (2,)

    def factors(self, fields, t, X, dimension):
        s = growth_stretch(X, UFL_MATH)
        return [s * s, s * s]


# -- the balance laws, written from the seed ---------------------------------------------------------
def first_piola(u, psi, p, F_g, params):
    """P_e + P_f = J (mu B_e - psi I) F^-T - alpha_BW J p F^-T (seed (4.11) and after (4.12c))."""
    F = ufl.Identity(2) + ufl.grad(u)
    J, F_e = ufl.det(F), F * ufl.inv(F_g)
    return J * (MU * F_e * F_e.T - (psi + params["alpha_BW"] * p) * ufl.Identity(2)) * ufl.inv(F).T


class GrowthProblem:
    """Sources of (4.12a)-(4.12c) (rho = 0, steady) for :func:`exact_mechanics`; boundary tractions."""

    fields = ("u", "psi", "p")
    needs_kinetics = False
    traction_boundaries = ("right", "top")

    def dirichlet(self) -> list[dict]:
        u = ["0.1 * sin(pi * x[0]) * (1.0 + x[1])", "0.08 * x[0] * x[1] * (1.0 - x[0]) + 0.05 * sin(pi * x[1])"]
        p = "0.1 + 0.3 * sin(pi * x[0] * x[1])"
        return ([{"boundary": b, "type": "displacement", "value": u} for b in ("left", "bottom")]
                + [{"boundary": b, "type": "fluid_pressure", "value": p} for b in ("left", "right", "bottom", "top")])

    def contributions(self, params, disc) -> list[tuple[str, object]]:
        X = disc.x
        exact = exact_mechanics(X, UFL_MATH)
        u, psi, p = exact["u"], exact["psi"], exact["p"]
        F_g = (1.0 + growth_stretch(X, UFL_MATH)) * ufl.Identity(2)
        P = first_piola(u, psi, p, F_g, params)
        F = ufl.Identity(2) + ufl.grad(u)
        J, C = ufl.det(F), F.T * F
        sources = {
            "u": -ufl.div(P),                                                    # (4.12a), rho = 0
            "psi": -(J - ufl.det(F_g)),                                          # (4.12c) as -(J - J_g)
            "p": -ufl.div(params["kappa"] / params["eta"] * J * ufl.inv(C) * ufl.grad(p)),  # (4.12b) times J
        }
        dx = quadrature_dx(disc)
        terms = [(name, lambda test, s=expand_derivatives(s): -ufl.inner(s, test) * dx) for name, s in sources.items()]
        N = ufl.FacetNormal(disc.mesh.ufl_domain())
        for boundary in self.traction_boundaries:
            ds = disc.ds(boundary)(metadata={"quadrature_degree": 8})
            terms.append(("u", lambda test, ds=ds: -ufl.inner(P * N, test) * ds))
        return terms

    def initialise(self, disc):
        for name in self.fields:
            disc.interpolate(name, lambda x, name=name: exact_mechanics(x, NUMPY_MATH)[name])

    def errors(self, sim) -> dict[str, float]:
        """L2 errors of u, psi, p and the H1 seminorm error of u."""
        disc = sim.disc
        exact = exact_mechanics(disc.x, UFL_MATH)
        dx = quadrature_dx(disc)
        norm = lambda e: float(np.sqrt(sim.backend.assemble_scalar(ufl.inner(e, e) * dx)))  # noqa: E731
        errors = {name: norm(disc.field(name) - exact[name]) for name in self.fields}
        errors["grad u"] = norm(ufl.grad(disc.field("u") - exact["u"]))
        return errors


# -- the chemotaxis on a prescribed moving reference configuration ------------------------------------
def prescribed_motion(X, t, math_):
    """A smooth, growing, shearing motion of the unit square (u(X, 0) != 0 on purpose)."""
    sin, pi = math_.sin, math_.pi
    grow = 0.2 + 0.3 * t
    u = [grow * X[0] + 0.05 * sin(pi * X[1]) * (1.0 + t), 0.5 * grow * X[1] + 0.04 * sin(pi * X[0]) * X[1]]
    return ufl.as_vector(u) if math_ is UFL_MATH else np.stack(np.broadcast_arrays(*u))


class PrescribedMotion(Physics):
    """Owns u and sets it to :func:`prescribed_motion` at every step; provides the finite-strain kinematics."""

    name = "prescribed_motion"
    finite_strain = True

    def fields(self):
        return [FieldSpec("u", degree=2, vector=True, description="prescribed displacement")]

    def setup(self, disc):
        self.disc = disc
        F, F_previous = (ufl.Identity(2) + ufl.grad(disc.field("u")), ufl.Identity(2) + ufl.grad(disc.previous("u")))
        J = ufl.det(F)
        disc.provide_kinematics(Kinematics(volume_ratio=J, volume_ratio_previous=ufl.det(F_previous),
                                           metric=J * ufl.inv(F.T * F), volume_change=ufl.tr(F.T * F) - 2,
                                           deformation_gradient=F, quadrature_degree=4), self.name)

    def _set(self, t):
        self.disc.interpolate("u", lambda x: prescribed_motion(x, t, NUMPY_MATH))

    def initialise(self, disc):
        self._set(disc.time)

    def before_step(self, t, dt):
        self._set(t - dt)
        self.disc.store_previous(["u"])
        self._set(t)

    def subproblems(self):
        return []


class ReferenceChemotaxisProblem:
    """Sources of seed (4.17a)-(4.17d) times J (material accumulation) with the sink xi_f J (tr C - d)."""

    fields = SPECIES
    needs_kinetics = True

    def contributions(self, params, kinetics, disc) -> list[tuple[str, object]]:
        time = ufl.variable(disc.t)
        X = disc.x
        exact = exact_solution(X, time, UFL_MATH)
        F = ufl.Identity(2) + ufl.grad(prescribed_motion(X, time, UFL_MATH))
        J, C = ufl.det(F), F.T * F
        K = J * ufl.inv(C)
        reactions = kinetics.rates({name: exact[name] for name in SPECIES}, time, ops_.UFL.at(X))
        chi = params["alpha"] * ufl.exp(-params["gamma"] * exact["m"])
        fluxes = {"m": K * (params["D_m"] * ufl.grad(exact["m"]) - chi * exact["m"] * ufl.grad(exact["f"])),
                  "e": None, "f": params["D_f"] * K * ufl.grad(exact["f"]), "b": params["D_b"] * K * ufl.grad(exact["b"])}
        terms = []
        N = ufl.FacetNormal(disc.mesh.ufl_domain())
        ds = disc.ds()(metadata={"quadrature_degree": 8})
        for name in SPECIES:
            source = J * (ufl.diff(exact[name], time) - reactions[name])
            if fluxes[name] is not None:
                source -= ufl.div(fluxes[name])
                # the profiles have Grad c . N_0 = 0, but the pulled-back flux K Grad c . N_0 does not vanish
                # once the tissue shears: its boundary value is a source too
                boundary = expand_derivatives(ufl.dot(fluxes[name], N))
                terms.append((name, lambda test, g=boundary: -g * test * ds))
            if name == "f":
                source += params["xi_f"] * J * (ufl.tr(C) - 2)  # (4.17c) times J
            dx = disc.dx_lumped if name in LUMPED else quadrature_dx(disc)
            source = expand_derivatives(source)
            terms.append((name, lambda test, s=source, dx=dx: -ufl.inner(s, test) * dx))
        return terms

    def initialise(self, disc):
        t0 = disc.time
        for name in self.fields:
            disc.interpolate(name, lambda x, name=name: exact_solution(x, t0, NUMPY_MATH)[name])

    def errors(self, sim) -> dict[str, float]:
        disc = sim.disc
        exact = exact_solution(disc.x, disc.t, UFL_MATH)
        dx = quadrature_dx(disc)
        return {name: float(np.sqrt(sim.backend.assemble_scalar((disc.field(name) - exact[name]) ** 2 * dx)))
                for name in self.fields}


# -- registration -----------------------------------------------------------------------------------
def _sources_physics(problem, requires):
    class ManufacturedGrowthSources(Physics):
        name = "manufactured_growth_sources"
        needs_kinetics = problem.needs_kinetics

        def fields(self):
            return []

        def setup(self, disc):
            args = (self.params, self.kinetics, disc) if self.needs_kinetics else (self.params, disc)
            for name, term in problem.contributions(*args):
                disc.contribute(name, term)

        def initialise(self, disc):
            problem.initialise(disc)

        def subproblems(self):
            return []

    ManufacturedGrowthSources.requires = requires
    return ManufacturedGrowthSources


class _Plugin:
    def __init__(self, physics, laws):
        self.physics, self.laws = physics, laws

    @hookimpl
    def primordia_physics(self):
        return self.physics

    @hookimpl
    def primordia_growth_laws(self):
        return self.laws


@contextlib.contextmanager
def registered(problem):
    """Register the problem's source module (and the test growth law, the prescribed motion) for the block."""
    physics = [_sources_physics(problem, problem.fields), PrescribedMotion]
    pm = get_plugin_manager()
    plugin = pm.register(_Plugin(physics, [StretchLaw]), name="tests.support.growth_mms")
    try:
        yield
    finally:
        pm.unregister(name=plugin)
