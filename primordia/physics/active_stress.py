r"""Isotropic active stress driven by the cell density (seed eq. (2.5)).

    sigma_act = (lambda + 2 mu / 3) tau m / (1 + zeta m^2) I

With the stress of (2.2) positive in tension, tau > 0 is a tension that the
skeleton balances by contracting where cells gather, tau < 0 dilates it
(tests/unit/test_active_stress.py).  The seed's sentence after (2.5) says the
opposite (tau > 0 "a local dilation"); (2.1b) and (2.5) as printed, which this
module implements, give a contraction.  The
module owns no field: it adds sigma_act : grad w to the momentum balance of
the poroelasticity module, reading m from the chemotaxis module (the current
value: with sequential splitting, the one just computed in this step).
Requires: ``m`` (provided by chemotaxis), ``u`` and ``lame_constants`` (provided by poroelasticity).
"""

from __future__ import annotations

import ufl

from primordia.core.errors import ConfigError
from primordia.physics.base import Coupling
from primordia.physics.seed_parameters import ACTIVE_STRESS


def active_stress(m, mu, lmbda, tau, zeta, dimension: int):
    """Seed eq. (2.5): (lambda + 2 mu/3) tau m / (1 + zeta m^2) I."""
    return (lmbda + 2.0 * mu / 3.0) * tau * m / (1.0 + zeta * m**2) * ufl.Identity(dimension)


class ActiveStress(Coupling):
    """Adds sigma_act(m) to the total stress of the momentum balance (seed eqs. (2.1b), (2.5))."""

    name = "active_stress"
    parameters = ACTIVE_STRESS
    requires = ("m", "u", "lame_constants")

    def check_composition(self, modules):
        finite = [module.name for module in modules if module.finite_strain]
        if finite:
            raise ConfigError(
                f"active_stress is the small-strain active stress of seed eq. (2.5) and cannot join {finite[0]}: "
                f"its (lambda + 2 mu/3) has no value for the incompressible neo-Hookean solid of (4.11), whose "
                f"constraint J_e = 1 would absorb an isotropic stress into psi; remove active_stress from model.physics")

    def setup(self, disc):
        mu, lmbda = disc.field("lame_constants")  # provided by the poroelasticity module
        sigma = active_stress(disc.field("m"), mu, lmbda, self.params["tau"], self.params["zeta"], disc.gdim)
        disc.contribute("u", lambda w: ufl.inner(sigma, ufl.grad(w)) * disc.dx, by=self.name)  # (2.1b), (2.1c)
