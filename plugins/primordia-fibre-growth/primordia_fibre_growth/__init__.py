r"""Anisotropic growth along a fibre field a0(X): a third-party growth-law plugin (seed section 4).

The seed's 2D law (4.14) grows the tissue equally in every in-plane direction.  Here the
same growth is split between a fibre direction a0(X) of the reference configuration,
given as formulas of x in the ``[growth_law]`` table, and the direction across it,
a0^perp = (-a0_2, a0_1) (dimensionless factors):

    gamma_f = along  (delta_2 t + delta_3 m / (1 + m^2)),
    gamma_c = across (delta_2 t + delta_3 m / (1 + m^2)),

    F_g = I + sqrt(gamma_f) a0 (x) a0 + sqrt(gamma_c) a0^perp (x) a0^perp

(F_g as printed after seed (4.12), with k_1 = a0(X), k_2 = a0^perp(X)).  With
``along = across = 1`` it is the seed's law (4.14) whatever the fibre.  The fluid source
ell = ell_0 (along + across) d/dt (delta_2 t + delta_3 m / (1 + m^2)) (seed (4.15), general
form) is derived by primordia from the factors; this plugin does not write it.

The fibre is normalised, a0 = v / |v|; where the formulas give v = 0 the fibre has no
direction and the tissue does not grow there (|v| is regularised, so F_g stays finite).

    [growth_law]
    name = "fibre"
    fibre = ["cos(q * x[1])", "sin(q * x[1])"]    # a0(X), normalised
    constants = { q = 0.3 }
    along = 1.0                                   # gamma_f / (4.14)
    across = 0.25                                 # gamma_c / (4.14)
"""

from __future__ import annotations

import numpy as np
import pluggy
import ufl

from primordia.core.errors import ConfigError
from primordia.core.expressions import VectorFormula
from primordia.core.validation import number
from primordia.physics.growth_laws import GrowthLaw, Seed2D, saturating

hookimpl = pluggy.HookimplMarker("primordia")

#: The major version of primordia's hook contract this plugin is written for.
PRIMORDIA_CONTRACT = 1

#: Regularisation of the fibre's length |v| = sqrt(v . v + eps^2): no division by zero where v = 0.
LENGTH_EPSILON = 1e-12


class FibreGrowth(GrowthLaw):
    """Seed eq. (4.14) split between a fibre a0(X) (``along``) and the direction across it (``across``), 2D."""

    name = "fibre"
    dimensions = (2,)
    requires = ("m",)
    parameters = Seed2D.parameters  # delta_2, delta_3 of (4.14), with the seed's values (section 5.4)
    options = {"directions": None, "fibre": ["1", "0"], "constants": {}, "along": 1.0, "across": 0.25}

    def __init__(self, params, **given):
        super().__init__(params, **given)
        if self.settings["directions"] is not None:
            raise ConfigError("growth_law.directions does not apply to the fibre law: its frame is the fibre "
                              "and the direction across it (give growth_law.fibre)")
        for key in ("along", "across"):
            number(self.settings[key], f"growth_law.{key}", at_least=0,
                   hint=f"growth {key} the fibre as a multiple of seed (4.14)")
        formulas = self.settings["fibre"]
        if len(formulas) != 2:
            raise ConfigError(f"growth_law.fibre must be 2 formulas of x (the fibre direction a0 in 2D), "
                              f"got {formulas!r}")
        self.fibre = VectorFormula(formulas, self.settings["constants"], where="growth_law.fibre")
        if self.fibre.depends_on_time():
            raise ConfigError("growth_law.fibre is a direction of the reference configuration: "
                              "formulas of x and constants, not of t")

    def check_dimension(self, dimension):
        super().check_dimension(dimension)
        self.fibre.check(np.empty((0, dimension)), [0.0])  # x[2] in 2D is one line, naming the formula

    def directions_at(self, X, dimension):
        """k_1 = a0(X) = v / |v| and k_2 = a0^perp(X): orthonormal at every X."""
        v = self.fibre.ufl(X, 0.0)
        a0 = v / ufl.sqrt(ufl.dot(v, v) + LENGTH_EPSILON**2)
        return [a0, ufl.as_vector([-a0[1], a0[0]])]

    def factors(self, fields, t, X, dimension):
        p = self.params
        gamma = p["delta_2"] * t + p["delta_3"] * saturating(fields["m"])  # seed eq. (4.14)
        return [self.settings["along"] * gamma, self.settings["across"] * gamma]


@hookimpl
def primordia_growth_laws():
    return [FibreGrowth]
