"""Source code of third-party plugins, installed by the tests as a distribution (the ``plugin_distribution`` fixture)."""

#: A third-party kinetics of the seed's species: nothing reacts, and the rest state is e, f, b = 1/2, 1/4, 1/8.
FROZEN_KINETICS = """\
from primordia.core.plugins import hookimpl
from primordia.physics.kinetics.painter2018 import Painter2018


class Frozen(Painter2018):
    name = "frozen"

    def split_rates(self, c, t, ops):
        return {species: (0.0, 0.0) for species in self.species_names}

    def initial_state(self, t0, ops):
        return {"m": self.params["m0"], "e": 0.5, "f": 0.25, "b": 0.125}


@hookimpl
def primordia_kinetics():
    return [Frozen]
"""

#: A third-party physics module owning a field, a coupling to the chemotaxis and a splitting scheme, as a plugin
#: author writes them from docs/plugins.md: the cells secrete a cue g, dg/dt = D_g lap g + s_g m - k_g g
#: (``guidance_cue``), and climb it, dm/dt += -div(chi_g m grad g) (``cue_chemotaxis``, a ``Coupling``); the
#: ``palindromic`` scheme advances every module over dt/2 in model order, then over dt/2 in reverse.
GUIDANCE = """\
import ufl

from primordia.core.parameters import Parameter
from primordia.core.plugins import hookimpl
from primordia.coupling.solvers import accumulate
from primordia.coupling.splitting import SplittingScheme
from primordia.physics.base import Coupling, FieldSpec, Physics, Subproblem, jacobian_is_constant


class Rows:
    def __init__(self, unknowns, *entries):
        self.unknowns, self.entries = unknowns, entries

    def add_to(self, system):
        for order, row, column, value in self.entries:
            system.add(order, row, column, value(system))


class GuidanceCue(Physics):
    name = "guidance_cue"
    requires = ("m",)
    parameters = (Parameter("D_g", 0.05, "diffusivity of the cue g (length^2/time)"),
                  Parameter("s_g", 1.0, "secretion of g per unit cell density (1/time)"),
                  Parameter("k_g", 0.5, "decay rate of g (1/time)"))
    options = {"initial_value": 0.0}

    def fields(self):
        return [FieldSpec("g", description="guidance cue secreted by the cells")]

    def setup(self, disc):
        self.disc = disc

    def initialise(self, disc):
        disc.interpolate("g", float(self.settings["initial_value"]))

    def subproblems(self):
        disc, p = self.disc, self.params
        g, v = disc.field("g"), disc.test("g")
        residual = ((g - disc.previous("g")) / disc.dt * v * disc.dx_lumped
                    + p["D_g"] * ufl.inner(ufl.grad(g), ufl.grad(v)) * disc.dx
                    + (p["k_g"] * g - p["s_g"] * disc.field("m")) * v * disc.dx_lumped)
        for term in disc.contributions("g", v):
            residual += term
        unknown = disc.unknown("g")
        jacobian = ufl.derivative(residual, unknown)
        return [Subproblem(name="guidance_cue.g", unknown=unknown, residual=residual, jacobian=jacobian,
                           constant_jacobian=jacobian_is_constant(jacobian, disc),
                           petsc_options={"ksp_type": "preonly", "pc_type": "lu"})]

    def fourier_symbol(self, context):
        p = self.params
        return Rows(("g",), (1, "g", "g", lambda system: 1.0),
                    (0, "g", "g", lambda system: p["D_g"] * system.K + p["k_g"]),
                    (0, "g", "m", lambda system: -p["s_g"]))


class CueChemotaxis(Coupling):
    name = "cue_chemotaxis"
    requires = ("m", "g")
    parameters = (Parameter("chi_g", 0.5, "chemotactic sensitivity of the cells to g"),)

    def setup(self, disc):
        chi = self.params["chi_g"]
        disc.contribute("m", lambda v: -chi * disc.field("m") * ufl.inner(ufl.grad(disc.previous("g")), ufl.grad(v))
                        * disc.dx, by=self.name)

    def fourier_symbol(self, context):
        chi, m0 = self.params["chi_g"], context.steady_state.values["m"]
        return Rows((), (0, "m", "g", lambda system: -chi * m0 * system.K))


class Palindromic(SplittingScheme):
    name = "palindromic"

    def advance(self, sim, t0, dt):
        stats, inner = {}, self.settings["inner_steps"]
        for start, flows in ((t0, self.flows), (t0 + 0.5 * dt, self.flows[::-1])):
            for flow in flows:
                for name, solve in sim.advance(flow, start, 0.5 * dt, inner).items():
                    accumulate(stats, name, solve)
        return stats


@hookimpl
def primordia_physics():
    return [GuidanceCue, CueChemotaxis]


@hookimpl
def primordia_splitting_schemes():
    return [Palindromic]
"""
