r"""Manufactured solutions and observed convergence rates, shared by the convergence tests.

A *manufactured problem* (:class:`ManufacturedProblem`) is an exact solution,
written once, and the sources that make it solve a model's balance laws.  Its
``exact(x, t, math_)`` gives every field: with :data:`UFL_MATH`, ``x`` a
``SpatialCoordinate`` and ``t`` a ``ufl.variable`` of the run's time constant,
it is the UFL expression from which the sources are derived symbolically
(``ufl.diff`` in time, ``ufl.grad`` / ``ufl.div`` in space, the reactions from
the kinetics plugin's own ``rates``) and against which errors are measured;
with :data:`NUMPY_MATH` it gives the values the initial fields interpolate.
The balance laws are written here again from the seed's equations, not taken
from the code under test (only the reactions are the kinetics plugin's own,
checked against the seed's formulas in ``tests/unit/test_painter2018.py``).

Problems:

* :class:`ChemotaxisProblem`: seed eqs. (2.3a)-(2.3d) without solid.  Every
  species is a product of cosines cos(k pi x) cos(l pi y) with integer k, l
  around a positive mean, so on the unit square grad c . n = 0 for each of them:
  the zero-flux conditions (2.7a), including the total cell flux
  (D_m grad m - chi m grad f) . n, hold exactly and no boundary source is needed.
  m stays in [0.5, 1.5] and e in [0.25, 0.75].
* :class:`PoroelasticProblem`: seed eqs. (2.1a)-(2.1c) (optionally with the
  active stress (2.5) of a given cell density), the displacement and pressure
  given as config formula strings, so that the *same strings* are the
  Dirichlet data of the run's boundary conditions and, through
  :class:`~primordia.core.expressions.Formula`, the UFL / numpy exact solution.
  Neumann data (traction sigma n, fluid flux (kappa/eta) grad p . n) are derived
  from those strings with sympy and handed back as formula strings
  (:meth:`PoroelasticProblem.traction`, :meth:`PoroelasticProblem.fluid_flux`).
* :class:`CoupledProblem`: both, plus the couplings of
  ``primordia.physics.mechanochemical`` and ``active_stress`` (solid advection
  u_t . grad c of m, f, b; the FGF sink xi_f div u; the active stress).

The sources enter each balance law through ``Discretisation.contribute``, from
a test-only physics module (:class:`ManufacturedSources`) registered in the
plugin manager like any third-party physics
(:func:`manufactured_sources_registered`); listed last in the model, its
``initialise`` runs last and sets every field (and the solid velocity) from the
exact solution at t = t_0.
"""

from __future__ import annotations

import contextlib
import math
from types import SimpleNamespace

import numpy as np
import ufl
from ufl.algorithms import expand_derivatives

from primordia.core import ops as ops_
from primordia.core.expressions import Formula, VectorFormula
from primordia.core.plugins import get_plugin_manager, hookimpl
from primordia.physics.base import Physics

SPECIES = ("m", "e", "f", "b")
ADVECTED = ("m", "f", "b")  # seed eqs. (2.3a), (2.3c), (2.3d): e is not advected

UFL_MATH = SimpleNamespace(cos=ufl.cos, exp=ufl.exp, pi=ufl.pi)
NUMPY_MATH = SimpleNamespace(cos=np.cos, exp=np.exp, pi=np.pi)

#: Quadrature degree of the source and error integrals (the integrands are not polynomials).
QUADRATURE_DEGREE = 6
#: Fields whose balance law is an ODE at each vertex (lumped accumulation and reaction, no
#: transport): their source is lumped alike.  Integrated exactly instead, the source at a
#: boundary vertex would be an average over a one-sided patch, off by O(h) in a layer of
#: width h that no diffusion smooths out, and the L2 rate of e would drift to 1.5.
LUMPED = ("e",)


