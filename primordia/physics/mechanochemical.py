r"""The mechano-chemical couplings of the small-strain model (seed eqs. (2.2a)-(2.2d)).

This module only couples (it owns no field and states no balance law). It adds
to the chemotaxis balance laws the terms that involve the moving solid:

* advection of the mobile species by the solid velocity (seed (2.2a), (2.2c), (2.2d)):
      + du/dt . grad c^n    for c in m, f, b
  explicit, like the rest of the IMEX transport coupling: du/dt is the solid
  velocity of the last completed step and c^n the start-of-step concentration, so
  the species matrices stay constant (factorised once) and the solves linear.  It is
  stable while |du/dt| dt / h << 1, which the seed's runs satisfy by orders of
  magnitude (series.nc records the fields, so a violation shows as growth);
* the FGF sink of volume change (seed (2.2c)):
      + xi_f div u
  with u the current displacement (xi_f > 0: dilation consumes FGF).

Active stress (the reverse coupling, m driving the solid) is the separate module
:mod:`primordia.physics.active_stress`.  Requires: ``u`` (poroelasticity) and
``m``, ``f``, ``b`` (chemotaxis).

With the advection term the cell transport matrix is no longer an M-matrix in
general: non-negativity of m is guaranteed without solid motion only (the seed's
velocities are small; ``series.nc`` records min m so it can be checked).
"""

from __future__ import annotations

import ufl

from primordia.physics.base import Physics
from primordia.physics.seed_parameters import MECHANOCHEMICAL

ADVECTED = ("m", "f", "b")


def solid_advection(velocity, c_previous, test, dx):
    """du/dt . grad c, explicit in c (seed eqs. (2.2a), (2.2c), (2.2d))."""
    return ufl.inner(velocity, ufl.grad(c_previous)) * test * dx


def fgf_sink(xi_f, u, test, dx):
    """xi_f div u (seed eq. (2.2c))."""
    return xi_f * ufl.div(u) * test * dx


class MechanoChemical(Physics):
    """Solid advection of m, f, b and the FGF sink xi_f div u."""

    name = "mechanochemical"
    parameters = MECHANOCHEMICAL
    requires = ("u", "m", "f", "b")

    def fields(self):
        return []

    def setup(self, disc):
        velocity = disc.rate("u")
        for species in ADVECTED:
            start_of_step = disc.previous(species)
            disc.contribute(species, lambda test, c=start_of_step: solid_advection(velocity, c, test, disc.dx))
        u = disc.field("u")
        disc.contribute("f", lambda test: fgf_sink(self.params["xi_f"], u, test, disc.dx))

    def initialise(self, disc):
        pass

    def subproblems(self):
        return []
