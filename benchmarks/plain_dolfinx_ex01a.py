"""Seed example 1a as a plain dolfinx 0.5 script: the reference for the framework's overhead.

The same discrete scheme as primordia's chemotaxis module (lumped mass,
exponentially fitted cell flux, IMEX species solves in the order m, e, f, b,
same PETSc solvers), written directly against dolfinx without any framework
layer.  Used by bench_examples.py; run alone:  python plain_dolfinx_ex01a.py 171 50
"""

import argparse
import logging
import time

import numpy as np
import ufl
from dolfinx import fem, mesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

P = dict(m0=0.75, D_m=0.03, D_f=0.1, D_b=1.0, alpha=4.0, gamma=1.0, kappa_1=0.05, kappa_2=0.025, kappa_3=1.0,
         kappa_4=1.0, K_1=1.0, K_2=2.0, K_3=5.0, P_1=2.0, P_2=2.0, P_3=2.0, delta_F=1.0, omega_1=1.0, omega_2=5.0,
         omega_3=0.04, kappa_F=1.0, kappa_B=1.0, delta_B=1.0)


def hill(m, i):
    return m ** P[f"P_{i}"] / (P[f"K_{i}"] ** P[f"P_{i}"] + m ** P[f"P_{i}"])


def bernoulli(x):
    small = np.abs(x) < 1e-6
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 - 0.5 * x + x * x / 12.0, safe / np.expm1(safe))


def ksp(comm, A, kind):
    solver = PETSc.KSP().create(comm)
    solver.setOperators(A)
    if kind == "lu":
        solver.setType("preonly"); solver.getPC().setType("lu")
        solver.getPC().setFactorSolverType("petsc"); solver.getPC().setFactorOrdering("nd")
    elif kind == "jacobi":
        solver.setType("preonly"); solver.getPC().setType("jacobi")
    else:
        solver.setType("gmres"); solver.getPC().setType("bjacobi"); solver.setTolerances(rtol=1e-12, atol=1e-14)
    return solver


