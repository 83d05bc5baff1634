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

import weakref
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from petsc4py import PETSc

from primordia.core.backend import sub_elements
from primordia.core.clocks import add_since, no_time
from primordia.core.clocks import now as clock_now
from primordia.core.errors import ConfigError, SolverError, warn
from primordia.coupling.affine import AffineResidual
from primordia.coupling.solver_options import (
    FRESH, GATHER, ORDERING, OWN_OPTIONS, PACKAGE, REBUILD, SPLITS, check_types, check_used, check_values, combine,
    depends_on_step, flatten, mumps_orders_itself, option_text, parallel_safe, petsc_reason, quoted_option,
    read_options)
from primordia.physics.kinematics import rigid_motions


def petsc_failure(solve: str, code: int, reason: str, prefix: str, options: dict | None = None) -> SolverError:
    """One line for a solve PETSc stopped with error ``code``: which solve, PETSc's reason, the option of the
    user's ``options`` whose value the reason quotes (one PETSc read only at set-up, e.g. of a fieldsplit's
    sub-solver), where the options are; a usage error (:func:`~primordia.coupling.solver_options.depends_on_step`)
    is not retried smaller."""
    return SolverError(f"{solve} failed (PETSc error {code}: {reason}{quoted_option(reason, options)}); "
                       f"try other options under -{prefix}", depends_on_step=depends_on_step(code))


#: PETSc's error codes of a zero pivot in an LU and a Cholesky factorisation (petscerror.h).
ZERO_PIVOTS = frozenset({71, 81})

#: A solve repeated within a step (a fixed-point pass after the first) stops at this fraction of the step's
#: first initial residual: about 5e4 machine epsilons, sixty times the floor at which Newton stalled.
ROUND_OFF_FLOOR = 1e-11

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
#: Lower-cased, as PETSc matches names (-chemotaxis_m_KSP_RTOL is the -chemotaxis_m_ksp_rtol a table would write).
_GIVEN_OUTSIDE = frozenset(name.lower() for name in PETSc.Options().getAll())
#: Options primordia wrote to the (process-wide) database, by prefix, so the next solver of a prefix starts clean.
_WRITTEN: dict[str, set[str]] = {}


def write_options(prefix: str, options: dict) -> None:
    """Write a solver's options under ``prefix``; options given outside win.

    PETSc's options database is process-wide: what an earlier solver of the same prefix
    wrote (another model run in the same Python process) is removed first, so one run's
    ``[solver]`` table never leaks into the next.  The options stay in the database for
    the life of the solver (PETSc reads some, e.g. MUMPS's, only when it factorises).
    """
    database = PETSc.Options()
    for name in _WRITTEN.pop(prefix, ()):
        database.delValue(name)
    written = _WRITTEN.setdefault(prefix, set())
    for key, value in options.items():
        name = prefix + key
        if name.lower() in _GIVEN_OUTSIDE:
            continue
        database[name] = option_text(value)
        written.add(name)


def solver_options(defaults: dict, overrides: dict | None, where: str, parallel: bool) -> tuple[dict, list[str]]:
    """The options of one solver (defaults < config table, see :mod:`~primordia.coupling.solver_options`) and
    the keys the user gave (checked once PETSc has read them)."""
    user = flatten(overrides or {}, where)
    options = parallel_safe(combine(flatten(defaults, f"the defaults of {where}"), user), parallel)
    check_types(options, where)
    check_values(options, where)
    return options, list(user)


def _reason_names(enum) -> dict[int, str]:
    return {getattr(enum, name): name for name in dir(enum) if name.isupper()}


SNES_REASONS = _reason_names(PETSc.SNES.ConvergedReason)
KSP_REASONS = _reason_names(PETSc.KSP.ConvergedReason)


def field_splits(backend, subproblem, splits, pc, where: str) -> list:
    """Hand a fieldsplit preconditioner its splits: the index sets of the named fields of the unknown.

    ``splits`` (the ``splits`` option) lists the fields of each split; by default each
    field is a split.  A split that is the subproblem's ``rigid_body`` field (a
    displacement) gets its rigid-body motions as near-nullspace, composed on its index
    set, which is where PETSc's fieldsplit hands them to AMG.  Returns the PETSc objects
    to keep alive.
    """
    space = subproblem.unknown.ufl_function_space()
    index_sets = backend.field_index_sets(space)
    names = tuple(subproblem.fields) or tuple(str(i) for i in range(len(index_sets)))
    by_name = dict(zip(names, index_sets))
    splits = splits or tuple((name,) for name in names)
    listed = [name for split in splits for name in split]
    for name in listed:
        if name not in by_name:
            raise ConfigError(f"{where}.splits: '{name}' is not a field of {subproblem.name} "
                              f"(fields: {', '.join(names)})")
    if sorted(listed) != sorted(names):
        raise ConfigError(f"{where}.splits must hold every field of {subproblem.name} once "
                          f"({', '.join(names)}), got {[list(split) for split in splits]}")
    pairs, keep = [], []
    for split in splits:
        if len(split) == 1:
            index_set = by_name[split[0]]
        else:
            indices = np.sort(np.concatenate([by_name[name].getIndices() for name in split]))
            index_set = PETSc.IS().createGeneral(indices.astype(PETSc.IntType), comm=by_name[split[0]].getComm())
        if split == (subproblem.rigid_body,):
            near_nullspace = rigid_body_modes(backend, subproblem.unknown, names.index(split[0]), index_set)
            index_set.compose("nearnullspace", near_nullspace)
            keep.append(near_nullspace)
        pairs.append(("_".join(split), index_set))
        keep.append(index_set)
    pc.setFieldSplitIS(*pairs)
    return keep


