"""One petsc4py solver layer for every backend.

A :class:`SubproblemSolver` solves ``residual(unknown) = 0`` by Newton's method
with a PETSc KSP configured from the options database under the subproblem's
prefix (e.g. ``-chemotaxis_m_ksp_type gmres``).  Defaults come from the
physics (``Subproblem.petsc_options``), then the config's ``[solver.PREFIX]``
table, then the command line, each overriding the previous one.  MUMPS and
hypre are available through the usual ``pc_factor_mat_solver_type`` /
``pc_type hypre`` options.

Linear subproblems take one Newton step (exact); a constant Jacobian is
assembled once and its preconditioner (e.g. an LU factorisation) reused.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from petsc4py import PETSc

from primordia.core.errors import SolverError
from primordia.coupling.edge_flux import apply_operator


@dataclass
class SolveStats:
    newton_iterations: int = 0
    linear_iterations: int = 0

    def __iadd__(self, other: "SolveStats") -> "SolveStats":
        self.newton_iterations += other.newton_iterations
        self.linear_iterations += other.linear_iterations
        return self


def accumulate(totals: dict[str, SolveStats], name: str, stats: SolveStats) -> None:
    """Add one solve's statistics to the running totals of subproblem ``name``."""
    totals.setdefault(name, SolveStats())
    totals[name] += stats


def set_default_options(prefix: str, defaults: dict, overrides: dict | None = None) -> None:
    """Write defaults (unless already set, e.g. on the command line) and overrides."""
    options = PETSc.Options()
    for key, value in defaults.items():
        if not options.hasName(prefix + key):
            options[prefix + key] = _option_text(value)
    for key, value in (overrides or {}).items():
        options[prefix + key] = _option_text(value)


def _parallel_safe(defaults: dict, comm) -> dict:
    """LU needs MUMPS on more than one rank; PETSc's own LU is faster in serial."""
    if defaults.get("pc_type") == "lu" and "pc_factor_mat_solver_type" not in defaults:
        return {**defaults, "pc_factor_mat_solver_type": "mumps" if comm.size > 1 else "petsc"}
    return defaults


def _option_text(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


class SubproblemSolver:
    """Newton + KSP for one :class:`~primordia.physics.base.Subproblem`."""

    def __init__(self, backend, subproblem, overrides: dict | None = None,
                 rtol: float = 1e-8, atol: float = 1e-10, max_iterations: int = 25):
        self.backend, self.sub = backend, subproblem
        self.rtol, self.atol, self.max_iterations = rtol, atol, max_iterations
        set_default_options(subproblem.prefix, _parallel_safe(subproblem.petsc_options, backend.comm), overrides)
        self.ksp = PETSc.KSP().create(backend.comm)
        self.ksp.setOptionsPrefix(subproblem.prefix)
        self.ksp.setFromOptions()
        self._jacobian = None  # assembled UFL Jacobian
        self._combined = None  # UFL Jacobian + algebraic operator
        self._residual = None
        self._increment = None

    def _assemble_jacobian(self):
        sub, backend = self.sub, self.backend
        if self._jacobian is None or not sub.constant_jacobian:
            self._jacobian = backend.assemble_matrix(sub.jacobian, sub.bcs, A=self._jacobian)
            fresh = True
        else:
            fresh = False
        if sub.operator is None:
            return self._jacobian, fresh
        operator = sub.operator.matrix()
        if self._combined is None:
            self._combined = operator.duplicate(copy=True)
        else:
            operator.copy(self._combined, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self._combined.axpy(1.0, self._jacobian, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        return self._combined, True

    def _assemble_residual(self, x):
        sub = self.sub
        self._residual = self.backend.assemble_residual(sub.residual, sub.jacobian, sub.bcs,
                                                        sub.unknown, b=self._residual)
        if sub.operator is not None:
            apply_operator(sub.operator, x, self._residual)
        return self._residual

    def solve(self) -> SolveStats:
        sub, backend = self.sub, self.backend
        stats = SolveStats()
        x = backend.petsc_vector(sub.unknown)
        if sub.operator is not None:
            sub.operator.update()
        first_norm = None
        for iteration in range(self.max_iterations):
            b = self._assemble_residual(x)
            norm = b.norm()
            if not np.isfinite(norm):
                raise SolverError(f"{sub.name}: the residual is not finite")
            first_norm = norm if first_norm is None else first_norm
            if iteration > 0 and (norm < self.atol or norm < self.rtol * first_norm):
                break
            A, changed = self._assemble_jacobian()
            if changed or iteration == 0:
                self.ksp.setOperators(A)
            if self._increment is None:
                self._increment = A.createVecRight()
            self._solve_linear(b)
            reason = self.ksp.getConvergedReason()
            if reason < 0:
                raise SolverError(f"{sub.name}: the linear solver diverged (PETSc reason {reason}); "
                                  f"try other options under -{sub.prefix}")
            stats.linear_iterations += max(self.ksp.getIterationNumber(), 1)
            x.axpy(-1.0, self._increment)
            backend.update_ghosts(sub.unknown)
            stats.newton_iterations += 1
            if sub.linear:
                break
        else:
            raise SolverError(f"{sub.name}: Newton did not converge in {self.max_iterations} iterations "
                              f"(residual {norm:.3e}, initial {first_norm:.3e})")
        if not np.isfinite(x.norm()):
            raise SolverError(f"{sub.name}: the solution is not finite")
        return stats

    def _solve_linear(self, b):
        """KSP solve; an unpivoted LU that meets a zero pivot is retried once with MUMPS."""
        try:
            self.ksp.solve(b, self._increment)
            failed = self.ksp.getConvergedReason() == PETSc.KSP.ConvergedReason.DIVERGED_PCSETUP_FAILED
        except PETSc.Error as error:
            failed, raised = True, error
        else:
            raised = None
        pc = self.ksp.getPC()
        if not failed:
            return
        if pc.getType() != "lu" or pc.getFactorSolverType() == "mumps":
            if raised is None:
                return  # a failed preconditioner set-up: reported by the caller from the KSP reason
            raise SolverError(f"{self.sub.name}: the linear solve failed (PETSc error {raised.ierr}); "
                              f"try other options under -{self.sub.prefix}") from None
        warnings.warn(f"{self.sub.name}: PETSc's unpivoted LU met a zero pivot, switching to MUMPS", stacklevel=3)
        operators = self.ksp.getOperators()
        PETSc.Options()[self.sub.prefix + "pc_factor_mat_solver_type"] = "mumps"
        self.ksp.reset()
        self.ksp.setFromOptions()
        self.ksp.setOperators(*operators)
        self.ksp.solve(b, self._increment)
