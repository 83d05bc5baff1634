"""Composing a model: from a TOML file or in a few lines of Python.

>>> from primordia import Model
>>> from primordia.core.meshes import rectangle
>>> model = Model(physics=["chemotaxis"], kinetics="painter2018",
...               parameters={"m0": 0.75, "D_m": 0.03},
...               mesh=rectangle((0, 0), (20, 20), cells=(43, 43)),
...               dt=0.2, t_final=20.0, output={"times": [10, 20], "snapshot_fields": ["m"]})
>>> result = model.run(backend="fenicsx", out="out/quick")     # doctest: +SKIP

:class:`Model` validates what it is given before any assembly: unknown
physics, kinetics, parameters or options, wrong signs and impossible meshes are
reported in one line naming the culprit.  The backend and the splitting scheme are
chosen by hooks a plugin may answer, for a run: they are checked when the run is
set up, or at once, with nothing solved or written, by ``check_choices()`` and
``check_forms()`` of ``Simulation(model, backend=model.backend)`` (what ``--dry-run`` does).
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from primordia.core import config as config_
from primordia.core.errors import ConfigError, PluginError, is_third_party, plugin_code, warn
from primordia.core.mesh_data import MeshData
from primordia.core.parameters import Parameter, ParameterSet
from primordia.core.plugins import lookup, registry
from primordia.core.validation import field_name, flag, number, numbers

#: The keys of ``[output]`` that say when the run writes (read by the run itself); every other key
#: is an option one registered output declares (:attr:`primordia.core.outputs.Output.options`).
OUTPUT_SCHEDULE = {"times": None, "series_every": 10}
#: Checkpoints: every N steps (0: never by steps) and every M minutes of wall time (0: never by time).
#: A run shorter than ``every_minutes`` writes none but its last, at the end or when stopped.
DEFAULT_CHECKPOINT = {"every_steps": 0, "every_minutes": 10.0}
#: More steps than this is a dt in the wrong units, not a run (at a millisecond per step: three hours).
MAX_STEPS = 10_000_000
#: Adaptive steps go down to dt / 2^10 unless ``time.dt_min`` says otherwise.
DEFAULT_HALVINGS = 10
#: Keys a restart may change: how long, what is written, how often checkpoints are, how solves are done.
CHANGEABLE_ON_RESTART = ("time.t_final", "time.adaptive", "time.dt_min", "output", "checkpoint", "solver",
                         "model.name", "model.description")


class Model:
    """A validated model: physics + kinetics + parameters + mesh + time + outputs.

    Each argument is a table or key of a config file (:mod:`primordia.core.config`):

    - ``physics``: model.physics, the names of the physics modules (``["chemotaxis", "poroelasticity"]``);
    - ``kinetics``, ``growth_law``: [kinetics], [growth_law], a name or a dict ``{"name": ..., options}``;
    - ``parameters``: [parameters], a dict of seed names to values (another model's ``parameters`` too);
    - ``mesh``: a :class:`~primordia.core.mesh_data.MeshData` (``rectangle``, ``box``, ``read_mesh`` of
      :mod:`primordia.core.meshes`, or built by hand) or a [mesh] table;
    - ``dt``, ``t_final``, ``t_start``, ``adaptive``, ``dt_min``: [time] (dimensionless time);
    - ``output``, ``checkpoint``, ``solver``: the tables of those names;
    - ``physics_options``: [physics], ``{module name: {option: value}}``;
    - ``coupling``: [coupling], a scheme's name or ``{"scheme": ..., options}``;
    - ``backend``, ``name``, ``description``: model.backend, model.name, model.description;
    - ``base_dir``: the folder a [mesh] table's ``path`` is relative to.

    The names a model may use are those registered (``primordia plugins`` lists them, and
    ``primordia.core.plugins.registry("physics")``, ``"kinetics"``, ``"growth_laws"`` gives them in
    Python).  :meth:`run` runs it; :meth:`resolved_config` is the config file that builds it again.
    """

    def __init__(self, physics=("chemotaxis",), kinetics: str | dict | None = None, parameters=None,
                 mesh: MeshData | dict | None = None, dt: float | None = None, t_final: float | None = None,
                 t_start: float = 0.0, output: dict | None = None, physics_options: dict | None = None,
                 coupling: str | dict = "sequential", solver: dict | None = None, backend: str = "fenicsx",
                 name: str = "", base_dir: str | Path = ".", growth_law: str | dict | None = None,
                 adaptive: bool = True, dt_min: float | None = None, checkpoint: dict | None = None,
                 description: str = ""):
        self.name = _text(name, "model.name")
        self.description = _text(description, "model.description")
        self.backend = _backend_name(backend, "model.backend")
        self.base_dir = _path(base_dir, "base_dir")
        if not isinstance(coupling, (str, dict)):
            raise ConfigError(f"[coupling] must be a table (scheme = \"...\" and its options), got {coupling!r}")
        coupling = {"scheme": coupling} if isinstance(coupling, str) else dict(coupling)
        self.coupling = coupling.pop("scheme", "sequential")
        if not isinstance(self.coupling, str):
            raise ConfigError(f"coupling.scheme must be the name of a splitting scheme, got {self.coupling!r}")
        self.coupling_options = coupling
        if not isinstance(solver, (dict, type(None))):
            raise ConfigError(f"[solver] must be a table of [solver.PREFIX] tables, got {solver!r}")
        self.solver = dict(solver or {})
        self._mesh_spec = mesh
        self.physics_classes = [lookup("physics", p) for p in _as_list(physics, "model.physics")]
        self.kinetics_spec = _kinetics_table(kinetics, self.physics_classes)
        self.kinetics_class = (lookup("kinetics", self.kinetics_spec["name"])
                               if self.kinetics_spec is not None else None)
        self.growth_law_spec = _growth_law_table(growth_law, self.physics_classes)
        self.growth_law_class = (lookup("growth_laws", self.growth_law_spec["name"])
                                 if self.growth_law_spec is not None else None)
        self.parameters = self._parameter_set(parameters or {})
        self.physics_options = self._physics_options(physics_options or {})
        self.t_start, self.dt, self.t_final = _time(t_start, dt, t_final)
        self.adaptive, self.dt_min = _adaptivity(adaptive, dt_min, self.dt, max(abs(self.t_start), abs(self.t_final)))
        self.output = self._output(output or {})
        #: output.times not given: the fields are written at t_final, which a restart that moves t_final follows
        self.output_times_default = output is None or output.get("times") is None
        self.checkpoint = _checkpoint(checkpoint)
        self._instantiate_physics()  # validates kinetics and physics options now
        self.mesh_data = self._mesh()
        from primordia.physics.base import module_code

        for module in self.physics_objects:  # what only the mesh and the time span show: boundary formulas
            with module_code(module, "check_inputs"):
                module.check_inputs(self.mesh_data, self.sample_times())
        self.inert_settings = self._inert_settings()
        self._built = True

    def __setattr__(self, name: str, value) -> None:
        # read-only once built: model.dt = 0.1 was taken and read back, while its output times, its physics objects
        # and config.toml kept what the model was built with (see ParameterSet.__setattr__ for its parameters)
        if not name.startswith("_") and vars(self).get("_built"):
            raise AttributeError(f"a Model is read-only once built (model.{name} = ... would change no run "
                                 f"consistently): build another Model with the new value, Model(...) or "
                                 f"Model.from_file(config, ['section.key=value'])")
        super().__setattr__(name, value)

    def __repr__(self) -> str:
        """What the model is, in one line: its composition, mesh and time span (not the default object repr)."""
        if "mesh_data" not in vars(self):  # a construction that raised part-way, as a traceback or debugger shows it
            return "Model(not set up: its construction raised)"
        pieces = [f"name={self.name!r}"] if self.name else []
        pieces.append(f"physics={[module.name for module in self.physics_objects]}")
        if self.kinetics_object is not None:
            pieces.append(f"kinetics={self.kinetics_object.name!r}")
        if self.growth_law_object is not None:
            pieces.append(f"growth_law={self.growth_law_object.name!r}")
        pieces += [f"mesh={self.mesh_data!r}", f"dt={self.dt:g}", f"t={self.t_start:g}..{self.t_final:g}",
                   f"coupling={self.coupling!r}", f"backend={self.backend!r}"]
        return f"Model({', '.join(pieces)})"

    # -- construction from a config --------------------------------------------------------
    @classmethod
    def from_config(cls, config: dict) -> "Model":
        """The model a config's tables (as :func:`primordia.core.config.load_config` reads them) describe."""
        config_.check_structure(config)
        model_table = config.get("model", {})
        time = config.get("time", {})
        if "dt" not in time or "t_final" not in time:
            raise ConfigError("the configuration needs [time] dt and t_final")
        if "mesh" not in config:
            raise ConfigError("the configuration needs a [mesh] table")
        return cls(
            physics=model_table.get("physics", ["chemotaxis"]), kinetics=config.get("kinetics"),
            parameters=config.get("parameters"), mesh=config["mesh"], dt=time["dt"], t_final=time["t_final"],
            t_start=time.get("t_start", 0.0), output=config.get("output"),
            physics_options=config.get("physics"), coupling=config.get("coupling", {}),
            solver=config.get("solver"), backend=model_table.get("backend", "fenicsx"),
            name=model_table.get("name", ""), description=model_table.get("description", ""),
            base_dir=config.get("_base_dir", "."), growth_law=config.get("growth_law"),
            adaptive=time.get("adaptive", True), dt_min=time.get("dt_min"), checkpoint=config.get("checkpoint"),
        )

    @classmethod
    def from_file(cls, path, overrides: list[str] | None = None) -> "Model":
        """The model of a TOML config file, with ``overrides`` as ``--set`` gives them (``["time.t_final=320"]``)."""
        return cls.from_config(config_.apply_overrides(config_.load_config(path), overrides or []))

    # -- validation pieces -------------------------------------------------------------------
    def _parameter_set(self, overrides: dict) -> ParameterSet:
        pieces = [(f"physics {cls.name}", cls) for cls in self.physics_classes]
        for label, piece in (("kinetics", self.kinetics_class), ("growth law", self.growth_law_class)):
            if piece is not None:
                pieces.append((f"{label} {piece.name}", piece))
        declarations = _declarations(pieces)
        if not isinstance(overrides, Mapping):  # a dict, or another model's parameters (a ParameterSet)
            raise ConfigError(f"[parameters] must be a table of name = value, got {_kind(overrides)}")
        overrides = dict(overrides)
        declared = {parameter.name: parameter for parameter in declarations}
        for name, value in overrides.items():  # in the order ParameterSet takes them
            if name not in declared:
                _refuse_a_law_of_another_dimension(self.growth_law_class, self._mesh_spec)
                _refuse_a_parameter_of_another_piece(name, [owner for owner, _ in pieces])
                break  # unknown to every piece: ParameterSet says so, with the names it may mean
            try:
                declared[name].check(value)
            except ConfigError as error:  # a value out of a third party's parameter's range: whose parameter it is
                raise ConfigError(f"{error}{_declared_by_a_plugin(name, pieces)}") from None
        return ParameterSet(declarations, overrides)

    def _physics_options(self, table: dict) -> dict:
        names = {cls.name for cls in self.physics_classes}
        if not isinstance(table, dict):
            raise ConfigError(f"[physics] must be a table of [physics.NAME] tables, got {table!r}")
        for name, options in table.items():
            if not isinstance(options, dict):
                raise ConfigError(f"physics.{name} must be a table of options ([physics.{name}]), got {options!r}")
        for name in table:
            if name not in names:
                raise ConfigError(f"[physics.{name}] configures a module that is not in model.physics "
                                  f"({', '.join(sorted(names))})")
        return {cls.name: dict(table.get(cls.name, {})) for cls in self.physics_classes}

    def _output(self, table: dict) -> dict:
        """``[output]``: the schedule, and the options of the registered outputs, with their defaults."""
        from primordia.core.outputs import declared_options, time_label

        if not isinstance(table, dict):
            raise ConfigError(f"[output] must be a table, got {table!r}")
        declared = declared_options((output for output, _ in registry("outputs").values()), OUTPUT_SCHEDULE)
        unknown = set(table) - set(OUTPUT_SCHEDULE) - set(declared)
        if unknown:
            raise ConfigError(f"unknown key output.{sorted(unknown)[0]} "
                              f"(known: {', '.join([*OUTPUT_SCHEDULE, *declared])})")
        self._field_options = [key for key, option in declared.items() if option.names_fields]
        output = {**OUTPUT_SCHEDULE, **{key: option.default for key, option in declared.items()}, **table}
        for key in declared.keys() & table.keys():
            output[key] = declared[key].check(table[key], f"output.{key}")
        times = numbers(output["times"], "output.times") if output["times"] is not None else [self.t_final]
        for t in times:
            # round-off of t_final only: 1e-12 was 5 steps of dt = 1e-13, past the run's end
            if not self.t_start < t <= self.t_final + min(1e-12, 1e-9 * self.dt):
                raise ConfigError(f"output time {time_label(t)} lies outside (t_start, t_final] = "
                                  f"({time_label(self.t_start)}, {time_label(self.t_final)}]")
            # in steps, as t_final is: 1e-9 in time was half a step of dt = 1e-12, and a time within it of
            # t_start fell on step 0, which no run writes
            if not _on_the_step_grid(self.t_start, t, self.dt):
                raise ConfigError(f"output time {time_label(t)} is not a multiple of dt = {time_label(self.dt)} "
                                  f"after t_start")
        # one time per step (a time given twice, or as 0.3 and 0.1 + 0.2, is one output and one entry in config.toml)
        on_steps = {self.step_of(float(t)): float(t) for t in reversed(times)}
        output["times"] = sorted(on_steps.values())
        number(output["series_every"], "output.series_every", integer=True, at_least=1, hint="steps")
        return output

    def _instantiate_physics(self):
        self.kinetics_object = None
        if self.kinetics_class is not None:
            options = {k: v for k, v in self.kinetics_spec.items() if k != "name"}
            self.kinetics_object = _construct("kinetics", self.kinetics_class, self.parameters, **options)
        self.growth_law_object = None
        if self.growth_law_class is not None:
            options = {k: v for k, v in self.growth_law_spec.items() if k != "name"}
            self.growth_law_object = _construct("growth law", self.growth_law_class, self.parameters, **options)
        self.physics_objects = [_construct("physics", cls, self.parameters, kinetics=self.kinetics_object,
                                           growth_law=self.growth_law_object, **self.physics_options[cls.name])
                                for cls in self.physics_classes]
        from primordia.physics.base import fields_of, module_code

        for module in self.physics_objects:  # what the others' checks read: one line if a module's is no list
            fields_of(module)
        for module in self.physics_objects:
            with module_code(module, "check_composition"):
                module.check_composition(self.physics_objects)
        fields = _unique_fields(self.physics_objects, self.kinetics_object)
        _check_requirements(self.physics_objects, fields)
        for key in self._field_options:  # output options that name fields (OutputOption.names_fields)
            if self.output[key] is None:
                self.output[key] = fields[:1]
            for name in self.output[key]:
                if name not in fields:
                    raise ConfigError(f"output.{key} names '{name}', which is not a field of this model "
                                      f"({', '.join(fields)})")

    def _inert_settings(self) -> list[str]:
        """What this model leaves without effect, one line each: a module option (``Physics.inert_options``) that
        holds another value than its default, and a [solver.NAME] table of a subproblem the modules' settings do
        not make (``Physics.inert_solver_tables``).  physics.chemotaxis.preconditioner = "lu" under solve = "split"
        was taken without a word, and [solver.chemotaxis_m] under solve = "coupled" refused as an unknown table.
        Warned (:meth:`warn_about_inert_settings`), not refused, as a [coupling] option of another scheme is: a
        config whose choice was switched with --set (solve = "coupled" to "split") keeps that choice's options.
        Only option values other than the default are told, since the resolved config.toml a restart reads holds
        every default: a refusal of the key itself stopped every restart of example 1a.  (A solver table is only
        ever the user's.)"""
        from primordia.core.json_toml import toml_text
        from primordia.physics.base import module_code

        told = []
        #: the tables told here, which the run's check that every table names a subproblem leaves alone
        #: (splitting.SplittingScheme.check_solver_tables)
        self.inert_solver_tables = {}
        for module in self.physics_objects:
            with module_code(module, "inert_options"):
                inert = module.inert_options(self.physics_objects, self.mesh_data.gdim, self.solver)
            defaults = type(module).options
            for key, why in (inert or {}).items():
                value = config_.as_toml_reads_it(module.settings.get(key))
                if key in defaults and value != config_.as_toml_reads_it(defaults[key]):
                    told.append(f"physics.{module.name}.{key} = {toml_text(value)} has no effect: {why}")
            with module_code(module, "inert_solver_tables"):
                tables = module.inert_solver_tables()
            for name, why in (tables or {}).items():
                if name in self.solver:
                    self.inert_solver_tables[name] = why
                    told.append(f"[solver.{name}] has no effect: {why}")
        return told

    def warn_about_inert_settings(self) -> None:
        """One warning per setting this model leaves without effect (:meth:`_inert_settings`): said by what runs or
        checks the model (a run, ``--dry-run``, a sweep once) once its checks passed (a refused input stays one
        line), not by each model a linear analysis or a sweep's gathering composes from a run's config."""
        for line in self.inert_settings:
            warn(line)

    def check_affordable(self) -> None:
        """The mesh against the memory the model's modules need per cell (``Physics.min_bytes_per_cell``), where
        that is more than the mesh's own floor: over the machines of an MPI run when Open MPI says how many
        ranks share one (``OMPI_COMM_WORLD_LOCAL_SIZE``), else not checked on several ranks (they may span
        machines this one cannot see).  A run's set-up and ``--dry-run`` ask it; a linear analysis of the
        model, which builds no system on the mesh, does not."""
        from primordia.core.errors import mpi_world
        from primordia.core.meshes import MIN_BYTES_PER_CELL, check_affordable

        tdim = self.mesh_data.gdim
        per_cell, name = max(((module.min_bytes_per_cell.get(tdim, 0), module.name)
                              for module in self.physics_objects), default=(0, ""))
        if per_cell <= MIN_BYTES_PER_CELL[tdim]:
            return
        size = mpi_world()[1]
        local = os.environ.get("OMPI_COMM_WORLD_LOCAL_SIZE", "")
        if size > 1 and not local.isdigit():
            return
        nodes = max(1, size // int(local)) if size > 1 else 1
        check_affordable(self.mesh_data.num_cells, tdim, per_cell, f"physics {name}", nodes)

    def _mesh(self) -> MeshData:
        from primordia.core.meshes import mesh_from_config

        if isinstance(self._mesh_spec, MeshData):
            if self._mesh_spec.source() is None:  # built by hand: a file or a generator's is checked already
                from primordia.core.meshes import check_mesh

                check_mesh(self._mesh_spec)
            return self._mesh_spec
        if isinstance(self._mesh_spec, dict):
            return mesh_from_config(self._mesh_spec, self.base_dir)
        hint = (": make one with MeshData(points, cells, boundaries), or read its file with "
                "primordia.core.meshes.read_mesh" if type(self._mesh_spec).__module__.startswith("meshio") else "")
        raise ConfigError(f"a model needs a mesh (a MeshData or a [mesh] table), got {_kind(self._mesh_spec)}{hint}")

    # -- what a run needs ----------------------------------------------------------------------
    @property
    def num_steps(self) -> int:
        return self.step_of(self.t_final)

    def step_of(self, t: float) -> int:
        """The step of the grid t_start + k dt nearest to time ``t`` (an output time's, t_final's, a restart's)."""
        return int(round((t - self.t_start) / self.dt))

    def step_time(self, step: int) -> float:
        """The time the run reaches at the end of nominal step ``step``: t_start + step dt, except that the
        step of an output time or of t_final reaches that time as given.  3 x 0.1 is 0.30000000000000004:
        a run with dt = 0.1 and output.times = [0.3] wrote that time in series.nc and fields.xdmf, where
        ``sel(time=0.3)`` did not find it."""
        key = (tuple(self.output["times"]), self.t_final, self.t_start, self.dt)
        if getattr(self, "_step_times", (None,))[0] != key:  # found once per set of times, not at every step
            self._step_times = (key, {self.step_of(t): t
                                      for t in (*self.output["times"], self.t_final)})
        return self._step_times[1].get(step, self.t_start + step * self.dt)

    def sample_times(self, count: int = 65) -> list[float]:
        """Times at which inputs that vary in time are checked: the run's span and its output times."""
        span = np.linspace(self.t_start, self.t_final, count)
        return sorted({*map(float, span), *self.output["times"]})

    @property
    def mesh_in_memory(self) -> bool:
        """Whether the mesh was made in Python with no ``[mesh]`` table that builds it: a config.toml of the model
        cannot rebuild it (``primordia run --restart`` refuses such a run in one line)."""
        return not isinstance(self._mesh_spec, dict) and self.mesh_data.source() is None

    def resolved_config(self) -> dict:
        """The fully resolved configuration (defaults filled in), as written to ``config.toml``.

        Except ``output.times`` when they were not given: the default is "at t_final", whatever t_final is, and
        written out as [t_final] it froze there.  A run extended from its config.toml with a later t_final
        (``Model.from_file(config.toml, ["time.t_final=..."])``, or that file given to ``--restart``) wrote no
        fields at its end, where ``--restart OUT --set time.t_final=...`` wrote them.
        """
        mesh = (copy.deepcopy(self._mesh_spec) if isinstance(self._mesh_spec, dict)
                else self.mesh_data.source()  # a generator's or the reader's mesh, unchanged: its table
                or {"type": "in-memory", "vertices": self.mesh_data.num_vertices,
                    "cells": self.mesh_data.num_cells, "description": self.mesh_data.description})
        if mesh.get("type") == "file":  # readable from wherever the resolved config is read (a restart)
            mesh["path"] = str((self.base_dir / Path(mesh["path"]).expanduser()).resolve())
        resolved = {
            "model": {"name": self.name, "physics": [p.name for p in self.physics_objects], "backend": self.backend},
            "parameters": dict(self.parameters),
            "physics": {p.name: dict(p.settings) for p in self.physics_objects},
            "mesh": mesh,
            "time": {"t_start": self.t_start, "dt": self.dt, "t_final": self.t_final, "adaptive": self.adaptive,
                     "dt_min": self.dt_min},
            "output": {key: value for key, value in self.output.items()
                       if not (key == "times" and self.output_times_default)},
            "checkpoint": dict(self.checkpoint),
            "coupling": {"scheme": self.coupling, **self.coupling_options},
        }
        if self.description:
            resolved["model"]["description"] = self.description
        if self.kinetics_object is not None:
            resolved["kinetics"] = {"name": self.kinetics_object.name, **self.kinetics_object.settings}
        if self.growth_law_object is not None:
            resolved["growth_law"] = {"name": self.growth_law_object.name, **self.growth_law_object.settings}
        if self.solver:
            resolved["solver"] = copy.deepcopy(self.solver)
        return config_.as_toml_reads_it(resolved)

    def run(self, backend: str | None = None, out: str | Path = "out/run", progress: bool = False, comm=None,
            overwrite: bool = False, restart: bool = False, continue_with: str | None = None):
        """Set up and run; returns the finished :class:`~primordia.coupling.orchestrator.Simulation`.

        ``continue_with``: how a run that stops early says it is continued (default, in Python's words,
        ``Model.run(out=..., restart=True)``; ``primordia run`` gives its command).

        An ``out`` directory that already holds a run is refused, unless ``overwrite``
        (its run files are removed first) or ``restart`` (the run continues from the
        checkpoint in ``out``, which must be of this same model).
        """
        from primordia.coupling.orchestrator import Simulation

        if restart and overwrite:
            raise ConfigError("restart=True continues the run in out, overwrite=True replaces it: choose one")
        existing = "restart" if restart else "overwrite" if overwrite else "refuse"
        out = out if isinstance(out, str) else _path(out, "out")  # a str as given: Simulation refuses "" (not ".")
        sim = Simulation(self, backend=backend or self.backend, out_dir=out, comm=comm, existing=existing)
        sim.restart_hint = continue_with or f"Model.run(out={str(out)!r}, restart=True)"
        sim.setup()
        sim.run(progress=progress)
        return sim

    def differences(self, resolved: dict, allowed=CHANGEABLE_ON_RESTART) -> list[str]:
        """Dotted keys where ``resolved`` (another run's resolved config) differs from this model's, except ``allowed``.

        A key ``resolved`` lacks is an option added since it was written, or one unset there (None, which TOML
        cannot hold, so config.toml leaves it out): the other run had the option's default, and this model differs
        only where it holds another value.  Every key ``resolved`` lacked was taken for the same: a restart of
        example 4 with ``--set growth_law.directions=...`` (default None, the axes) continued with the frame
        turned, as did linear Biot's ``shear_modulus`` (default None, from E and nu) set on a restart.
        """
        current, defaults = self.resolved_config(), self._option_defaults()
        return [key for key in _differences(current, resolved)
                if not any(key == a or key.startswith(a + ".") for a in allowed)
                and (_has(resolved, key) or _away_from_default(current, defaults, key))]

    def _option_defaults(self) -> dict:
        """The defaults of the pieces' options, laid out as :meth:`resolved_config` lays out their values."""
        defaults = {"physics": {module.name: dict(type(module).options) for module in self.physics_objects}}
        for section, piece in (("kinetics", self.kinetics_object), ("growth_law", self.growth_law_object)):
            if piece is not None:
                defaults[section] = dict(type(piece).options)
        return defaults


#: The dimension of the meshes the generators of a ``[mesh]`` table make, known before the mesh is.
_GENERATED_DIMENSIONS = {"rectangle": 2, "box": 3}


def _refuse_a_law_of_another_dimension(law, mesh) -> None:
    """The growth law against the mesh's dimension where it is known before the mesh is made (a MeshData, a
    generator's table; a file's is checked once it is read), when a parameter is not the model's: example 4 with its
    law switched to seed2d was told to remove seed3d's delta_1, and the next attempt that seed2d is written for
    2D, the mistake made."""
    if law is None:
        return
    kind = mesh.get("type") if isinstance(mesh, dict) else None
    dimension = mesh.gdim if isinstance(mesh, MeshData) else _GENERATED_DIMENSIONS.get(kind if isinstance(kind, str)
                                                                                       else None)
    if dimension is not None:
        from primordia.physics.growth_laws import refuse_another_dimension

        refuse_another_dimension(law, dimension)


def _refuse_a_parameter_of_another_piece(name: str, used: list[str]) -> None:
    """One line when the unknown parameter ``name`` is one of a registered piece this model does not use (say,
    example 4's delta_1 after its growth law was switched to seed2d); nothing otherwise (the caller's
    "unknown parameter" line, with its suggestions, follows)."""
    labels = {"physics": "physics", "kinetics": "kinetics", "growth_laws": "growth law"}
    owners = [f"{label} {piece_name}" for kind, label in labels.items()
              for piece_name, (piece, _) in registry(kind).items()
              if any(getattr(parameter, "name", None) == name for parameter in getattr(piece, "parameters", ()))]
    if owners:
        raise ConfigError(f"parameter '{name}' belongs to {' and '.join(owners)}, which this model does not use "
                          f"(it uses {', '.join(used)}): remove it from [parameters], or use that piece")


def _declared_by_a_plugin(name: str, pieces) -> str:
    """`` (declared by kinetics NAME, a plugin)`` when a third party's piece declares the parameter ``name``:
    "parameter k_g must be >= 0" said neither which plugin's parameter it is nor where its range comes from.
    Empty for primordia's own (the seed's Table 3.1, mostly)."""
    owners = [owner for owner, piece in pieces
              if is_third_party(piece) and any(parameter.name == name for parameter in piece.parameters)]
    return f" (declared by {', '.join(owners)}, a plugin)" if owners else ""


def _declarations(pieces) -> list[Parameter]:
    """The parameters the pieces of a model declare, checked: a default that is no valid value of its parameter,
    or one name declared with two defaults, is one line naming the pieces (a plugin's mistake, not the user's)."""
    declarations: list[Parameter] = []
    owners: dict[str, tuple[Parameter, str]] = {}
    for owner, piece in pieces:
        declared = piece.parameters
        if not isinstance(declared, (list, tuple)) or not all(isinstance(p, Parameter) for p in declared):
            raise PluginError(f"{owner}: its parameters must be a tuple of primordia.core.parameters.Parameter, "
                              f"got {declared!r}")
        for parameter in declared:
            if not isinstance(parameter.description, str) or not parameter.description.strip():
                raise PluginError(f"{owner} declares parameter {parameter.name} without a description: every message "
                                  f"about it quotes what it is (say its unit there too, e.g. \"decay rate of h "
                                  f"(1/time)\")")
            try:
                parameter.check(parameter.default)
            except ConfigError as error:
                raise PluginError(f"{owner} declares parameter {parameter.name} with the default "
                                  f"{parameter.default!r}, not a valid value of it: {error}") from None
            if parameter.name in owners and owners[parameter.name][0].default != parameter.default:
                first, first_owner = owners[parameter.name]
                raise PluginError(f"parameter {parameter.name} is declared by {first_owner} (default "
                                  f"{first.default:g}) and by {owner} (default {parameter.default:g}): one model has "
                                  f"one value per name, so one of them must rename it")
            owners.setdefault(parameter.name, (parameter, owner))
            declarations.append(parameter)
    return declarations


def _construct(label: str, cls, *args, **kwargs):
    """``cls(*args, **kwargs)`` for a piece of the model; a piece whose constructor fails other than with a
    one-line error of primordia (a bug of its plugin) is one line naming it, not a traceback."""
    with plugin_code(f"{label} {getattr(cls, 'name', cls.__name__)} ({cls.__module__}.{cls.__qualname__}) "
                     f"could not be set up", source=cls):
        return cls(*args, **kwargs)


def _check_requirements(modules, fields: list[str]) -> None:
    """What each module ``requires`` is a field of the model or a quantity a module ``provides``, or one line
    naming it (and the registered modules that would provide it)."""
    offered = set(fields) | {name for module in modules for name in getattr(module, "provides", ())}
    for module in modules:
        for name in module.requires:
            if name in offered:
                continue
            providers = sorted(piece_name for piece_name, (piece, _) in registry("physics").items()
                               if name in getattr(piece, "provides", ()))
            hint = f"; physics {' or '.join(providers)} provides it" if providers else ""
            raise ConfigError(f"physics {module.name} requires '{name}', which no physics module of this model "
                              f"provides (fields: {', '.join(fields)}){hint}")


def _unique_fields(modules, kinetics) -> list[str]:
    """The fields of the model's modules, each owned by one module (a kinetics' species named like another
    module's field, say ``u``, is one line naming both)."""
    owners: dict[str, str] = {}
    for module in modules:
        for spec in module.fields():
            owner = f"physics {module.name}"
            field_name(spec.name, owner)
            if module.needs_kinetics and kinetics is not None and spec.name in kinetics.species_names:
                owner += f" (a species of kinetics {kinetics.name})"
            if spec.name in owners:
                raise ConfigError(f"field '{spec.name}' is provided by both {owners[spec.name]} and {owner}")
            owners[spec.name] = owner
    return list(owners)


def _differences(a, b, prefix: str = "") -> list[str]:
    """Dotted keys at which two nested tables differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [key for name in dict.fromkeys([*a, *b])
                for key in _differences(a.get(name), b.get(name), f"{prefix}{name}.")]
    return [] if a == b else [prefix.rstrip(".")]


#: What :func:`_at` gives for a dotted key a table does not hold.
_MISSING = object()


def _at(table: dict, dotted: str):
    """The value of the dotted key ``dotted`` in the nested ``table``, or :data:`_MISSING`."""
    for part in dotted.split("."):
        if not isinstance(table, dict) or part not in table:
            return _MISSING
        table = table[part]
    return table


def _has(table: dict, dotted: str) -> bool:
    return _at(table, dotted) is not _MISSING


def _away_from_default(current: dict, defaults: dict, dotted: str) -> bool:
    """Whether the option ``dotted`` of the resolved config ``current`` holds another value than its default
    (``defaults``, :meth:`Model._option_defaults`; an option unset in ``current`` holds None).  A key of no
    piece's options (a table added since) is taken to be at its default, as before."""
    default = _at(defaults, dotted)
    if default is _MISSING:
        return False
    value = _at(current, dotted)
    return (None if value is _MISSING else value) != config_.as_toml_reads_it(default)


def _as_list(value, where: str) -> list[str]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) and v.strip() for v in value) or not value:
        raise ConfigError(f"{where} must be a non-empty list of names, got {value!r}")
    for name in value:
        if value.count(name) > 1:
            raise ConfigError(f"{where} lists '{name}' twice; each physics module joins a model once")
    return list(value)


