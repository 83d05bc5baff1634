"""Species come from the kinetics: a fifth species joins the model without touching the physics.

A third-party kinetics ``painter2018_signal`` adds to the seed's m, e, f, b a signal g
that the cells secrete and that diffuses, decays and is carried by the solid:

    dg/dt = div(D_g grad g) + k_g m - delta_g g,        g(0) = 0.

The transport physics (chemotaxis), the mechano-chemical couplings and the linear
analysis read the declaration: g is a field, is solved after b, is advected, and its
total obeys the lumped backward-Euler step of the ODE (the flux integrates to zero,
the cells' total M is conserved):

    G^{n+1} = (G^n + dt k_g M) / (1 + dt delta_g).
"""

from __future__ import annotations

import numpy as np
import pytest

from primordia.analysis import linearise_model
from primordia.core.meshes import rectangle
from primordia.core.parameters import Parameter
from primordia.core.plugins import get_plugin_manager, hookimpl
from primordia.model import Model
from primordia.physics.kinetics.base import Species
from primordia.physics.kinetics.painter2018 import Painter2018

K_G, DELTA_G, D_G = 0.3, 0.8, 0.5


class Signal(Painter2018):
    """painter2018 plus a secreted, decaying, diffusing signal g."""

    name = "painter2018_signal"
    species = Painter2018.species + (Species("g", "a signal the cells secrete", diffusivity="D_g", advected=True),)
    parameters = Painter2018.parameters + (
        Parameter("D_g", D_G, "signal diffusivity", source="test"),
        Parameter("k_g", K_G, "signal secretion per cell", source="test"),
        Parameter("delta_g", DELTA_G, "signal decay rate", source="test"),
    )

    def split_rates(self, c, t, ops):
        rates = super().split_rates(c, t, ops)
        rates["g"] = (self.params["k_g"] * c["m"], self.params["delta_g"])
        return rates

    def initial_state(self, t0, ops):
        return {**super().initial_state(t0, ops), "g": 0.0}


class _Plugin:
    @hookimpl
    def primordia_kinetics(self):
        return [Signal]


@pytest.fixture(scope="module", autouse=True)
def registered():
    pm = get_plugin_manager()
    name = pm.register(_Plugin(), name="tests.signal_kinetics")
    yield
    pm.unregister(name=name)


def signal_model(physics=("chemotaxis",), **kwargs) -> Model:
    return Model(physics=list(physics), kinetics={"name": "painter2018_signal", "priming_wave": False},
                 parameters={"m0": 0.75, "D_m": 0.03}, mesh=rectangle((0, 0), (4, 4), (8, 8)), dt=0.1, t_final=0.5,
                 output={"pictures": False}, physics_options={"chemotaxis": {"perturbation": 0.2}}, **kwargs)


def test_the_fifth_species_is_a_field_solved_after_the_seeds():
    model = signal_model()
    (chemotaxis,) = model.physics_objects
    assert [spec.name for spec in chemotaxis.fields()] == ["m", "e", "f", "b", "g"]
    assert "D_g" in model.parameters and "k_g" in model.parameters


@pytest.mark.parametrize("backend", ["fenicsx", "skfem"])
def test_its_total_follows_its_own_equation(backend, tmp_path):
    sim = signal_model().run(backend=backend, out=tmp_path)
    assert [solver.sub.name for solver in sim.solvers][-1] == "chemotaxis.g"
    totals = sim.field_statistics()
    cells = totals["m"]["integral"]
    expected = 0.0
    for _ in range(5):
        expected = (expected + 0.1 * K_G * cells) / (1 + 0.1 * DELTA_G)
    assert totals["g"]["integral"] == pytest.approx(expected, rel=1e-10)
    assert totals["g"]["max"] > totals["g"]["min"]  # secreted where the (perturbed) cells are


def test_the_couplings_read_the_declaration():
    model = signal_model(("chemotaxis", "poroelasticity", "active_stress", "mechanochemical"))
    coupling = model.physics_objects[-1]
    assert coupling.advected == ("m", "f", "b", "g") and coupling.sinks == ("f",)
    assert coupling.requires == ("u", "m", "f", "b", "g")


def test_the_analysis_has_five_species():
    linear = linearise_model(signal_model())
    assert linear.species == ("m", "e", "f", "b", "g")
    assert linear.steady_state.values["g"] == pytest.approx(K_G * 0.75 / DELTA_G, rel=1e-12)
    k = 1.7
    roots = linear.rates(np.array([k]))[0]
    # g feeds nothing back: -(D_g k^2 + delta_g) is a root, the others are painter2018's
    assert np.min(np.abs(roots - (-(D_G * k**2 + DELTA_G)))) < 1e-10
    painter = linearise_model(Model(physics=["chemotaxis"], kinetics={"name": "painter2018", "priming_wave": False},
                                    parameters={"m0": 0.75, "D_m": 0.03}, mesh=rectangle((0, 0), (1, 1), (2, 2)),
                                    dt=0.1, t_final=0.1))
    for root in painter.rates(np.array([k]))[0]:
        assert np.min(np.abs(roots - root)) < 1e-10


class _Unevaluable(Signal):
    """A kinetics whose initial state raises from its own code (here on purpose; in practice a bug or a parameter)."""

    name = "painter2018_unevaluable"

    def initial_state(self, t0, ops):
        raise ValueError("math domain error")


class _UnevaluablePlugin:
    @hookimpl
    def primordia_kinetics(self):
        return [_Unevaluable]


def test_a_third_party_initial_state_that_raises_is_placed_in_its_file():
    """It was blamed on the parameters alone, with no place: a plugin author could not tell their bug from them."""
    from primordia.core.errors import ConfigError
    from primordia.testing import registered as registering

    with registering(_UnevaluablePlugin(), name="tests.unevaluable"):
        with pytest.raises(ConfigError) as caught:
            Model(physics=["chemotaxis"], kinetics={"name": "painter2018_unevaluable"},
                  mesh=rectangle((0, 0), (4, 4), (4, 4)), dt=0.1, t_final=0.2, output={"pictures": False})
    message = str(caught.value)
    assert message.startswith("kinetics painter2018_unevaluable: the initial state cannot be evaluated with these "
                              "parameters (ValueError: math domain error (at "), message
    assert f"{__file__}:" in message, message


def test_a_plugins_parameter_out_of_range_names_the_plugin():
    """"parameter k_g must be > 0 (signal secretion per cell), got -1" did not say whose parameter it is (the
    plugin QA pass)."""
    from primordia.core.errors import ConfigError

    with pytest.raises(ConfigError) as caught:
        Model(physics=["chemotaxis"], kinetics={"name": "painter2018_signal"}, parameters={"k_g": -1.0},
              mesh=rectangle((0, 0), (4, 4), (4, 4)), dt=0.1, t_final=0.2, output={"pictures": False})
    assert str(caught.value) == ("parameter k_g must be > 0 (signal secretion per cell), got -1 (declared by "
                                 "kinetics painter2018_signal, a plugin)")
    with pytest.raises(ConfigError) as caught:  # primordia's own kinetics: the seed's parameter, as before
        Model(physics=["chemotaxis"], kinetics={"name": "painter2018"}, parameters={"D_m": -1.0},
              mesh=rectangle((0, 0), (4, 4), (4, 4)), dt=0.1, t_final=0.2, output={"pictures": False})
    assert str(caught.value) == "parameter D_m must be > 0 (cell diffusivity), got -1"
