r"""Convergence of linear Biot poroelasticity with inertia (seed eqs. (2.1a)-(2.1c)) by manufactured solutions.

Both element pairs of ``primordia.physics.poroelastic_linear`` (P1-P1, the
seed's, and Taylor-Hood P2-P1) on both backends, with Dirichlet data on every
side or with a traction and a fluid flux on some sides: the L2 errors of u and
p at t = T on 16 x 16, 32 x 32 and 64 x 64 squares of the unit square must
fall at the theoretical rates, observed rates (successive and fitted) within 0.2.

Theoretical rates.  P1-P1: u 2, p 2.  P2-P1: p 2; u 3 *only when the pressure
is resolved*.  In Biot's system the pressure is not a Lagrange multiplier
(as in Stokes, where P2-P1 gives u at h^3) but the solution of its own
parabolic equation, and its P1 error p - p_h (O(h^2) in L2, and no better in
H^-1 for P1) forces the momentum balance through -p I: the displacement then
carries an O(h^2) error as well.  Measured (P2-P1, this problem, meshes
8-16-32): u rates 2.17, 2.04 with a generic pressure, 3.07, 3.02 with a
pressure affine in x (exactly representable: no pollution), and still fitted
2.31 with kappa = 1e-6 or 2.10 with C_0 = alpha_BW = 1e-6.  So the P2-P1 pair is checked on
two exact solutions sharing the displacement: ``generic`` (p non-polynomial;
u and p at 2) and ``affine_pressure`` (p = (a . x)(1 + t); u at 3).

The time discretisation is made exact, so that what is measured is the spatial
error alone (a time error would not shrink with h and would flatten the rates):

    u = U(x) t^2 + V(x) (1 + t),  div U = 0  (U the curl of a stream function),
    p = P(x) (1 + t).

* inertia: the scheme's rho (u^{n+1} - u^n - dt v^n) / dt^2 with
  v^n = (u^n - u^{n-1}) / dt is rho times the second difference of u, which is
  exact (= u_tt = 2U) for u quadratic in t; the initial velocity is set to the
  backward difference (u(0) - u(-dt)) / dt, so that this also holds in the first step;
* storage: d/dt (C_0 p + alpha_BW div u) = d/dt (C_0 P (1 + t) + alpha_BW div V (1 + t))
  is linear in t (div U = 0 removes the t^2 part), where backward Euler is exact;
* elastic, Darcy and boundary terms are evaluated at t^{n+1}, as are the sources.

That this is needed, and enough: starting instead from the exact velocity u_t(0)
(an O(dt) inertia error in the first step) the P2-P1 u error stalls at 1.7e-4 on
all three meshes (rates 0.08, 0.004); with the backward difference it falls at 3.

The exact solution is written once, as the formula strings of the run's
boundary conditions (``displacement``, ``fluid_pressure``); the sources are
derived from the same strings in UFL, the Neumann data (``traction``,
``fluid_flux``) with sympy (see ``tests/support/mms.py``).
"""

from __future__ import annotations

import pytest

from mms import PoroelasticProblem, l2_errors, manufactured_sources_registered, observed_rates
from primordia.core.meshes import rectangle
from primordia.coupling.orchestrator import Simulation
from primordia.model import Model

CELLS_PER_SIDE = (16, 32, 64)
DT, STEPS = 0.2, 3
#: Moderate values of order one (E ~ 10): every term of (2.1a)-(2.1c) matters.
PARAMETERS = {"E": 10.0, "nu": 0.3, "C_0": 1.0, "kappa": 1.0, "eta": 1.0, "alpha_BW": 1.0, "rho": 1.0}