# -- the exact solutions --------------------------------------------------------------------------
def species_profiles(x, amplitude, math_) -> dict:
    """m, e, f, b: zero-flux cosine profiles around positive means, scaled by ``amplitude`` (dimensionless)."""
    pi, cos = math_.pi, math_.cos
    return {
        "m": 1.0 + 0.5 * amplitude * cos(pi * x[0]) * cos(pi * x[1]),
        "e": 0.5 + 0.25 * amplitude * cos(pi * x[0]) * cos(2 * pi * x[1]),
        "f": 0.5 + 0.25 * amplitude * cos(2 * pi * x[0]) * cos(pi * x[1]),
        "b": 1.0 + 0.5 * amplitude * cos(2 * pi * x[0]) * cos(2 * pi * x[1]),
    }


def exact_solution(x, t, math_) -> dict:
    """m, e, f, b of the chemotaxis problem at points ``x`` and time ``t``: decaying like exp(-t)."""
    return species_profiles(x, math_.exp(-t), math_)


def lame_constants(params) -> tuple[float, float]:
    """(mu, lambda) from Young's modulus and Poisson's ratio (textbook formulas, not the code's)."""
    E, nu = params["E"], params["nu"]
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


# -- the balance laws, written from the seed ------------------------------------------------------
def chemotaxis_residuals(params, kinetics, exact, time, x, velocity=None) -> dict:
    """dc/dt [+ u_t . grad c] - div(flux_c) - R_c for each species (seed eqs. (2.3a)-(2.3d))."""
    reactions = kinetics.rates({name: exact[name] for name in SPECIES}, time, ops_.UFL.at(x))
    chi = params["alpha"] * ufl.exp(-params["gamma"] * exact["m"])  # seed eq. (2.3a)
    fluxes = {  # dc/dt = div(flux) + R
        "m": params["D_m"] * ufl.grad(exact["m"]) - chi * exact["m"] * ufl.grad(exact["f"]),
        "e": None,
        "f": params["D_f"] * ufl.grad(exact["f"]),
        "b": params["D_b"] * ufl.grad(exact["b"]),
    }
    residuals = {}
    for name in SPECIES:
        residual = ufl.diff(exact[name], time) - reactions[name]
        if fluxes[name] is not None:
            residual -= ufl.div(fluxes[name])
        if velocity is not None and name in ADVECTED:
            residual += ufl.dot(velocity, ufl.grad(exact[name]))  # seed (2.3a), (2.3c), (2.3d)
        residuals[name] = residual
    return residuals


def total_stress(params, u, p, m=None):
    """lambda div u I + 2 mu eps(u) - p I [+ (lambda + 2 mu/3) tau m/(1 + zeta m^2) I] (seed (2.2), (2.5))."""
    mu, lmbda = lame_constants(params)
    identity = ufl.Identity(len(u))
    sigma = lmbda * ufl.div(u) * identity + mu * (ufl.grad(u) + ufl.grad(u).T) - p * identity
    if m is not None:
        sigma += (lmbda + 2.0 * mu / 3.0) * params["tau"] * m / (1.0 + params["zeta"] * m**2) * identity
    return sigma


def poroelastic_residuals(params, exact, time, m=None) -> dict:
    """rho u_tt - div sigma and d/dt(C_0 p + alpha_BW div u) - div((kappa/eta) grad p) (seed (2.1a), (2.1c))."""
    u, p = exact["u"], exact["p"]
    velocity = ufl.diff(u, time)
    return {
        "u": params["rho"] * ufl.diff(velocity, time) - ufl.div(total_stress(params, u, p, m)),
        "p": (ufl.diff(params["C_0"] * p + params["alpha_BW"] * ufl.div(u), time)
              - ufl.div(params["kappa"] / params["eta"] * ufl.grad(p))),
    }


# -- manufactured problems ------------------------------------------------------------------------
class ManufacturedProblem:
    """An exact solution of some fields and the sources that make it solve the model."""

    fields: tuple[str, ...] = ()

    def exact(self, x, t, math_) -> dict:
        """Every field at ``x``, ``t``: UFL (``math_ = UFL_MATH``) or numpy (``NUMPY_MATH``)."""
        raise NotImplementedError

    def residuals(self, params, kinetics, exact, time, x) -> dict:
        """The balance laws applied to ``exact``: the sources, as UFL expressions."""
        raise NotImplementedError

    def sources(self, params, kinetics, disc) -> dict:
        time = ufl.variable(disc.t)
        exact = self.exact(disc.x, time, UFL_MATH)
        return {name: expand_derivatives(source)
                for name, source in self.residuals(params, kinetics, exact, time, disc.x).items()}

    def initialise(self, disc) -> None:
        """Fields at t_0 from the exact solution (the interpolant)."""
        t0 = disc.time
        for name in self.fields:
            disc.interpolate(name, lambda x, name=name: self.exact(x, t0, NUMPY_MATH)[name])


