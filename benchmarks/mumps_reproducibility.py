"""Whether a direct solve gives the same bits at every launch: run it several times under mpirun and compare.

    for i in $(seq 16); do mpirun -n 2 python benchmarks/mumps_reproducibility.py; done | sort | uniq -c

prints each distinct solution's digest with the number of launches that gave it.  The matrix and
right-hand side are fixed (a non-symmetric 5-point operator on an n x n grid), so a second digest is
the solver's own.  On 2026-12-05 (Open MPI 4.1, Debian's PETSc 3.18 and MUMPS), n = 60 on 2 ranks:
MUMPS gave a second solution, 3.3e-15 apart, in 2 of 16 launches; SuperLU_DIST (``--package
superlu_dist``) and serial MUMPS never did (README, "Solvers": the growth).
"""

from __future__ import annotations

import argparse
import hashlib

import numpy as np
from petsc4py import PETSc

from machine import require_at_least  # benchmarks/machine.py


def operator(n: int) -> PETSc.Mat:
    """The fixed test matrix: a 5-point stencil with unequal, slightly varying weights (no symmetry to exploit)."""
    matrix = PETSc.Mat().createAIJ([n * n, n * n], nnz=5)
    first, last = matrix.getOwnershipRange()
    for row in range(first, last):
        x, y = divmod(row, n)
        matrix[row, row] = 4.0 + 0.1 * np.sin(row)
        for dx, dy, weight in ((1, 0, -1.0), (-1, 0, -1.3), (0, 1, -0.7), (0, -1, -1.1)):
            if 0 <= x + dx < n and 0 <= y + dy < n:
                matrix[row, (x + dx) * n + y + dy] = weight + 0.01 * np.cos(row + dx)
    matrix.assemble()
    return matrix


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=60, help="grid points per side (n^2 unknowns)")
    parser.add_argument("--package", default="mumps", help="the factor package (mumps, superlu_dist, ...)")
    arguments = parser.parse_args()
    require_at_least(parser, ("--n", arguments.n, 1))
    matrix = operator(arguments.n)
    rhs = matrix.createVecLeft()
    first, last = rhs.getOwnershipRange()
    rhs.setArray(np.cos(0.37 * np.arange(first, last)))
    solution = rhs.duplicate()
    ksp = PETSc.KSP().create()
    ksp.setOperators(matrix)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType(arguments.package)
    try:
        ksp.setUp()  # the factorisation
    except PETSc.Error as error:
        parser.error(f"--package {arguments.package}: this PETSc cannot factorise with it (PETSc error {error.ierr})")
    ksp.solve(rhs, solution)
    parts = PETSc.COMM_WORLD.tompi4py().gather(solution.getArray().tobytes(), root=0)
    if PETSc.COMM_WORLD.rank == 0:
        print(hashlib.sha256(b"".join(parts)).hexdigest()[:16])


if __name__ == "__main__":
    main()
