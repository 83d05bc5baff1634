"""Growth laws with known answers, registered like third-party plugins (``primordia_growth_laws``).

* ``test_uniform``: F_g = g I, constant in time (parameter ``g``): the in-plane factors are
  (g - 1)^2 (they enter F_g through their roots, as printed after seed (4.12)) and the third g - 1.
* ``test_linear``: F_g = (1 + r t) I, each stretch linear in time (parameter ``r``); the law
  overrides :meth:`~primordia.physics.growth_laws.GrowthLaw.stretches` to use its factors
  gamma_i = r t directly, so F_g(0) = I exactly and ell = ell_0 d r is constant.
* ``test_anisotropic``: F_g = I + sum_i (g_i - 1) k_i (x) k_i, constant in time (parameters ``g1``, ``g2``,
  ``g3``), on the directions of ``[growth_law] directions``.
"""

from __future__ import annotations

import contextlib

from primordia.core.parameters import Parameter
from primordia.core.plugins import get_plugin_manager, hookimpl
from primordia.physics.growth_laws import GrowthLaw


class Uniform(GrowthLaw):
    name = "test_uniform"
    parameters = (Parameter("g", 1.2, "uniform growth stretch (dimensionless)"),)

    def factors(self, fields, t, X, dimension):
        excess = self.params["g"] - 1.0
        return [excess**2, excess**2, excess][:dimension]


class Linear(GrowthLaw):
    name = "test_linear"
    parameters = (Parameter("r", 0.1, "growth stretch rate (1/time)"),)

    def factors(self, fields, t, X, dimension):
        return [self.params["r"] * t] * dimension

    def stretches(self, gammas):
        return list(gammas)


class Anisotropic(GrowthLaw):
    name = "test_anisotropic"
    parameters = (Parameter("g1", 1.3, "growth stretch along k_1 (dimensionless)"),
                  Parameter("g2", 1.1, "growth stretch along k_2 (dimensionless)"),
                  Parameter("g3", 1.05, "growth stretch along k_3 (dimensionless)"))

    def factors(self, fields, t, X, dimension):
        return [self.params[name] - 1.0 for name in ("g1", "g2", "g3")][:dimension]

    def stretches(self, gammas):
        return list(gammas)


class _Plugin:
    @hookimpl
    def primordia_growth_laws(self):
        return [Uniform, Linear, Anisotropic]


@contextlib.contextmanager
def registered():
    """The test laws in the process-wide plugin manager, for the block."""
    pm = get_plugin_manager()
    plugin = pm.register(_Plugin(), name="tests.support.growth_test_laws")
    try:
        yield
    finally:
        pm.unregister(name=plugin)