def solver_reading(ksp, option: str, above: str = "") -> str:
    """The types of the (inner) solver whose options ``option`` (prefix and all) is one of, named by their options
    relative to ``ksp``'s: "fieldsplit_u_ksp_type preonly, fieldsplit_u_pc_type gamg" for an option of a
    fieldsplit's split, which the split's own solver reads or not (the outer "ksp_type gmres, pc_type fieldsplit"
    sent the user to the wrong one).  A preconditioner that was not set up has no inner solvers to name."""
    pc = ksp.getPC()
    inner = {"fieldsplit": pc.getFieldSplitSubKSP, "asm": pc.getASMSubKSP}.get(pc.getType())
    try:
        subs = inner() if inner is not None else []
    except PETSc.Error:
        subs = []
    own = ksp.getOptionsPrefix() or ""
    for sub in subs:
        prefix = sub.getOptionsPrefix() or ""
        if prefix.startswith(own) and len(prefix) > len(own) and option.startswith(prefix):
            return solver_reading(sub, option, above + prefix[len(own):])
    return f"{above}ksp_type {ksp.getType()}, {above}pc_type {pc.getType()}"


def rigid_body_modes(backend, unknown, index: int, index_set) -> PETSc.NullSpace:
    """The rigid-body motions of the displacement field ``index`` of ``unknown``, on its index set (orthonormal).

    Translations along each axis and rotations (-y, x) in 2D, and about each axis in 3D:
    the near-nullspace that lets AMG coarsen elasticity (without it, the coarse spaces
    miss the rotations and the iteration count grows with the mesh).
    """
    scratch = backend.function(unknown.ufl_function_space(), "rigid_body_mode")
    dimension = sub_elements(unknown.ufl_function_space().ufl_element())[index].value_shape()[0]
    modes = 3 if dimension == 2 else 6
    motions = [lambda x, k=k: rigid_motions(x[:dimension].T)[k].T for k in range(modes)]
    vectors = []
    for motion in motions:
        backend.local_array(scratch)[:] = 0.0
        backend.interpolate_component(scratch, index, motion)
        whole = backend.petsc_vector(scratch)
        part = whole.getSubVector(index_set)
        vector = part.copy()
        whole.restoreSubVector(index_set, part)
        for other in vectors:  # modified Gram-Schmidt
            vector.axpy(-vector.dot(other), other)
        vector.scale(1.0 / vector.norm())
        vectors.append(vector)
    return PETSc.NullSpace().create(vectors=vectors, comm=vectors[0].getComm())


def _weakly(method):
    """``method`` as a PETSc callback that does not keep its object alive.

    A SNES holds its callbacks. A bound method would hold the solver, which holds the SNES:
    a reference cycle that Python frees only at its next full collection, maybe long after
    the solver was dropped (at a checkpoint or a rejected step the solvers are made anew),
    with its factorisation still allocated: over 1 GB at the seed's 171 x 171 mesh, each
    time, for example 2a.  (Destroying the SNES by hand instead left 17 MB behind at 43^2.)
    """
    owner = weakref.WeakMethod(method)
    name = method.__qualname__

    def callback(*args):
        bound = owner()
        if bound is None:  # someone kept the SNES and solved with it after its solver was dropped
            raise SolverError(f"{name}: the solver that made this SNES is gone; make a new solver")
        return bound(*args)

    return callback


def SubproblemSolver(backend, subproblem, overrides: dict | None = None):
    """The solver for ``subproblem``: a KSP solve when it is linear, SNES (Newton) otherwise."""
    cls = LinearSolver if subproblem.linear else NewtonSolver
    return cls(backend, subproblem, overrides)


def check_settings(subproblem, overrides: dict | None, parallel: bool) -> None:
    """What :func:`SubproblemSolver` would refuse in the options of ``subproblem``'s solver before making it
    (``overrides``: its ``[solver.*]`` table; ``parallel``: on more than one rank), with no solver made, and a
    value PETSc cannot read as the solver reads its options (``ksp_gmres_haptol = "zz"``, a line search type it
    lacks): read by a KSP or SNES of this process alone, with no operator, whose options are then taken away
    (the dry run said "the input is valid" to them, and the run stopped at set-up)."""
    cls = LinearSolver if subproblem.linear else NewtonSolver
    options, user_keys = cls.settings(subproblem, overrides, parallel)
    options = {key: value for key, value in options.items() if key not in OWN_OPTIONS}
    write_options(subproblem.prefix, options)
    solver = (PETSc.KSP if subproblem.linear else PETSc.SNES)().create(PETSc.COMM_SELF)
    try:
        solver.setOptionsPrefix(subproblem.prefix)
        if str(options.get("pc_type")) == "fieldsplit":  # as _configure: the splits' index sets need the mesh
            (solver if subproblem.linear else solver.getKSP()).getPC().setType("fieldsplit")
        read_options(solver, f"solver.{subproblem.prefix[:-1]}", {key: options[key] for key in user_keys
                                                                   if key in options})
    finally:
        solver.destroy()
        write_options(subproblem.prefix, {})


