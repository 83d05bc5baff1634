r"""Assembly of a Taylor-Hood finite-strain growth system on both backends: skfem vs fenicsx.

The form is representative of the (u, psi, p) system of example 2a: P2
displacement, P1 solid pressure psi, P1 fluid pressure p, with a prescribed
isotropic growth g(x) (F_g = g I):

    F = I + grad u,  J = det F,  F_e = F F_g^{-1},  B_e = F_e F_e^T,  C = F^T F
    P_e = J (mu B_e - psi I) F^{-T}                      momentum:   P_e : grad w
    (J - J_g) phi,  J_g = det F_g                         constraint
    J C^{-1} grad p . grad q                              Darcy flux

integrated with an explicit quadrature degree of 4; the Jacobian is
``ufl.derivative`` of the residual.  Prints, for 43, 86 and 171 squares per side
and a small box, the time (ms, best of repeats, after one warm-up assembly that
includes JIT / form preprocessing) of assembling the residual and the Jacobian,
and the ratios skfem/fenicsx.  ``--clock cpu`` times the process's CPU time
instead of the wall clock: steadier on a machine others are using (it counts
every thread of the process, BLAS's included).

    .venv/bin/python benchmarks/bench_skfem_mixed.py [--sizes 43 86 171] [--box 8] [--repeats 3] [--clock cpu]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import ufl
from mpi4py import MPI

from primordia.core.meshes import box, rectangle
from primordia.core.clocks import CLOCKS

from machine import describe, require_at_least  # benchmarks/machine.py


def growth_system(backend, data):
    """Residual and Jacobian forms of the finite-strain growth system on ``data``, state set."""
    mesh = backend.create_mesh(data)
    cell = mesh.ufl_domain().ufl_cell()
    P1 = ufl.FiniteElement("Lagrange", cell, 1)
    space = backend.function_space(mesh, ufl.MixedElement([ufl.VectorElement("Lagrange", cell, 2), P1, P1]))
    state = backend.function(space, "state")
    gdim = data.gdim
    backend.interpolate_component(state, 0, lambda x: 0.02 * np.stack([np.sin(x[(i + 1) % gdim]) for i in range(gdim)]))
    backend.interpolate_component(state, 1, lambda x: 0.5 + 0.1 * x[0])
    backend.interpolate_component(state, 2, lambda x: 0.1 * np.cos(x[1]))
    u, psi, p = ufl.split(state)
    w, phi, q = ufl.TestFunctions(space)
    x = ufl.SpatialCoordinate(mesh)
    growth = 1.0 + 0.05 * ufl.sin(x[0])
    identity = ufl.Identity(gdim)
    F = identity + ufl.grad(u)
    J = ufl.det(F)
    F_e = F / growth
    B_e = F_e * F_e.T
    P_e = J * (backend.constant(mesh, 1.3) * B_e - psi * identity) * ufl.inv(F).T
    C = F.T * F
    dx = ufl.dx(domain=mesh, metadata={"quadrature_degree": 4})
    residual = (ufl.inner(P_e, ufl.grad(w)) + (J - growth ** gdim) * phi
                + J * ufl.inner(ufl.inv(C) * ufl.grad(p), ufl.grad(q))) * dx
    return residual, ufl.derivative(residual, state, ufl.TrialFunction(space)), space


def best_ms(repeats: int, fn, clock=time.perf_counter) -> float:
    fn()  # warm-up: JIT (fenicsx) or form preprocessing (skfem)
    times = []
    for _ in range(repeats):
        start = clock()
        fn()
        times.append(clock() - start)
    return 1e3 * min(times)


def timings(backend, data, repeats: int, clock) -> tuple[float, float, int]:
    residual, jacobian, space = growth_system(backend, data)
    A = backend.assemble_matrix(jacobian)
    b = backend.assemble_vector(residual)
    return (best_ms(repeats, lambda: backend.assemble_vector(residual, b), clock),
            best_ms(repeats, lambda: backend.assemble_matrix(jacobian, A=A), clock),
            backend.num_dofs(space))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[43, 86, 171], help="squares per side (2D)")
    parser.add_argument("--box", type=int, nargs="*", default=[8], help="hexahedra per side (3D)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--clock", choices=CLOCKS, default="wall")
    args = parser.parse_args()
    require_at_least(parser, ("--repeats", args.repeats, 1), ("--sizes", min(args.sizes), 1),
                     ("--box", min(args.box, default=1), 1))
    print(describe(), flush=True)
    clock = CLOCKS[args.clock]

    from primordia.backends.fenicsx import FenicsxBackend
    from primordia.backends.skfem import SkfemBackend

    meshes = [(f"{n}^2", rectangle((0.0, 0.0), (20.0, 20.0), (n, n))) for n in args.sizes]
    meshes += [(f"{n}^3", box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (n, n, n))) for n in args.box]
    print(f"P2-P1-P1 finite-strain growth system, ms per assembly ({args.clock} clock, best of {args.repeats})")
    print(f"{'mesh':>6} {'dofs':>8} | {'residual':>25} | {'Jacobian':>25} | {'both':>7}")
    print(f"{'':>6} {'':>8} | {'fenicsx':>8} {'skfem':>8} {'ratio':>7} | {'fenicsx':>8} {'skfem':>8} {'ratio':>7} |"
          f" {'ratio':>7}")
    for label, data in meshes:
        fx_residual, fx_jacobian, dofs = timings(FenicsxBackend(MPI.COMM_WORLD), data, args.repeats, clock)
        sk_residual, sk_jacobian, _ = timings(SkfemBackend(), data, args.repeats, clock)
        both = (sk_residual + sk_jacobian) / (fx_residual + fx_jacobian)  # one Newton iteration
        print(f"{label:>6} {dofs:>8} | {fx_residual:>8.1f} {sk_residual:>8.1f} {sk_residual / fx_residual:>7.2f} | "
              f"{fx_jacobian:>8.1f} {sk_jacobian:>8.1f} {sk_jacobian / fx_jacobian:>7.2f} | {both:>7.2f}", flush=True)


if __name__ == "__main__":
    main()