#: U = curl(sin(pi x) sin(pi y) / pi) (divergence-free), V, P: smooth and not polynomial.
STREAM = ["sin(pi * x[0]) * cos(pi * x[1])", "-cos(pi * x[0]) * sin(pi * x[1])"]
DILATION = ["0.5 * sin(pi * x[0]) * x[1]", "0.5 * cos(pi * x[1]) * x[0] + 0.2 * x[1] ** 2"]
DISPLACEMENT = [f"({U}) * t ** 2 + ({V}) * (1 + t)" for U, V in zip(STREAM, DILATION)]
EXACT = {
    "generic": PoroelasticProblem(DISPLACEMENT, "(cos(pi * x[0]) * sin(pi * x[1]) + 0.5 * x[0]) * (1 + t)"),
    "affine_pressure": PoroelasticProblem(DISPLACEMENT, "(0.5 * x[0] - 0.3 * x[1]) * (1 + t)"),
}
#: Outward normals of the sides of the unit square.
NORMALS = {"left": (-1, 0), "right": (1, 0), "bottom": (0, -1), "top": (0, 1)}
#: (element pair, exact solution, theoretical L2 rates): see the module docstring.
CASES = [
    pytest.param(1, "generic", {"u": 2.0, "p": 2.0}, id="P1-P1"),
    pytest.param(2, "generic", {"u": 2.0, "p": 2.0}, id="P2-P1"),
    pytest.param(2, "affine_pressure", {"u": 3.0}, id="P2-P1-affine-pressure"),
]


def boundary_conditions(exact: PoroelasticProblem, kind: str) -> list[dict]:
    """``dirichlet``: u and p prescribed on all sides; ``mixed``: a traction on the right
    side and a fluid flux on the top (p prescribed there is replaced), Dirichlet elsewhere."""
    if kind == "dirichlet":
        return [bc for side in NORMALS for bc in exact.dirichlet(side)]
    conditions = [bc for side in ("left", "bottom") for bc in exact.dirichlet(side)]
    conditions.append({"boundary": "right", "type": "traction", "value": exact.traction(PARAMETERS, NORMALS["right"])})
    conditions.append({"boundary": "right", "type": "fluid_pressure", "value": exact.pressure_text})
    conditions.append({"boundary": "top", "type": "displacement", "value": exact.displacement_text})
    conditions.append({"boundary": "top", "type": "fluid_flux", "value": exact.fluid_flux(PARAMETERS, NORMALS["top"])})
    return conditions


def manufactured_run(backend: str, degree: int, exact: PoroelasticProblem, kind: str, cells: int,
                     out_dir) -> dict[str, float]:
    """L2 errors of u and p at t = STEPS * DT on a cells x cells mesh."""
    model = Model(
        physics=["poroelasticity", "manufactured_sources"],
        parameters=PARAMETERS,
        mesh=rectangle((0.0, 0.0), (1.0, 1.0), (cells, cells)),
        dt=DT,
        t_final=STEPS * DT,
        output={"pictures": False, "series_every": 10**6},
        physics_options={"poroelasticity": {"displacement_degree": degree,
                                            "boundary": boundary_conditions(exact, kind)}},
    )
    sim = Simulation(model, backend=backend, out_dir=out_dir).setup()
    while sim.step_index < model.num_steps:
        sim.step()
    assert sim.time == pytest.approx(STEPS * DT)
    return l2_errors(sim, exact)


@pytest.mark.parametrize("kind", ["dirichlet", "mixed"])
@pytest.mark.parametrize("degree, solution, theory", CASES)
@pytest.mark.parametrize("backend", ["fenicsx", "skfem"])
def test_poroelasticity_converges_at_the_theoretical_rates(backend, degree, solution, theory, kind, tmp_path):
    exact = EXACT[solution]
    with manufactured_sources_registered(exact):
        errors = [manufactured_run(backend, degree, exact, kind, n, tmp_path / f"n{n}") for n in CELLS_PER_SIDE]
    sizes = [1.0 / n for n in CELLS_PER_SIDE]
    report = []
    for name, expected in theory.items():
        successive, fitted = observed_rates(sizes, [e[name] for e in errors])
        report.append(f"{name}: errors {[f'{e[name]:.3e}' for e in errors]}, "
                      f"rates {[round(r, 3) for r in successive]}, fitted {fitted:.3f} (theory {expected:g})")
    print(f"[{backend}, P{degree}-P1, {solution}, {kind}]\n" + "\n".join(report))
    for name, expected in theory.items():
        successive, fitted = observed_rates(sizes, [e[name] for e in errors])
        assert abs(fitted - expected) < 0.2, "\n".join(report)
        assert all(abs(r - expected) < 0.2 for r in successive), "\n".join(report)
