r"""Manufactured solutions of the finite-strain growth model (seed section 4), shared by its convergence tests.

Two problems, each an exact solution written once in UFL (on the reference
coordinates X) and a test-only physics module that adds the sources making it
solve the model, registered in the plugin manager like any third-party physics:

* :class:`GrowthProblem` -- seed eqs. (4.11), (4.12a)-(4.12c) for (u, psi, p).
  Growth is incompatible and anisotropic: F_g = I + s_1 k_1 (x) k_1 + s_2 k_2 (x) k_2
  with s_1 != s_2 varying in space and the directions k_i turned from the axes (a test
  growth law registered through the ``primordia_growth_laws`` hook, its frame given as
  ``directions``), so the stresses are not trivial and F_e = F F_g^-1 differs from
  F_g^-1 F.  u is fixed on ``left`` and ``bottom`` (the exact values), the exact
  traction P N_0 is applied on ``right`` and ``top`` (as a manufactured boundary
  source), p is fixed on the whole boundary; psi is then unique.  Two cases:

  - ``steady``: quasi-static (rho = 0), a steady exact solution and a large time step,
    so that the spatial error is what remains; the growth does not change in time;
  - ``transient``: p = P(X) (1 + t) and growth stretches s_i(X) (1 + r t), so the fluid
    gains ell = ell_0 sum_i d gamma_i/dt (4.15), still quasi-static (rho = 0).  Backward
    Euler is exact for it (the storage C_0 dp/dt of a p linear in t, with alpha_BW = 0:
    the fluid stress and alpha_BW (tr C - d) are the steady case's), so the error is again
    the spatial one, while the storage and the fluid source make a large part of the
    sources;
  - ``inertial``: the transient case with rho = 1 and u = U + t^2 W, whose second difference
    the scheme's (u - u^n - dt v^n)/dt^2 takes exactly (v^0 the backward difference), so
    the inertia of (4.12a) makes part of the sources and its sign and size are checked.
    On 8 x 8 and 16 x 16 only: on 32 x 32 Newton converges quadratically to 4.6e-7 of
    0.97 and then stalls at 3e-7, also with an exact LU at every Newton step.  The tangent
    there is nearly singular: its smallest eigenvalue is 7e-9 against a largest of 100, its
    eigenvector a psi oscillating over two to four cells along the traction side x = 1 near
    y = 0.85 (u and p 1e-2 of it).  The quasi-static ``transient`` case has the same boundary
    modes, less nearly singular (3.8e-7), and converges.  A wrong sign of the inertia, or a missing dt v^n, makes Newton
    diverge on 8 x 8 already.
* :class:`ReferenceChemotaxisProblem` -- seed eqs. (4.17a)-(4.17d) multiplied by J,
  with the FGF sink xi_f J (tr C - d) and the boundary flux the exact species
  carry through the sheared boundary, on a tissue moving by a prescribed
  deformation (``prescribed_motion``, a test physics that owns u, sets it to the
  exact motion at every step and provides the finite-strain kinematics through the
  same function as ``poroelastic_growth``,
  :func:`primordia.physics.kinematics.finite_strain_kinematics`).  The species are
  those of ``mms.py``.

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
from primordia.core.parameters import Parameter
from primordia.core.plugins import get_plugin_manager, hookimpl
from primordia.physics.base import FieldSpec, Physics
from primordia.physics.growth_laws import GrowthLaw
from primordia.physics.kinematics import finite_strain_kinematics

MU = 4.0  # the shear modulus of the runs (the option's default, seed section 5.4)
UFL_MATH = SimpleNamespace(sin=ufl.sin, cos=ufl.cos, exp=ufl.exp, pi=ufl.pi)
NUMPY_MATH = SimpleNamespace(sin=np.sin, cos=np.cos, exp=np.exp, pi=np.pi)


# -- exact fields, in one place for UFL and numpy --------------------------------------------------
#: The growth directions k_1, k_2: the axes turned by pi/6, so that F_g is not diagonal.
GROWTH_DIRECTIONS = [[np.cos(np.pi / 6), np.sin(np.pi / 6)], [-np.sin(np.pi / 6), np.cos(np.pi / 6)]]


def growth_stretches(X, t, rate, math_) -> list:
    """s_1, s_2 of F_g = I + sum_i s_i k_i (x) k_i, so gamma_i = s_i^2 (roots as printed after (4.12))."""
    sin, cos, pi = math_.sin, math_.cos, math_.pi
    grow = 1.0 + rate * t
    return [(0.2 + 0.1 * sin(pi * X[0]) * cos(pi * X[1])) * grow, (0.1 + 0.05 * cos(pi * X[0]) * X[1]) * grow]


def growth_tensor(X, t, rate):
    """F_g built from the seed's formula (after (4.12)) with the stretches and directions above."""
    k = [ufl.as_vector(direction) for direction in GROWTH_DIRECTIONS]
    stretches = growth_stretches(X, t, rate, UFL_MATH)
    return ufl.Identity(2) + sum(s * ufl.outer(k_i, k_i) for s, k_i in zip(stretches, k))


