"""Painter et al. (2018) kinetics of the feather-bud model: the built-in plugin.

The seed's four species and their reactions, in the dimensionless scaling of
seed section 2 (``gamma = kappa_F = kappa_B = delta_B = D_b = 1`` by default;
they remain parameters so a dimensional run can change them):

==========  =================================  ============  ==========================================
species     meaning                            transport     reaction
==========  =================================  ============  ==========================================
m  (2.3a)   mesenchymal cell density           D_m, climbs   none (cells only move)
                                               f: chi(m) = alpha exp(-gamma m)
e  (2.3b)   epithelium activation state        immobile      [kappa_1 w h_1(m) + kappa_2 h_2(m)](1 - e)
                                                             - [1 - h_1(m)](kappa_3 + kappa_4 b) e
f  (2.3c)   FGF                                D_f           kappa_F e - delta_F f  (sink xi_f div u)
b  (2.3d)   BMP                                D_b           kappa_B h_3(m) m - delta_B b
==========  =================================  ============  ==========================================

m, f and b are carried by the moving solid, f is consumed by dilation, and m
starts perturbed; with the Hill functions and the priming wave of seed eq. (2.4)

    h_i(m) = m^P_i / (K_i^P_i + m^P_i),
    w(x, t) = omega_1/2 [1 + tanh(omega_2 (t - x_2 / omega_3))].

The wave sweeps the domain in the +x_2 direction at speed omega_3; the option
``priming_wave = false`` replaces it by its saturated value ``w = omega_1``
everywhere, the spatially homogeneous state the linear stability analysis of
seed section 3 linearises about (:meth:`Painter2018.homogeneous`).

It registers through the same ``primordia_kinetics`` hook a third party uses.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from primordia.core.parameters import Parameter
from primordia.physics.kinetics.base import Kinetics, Species

#: The rest density and the transport of the species (seed eq. (2.3a)-(2.3d), (2.6)).
TRANSPORT = (
    Parameter("m0", 2.0, "rest density of mesenchymal cells (seed eq. (2.6))"),
    Parameter("D_m", 0.01, "cell diffusivity"),
    Parameter("D_f", 0.1, "FGF diffusivity"),
    Parameter("D_b", 1.0, "BMP diffusivity (1 in the seed's scaling)", source="seed section 2 scaling"),
    Parameter("alpha", 4.0, "chemotactic sensitivity to FGF", constraint="nonnegative"),
    Parameter("gamma", 1.0, "saturation of the chemotactic flux alpha m exp(-gamma m)",
              constraint="nonnegative", source="seed section 2 scaling"),
)

#: The reactions (seed eqs. (2.3b)-(2.3d), (2.4)).
REACTIONS = (
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

PARAMETERS = TRANSPORT + REACTIONS

#: The four species of seed eqs. (2.3a)-(2.3d), in solve order.
SPECIES = (
    Species("m", "mesenchymal cell density", diffusivity="D_m", attractant="f", advected=True, perturbed=True),
    Species("e", "epithelium activation state (dimensionless, in [0, 1])"),
    Species("f", "FGF concentration", diffusivity="D_f", advected=True, volume_sink=True),
    Species("b", "BMP concentration", diffusivity="D_b", advected=True),
)


def hill(m, threshold: float, exponent: float):
    """Seed eq. (2.4): h(m) = m^P / (K^P + m^P), dimensionless."""
    return m**exponent / (threshold**exponent + m**exponent)


class Painter2018(Kinetics):
    """Seed eqs. (2.3a)-(2.3d), (2.4) and the rest state (2.6)."""

    name = "painter2018"
    species = SPECIES
    parameters = PARAMETERS
    options = {"priming_wave": True}

    # -- the pieces of seed eq. (2.4) -------------------------------------------------
    def h(self, i: int, m):
        p = self.params
        return hill(m, p[f"K_{i}"], p[f"P_{i}"])

    def priming_wave(self, t, ops):
        """w(x, t) of seed eq. (2.4); ``omega_1`` everywhere when the wave is off."""
        p = self.params
        if not self.settings["priming_wave"]:
            return p["omega_1"]
        x2 = ops.x[1]
        return 0.5 * p["omega_1"] * (1.0 + ops.tanh(p["omega_2"] * (t - x2 / p["omega_3"])))

    def activation(self, m, t, ops):
        """k_on = kappa_1 w h_1(m) + kappa_2 h_2(m) (seed eq. (2.3b))."""
        p = self.params
        return p["kappa_1"] * self.priming_wave(t, ops) * self.h(1, m) + p["kappa_2"] * self.h(2, m)

    def inactivation(self, m, b):
        """k_off = [1 - h_1(m)](kappa_3 + kappa_4 b) (seed eq. (2.3b))."""
        p = self.params
        return (1.0 - self.h(1, m)) * (p["kappa_3"] + p["kappa_4"] * b)

    # -- the kinetics contract --------------------------------------------------------
    def split_rates(self, c: Mapping[str, Any], t, ops):
        p = self.params
        m, e, b = c["m"], c["e"], c["b"]
        k_on = self.activation(m, t, ops)
        k_off = self.inactivation(m, b)
        return {
            "m": (0.0, 0.0),  # seed eq. (2.3a): no reaction
            "e": (k_on, k_on + k_off),  # seed eq. (2.3b): k_on (1 - e) - k_off e
            "f": (p["kappa_F"] * e, p["delta_F"]),  # seed eq. (2.3c): kappa_F e - delta_F f
            "b": (p["kappa_B"] * self.h(3, m) * m, p["delta_B"]),  # seed eq. (2.3d)
        }

    def sensitivity(self, species: str, density, ops):
        """chi(m) = alpha exp(-gamma m): the cells' flux is chi(m) m grad f (seed eq. (2.3a))."""
        return self.params["alpha"] * ops.exp(-self.params["gamma"] * density)

    def initial_state(self, t0, ops):
        """Seed eq. (2.6): m = m0 and e, f, b at rest with it (w evaluated at t0).

        The seed prints f(0) = e_0 / delta_F and b(0) = h_3(m_0) m_0 for its
        scaling; with kappa_F, kappa_B, delta_B kept general these are the
        zeros of the f and b reactions: f = kappa_F e / delta_F,
        b = kappa_B h_3(m0) m0 / delta_B.
        """
        p = self.params
        m0 = p["m0"]
        b0 = p["kappa_B"] * self.h(3, m0) * m0 / p["delta_B"]
        k_on = self.activation(m0, t0, ops)
        e0 = k_on / (k_on + self.inactivation(m0, b0))
        return {"m": m0, "e": e0, "f": p["kappa_F"] * e0 / p["delta_F"], "b": b0}

    def homogeneous(self):
        """The same kinetics behind the priming wave, w = omega_1 everywhere (seed section 3)."""
        if not self.settings["priming_wave"]:
            return self
        return type(self)(self.params, **{**self.settings, "priming_wave": False})
