"""Convergence of the finite-strain growth model (seed section 4) by manufactured solutions, on both backends.

* Finite-strain poroelasticity with growth, Taylor-Hood P2-P1-P1 (seed section 5.1):
  on 8 x 8, 16 x 16 and 32 x 32 squares of the unit square the L2 errors must fall
  like h^3 (u), h^2 (psi, p) and the H1 seminorm error of u like h^2 (observed
  rates within 0.2 of these).  Growth is incompatible and anisotropic, along
  directions turned from the axes, so the solid carries residual stresses and
  F_e = F F_g^-1 is checked in full.  Three cases: ``steady`` (rho = 0, a large time
  step, the fluid stress and alpha_BW (tr C - d) at work), ``transient`` (the storage
  and the fluid source ell of (4.15) of a growth that changes in time, with a time
  discretisation that is exact for the solution) and ``inertial`` (the same with
  rho u_tt, on 8 x 8 and 16 x 16: see ``growth_mms``): the error is the spatial one.
* The chemotaxis in the reference configuration (seed (4.17a)-(4.17d) times J, with
  the FGF sink xi_f J (tr C - d)) on a tissue that grows and shears by a prescribed
  motion: every species at second order in L2, with dt = h^2, for both transport
  schemes (the exponentially fitted flux then runs on the pulled-back metric).

Exact solutions and sources: ``tests/support/growth_mms.py``; the rate fit: ``tests/support/mms.py``.
"""

from __future__ import annotations

import pytest

from growth_mms import GrowthProblem, ReferenceChemotaxisProblem, registered
from mms import SPECIES, observed_rates
from primordia.core.meshes import rectangle
from primordia.coupling.orchestrator import Simulation
from primordia.model import Model

BACKENDS = ("fenicsx", "skfem")
EXPECTED = {"u": 3.0, "grad u": 2.0, "psi": 2.0, "p": 2.0}


def _report(name, sizes, errors, expected):
    successive, fitted = observed_rates(sizes, errors)
    line = (f"{name}: errors {[f'{e:.3e}' for e in errors]}, rates {[round(r, 3) for r in successive]}, "
            f"fitted {fitted:.3f} (expected {expected})")
    return line, successive, fitted


@pytest.mark.parametrize("case", ["steady", "transient", "inertial"])
@pytest.mark.parametrize("backend", BACKENDS)
def test_taylor_hood_growth_converges_at_the_optimal_rates(backend, case, tmp_path):
    problem = GrowthProblem(case)
    cells_per_side = (8, 16) if case == "inertial" else (8, 16, 32)
    errors = []
    with registered(problem):
        for n in cells_per_side:
            model = Model(physics=["poroelastic_growth", "manufactured_growth_sources"],
                          growth_law=problem.growth_law(), parameters=problem.parameters(),
                          mesh=rectangle((0.0, 0.0), (1.0, 1.0), (n, n)), dt=problem.case["dt"],
                          t_final=problem.case["steps"] * problem.case["dt"],
                          physics_options={"poroelastic_growth": {"boundary": problem.dirichlet(),
                                                                  "initial_equilibrium": False}},
                          solver={"poroelastic_growth": {"snes_rtol": 1e-12, "snes_atol": 1e-13}},
                          output={"pictures": False, "series_every": 10**6})
            sim = Simulation(model, backend=backend, out_dir=tmp_path / f"n{n}").setup()
            while sim.step_index < model.num_steps:
                sim.step()
            errors.append(problem.errors(sim))
    sizes = [1.0 / n for n in cells_per_side]
    report = []
    for name, expected in EXPECTED.items():
        line, successive, fitted = _report(name, sizes, [e[name] for e in errors], expected)
        report.append(line)
        assert abs(fitted - expected) < 0.2, "\n".join(report)
        assert abs(successive[-1] - expected) < 0.2, "\n".join(report)
    print(f"[{backend}, {case}]\n" + "\n".join(report))


@pytest.mark.parametrize("flux_scheme", ["exponential_fitting", "galerkin"])
@pytest.mark.parametrize("backend", BACKENDS)
def test_chemotaxis_in_the_reference_configuration_converges_at_second_order(backend, flux_scheme, tmp_path):
    problem = ReferenceChemotaxisProblem()
    cells_per_side = (8, 16, 32)
    final_time = 0.0625
    errors = []
    with registered(problem):
        for n in cells_per_side:
            h = 1.0 / n
            model = Model(physics=["chemotaxis", "prescribed_motion", "mechanochemical",
                                   "manufactured_growth_sources"],
                          kinetics={"name": "painter2018", "priming_wave": False},
                          parameters={"D_m": 0.5, "xi_f": 0.4},
                          mesh=rectangle((0.0, 0.0), (1.0, 1.0), (n, n)), dt=h**2, t_final=final_time,
                          physics_options={"chemotaxis": {"flux_scheme": flux_scheme, "perturbation": 0.0}},
                          output={"pictures": False, "series_every": 10**6})
            sim = Simulation(model, backend=backend, out_dir=tmp_path / f"n{n}").setup()
            while sim.step_index < model.num_steps:
                sim.step()
            assert sim.time == pytest.approx(final_time)
            errors.append(problem.errors(sim))
    sizes = [1.0 / n for n in cells_per_side]
    report = []
    for name in SPECIES:
        line, successive, fitted = _report(name, sizes, [e[name] for e in errors], 2.0)
        report.append(line)
        assert abs(fitted - 2.0) < 0.2, "\n".join(report)
        assert all(abs(r - 2.0) < 0.2 for r in successive), "\n".join(report)
    print(f"[{backend}, {flux_scheme}]\n" + "\n".join(report))