#: The two cases (module docstring): growth rate r, acceleration of u, pressure rate, and the model's values.
CASES = {
    "steady": {"growth_rate": 0.0, "acceleration": 0.0, "pressure_rate": 0.0,
               "parameters": {"rho": 0.0, "kappa": 0.2, "eta": 0.5, "C_0": 0.1, "alpha_BW": 0.4, "ell_0": 0.0},
               "dt": 1e8, "steps": 2},
    "transient": {"growth_rate": 0.5, "acceleration": 0.0, "pressure_rate": 1.0,
                  "parameters": {"rho": 0.0, "kappa": 0.2, "eta": 0.5, "C_0": 0.5, "alpha_BW": 0.0, "ell_0": 2.0},
                  "dt": 0.25, "steps": 2},
    "inertial": {"growth_rate": 0.5, "acceleration": 1.0, "pressure_rate": 1.0,
                 "parameters": {"rho": 1.0, "kappa": 0.2, "eta": 0.5, "C_0": 0.5, "alpha_BW": 0.0, "ell_0": 2.0},
                 "dt": 0.25, "steps": 2},
}

#: u, p as formula strings of X and t (the Dirichlet data), with {a} the acceleration, {q} the pressure rate.
DISPLACEMENT = ["0.1 * sin(pi * x[0]) * (1.0 + x[1]) + {a} * t ** 2 * 0.2 * x[1] * cos(pi * x[0])",
                "0.08 * x[0] * x[1] * (1.0 - x[0]) + 0.05 * sin(pi * x[1])"
                " + {a} * t ** 2 * 0.1 * sin(pi * x[0] * x[1])"]
PRESSURE = "(0.1 + 0.3 * sin(pi * x[0] * x[1])) * (1.0 + {q} * t)"


def exact_mechanics(X, t, case, math_) -> dict:
    """u, psi, p on the unit square at time t (moderate strains: |Grad u| < 0.5)."""
    sin, cos, pi = math_.sin, math_.cos, math_.pi
    a, q = case["acceleration"], case["pressure_rate"]
    u = [0.1 * sin(pi * X[0]) * (1.0 + X[1]) + a * t**2 * 0.2 * X[1] * cos(pi * X[0]),
         0.08 * X[0] * X[1] * (1.0 - X[0]) + 0.05 * sin(pi * X[1]) + a * t**2 * 0.1 * sin(pi * X[0] * X[1])]
    return {"u": ufl.as_vector(u) if math_ is UFL_MATH else np.stack(np.broadcast_arrays(*u)),
            "psi": MU + 0.5 * cos(pi * X[0]) * X[1],
            "p": (0.1 + 0.3 * sin(pi * X[0] * X[1])) * (1.0 + q * t)}


class StretchLaw(GrowthLaw):
    """A test growth law: gamma_i = s_i(X, t)^2 of :func:`growth_stretches`, on the frame given as ``directions``."""

    name = "test_mms_stretch"
    requires = ()
    dimensions = (2,)
    parameters = (Parameter("mms_growth_rate", 0.0, "growth rate r of the stretches s_i (1 + r t)",
                            constraint="nonnegative", source="test"),)

    def factors(self, fields, t, X, dimension):
        return [s * s for s in growth_stretches(X, t, self.params["mms_growth_rate"], UFL_MATH)]


