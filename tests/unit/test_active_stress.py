"""The sign conventions of the mechano-chemical couplings of example 1b, by a tiny run (scikit-fem).

Seed eq. (2.5) adds sigma_act = (lambda + 2 mu/3) tau m / (1 + zeta m^2) I to the stress of (2.1b), the
stress of (2.2) being positive in tension: tau > 0 is a tension the skeleton balances by contracting (the
tissue of example 1b, clamped at the bottom and free elsewhere, pulls its top edge down and loads its fluid,
p > 0).  The seed's sentence after (2.5) calls tau > 0 a dilation; the equations, which primordia
implements, give the opposite.  The FGF sink xi_f div u of (2.3c) consumes FGF where the tissue dilates.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from primordia.core import config as config_
from primordia.model import Model


def run(tmp_path, tau: float, xi_f: float):
    config = config_.load_config(Path(__file__).resolve().parents[2] / "examples" / "ex01b.toml")
    config["mesh"]["cells"], config["time"]["dt"], config["time"]["t_final"] = [4, 4], 0.2, 0.4
    config["output"] = {"times": [0.4], "pictures": False}
    config["physics"]["poroelasticity"]["boundary"][1]["constants"]["s0"] = 0.0  # no pull: the cells alone
    config["physics"]["chemotaxis"]["perturbation"] = 0.0                       # m = m0 everywhere
    config["parameters"].update(tau=tau, xi_f=xi_f)
    sim = Model.from_config(config).run(backend="skfem", out=tmp_path / f"tau{tau}_xi{xi_f}")
    points, values = sim.model.mesh_data.points, sim.vertex_values()
    top = points[:, 1] == points[:, 1].max()
    return values["u"][top, 1].mean(), values["p"].mean(), values["f"].sum()


@pytest.mark.parametrize("tau", [1.0, -1.0])
def test_a_positive_active_stress_contracts_the_tissue_and_a_negative_one_dilates_it(tmp_path, tau):
    top_displacement, pressure, _ = run(tmp_path, tau, 0.0)
    assert np.sign(top_displacement) == -np.sign(tau) and abs(top_displacement) > 1e-3
    assert np.sign(pressure) == np.sign(tau)


@pytest.mark.parametrize("tau", [1.0, -1.0])
def test_the_fgf_sink_consumes_fgf_where_the_tissue_dilates(tmp_path, tau):
    _, _, fgf_without = run(tmp_path, tau, 0.0)
    _, _, fgf_with = run(tmp_path, tau, 0.15)
    assert np.sign(fgf_with - fgf_without) == np.sign(tau)   # contraction (tau > 0): div u < 0, a source
