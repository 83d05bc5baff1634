"""Painter et al. (2018) kinetics of the feather-bud model: the built-in plugin.

Reaction terms of seed eqs. (2.2b)-(2.2d) in the dimensionless scaling of
seed section 2 (``gamma = kappa_F = kappa_B = delta_B = D_b = 1`` by default;
they remain parameters so a dimensional run can change them):

* epithelium (2.2b):   de/dt = [kappa_1 w h_1(m) + kappa_2 h_2(m)](1 - e)
                               - [1 - h_1(m)](kappa_3 + kappa_4 b) e
* FGF (2.2c):          production kappa_F e, loss delta_F f
* BMP (2.2d):          production kappa_B h_3(m) m, loss delta_B b
* cells (2.2a):        no reaction (m is conserved; only transport moves it)

with the Hill functions and the priming wave of seed eq. (2.3)

    h_i(m) = m^P_i / (K_i^P_i + m^P_i),
    w(x, t) = omega_1/2 [1 + tanh(omega_2 (t - x_2 / omega_3))].

The wave sweeps the domain in the +x_2 direction at speed omega_3; the option
``priming_wave = false`` replaces it by its saturated value ``w = omega_1``
everywhere, the spatially homogeneous state the linear stability analysis of
seed section 3 linearises about.

It registers through the same ``primordia_kinetics`` hook a third party uses.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from primordia.core.parameters import Parameter
from primordia.physics.kinetics.base import Kinetics

PARAMETERS = (
    Parameter("kappa_1", 0.05, "wave-driven activation rate of the epithelium", constraint="nonnegative"),
    Parameter("kappa_2", 0.025, "cell-driven activation rate of the epithelium", constraint="nonnegative"),
    Parameter("kappa_3", 1.0, "basal inactivation rate of the epithelium", constraint="nonnegative"),
    Parameter("kappa_4", 1.0, "BMP-driven inactivation rate of the epithelium", constraint="nonnegative"),
    Parameter("K_1", 1.0, "Hill threshold of h_1"),
    Parameter("K_2", 2.0, "Hill threshold of h_2"),
    Parameter("K_3", 5.0, "Hill threshold of h_3"),
    Parameter("P_1", 2.0, "Hill exponent of h_1"),
    Parameter("P_2", 2.0, "Hill exponent of h_2"),
    Parameter("P_3", 2.0, "Hill exponent of h_3"),
    Parameter("delta_F", 1.0, "FGF decay rate"),
    Parameter("omega_1", 1.0, "priming wave amplitude"),
    Parameter("omega_2", 5.0, "priming wave steepness"),
    Parameter("omega_3", 0.04, "priming wave speed (along x_2)"),
    Parameter("kappa_F", 1.0, "FGF production by the epithelium (1 in the seed's scaling)",
              source="seed section 2 scaling"),
    Parameter("kappa_B", 1.0, "BMP production by cells (1 in the seed's scaling)",
              source="seed section 2 scaling"),
    Parameter("delta_B", 1.0, "BMP decay rate (1 in the seed's scaling)",
              source="seed section 2 scaling"),
)


def hill(m, threshold: float, exponent: float):
    """Seed eq. (2.3): h(m) = m^P / (K^P + m^P), dimensionless."""
    return m**exponent / (threshold**exponent + m**exponent)


class Painter2018(Kinetics):
    """Seed eqs. (2.2b)-(2.2d) and (2.3)."""

    name = "painter2018"
    parameters = PARAMETERS
    options = {"priming_wave": True}

    # -- the pieces of seed eq. (2.3) -------------------------------------------------
    def h(self, i: int, m):
        p = self.params
        return hill(m, p[f"K_{i}"], p[f"P_{i}"])

    def priming_wave(self, t, ops):
        """w(x, t) of seed eq. (2.3); ``omega_1`` everywhere when the wave is off."""
        p = self.params
        if not self.opts["priming_wave"]:
            return p["omega_1"]
        x2 = ops.x[1]
        return 0.5 * p["omega_1"] * (1.0 + ops.tanh(p["omega_2"] * (t - x2 / p["omega_3"])))

    def activation(self, m, t, ops):
        """k_on = kappa_1 w h_1(m) + kappa_2 h_2(m) (seed eq. (2.2b))."""
        p = self.params
        return p["kappa_1"] * self.priming_wave(t, ops) * self.h(1, m) + p["kappa_2"] * self.h(2, m)

    def inactivation(self, m, b):
        """k_off = [1 - h_1(m)](kappa_3 + kappa_4 b) (seed eq. (2.2b))."""
        p = self.params
        return (1.0 - self.h(1, m)) * (p["kappa_3"] + p["kappa_4"] * b)

    # -- the kinetics contract --------------------------------------------------------
    def split_rates(self, c: Mapping[str, Any], t, ops):
        p = self.params
        m, e, b = c["m"], c["e"], c["b"]
        k_on = self.activation(m, t, ops)
        k_off = self.inactivation(m, b)
        return {
            "m": (0.0, 0.0),  # seed eq. (2.2a): no reaction
            "e": (k_on, k_on + k_off),  # seed eq. (2.2b): k_on (1 - e) - k_off e
            "f": (p["kappa_F"] * e, p["delta_F"]),  # seed eq. (2.2c): kappa_F e - delta_F f
            "b": (p["kappa_B"] * self.h(3, m) * m, p["delta_B"]),  # seed eq. (2.2d)
        }

    def initial_state(self, m0: float, t0, ops):
        """Seed eq. (2.5): e, f, b at rest with m = m0 (w evaluated at t0).

        The seed prints f(0) = e_0 / delta_F and b(0) = h_3(m_0) m_0 for its
        scaling; with kappa_F, kappa_B, delta_B kept general these are the
        zeros of the f and b reactions: f = kappa_F e / delta_F,
        b = kappa_B h_3(m0) m0 / delta_B.
        """
        p = self.params
        b0 = p["kappa_B"] * self.h(3, m0) * m0 / p["delta_B"]
        k_on = self.activation(m0, t0, ops)
        e0 = k_on / (k_on + self.inactivation(m0, b0))
        return {"e": e0, "f": p["kappa_F"] * e0 / p["delta_F"], "b": b0}
