"""The installable example plugin plugins/primordia-logistic works as a third party's would."""

import math
import subprocess
import sys

import pytest

from primordia.core.plugins import get_plugin_manager, registry
from primordia.model import Model

OVERRIDES = ["mesh.cells=[12,12]", "time.t_final=20", "output.times=[20]", "output.pictures=false",
             "kinetics.priming_wave=false"]


def test_it_is_found_through_its_entry_point():
    kinetics = registry("kinetics", get_plugin_manager())
    piece, origin = kinetics["painter2018_logistic"]
    assert origin.startswith("primordia-logistic ")
    listing = subprocess.run([sys.executable, "-m", "primordia.cli", "plugins"], capture_output=True, text=True)
    assert any("painter2018_logistic" in line and "primordia-logistic" in line for line in listing.stdout.splitlines())


def test_its_cells_proliferate_towards_the_carrying_capacity(tmp_path):
    def total_cells(extra):
        model = Model.from_file("examples/ex01a.toml", OVERRIDES + extra)
        return model.run(out=tmp_path / str(len(extra))).field_statistics()["m"]["integral"]

    conserved = total_cells([])  # painter2018: m is conserved, so this is also the initial total
    grown = total_cells(['kinetics.name="painter2018_logistic"', "parameters.r_m=0.05", "parameters.m_cap=2.0"])
    area, start = 400.0, conserved / 400.0
    assert abs(start - 0.75) < 0.01
    # logistic growth from ~0.75 towards 2 at rate 0.05 over t = 20 (m ~ 1.24 on average)
    expected = area * 2.0 / (1.0 + (2.0 / start - 1.0) * math.exp(-0.05 * 20))
    assert abs(grown - expected) / expected < 0.02, (grown, expected)


def test_its_parameters_are_validated():
    try:
        Model.from_file("examples/ex01a.toml", OVERRIDES + ['kinetics.name="painter2018_logistic"',
                                                             "parameters.r_m=-1"])
    except Exception as error:  # noqa: BLE001
        assert "r_m must be > 0" in str(error)
    else:
        raise AssertionError("a negative proliferation rate was accepted")


def test_its_analysis_follows_its_own_reactions():
    """primordia stability of example 1a with this kinetics: the proliferation term is in the derived Jacobian."""
    from primordia.analysis import linearise_model

    at_rest = OVERRIDES + ['kinetics.name="painter2018_logistic"', "parameters.r_m=0.05", "parameters.m_cap=0.75"]
    linear = linearise_model(Model.from_file("examples/ex01a.toml", at_rest))
    assert linear.steady_state.conserved == () and linear.steady_state.values["m"] == 0.75
    assert linear.reaction_jacobian[0, 0] == pytest.approx(-0.05, rel=1e-14)  # d/dm [r m (1 - m / m_cap)] at m = m_cap
    mode = linear.fastest_mode(kind="stationary")
    assert (round(mode.k_max, 3), round(mode.growth_rate, 4)) == (2.854, 0.1253)  # painter2018: 2.784, 0.1546
