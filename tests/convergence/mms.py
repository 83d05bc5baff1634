r"""Manufactured solutions and observed convergence rates, shared by the convergence tests.

The exact solution of the chemotaxis system (seed eqs. (2.2a)-(2.2d)) is
written once, :func:`exact_solution`, as a function of the coordinates ``x``,
the time ``t`` and a maths namespace: with :data:`UFL_MATH`, ``x`` a
``SpatialCoordinate`` and ``t`` a ``ufl.variable`` of the run's time constant,
it is the UFL expression from which the sources are derived symbolically
(``ufl.diff`` in time, ``ufl.grad`` / ``ufl.div`` in space, the reactions from
the kinetics plugin's own ``rates``) and against which errors are measured;
with :data:`NUMPY_MATH` it gives the values the initial fields interpolate.

Every species is a product of cosines cos(k pi x) cos(l pi y) with integer k, l
around a positive mean, so on the unit square grad c . n = 0 for each of them:
the zero-flux conditions (2.6a), including the total cell flux
(D_m grad m - chi m grad f) . n, hold exactly and no boundary source is needed.
m stays in [0.5, 1.5] and e in [0.25, 0.75].

The sources enter each balance law through ``Discretisation.contribute``, from
a test-only physics module (:class:`ManufacturedSources`) registered in the
plugin manager like any third-party physics; listed after ``chemotaxis`` in
the model, its ``initialise`` runs last and sets every species to the
interpolant of the exact solution at t = 0.
"""

from __future__ import annotations

import contextlib
import math
from types import SimpleNamespace

import numpy as np
import ufl
from ufl.algorithms import expand_derivatives

from primordia.core import ops as ops_
from primordia.core.plugins import get_plugin_manager, hookimpl
from primordia.physics.base import Physics

SPECIES = ("m", "e", "f", "b")

UFL_MATH = SimpleNamespace(cos=ufl.cos, exp=ufl.exp, pi=ufl.pi)
NUMPY_MATH = SimpleNamespace(cos=np.cos, exp=np.exp, pi=np.pi)

#: Quadrature degree of the source and error integrals (the integrands are not polynomials).
QUADRATURE_DEGREE = 6


def exact_solution(x, t, math_) -> dict:
    """m, e, f, b at points ``x`` and time ``t`` (dimensionless), in the namespace ``math_``."""
    pi, cos = math_.pi, math_.cos
    decay = math_.exp(-t)
    return {
        "m": 1.0 + 0.5 * decay * cos(pi * x[0]) * cos(pi * x[1]),
        "e": 0.5 + 0.25 * decay * cos(pi * x[0]) * cos(2 * pi * x[1]),
        "f": 0.5 + 0.25 * decay * cos(2 * pi * x[0]) * cos(pi * x[1]),
        "b": 1.0 + 0.5 * decay * cos(2 * pi * x[0]) * cos(2 * pi * x[1]),
    }


def manufactured_sources(params, kinetics, disc) -> dict:
    """s_c = dc/dt - div(flux_c) - R_c for each species, as UFL expressions of x and t.

    The fluxes are written here from the seed's equations, not taken from the
    code under test; the reactions R_c are the kinetics plugin's own ``rates``
    (checked against the seed's formulas in ``tests/unit/test_painter2018.py``).
    """
    time = ufl.variable(disc.t)
    exact = exact_solution(disc.x, time, UFL_MATH)
    reactions = kinetics.rates(exact, time, ops_.UFL.at(disc.x))
    chi = params["alpha"] * ufl.exp(-params["gamma"] * exact["m"])  # seed eq. (2.2a)
    fluxes = {  # seed eqs. (2.2a)-(2.2d): dc/dt = div(flux) + R
        "m": params["D_m"] * ufl.grad(exact["m"]) - chi * exact["m"] * ufl.grad(exact["f"]),
        "e": None,
        "f": params["D_f"] * ufl.grad(exact["f"]),
        "b": params["D_b"] * ufl.grad(exact["b"]),
    }
    sources = {}
    for name in SPECIES:
        source = ufl.diff(exact[name], time) - reactions[name]
        if fluxes[name] is not None:
            source -= ufl.div(fluxes[name])
        sources[name] = expand_derivatives(source)
    return sources


def quadrature_dx(disc):
    return disc.backend.measure("dx", disc.mesh, metadata={"quadrature_degree": QUADRATURE_DEGREE})


class ManufacturedSources(Physics):
    """Adds the manufactured source of each species to its balance law; starts from the exact solution."""

    name = "manufactured_sources"
    requires = SPECIES

    def fields(self):
        return []

    def setup(self, disc):
        dx = quadrature_dx(disc)
        for name, source in manufactured_sources(self.params, self.kinetics, disc).items():
            disc.contribute(name, lambda test, source=source: -source * test * dx)

    def initialise(self, disc):
        t0 = disc.time
        for name in SPECIES:
            disc.interpolate(name, lambda x, name=name: exact_solution(x, t0, NUMPY_MATH)[name])

    def subproblems(self):
        return []


class _Plugin:
    @hookimpl
    def primordia_physics(self):
        return [ManufacturedSources]


@contextlib.contextmanager
def manufactured_sources_registered():
    """Register :class:`ManufacturedSources` in the process-wide plugin manager for the block."""
    pm = get_plugin_manager()
    plugin = pm.register(_Plugin(), name="tests.convergence.mms")
    try:
        yield
    finally:
        pm.unregister(name=plugin)


def l2_errors(sim) -> dict[str, float]:
    """||c_h - c||_L2 of each species at the run's current time."""
    disc = sim.disc
    exact = exact_solution(disc.x, disc.t, UFL_MATH)
    dx = quadrature_dx(disc)
    return {name: math.sqrt(sim.backend.assemble_scalar((disc.field(name) - exact[name]) ** 2 * dx))
            for name in SPECIES}


def observed_rates(sizes, errors) -> tuple[np.ndarray, float]:
    """Rates between successive meshes, and the least-squares rate over all of them.

    ``sizes`` are mesh sizes h (any order), ``errors`` the matching errors; the
    rate r fits error ~ C h^r.
    """
    log_h, log_e = np.log(np.asarray(sizes, float)), np.log(np.asarray(errors, float))
    successive = np.diff(log_e) / np.diff(log_h)
    fitted = np.polyfit(log_h, log_e, 1)[0]
    return successive, float(fitted)
