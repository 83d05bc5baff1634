"""The coupling orchestrator: set up a model on a backend and march it in time.

``setup()`` is an ordered list of single-purpose steps; ``run()`` loops
``step()``; everything time-dependent is updated in ``step()``.  Which
operator-splitting scheme shares a step between the physics modules is chosen
through the ``primordia_select_splitting_scheme`` hook; which backend assembles
the forms, through ``primordia_select_backend``.

A run survives what a long run meets:

* a step that fails (a solve that does not converge, non-finite values, a negative
  density a physics module promised to keep >= 0) is undone and retried in smaller
  sub-steps (:mod:`primordia.core.timestepping`); ``series.nc`` records dt and every
  rejection;
* checkpoints (every N steps, every M minutes, and whenever the run stops) hold
  everything the next step needs (:meth:`Simulation.write_checkpoint`), and a run
  set up with ``existing="restart"`` continues from the one in its directory, bit for bit;
* Ctrl-C, SIGTERM and SIGUSR1 stop the run between two steps (:mod:`primordia.core.signals`),
  and ``summary.json`` always says why a run stopped;
* an output that fails is disabled with a warning and the run goes on; a file system that takes no
  more (a full disk) stops the run in one line, its last checkpoint kept for ``--restart``.

Under MPI every decision that ends or changes a step is taken by all ranks together.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import time as clock
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import ufl

from primordia.core import checkpoint as checkpoint_file
from primordia.core.atomic_files import StorageError, make_directory, storage_error
from primordia.core.clocks import no_time
from primordia.core.errors import ConfigError, InterruptedRun, PluginError, PrimordiaError, SolverError, warn
from primordia.core.outputs import continued_from_checkpoint, existing_run, step_time_label, time_label
from primordia.core.plugins import PLUGINS_VARIABLE, choose, get_plugin_manager, make_backend, registry, software
from primordia.core.reductions import (RanksMissing, every_rank_stops, largest, largest_in_place, lowest_rank_where,
                                      on_every_rank)
from primordia.core.signals import INTERRUPTS, copy_window, signal_name
from primordia.core.timestepping import StepController
from primordia.coupling.batched import batch_remainders
from primordia.coupling.solvers import (SubproblemSolver, accumulate, check_settings, independent_batches,
                                       solve_in_turn)
from primordia.coupling.splitting import grouped_direct
from primordia.physics.base import module_code, subproblems_of
from primordia.physics.discretisation import Discretisation

#: How far below zero a field promised non-negative may fall (round-off of the solves) before the step is rejected,
#: relative to the field's largest value: the solves' errors scale with it (a fixed 1e-8 rejected m = -1.3e-7
#: beside m = 2.6e8, a relative 5e-16, and would pass m = -1e-9 beside m = 1e-10).
NEGATIVE_TOLERANCE = 1e-8

#: What a stopped run's line says when its folder holds no checkpoint to continue from.
NO_CHECKPOINT = "it wrote no checkpoint to continue from"

#: (long_name, units) of :meth:`Simulation.step_sizes`' keys.
STEP_SIZES = {"dt": ("the last sub-step's length", "1"),  # the seed's dimensionless time (UDUNITS: "1")
              "rejections": ("rejected sub-steps so far (adaptive steps)", "1")}
#: (long_name, units) of :meth:`Simulation.memory_use`'s keys.
#: MB here are MiB (/proc's kB / 1024), which UDUNITS-2 writes "1048576 byte" (it knows neither "MB" nor "MiB").
MEMORY_USE = {"memory_mb": ("resident memory, summed over the ranks (MiB)", "1048576 byte"),
              "peak_memory_mb": ("peak resident memory so far, summed over the ranks (MiB)", "1048576 byte")}
#: How long a rank whose output failed waits for the other ranks to finish that output before it takes them for
#: stuck in a collective call it never reached, and aborts the job: at least OUTPUT_PATIENCE_S seconds and
#: OUTPUT_PATIENCE_FACTOR times the longest this output has taken at that moment on this rank.  Generous: taking
#: a slow rank for a stuck one kills a run that would have gone on, from its last checkpoint.
OUTPUT_PATIENCE_S = 300.0
OUTPUT_PATIENCE_FACTOR = 10.0


class Simulation:
    """One run of a :class:`~primordia.model.Model` on one backend.

    ``existing`` says what to do with an ``out_dir`` that already holds a run:
    ``"reuse"`` (write over it), ``"refuse"`` (a one-line error), ``"overwrite"``
    (remove its files first) or ``"restart"`` (continue it from its checkpoint).
    """

    def __init__(self, model, backend: str = "fenicsx", out_dir: str | Path = "out/run", comm=None,
                 existing: str = "reuse"):
        self.model = model
        self.backend_name = backend
        if isinstance(out_dir, str) and not out_dir.strip():  # Path("") is the current directory, files and all
            raise ConfigError("a run's out needs a directory name (\".\" for the current directory)")
        self.out_dir = Path(out_dir)
        #: how a stopped run is continued, in its lines (Model.run gives its own, in Python's words); the command
        #: cannot rebuild a mesh made in Python (config.toml holds no table of it), so Python's words then too
        self.restart_hint = (f"Simulation(model, out_dir={str(self.out_dir)!r}, existing=\"restart\")"
                             if model.mesh_in_memory
                             else f"primordia run --restart {self.out_dir}")
        self.comm = comm
        self._output_comm = None  # see _outputs_comm
        self._output_seconds: dict[tuple[str, str], float] = {}  # the longest call of each output, at each moment
        self.existing = existing
        self.step_index = 0
        self.time = model.t_start
        self.dt = model.dt
        self.last_dt = model.dt  # the last sub-step taken (dt unless steps were rejected)
        # the nominal step under way: where it began and the part of it behind (its accepted sub-steps; a run
        # that stops inside a step, with a failure or a second signal, keeps them, and so does its checkpoint)
        self.step_begin = self.time
        self.step_done = 0.0
        self.controller = StepController(model.dt, model.dt_min, adaptive=model.adaptive)
        self.iterations: dict[str, list[int]] = {}  # linear iterations per step, by subproblem
        self.newton: dict[str, list[tuple[int, int]]] = {}  # (Newton iterations, SNES reason) per step, nonlinear ones
        self.coupling_iterations: dict[str, list[int]] = {}  # outer iterations per step, by scheme
        self.rejections: list[dict] = []  # every rejected sub-step: time, dt, reason
        self.snapshot_times: list[float] = []  # the output times whose fields were written (a restart's too)
        self.restarts = 0
        self.status = "setting up"
        self._set_up = False  # setup() has finished: a Simulation is set up, and run, once
        self.outputs: list = []
        self._saved_state = None  # a sub-step's start values (their arrays reused from step to step)
        self._times_tried: list[float] = []  # the times the try under way set (Simulation.substep)
        self._state_version = 0  # counts accepted sub-steps and restores: vertex values are cached per version
        self._vertex_cache: tuple[int, dict] | None = None
        self._statistics_cache: tuple[int, dict] | None = None  # field_statistics, per version likewise
        # parallel checkpoints: each state group's DOF layout (_DofLayout; groups laid out alike share one)
        self._dof_layouts: dict[str, _DofLayout] = {}
        self._solver_dt = model.dt
        self._wall_before = 0.0  # wall time of the earlier parts of a restarted run
        self._checkpoint_step: int | None = None
        # linear algebra of the solvers made anew since, by subproblem and clock (linear_solve_seconds)
        self._solve_seconds: dict[str, dict[str, float]] = {}
        self._first_step = 0  # the step this process started from (a restart's checkpoint)
        self._wall_after_first: float | None = None  # when this process's first step (and its outputs) ended
        self._wall_end: float | None = None  # when the run ended: its summary's times stop there
        self._unwritten: str | None = None  # a write a full disk refused while the run ended (outputs' finish)
        self._checked_checkpoint: dict | None = None  # read by check_choices, its fields taken by check_forms

    def __repr__(self) -> str:
        """Where the run is: its model, backend, status, time and step, and its output folder."""
        name = repr(self.model.name) if self.model.name else "an unnamed model"
        return (f"Simulation({name} on {self.backend_name}, {self.status}, "
                f"t = {self.time:g} after {self.step_index} steps, out_dir={str(self.out_dir)!r})")

    # -- setup ----------------------------------------------------------------------------
    def setup(self) -> "Simulation":
        if self._set_up:  # again: claiming out_dir again cleared the finished run's fields and checkpoint
            raise ConfigError(f"this Simulation is set up already ({self.status}, t = {self.time:g}): a Simulation "
                              f"runs once; make a new one, or continue its run with Model.run(out=..., restart=True)")
        # a signal an earlier run of the process received (stopped by it, or counted while it ended) is not this
        # run's: it stopped every later run from Python after its first step, "interrupted (Ctrl-C)"
        INTERRUPTS.reset()
        self.model.check_affordable()  # before the directory is claimed: nothing written for a run that cannot fit
        self._choose_backend()
        self._claim_directory()
        self._set_up_physics_on_the_mesh()
        checkpoint = self._read_checkpoint() if self.existing == "restart" else None
        if checkpoint is None:
            self._initialise_fields()
        self._create_solvers()
        if checkpoint is not None:
            self._restore(checkpoint)
        self._attach_outputs(checkpoint)
        if checkpoint is not None and self._missed_snapshot():  # an output time added where the run is
            self._write_missed_snapshot()
        self._first_step = self.step_index
        self._set_up = True
        self.model.warn_about_inert_settings()  # once set up (a refused input is one line), however it is run
        return self

    def check_choices(self) -> None:
        """Ask the choosers for this run's backend and splitting scheme, as :meth:`setup` would, and drop
        the answers: an unknown or unavailable backend or scheme is one ConfigError/PluginError now
        (``primordia run --dry-run``), with nothing discretised, allocated or written.  A restart
        (``existing="restart"``) is checked against its checkpoint too: what it may not change, an output
        time it has passed."""
        self.model.check_affordable()
        self._choose_backend()
        self._choose_splitting()
        # the run already in out_dir, refused in the words of setup(), on every rank: "the input is valid; OUT
        # already holds a run that ended" passed where the run, without --overwrite, stopped at once
        problem = self._refusal_of(existing_run(self.out_dir)) if self.is_root else None
        problem = self.comm.bcast(problem, root=0)
        if problem is not None:
            raise ConfigError(problem)
        if self.existing == "restart":
            self._checked_checkpoint = self._read_checkpoint()
        self.backend = self.scheme = None

    def check_forms(self) -> None:
        """What :meth:`setup` refuses once the modules state their forms to each other, with nothing solved,
        no solver made and nothing written (``primordia run --dry-run``): the mesh on the backend, the fields
        grouped by the scheme, every module's ``setup``, ``initialise`` (not the initial solves: they would
        assemble and solve) and (initial) subproblems, the same on every rank, whether the scheme can solve
        them and every ``[solver.NAME]`` table names one, and whether every term a module contributes is read
        by the balance law it is added to; a restart's checkpoint holds every state function, laid out alike.

        A term added to a field whose owner reads no contributed terms passed ``--dry-run`` and stopped the
        run at set-up.  It costs 0.2-0.7 s: examples 1a at the seed's 58,482 triangles (fenicsx) 0.2 s, 2a
        0.7 s (0.2 s of it the exponential fitting's stiffness matrix, its only assembly), 4 at 20 x 20 x 2
        boxes 0.7 s, at 60 x 60 x 6 (129,600 tetrahedra) 3.3 s, of which the mesh 0.9 s and the growth's
        failure hint (whether the boundary conditions enclose the tissue) 1.1 s, found once a set-up since.
        """
        self._choose_backend()
        self._set_up_physics_on_the_mesh()
        if self.existing != "restart":  # a restart takes the fields from its checkpoint
            self._set_initial_values()
        subproblems = [subproblems_of(physics, disc=self.disc) for physics in self.model.physics_objects]
        for subproblem in (sub for own in subproblems for sub in own):
            self._refuse_forms_differing_across_ranks(subproblem)
        initial = []
        if self.existing != "restart":  # the initial solves too (a restart does not solve them again)
            for physics in self.model.physics_objects:
                for subproblem in subproblems_of(physics, initial=True):
                    initial.append(self._holding_the_others(subproblem, physics))
                    self._refuse_forms_differing_across_ranks(initial[-1])
        self.scheme.check_subproblems(subproblems)  # e.g. strang with one module that solves anything
        # a misspelt [solver.NAME] table (the initial subproblems are built for their names here)
        self.scheme.check_table_names(self.model, self.scheme.solver_prefixes(subproblems))
        # what the solvers refuse before they are made: splits under a solver that is no fieldsplit, ...
        for subproblem in initial + self.scheme.solved_subproblems(self.disc, subproblems):
            check_settings(subproblem, self.model.solver.get(subproblem.prefix[:-1]), self.comm.size > 1)
        self.disc.check_contributions()
        if self.existing == "restart":  # after the subproblems: they make some of the state (Discretisation.at_balance)
            self._restore_fields(self._checked_checkpoint or self._read_checkpoint())
        self.backend = self.scheme = self.disc = self._checked_checkpoint = None

    def _set_up_physics_on_the_mesh(self) -> None:
        """What the forms are built on, for :meth:`setup` and :meth:`check_forms` alike: the scheme (its field
        groups), the mesh on the backend, the fields and every module's ``setup``."""
        self._choose_splitting()
        self._discretise()
        self._create_fields()
        self._setup_physics()

    def _choose_backend(self):
        if self.comm is None:
            from mpi4py import MPI

            self.comm = MPI.COMM_WORLD
        self.is_root = self.comm.rank == 0
        self.backend = make_backend(self.backend_name, self.comm)

    def _claim_directory(self):
        """Make ``out_dir`` this run's: refuse, clear or keep a run already in it (decided on rank 0 for all)."""
        from primordia.core.outputs import ANALYSIS_FILE, clear_run, directory_problem, existing_run

        problem = None
        if self.is_root:
            problem = directory_problem(self.out_dir)
            found = existing_run(self.out_dir) if problem is None else None
            problem = problem or self._refusal_of(found)
            if problem is None and found and self.existing == "overwrite":
                clear_run(self.out_dir)
            if problem is None and self.existing == "restart" and (self.out_dir / ANALYSIS_FILE).is_file():
                warn(f"{self.out_dir / ANALYSIS_FILE} (primordia analyse) measures the run as it was before this "
                     f"restart; run primordia analyse {self.out_dir} again when it ends")
            if problem is None:
                try:
                    make_directory(self.out_dir)
                except PrimordiaError as error:  # in the words of every other directory primordia creates
                    problem = str(error)
        problem = self.comm.bcast(problem, root=0)
        if problem is not None:
            raise ConfigError(problem)

    def _refusal_of(self, found: str | None) -> str | None:
        """Why this run may not take ``out_dir``, which holds ``found`` (:func:`existing_run`), as ``existing``
        says (None: it may)."""
        if found and "in progress" in found:
            return f"{self.out_dir} holds {found}; stop it first"
        if found and self.existing == "refuse":
            return (f"{self.out_dir} already holds {found}; use --overwrite to replace it, or --restart "
                    f"{self.out_dir} to continue it (from Python: Model.run(..., overwrite=True) or restart=True)")
        if self.existing == "restart" and not (self.out_dir / checkpoint_file.CHECKPOINT_FILE).is_file():
            return self._no_checkpoint(found)
        return None

    def _no_checkpoint(self, found: str | None) -> str:
        return (f"{self.out_dir} holds no checkpoint to restart from" + (f" ({found})" if found else "")
                + f"; checkpoints are written every checkpoint.every_minutes "
                  f"({self.model.checkpoint['every_minutes']:g}) and when a run stops")

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
            with module_code(physics, "setup"):
                physics.setup(self.disc)

    def _initialise_fields(self):
        self._set_initial_values()
        self.disc.store_previous()
        for physics in self.model.physics_objects:
            for subproblem in subproblems_of(physics, initial=True):
                self._solve_initial(self._holding_the_others(subproblem, physics))
        self.disc.store_previous()

    def _set_initial_values(self):
        """Every module's ``initialise``: the fields' values before the initial solves."""
        for physics in self.model.physics_objects:
            with module_code(physics, "initialise"):
                physics.initialise(self.disc)

    def _holding_the_others(self, subproblem, physics):
        """``subproblem`` with the fields it does not solve for held at their initial values.

        A module's initial solve states equations for its own fields only; when the
        scheme groups them with other fields (one monolithic function), those others
        get (c - c_0) v = 0 so the solve neither moves them nor meets zero rows.
        """
        owned = {spec.name for spec in physics.fields()}
        disc = self.disc
        group = disc.group_of_function(subproblem.unknown)
        others = [name for name in disc.group_fields(group) if name not in owned]
        if not others:
            return subproblem
        if subproblem.unknown is disc.group_function(group):
            held = {name: disc.field(name) - disc.previous(name) for name in others}
        else:  # an initial rate: the others' rates stay 0
            held = {name: disc.rate(name) for name in others}
        residual = subproblem.residual + sum(ufl.inner(held[name], disc.test(name)) * disc.dx for name in others)
        # The module's own solver, unless it splits by field: its splits name its fields alone, not the group's.
        options = subproblem.petsc_options
        if options.get("pc_type") == "fieldsplit":
            options = grouped_direct([options])
        return dataclasses.replace(subproblem, residual=residual, jacobian=ufl.derivative(residual, subproblem.unknown),
                                   petsc_options=options)

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

    def _carry_solve_times(self, solvers) -> None:
        """Add the solve times of ``solvers`` (about to be replaced) to the run's: they go on counting in
        :meth:`linear_solve_seconds`."""
        for solver in solvers:
            carried = self._solve_seconds.setdefault(solver.sub.name, no_time())
            for name, seconds in solver.linear_solve_seconds.items():
                carried[name] += seconds

    def _create_solvers(self):
        """The scheme's solvers, and what is read from the forms they were built with (diagnostics, promises)."""
        self._carry_solve_times(getattr(self, "solvers", ()))
        self._batches: dict[tuple, list[list]] = {}  # the old solvers' batches hold them: dropped first
        self.scheme.build(self)
        self.disc.check_contributions()
        # a field's integral (outputs): its values against its basis functions' integrals, else a form
        self._integral_weights = {name: self._basis_integrals(name) for name in self.disc.field_names()}
        self._integrals = {name: self._integrand(self.disc.field(name)) * self.disc.dx
                           for name, weights in self._integral_weights.items() if weights is None}
        self.diagnostics, self._nonnegative = [], []
        for physics in self.model.physics_objects:
            with module_code(physics, "diagnostics"):
                self.diagnostics += physics.diagnostics()
            with module_code(physics, "nonnegative_fields"):
                self._nonnegative += [(name, physics.name) for name in physics.nonnegative_fields()
                                      if self.disc.is_alone(name)]
        self._fields_of = {solver.sub.name: self.disc.group_fields(self.disc.group_of_function(solver.sub.unknown))
                           for solver in self.solvers}
        # the old solvers' PETSc objects (a factorisation) go now, before the new ones make theirs, once
        # nothing here holds them: a loop variable kept the last old solver (example 2b's Newton solver)
        # and the old diagnostics the fitted operators until the next step's collection, after the new
        # factorisation: two of them at once, 1.74 -> 3.06 GB resident at 171^2 after a checkpoint
        self._collect_petsc_garbage()
        release_free_memory()  # and what they held is the system's again, not the allocator's

    def _basis_integrals(self, name: str):
        """For a scalar field that is a whole backend function, the integrals of its basis functions (a vector):
        its integral is then their dot product with its values, exactly, where assembling the integral
        cost 1.3 ms a field at 171^2 in serial, for every row of the series.  None for the others."""
        field = self.disc.field(name)
        if field.ufl_shape or not self.disc.is_alone(name):
            return None
        return self.backend.assemble_vector(ufl.TestFunction(field.ufl_function_space()) * self.disc.dx)

    def _integral(self, name: str) -> float:
        weights = self._integral_weights[name]
        if weights is None:
            return self.backend.assemble_scalar(self._integrals[name])
        return weights.dot(self.backend.petsc_vector(self.disc.field(name)))

    @staticmethod
    def _integrand(field):
        """The field itself, or its magnitude for vectors (the integral reported in outputs)."""
        return ufl.sqrt(ufl.inner(field, field)) if field.ufl_shape else field

    def solver_for(self, subproblem) -> SubproblemSolver:
        """A solver for ``subproblem`` with the config's ``[solver.PREFIX]`` options."""
        self._refuse_forms_differing_across_ranks(subproblem)
        return SubproblemSolver(self.backend, subproblem, overrides=self.model.solver.get(subproblem.prefix[:-1]))

    def _refuse_forms_differing_across_ranks(self, subproblem) -> None:
        """One line, on every rank, when ``subproblem``'s forms are not the same on every rank.

        Each rank builds the forms from the modules' and plugins' answers; one that answers otherwise on some
        rank (a NaN there, a value read from a file only one rank sees) makes forms whose evaluation takes other
        collective calls there: ``mpirun -n 2`` with kinetics whose production of m was NaN on rank 1 alone hung
        until ``timeout`` killed it.  UFL's signatures hold the forms' literals; FFCx computes them to compile
        the forms anyway, and they are kept on the forms.
        """
        if self.comm.size == 1:
            return
        mine = f"{subproblem.residual.signature()} {subproblem.jacobian.signature()}"
        ranks = [rank for rank, theirs in enumerate(self.comm.allgather(mine)) if theirs != mine]
        if ranks:
            raise PluginError(f"{subproblem.name}: its equations differ between MPI ranks (rank {self.comm.rank} and "
                              f"rank {ranks[0]}): a plugin answers otherwise on some rank (a NaN there, or a value "
                              f"read from a file only one rank sees)")

    def _choose_splitting(self):
        from primordia.coupling.splitting import SplittingScheme

        pm = get_plugin_manager()
        schemes = {name: cls for name, (cls, _) in registry("splitting_schemes", pm).items()}
        self.scheme = choose("primordia_select_splitting_scheme", lambda answer: isinstance(answer, SplittingScheme),
                             pm, name=self.model.coupling, options=self.model.coupling_options, schemes=schemes,
                             physics=self.model.physics_objects)
        if self.scheme is None:
            raise PluginError(f"no plugin chose a splitting scheme for '{self.model.coupling}'")

    def _attach_outputs(self, checkpoint: dict | None):
        self.outputs = [cls() for cls, _ in registry("outputs").values()]
        self.wall_start = clock.perf_counter()
        self._last_checkpoint_wall = self.wall_start
        self.wall_time = 0.0
        self.status = "running"
        states = (checkpoint or {}).get("outputs", {})
        if self.comm.size > 1:
            self._outputs_comm()
        try:
            for output in list(self.outputs):
                if checkpoint is None:
                    self._call_output(output, "start")
                else:
                    self._call_output(output, "resume", states.get(output.name, {}))
        except BaseException as exc:  # what started must say why the run did not
            self._stopped_in_setup(exc)
            raise

    def _write_missed_snapshot(self) -> None:
        """The fields at the output time a restart is at and the run did not write (the checkpoint at the end says
        it is written: the next restart skips it).  The outputs have started: a failure here says why in
        ``summary.json``, which said "running" (a full disk's StorageError left it so, and the next run into the
        folder called the run killed without a word)."""
        try:
            self._snapshot()
        except BaseException as exc:
            self._stopped_in_setup(exc)
            raise

    def _stopped_in_setup(self, exc: BaseException) -> None:
        """The outputs have started and ``exc`` stops the run before its first step: they finish saying why, and a
        full disk's line says where the run is and how it goes on, as it does in :meth:`run`."""
        with INTERRUPTS.mode_of("shielded"):
            self._finish(self._stop_status(exc))
        if isinstance(exc, StorageError):
            raise StorageError(self._stopped_by_storage(str(exc))) from None

    # -- checkpoints ----------------------------------------------------------------------
    def write_checkpoint(self) -> None:
        """Write everything the next step needs to ``checkpoint.npz`` (all ranks call this; rank 0 writes)."""
        fields, layout = {}, {}
        for key, function in self.disc.state_functions().items():
            owned = np.array(self.backend.petsc_vector(function).getArray(readonly=True))
            # DOFs are stored in an order of their own, which no partition decides: a run continues on as many
            # ranks as it likes (a serial checkpoint held the backend's order, which only a serial run could read)
            order = self._checkpoint_order(key, function)
            parts = self.comm.gather(owned, root=0)
            if self.is_root:
                fields[key], layout[key] = np.concatenate(parts)[order[0]], order[1]
        physics = self.comm.gather({p.name: p.state() for p in self.model.physics_objects}, root=0)
        self._last_checkpoint_wall = clock.perf_counter()
        written, failure = self._write_checkpoint_file(fields, layout, physics) if self.is_root else (None, None)
        if self.comm.size > 1:
            written, failure = self.comm.bcast((written, failure), root=0)
        if written:  # summary.json's checkpoint_step: it named a step whose checkpoint the full disk had refused
            self._checkpoint_step = self.step_index
        if failure is not None:  # a full disk: the previous checkpoint stays whole, and nothing more can be saved
            raise StorageError(failure)

    def _write_checkpoint_file(self, fields: dict, layout: dict, physics: list) -> tuple[bool, str | None]:
        """Rank 0 writes the checkpoint: (whether it is written, why a full disk refused it); another failure
        is warned about, and the run goes on."""
        tree = {
            "config": self.resolved_config(), "output_times_default": self.model.output_times_default,
            "backend": self.backend.name, "mpi_ranks": self.comm.size,
            "named_plugins": os.environ.get(PLUGINS_VARIABLE, ""),  # -p's: what a restart must load again
            "software": software(),  # the installed plugins among them: a restart that lacks one names it
            "mesh": self.model.mesh_data.fingerprint(),
            "run": {"step": self.step_index, "time": self.time, "last_dt": self.last_dt,
                    "step_begin": self.step_begin, "step_done": self.step_done,
                    "controller": self.controller.state(), "iterations": self.iterations,
                    "newton": {name: [list(r) for r in record] for name, record in self.newton.items()},
                    "coupling_iterations": self.coupling_iterations, "rejections": self.rejections,
                    "snapshot_times": self.snapshot_times,
                    "restarts": self.restarts, "wall_time_s": self._wall_time()},
            "fields": fields, "layout": layout, "physics": physics,
            "outputs": {output.name: output.state() for output in self.outputs},
        }
        try:
            # shielded: a second Ctrl-C or SIGTERM while the run writes the checkpoint of its stop aborted the
            # write (the previous checkpoint stayed, while the run said where it had stopped); it is counted,
            # and the run stops once the checkpoint is whole
            with INTERRUPTS.mode_of("shielded"):
                checkpoint_file.write(self.out_dir / checkpoint_file.CHECKPOINT_FILE, tree)
        except StorageError as error:
            return False, str(error)
        except (OSError, PrimordiaError) as error:
            warn(f"cannot write the checkpoint at t = {self.time:g}: {error}; the run goes on without it")
            return False, None
        return True, None

    def resolved_config(self) -> dict:
        """The model's resolved configuration (``config.toml``, the checkpoint's), naming the backend this run is on.

        ``Model.run(backend=...)`` and ``Simulation(model, backend=...)`` may run a model on another backend than
        its ``[model] backend``: both files named the model's, so config.toml misstated the run, and the command's
        ``--restart`` of it was refused ("it was written on backend skfem, this run is on fenicsx"; with
        ``--backend skfem``, "model.backend differs from the checkpointed run's").
        """
        resolved = self.model.resolved_config()
        resolved["model"]["backend"] = self.backend_name
        return resolved

    def _read_checkpoint(self) -> dict:
        tree, problem = None, None
        if self.is_root:
            try:
                tree = checkpoint_file.read(self.out_dir / checkpoint_file.CHECKPOINT_FILE)
                problem = self._incompatibility(tree)
            except PrimordiaError as error:
                problem = str(error)
        problem = self.comm.bcast(problem, root=0)
        if problem is not None:
            raise ConfigError(problem)
        return self.comm.bcast(tree, root=0)

    def _incompatibility(self, tree: dict) -> str | None:
        """Why this run cannot continue the checkpointed one (None: it can)."""
        where = f"cannot restart from {self.out_dir / checkpoint_file.CHECKPOINT_FILE}"
        if tree["mpi_ranks"] != self.comm.size and (not tree["layout"] or not _alike(tree["physics"])):
            why = ("its fields are in the DOF order of a serial run (an older primordia wrote it): continue it "
                   "in serial" if not tree["layout"] else "a physics module's state differs between its ranks")
            return (f"{where}: it was written on {tree['mpi_ranks']} MPI rank(s), this run has {self.comm.size}, "
                    f"and {why}")
        if tree["backend"] != self.backend.name:
            return f"{where}: it was written on backend {tree['backend']}, this run is on {self.backend.name}"
        from primordia.model import CHANGEABLE_ON_RESTART

        # the backend is the one just checked, which Model.run(backend=...) may have chosen over the model's own
        differences = self.model.differences(tree["config"], (*CHANGEABLE_ON_RESTART, "model.backend"))
        if differences:
            key = differences[0]
            return f"{where}: {key} differs from the checkpointed run's (a restart continues the same model)"
        # the config names a mesh file by its path: a file rewritten since gave the checkpoint's fields to another mesh
        fingerprint = self.model.mesh_data.fingerprint()
        if tree.get("mesh", fingerprint) != fingerprint:  # a checkpoint from before 2026-12-05 holds none
            source = self.model.mesh_data.source() or {}
            mesh = f"the mesh read from {source['path']}" if source.get("type") == "file" else "the mesh"
            return f"{where}: {mesh} differs from the checkpointed run's (a restart continues the same model)"
        inside_a_step = tree["run"].get("step_done", 0.0) > 0.0  # then past the end of step "step" too
        if tree["run"]["step"] + inside_a_step > self.model.num_steps:
            return f"{where}: it is at t = {tree['run']['time']:g}, past time.t_final = {self.model.t_final:g}"
        # an output time the run has passed without writing it (a checkpoint from before 2026-12-05 holds none)
        written = {self.model.step_of(t) for t in tree["run"].get("snapshot_times", self.model.output["times"])}
        behind = [t for t in self.model.output["times"]
                  if self.model.step_of(t) not in written and self.model.step_of(t) <= tree["run"]["step"]]
        if behind and (self.model.step_of(behind[0]) < tree["run"]["step"] or inside_a_step):
            return (f"{where}: output time {time_label(behind[0])} is before its t = {tree['run']['time']:g}, and "
                    f"the run did not write the fields there (a restart writes later times, and the time it is at)")
        return None

    def _missed_snapshot(self) -> bool:
        """A restart at an output time the run did not write (checked by :meth:`_incompatibility`)."""
        return (self.step_done == 0.0 and self.step_index not in {self.model.step_of(t) for t in self.snapshot_times}
                and self.step_index in {self.model.step_of(t) for t in self.model.output["times"]})

    def _restore(self, tree: dict) -> None:
        """Put the run back where the checkpoint left it (every rank takes its own part of each field)."""
        self._restore_fields(tree)
        states = tree["physics"]  # one per rank of the checkpointed run, all alike if their number is not ours
        for physics in self.model.physics_objects:
            physics.restore_state(states[self.comm.rank if len(states) == self.comm.size else 0].get(physics.name, {}))
        run = tree["run"]
        self.step_index, self.time, self.last_dt = int(run["step"]), float(run["time"]), float(run["last_dt"])
        self.step_begin, self.step_done = float(run.get("step_begin", self.time)), float(run.get("step_done", 0.0))
        self.controller.restore(run["controller"])
        self.iterations = {k: [int(i) for i in v] for k, v in run["iterations"].items()}
        self.newton = {k: [tuple(int(i) for i in r) for r in v] for k, v in run["newton"].items()}
        self.coupling_iterations = {k: [int(i) for i in v] for k, v in run["coupling_iterations"].items()}
        self.rejections = list(run["rejections"])
        self.snapshot_times = [float(t) for t in run.get("snapshot_times", self.model.output["times"])
                               if self.model.step_of(t) <= self.step_index]
        self.restarts = int(run["restarts"]) + 1
        self._wall_before = float(run["wall_time_s"])
        self._solver_dt = self.last_dt
        self._checkpoint_step = self.step_index
        self.disc.set_time(self.time, self.last_dt)
        self.disc.restore_spans(self.last_dt)  # what a module reading another's field before it runs divides by
        self._state_version += 1

    def _restore_fields(self, tree: dict) -> None:
        """Every state function's values from the checkpoint ``tree``, or one line saying why it holds none for
        this run (``--restart --dry-run`` too: it takes them into the discretisation it drops)."""
        wrong = False
        missing = [key for key in self.disc.state_functions() if key not in tree["fields"]]
        if missing:  # e.g. the displacement at the species' last balance, kept since 2026-12-05
            raise ConfigError(f"cannot restart from {self.out_dir / checkpoint_file.CHECKPOINT_FILE}: it holds no "
                              f"{missing[0]}, which this run reads (it was written by an older primordia); run it "
                              f"again from the start")
        for key, function in self.disc.state_functions().items():
            owned = self.backend.petsc_vector(function)
            values = tree["fields"][key]
            if tree["layout"]:  # empty in a serial checkpoint of an older primordia: the backend's own order
                stored, mine = _rows(tree["layout"][key]), _rows(self._dof_layout(key, function).keys)
                at = np.minimum(np.searchsorted(stored, mine), len(stored) - 1)
                wrong |= not np.array_equal(stored[at], mine)
                values = values[at]
            if len(values) != owned.getLocalSize():
                wrong = True
                continue
            owned.array[:] = values
            self.backend.update_ghosts(function)
        if largest(self.comm, wrong):
            raise ConfigError(f"cannot restart from {self.out_dir / checkpoint_file.CHECKPOINT_FILE}: its fields are "
                              f"laid out differently (another mesh partition or another discretisation)")

    def _checkpoint_order(self, key: str, function) -> tuple[np.ndarray, np.ndarray] | None:
        """:attr:`_DofLayout.order` of ``key``'s group.  Collective the first time for a layout, then kept: the
        partition holds for the run, and sorting the keys of each of example 1a's eight state vectors at 171^2
        took 24 ms of a 49 ms checkpoint on 2 ranks."""
        layout = self._dof_layout(key, function)
        if not layout.sorted:
            parts = self.comm.gather(layout.keys, root=0)
            if self.is_root:
                keys = np.concatenate(parts)
                order = np.argsort(_rows(keys), kind="stable")
                layout.order = (order, keys[order])
            layout.sorted = True
        return layout.order

    def _dof_layout(self, key: str, function) -> "_DofLayout":
        """The layout of ``key``'s group, whose keys are (field, component, node coordinates in units of 1e-9 of
        the domain) of each owned DOF, as integers.

        The same DOF has the same key whatever the mesh partition: found by interpolating a
        marker, the component index and each coordinate into a scratch function of the space.
        """
        group = key.partition("/")[0]
        cache = self._dof_layouts
        if group in cache:
            return cache[group]
        fields, gdim = self.disc.group_fields(group), self.mesh_data.gdim
        space = function.ufl_function_space()
        # a group of one field whose DOFs are another such group's (the species of example 1a) has its keys:
        # the same markers, components and coordinates.  All ranks decide together (the next step gathers).
        for other, layout in cache.items():
            others = self.disc.group_fields(other)
            alike = (len(fields) == len(others) == 1
                     and self.disc.field(fields[0]).ufl_shape == self.disc.field(others[0]).ufl_shape
                     and self.backend.shares_dofs(space, self.disc.group_function(other).ufl_function_space()))
            alike = on_every_rank(self.comm, alike)
            if alike:
                cache[group] = layout
                return layout
        scratch = self.backend.function(space, "dof_keys")
        owned = self.backend.petsc_vector(scratch).getLocalSize()
        scale = 1e-9 * float(np.max(np.ptp(self.mesh_data.points, axis=0)))
        keys = np.full((owned, 2 + gdim), -1, dtype=np.int64)

        def interpolated(index: int, size: int, value) -> np.ndarray:
            self.backend.local_array(scratch)[:] = 0.0
            def values(x):
                return np.broadcast_to(value(x), (size, x.shape[1])).copy() if size > 1 else value(x)[0].copy()
            if len(fields) == 1:
                self.backend.interpolate(scratch, values)
            else:
                self.backend.interpolate_component(scratch, index, values)
            return self.backend.local_array(scratch)[:owned].copy()

        for index, name in enumerate(fields):
            size = int(np.prod(self.disc.field(name).ufl_shape)) if self.disc.field(name).ufl_shape else 1
            ones = np.ones((size, 1))
            mine = interpolated(index, size, lambda x: ones * np.ones(x.shape[1])) != 0.0
            keys[mine, 0] = index
            keys[mine, 1] = interpolated(index, size, lambda x: np.arange(size)[:, None] * np.ones(x.shape[1]))[mine]
            for axis in range(gdim):
                coordinate = interpolated(index, size, lambda x, axis=axis: ones * x[axis][None, :])
                keys[mine, 2 + axis] = np.round(coordinate[mine] / scale).astype(np.int64)
        cache[group] = _DofLayout(keys)
        return cache[group]

    # -- time loop ------------------------------------------------------------------------
    def run(self, progress: bool = False) -> "Simulation":
        self._check_steppable("run")
        bar = _progress_bar(self, progress)
        snapshot_steps = {self.model.step_of(t) for t in self.model.output["times"]}
        try:
            INTERRUPTS.copy_window = copy_window() if self.comm.size > 1 else 0.0
            with INTERRUPTS.installed(), INTERRUPTS.mode_of("deferred"):
                while self.step_index < self.model.num_steps:
                    self.step()
                    bar.update(1)
                    bar.set_postfix_str(f"t={self.time:.2f}", refresh=False)
                    if (self.step_index % self.model.output["series_every"] == 0 or self.step_index in snapshot_steps
                            or self.step_index == self.model.num_steps):  # the last state is always in the series
                        self._notify("record")
                    if self.step_index in snapshot_steps:
                        self._snapshot()
                    self._between_steps()
                    if self.step_index == self._first_step + 1:
                        self._wall_after_first = clock.perf_counter()
        except BaseException as exc:  # record why the run stopped, then let the error through
            # in the loop only a second signal raises (and may come back as a failed solve): a failure with one
            # signal or none, or one before a signal that came while the run stopped, is the failure
            raised_by_a_signal = INTERRUPTS.count > 1
            bar.close()
            self._stop_together(exc)
            with INTERRUPTS.installed(), INTERRUPTS.mode_of("shielded"):
                self._stop(exc)
            if isinstance(exc, KeyboardInterrupt):
                signum = getattr(exc, "signum", None) or INTERRUPTS.received or signal.SIGINT
                how = (f"continue it with: {self.restart_hint}"
                       if self._checkpoint_step == self.step_index or not self.is_root else self._how_it_continues())
                raise InterruptedRun(signum, f"{self.status}; {how}") from None
            if not raised_by_a_signal:  # the run has stopped, as the signal asked: the failure's line says why
                INTERRUPTS.reset()
            if isinstance(exc, StorageError):
                raise StorageError(self._stopped_by_storage(str(exc))) from None
            if isinstance(exc, SolverError) and exc.depends_on_step and self.is_root:
                raise SolverError(self._failed_step(str(exc))) from None
            raise
        bar.close()
        with INTERRUPTS.installed(), INTERRUPTS.mode_of("shielded"):
            # a completed run can be extended: --restart with a later t_final; a restart with no step left
            # writes one too, which counts it (and holds an output time it wrote), or the next counted from its number
            try:
                if self._checkpoint_step != self.step_index or self.step_index == self._first_step:
                    self.write_checkpoint()
            except StorageError as exc:
                self._finish(self._stop_status(exc))
                raise StorageError(self._stopped_by_storage(str(exc))) from None
            self._finish("completed")
        if self._unwritten is not None:  # the outputs' last writes did not fit: the files lack the run's end
            self._patch_summary(self.status)  # it said "completed" when the pictures, drawn after it, did not fit
            raise StorageError(self._stopped_by_storage(self._unwritten))
        return self

    def _stopped_by_storage(self, failure: str) -> str:
        """The one line of a run a full disk stopped: what could not be written, where the run is, how it goes on
        (rank 0's words: the other ranks print nothing)."""
        if not self.is_root:
            return failure
        return f"{failure}; the run stopped at t = {step_time_label(self.time)} ({self._how_it_continues()})"

    def _failed_step(self, failure: str) -> str:
        """The line of a step that failed at every dt down to dt_min, with how the run goes on: the checkpoint
        just written holds every step before it, and a restart may change what failed (README, "Long runs")."""
        how = continued_from_checkpoint(self.out_dir, self.restart_hint)
        how = (f"{how} (a restart may change [solver], time.adaptive and time.dt_min)" if how is not None
               else NO_CHECKPOINT)
        return f"{(failure.splitlines() or [''])[0]}; {how}"

    def _how_it_continues(self) -> str:
        """How a run stopped before its last step was checkpointed goes on: from the checkpoint in its folder."""
        return continued_from_checkpoint(self.out_dir, self.restart_hint) or NO_CHECKPOINT

    def _snapshot(self) -> None:
        self._notify("snapshot")
        self.snapshot_times.append(self.time)

    def _between_steps(self) -> None:
        """Checkpoint when due, and stop when asked: decided by all ranks together."""
        every_steps, every_minutes = self.model.checkpoint["every_steps"], self.model.checkpoint["every_minutes"]
        due_by_time = every_minutes > 0 and clock.perf_counter() - self._last_checkpoint_wall >= 60 * every_minutes
        asked = INTERRUPTS.received or 0
        if self.comm.size > 1:
            due_by_time, asked = self.comm.bcast(due_by_time, root=0), largest(self.comm, asked)
        if asked or due_by_time or (every_steps and self.step_index % every_steps == 0):
            self.write_checkpoint()
            if not asked:
                # solvers may carry state from step to step that no checkpoint holds (a lagged Newton
                # preconditioner): they start afresh here as they do in a restarted run, which then
                # repeats this one bit for bit
                self._create_solvers()
        if asked:
            raise InterruptedRun(asked)

    def _stop(self, exc: BaseException) -> None:
        """The run stops early: keep a checkpoint when the state is whole, and say why in the outputs."""
        urgent_in_parallel = isinstance(exc, KeyboardInterrupt) and self.comm.size > 1 and INTERRUPTS.count > 1
        if urgent_in_parallel:  # ranks may be anywhere: no collective is safe, rank 0 only patches the summary
            self._flush_outputs()
            self.status = self._stop_status(exc)
            self._patch_summary(self.status)
            return
        # every step is whole (a failed one was undone); a full disk keeps the last checkpoint written before it
        if (self._checkpoint_step != self.step_index and isinstance(exc, (KeyboardInterrupt, PrimordiaError))
                and not isinstance(exc, StorageError)):
            try:
                self.write_checkpoint()
            except StorageError as error:
                warn(f"{error}: the last checkpoint written before stays")
        self._finish(self._stop_status(exc))

    def _stop_status(self, exc: BaseException) -> str:
        if isinstance(exc, KeyboardInterrupt):
            signum = getattr(exc, "signum", None) or INTERRUPTS.received or signal.SIGINT
            return f"interrupted at t = {self.time:g} ({signal_name(signum)})"
        reason = (str(exc).splitlines() or [""])[0]
        if not isinstance(exc, PrimordiaError):
            reason = f"{type(exc).__name__}: {reason}"
        return f"stopped at t = {self.time:g}: {reason}"

    def _patch_summary(self, status: str, here: bool = False) -> None:
        """``summary.json`` says ``status`` (rank 0 writes it; ``here``: this rank, when rank 0 cannot)."""
        if not (self.is_root or here):
            return
        import json

        from primordia.core.outputs import write_last_summary

        try:
            summary = json.loads((self.out_dir / "summary.json").read_text())
            summary.update(status=status, steps=self.step_index, time=self.time)
            summary.pop("process", None)
            write_last_summary(self.out_dir, summary)
        except (OSError, ValueError, PrimordiaError):
            pass

    def step(self) -> None:
        """Advance every field over one step ``dt``, in sub-steps when a try fails (see module docstring).

        A step that a stopped run left part-way (``step_done`` > 0, restored from its checkpoint) goes on
        from where it stopped, on its own grid: sub-steps of dt / 2^level from ``step_begin``.
        """
        self._check_steppable("step")
        if self.step_index >= self.model.num_steps:  # a step past t_final was taken without a word
            raise ConfigError(f"the run has reached t_final = {time_label(self.model.t_final)}; to go further, "
                              f"continue it with a later t_final: Model.run(out=..., restart=True)")
        if self.step_done == 0.0:
            self.step_begin = self.time
        t_begin, t_end = self.step_begin, self.model.step_time(self.step_index + 1)
        failed_tries = 0
        while self.step_done < 1.0:
            fraction, dt = self.controller.fraction, self.controller.step
            done = self.step_done + fraction
            t_next = t_end if done == 1.0 else t_begin + done * (t_end - t_begin)
            failure = self._substep(t_next, dt)
            if failure is None:
                self.step_done = done
                self.controller.accepted(done)
                continue
            event = {"time": self.time, "dt": dt, "reason": failure}
            self.rejections.append(event)
            self._notify("rejection", event)
            self._create_solvers()  # nothing of the failed try (e.g. a lagged preconditioner) may carry over
            failed_tries += 1
            if not self.controller.rejected():
                where = self._step_label(t_next)
                if not self.model.adaptive:
                    raise SolverError(f"{where}: {failure}")
                # "retried down to" its first try's dt said a retry that never was (time.dt_min = dt)
                tried = f"retried down to dt = {dt:g}" if failed_tries > 1 else f"not retried at dt = {dt:g}"
                raise SolverError(f"{where}: {failure}; {tried}, and half of it would fall below time.dt_min = "
                                  f"{self.model.dt_min:g}")
        self.step_index += 1
        self.time, self.step_done = t_end, 0.0
        self._collect_petsc_garbage()

    def _check_steppable(self, what: str) -> None:
        """One line, not an AttributeError from inside, when the run is stepped before :meth:`setup`."""
        if not self._set_up:
            raise ConfigError(f"Simulation.{what}() needs setup() first (Model.run does both)")

    def _step_label(self, t_next: float) -> str:
        """The step under way and the try that failed, for a failure's line: "step N (t = a -> b)"."""
        return f"step {self.step_index + 1} (t = {self.time:g} -> {t_next:g})"

    def _collect_petsc_garbage(self) -> None:
        """Destroy the PETSc objects dropped during the step (collective: every rank steps).

        petsc4py (3.18) defers destroying objects of a parallel communicator to
        ``garbage_cleanup`` (freeing them when Python drops them could deadlock), so a
        vector copied and dropped inside a step would otherwise stay allocated (example
        2a at 86 x 86 squares grew to 15 GB over 2,600 steps, through the fixed-point
        iteration's copies, now kept).
        """
        self.backend.collect_garbage()

    def _substep(self, t_next: float, dt: float) -> str | None:
        """Try to advance from ``self.time`` to ``t_next``; None on success, else why the try was undone."""
        if dt != self._solver_dt:
            for solver in self.solvers:
                solver.step_size_changed()
            self._solver_dt = dt
        saved = self._saved_state = self.disc.copy_state(into=self._saved_state)
        saved_physics = [physics.state() for physics in self.model.physics_objects]
        self._times_tried = []
        try:
            stats = self.scheme.advance(self, self.time, dt)
            failure = self._inadmissible(t_next)
        except SolverError as error:
            if INTERRUPTS.urgent:  # a signal that came back from inside PETSc as a failed solve
                self._undo(saved, saved_physics)
                raise InterruptedRun(INTERRUPTS.received) from None
            failure = self._name_fields(str(error))
            if not error.depends_on_step:  # no smaller step can mend it: stop now, not after halving to dt_min
                self._undo(saved, saved_physics)
                raise SolverError(f"{self._step_label(t_next)}: {failure}", depends_on_step=False) from None
        except BaseException:
            self._undo(saved, saved_physics)
            raise
        if failure is not None:
            self._undo(saved, saved_physics)
            self._refuse_inputs_not_finite_at(self._times_tried, t_next)
            return failure
        nonlinear = {solver.sub.name for solver in self.solvers if not solver.sub.linear}
        for name, solve in stats.items():
            self.iterations.setdefault(name, []).append(solve.linear_iterations)
            if name in nonlinear:
                self.newton.setdefault(name, []).append((solve.newton_iterations, solve.reason))
        self.disc.set_time(t_next, dt)
        self.time, self.last_dt = t_next, dt
        self._state_version += 1
        return None

    def _refuse_inputs_not_finite_at(self, times: list[float], t_next: float) -> None:
        """The one line of an input (a boundary formula) that is not finite at a time a failed try set: no smaller
        step mends it.  The model checks inputs at sample times of the span (``Model.sample_times``); a formula
        singular at a step time between them ("s0 / (t - 0.25)", dt = 0.25) failed that step at every dt, each
        try still ending there, until dt_min, and the run blamed the solve ("the residual is not finite")."""
        if not times:  # the try failed before it set a time (a scheme's own failure)
            return
        try:
            for module in self.model.physics_objects:
                with module_code(module, "check_inputs"):
                    # from t_start, as at set-up: a module may read times[0] as the start (chemotaxis's initial state)
                    module.check_inputs(self.model.mesh_data, sorted({self.model.t_start, *times}))
        except ConfigError as error:
            raise ConfigError(f"{self._step_label(t_next)}: {error}") from None

    def _undo(self, saved: dict, saved_physics: list) -> None:
        self.disc.restore_state(saved)
        for physics, state in zip(self.model.physics_objects, saved_physics):
            physics.restore_state(state)
        self.disc.set_time(self.time, self._solver_dt)

    def _name_fields(self, failure: str) -> str:
        """A solver's failure, with the fields its subproblem solves for."""
        name = failure.partition(":")[0]
        fields = self._fields_of.get(name)
        if fields and fields != [name.rpartition(".")[2]]:
            return f"{name} (fields {', '.join(fields)}):{failure.partition(':')[2]}"
        return failure

    def _inadmissible(self, t: float) -> str | None:
        """Why the fields just computed cannot be accepted (non-finite, or negative where promised not), or None."""
        groups, count = self.disc.groups(), len(self._nonnegative)
        flags = np.zeros(len(groups) + 2 * count)  # per group: not finite; per promised field: -min, then max
        for i, group in enumerate(groups):
            flags[i] = not np.all(np.isfinite(self.backend.local_array(self.disc.group_function(group))))
        for j, (name, _) in enumerate(self._nonnegative):
            values = self.backend.local_array(self.disc.function_of(name)[0])
            flags[len(groups) + j] = -float(np.min(values)) if len(values) else -np.inf
            flags[len(groups) + count + j] = float(np.max(values)) if len(values) else -np.inf
        largest_in_place(self.comm, flags)
        for i, group in enumerate(groups):
            if flags[i]:
                return f"field {', '.join(self.disc.group_fields(group))} is not finite at t = {t:g}"
        for j, (name, owner) in enumerate(self._nonnegative):
            if -flags[len(groups) + j] < -NEGATIVE_TOLERANCE * max(flags[len(groups) + count + j], 0.0):
                return (f"field {name} fell to {-flags[len(groups) + j]:.3g} at t = {t:g}, below 0 where the "
                        f"scheme of {owner} keeps it >= 0")
        return None

    def advance(self, solvers: list, t0: float, duration: float, inner_steps: int = 1) -> dict:
        """Advance the fields of ``solvers`` from ``t0`` over ``duration`` in ``inner_steps`` steps.

        The other fields stay frozen.  Per inner step: time-dependent data are
        updated, the start values of these fields stored, the subproblems solved
        in order, and the rates of these fields (e.g. the solid velocity) updated.
        """
        delta = duration / inner_steps
        groups = list(dict.fromkeys(self.disc.group_of_function(s.sub.unknown) for s in solvers))
        stats: dict = {}
        batches = self.batches(solvers)
        for k in range(inner_steps):
            with self.substep(groups, t0 + (k + 1) * delta, delta):
                for name, solve in solve_in_turn(batches):
                    accumulate(stats, name, solve)
        return stats

    def batches(self, solvers: list) -> list[list]:
        """``solvers`` grouped for :func:`~primordia.coupling.solvers.solve_in_turn` (found once per list)."""
        key = tuple(id(solver) for solver in solvers)
        if key not in self._batches:
            self._batches[key] = independent_batches(solvers)
            batch_remainders(self.backend, solvers)  # their explicit terms assembled as one form, when they can
        return self._batches[key]

    @contextmanager
    def substep(self, groups: list[str], t: float, dt: float):
        """Bookkeeping around the solves that bring ``groups`` to time ``t`` over ``dt``.

        Before: time-dependent data are updated and the start values of these
        fields stored; after: the rates of these fields (e.g. the solid velocity).
        """
        self.disc.set_time(t, dt)
        self._times_tried.append(t)
        for physics in self.model.physics_objects:
            with module_code(physics, "before_step"):
                physics.before_step(t, dt)
        self.disc.store_previous(groups)
        yield
        self.disc.update_rates(dt, groups)

    def record_coupling_iterations(self, scheme: str, count: int) -> None:
        """Outer iterations a scheme needed in this step (e.g. the fixed-point iteration)."""
        self.coupling_iterations.setdefault(scheme, []).append(count)

    # -- outputs --------------------------------------------------------------------------
    def _notify(self, moment: str, *args):
        outputs = list(self.outputs)
        if moment == "finish":  # slow ones (the pictures) last, so that summary.json has the status before them
            outputs.sort(key=lambda output: bool(getattr(output, "finishes_last", False)))
        for output in outputs:  # the status an output finishes with is the run's as it is then (see _call_output)
            self._call_output(output, moment, *((self.status,) if moment == "finish" else args))

    def _call_output(self, output, moment: str, *args) -> None:
        """Call one output; one that fails (on any rank) is disabled on all, with a warning, and the run goes on.

        A file system that takes no more (a full disk, :class:`StorageError`) stops the run instead: every later
        write would fail as well, and the run computed on, writing nothing, to end "completed" with exit status 0
        and its files missing their last times.  While the run ends, such a failure ends that output in silence
        (the run's line says the disk is full); a completed run then stops with it, its summary saying so.

        The ranks agree on the failure over a communicator of their own (:meth:`_outputs_comm`), without
        blocking a rank whose output raised: the others may be waiting for it inside a collective call of the
        same output that it never reached (``primordia_outputs``'s contract forbids that, but a third party's
        output can do it), which no rank can leave.  That rank waits for them as long as the output has ever
        taken here, times ``OUTPUT_PATIENCE_FACTOR``, and at least ``OUTPUT_PATIENCE_S``, then ends the job
        with one line (:meth:`_abort_for_output`).  Until 2026-12-05 it entered the failure's allgather on
        the run's communicator, and a 2-rank run whose output raised on rank 1 before its ``allreduce`` hung
        until ``timeout 120`` killed it.
        """
        failure, storage, began = None, None, clock.perf_counter()
        try:
            getattr(output, moment)(self, *args)
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception as error:  # noqa: BLE001 - an output must not end the run
            failure = (str(error).splitlines() or [""])[0] or type(error).__name__
            if not isinstance(error, PrimordiaError):
                failure = f"{type(error).__name__}: {failure}"
            storage = storage_error(f"a file of output '{output.name}'", error)
            storage = None if storage is None else str(storage)
        if self.comm.size > 1:
            failure, storage = self._agreed_failure(output, moment, failure, storage, clock.perf_counter() - began)
        if failure is None:
            return
        if storage is not None and self.status == "running":  # kept: as the run stops it may fit (summary.json)
            raise StorageError(storage)
        self.outputs.remove(output)
        if storage is None:
            warn(f"output '{output.name}' failed at t = {self.time:g} ({moment}): {failure}; "
                 f"it is disabled for the rest of the run")
        elif self.status == "completed":
            self._unwritten, self.status = storage, self._stop_status(StorageError(storage))

    def _outputs_comm(self):
        """A duplicate of the run's communicator on which only the ranks' agreements on failures are made
        (:meth:`_call_output`, :meth:`_stop_together`): a rank that failed alone is then never matched with the
        others' collective calls.  Made before the first output is called, when every rank is at the same point."""
        if self._output_comm is None:
            self._output_comm = self.comm.Dup()
        return self._output_comm

    def _agreed_failure(self, output, moment: str, failure: str | None, storage: str | None,
                        took: float) -> tuple[str | None, str | None]:
        """The failure of the lowest rank where ``output`` failed (naming the rank) and whether it was a full
        disk's (:class:`StorageError`), or (None, None), on every rank."""
        key = (output.name, moment)
        longest = self._output_seconds[key] = max(self._output_seconds.get(key, 0.0), took)
        comm = self._outputs_comm()
        patience = None if failure is None else max(OUTPUT_PATIENCE_S, OUTPUT_PATIENCE_FACTOR * longest)
        try:
            rank = lowest_rank_where(comm, failure is not None, patience)
        except RanksMissing:
            self._abort_for_output(output, moment, failure, patience)
        if rank is None:
            return None, None
        failure, storage = comm.bcast((failure, storage), root=rank)
        return f"{failure} (on rank {rank})", storage

    def _abort_for_output(self, output, moment: str, failure: str, patience: float) -> None:
        """``output`` failed here and the other ranks are still inside it after ``patience`` seconds: waiting in a
        collective call this rank will never make, as far as can be told, which no rank can get them out of."""
        self._abort_alone(f"stopped at t = {self.time:g}: output '{output.name}' failed on rank {self.comm.rank} "
                          f"({moment}): {failure}, and the other ranks were still inside it after {patience:g} s (a "
                          f"collective call this rank never reached)")

    def _stop_together(self, exc: BaseException) -> None:
        """Return once every rank stops the run, as they do when a step fails (its verdict is every rank's).

        A step that raised on one rank alone (a physics plugin's ``before_step`` failing on rank 1 only) sent
        that rank into the stop's collective calls (the checkpoint's gather) while the others sat in the step's:
        ``mpirun -n 2`` hung without a word until ``timeout 120``.  After ``OUTPUT_PATIENCE_S`` that rank says why
        in one line and aborts the job; the checkpoint before that step is whole and continues the run.
        """
        if self.comm.size == 1 or (isinstance(exc, KeyboardInterrupt) and INTERRUPTS.count > 1):
            return  # a second signal: the ranks may be anywhere, and _stop makes no collective call then
        if not every_rank_stops(self._outputs_comm(), OUTPUT_PATIENCE_S):
            self._abort_alone(f"{self._stop_status(exc)} (on rank {self.comm.rank} alone: the other ranks were "
                              f"still in the step after {OUTPUT_PATIENCE_S:g} s)")

    def _abort_alone(self, status: str) -> None:
        """This rank cannot go on and the others are stuck where it will never join them: say ``status`` in one
        line, mark the summary with it (rank 0, which writes it, may be stuck) and end the job (MPI_Abort, exit
        status 2).  The last checkpoint is whole (written atomically) and continues the run."""
        import sys

        from mpi4py import MPI

        restart = (f"; continue it from its last checkpoint with: {self.restart_hint}"
                   if (self.out_dir / checkpoint_file.CHECKPOINT_FILE).exists() else "")
        print(f"primordia: error: {status}; the run is aborted{restart}", file=sys.stderr, flush=True)
        self._flush_outputs()
        self._patch_summary(status, here=True)
        MPI.COMM_WORLD.Abort(2)

    def _flush_outputs(self) -> None:
        """Have the outputs write on this rank what waits in memory (series.nc's rows of the last
        ``SERIES_INTERVAL`` seconds, on rank 0), before the run ends without their finish: what a rewrite of
        series.nc costs (4.8 ms for example 1a's 261 rows), once.  When a rank other than 0 aborts, rank 0 is inside
        a collective call and runs no Python again: its rows since the last rewrite are lost, as under SIGKILL."""
        for output in list(self.outputs):
            try:
                output.flush(self)
            except Exception:  # noqa: BLE001 - the run's line is being said: nothing of an output may hide it
                pass

    def _finish(self, status: str):
        self.status = status
        self._wall_end = clock.perf_counter()
        self.wall_time = self._wall_time()
        self._notify("finish")
        if self._output_comm is not None:  # every rank is here: the finish's failures were just agreed on
            self._output_comm.Free()
            self._output_comm = None

    def _wall_time(self) -> float:
        return self._wall_before + self._clock_of_the_run() - self.wall_start

    def _clock_of_the_run(self) -> float:
        """Now, or when the run ended: the summary of a finished run asked later (a notebook's next cell) counted
        the time since as the run's, its wall_time_s and ms per step growing as the Simulation waited."""
        return self._wall_end if self._wall_end is not None else clock.perf_counter()

    # -- what outputs read ------------------------------------------------------------------
    def field_specs(self) -> dict:
        """Every field's :class:`~primordia.physics.base.FieldSpec` (its meaning, scalar or vector), by name."""
        return {spec.name: spec for module in self.model.physics_objects for spec in module.fields()}

    @property
    def displacement_field(self) -> str | None:
        """The field the physics declares the tissue's displacement (pictures deform by it), or None."""
        return self.disc.displacement_field()

    def vertex_values(self) -> dict:
        """All fields at the MeshData vertices (rank 0; None elsewhere), cached per state."""
        if self._vertex_cache is None or self._vertex_cache[0] != self._state_version:
            values = {name: self.backend.vertex_values(*self.disc.function_of(name))
                      for name in self.disc.field_names()}
            self._vertex_cache = (self._state_version, values)
        return self._vertex_cache[1]

    def field_statistics(self) -> dict[str, dict[str, float]]:
        """Integral (of the magnitude, for vectors), min and max over the vertices of every field, cached per
        state as :meth:`vertex_values` is: a row of the series and the summary written with it read the same.

        The extrema are reduced over the ranks' own vertices (``vertex_extrema``): gathering every field to
        rank 0 for them took 1.2 ms of each row's 4.3 at 171^2 (example 1a), on 2 ranks as in serial.  The
        integrals of fields that share a function (example 1b's u and p) are assembled, 2.4 ms each there.
        """
        if self._statistics_cache is None or self._statistics_cache[0] != self._state_version:
            statistics = {}
            for name in self.disc.field_names():
                low, high = self.backend.vertex_extrema(*self.disc.function_of(name))
                statistics[name] = {"integral": self._integral(name), "min": low, "max": high}
            self._statistics_cache = (self._state_version, statistics)
        return {name: dict(values) for name, values in self._statistics_cache[1].items()}

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

    def series_descriptions(self) -> dict[str, tuple[str, str]]:
        """(long_name, units) of each key :meth:`iteration_counts`, :meth:`step_sizes` and :meth:`memory_use`
        record."""
        described = {**STEP_SIZES, **MEMORY_USE}
        for name in self.iterations:
            key = name.replace('.', '_')
            described[f"{key}_linear_iterations"] = (f"linear (Krylov) iterations in the last step of {key}", "1")
        for name in self.newton:
            key = name.replace('.', '_')
            described[f"{key}_newton_iterations"] = (f"Newton iterations in the last step of {key}", "1")
            described[f"{key}_snes_reason"] = (f"PETSc's SNES converged reason (> 0: converged) of the last solve "
                                               f"of {key}", "1")
        for scheme in self.coupling_iterations:
            described[f"{scheme}_iterations"] = (f"outer coupling iterations in the last step of the splitting "
                                                 f"scheme {scheme}", "1")
        return described

    def step_sizes(self) -> dict[str, float]:
        """The last sub-step's dt and the number of rejected sub-steps so far (:data:`STEP_SIZES` says what)."""
        return {"dt": self.last_dt, "rejections": float(len(self.rejections))}

    def memory_use(self) -> dict[str, float]:
        """Resident memory now and its peak so far (since this process started), in MB summed over the ranks
        (:data:`MEMORY_USE` says what).

        Recorded in the series, a run that leaks shows it long before the kernel kills it.
        """
        now, peak = resident_memory_mb()
        if self.comm.size > 1:
            now, peak = self.comm.allreduce(now), self.comm.allreduce(peak)
        return {"memory_mb": now, "peak_memory_mb": peak}

    def linear_solve_seconds(self, clock: str = "cpu") -> dict[str, float]:
        """Per subproblem, the seconds this process has spent in its linear algebra (Krylov iterations,
        preconditioner set-up, factorisations, diagonal divisions; not assembly), the solvers made anew at
        checkpoints included, the largest over the ranks (collective).  ``clock``: "cpu" (this process's
        CPU time) or "wall"."""
        totals = {name: seconds[clock] for name, seconds in self._solve_seconds.items()}
        for solver in getattr(self, "solvers", ()):
            totals[solver.sub.name] = totals.get(solver.sub.name, 0.0) + solver.linear_solve_seconds[clock]
        names = sorted(totals)
        values = np.array([totals[name] for name in names])
        if self.comm.size > 1:
            values = np.max(self.comm.allgather(values), axis=0)
        return {name: float(value) for name, value in zip(names, values)}

    def linear_solve_ms(self) -> dict[str, float]:
        """:meth:`linear_solve_seconds` in ms per step of this process: what a step cannot do without, to
        hold its whole cost against."""
        steps = self.step_index - self._first_step
        totals = self.linear_solve_seconds()
        return {name: 1e3 * seconds / steps for name, seconds in totals.items()} if steps else {}

    def _ms_per_step_after_first(self) -> float | None:
        """Wall ms per step of this process after its first step, outputs included: what a long run settles
        to.  The first step also loads the compiled forms and makes the first factorisations and AMG
        hierarchies (example 2a at 171 x 171 squares: the growth system's first LU factorisation), which a
        run of thousands of steps amortises and ``ms_per_step`` of a short one does not."""
        later = self.step_index - self._first_step - 1
        if self._wall_after_first is None or later < 1:
            return None
        return 1e3 * (self._clock_of_the_run() - self._wall_after_first) / later

    def summary(self, status: str) -> dict:
        wall = self._wall_time()
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
            "rejected_steps": len(self.rejections),
            "restarts": self.restarts,
            "checkpoint_step": self._checkpoint_step,
            "wall_time_s": wall,
            "ms_per_step": 1e3 * wall / self.step_index if self.step_index else None,
            "ms_per_step_after_first": self._ms_per_step_after_first(),
            "linear_solve_ms_per_step": self.linear_solve_ms(),
            "final": self.field_statistics(),
            "mean_linear_iterations": {name: float(np.mean(its)) for name, its in self.iterations.items() if its},
            "mean_newton_iterations": {name: float(np.mean([its for its, _ in record]))
                                       for name, record in self.newton.items() if record},
            "mean_coupling_iterations": {scheme: float(np.mean(its))
                                         for scheme, its in self.coupling_iterations.items() if its},
            "splitting_scheme": self.scheme.name,
            "peak_memory_mb": self.memory_use()["peak_memory_mb"],
            "software": software(),  # the versions and plugins it was computed with (this process's)
        }