def main(n: int, steps: int, dt: float = 0.2) -> float:
    comm = MPI.COMM_WORLD
    domain = mesh.create_rectangle(comm, [np.array([0.0, 0.0]), np.array([20.0, 20.0])], [n, n],
                                   mesh.CellType.triangle, diagonal=mesh.DiagonalType.right)
    V = fem.FunctionSpace(domain, ("CG", 1))
    m, e, f, b = (fem.Function(V) for _ in range(4))
    m_n, e_n, f_n, b_n = (fem.Function(V) for _ in range(4))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    dxl = ufl.dx(metadata={"quadrature_rule": "vertex", "quadrature_degree": 1})
    x = ufl.SpatialCoordinate(domain)
    t = fem.Constant(domain, 0.0)

    # initial data (seed eq. (2.6)), perturbed m
    rng = np.random.default_rng(1)
    m.x.array[:] = P["m0"] * (1 + 0.01 * rng.uniform(-1, 1, m.x.array.size))
    b0 = hill(P["m0"], 3) * P["m0"]
    m0 = P["m0"]
    def e_initial(X):
        w = 0.5 * (1 + np.tanh(P["omega_2"] * (0 - X[1] / P["omega_3"])))
        kon = P["kappa_1"] * w * hill(m0, 1) + P["kappa_2"] * hill(m0, 2)
        return kon / (kon + (1 - hill(m0, 1)) * (P["kappa_3"] + P["kappa_4"] * b0))
    e.interpolate(e_initial); f.x.array[:] = e.x.array; b.x.array[:] = b0

    # forms
    w = 0.5 * P["omega_1"] * (1 + ufl.tanh(P["omega_2"] * (t - x[1] / P["omega_3"])))
    kon = P["kappa_1"] * w * hill(m, 1) + P["kappa_2"] * hill(m, 2)
    koff = (1 - hill(m, 1)) * (P["kappa_3"] + P["kappa_4"] * b)
    a_m = fem.form(u / dt * v * dxl)
    L_m = fem.form(m_n / dt * v * dxl)
    a_e = fem.form((1 / dt + kon + koff) * u * v * dxl)
    L_e = fem.form((e_n / dt + kon) * v * dxl)
    a_f = fem.form((1 / dt + P["delta_F"]) * u * v * dxl + P["D_f"] * ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx)
    L_f = fem.form((f_n / dt + P["kappa_F"] * e) * v * dxl)
    a_b = fem.form((1 / dt + P["delta_B"]) * u * v * dxl + P["D_b"] * ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx)
    L_b = fem.form((b_n / dt + P["kappa_B"] * hill(m, 3) * m) * v * dxl)
    stiffness = fem_petsc.assemble_matrix(fem.form(ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx)); stiffness.assemble()

    # exponentially fitted cell transport from the stiffness pattern
    indptr, cols, vals = stiffness.getValuesCSR()
    rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    diag = np.flatnonzero(cols == rows)
    weights = np.where(cols == rows, 0.0, -vals) * P["D_m"]
    A_chi = stiffness.duplicate(copy=True)
    M_m = fem_petsc.assemble_matrix(a_m); M_m.assemble()
    J_m = A_chi.duplicate(copy=True)

    A_e = fem_petsc.assemble_matrix(a_e); A_e.assemble()
    A_f = fem_petsc.assemble_matrix(a_f); A_f.assemble()
    A_b = fem_petsc.assemble_matrix(a_b); A_b.assemble()
    solvers = dict(m=ksp(comm, J_m, "gmres"), e=ksp(comm, A_e, "jacobi"), f=ksp(comm, A_f, "lu"), b=ksp(comm, A_b, "lu"))
    rhs = {k: fem_petsc.create_vector(L) for k, L in dict(m=L_m, e=L_e, f=L_f, b=L_b).items()}

    def solve(name, L, function):
        vec = rhs[name]
        with vec.localForm() as loc:
            loc.set(0.0)
        fem_petsc.assemble_vector(vec, L)
        solvers[name].solve(vec, function.vector)
        function.x.scatter_forward()

    start = time.perf_counter()
    for step in range(steps):
        for new, old in ((m, m_n), (e, e_n), (f, f_n), (b, b_n)):
            old.x.array[:] = new.x.array
        t.value = (step + 1) * dt
        chi = P["alpha"] * np.exp(-P["gamma"] * m_n.x.array)
        peclet = 0.5 * (chi[rows] + chi[cols]) * (f_n.x.array[cols] - f_n.x.array[rows]) / P["D_m"]
        values = -weights * bernoulli(peclet)
        values[diag] = np.bincount(rows, weights=weights * bernoulli(-peclet), minlength=len(indptr) - 1)
        A_chi.setValuesCSR(indptr, cols, values); A_chi.assemble()
        A_chi.copy(J_m, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        J_m.axpy(1.0, M_m, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        solvers["m"].setOperators(J_m)
        solve("m", L_m, m)
        A_e.zeroEntries(); fem_petsc.assemble_matrix(A_e, a_e); A_e.assemble()
        solvers["e"].setOperators(A_e)
        solve("e", L_e, e)
        solve("f", L_f, f)
        solve("b", L_b, b)
    elapsed = time.perf_counter() - start
    return 1e3 * elapsed / steps, float(m.vector.min()[1]), float(m.vector.max()[1])


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cells", nargs="?", type=int, default=171, help="squares per side (default 171, the seed's)")
    parser.add_argument("steps", nargs="?", type=int, default=50, help="time steps to time (default 50)")
    arguments = parser.parse_args()
    logging.disable(logging.INFO)  # not the JIT build lines setuptools logs at the first run of a size
    n, steps = arguments.cells, arguments.steps
    if n < 1 or steps < 1:
        parser.error("cells and steps must be positive")
    ms, m_min, m_max = main(n, steps)
    print(f"plain dolfinx: {n}x{n}: {ms:.2f} ms/step (m in [{m_min:.4f}, {m_max:.4f}])")
