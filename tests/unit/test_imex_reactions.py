"""The split chemotaxis step's reactions: production explicit, loss implicit, whatever a species' rates read.

A kinetics whose production or loss rate reads the species itself (Schnakenberg's u^2 v, a quadratic decay)
is stepped as the docs state, on a uniform field (where the fluxes vanish) exactly

    c^{n+1} = (c^n + dt P(c^n)) / (1 + dt L(c^n)),

which stays positive for any dt.  Before, the own species was read at its unknown and the "linear" solve was
one Newton step of the implicit reaction: with P = k c^2, dt = 4, the first step went from 1 down to 0.45
instead of up to 3.57 (the matrix had lost its diagonal), and the third to c = -0.034 instead of 4,372.
"""

from __future__ import annotations

import pytest

from primordia.core.meshes import rectangle
from primordia.core.parameters import Parameter
from primordia.core.plugins import hookimpl
from primordia.model import Model
from primordia.physics.kinetics.base import Kinetics, Species
from primordia.testing import BACKENDS, registered

K, LOSS, DECAY, DT, STEPS = 1.0, 0.1, 0.5, 4.0, 3


class SelfFeeding(Kinetics):
    """c feeds itself (P = k c^2) and decays linearly; d decays quadratically (L = decay d)."""

    name = "tests_self_feeding"
    species = (Species("c", "a self-feeding species", diffusivity="D"),
               Species("d", "a quadratically decaying one", diffusivity="D"))
    parameters = (Parameter("D", 0.1, "diffusivity", source="test"),
                  Parameter("k", K, "self-feeding rate", source="test"),
                  Parameter("loss", LOSS, "linear loss rate of c", source="test"),
                  Parameter("decay", DECAY, "quadratic decay rate of d", source="test"))

    def split_rates(self, c, t, ops):
        p = self.params
        return {"c": (p["k"] * c["c"] ** 2, p["loss"]), "d": (0.0, p["decay"] * c["d"])}

    def initial_state(self, t0, ops):
        return {"c": 1.0, "d": 2.0}


class _Plugin:
    @hookimpl
    def primordia_kinetics(self):
        return [SelfFeeding]


@pytest.mark.parametrize("backend", BACKENDS)
def test_own_production_and_loss_are_read_at_the_start_of_the_solve(backend, tmp_path):
    c, d = 1.0, 2.0
    for _ in range(STEPS):
        c, d = (c + DT * K * c**2) / (1 + DT * LOSS), d / (1 + DT * DECAY * d)
    with registered(_Plugin()):
        model = Model(physics=["chemotaxis"], kinetics={"name": "tests_self_feeding"},
                      mesh=rectangle((0, 0), (1, 1), (4, 4)), dt=DT, t_final=STEPS * DT,
                      physics_options={"chemotaxis": {"perturbation": 0.0}}, output={"pictures": False})
        statistics = model.run(backend=backend, out=tmp_path).field_statistics()
    for name, expected in (("c", c), ("d", d)):
        extrema = statistics[name]["min"], statistics[name]["max"]
        assert extrema == pytest.approx((expected, expected), rel=1e-12), name