# -- the balance laws, written from the seed ---------------------------------------------------------
def first_piola(u, psi, p, F_g, params):
    """P_e + P_f = J (mu B_e - psi I) F^-T - alpha_BW J p F^-T (seed (4.11) and after (4.12c))."""
    F = ufl.Identity(2) + ufl.grad(u)
    J, F_e = ufl.det(F), F * ufl.inv(F_g)
    return J * (MU * F_e * F_e.T - (psi + params["alpha_BW"] * p) * ufl.Identity(2)) * ufl.inv(F).T


class GrowthProblem:
    """Sources of (4.12a)-(4.12c) for :func:`exact_mechanics` in one of :data:`CASES`; boundary tractions."""

    fields = ("u", "psi", "p")
    needs_kinetics = False
    traction_boundaries = ("right", "top")

    def __init__(self, case: str = "steady"):
        self.case = CASES[case]

    def dirichlet(self) -> list[dict]:
        values = {"a": self.case["acceleration"], "q": self.case["pressure_rate"]}
        u = [text.format(**values) for text in DISPLACEMENT]
        p = PRESSURE.format(**values)
        return ([{"boundary": b, "type": "displacement", "value": u} for b in ("left", "bottom")]
                + [{"boundary": b, "type": "fluid_pressure", "value": p} for b in ("left", "right", "bottom", "top")])

    def growth_law(self) -> dict:
        return {"name": StretchLaw.name, "directions": GROWTH_DIRECTIONS}

    def parameters(self) -> dict:
        return {**self.case["parameters"], "mms_growth_rate": self.case["growth_rate"]}

    def contributions(self, params, disc) -> list[tuple[str, object]]:
        X, time = disc.x, ufl.variable(disc.t)
        exact = exact_mechanics(X, time, self.case, UFL_MATH)
        u, psi, p = exact["u"], exact["psi"], exact["p"]
        rate = self.case["growth_rate"]
        F_g = growth_tensor(X, time, rate)
        P = first_piola(u, psi, p, F_g, params)
        F = ufl.Identity(2) + ufl.grad(u)
        J, C = ufl.det(F), F.T * F
        gammas = [s * s for s in growth_stretches(X, time, rate, UFL_MATH)]
        ell = params["ell_0"] * sum(ufl.diff(gamma, time) for gamma in gammas)  # (4.15), general form
        content = params["C_0"] * p + params["alpha_BW"] * (ufl.tr(C) - 2)
        sources = {
            "u": params["rho"] * ufl.diff(ufl.diff(u, time), time) - ufl.div(P),              # (4.12a)
            "psi": -(J - ufl.det(F_g)),                                                    # (4.12c) as -(J - J_g)
            "p": (J * ufl.diff(content, time)                                               # (4.12b) times J
                  - ufl.div(params["kappa"] / params["eta"] * J * ufl.inv(C) * ufl.grad(p)) - J * ell),
        }
        dx = quadrature_dx(disc)
        terms = [(name, lambda test, s=expand_derivatives(s): -ufl.inner(s, test) * dx) for name, s in sources.items()]
        N = ufl.FacetNormal(disc.mesh.ufl_domain())
        for boundary in self.traction_boundaries:
            ds = disc.ds(boundary)(metadata={"quadrature_degree": 8})
            traction = expand_derivatives(P * N)
            terms.append(("u", lambda test, ds=ds, traction=traction: -ufl.inner(traction, test) * ds))
        return terms

    def initialise(self, disc):
        t0, dt = disc.time, float(disc.dt.value)
        for name in self.fields:
            disc.interpolate(name, lambda x, name=name: exact_mechanics(x, t0, self.case, NUMPY_MATH)[name])
        # the backward difference, with which the scheme's second difference of u is exact (u quadratic in t)
        disc.set_rate("u", lambda x: (exact_mechanics(x, t0, self.case, NUMPY_MATH)["u"]
                                      - exact_mechanics(x, t0 - dt, self.case, NUMPY_MATH)["u"]) / dt)

    def errors(self, sim) -> dict[str, float]:
        """L2 errors of u, psi, p and the H1 seminorm error of u."""
        disc = sim.disc
        exact = exact_mechanics(disc.x, disc.t, self.case, UFL_MATH)
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
        # the kinematics poroelastic_growth provides, so that the sources below (written from the seed)
        # check them too
        kinematics = finite_strain_kinematics(disc.field("u"), disc.previous("u"), quadrature_degree=4)
        disc.provide_kinematics(kinematics, self.name)

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
