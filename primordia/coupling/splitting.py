"""Operator-splitting schemes: how the physics modules of a run share a time step.

Each scheme is one small class, registered through the
``primordia_splitting_schemes`` hook and chosen by the ``firstresult`` hook
``primordia_select_splitting_scheme`` from ``[coupling] scheme``.  A *sub-flow*
is the set of subproblems of one physics module (e.g. the four species solves of
the chemotaxis, or the (u, p) solve of the poroelasticity); the others' fields are
frozen while it runs.

* ``sequential`` (Lie):  A(dt) then B(dt) ...  splitting error O(dt).
* ``strang``:            A(dt/2), B(dt), A(dt/2) for two sub-flows (the first
  module against the rest); splitting error O(dt^2).
* ``fixed_point``:       the seed's outer iteration (section 5.1): sweep all
  subproblems from the start-of-step state until the relative change of every
  field group falls below ``tolerance``; iteration counts are recorded.
* ``monolithic``:        all fields in one (mixed) function and one Newton solve.

Each sub-flow can be integrated with ``inner_steps`` backward-Euler steps
(``[coupling] inner_steps``, default 1): with many inner steps the sub-flows
approach the exact ones and the splitting error of the scheme is what remains.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable, Mapping
from abc import ABC, abstractmethod

import ufl

from primordia.core.config import Configured, merge_options
from primordia.core.errors import ConfigError, SolverError
from primordia.core.plugins import hookimpl
from primordia.core.validation import number
from primordia.coupling.solver_options import check_table_values, check_tables
from primordia.coupling.solvers import accumulate, solve_in_turn
from primordia.physics.base import Subproblem, check_affine, module_code, subproblems_of


class SplittingScheme(Configured, ABC):
    name: str
    #: Options of the ``[coupling]`` table this scheme reads (with defaults); the values of a run are
    #: ``self.settings`` (the table's values over these defaults).
    options: dict = {"inner_steps": 1}
    _tables_checked = False  # see check_solver_tables

    def __init__(self, physics: list, **given):
        self.physics = physics
        self.settings: dict = merge_options(f"coupling scheme '{self.name}'", self.options, given)
        number(self.settings.get("inner_steps", 1), "coupling.inner_steps", at_least=1, integer=True)
        for module in physics:
            with module_code(module, "check_scheme"):
                module.check_scheme(self, physics)

    def field_groups(self, physics: list) -> dict[str, list]:
        """Which fields are solved together: by default, as each module groups its own."""
        groups: dict[str, list] = {}
        for module in physics:
            for spec in module.fields():
                groups.setdefault(spec.group or spec.name, []).append(spec)
        return groups

    def check_subproblems(self, subproblems: list[list[Subproblem]]) -> None:
        """Refuse, in one line (:class:`ConfigError`; :class:`PluginError` for a module's own mistake), modules'
        subproblems this scheme cannot solve (``subproblems``: each module's, in model order): before any solver
        is made, by :meth:`build` and by
        ``primordia run --dry-run``, which makes none.  Here: a subproblem marked linear whose residual is not
        affine (:func:`~primordia.physics.base.check_affine`), for the schemes that solve each as it is; a
        scheme overriding this calls it too unless it solves them otherwise."""
        for module, own in zip(self.physics, subproblems):
            for sub in own:
                check_affine(module, sub)

    def build(self, sim) -> None:
        """Create the solvers, one per subproblem, grouped in sub-flows (one per module)."""
        subproblems = [subproblems_of(module, disc=sim.disc) for module in self.physics]
        self.check_subproblems(subproblems)
        self.flows = [[sim.solver_for(sub) for sub in own] for own in subproblems]
        self.flows = [flow for flow in self.flows if flow]
        sim.solvers = [solver for flow in self.flows for solver in flow]
        self.check_solver_tables(sim)

    def check_solver_tables(self, sim) -> None:
        """Every ``[solver.NAME]`` table of the config names a subproblem of this run, with KSP, PC and factor
        types this PETSc has and tolerances in range (or one line, exit 2).

        Once a run: neither the tables nor the subproblems' names change within it, while the solvers are
        made again at every checkpoint and rejected step, where building the initial subproblems again for
        their names took 24 of the 173 ms (example 2a at 86 x 86).
        """
        if self._tables_checked:
            return
        self.check_table_names(sim.model, [solver.sub.prefix for solver in sim.solvers])
        # the types and values of a table no solver of this process reads (a restart does not solve the initial
        # state again): pc_type = "hypr" under [solver.poroelastic_growth_initial] was taken without a word
        check_table_values(sim.model.solver)
        self._tables_checked = True

    def check_table_names(self, model, prefixes: list[str]) -> None:
        """Every ``[solver.NAME]`` table of ``model``'s config names one of the solvers' ``prefixes`` or an initial
        solve's, or one line naming it (a table another setting makes is told by the model, in one warning)."""
        initial = [sub.prefix for module in self.physics for sub in subproblems_of(module, initial=True)]
        check_tables({name: table for name, table in model.solver.items() if name not in model.inert_solver_tables},
                     prefixes + initial)

    def solver_prefixes(self, subproblems: list[list[Subproblem]]) -> list[str]:
        """The options prefixes of the solvers :meth:`build` makes of the modules' ``subproblems``: what
        ``primordia run --dry-run``, which makes none, checks the ``[solver.*]`` tables against."""
        return [sub.prefix for own in subproblems for sub in own]

    def solved_subproblems(self, disc, subproblems: list[list[Subproblem]]) -> list[Subproblem]:
        """The subproblems :meth:`build` makes solvers of, from the modules' ``subproblems`` on ``disc``: what
        ``primordia run --dry-run``, which makes none, checks the solvers' options of."""
        return [sub for own in subproblems for sub in own]

    @abstractmethod
    def advance(self, sim, t0: float, dt: float) -> dict:
        """Advance all fields from ``t0`` to ``t0 + dt``; return solver statistics by subproblem."""


class Sequential(SplittingScheme):
    """Lie splitting: each sub-flow over the whole step, in model order."""

    name = "sequential"

    def advance(self, sim, t0, dt):
        stats = {}
        for flow in self.flows:
            stats.update(sim.advance(flow, t0, dt, self.settings["inner_steps"]))
        return stats


class Strang(SplittingScheme):
    """Strang splitting: first module over dt/2, the rest over dt, first module over dt/2."""

    name = "strang"

    def check_subproblems(self, subproblems):
        super().check_subproblems(subproblems)
        if sum(1 for own in subproblems if own) < 2:
            raise ConfigError("the strang scheme needs at least two physics modules with subproblems")

    def build(self, sim):
        super().build(sim)
        self.first = self.flows[0]
        self.rest = [solver for flow in self.flows[1:] for solver in flow]

    def advance(self, sim, t0, dt):
        inner = self.settings["inner_steps"]
        stats = sim.advance(self.first, t0, 0.5 * dt, inner)
        stats.update(sim.advance(self.rest, t0, dt, inner))
        for name, solve in sim.advance(self.first, t0 + 0.5 * dt, 0.5 * dt, inner).items():
            accumulate(stats, name, solve)
        return stats


class FixedPoint(SplittingScheme):
    """The seed's outer fixed-point iteration between the modules, until the fields stop changing."""

    name = "fixed_point"
    options = {"tolerance": 1e-8, "max_iterations": 50}

    def __init__(self, physics, **given):
        super().__init__(physics, **given)
        number(self.settings["tolerance"], "coupling.tolerance", above=0)
        number(self.settings["max_iterations"], "coupling.max_iterations", at_least=1, integer=True)

    def advance(self, sim, t0, dt):
        groups = sim.disc.groups()
        vectors = {g: sim.backend.petsc_vector(sim.disc.group_function(g)) for g in groups}
        # work vectors made once: PETSc objects dropped inside a step are only freed by a garbage collection
        if getattr(self, "_work", None) is None or set(self._work) != set(groups):
            self._work = {g: (vector.duplicate(), vector.duplicate()) for g, vector in vectors.items()}
        stats = {}
        with sim.substep(groups, t0 + dt, dt), contextlib.ExitStack() as passes:
            for solver in sim.solvers:  # each Newton solve judged against the step's first (NewtonSolver)
                passes.enter_context(solver.repeated_within_a_step())
            for iteration in range(1, self.settings["max_iterations"] + 1):
                for g, vector in vectors.items():
                    vector.copy(self._work[g][0])
                for name, solve in solve_in_turn(sim.batches(sim.solvers)):
                    accumulate(stats, name, solve)
                change = max(_relative_change(*self._work[g], vectors[g]) for g in groups)
                if change < self.settings["tolerance"]:
                    break
            else:
                raise SolverError(f"fixed-point coupling did not converge in {self.settings['max_iterations']} "
                                  f"iterations (relative change {change:.2e} > tolerance {self.settings['tolerance']:g})")
        sim.record_coupling_iterations(self.name, iteration)
        return stats


#: The monolithic Newton system's solver, overridable in ``[solver.monolithic]``: a direct solve with PETSc's
#: LU and a nested-dissection ordering (MUMPS on more than one rank, and whenever the unpivoted LU meets a
#: zero pivot, as in a saddle point).  ``pc_type = "fieldsplit"`` splits it by field (the fields' names).
MONOLITHIC_DEFAULTS = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_ordering_type": "nd"}
#: The direct solve of a grouped system that needs pivoting: MUMPS, with its own ordering (not PETSc's nd,
#: see :func:`~primordia.coupling.solver_options.combine`).
PIVOTING_DIRECT = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}


def grouped_direct(module_options: Iterable[Mapping]) -> dict:
    """The direct solve of a system grouping several modules' fields (the monolithic scheme's Newton system, a
    module's initial solve within it), given the modules' own solver options: :data:`PIVOTING_DIRECT` when a
    module's own system needs pivoting (its factorisation is MUMPS, or it is split by field: the growth's Schur
    split u | (psi, p), whose blocks meet a zero pivot in PETSc's unpivoted LU, and whose splits name that
    module's fields, not the group's), else :data:`MONOLITHIC_DEFAULTS`."""
    if any(options.get("pc_factor_mat_solver_type") == "mumps" or options.get("pc_type") == "fieldsplit"
           for options in module_options):
        return dict(PIVOTING_DIRECT)
    return dict(MONOLITHIC_DEFAULTS)


class Monolithic(SplittingScheme):
    """All fields in one mixed function, all residuals in one Newton solve."""

    name = "monolithic"
    options = {}
    #: The one subproblem, and options prefix, of the Newton solve of every field.
    SOLVE = "monolithic"

    def field_groups(self, physics):
        return {"monolithic": [spec for module in physics for spec in module.fields()]}

    def check_subproblems(self, subproblems):
        for sub in (sub for own in subproblems for sub in own):
            if sub.operator is not None:
                raise ConfigError(f"the monolithic scheme cannot include {sub.name}: its algebraic operator "
                                  f"acts on its own field alone (choose a form without one in its module's options)")

    def solver_prefixes(self, subproblems):
        return [f"{self.SOLVE}_"]

    def solved_subproblems(self, disc, subproblems):
        """The one subproblem of every field: the modules' residuals summed, solved by Newton."""
        subproblems = [sub for module_subproblems in subproblems for sub in module_subproblems]
        unknown = subproblems[0].unknown
        residual = sum((sub.residual for sub in subproblems[1:]), subproblems[0].residual)
        stabilisations = [sub.preconditioner for sub in subproblems if sub.preconditioner is not None]
        return [Subproblem(
            name=self.SOLVE, unknown=unknown, residual=residual, jacobian=ufl.derivative(residual, unknown),
            bcs=[bc for sub in subproblems for bc in sub.bcs], linear=False,
            petsc_options=grouped_direct(sub.petsc_options for sub in subproblems),
            fields=disc.unknown_fields(disc.field_names()[0]),
            rigid_body=next((sub.rigid_body for sub in subproblems if sub.rigid_body), None),
            preconditioner=sum(stabilisations[1:], stabilisations[0]) if stabilisations else None)]

    def build(self, sim):
        own = [subproblems_of(module, disc=sim.disc) for module in self.physics]
        self.check_subproblems(own)
        self.flows = [[sim.solver_for(combined) for combined in self.solved_subproblems(sim.disc, own)]]
        sim.solvers = self.flows[0]
        self.check_solver_tables(sim)

    def advance(self, sim, t0, dt):
        return sim.advance(self.flows[0], t0, dt, 1)


def _relative_change(old, work, new) -> float:
    """|new - old| / |new|, with ``work`` to hold the difference."""
    work.waxpy(-1.0, old, new)
    return work.norm() / max(new.norm(), 1e-300)


@hookimpl
def primordia_splitting_schemes():
    return [Sequential, Strang, FixedPoint, Monolithic]