class _Solver:
    """What both paths share: options, the algebraic operator, assembly of residual and tangent."""

    defaults: dict = {}

    def __init__(self, backend, subproblem, overrides: dict | None = None):
        self.backend, self.sub = backend, subproblem
        self.where = f"solver.{subproblem.prefix[:-1]}"
        options, self._user_keys = self.settings(subproblem, overrides, backend.comm.size > 1)
        self._splits = options.pop(SPLITS, None)
        self._rebuild_after = options.pop(REBUILD, 0) or None  # see NewtonSolver
        gather = bool(options.pop(GATHER, False))
        self._gather = gather and backend.comm.size > 1  # see LinearSolver
        #: the rank that solves the whole system when it is gathered; set by independent_batches so that
        #: subproblems solved at once go to different ranks
        self.owner = 0
        self.options = options
        #: the options the user gave, as PETSc holds them (named in a failure whose reason quotes one's value)
        self.user_options = {key: options[key] for key in self._user_keys if key in options}
        write_options(subproblem.prefix, options)
        self._unchecked = bool(self._user_keys)  # the user's options are checked once PETSc has read them
        self._jacobian = None  # assembled UFL Jacobian
        self._stale = False  # a constant Jacobian to assemble again (dt changed)
        self._combined = None  # UFL Jacobian + algebraic operator
        self._stabilisation = None  # the assembled ``Subproblem.preconditioner`` form
        self._preconditioner = None  # tangent + stabilisation
        self._residual = None
        #: Seconds spent in the linear algebra of the solves (Krylov iterations, preconditioner set-up,
        #: factorisations, diagonal divisions), not in assembly: what a step cannot do without.  By
        #: clock: "cpu" (this process's CPU time: its threads, other programs' load left out) and
        #: "wall"; hold a step's time against the same clock (numpy's BLAS threads, which spin
        #: after a product, count in CPU time while the main thread solves).
        self.linear_solve_seconds = no_time()

    @classmethod
    def settings(cls, subproblem, overrides: dict | None, parallel: bool) -> tuple[dict, list[str]]:
        """The options of this solver of ``subproblem`` (its own keys included: ``splits``, ...) and the keys the
        user gave, or one line for what can be told of them before a solver is made: by the solver, and by
        ``primordia run --dry-run`` (:func:`check_settings`), which makes none.  The dry run said "the input is
        valid" to ``splits`` under a solver that is no fieldsplit, which the run refused."""
        where = f"solver.{subproblem.prefix[:-1]}"
        options, user_keys = solver_options({**cls.defaults, **subproblem.petsc_options}, overrides, where, parallel)
        if options.get(SPLITS) is not None and str(options.get("pc_type")) != "fieldsplit":
            raise ConfigError(f"{where}.{SPLITS} names the splits of pc_type = \"fieldsplit\"; this solver's "
                              f"pc_type is {option_text(options.get('pc_type', 'PETSc default'))!r}")
        gather = bool(options.get(GATHER, False))
        if gather and not subproblem.linear:
            raise ConfigError(f"{where}.{GATHER}: a Newton solve is not gathered to one rank; the option "
                              f"is for linear subproblems")
        if gather and str(options.get("pc_type")) == "fieldsplit":
            raise ConfigError(f"{where}.{GATHER}: a system solved on one rank takes a whole-matrix "
                              f"preconditioner, not fieldsplit")
        return options, user_keys

    def step_size_changed(self) -> None:
        """dt changed (an adaptive time step): a constant Jacobian holds 1/dt, so the next solve assembles it again."""
        self._stale = True

    @contextmanager
    def repeated_within_a_step(self):
        """The block solves this subproblem several times within one time step (an outer fixed-point
        iteration); a Newton solve then judges every solve against the step's first one (see NewtonSolver)."""
        yield

    def _configure(self, pc) -> None:
        """Before PETSc reads the options: name the fields of a fieldsplit preconditioner (index sets)."""
        if str(self.options.get("pc_type")) == "fieldsplit":
            pc.setType("fieldsplit")
            self._split_objects = field_splits(self.backend, self.sub, self._splits, pc, self.where)

    def _check_options_used(self) -> None:
        """After the first solve, every option the user gave has been read by PETSc, or it is a mistake
        (a system solved on one rank: that rank's KSP read them, its verdict is every rank's)."""
        if self._unchecked:
            self._unchecked = False
            check_used(self.sub.prefix, self._user_keys, self.where,
                       comm=self.backend.comm if self._gather else None, root=self.owner,
                       in_use=lambda option: "here " + solver_reading(self.ksp, option))

    @property
    def gathered(self) -> bool:
        """Whether the whole system is solved on one rank (``solve_on_one_rank``, more than one rank)."""
        return self._gather

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
        """The preconditioning matrix: the tangent, plus the subproblem's stabilisation form when it has one.

        The stabilisation (e.g. the terms that make a block a sparse Schur complement
        approximation) is assembled once when it reads no field, and added to the tangent.
        """
        form = self.sub.preconditioner
        if form is None or str(self.options.get("pc_type")) != "fieldsplit":  # a whole-matrix preconditioner
            return tangent                                                   # works on the tangent itself
        if self._stabilisation is None or form.coefficients() or self._stale:
            self._stabilisation = self.backend.assemble_matrix(form, self.sub.bcs, A=self._stabilisation,
                                                               diagonal=0.0)
        if self._preconditioner is None:
            self._preconditioner = tangent.duplicate(copy=True)
        else:
            tangent.copy(self._preconditioner, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self._preconditioner.axpy(1.0, self._stabilisation, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        return self._preconditioner

    def _switch_to_mumps(self, ksp) -> bool:
        """An unpivoted LU met a zero pivot (a saddle point): use MUMPS from now on; False if that is not the case."""
        pc = ksp.getPC()
        if pc.getType() != "lu" or pc.getFactorSolverType() == "mumps":
            return False
        warn(f"{self.sub.name}: PETSc's unpivoted LU met a zero pivot, switching to MUMPS")
        operators = ksp.getOperators()
        self.options = mumps_orders_itself({**self.options, PACKAGE: "mumps"}, self._user_keys)  # as combine does
        write_options(self.sub.prefix, self.options)
        ksp.reset()
        ksp.setFromOptions()
        if ORDERING not in self.options:  # the PC keeps the ordering it read before the reset
            ksp.getPC().setFactorOrdering("external")
        ksp.setOperators(*operators)
        return True

    def _assemble_residual(self, x, b=None):
        sub = self.sub
        b = self.backend.assemble_residual(sub.residual, sub.jacobian, sub.bcs, sub.unknown,
                                           b=b if b is not None else self._residual)
        if sub.operator is not None:
            sub.operator.apply(x, b)
        return b


class LinearSolver(_Solver):
    """One exact Newton step, x <- x - J^{-1} F(x), for an affine residual (a KSP solve).

    The residual is evaluated as matrices times fields where the form allows it
    (:class:`~primordia.coupling.affine.AffineResidual`): constant matrices are assembled
    once, what is left is assembled at every solve.  A diagonal system with the default
    options (``preonly`` + ``jacobi``) is solved by a division, without a matrix.

    A matrix that changes at every step (the cell density's: its fitted chemotactic flux
    reads f) may keep the preconditioner built for an earlier one, ``rebuild_preconditioner_after
    = N`` or ``"fresh+K"`` (:class:`KeptPreconditioner`): the Krylov method always solves with
    the current matrix, to the same tolerance, and the preconditioner is built again only
    after a solve needed more than N iterations, or K more than the first solve after the
    last build, and when dt changed.  A solve that fails with a kept preconditioner is
    repeated once with a fresh one.
    """

    def __init__(self, backend, subproblem, overrides: dict | None = None):
        super().__init__(backend, subproblem, overrides)
        self._on_one_rank = None
        self.ksp = PETSc.KSP().create(PETSc.COMM_SELF if self._gather else backend.comm)
        self.ksp.setOptionsPrefix(subproblem.prefix)
        self._configure(self.ksp.getPC())
        read_options(self.ksp, self.where, self.user_options)
        self._increment = None
        self._affine = AffineResidual(backend, subproblem)
        self._pointwise = (not self._user_keys and subproblem.operator is None and self.options.get("ksp_type") == "preonly"
                           and self.options.get("pc_type") == "jacobi")
        self._operators = None  # what the KSP was last given
        # a constant Jacobian, no operator and a direct solve: solve for x itself
        # (AffineResidual.right_hand_side), which spares the product J x of the residual and the update
        # x - dx (f, b and the linear Biot system in serial).  A Krylov solve keeps the increment: its
        # tolerance is then relative to the step's change, not to the whole solution
        self._for_unknown = (self._affine.available and self._affine.constant_jacobian
                             and subproblem.operator is None and self.options.get("ksp_type") == "preonly")
        self._rebuild_rule = self._kept_preconditioner()
        self.preconditioner_builds = 0  # solves that built the preconditioner (for a changed matrix)

    @classmethod
    def settings(cls, subproblem, overrides: dict | None, parallel: bool) -> tuple[dict, list[str]]:
        """Also a ``rebuild_preconditioner_after`` the user gave where it cannot work (:meth:`_kept_preconditioner`)."""
        options, user_keys = super().settings(subproblem, overrides, parallel)
        refusal = cls._why_not_kept(options, bool(options.get(GATHER)) and parallel)
        if options.get(REBUILD) and refusal is not None and REBUILD in user_keys:
            raise ConfigError(f"solver.{subproblem.prefix[:-1]}.{REBUILD} {refusal}")
        return options, user_keys

    @staticmethod
    def _why_not_kept(options: dict, gathered: bool) -> str | None:
        """Why a preconditioner cannot be kept over steps under ``options`` (None: it can)."""
        if str(options.get("ksp_type")) == "preonly":
            return f"{NEEDS_KRYLOV} the preconditioner is the whole solve, and a kept one would solve with an old matrix"
        if gathered:
            return f"does not apply to a system solved on one rank ({GATHER})"
        return None

    def _kept_preconditioner(self) -> "KeptPreconditioner | None":
        """The rule of ``rebuild_preconditioner_after``, where it can work (a user's setting elsewhere was refused by
        :meth:`settings`)."""
        if self._rebuild_after is None or self._why_not_kept(self.options, self._gather) is not None:
            return None
        return KeptPreconditioner(self._rebuild_after)

    def step_size_changed(self) -> None:
        super().step_size_changed()
        self._affine.invalidate()
        if self._rebuild_rule is not None:
            self._rebuild_rule.discard()  # the matrix holds 1/dt: an old preconditioner would be far off

    def solve(self) -> SolveStats:
        b, target = self._right_hand_side()
        if self._affine.available and self._solve_diagonal(b, target):
            iterations, reason = 1, PETSc.KSP.ConvergedReason.CONVERGED_ITS
        elif self._gather:
            ((iterations, reason),) = _solve_gathered([self], [(b, target)])
        else:
            A, changed = self._affine_tangent() if self._affine.available else self._assemble_jacobian()
            if changed or self._operators is not A:
                self.ksp.setOperators(A, self._assemble_preconditioner(A))
                self._operators = A
            kept = self._keep_preconditioner(changed)
            self._solve_linear(b, target)
            if kept and self.ksp.getConvergedReason() < 0:  # too old for this matrix: once more with a fresh one
                self._rebuild_rule.discard()
                self._keep_preconditioner(changed)
                self._solve_linear(b, target)
            iterations, reason = max(self.ksp.getIterationNumber(), 1), self.ksp.getConvergedReason()
            if self._rebuild_rule is not None:
                self._rebuild_rule.solved(iterations)
        return self._finish(iterations, reason)

    def _keep_preconditioner(self, changed: bool) -> bool:
        """Whether this solve keeps the preconditioner of an earlier matrix (``rebuild_preconditioner_after``);
        PETSc builds it again from a changed matrix otherwise."""
        rule = self._rebuild_rule
        if rule is None:
            return False
        keep = rule.keeps()
        self.ksp.getPC().setReusePreconditioner(keep)
        if not keep:
            rule.built()
            if changed:  # PETSc sets a preconditioner up again only for a changed matrix
                self.preconditioner_builds += 1
        return keep

    def _right_hand_side(self):
        """The step's right-hand side and where its solve goes: (b, x) for a constant Jacobian and a direct
        solve, (F(x), increment) otherwise."""
        sub, backend = self.sub, self.backend
        x = backend.petsc_vector(sub.unknown)
        if sub.operator is not None:
            sub.operator.update()
        if self._for_unknown:
            b = self._residual = self._affine.right_hand_side(x, self._residual)
        elif self._affine.available:
            b = self._residual = self._affine.residual(x, self._residual)
            if sub.operator is not None:
                sub.operator.apply(x, b)
        else:
            b = self._residual = self._assemble_residual(x)
        if not np.isfinite(b.norm()):
            raise SolverError(f"{sub.name}: the residual is not finite")
        if self._increment is None:
            self._increment = b.duplicate()
        return b, (x if self._for_unknown else self._increment)

    def _finish(self, iterations: int, reason: int) -> SolveStats:
        sub, backend = self.sub, self.backend
        if reason < 0:
            hint = f" ({sub.failure_hint})" if sub.failure_hint else ""  # as a Newton solve's failure says it
            raise SolverError(f"{sub.name}: the linear solver diverged (PETSc reason {KSP_REASONS.get(reason, reason)})"
                              f"{hint}; try other options under -{sub.prefix}")
        x = backend.petsc_vector(sub.unknown)
        if not self._for_unknown:
            x.axpy(-1.0, self._increment)
        backend.update_ghosts(sub.unknown)
        if not np.isfinite(x.norm()):
            raise SolverError(f"{sub.name}: the solution is not finite")
        return SolveStats(newton_iterations=1, linear_iterations=iterations, reason=reason)

    def _gathered(self, b) -> "_OnOneRank":
        """The system gathered to :attr:`owner` (collective: the matrix is gathered again when it changed)."""
        A, changed = self._affine_tangent() if self._affine.available else self._assemble_jacobian()
        if self._on_one_rank is None or self._on_one_rank.owner != self.owner:
            self._on_one_rank = _OnOneRank(self.ksp, b, self.owner, self.sub.name, self.user_options)
            changed = True
        if changed or self._operators is not A:
            self._on_one_rank.set_matrix(A)
            self._operators = A
        return self._on_one_rank

    def _solve_diagonal(self, b, solution) -> bool:
        """A diagonal system under the default options: ``solution`` by a division; False otherwise."""
        if not self._pointwise:
            return False
        jacobian = self._affine.jacobian
        jacobian.refresh()
        if jacobian.diagonal is None:
            self._pointwise = False
            return False
        start = clock_now()
        solution.pointwiseDivide(b, jacobian.diagonal)
        add_since(self.linear_solve_seconds, start)
        return True

    def _affine_tangent(self):
        """The tangent from the split residual's Jacobian (assembled only when stale), plus the operator."""
        jacobian = self._affine.jacobian
        changed = jacobian.refresh() or self._stale
        self._stale = False
        if self.sub.operator is None:
            return jacobian.as_matrix(), changed
        if jacobian.diagonal is not None:  # a lumped Jacobian: the operator may add it to its own values
            shifted = self.sub.operator.shifted(jacobian.diagonal)
            if shifted is not None:
                return shifted, True
        operator = self.sub.operator.matrix()
        if self._combined is None:
            self._combined = operator.duplicate(copy=True)
        else:
            operator.copy(self._combined, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        if jacobian.diagonal is not None:  # a lumped Jacobian: add its diagonal, no sparse sum
            self._combined.setDiagonal(jacobian.diagonal, addv=PETSc.InsertMode.ADD_VALUES)
        else:
            self._combined.axpy(1.0, jacobian.as_matrix(), structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        return self._combined, True

    def _solve_linear(self, b, solution):
        """KSP solve into ``solution``; an unpivoted LU that meets a zero pivot is retried once with MUMPS."""
        start = clock_now()
        try:
            self._solve_linear_once(b, solution)
        finally:
            add_since(self.linear_solve_seconds, start)
        self._check_options_used()

    def _solve_linear_once(self, b, solution):
        """A zero pivot is a failed set-up, or PETSc's error 71 or 81 when it was told to raise
        (``ksp_error_if_not_converged``); any other error it raised is its own (a viewer it cannot open, a value
        it cannot read), which MUMPS would not mend: it was taken for a zero pivot, a warning said so, and
        the option that caused it was then reported unread (the switch writes the options anew)."""
        try:
            self.ksp.solve(b, solution)
            failed = self.ksp.getConvergedReason() == PETSc.KSP.ConvergedReason.DIVERGED_PCSETUP_FAILED
        except PETSc.Error as error:
            failed, raised = error.ierr in ZERO_PIVOTS, error
        else:
            raised = None
        if failed and self._switch_to_mumps(self.ksp):
            self.ksp.solve(b, solution)
        elif raised is not None:
            raise petsc_failure(f"{self.sub.name}: the linear solve", raised.ierr, petsc_reason(raised),
                                self.sub.prefix, self.user_options) from None


#: Why rebuild_preconditioner_after cannot apply to a direct solve (the start of the one-line refusal).
NEEDS_KRYLOV = 'needs a Krylov method (ksp_type "gmres", ...): with ksp_type = "preonly"'


class KeptPreconditioner:
    """When a solve builds its kept preconditioner again (``rebuild_preconditioner_after``).

    ``N``: once a solve needed more than N Krylov iterations.  ``"fresh+K"``: once a solve
    needed more than K iterations above what a fresh preconditioner needed; that count grows
    with the mesh and the ranks (the cell density's block Jacobi/ILU: 4, 5, 7, 11 iterations
    at 43, 86, 171, 342 cells per side; additive Schwarz on 2 ranks 9 at 171), so one
    relative default serves every size.  "Fresh" is the solves from the build until one
    that settles the count: a linear subproblem's first solve, a Newton solve's last
    (:class:`NewtonSolver`: the most any of its Newton steps needed).  The count of solves
    is deterministic, unlike a rule on measured times, so a run gives the same iterates
    each time.
    """

    def __init__(self, after: int | str):
        relative = isinstance(after, str)  # "fresh+K", as solver_options normalises it
        self._above = int(after[len(FRESH) + 1:]) if relative else None
        self._limit = None if relative else int(after)
        self._last = None  # iterations of the last solve; None: build at the next
        self._fresh = None  # the most iterations a solve needed since the last build
        self._settled = True  # whether ``_fresh`` is complete

    def keeps(self) -> bool:
        """Whether the next solve keeps the preconditioner (never the first, nor after :meth:`discard`;
        always while a relative bound is still measuring the fresh one)."""
        if self._last is None:
            return False
        if self._above is None:
            return self._last <= self._limit
        return not self._settled or self._last <= self._fresh + self._above

    def built(self) -> None:
        self._fresh, self._settled = None, False

    def solved(self, iterations: int, *, settles: bool = True) -> None:
        """A solve took ``iterations``; ``settles``: it ends the fresh preconditioner's count."""
        self._last = iterations
        if not self._settled:
            self._fresh = max(self._fresh or 0, iterations)
            self._settled = settles

    def discard(self) -> None:
        """Build the preconditioner at the next solve (dt changed, a solve failed with the kept one)."""
        self._last = None


class _OnOneRank:
    """A distributed linear system solved whole by one rank, in phases others can overlap.

    The owner holds the whole matrix (gathered once, and again when it changes) and
    factorises it with its serial KSP; a solve sends the right-hand side to it, it solves,
    and the solution goes back to the ranks that own its rows.  Between those phases
    another rank can solve another system (:func:`solve_in_turn`): on 2 ranks the species
    f and b of example 1a are each solved by one rank, at once, where a ``redundant``
    solve had every rank solve both.  The owner's memory is that of a serial solve; the
    others hold none of it.
    """

    def __init__(self, ksp, b, owner: int, name: str, options: dict | None = None):
        self.ksp, self.owner, self.name = ksp, owner, name
        self._options = options  # the user's, named in a failure whose reason quotes one's value
        comm = b.getComm().tompi4py()
        self.mine = comm.rank == owner
        size = b.getSize() if self.mine else 0
        self._rows = PETSc.IS().createStride(size, 0, 1, comm=PETSc.COMM_SELF)
        self._b = PETSc.Vec().createSeq(size, comm=PETSc.COMM_SELF)
        self._x = self._b.duplicate()
        self._scatter = PETSc.Scatter().create(b, self._rows, self._b, None)
        self._local = None
        self._outcome = (1, PETSc.KSP.ConvergedReason.CONVERGED_ITS, None)  # iterations, reason, PETSc error
        self._comm = comm

    def set_matrix(self, A) -> None:
        """Gather ``A`` to the owner (collective)."""
        if self._local is None:
            self._local = A.createSubMatrices(self._rows, self._rows)[0]
        else:
            A.createSubMatrices(self._rows, self._rows, submats=[self._local])
        if self.mine:
            self.ksp.setOperators(self._local)

    def send(self, b) -> None:
        self._scatter.begin(b, self._b, PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)

    def receive(self, b) -> None:
        self._scatter.end(b, self._b, PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)

    def solve(self) -> None:
        """The owner's serial solve (nothing on the other ranks)."""
        if not self.mine:
            return
        try:
            self.ksp.solve(self._b, self._x)
        except PETSc.Error as error:  # told on every rank by result()
            self._outcome = (0, 0, (error.ierr, petsc_reason(error)))
        else:
            self._outcome = (max(self.ksp.getIterationNumber(), 1), self.ksp.getConvergedReason(), None)

    def return_to(self, x) -> None:
        self._scatter.begin(self._x, x, PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.REVERSE)

    def arrive(self, x) -> None:
        self._scatter.end(self._x, x, PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.REVERSE)

    def result(self) -> tuple[int, int]:
        """(Krylov iterations, converged reason) of the owner's solve, on every rank."""
        iterations, reason, error = self._comm.bcast(self._outcome, root=self.owner)
        if error:
            raise petsc_failure(f"{self.name}: the linear solve on rank {self.owner}", *error,
                                self.ksp.getOptionsPrefix(), self._options)
        return int(iterations), int(reason)


def independent_batches(solvers: list) -> list[list]:
    """``solvers`` in order, consecutive gathered linear solves that do not read each other's unknowns
    in one batch: solved at once, each on its own rank (the rest alone)."""
    batches: list[list] = []
    for solver in solvers:
        last = batches[-1] if batches else None
        if (solver.gathered and last and last[0].gathered
                and len(last) < solver.backend.comm.size
                and not any(earlier.sub.unknown in solver.sub.residual.coefficients() for earlier in last)):
            last.append(solver)
        else:
            batches.append([solver])
    for batch in batches:
        for rank, solver in enumerate(batch):
            if solver.gathered:
                solver.owner = rank
    return batches


def solve_in_turn(batches: list[list]):
    """Solve the batches of :func:`independent_batches` in order; yield (subproblem name, statistics)."""
    for batch in batches:
        if len(batch) == 1:
            yield batch[0].sub.name, batch[0].solve()
            continue
        sides = [solver._right_hand_side() for solver in batch]
        for solver, (iterations, reason) in zip(batch, _solve_gathered(batch, sides)):
            yield solver.sub.name, solver._finish(iterations, reason)


def _solve_gathered(solvers: list, sides: list) -> list[tuple[int, int]]:
    """(Krylov iterations, reason) of each of ``solvers``' gathered systems, solved at once for the right-hand
    sides and targets ``sides``: every send, each owner's solve, every return, so each rank solves its own
    system while the others solve theirs.  Each solver is charged an equal share of the time."""
    systems = [solver._gathered(b) for solver, (b, _) in zip(solvers, sides)]
    start = clock_now()
    for system, (b, _) in zip(systems, sides):
        system.send(b)
    for system, (b, _) in zip(systems, sides):
        system.receive(b)
    for system in systems:
        system.solve()
    for system, (_, target) in zip(systems, sides):
        system.return_to(target)
    for system, (_, target) in zip(systems, sides):
        system.arrive(target)
    spent = {clock: (time - start[clock]) / len(solvers) for clock, time in clock_now().items()}
    results = []
    for solver, system in zip(solvers, systems):
        for clock, time in spent.items():
            solver.linear_solve_seconds[clock] += time
        results.append(system.result())
        solver._check_options_used()
    return results


class NewtonSolver(_Solver):
    """PETSc SNES on the subproblem's residual and its UFL tangent (seed section 5.1).

    With the option ``rebuild_preconditioner_after = N`` the preconditioner is kept over
    Newton steps and time steps while it works: every Newton step's Krylov solve uses the
    current tangent, but the preconditioning matrix (a copy of an earlier tangent) is
    only refreshed, and its factorisation or AMG hierarchy built again, after a Krylov
    solve took more than N iterations, or when a Newton solve failed in its linear
    solve (then the solve is repeated once with a fresh one).  ``"fresh+K"``: after a
    Krylov solve took more than K iterations above the most any Newton step took with
    the fresh preconditioner, from its build to the end of that Newton solve (the first
    Newton step of a time step needs far fewer than the later ones: 5 against about 30
    on coarse example 2a, so one solve alone is no measure).  A fresh AMG hierarchy's
    count grows slowly with the mesh (the growth system's Schur fieldsplit in 3D: 18.3,
    20.5, 21.3 per Newton step at 20, 30, 40 boxes a side), so a fixed bound leaves a
    kept one less and less room and at some size rebuilds it at every Newton step,
    where the relative bound keeps the same margin at every size.  PETSc's own
    ``snes_lag_preconditioner`` rebuilds at fixed intervals instead, whether the old
    preconditioner still works or not.  PETSc sets up a preconditioner again only when
    its matrix changed, which is what keeps the old one.

    With PETSc's ``snes_mf_operator`` the Krylov method applies the tangent matrix-free,
    by differences of the residual, and the tangent is assembled only to refresh a kept
    preconditioner: worth it where a residual costs a fraction of a tangent and the kept
    preconditioner leaves few Krylov iterations (example 2a's reused LU on fenicsx).
    """

    defaults = NEWTON_DEFAULTS

    @classmethod
    def settings(cls, subproblem, overrides: dict | None, parallel: bool) -> tuple[dict, list[str]]:
        """Also a ``rebuild_preconditioner_after`` the user gave to a solve that is the preconditioner alone: the
        preconditioner is the whole solve, and kept, it would freeze the tangent (and a single application never
        counts more than one iteration)."""
        options, user_keys = super().settings(subproblem, overrides, parallel)
        if str(options.get("ksp_type")) == "preonly" and options.get(REBUILD) and REBUILD in user_keys:
            raise ConfigError(f"solver.{subproblem.prefix[:-1]}.{REBUILD} {NEEDS_KRYLOV} a kept preconditioner would "
                              f"freeze the tangent")
        return options, user_keys

    def __init__(self, backend, subproblem, overrides: dict | None = None):
        super().__init__(backend, subproblem, overrides)
        self.snes = PETSc.SNES().create(backend.comm)
        self.snes.setOptionsPrefix(subproblem.prefix)
        state = backend.petsc_vector(subproblem.unknown)
        # SNES iterates on its own vector: its line search evaluates F at trial points, which are
        # copied into the unknown's function only while the residual is assembled
        self._x = state.copy()
        self._F = state.duplicate()
        self.snes.setFunction(_weakly(self._function), self._F)
        self._tangent_matrices = None
        if str(self.options.get("ksp_type")) == "preonly":  # a user's rule here was refused by settings()
            self._rebuild_after = None
        self._kept = None  # the preconditioning matrix kept while it works (rebuild_preconditioner_after)
        self._rebuild_rule = KeptPreconditioner(self._rebuild_after) if self._rebuild_after is not None else None
        self._rebuild = False  # refresh it at the next tangent (a Newton solve failed in its linear solve)
        self.preconditioner_builds = 0  # refreshes of the kept preconditioning matrix
        self.ksp = self.snes.getKSP()
        self._assembly_seconds = no_time()  # in the SNES callbacks, taken off its solve time
        self._configure(self.ksp.getPC())
        read_options(self.snes, self.where, self.user_options)
        self.history: tuple[np.ndarray, np.ndarray] = (np.empty(0), np.empty(0))
        #: within :meth:`repeated_within_a_step`: the first solve's initial residual norm (None before it)
        self._step_reference: float | None = None
        self._repeated = False

    @contextmanager
    def repeated_within_a_step(self):
        """Solves repeated within one step (the fixed-point passes) need not go below the step's round-off.

        A later pass starts nearly converged, and ``snes_atol`` may lie below what round-off leaves of
        the step's residual: the momentum residual carries rho / dt^2 and the storage 1 / dt, so its
        floor rises as an adaptive step halves dt, and Newton stalled at 1.9e-6 (1.7e-13 of the first
        pass's initial 1.09e7) above the 1e-7 it was asked for (example 2a at 6 x 6, delta_2 = 5: the
        run stopped at dt_min).  A later solve also stops at :data:`ROUND_OFF_FLOOR` times the step's
        first initial residual.  A floor of ``snes_rtol`` times it instead let later passes stop as soon
        as the first did, and runs on 2 ranks then differed by 2e-8 from launch to launch.
        """
        self._repeated, self._step_reference = True, None
        try:
            yield
        finally:
            self._repeated, self._step_reference = False, None

    # -- SNES callbacks ----------------------------------------------------------------------
    def _load(self, x) -> None:
        """Put the iterate ``x`` into the unknown's function (owned values and ghosts)."""
        state = self.backend.petsc_vector(self.sub.unknown)
        if x.handle != state.handle:
            x.copy(state)
        self.backend.update_ghosts(self.sub.unknown)

    def _function(self, snes, x, F) -> None:
        start = clock_now()
        self._load(x)
        self._assemble_residual(self.backend.petsc_vector(self.sub.unknown), b=F)
        add_since(self._assembly_seconds, start)

    def _tangent(self, snes, x, J, P) -> None:
        start = clock_now()
        self._load(x)
        # snes_mf_operator: the Krylov method applies the tangent by differences of the residual, J v =
        # (F(x + h v) - F(x)) / h, and the tangent is assembled only when the preconditioner needs it
        matrix_free = J.getType() == PETSc.Mat.Type.MFFD
        if matrix_free:
            J.assemble()  # its new base point x
        refresh = self._kept is not None and (self._rebuild or self._kept_too_old())
        if self._kept is None or refresh or not matrix_free:
            tangent, _ = self._assemble_jacobian()  # into the matrices handed to SNES (same objects)
            if self._kept is None:
                self._assemble_preconditioner(tangent)
            elif refresh:
                self._refresh_kept(tangent)
        add_since(self._assembly_seconds, start)

    def _kept_too_old(self) -> bool:
        """Whether the last Krylov solve, within a Newton solve, took more iterations than the kept
        preconditioner may (:class:`KeptPreconditioner`; none since a build: no)."""
        last = self.ksp.getIterationNumber()
        if last == 0:
            return False
        self._rebuild_rule.solved(last, settles=False)  # the Newton solve goes on: a fresh count may grow
        return not self._rebuild_rule.keeps()

    def _built_kept(self) -> None:
        """The kept preconditioning matrix was (re)built: the Newton solve under way measures it fresh."""
        self.preconditioner_builds += 1
        self._rebuild_rule.built()
        self.ksp.setIterationNumber(0)  # a count read before this matrix's first solve is not its own

    def _attach_tangent(self) -> None:
        """Create the tangent (and preconditioning) matrices once, at the initial state."""
        tangent, _ = self._assemble_jacobian()
        preconditioner = self._assemble_preconditioner(tangent)
        if self._rebuild_rule is not None:  # a matrix of its own, which keeps its values while the tangent moves on
            self._kept = preconditioner.duplicate(copy=True) if preconditioner is tangent else preconditioner
            preconditioner = self._kept
            self._built_kept()
        self.snes.setJacobian(_weakly(self._tangent), tangent, preconditioner)
        self._tangent_matrices = (tangent, preconditioner)

    def _refresh_kept(self, tangent) -> None:
        """The kept preconditioning matrix from the current tangent: PETSc then sets the preconditioner up again."""
        preconditioner = self._assemble_preconditioner(tangent)
        if preconditioner is tangent:
            tangent.copy(self._kept, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self._rebuild = False
        self._built_kept()

    # -- one solve ---------------------------------------------------------------------------
    def solve(self) -> SolveStats:
        sub, backend = self.sub, self.backend
        state = backend.petsc_vector(sub.unknown)
        if sub.operator is not None:
            sub.operator.update()
        if self._tangent_matrices is None:
            self._attach_tangent()
        state.copy(self._x)
        self._run_snes()
        if (self.snes.getConvergedReason() == PETSc.SNES.ConvergedReason.DIVERGED_LINEAR_SOLVE
                and self.ksp.getConvergedReason() == PETSc.KSP.ConvergedReason.DIVERGED_PCSETUP_FAILED
                and self._switch_to_mumps(self.ksp)):
            state.copy(self._x)
            self._run_snes()
        elif (self._kept is not None
              and self.snes.getConvergedReason() == PETSc.SNES.ConvergedReason.DIVERGED_LINEAR_SOLVE):
            self._rebuild = True  # a kept preconditioner too old for this tangent: once more with a fresh one
            state.copy(self._x)
            self._run_snes()
        self._check_options_used()
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

    def _run_snes(self) -> None:
        """SNES solve; its time outside the residual and tangent callbacks is linear algebra."""
        rtol, atol, stol, max_it = self.snes.getTolerances()
        self.snes.setConvergenceHistory(length=max_it + 1, reset=True)
        if self._step_reference is not None:  # a later pass of the step: not below its round-off (see above)
            self.snes.setTolerances(atol=max(atol, ROUND_OFF_FLOOR * self._step_reference))
        self._assembly_seconds, start = no_time(), clock_now()
        try:
            self.snes.solve(None, self._x)
            if self._kept is not None and self.ksp.getIterationNumber():
                self._rebuild_rule.solved(self.ksp.getIterationNumber())  # its last Krylov solve: no tangent read it
        except PETSc.Error as error:
            raise petsc_failure(f"{self.sub.name}: the nonlinear solve", error.ierr, petsc_reason(error),
                                self.sub.prefix, self.user_options) from None
        finally:
            add_since(self.linear_solve_seconds, start, minus=self._assembly_seconds)
            self.snes.setTolerances(atol=atol)
        if self._repeated and self._step_reference is None and self.snes.getConvergedReason() > 0:
            self._step_reference = float(self.snes.getConvergenceHistory()[0][0])

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
