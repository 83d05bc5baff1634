"""One petsc4py solver layer for every backend.

:func:`SubproblemSolver` solves ``residual(unknown) = 0`` for one
:class:`~primordia.physics.base.Subproblem`, with PETSc objects configured from
the options database under the subproblem's prefix (e.g.
``-chemotaxis_m_ksp_type gmres``, ``-poroelastic_growth_snes_linesearch_type bt``).
Defaults come from this layer (:data:`NEWTON_DEFAULTS`), then the physics
(``Subproblem.petsc_options``), then the config's ``[solver.PREFIX]`` table,
then the command line, each overriding the previous one.  MUMPS and hypre are
available through the usual ``pc_factor_mat_solver_type`` / ``pc_type hypre``
options.

Two paths:

* **linear** subproblems (an affine residual: one Newton step is exact) take a
  KSP solve, :class:`LinearSolver`; a constant Jacobian is assembled once and its
  preconditioner (e.g. an LU factorisation) reused.  This is the fast path of
  the chemotaxis species and of linear poroelasticity.
* **nonlinear** subproblems go through PETSc SNES, :class:`NewtonSolver`: Newton
  with a backtracking line search and the seed's tolerances (section 5.1: 1e-7 on
  the relative or the absolute l2 norm of the residual), every option
  overridable.  The Jacobian is the UFL derivative of the residual; a separate
  preconditioning form (``Subproblem.preconditioner``) is assembled into the
  preconditioning matrix when given.  A failure raises a :class:`SolverError`
  naming SNES's reason.

Dirichlet conditions follow the backend contract (lifted residual, identity
rows), so the Newton update lands exactly on the prescribed values.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from petsc4py import PETSc

from primordia.core.errors import SolverError
from primordia.coupling.edge_flux import apply_operator

#: Defaults of every nonlinear solve (seed section 5.1), below the physics' own and the user's.
NEWTON_DEFAULTS = {
    "snes_type": "newtonls",
    "snes_linesearch_type": "bt",
    "snes_rtol": 1e-7,
    "snes_atol": 1e-7,
    "snes_stol": 0.0,
    "snes_max_it": 25,
}


@dataclass
class SolveStats:
    """What one or more solves of a subproblem cost, and how the last one ended."""

    newton_iterations: int = 0
    linear_iterations: int = 0
    #: PETSc's converged reason of the last solve (KSP for linear, SNES for nonlinear subproblems).
    reason: int = 0

    def __iadd__(self, other: "SolveStats") -> "SolveStats":
        self.newton_iterations += other.newton_iterations
        self.linear_iterations += other.linear_iterations
        self.reason = other.reason
        return self


def accumulate(totals: dict[str, SolveStats], name: str, stats: SolveStats) -> None:
    """Add one solve's statistics to the running totals of subproblem ``name``."""
    totals.setdefault(name, SolveStats())
    totals[name] += stats


#: Options PETSc had before primordia wrote any (PETSC_OPTIONS, petsc4py.init arguments): the user's, never touched.
_GIVEN_OUTSIDE = frozenset(PETSc.Options().getAll())
#: Options primordia wrote to the (process-wide) database, by prefix, so the next solver of a prefix starts clean.
_WRITTEN: dict[str, set[str]] = {}


def set_default_options(prefix: str, defaults: dict, overrides: dict | None = None) -> None:
    """Write this solver's options under ``prefix``: defaults, then overrides; options given outside win.

    PETSc's options database is process-wide: what an earlier solver of the same prefix
    wrote (another model run in the same Python process) is removed first, so one run's
    ``[solver]`` table never leaks into the next.  The options stay in the database for
    the life of the solver (PETSc reads some, e.g. MUMPS's, only when it factorises).
    """
    options = PETSc.Options()
    for name in _WRITTEN.pop(prefix, ()):
        options.delValue(name)
    written = _WRITTEN.setdefault(prefix, set())
    for key, value in {**defaults, **(overrides or {})}.items():
        name = prefix + key
        if name in _GIVEN_OUTSIDE:
            continue
        options[name] = _option_text(value)
        written.add(name)


def _parallel_safe(defaults: dict, comm) -> dict:
    """LU needs MUMPS on more than one rank; PETSc's own LU is faster in serial."""
    if defaults.get("pc_type") == "lu" and "pc_factor_mat_solver_type" not in defaults:
        return {**defaults, "pc_factor_mat_solver_type": "mumps" if comm.size > 1 else "petsc"}
    return defaults