class ChemotaxisProblem(ManufacturedProblem):
    """Seed eqs. (2.3a)-(2.3d) on the unit square, every species decaying like exp(-t)."""

    fields = SPECIES

    def exact(self, x, t, math_):
        return exact_solution(x, t, math_)

    def residuals(self, params, kinetics, exact, time, x):
        return chemotaxis_residuals(params, kinetics, exact, time, x)


class PoroelasticProblem(ManufacturedProblem):
    """Seed eqs. (2.1a)-(2.1c): u and p given as formula strings of x and t (the config's syntax).

    The initial solid velocity is the backward difference (u(t_0) - u(t_0 - dt)) / dt:
    the scheme's inertia rho (u^1 - u^0 - dt v^0) / dt^2 is then the second
    difference of u, exact for u quadratic in time from the first step on.
    """

    fields = ("u", "p")

    def __init__(self, displacement: list[str], pressure: str, constants: dict | None = None):
        self.displacement_text, self.pressure_text = list(displacement), pressure
        self.constants = dict(constants or {})
        self.displacement = VectorFormula(self.displacement_text, self.constants, "exact displacement")
        self.pressure = Formula(pressure, self.constants, "exact pressure")

    def exact(self, x, t, math_):
        if math_ is UFL_MATH:
            return {"u": self.displacement.ufl(x, t), "p": self.pressure.ufl(x, t)}
        return {"u": self.displacement.numpy(x, t), "p": self.pressure.numpy(x, t)}

    def residuals(self, params, kinetics, exact, time, x):
        return poroelastic_residuals(params, exact, time)

    def initialise(self, disc):
        super().initialise(disc)
        t0, dt = disc.time, float(disc.dt.value)
        disc.set_rate("u", lambda x: (self.displacement.numpy(x, t0) - self.displacement.numpy(x, t0 - dt)) / dt)

    # -- boundary data, derived from the same strings with sympy ----------------------------
    def dirichlet(self, boundary: str) -> list[dict]:
        """``displacement`` and ``fluid_pressure`` conditions on ``boundary`` (the exact strings)."""
        return [{"boundary": boundary, "type": "displacement", "value": self.displacement_text,
                 "constants": self.constants},
                {"boundary": boundary, "type": "fluid_pressure", "value": self.pressure_text,
                 "constants": self.constants}]

    def traction(self, params, normal) -> list[str]:
        """sigma(u, p) n as formula strings, for a flat boundary of outward normal ``normal``."""
        return self._symbolic().traction(params, normal)

    def fluid_flux(self, params, normal) -> str:
        """(kappa/eta) grad p . n as a formula string."""
        return self._symbolic().fluid_flux(params, normal)

    def _symbolic(self):
        return _Sympy(self.displacement_text, self.pressure_text, self.constants)


class _Sympy:
    """The exact strings as sympy expressions, and derived quantities printed back as formula strings."""

    def __init__(self, displacement, pressure, constants):
        import sympy

        self.sympy = sympy
        self.x, self.t = sympy.IndexedBase("x"), sympy.Symbol("t")
        names = {"x": self.x, "t": self.t, "pi": sympy.pi,
                 **{name: sympy.Float(value, 17) for name, value in constants.items()}}
        self.u = [sympy.sympify(text, locals=names) for text in displacement]
        self.p = sympy.sympify(pressure, locals=names)

    def _text(self, expression) -> str:
        return self.sympy.sstr(expression, full_prec=True)

    def traction(self, params, normal):
        mu, lmbda = lame_constants(params)
        d = len(self.u)
        grad = [[self.sympy.diff(self.u[i], self.x[j]) for j in range(d)] for i in range(d)]
        divergence = sum(grad[i][i] for i in range(d))
        sigma = [[mu * (grad[i][j] + grad[j][i]) + (lmbda * divergence - self.p if i == j else 0)
                  for j in range(d)] for i in range(d)]
        return [self._text(sum(sigma[i][j] * normal[j] for j in range(d))) for i in range(d)]

    def fluid_flux(self, params, normal):
        conductivity = params["kappa"] / params["eta"]
        return self._text(sum(conductivity * self.sympy.diff(self.p, self.x[j]) * normal[j]
                              for j in range(len(normal))))


