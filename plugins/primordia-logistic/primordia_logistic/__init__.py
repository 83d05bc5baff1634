"""Painter (2018) kinetics plus logistic proliferation of mesenchymal cells.

A third-party kinetics plugin: it subclasses the built-in kinetics and
registers through the same ``primordia_kinetics`` hook.
"""

from __future__ import annotations

import pluggy

from primordia.core.parameters import Parameter
from primordia.physics.kinetics.painter2018 import Painter2018

hookimpl = pluggy.HookimplMarker("primordia")


class Painter2018Logistic(Painter2018):
    """Seed eqs. (2.3b)-(2.3d) with R_m = r_m m (1 - m / m_cap) added to (2.3a)."""

    name = "painter2018_logistic"
    parameters = Painter2018.parameters + (
        Parameter("r_m", 0.01, "cell proliferation rate (1/time, dimensionless)", source="primordia-logistic"),
        Parameter("m_cap", 2.0, "cell carrying capacity (dimensionless)", source="primordia-logistic"),
    )

    def split_rates(self, c, t, ops):
        rates = super().split_rates(c, t, ops)
        r_m, m_cap = self.params["r_m"], self.params["m_cap"]
        m = c["m"]
        rates["m"] = (r_m * m, r_m * m / m_cap)  # production r m, loss (r / m_cap) m
        return rates


@hookimpl
def primordia_kinetics():
    return [Painter2018Logistic]