def _option_text(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def _reason_names(enum) -> dict[int, str]:
    return {getattr(enum, name): name for name in dir(enum) if name.isupper()}


SNES_REASONS = _reason_names(PETSc.SNES.ConvergedReason)
KSP_REASONS = _reason_names(PETSc.KSP.ConvergedReason)


def SubproblemSolver(backend, subproblem, overrides: dict | None = None):
    """The solver for ``subproblem``: a KSP solve when it is linear, SNES (Newton) otherwise."""
    cls = LinearSolver if subproblem.linear else NewtonSolver
    return cls(backend, subproblem, overrides)


class _Solver:
    """What both paths share: options, the algebraic operator, assembly of residual and tangent."""

    defaults: dict = {}

    def __init__(self, backend, subproblem, overrides: dict | None = None):
        self.backend, self.sub = backend, subproblem
        set_default_options(subproblem.prefix,
                            _parallel_safe({**self.defaults, **subproblem.petsc_options}, backend.comm), overrides)
        self._jacobian = None  # assembled UFL Jacobian
        self._stale = False  # a constant Jacobian to assemble again (dt changed)
        self._combined = None  # UFL Jacobian + algebraic operator
        self._preconditioner = None  # assembled preconditioning form, when the subproblem has one
        self._residual = None

    def step_size_changed(self) -> None:
        """dt changed (an adaptive time step): a constant Jacobian holds 1/dt, so the next solve assembles it again."""
        self._stale = True

    def _assemble_jacobian(self):
        """The tangent (with the algebraic operator added) and whether it changed."""
        sub, backend = self.sub, self.backend
        if self._jacobian is None or not sub.constant_jacobian or self._stale:
            self._jacobian = backend.assemble_matrix(sub.jacobian, sub.bcs, A=self._jacobian)
            fresh, self._stale = True, False
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

    def _assemble_preconditioner(self, tangent):
        """The preconditioning matrix: the tangent itself, or the subproblem's own form."""
        if self.sub.preconditioner is None:
            return tangent
        self._preconditioner = self.backend.assemble_matrix(self.sub.preconditioner, self.sub.bcs,
                                                            A=self._preconditioner)
        return self._preconditioner

    def _assemble_residual(self, x, b=None):
        sub = self.sub
        b = self.backend.assemble_residual(sub.residual, sub.jacobian, sub.bcs, sub.unknown,
                                           b=b if b is not None else self._residual)
        if sub.operator is not None:
            apply_operator(sub.operator, x, b)
        return b


class LinearSolver(_Solver):
    """One exact Newton step, x <- x - J^{-1} F(x), for an affine residual (a KSP solve)."""

    def __init__(self, backend, subproblem, overrides: dict | None = None):
        super().__init__(backend, subproblem, overrides)
        self.ksp = PETSc.KSP().create(backend.comm)
        self.ksp.setOptionsPrefix(subproblem.prefix)
        self.ksp.setFromOptions()
        self._increment = None

    def solve(self) -> SolveStats:
        sub, backend = self.sub, self.backend
        x = backend.petsc_vector(sub.unknown)
        if sub.operator is not None:
            sub.operator.update()
        b = self._residual = self._assemble_residual(x)
        if not np.isfinite(b.norm()):
            raise SolverError(f"{sub.name}: the residual is not finite")
        A, changed = self._assemble_jacobian()
        if changed or self._increment is None:
            self.ksp.setOperators(A, self._assemble_preconditioner(A))
        if self._increment is None:
            self._increment = A.createVecRight()
        self._solve_linear(b)
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise SolverError(f"{sub.name}: the linear solver diverged (PETSc reason {KSP_REASONS.get(reason, reason)}); "
                              f"try other options under -{sub.prefix}")
        x.axpy(-1.0, self._increment)
        backend.update_ghosts(sub.unknown)
        if not np.isfinite(x.norm()):
            raise SolverError(f"{sub.name}: the solution is not finite")
        return SolveStats(newton_iterations=1, linear_iterations=max(self.ksp.getIterationNumber(), 1),
                          reason=reason)

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
        _WRITTEN.setdefault(self.sub.prefix, set()).add(self.sub.prefix + "pc_factor_mat_solver_type")
        self.ksp.reset()
        self.ksp.setFromOptions()
        self.ksp.setOperators(*operators)
        self.ksp.solve(b, self._increment)


class NewtonSolver(_Solver):
    """PETSc SNES on the subproblem's residual and its UFL tangent (seed section 5.1)."""

    defaults = NEWTON_DEFAULTS

    def __init__(self, backend, subproblem, overrides: dict | None = None):
        super().__init__(backend, subproblem, overrides)
        self.snes = PETSc.SNES().create(backend.comm)
        self.snes.setOptionsPrefix(subproblem.prefix)
        state = backend.petsc_vector(subproblem.unknown)
        # SNES iterates on its own vector: its line search evaluates F at trial points, which are
        # copied into the unknown's function only while the residual is assembled
        self._x = state.copy()
        self._F = state.duplicate()
        self.snes.setFunction(self._function, self._F)
        self._tangent_matrices = None
        self.snes.setFromOptions()
        self.ksp = self.snes.getKSP()
        self.history: tuple[np.ndarray, np.ndarray] = (np.empty(0), np.empty(0))

    # -- SNES callbacks ----------------------------------------------------------------------
    def _load(self, x) -> None:
        """Put the iterate ``x`` into the unknown's function (owned values and ghosts)."""
        state = self.backend.petsc_vector(self.sub.unknown)
        if x.handle != state.handle:
            x.copy(state)
        self.backend.update_ghosts(self.sub.unknown)

    def _function(self, snes, x, F) -> None:
        self._load(x)
        self._assemble_residual(self.backend.petsc_vector(self.sub.unknown), b=F)

    def _tangent(self, snes, x, J, P) -> None:
        self._load(x)
        self._assemble_jacobian()  # into the matrices handed to SNES (same objects)
        if self.sub.preconditioner is not None:
            self._assemble_preconditioner(None)

    def _attach_tangent(self) -> None:
        """Create the tangent (and preconditioning) matrices once, at the initial state."""
        tangent, _ = self._assemble_jacobian()
        preconditioner = self._assemble_preconditioner(tangent)
        self.snes.setJacobian(self._tangent, tangent, preconditioner)
        self._tangent_matrices = (tangent, preconditioner)

    # -- one solve ---------------------------------------------------------------------------
    def solve(self) -> SolveStats:
        sub, backend = self.sub, self.backend
        state = backend.petsc_vector(sub.unknown)
        if sub.operator is not None:
            sub.operator.update()
        if self._tangent_matrices is None:
            self._attach_tangent()
        state.copy(self._x)
        self.snes.setConvergenceHistory(length=self.snes.getTolerances()[3] + 1, reset=True)
        try:
            self.snes.solve(None, self._x)
        except PETSc.Error as error:
            raise SolverError(f"{sub.name}: the nonlinear solve failed (PETSc error {error.ierr}); "
                              f"try other options under -{sub.prefix}") from None
        self.history = tuple(np.array(h) for h in self.snes.getConvergenceHistory())
        reason = self.snes.getConvergedReason()
        if reason < 0:
            self._load(self._x)  # leave the last iterate in the field, for the record
            raise SolverError(self._failure(reason))
        self._load(self._x)
        if not np.isfinite(state.norm()):
            raise SolverError(f"{sub.name}: the solution is not finite")
        return SolveStats(newton_iterations=self.snes.getIterationNumber(),
                          linear_iterations=self.snes.getLinearSolveIterations(), reason=reason)

    def _failure(self, reason: int) -> str:
        """One line: which solve, why SNES stopped, how far it got, where to change options."""
        residuals = self.history[0]
        progress = (f", residual {residuals[-1]:.3e} from {residuals[0]:.3e}" if len(residuals) else "")
        detail = SNES_REASONS.get(reason, str(reason))
        if reason == PETSc.SNES.ConvergedReason.DIVERGED_LINEAR_SOLVE:
            detail += f" (KSP: {KSP_REASONS.get(self.ksp.getConvergedReason(), self.ksp.getConvergedReason())})"
        hint = f" ({self.sub.failure_hint})" if self.sub.failure_hint else ""
        return (f"{self.sub.name}: Newton did not converge: {detail} after {self.snes.getIterationNumber()} "
                f"iterations{progress}{hint}; options under -{self.sub.prefix}")
