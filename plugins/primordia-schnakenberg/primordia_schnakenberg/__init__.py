r"""Schnakenberg kinetics: a classic two-species activator-inhibitor system, as a third party writes it.

The reaction-diffusion system of Schnakenberg (1979) in the dimensionless form
of Murray, *Mathematical Biology II* (3rd ed., 2003), chapter 2:

    du/dt = gamma (a - u + u^2 v) + D_u Laplacian u         (u: the species "activator")
    dv/dt = gamma (b - u^2 v)     + D_v Laplacian v         (v: "inhibitor", the substrate u consumes)

Murray writes D_u = 1, D_v = d; the diffusion ratio is d = D_v / D_u.  (The
fields are not called u and v: in a primordia model ``u`` is the displacement.)  The
homogeneous steady state is u_0 = a + b, v_0 = b / (a + b)^2; it is Turing-unstable
(diffusion-driven) when b > a, (a + b)^3 > b - a and d exceeds the critical ratio
d_c (Murray, section 2.3), all of which primordia's linear stability analysis
finds from this module's code alone.

The plugin declares its own species (no chemotaxis, no mechanical coupling) and
registers through the ``primordia_kinetics`` hook and the ``primordia`` entry-point
group, like any third party.  For the IMEX scheme the rates are split into a
non-negative production and loss:

    R_u = gamma (a + u^2 v) - gamma u,      R_v = gamma b - gamma u^2 v.
"""

from __future__ import annotations

import pluggy

from primordia.core.parameters import Parameter
from primordia.physics.kinetics.base import Kinetics, Species

hookimpl = pluggy.HookimplMarker("primordia")

SOURCE = "Murray, Mathematical Biology II, ch. 2"

PARAMETERS = (
    Parameter("a", 0.1, "constant supply of the activator u", constraint="nonnegative", source=SOURCE),
    Parameter("b", 0.9, "constant supply of the inhibitor v", constraint="nonnegative", source=SOURCE),
    Parameter("gamma", 1.0, "strength of the reactions (Murray's gamma; proportional to the domain area)",
              source=SOURCE),
    Parameter("D_u", 1.0, "diffusivity of the activator (Murray's u)", source=SOURCE),
    Parameter("D_v", 20.0, "diffusivity of the inhibitor (Murray's v; his d when D_u = 1)", source=SOURCE),
)

SPECIES = (
    Species("activator", "Murray's u (dimensionless)", diffusivity="D_u", perturbed=True),
    Species("inhibitor", "Murray's v (dimensionless)", diffusivity="D_v"),
)


class Schnakenberg(Kinetics):
    """R_u = gamma (a - u + u^2 v), R_v = gamma (b - u^2 v) (Murray II, ch. 2)."""

    name = "schnakenberg"
    species = SPECIES
    parameters = PARAMETERS

    def split_rates(self, c, t, ops):
        p = self.params
        u, v = c["activator"], c["inhibitor"]
        return {
            "activator": (p["gamma"] * (p["a"] + u**2 * v), p["gamma"]),  # gamma (a + u^2 v) - gamma u
            "inhibitor": (p["gamma"] * p["b"], p["gamma"] * u**2),  # gamma b - (gamma u^2) v
        }

    def initial_state(self, t0, ops):
        """The homogeneous steady state u_0 = a + b, v_0 = b / (a + b)^2."""
        p = self.params
        u0 = p["a"] + p["b"]
        return {"activator": u0, "inhibitor": p["b"] / u0**2}


@hookimpl
def primordia_kinetics():
    return [Schnakenberg]