def _kind(value) -> str:
    """What a value given in the place of a table is, in a few words: a class or an object by its type's name
    (a kinetics class, a meshio.Mesh), anything else by its repr, shortened."""
    if isinstance(value, type):
        return f"the class {value.__module__}.{value.__qualname__}"
    if isinstance(value, (str, int, float, bool, list, tuple, dict, type(None))):
        text = repr(value)
        return text if len(text) <= 80 else text[:77] + "..."
    return f"a {type(value).__module__}.{type(value).__qualname__} object"


def _path(value, where: str) -> Path:
    """A folder given as a str or a path-like object; anything else was a TypeError from inside pathlib."""
    if not isinstance(value, (str, os.PathLike)):
        raise ConfigError(f"{where} must be a folder (a str or a pathlib.Path), got {_kind(value)}")
    return Path(value)


def _text(value, where: str) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{where} must be a string, got {value!r}")
    return value


def _backend_name(value, where: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(f"{where} must name a backend (e.g. \"fenicsx\" or \"skfem\"), got {value!r}")
    return value


def _adaptivity(adaptive, dt_min, dt: float, latest: float) -> tuple[bool, float]:
    """(time.adaptive, time.dt_min): whether failed steps are retried smaller, and down to which dt.

    ``latest`` is the largest |t| of the run: a try shorter than 2^-40 of it barely moves t (at 2^-53, not at
    all), so a failing step was halved a thousand times for dt_min = 1e-300.  The default, dt / 2^10, stays
    allowed (it is written in config.toml, which a restart reads).
    """
    adaptive = flag(adaptive, "time.adaptive")
    default = dt / 2 ** DEFAULT_HALVINGS
    if dt_min is None:
        return adaptive, default
    dt_min = float(number(dt_min, "time.dt_min", above=0, at_most=dt, hint=f"at most time.dt = {dt:g}"))
    resolution = 2.0 ** -40 * latest
    if dt_min < min(resolution, default):
        raise ConfigError(f"time.dt_min = {dt_min:g} is below what the run's time can tell apart (2^-40 |t| = "
                          f"{resolution:.3g} at t = {latest:g}): a step that short leaves t unchanged")
    return adaptive, dt_min


def _checkpoint(table) -> dict:
    """The ``[checkpoint]`` table with its defaults, checked."""
    if table is None:
        table = {}
    if not isinstance(table, dict):
        raise ConfigError(f"[checkpoint] must be a table (every_steps, every_minutes), got {table!r}")
    unknown = set(table) - set(DEFAULT_CHECKPOINT)
    if unknown:
        raise ConfigError(f"unknown key checkpoint.{sorted(unknown)[0]} (known: {', '.join(DEFAULT_CHECKPOINT)})")
    checkpoint = {**DEFAULT_CHECKPOINT, **table}
    steps = number(checkpoint["every_steps"], "checkpoint.every_steps", integer=True, at_least=0,
                   hint="0: never by steps")
    minutes = number(checkpoint["every_minutes"], "checkpoint.every_minutes", at_least=0, hint="0: never by time")
    return {"every_steps": steps, "every_minutes": float(minutes)}


def _kinetics_table(kinetics, physics_classes) -> dict | None:
    if not any(cls.needs_kinetics for cls in physics_classes):
        if kinetics:
            raise ConfigError("[kinetics] is given but no physics module of this model uses reaction kinetics")
        return None
    if kinetics is None:
        return {"name": "painter2018"}
    if isinstance(kinetics, str):
        return {"name": kinetics}
    if not isinstance(kinetics, dict):
        raise ConfigError(f"[kinetics] must be a table with a name (in Python: kinetics=\"painter2018\" or "
                          f"{{\"name\": ..., options}}), got {_kind(kinetics)}")
    table = {"name": "painter2018", **kinetics}
    if not isinstance(table["name"], str):
        raise ConfigError(f"kinetics.name must be the name of a kinetics, got {table['name']!r}")
    return table


def _growth_law_table(growth_law, physics_classes) -> dict | None:
    """The ``[growth_law]`` table (name + options) when a module needs one; refused when none does."""
    needing = [cls.name for cls in physics_classes if cls.needs_growth_law]
    if not needing:
        if growth_law:
            raise ConfigError("[growth_law] is given but no physics module of this model grows "
                              "(add poroelastic_growth to model.physics)")
        return None
    if growth_law is None:
        from primordia.core.plugins import registry

        known = ", ".join(sorted(registry("growth_laws"))) or "none"
        raise ConfigError(f"physics {needing[0]} needs a growth law: add [growth_law] name = \"...\" "
                          f"(registered: {known})")
    if isinstance(growth_law, str):
        return {"name": growth_law}
    if not isinstance(growth_law, dict) or "name" not in growth_law:
        raise ConfigError(f"[growth_law] must be a table with a name (e.g. name = \"seed2d\"; in Python: "
                          f"growth_law=\"seed2d\" or {{\"name\": ..., options}}), got {_kind(growth_law)}")
    if not isinstance(growth_law["name"], str):
        raise ConfigError(f"growth_law.name must be the name of a growth law, got {growth_law['name']!r}")
    return dict(growth_law)


def _on_the_step_grid(start: float, end: float, dt: float) -> bool:
    """Whether the span from ``start`` to ``end`` is a whole number of steps of ``dt``, at least one, to round-off.

    A span of less than half a step was within the tolerance of 0 steps (such a run "completed" at t_start);
    the tolerance was 1e-9 of the steps, which let t_final = 520.0000001 with dt = 0.2 through (5e-7 of a
    step, the last step solved with dt). It is now 1e-12 of the steps and of the times' size in steps (the
    subtraction's round-off: t_start = 1e6, dt = 0.1).
    """
    steps = (end - start) / dt
    return round(steps) >= 1 and abs(steps - round(steps)) <= 1e-12 * (abs(steps) + max(abs(start), abs(end)) / dt)


def _time(t_start, dt, t_final) -> tuple[float, float, float]:
    from primordia.core.outputs import time_label  # %g: "t_final - t_start = 520" for t_final = 520.0001

    t_start, dt = number(t_start, "time.t_start"), number(dt, "time.dt", above=0)
    t_final = number(t_final, "time.t_final")
    if t_final <= t_start:
        raise ConfigError(f"time.t_final ({time_label(t_final)}) must be greater than time.t_start "
                          f"({time_label(t_start)})")
    steps = (t_final - t_start) / dt
    if not math.isfinite(steps) or steps > MAX_STEPS:
        raise ConfigError(f"time.dt = {dt:g} gives {steps:.3g} steps from t_start = {t_start:g} to t_final = "
                          f"{t_final:g}, more than {MAX_STEPS:,}: is dt in the model's (dimensionless) time units?")
    if not _on_the_step_grid(t_start, t_final, dt):
        span = time_label(t_final) if t_start == 0 else f"{time_label(t_final)} - {time_label(t_start)}"
        raise ConfigError(f"time.t_final - time.t_start = {span} is not a multiple of dt = {time_label(dt)}")
    return float(t_start), float(dt), float(t_final)