def resident_memory_mb() -> tuple[float, float]:
    """This process's resident memory and its peak (Linux's /proc; elsewhere the peak for both)."""
    import resource

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux
    try:
        fields = Path("/proc/self/status").read_text().split("\n")
        now = next(float(line.split()[1]) for line in fields if line.startswith("VmRSS:")) / 1024.0
    except (OSError, StopIteration, ValueError, IndexError):
        now = peak
    return now, max(peak, now)


def release_free_memory() -> bool:
    """Give the memory the process has freed back to the system (glibc's ``malloc_trim``); whether it could.

    glibc keeps freed memory for later allocations, so the resident size stays at its
    peak: example 2b at 171 x 171 squares kept 2.77 GB after its first steps, and 1.83 GB
    once trimmed (the transient of the first factorisations and form compilations).
    Elsewhere (musl, macOS) nothing is done.
    """
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):
        return False
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    trim(0)
    return True


@dataclasses.dataclass(eq=False)
class _DofLayout:
    """A state group's DOFs as a parallel checkpoint stores them (``Simulation._dof_layout``).

    ``keys``: this rank's owned DOFs' keys.  ``order``, once ``sorted``: on rank 0, the permutation from the
    ranks' owned DOFs, gathered in rank order, to the order of their keys, and the keys in that order; None
    elsewhere.
    """

    keys: np.ndarray
    sorted: bool = False
    order: tuple[np.ndarray, np.ndarray] | None = None


def _alike(states: list) -> bool:
    """Whether the ranks' physics states of a checkpoint are all the same (any rank's then serves every rank)."""
    def same(one, other) -> bool:
        if isinstance(one, dict):
            return isinstance(other, dict) and one.keys() == other.keys() and all(same(one[k], other[k]) for k in one)
        if isinstance(one, (list, tuple)):
            return (isinstance(other, (list, tuple)) and len(one) == len(other)
                    and all(same(a, b) for a, b in zip(one, other)))
        if isinstance(one, np.ndarray) or isinstance(other, np.ndarray):
            return np.array_equal(one, other)
        return one == other

    return all(same(states[0], state) for state in states[1:])


def _rows(keys: np.ndarray) -> np.ndarray:
    """Integer key rows as single comparable items (sortable, searchable)."""
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    return keys.view(np.dtype((np.void, keys.dtype.itemsize * keys.shape[1]))).ravel()


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

    return tqdm(total=sim.model.num_steps, initial=sim.step_index, unit="step", dynamic_ncols=True, file=sys.stderr,
                mininterval=0.5 if sys.stderr.isatty() else 15.0,
                bar_format="{l_bar}{bar}| step {n_fmt}/{total_fmt} {postfix} [{elapsed}<{remaining}]")
