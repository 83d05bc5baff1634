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
