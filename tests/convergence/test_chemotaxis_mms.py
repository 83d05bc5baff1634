"""P1 convergence of the chemotaxis system (seed eqs. (2.3a)-(2.3d)) by manufactured solutions.

Both transport schemes of ``primordia.physics.chemotaxis`` (the exponentially
fitted edge flux and plain Galerkin) on both backends: the L2 error of every
species at t = T on 8 x 8, 16 x 16 and 32 x 32 squares of the unit square must
fall like h^2 (observed rates within 0.2 of 2).

Backward Euler is first order in time, so dt = h^2 (16, 64, 256 steps to
T = 1/4): the time error then shrinks like h^2 too, and a spatial error of
order h would show as a rate near 1.  With D_m = 0.5 the cell Peclet number
chi |grad f| h / D_m stays below 0.6 on the coarsest mesh, where the fitted
flux is already in its central (second-order) regime.  The exact solution,
the sources and the rate fit live in ``tests/support/mms.py``.
"""

from __future__ import annotations

import pytest

from mms import SPECIES, l2_errors, manufactured_sources_registered, observed_rates
from primordia.core.meshes import rectangle
from primordia.coupling.orchestrator import Simulation
from primordia.model import Model

CELLS_PER_SIDE = (8, 16, 32)
FINAL_TIME = 0.25
PARAMETERS = {"D_m": 0.5}  # D_f, D_b, alpha, gamma and the kinetics keep their seed values


def manufactured_run(backend: str, flux_scheme: str, cells: int, out_dir) -> dict[str, float]:
    """L2 errors of m, e, f, b at FINAL_TIME on a cells x cells mesh, dt = h^2."""
    h = 1.0 / cells
    model = Model(
        physics=["chemotaxis", "manufactured_sources"],
        kinetics={"name": "painter2018", "priming_wave": False},  # w = omega_1: no moving front
        parameters=PARAMETERS,
        mesh=rectangle((0.0, 0.0), (1.0, 1.0), (cells, cells)),
        dt=h**2,
        t_final=FINAL_TIME,
        output={"pictures": False, "series_every": 10**6},
        physics_options={"chemotaxis": {"flux_scheme": flux_scheme, "perturbation": 0.0}},
    )
    sim = Simulation(model, backend=backend, out_dir=out_dir).setup()
    while sim.step_index < model.num_steps:
        sim.step()
    assert sim.time == pytest.approx(FINAL_TIME)
    return l2_errors(sim)


@pytest.mark.parametrize("flux_scheme", ["exponential_fitting", "galerkin"])
@pytest.mark.parametrize("backend", ["fenicsx", "skfem"])
def test_p1_converges_at_second_order_in_l2(backend, flux_scheme, tmp_path):
    with manufactured_sources_registered():
        errors = [manufactured_run(backend, flux_scheme, n, tmp_path / f"n{n}") for n in CELLS_PER_SIDE]
    sizes = [1.0 / n for n in CELLS_PER_SIDE]
    report = []
    for name in SPECIES:
        successive, fitted = observed_rates(sizes, [e[name] for e in errors])
        report.append(f"{name}: errors {[f'{e[name]:.3e}' for e in errors]}, "
                      f"rates {[round(r, 3) for r in successive]}, fitted {fitted:.3f}")
        assert abs(fitted - 2.0) < 0.2, "\n".join(report)
        assert all(abs(r - 2.0) < 0.2 for r in successive), "\n".join(report)
    print(f"[{backend}, {flux_scheme}]\n" + "\n".join(report))
