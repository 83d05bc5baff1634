r"""Convergence of the coupled poro-mechano-chemical model (seed eqs. (2.1)-(2.5)) by manufactured solutions.

The model of seed example 1b: ``chemotaxis`` + ``poroelasticity`` (P1-P1) +
``active_stress`` + ``mechanochemical``, on both backends.  The sources of all
six fields are derived in UFL from one exact solution, coupling terms included
(solid advection u_t . grad c of m, f, b; the FGF sink xi_f div u; the active
stress (lambda + 2 mu/3) tau m / (1 + zeta m^2) I; see ``mms.CoupledProblem``).
The L2 error of every field at t = T on 16 x 16, 32 x 32 and 64 x 64 squares of
the unit square must fall like h^2 (observed rates within 0.2 of 2).

The exact solution makes every time discretisation *and the coupling lag* exact,
so that only the spatial error is measured:

* m, e, f, b: the steady zero-flux cosine profiles of ``mms.species_profiles``
  (backward Euler and the lagged IMEX terms chi(m^n), grad f^n and the explicit
  advection u_t . grad c^n are exact);
* u = U_0(x) + t U_1(x) with div U_1 = 0 (U_1 the curl of a stream function):
  u_tt = 0, and the scheme's second difference of u is exact; the solid
  velocity is the constant U_1, so the *lagged* velocity (u^n - u^{n-1}) / dt
  that advects the species is exact too;
* p = P(x) (1 + t): backward Euler is exact for the storage term, where
  d/dt div u = div U_1 = 0.

Which coupling scheme: ``sequential`` (Lie, chemotaxis then poroelasticity, as
in examples/ex01b.toml), because in this construction its lag is exact.  The
species solves of step n+1 see u^n instead of u^{n+1}: the advecting velocity
is the constant U_1 either way, and the FGF sink xi_f div u^n = xi_f div u^{n+1}
because div u does not change in time (div U_1 = 0); the solid solve sees
m^{n+1}, already computed, and m is steady anyway.  A splitting error would not
shrink with h (dt is fixed) and would show as flattened rates; ``fixed_point``
(the seed's iteration, converged to 1e-10) is run alongside as the scheme with
no splitting error by construction, and must give the same rates.
"""

from __future__ import annotations

import pytest

from mms import CoupledProblem, PoroelasticProblem, l2_errors, manufactured_sources_registered, observed_rates
from primordia.core.meshes import rectangle
from primordia.coupling.orchestrator import Simulation
from primordia.model import Model

CELLS_PER_SIDE = (16, 32, 64)
DT, STEPS = 0.2, 3
#: D_m = 0.5 keeps the cell Peclet number small (as in test_chemotaxis_mms.py); mechanics of order one;
#: the couplings tau and xi_f strong enough that their terms are a large part of the sources.  The active
#: stress acts through d/dm [m / (1 + m^2)] grad m, small where m is near 1: at tau = 0.5 its force was 1.5%
#: of the momentum source, and (lambda + mu) for (lambda + 2 mu/3) in (2.5) kept every rate within 0.1 of 2.
PARAMETERS = {"D_m": 0.5, "E": 10.0, "nu": 0.3, "C_0": 1.0, "kappa": 1.0, "eta": 1.0, "alpha_BW": 1.0,
              "rho": 1.0, "tau": 20.0, "zeta": 1.0, "xi_f": 0.5}

#: U_0 with div U_0 != 0 (the FGF sink sees it); U_1 = curl(sin(pi x) sin(pi y) / pi), divergence-free.
U0 = ["0.5 * sin(pi * x[0]) * x[1]", "0.5 * cos(pi * x[1]) * x[0] + 0.2 * x[1] ** 2"]
U1 = ["sin(pi * x[0]) * cos(pi * x[1])", "-cos(pi * x[0]) * sin(pi * x[1])"]
SOLID = PoroelasticProblem(displacement=[f"{a} + t * ({b})" for a, b in zip(U0, U1)],
                           pressure="(cos(pi * x[0]) * sin(pi * x[1]) + 0.5 * x[0]) * (1 + t)")
EXACT = CoupledProblem(SOLID)
SIDES = ("left", "right", "bottom", "top")


def manufactured_run(backend: str, coupling: dict, cells: int, out_dir) -> dict[str, float]:
    """L2 errors of m, e, f, b, u, p at t = STEPS * DT on a cells x cells mesh."""
    model = Model(
        physics=["chemotaxis", "poroelasticity", "active_stress", "mechanochemical", "manufactured_sources"],
        kinetics={"name": "painter2018", "priming_wave": False},  # w = omega_1: no moving front
        parameters=PARAMETERS,
        mesh=rectangle((0.0, 0.0), (1.0, 1.0), (cells, cells)),
        dt=DT,
        t_final=STEPS * DT,
        output={"pictures": False, "series_every": 10**6},
        physics_options={"chemotaxis": {"flux_scheme": "exponential_fitting", "perturbation": 0.0},
                         "poroelasticity": {"boundary": [bc for side in SIDES for bc in SOLID.dirichlet(side)]}},
        coupling=coupling,
    )
    sim = Simulation(model, backend=backend, out_dir=out_dir).setup()
    while sim.step_index < model.num_steps:
        sim.step()
    assert sim.time == pytest.approx(STEPS * DT)
    return l2_errors(sim, EXACT)


@pytest.mark.parametrize("coupling", [{"scheme": "sequential"}, {"scheme": "fixed_point", "tolerance": 1e-10}],
                         ids=["sequential", "fixed_point"])
@pytest.mark.parametrize("backend", ["fenicsx", "skfem"])
def test_coupled_p1_converges_at_second_order_in_l2(backend, coupling, tmp_path):
    with manufactured_sources_registered(EXACT):
        errors = [manufactured_run(backend, coupling, n, tmp_path / f"n{n}") for n in CELLS_PER_SIDE]
    sizes = [1.0 / n for n in CELLS_PER_SIDE]
    report = []
    for name in EXACT.fields:
        successive, fitted = observed_rates(sizes, [e[name] for e in errors])
        report.append(f"{name}: errors {[f'{e[name]:.3e}' for e in errors]}, "
                      f"rates {[round(r, 3) for r in successive]}, fitted {fitted:.3f}")
    print(f"[{backend}, {coupling['scheme']}]\n" + "\n".join(report))
    for name in EXACT.fields:
        successive, fitted = observed_rates(sizes, [e[name] for e in errors])
        assert abs(fitted - 2.0) < 0.2, "\n".join(report)
        assert all(abs(r - 2.0) < 0.2 for r in successive), "\n".join(report)
