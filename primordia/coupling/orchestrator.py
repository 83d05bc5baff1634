"""The coupling orchestrator: set up a model on a backend and march it in time.

``setup()`` is an ordered list of single-purpose steps; ``run()`` loops
``step()``; everything time-dependent is updated in ``step()``.  Which
operator-splitting scheme shares a step between the physics modules is chosen
through the ``primordia_select_splitting_scheme`` hook; which backend assembles
the forms, through ``primordia_select_backend``.
"""

from __future__ import annotations

import dataclasses
import time as clock
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import ufl

from primordia.core.errors import PrimordiaError, SolverError
from primordia.core.plugins import get_plugin_manager, registry
from primordia.coupling.discretisation import Discretisation
from primordia.coupling.solvers import SubproblemSolver, accumulate


class Simulation:
    """One run of a :class:`~primordia.model.Model` on one backend."""

    def __init__(self, model, backend: str = "fenicsx", out_dir: str | Path = "out/run", comm=None):
        self.model = model
        self.backend_name = backend
        self.out_dir = Path(out_dir)
        self.comm = comm
        self.step_index = 0
        self.time = model.t_start
        self.dt = model.dt
        self.iterations: dict[str, list[int]] = {}  # linear iterations per step, by subproblem
        self.newton: dict[str, list[tuple[int, int]]] = {}  # (Newton iterations, SNES reason) per step, nonlinear ones
        self.coupling_iterations: dict[str, list[int]] = {}  # outer iterations per step, by scheme
        self._vertex_cache: tuple[int, dict] | None = None

    # -- setup ----------------------------------------------------------------------------
    def setup(self) -> "Simulation":
        self._choose_backend()
        self._choose_splitting()
        self._discretise()
        self._create_fields()
        self._setup_physics()
        self._initialise_fields()
        self._create_solvers()
        self._attach_outputs()
        return self

    def _choose_backend(self):
        pm = get_plugin_manager()
        if self.comm is None:
            from mpi4py import MPI

            self.comm = MPI.COMM_WORLD
        entries = {name: entry for name, (entry, _) in registry("backends", pm).items()}
        self.backend = pm.hook.primordia_select_backend(name=self.backend_name, entries=entries, comm=self.comm)
        self.is_root = self.comm.rank == 0

    def _discretise(self):
        self.mesh_data = self.model.mesh_data
        self.disc = Discretisation(self.backend, self.mesh_data)
        self.disc.set_time(self.time, self.dt)

    def _create_fields(self):
        owners = {spec.name: physics.name for physics in self.model.physics_objects for spec in physics.fields()}
        for group, specs in self.scheme.field_groups(self.model.physics_objects).items():
            self.disc.add_group(group, specs, owners)

    def _setup_physics(self):
        # modules that own fields first: they provide what the pure couplings read
        ordered = sorted(self.model.physics_objects, key=lambda module: not module.fields())
        for physics in ordered:
            for name in physics.requires:
                self.disc.field(name)  # names a missing provider before any assembly
            physics.setup(self.disc)

    def _initialise_fields(self):
        for physics in self.model.physics_objects:
            physics.initialise(self.disc)
        self.disc.store_previous()
        for physics in self.model.physics_objects:
            for subproblem in physics.initial_subproblems():
                self._solve_initial(self._holding_the_others(subproblem, physics))
        self.disc.store_previous()

    def _holding_the_others(self, subproblem, physics):
        """``subproblem`` with the fields it does not solve for held at their initial values.

        A module's initial solve states equations for its own fields only; when the
        scheme groups them with other fields (one monolithic function), those others
        get (c - c_0) v = 0 so the solve neither moves them nor meets zero rows.
        """
        owned = {spec.name for spec in physics.fields()}
        group = self.disc.group_of_function(subproblem.unknown)
        others = [name for name in self.disc.group_fields(group) if name not in owned]
        if not others:
            return subproblem
        disc = self.disc
        residual = subproblem.residual + sum(
            ufl.inner(disc.field(name) - disc.previous(name), disc.test(name)) * disc.dx for name in others)
        return dataclasses.replace(subproblem, residual=residual,
                                   jacobian=ufl.derivative(residual, subproblem.unknown))

    def _solve_initial(self, subproblem) -> None:
        """One solve completing the initial state, in continuation stages when the subproblem asks for them."""
        solver = self.solver_for(subproblem)
        ramp, stages = subproblem.continuation or (None, 1)
        for stage in range(1, stages + 1):
            if ramp is not None:
                ramp.value = stage / stages
            try:
                solver.solve()
            except SolverError as error:
                at = f" (continuation stage {stage}/{stages})" if ramp is not None else ""
                raise SolverError(f"initial state at t = {self.time:g}{at}: {error}") from None

    def _create_solvers(self):
        self.scheme.build(self)
        self._integrals = {name: self._integrand(self.disc.field(name)) * self.disc.dx
                           for name in self.disc.field_names()}
        self.diagnostics = [d for physics in self.model.physics_objects for d in physics.diagnostics()]

    @staticmethod
    def _integrand(field):
        """The field itself, or its magnitude for vectors (the integral reported in outputs)."""
        return ufl.sqrt(ufl.inner(field, field)) if field.ufl_shape else field

    def solver_for(self, subproblem) -> SubproblemSolver:
        """A solver for ``subproblem`` with the config's ``[solver.PREFIX]`` options."""
        return SubproblemSolver(self.backend, subproblem, overrides=self.model.solver.get(subproblem.prefix[:-1]))

    def _choose_splitting(self):
        pm = get_plugin_manager()
        schemes = {name: cls for name, (cls, _) in registry("splitting_schemes", pm).items()}
        self.scheme = pm.hook.primordia_select_splitting_scheme(
            name=self.model.coupling, options=self.model.coupling_options, schemes=schemes,
            physics=self.model.physics_objects)

    def _attach_outputs(self):
        if self.is_root:
            self.out_dir.mkdir(parents=True, exist_ok=True)
        self.outputs = [cls() for cls, _ in registry("outputs").values()]
        self.wall_start = clock.perf_counter()
        self.wall_time = 0.0
        self.status = "running"
        for output in self.outputs:
            output.start(self)

    # -- time loop ------------------------------------------------------------------------
    def run(self, progress: bool = False) -> "Simulation":
        bar = _progress_bar(self, progress)
        snapshot_steps = {int(round((t - self.model.t_start) / self.dt)) for t in self.model.output["times"]}
        try:
            while self.step_index < self.model.num_steps:
                self.step()
                bar.update(1)
                bar.set_postfix_str(f"t={self.time:.2f}", refresh=False)
                if self.step_index % self.model.output["series_every"] == 0 or self.step_index in snapshot_steps:
                    self._notify("record")
                if self.step_index in snapshot_steps:
                    self._notify("snapshot")
        except BaseException as exc:  # record why the run stopped, then let the error through
            bar.close()
            reason = "interrupted" if isinstance(exc, KeyboardInterrupt) else str(exc).splitlines()[0]
            if not isinstance(exc, (PrimordiaError, KeyboardInterrupt)):
                reason = f"{type(exc).__name__}: {reason}"
            self._finish(f"stopped at t = {self.time:g}: {reason}")
            raise
        bar.close()
        self._finish("completed")
        return self

    def step(self) -> None:
        """Advance every field by one time step ``dt`` (the splitting scheme decides how)."""
        t_next = self.model.t_start + (self.step_index + 1) * self.dt
        try:
            stats = self.scheme.advance(self, self.time, self.dt)
        except SolverError as error:
            raise SolverError(f"step {self.step_index + 1} (t = {self.time:g} -> {t_next:g}): {error}") from None
        self.disc.set_time(t_next, self.dt)
        nonlinear = {solver.sub.name for solver in self.solvers if not solver.sub.linear}
        for name, solve in stats.items():
            self.iterations.setdefault(name, []).append(solve.linear_iterations)
            if name in nonlinear:
                self.newton.setdefault(name, []).append((solve.newton_iterations, solve.reason))
        self.step_index += 1
        self.time = t_next
        self._check_finite()

    def advance(self, solvers: list, t0: float, duration: float, inner_steps: int = 1) -> dict:
        """Advance the fields of ``solvers`` from ``t0`` over ``duration`` in ``inner_steps`` steps.

        The other fields stay frozen.  Per inner step: time-dependent data are
        updated, the start values of these fields stored, the subproblems solved
        in order, and the rates of these fields (e.g. the solid velocity) updated.
        """
        delta = duration / inner_steps
        groups = list(dict.fromkeys(self.disc.group_of_function(s.sub.unknown) for s in solvers))
        stats: dict = {}
        for k in range(inner_steps):
            with self.substep(groups, t0 + (k + 1) * delta, delta):
                for solver in solvers:
                    accumulate(stats, solver.sub.name, solver.solve())
        return stats

    @contextmanager
    def substep(self, groups: list[str], t: float, dt: float):
        """Bookkeeping around the solves that bring ``groups`` to time ``t`` over ``dt``.

        Before: time-dependent data are updated and the start values of these
        fields stored; after: the rates of these fields (e.g. the solid velocity).
        """
        self.disc.set_time(t, dt)
        for physics in self.model.physics_objects:
            physics.before_step(t, dt)
        self.disc.store_previous(groups)
        yield
        self.disc.update_rates(dt, groups)

    def record_coupling_iterations(self, scheme: str, count: int) -> None:
        """Outer iterations a scheme needed in this step (e.g. the fixed-point iteration)."""
        self.coupling_iterations.setdefault(scheme, []).append(count)

    def _check_finite(self):
        for group in self.disc.groups():
            if not np.all(np.isfinite(self.backend.local_array(self.disc.group_function(group)))):
                raise SolverError(f"a field of {group} ({', '.join(self.disc.group_fields(group))}) "
                                  f"is not finite at t = {self.time:g}")

    def _notify(self, moment: str, *args):
        for output in self.outputs:
            getattr(output, moment)(self, *args)

    def _finish(self, status: str):
        self.status = status
        self.wall_time = clock.perf_counter() - self.wall_start
        self._notify("finish", status)

    # -- what outputs read ------------------------------------------------------------------
    def vertex_values(self) -> dict:
        """All fields at the MeshData vertices (rank 0; None elsewhere), cached per step."""
        if self._vertex_cache is None or self._vertex_cache[0] != self.step_index:
            values = {name: self.backend.vertex_values(*self.disc.function_of(name))
                      for name in self.disc.field_names()}
            self._vertex_cache = (self.step_index, values)
        return self._vertex_cache[1]

    def field_statistics(self) -> dict[str, dict[str, float]]:
        """Integral (of the magnitude, for vectors), min and max over the vertices of every field."""
        values = self.vertex_values()
        extremes = None
        if self.is_root:
            extremes = {name: (float(np.min(v)), float(np.max(v))) for name, v in values.items()}
        extremes = self.comm.bcast(extremes, root=0)
        return {name: {"integral": self.backend.assemble_scalar(self._integrals[name]),
                       "min": extremes[name][0], "max": extremes[name][1]}
                for name in self.disc.field_names()}

    def diagnostic_values(self) -> dict[str, float]:
        """The physics modules' derived quantities (integrals, extrema), by their recorded names."""
        values = {}
        for diagnostic in self.diagnostics:
            if diagnostic.kind == "integral":
                values[diagnostic.name] = self.backend.assemble_scalar(diagnostic.expression)
            elif diagnostic.kind == "value":
                values[diagnostic.name] = float(diagnostic.expression())
            else:
                low, high = self.backend.extrema(diagnostic.expression, self.disc.mesh)
                values[f"{diagnostic.name}_min"], values[f"{diagnostic.name}_max"] = low, high
        return values

    def iteration_counts(self) -> dict[str, float]:
        """Linear (and Newton) iterations per subproblem, SNES reasons and outer coupling iterations, of the last step."""
        counts = {f"{name.replace('.', '_')}_linear_iterations": float(its[-1])
                  for name, its in self.iterations.items() if its}
        for name, record in self.newton.items():
            if record:
                counts[f"{name.replace('.', '_')}_newton_iterations"] = float(record[-1][0])
                counts[f"{name.replace('.', '_')}_snes_reason"] = float(record[-1][1])
        counts.update({f"{scheme}_iterations": float(its[-1]) for scheme, its in self.coupling_iterations.items()})
        return counts

    def summary(self, status: str) -> dict:
        wall = clock.perf_counter() - self.wall_start
        field_space = {group: self.disc.group_function(group).ufl_function_space() for group in self.disc.groups()}
        return {
            "status": status,
            "backend": self.backend.name,
            "mpi_ranks": self.comm.size,
            "cells": self.backend.num_cells(self.disc.mesh),
            "dofs": {name: self.backend.num_dofs(space) for name, space in field_space.items()},
            "dofs_total": sum(self.backend.num_dofs(space) for space in field_space.values()),
            "steps": self.step_index,
            "time": self.time,
            "dt": self.dt,
            "wall_time_s": wall,
            "ms_per_step": 1e3 * wall / self.step_index if self.step_index else None,
            "final": self.field_statistics(),
            "mean_linear_iterations": {name: float(np.mean(its)) for name, its in self.iterations.items() if its},
            "mean_newton_iterations": {name: float(np.mean([its for its, _ in record]))
                                       for name, record in self.newton.items() if record},
            "mean_fixed_point_iterations": (float(np.mean(self.coupling_iterations["fixed_point"]))
                                            if self.coupling_iterations.get("fixed_point") else None),
            "splitting_scheme": self.scheme.name,
        }


class _NoBar:
    def update(self, n):
        pass

    def set_postfix_str(self, text, refresh=False):
        pass

    def close(self):
        pass


def _progress_bar(sim: Simulation, enabled: bool):
    """A progress bar on rank 0: simulated time, step, ETA (tqdm)."""
    if not (enabled and sim.is_root):
        return _NoBar()
    import sys

    from tqdm import tqdm

    return tqdm(total=sim.model.num_steps, unit="step", dynamic_ncols=True, file=sys.stderr,
                mininterval=0.5 if sys.stderr.isatty() else 15.0,
                bar_format="{l_bar}{bar}| step {n_fmt}/{total_fmt} {postfix} [{elapsed}<{remaining}]")
