"""A physics module that owns a field: a morphogen h that the cells secrete, which diffuses and decays,

    dh/dt = D_h lap h + s_h m - k_h h   in Omega,      grad h . n = 0 on its boundary,

with m the cell density of the ``chemotaxis`` module. Not part of the seed: an example of what a
third party adds when a model needs one more field (a signal read out by another plugin, a marker of
where the cells have been). Backward Euler with a lumped mass, the seed's choice for its species
(section 5.1): the integral of h then obeys the same step exactly,

    H^{n+1} (1 + dt k_h) = H^n + dt s_h M^{n+1},     H = int h dx, M = int m dx,

which the plugin's test checks on both backends. On a fixed tissue only: a growing one would need
the pull-back of the chemotaxis module (J C^-1, seed (4.17a)), and is refused in one line.
"""

from __future__ import annotations

import ufl

from primordia.core.errors import ConfigError
from primordia.core.parameters import Parameter
from primordia.core.plugins import hookimpl
from primordia.physics.base import FieldSpec, Physics, Subproblem, jacobian_is_constant

#: The plugin contract this package was written against (``primordia plugins`` checks it).
PRIMORDIA_CONTRACT = 1

SOURCE = "primordia-morphogen (an example plugin, not the seed)"


class Morphogen(Physics):
    """The morphogen h: its field, its initial value, and one linear solve a step."""

    name = "morphogen"
    requires = ("m",)  # the cell density, from chemotaxis: the physics it reads are set up first
    parameters = (
        Parameter("D_h", 0.05, "diffusivity of the morphogen h (length^2/time)", source=SOURCE),
        Parameter("s_h", 1.0, "secretion of h per unit cell density (1/time)", constraint="nonnegative", source=SOURCE),
        Parameter("k_h", 0.5, "decay rate of h (1/time)", constraint="nonnegative", source=SOURCE),
    )
    options = {"initial_value": 0.0}

    def check_composition(self, modules) -> None:
        growing = [module.name for module in modules if module.finite_strain]
        if growing:
            raise ConfigError(f"physics morphogen is written on a fixed tissue; {', '.join(growing)} grows it "
                              f"(h would need the pull-back J C^-1 of seed (4.17a))")

    def fields(self):
        return [FieldSpec("h", degree=1, description="morphogen secreted by the cells")]

    def fourier_symbol(self, context):
        """h's part of ``primordia stability``: nothing the model runs reads h, so it adds one root,
        -(D_h K + k_h), and leaves the others as they are."""
        if "m" not in context.steady_state.values:
            raise ConfigError("physics morphogen reads the cell density m, which the kinetics does not declare")
        p = self.params
        return MorphogenWaves(p["D_h"], p["s_h"], p["k_h"])

    def setup(self, disc):
        self.disc = disc

    def initialise(self, disc):
        disc.interpolate("h", float(self.settings["initial_value"]))

    def subproblems(self):
        disc, p = self.disc, self.params
        h, h_previous, v = disc.field("h"), disc.previous("h"), disc.test("h")
        residual = ((h - h_previous) / disc.dt * v * disc.dx_lumped
                    + p["D_h"] * ufl.inner(ufl.grad(h), ufl.grad(v)) * disc.dx
                    + (p["k_h"] * h - p["s_h"] * disc.field("m")) * v * disc.dx_lumped)
        for term in disc.contributions("h", v):  # what other modules add to h's balance law
            residual += term
        unknown = disc.unknown("h")
        jacobian = ufl.derivative(residual, unknown)
        # linear, and its matrix constant on a fixed mesh with a fixed dt: factorised once, a step costs a solve
        return [Subproblem(name=f"{self.name}.h", unknown=unknown, residual=residual, jacobian=jacobian,
                           linear=True, constant_jacobian=jacobian_is_constant(jacobian, disc),
                           petsc_options={"ksp_type": "preonly", "pc_type": "lu"})]


class MorphogenWaves:
    """h's row of the linear stability analysis: (phi + D_h K + k_h) h - s_h m (plane waves, grad -> i k)."""

    unknowns = ("h",)

    def __init__(self, D_h: float, s_h: float, k_h: float, cells: str = "m"):
        self.D_h, self.s_h, self.k_h, self.cells = D_h, s_h, k_h, cells

    def add_to(self, system) -> None:
        system.add(1, "h", "h", 1.0)                              # dh/dt
        system.add(0, "h", "h", self.D_h * system.K + self.k_h)   # - D_h lap h + k_h h
        system.add(0, "h", self.cells, -self.s_h)                 # - s_h m


@hookimpl
def primordia_physics():
    return [Morphogen]