class CoupledProblem(ManufacturedProblem):
    """Chemotaxis + poroelasticity + active stress + mechano-chemical couplings (seed eqs. (2.1)-(2.5)).

    The species are the steady profiles of :func:`species_profiles`; u and p
    come from a :class:`PoroelasticProblem`.
    """

    fields = SPECIES + ("u", "p")

    def __init__(self, solid: PoroelasticProblem):
        self.solid = solid

    def exact(self, x, t, math_):
        return {**species_profiles(x, 1.0, math_), **self.solid.exact(x, t, math_)}

    def residuals(self, params, kinetics, exact, time, x):
        velocity = ufl.diff(exact["u"], time)
        residuals = chemotaxis_residuals(params, kinetics, exact, time, x, velocity=velocity)
        residuals["f"] += params["xi_f"] * ufl.div(exact["u"])  # seed eq. (2.3c): FGF sink
        residuals.update(poroelastic_residuals(params, exact, time, m=exact["m"]))
        return residuals

    def initialise(self, disc):
        super().initialise(disc)
        self.solid.initialise(disc)


CHEMOTAXIS = ChemotaxisProblem()


def quadrature_dx(disc):
    return disc.backend.measure("dx", disc.mesh, metadata={"quadrature_degree": QUADRATURE_DEGREE})


class ManufacturedSources(Physics):
    """Adds the manufactured source of each field to its balance law; starts from the exact solution."""

    name = "manufactured_sources"
    problem: ManufacturedProblem = CHEMOTAXIS
    requires = SPECIES

    def fields(self):
        return []

    def setup(self, disc):
        for name, source in self.problem.sources(self.params, self.kinetics, disc).items():
            dx = disc.dx_lumped if name in LUMPED else quadrature_dx(disc)
            disc.contribute(name, lambda test, source=source, dx=dx: -ufl.inner(source, test) * dx)

    def initialise(self, disc):
        self.problem.initialise(disc)

    def subproblems(self):
        return []


class PhysicsPlugin:
    """A plugin contributing one physics class (a test registers it for a block)."""

    def __init__(self, physics):
        self.physics = physics

    @hookimpl
    def primordia_physics(self):
        return [self.physics]


@contextlib.contextmanager
def manufactured_sources_registered(problem: ManufacturedProblem = CHEMOTAXIS):
    """Register ``manufactured_sources`` (for ``problem``) in the process-wide plugin manager for the block."""
    physics = type("ManufacturedSources", (ManufacturedSources,), {"problem": problem, "requires": problem.fields})
    pm = get_plugin_manager()
    plugin = pm.register(PhysicsPlugin(physics), name="tests.convergence.mms")
    try:
        yield
    finally:
        pm.unregister(name=plugin)


def l2_errors(sim, problem: ManufacturedProblem = CHEMOTAXIS) -> dict[str, float]:
    """||c_h - c||_L2 of each field of ``problem`` at the run's current time."""
    disc = sim.disc
    exact = problem.exact(disc.x, disc.t, UFL_MATH)
    dx = quadrature_dx(disc)
    errors = {}
    for name in problem.fields:
        difference = disc.field(name) - exact[name]
        errors[name] = math.sqrt(sim.backend.assemble_scalar(ufl.inner(difference, difference) * dx))
    return errors


def observed_rates(sizes, errors) -> tuple[np.ndarray, float]:
    """Rates between successive meshes, and the least-squares rate over all of them.

    ``sizes`` are mesh sizes h (any order), ``errors`` the matching errors; the
    rate r fits error ~ C h^r.
    """
    log_h, log_e = np.log(np.asarray(sizes, float)), np.log(np.asarray(errors, float))
    successive = np.diff(log_e) / np.diff(log_h)
    fitted = np.polyfit(log_h, log_e, 1)[0]
    return successive, float(fitted)
