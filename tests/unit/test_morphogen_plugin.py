"""The installable example plugin plugins/primordia-morphogen: a third party's physics module owning a field."""

import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from primordia.core.errors import ConfigError
from primordia.core.plugins import get_plugin_manager, registry
from primordia.model import Model
from primordia.testing import assert_backends_agree, run_on_backends

DT, K_H, S_H = 0.2, 0.2, 1.5
OVERRIDES = ['model.physics=["chemotaxis", "morphogen"]', "mesh.cells=[12,12]", "time.t_final=2",
             f"output.times={[round(DT * i, 10) for i in range(1, 11)]}", "output.pictures=false",
             f"parameters.k_h={K_H}", f"parameters.s_h={S_H}", "physics.morphogen.initial_value=0.1"]


def test_it_is_found_through_its_entry_point():
    piece, origin = registry("physics", get_plugin_manager())["morphogen"]
    assert origin.startswith("primordia-morphogen ")
    listing = subprocess.run([sys.executable, "-m", "primordia", "plugins"], capture_output=True, text=True)
    assert any("morphogen" in line and "primordia-morphogen" in line for line in listing.stdout.splitlines())


def test_its_integral_obeys_the_backward_euler_step_and_the_backends_agree(tmp_path):
    """Lumped mass, zero flux: H^{n+1} (1 + dt k_h) = H^n + dt s_h M^{n+1}, with M the cells' integral of the
    same step (chemotaxis is solved first: morphogen requires m). Both backends assemble the same forms and
    solve them directly, so only round-off separates them."""
    sims = run_on_backends(lambda: Model.from_file("examples/ex01a.toml", OVERRIDES), tmp_path)
    assert_backends_agree(sims, rtol=1e-10)
    for backend, sim in sims.items():
        series = xr.open_dataset(sim.out_dir / "series.nc")
        h, m = series["h_integral"].values, series["m_integral"].values
        assert h[0] == pytest.approx(0.1 * 400.0, rel=1e-12) and len(h) == 11
        stepped = (h[:-1] + DT * S_H * m[1:]) / (1.0 + DT * K_H)
        assert np.abs(stepped - h[1:]).max() < 1e-12 * h[-1], backend
        assert series["h_integral"].attrs["long_name"] == "integral of h over the reference domain"
        assert "morphogen_h_linear_iterations" in series


def test_a_growing_tissue_is_refused_in_one_line():
    with pytest.raises(ConfigError) as refused:
        Model.from_file("examples/ex02a.toml", ['model.physics=["chemotaxis", "poroelastic_growth", '
                                                 '"mechanochemical", "morphogen"]', "mesh.cells=[4,4]"])
    assert "physics morphogen is written on a fixed tissue; poroelastic_growth grows it" in str(refused.value)
    assert "\n" not in str(refused.value)


def test_a_negative_decay_rate_is_refused():
    with pytest.raises(ConfigError, match="k_h"):
        Model.from_file("examples/ex01a.toml", [*OVERRIDES, "parameters.k_h=-1"])


@pytest.mark.parametrize("example, physics", [
    ("ex01a", '["chemotaxis", "morphogen"]'),
    ("ex01b", '["chemotaxis", "poroelasticity", "active_stress", "mechanochemical", "morphogen"]'),
])
def test_its_fourier_symbol_adds_its_own_root_to_the_analysis(example, physics):
    """Nothing the model runs reads h: the roots of det M are the model's without it, and -(D_h K + k_h)."""
    from primordia.analysis import linearise_model

    alone = linearise_model(Model.from_file(f"examples/{example}.toml", ["mesh.cells=[4,4]"]))
    linear = linearise_model(Model.from_file(f"examples/{example}.toml", [
        "mesh.cells=[4,4]", f"model.physics={physics}", f"parameters.k_h={K_H}", "parameters.D_h=0.08"]))
    assert linear.unknowns(2)[-1] == "h" and linear.extra == ("h",)
    k = np.array([0.0, 0.4, 1.3, 2.784, 6.0])
    with_h, without = linear.growth_rates(k, d=2), alone.growth_rates(k, d=2)
    for i, K in enumerate(k**2):
        expected = list(np.append(without.rates[i], -(0.08 * K + K_H)))
        got = with_h.rates[i]
        assert np.isfinite(got).sum() == np.isfinite(expected).sum(), K
        for root in got[np.isfinite(got)]:  # each root matched to the nearest expected one, once
            nearest = min(range(len(expected)), key=lambda j: abs(expected[j] - root) if np.isfinite(expected[j])
                          else np.inf)
            assert abs(expected.pop(nearest) - root) <= 1e-9 * (1.0 + abs(root)), (K, root)
    assert linear.fastest_mode(kind="stationary").k_max == pytest.approx(
        alone.fastest_mode(kind="stationary").k_max, rel=1e-6)
