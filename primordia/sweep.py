"""Parameter sweeps: an ensemble of runs on a dask.distributed cluster, gathered into one Dataset.

    primordia sweep CONFIG.toml --vary parameters.alpha=2:8:7 --vary parameters.m0=0.5:1.5:5
                    [--seeds N] [--set SECTION.KEY=VALUE ...] [--scheduler ADDRESS] [--workers N]
                    [--timeout SECONDS] [--out DIR] [--no-progress]

Each combination of the varied values (and of the seeds 1..N of the random initial
perturbation, ``physics.chemotaxis.seed``) is one run, in its own folder
``OUT/runs/alpha=2_m0=0.5_seed=1/``: the run directory of ``primordia run``, its
pattern metrics ``metrics.nc`` (:mod:`primordia.analysis.patterns`), ``run.log`` (what
the run printed) and ``sweep.json`` (status, reason, wall time).  ``OUT/sweep.nc``
gathers them into one xarray Dataset whose dimensions are the varied keys (and
``seed``), then time, configuration and species; ``OUT/sweep_map.png`` draws the
simulated patterning map over two varied parameters with the linear analysis's
boundary and predicted wavelength over it.

* The runs go to a dask.distributed cluster: a local one with ``--workers`` processes
  (default: one per core), or the one whose scheduler is at ``--scheduler ADDRESS``.
  The configuration and ``OUT`` must then be on a file system the workers share.
* Each run is ``primordia run`` in a subprocess of its worker: a crash (a segfault in
  PETSc, memory exhaustion) or a hang (``--timeout``) ends that run only, PETSc's option
  database and MPI are fresh for every run (MPI starts as a singleton: the variables of
  an enclosing ``mpirun`` are not passed on), and the worker stays healthy for the next run.
* A run that fails is recorded (``status`` = "failed" and ``reason`` in the Dataset, and
  its metrics at the output times it reached, if it wrote any: a time-out's, a divergence's),
  not fatal (when none completes, the command ends in one line, exit status 2, after
  writing them).  Running the same command again skips every run already done (completed,
  with its metrics, from the same configuration and overrides) and retries the others.
* Mistakes in the command (malformed ``--vary``, unknown key or parameter, missing
  config, a backend no run can use) are one-line errors before anything runs; a value
  a run rejects (e.g. a negative diffusivity) fails that run only.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import itertools
import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from primordia.core.config import apply_overrides, load_config, parse_assignment
from primordia.core.errors import ConfigError, PrimordiaError, one_line, warn
from primordia.core.validation import is_number, number

#: The option that seeds the random initial perturbation (``--seeds``).
SEED_KEY = "physics.chemotaxis.seed"
DATASET_FILE = "sweep.nc"
PICTURE_FILE = "sweep_map.png"
RECORD_FILE = "sweep.json"
LOCK_FILE = ".sweep.lock"
#: The most runs one sweep makes: beyond it, a typo (``alpha=1:5:100000000``) filled the memory
#: with the runs' names (1 GB per million) before a word was said.
MAX_RUNS = 100_000
#: Seconds to wait for the dask scheduler of ``--scheduler`` to answer.
SCHEDULER_TIMEOUT = 20.0


@dataclass(frozen=True)
class Axis:
    """One varied configuration key and its values."""

    key: str  #: dotted config key, e.g. "parameters.alpha"
    values: tuple

    @classmethod
    def parse(cls, text: str) -> "Axis":
        """``"section.key=LO:HI:N"``: N values from LO to HI (integers if LO and HI are written as integers)."""
        key, sep, spec = str(text).partition("=")
        key = key.strip()
        parts = spec.split(":")
        if not sep or len(key.split(".")) < 2 or not all(key.split(".")) or len(parts) != 3:
            raise ConfigError(f"--vary expects SECTION.KEY=LO:HI:N (e.g. parameters.alpha=2:8:7), got {text!r}")
        try:
            low, high, count = float(parts[0]), float(parts[1]), int(parts[2])
        except ValueError:
            raise ConfigError(f"--vary {text}: LO and HI must be numbers and N an integer") from None
        if count < 1 or (count == 1 and low != high) or not (np.isfinite(low) and np.isfinite(high)):
            raise ConfigError(f"--vary {text}: need N >= 1 finite values (N = 1 only with LO = HI)")
        if count > MAX_RUNS:
            raise ConfigError(f"--vary {text}: N = {count} values, more runs than a sweep makes ({MAX_RUNS})")
        if low > high:  # as stability map's axes: the sweep's coordinates and map axes increase
            raise ConfigError(f"--vary {text}: LO must not exceed HI (the values go from LO up to HI)")
        if count > 1 and low == high:  # N copies of one run, all writing into one folder
            raise ConfigError(f"--vary {text}: LO = HI repeats one value {count} times (N = 1 runs it once)")
        values = np.linspace(low, high, count)
        if _is_integer(parts[0]) and _is_integer(parts[1]) and np.allclose(values, np.round(values)):
            return cls(key, tuple(int(round(v)) for v in values))
        return cls(key, tuple(float(v) for v in values))

    @property
    def name(self) -> str:
        """The Dataset dimension: the parameter's name for ``parameters.*``, else the whole key."""
        return self.key.removeprefix("parameters.")

    @property
    def labels(self) -> tuple[str, ...]:
        """The values as run folder names write them: ``%g``, with more digits where ``%g`` would
        give two values one name (4 and 4.0000005, 3000000 and 3000001) and so one folder."""
        for digits in range(6, 18):
            labels = tuple(f"{value:.{digits}g}" for value in self.values)
            if len(set(labels)) == len(labels):
                return labels
        return tuple(repr(value) for value in self.values)


def _is_integer(text: str) -> bool:
    try:
        int(text.strip())
    except ValueError:
        return False
    return True


def _checked_pieces(axes, fixed, seeds) -> tuple[tuple, tuple, tuple]:
    """A Sweep's axes, fixed overrides and seeds as tuples, or one line: a lone Axis or string, or a count of
    seeds, was a TypeError or read letter by letter ("--set expects section.key=value, got 'm'"), and a seed
    given twice (or as True or "1") made runs that wrote into one folder or failed one by one."""
    def pieces(value, kind, what: str, example: str) -> tuple:
        if isinstance(value, (str, kind)) or not isinstance(value, Sequence) or not all(
                isinstance(piece, kind) and not isinstance(piece, bool) for piece in value):
            raise ConfigError(f"Sweep {what} must be a tuple of {kind.__name__}, e.g. {what}={example}, got {value!r}")
        return tuple(value)

    axes = pieces(axes, Axis, "axes", '(Axis.parse("parameters.alpha=2:8:7"),)')
    fixed = pieces(fixed, str, "fixed", '("mesh.cells=[43,43]",)')
    seeds = pieces(seeds, int, "seeds", "(1, 2, 3) (what --seeds 3 runs)")
    for axis in axes:
        if not all(is_number(value) for value in axis.values) or len(set(axis.labels)) != len(axis.values):
            raise ConfigError(f"Sweep axis {axis.key} must have distinct numbers as values, got {axis.values!r}")
    if min(seeds, default=0) < 0 or len(set(seeds)) != len(seeds):
        raise ConfigError(f"Sweep seeds must be distinct integers >= 0 (each a run of its own), got {seeds!r}")
    return axes, fixed, seeds


@dataclass(frozen=True)
class Point:
    """One run of the sweep."""

    index: tuple[int, ...]  #: position along each dimension of the Dataset
    overrides: tuple[str, ...]  #: the --set assignments of this run (fixed ones first)
    directory: Path
    fingerprint: str  #: what makes a finished run reusable: the configuration it runs (:func:`_fingerprint`)
    #: the fingerprint sweeps wrote before 2026-12-05 (the config's text and the overrides as written): a run
    #: they completed is still taken as done
    written_fingerprint: str = ""


@dataclass
class Sweep:
    """A configuration, fixed overrides, the varied axes and the seeds; validated on construction."""

    config: Path
    axes: tuple[Axis, ...]
    seeds: tuple[int, ...] = ()
    fixed: tuple[str, ...] = ()
    out: Path | None = None  #: default out/sweep_<config name>, as the command's
    config_text: str = field(init=False, repr=False)  #: the configuration file as read, for earlier fingerprints
    given: dict = field(init=False, repr=False)  #: what every run is given (the file, the fixed --set), by value
    base_config: dict = field(init=False, repr=False)  #: resolved configuration with the fixed overrides
    inert_settings: list = field(init=False, repr=False)  #: what the runs leave without effect (Model.inert_settings)
    #: per dimension, its coordinate's values and attributes in sweep.nc (:func:`_coordinate`)
    coordinates: dict = field(init=False, repr=False)

    def __post_init__(self):
        from primordia.model import Model

        self.config = Path(self.config)
        if isinstance(self.out, str) and not self.out.strip():  # Path("") is the current directory
            raise ConfigError("a sweep's out needs a directory name")
        self.out = Path(self.out) if self.out is not None else Path("out") / f"sweep_{self.config.stem}"
        self.axes, self.fixed, self.seeds = _checked_pieces(self.axes, self.fixed, self.seeds)
        if not self.axes:
            raise ConfigError("sweep needs at least one --vary SECTION.KEY=LO:HI:N")
        runs = int(np.prod([len(values) for _, values in self.dimensions], dtype=float))
        if runs > MAX_RUNS:
            raise ConfigError(f"the sweep would make {runs} runs, more than a sweep makes ({MAX_RUNS})")
        keys = self.keys
        if len(set(keys)) != len(keys):
            twice = sorted({k for k in keys if keys.count(k) > 1})
            raise ConfigError(f"a key is varied twice: {', '.join(twice)}"
                              + (" (--seeds varies it)" if SEED_KEY in twice else ""))
        table = apply_overrides(load_config(self.config), list(self.fixed))  # missing config, bad --set: one line
        model = Model.from_config(table)
        for text in self.fixed:  # a --set the --vary would override without a word
            for key in set(_assigned_keys(text)) & set(keys):
                raise ConfigError(f"{key} is both fixed (--set {text}) and varied "
                                  f"({'--seeds' if key == SEED_KEY else '--vary'}): drop one of them")
        from primordia.core.outputs import directory_problem

        for directory in (self.out, self.out / "runs"):  # before any worker fails to make its run's folder
            problem = directory_problem(directory)
            if problem is not None:
                raise ConfigError(problem)
        resolved = model.resolved_config()
        for key in keys:
            if key.startswith("parameters.") and key.count(".") == 1:
                model.parameters.declaration(key.split(".", 1)[1])  # unknown parameter, with suggestions
                continue
            value = _lookup(resolved, key)
            if not is_number(value):
                raise ConfigError(f"--vary {key}: not a number of the resolved configuration of {self.config}"
                                  + (" (--seeds needs physics = [\"chemotaxis\", ...])" if key == SEED_KEY else ""))
        self.config_text = self.config.read_text()
        self.given = _by_value(table)  # the fingerprints' (see _fingerprint)
        self.base_config = resolved
        self.inert_settings = model.inert_settings + _inert_axes(model, keys)  # said once the runs' check passed
        self.coordinates = {name: _coordinate(model, resolved, key, values)
                            for key, (name, values) in zip(keys, self.dimensions)}

    @property
    def keys(self) -> list[str]:
        """The varied config keys, the seed's last."""
        return [axis.key for axis in self.axes] + ([SEED_KEY] if self.seeds else [])

    @property
    def dimensions(self) -> list[tuple[str, tuple]]:
        """(name, values) of every Dataset dimension of the sweep, seeds last."""
        dims = [(axis.name, axis.values) for axis in self.axes]
        return dims + ([("seed", self.seeds)] if self.seeds else [])

    def points(self) -> list[Point]:
        keys, ranges = self.keys, [values for _, values in self.dimensions]
        labels = [axis.labels for axis in self.axes] + ([tuple(str(seed) for seed in self.seeds)] if self.seeds else [])
        paths = [parse_assignment(f"{key}=0")[0] for key in keys]  # as --set reads the key ("a"."b" is a.b)
        points = []
        for index in itertools.product(*(range(len(values)) for values in ranges)):
            values = [ranges[d][i] for d, i in enumerate(index)]
            assignments = tuple(f"{key}={value!r}" for key, value in zip(keys, values))
            name = "_".join(f"{dim}={labels[d][i]}" for d, ((dim, _), i) in enumerate(zip(self.dimensions, index)))
            overrides = tuple(self.fixed) + assignments
            written = hashlib.sha256("\n".join((self.config_text, *overrides)).encode()).hexdigest()[:16]
            points.append(Point(index, overrides, self.out / "runs" / name,
                                _fingerprint(self.given, sorted(zip(paths, map(float, values)))), written))
        return points


def _fingerprint(given: dict, varied: list) -> str:
    """A digest of the configuration a run is given, not of how the command wrote it: ``given``, its file as TOML
    reads it with the --set values applied (:func:`_by_value`), and ``varied``, its [key path, value] pairs
    (the --vary and --seeds values, in key order).  ``--set a=1`` and ``--set a=1.0``, ``--vary alpha=1:5:2`` and
    ``1.0:5.0:2``, --set flags in another order, or a comment in the file ran every point again.  The file's
    folder (``_base_dir``, resolved: a relative or an absolute path to it is one) is part of it, since a relative
    mesh path names another file from another folder: the text alone took runs on another mesh for done.  Not
    the resolved config with its defaults: making each point's model cost 0.37 s at example 1a's 171 x 171 (its
    mesh), and :meth:`Sweep.points` is asked more than once per sweep.  A default written out is another
    fingerprint, so such a point is run again, never a run of another model taken as done."""
    text = json.dumps([given, varied], sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _by_value(value):
    """A configuration with every number a float (compared by value, as a restart compares a checkpoint's config,
    ``Model.differences``), tables with string keys, anything else TOML holds (a date) as its text."""
    if isinstance(value, dict):
        return {str(key): _by_value(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_by_value(item) for item in value]
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    return value if isinstance(value, (str, bool)) or value is None else str(value)


def _inert_axes(model, keys: list[str]) -> list[str]:
    """One line per varied physics option the model's other settings leave without effect (``--seeds`` under
    perturbation_shape = "cosine": every seed was the same run).  Only where no other varied key is an option of
    the same module, since the others' values may give it its effect at some points."""
    told = []
    for key in keys:
        section, name, option = (key.split(".") + ["", ""])[:3]
        module = next((m for m in model.physics_objects if section == "physics" and m.name == name), None)
        if module is None or key.count(".") != 2 or any(other != key and other.startswith(f"physics.{name}.")
                                                        for other in keys):
            continue
        why = module.inert_options(model.physics_objects, model.mesh_data.gdim, model.solver).get(option)
        if why is not None:
            flag = "--seeds" if key == SEED_KEY else f"--vary {key}"
            told.append(f"{flag} varies {key}, which has no effect: {why}; the runs differ in nothing else")
    return told


def _coordinate(model, resolved: dict, key: str, values: tuple) -> tuple[np.ndarray, dict]:
    """The values of a varied key as sweep.nc's coordinate, and its attributes: a model parameter's description
    and units (as patterning_*.nc gives them), another key's name.  A parameter, or a key whose resolved value is
    a float, is a float coordinate: ``alpha=2:6:2`` was stored as int32 (the values as ``--vary`` wrote them),
    another type than ``alpha=2.0:6.0:2`` for the same floats the runs were given."""
    if key.startswith("parameters.") and key.count(".") == 1:
        attrs = {"long_name": model.parameters.declaration(key.split(".", 1)[1]).description,
                 "units": "1"}  # the seed's dimensionless parameters (seed section 2)
        return np.asarray(values, dtype=float), attrs
    if key == SEED_KEY:
        attrs = {"long_name": f"seed of the random initial perturbation ({SEED_KEY})"}
    else:
        attrs = {"long_name": f"the configuration's {key}"}
    return np.asarray(values, dtype=float if isinstance(_lookup(resolved, key), float) else None), attrs


def _assigned_keys(text: str) -> list[str]:
    """The dotted config keys a ``--set`` assignment sets (an inline table sets each of its keys)."""
    path, value = parse_assignment(text)

    def leaves(prefix: list[str], value) -> list[str]:
        if isinstance(value, dict):
            return [key for name, item in value.items() for key in leaves([*prefix, str(name)], item)]
        return [".".join(prefix)]

    return leaves(path, value)


def _lookup(table: dict, key: str):
    for part in key.split("."):
        if not isinstance(table, dict) or part not in table:
            return None
        table = table[part]
    return table


def is_done(point: Point) -> bool:
    """A run directory with its metrics, completed from the same configuration and overrides."""
    record = _read_record(point.directory)
    return (record.get("status") == "completed"
            and record.get("fingerprint") in {point.fingerprint, point.written_fingerprint} - {""}
            and _has_metrics(point.directory))


def _has_metrics(directory: Path) -> bool:
    """Whether ``directory``'s metrics.nc reads, with every variable :func:`gather` takes from it.

    A metrics.nc that did not (truncated, written by another version) failed every later
    sweep of the same command in gather, with a traceback, where running that point again mends it.
    """
    import xarray as xr

    from primordia.analysis.patterns.run import METRICS_FILE, SCALAR_METRICS

    needed = {name for name, _, _ in SCALAR_METRICS} | {"pattern", "time", "configuration", "species"}
    try:
        with xr.open_dataset(directory / METRICS_FILE, engine="scipy") as metrics:
            return needed <= set(metrics.variables)
    except Exception:  # noqa: BLE001 - missing, unreadable, not NetCDF: the run is done again
        return False


def _read_record(directory: Path) -> dict:
    try:
        return json.loads((directory / RECORD_FILE).read_text())
    except (OSError, ValueError):
        return {}


def execute(config: str, overrides: Sequence[str], directory: str, fingerprint: str,
            timeout: float | None = None, sweep: str | None = None) -> dict:
    """Run one point (in a dask worker): ``primordia run`` in a subprocess, then its pattern metrics.

    A point whose folder holds a checkpoint (its run was interrupted: the sweep stopped, a worker
    was lost, a time limit) goes on from it (``--restart``) instead of starting again; a
    checkpoint of another model (the sweep's config or overrides changed) is replaced by a run
    from the start.  Returns and writes ``sweep.json``: status ("completed" or "failed"),
    reason, wall time.  Never raises for a failed run.  ``sweep``: a token of the sweep that asks; once
    that sweep is interrupted (:func:`stop_runs`), its points not yet started are not started.
    """
    if sweep is not None and sweep in _STOPPED:
        return {"status": "failed", "reason": NOT_STARTED, "fingerprint": fingerprint}
    import dask

    from primordia.analysis.patterns.run import METRICS_FILE, analyse_run
    from primordia.core.atomic_files import atomic_write_text

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    for stale in (RECORD_FILE, METRICS_FILE):
        (directory / stale).unlink(missing_ok=True)
    command = [sys.executable, "-m", "primordia.cli", "run", str(config), "--no-progress"]
    for assignment in overrides:
        command += ["--set", assignment]
    start = time.perf_counter()
    summary = _file_bytes(directory / "summary.json")
    log, reason = _resume_or_run(command, directory, timeout, sweep)
    atomic_write_text(directory / "run.log", log)
    measured = False
    # a failed run's outputs when they are its own: it wrote its summary.json.  One refused at its start (a --set
    # its checkpoint's restart or its config refuses) left the folder's earlier run, whose fields.xdmf (of another
    # configuration) was measured and recorded as this point's
    if not reason or ((directory / "fields.xdmf").is_file() and _file_bytes(directory / "summary.json") != summary):
        try:
            # dask's own scheduler: in a worker, xarray would lock metrics.nc with a dask.distributed
            # Lock through the cluster's scheduler (and a client it opens for it), and fail, with the
            # run done, when the sweep stops (Ctrl-C) while the run is measured.  The run's folder is
            # its own: no other process writes there.
            with dask.config.set(scheduler="synchronous"):
                analyse_run(directory, pictures=False)
            measured = True
        except Exception as error:  # noqa: BLE001 - a failed analysis is recorded like a failed run
            # a failed run is measured at the output times it reached (a time-out's, a divergence's), when it
            # wrote any: what it failed of stays its reason
            reason = reason or f"pattern metrics: {type(error).__name__}: {error}"
    return _record(directory, fingerprint, overrides, reason, start, measured)


def _file_bytes(path: Path) -> bytes | None:
    """The contents of ``path``, None if it cannot be read."""
    try:
        return path.read_bytes()
    except OSError:
        return None


def check_runs(config: str, overrides: Sequence[str], directory: str) -> str:
    """Why every run of the sweep would fail, or "": ``primordia run --dry-run`` with the fixed overrides, in a
    worker of an external cluster (whose backends are the runs'), or in the sweep's process for a local one.

    The sweep checks the configuration itself, but not the backend and the splitting scheme a plugin chooses
    for a run, nor the solver options: ``--set model.backend=nope`` ran and failed every run, and the sweep
    ended with exit status 0.
    """
    environment = _run_environment()
    command = [sys.executable, "-m", "primordia.cli", "run", config, "--dry-run", "--out", directory]
    for assignment in overrides:
        command += ["--set", assignment]
    result = subprocess.run(command, capture_output=True, text=True, env=environment)
    return _failure_reason(result.returncode, result.stderr, Path(directory))


def _refuse_if_every_run_fails(problem: str) -> None:
    if problem:
        raise ConfigError(f"every run of the sweep would fail: {problem}")


def _run_environment() -> dict[str, str]:
    """The environment of a ``primordia run`` the sweep starts: this process's without the MPI launcher's variables
    (the run is serial, not a rank of a job; a user's own ``OMPI_MCA_`` settings stay) nor the mark of a worker
    starting (the run takes a Ctrl-C)."""
    from primordia.core.launcher import without_launcher

    return {k: v for k, v in without_launcher(os.environ).items() if k != WORKER_STARTING}


#: The runs this (worker) process has going, by directory: what :func:`stop_runs` asks to stop.
_RUNNING: dict[str, subprocess.Popen] = {}
_RUNNING_LOCK = threading.Lock()
#: The sweeps (their tokens) that were interrupted: their points not started yet are not started.
_STOPPED: set[str] = set()


#: Why a point of an interrupted sweep has no run.
NOT_STARTED = "not started: the sweep was interrupted"


def _run_point(command: list[str], directory: Path, timeout: float | None,
               sweep: str | None = None) -> tuple[str, str]:
    """(its output, why it failed or "") of ``primordia run`` in a subprocess, killed with its worker; not started
    once ``sweep`` (its token) is interrupted.

    The check and the start are one step under :data:`_RUNNING_LOCK`, as :func:`stop_runs` is: a run started
    between the point's check at its start and the run's registration was neither refused nor asked to stop,
    and the interrupted sweep waited for it to end (up to :data:`STOP_GRACE`), whatever it took.
    """
    environment = _run_environment()
    command = _dying_with_its_parent(command)
    with _RUNNING_LOCK:
        if sweep is not None and sweep in _STOPPED:
            return "", NOT_STARTED
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                   env=environment)
        _RUNNING[str(directory)] = process
    try:
        try:
            stdout, stderr = process.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            stdout, stderr = process.communicate()
            return stdout + stderr, f"timed out after {timeout:g} s"
    finally:
        with _RUNNING_LOCK:
            _RUNNING.pop(str(directory), None)
    return stdout + stderr, _failure_reason(process.returncode, stderr, directory)


def stop_runs(sweep: str | None = None) -> int:
    """Ask every run this process has going to stop (SIGTERM: each finishes its step, writes its checkpoint
    and says "interrupted"), and start no more points of ``sweep`` (its token); how many were asked.  Run
    on every worker when a sweep is interrupted: a run on another machine hears no Ctrl-C, and a local
    one would be killed with its worker."""
    import signal

    with _RUNNING_LOCK:
        if sweep is not None:
            _STOPPED.add(sweep)
        running = [process for process in _RUNNING.values() if process.poll() is None]
    for process in running:
        with contextlib.suppress(ProcessLookupError):
            process.send_signal(signal.SIGTERM)
    return len(running)


#: What ``primordia run --restart`` says when the checkpoint is not this point's model (then run from the start).
ANOTHER_RUN = ("differs from the checkpointed run's", "it was written on backend", "cannot restart from")


def _resume_or_run(command: list[str], directory: Path, timeout: float | None,
                   sweep: str | None = None) -> tuple[str, str]:
    """(log, why it failed or "") of the point's run: continued from its checkpoint if its folder holds one of
    this model (an interrupted run), else from the start (none once ``sweep`` is interrupted)."""
    from primordia.core.checkpoint import CHECKPOINT_FILE

    fresh = [*command, "--out", str(directory), "--overwrite"]
    if not (directory / CHECKPOINT_FILE).is_file():
        return _run_point(fresh, directory, timeout, sweep)
    log, reason = _run_point([*command, "--restart", str(directory)], directory, timeout, sweep)
    if not reason or not any(text in log for text in ANOTHER_RUN):
        return log, reason
    again, reason = _run_point(fresh, directory, timeout, sweep)
    return f"{log}\n[the checkpoint could not be continued: the point is run from the start]\n{again}", reason


def _record(directory: Path, fingerprint: str, overrides: Sequence[str], reason: str, start: float,
            measured: bool = False) -> dict:
    """``sweep.json`` of a point: status, reason, fingerprint, wall time, whether its metrics.nc is this run's
    (written, and returned)."""
    from primordia.core.json_toml import write_json

    record = {"status": "failed" if reason else "completed", "reason": reason, "fingerprint": fingerprint,
              "wall_time_s": time.perf_counter() - start, "overrides": list(overrides), "metrics": measured}
    write_json(directory / RECORD_FILE, record)
    return record


def _dying_with_its_parent(command: list[str]) -> list[str]:
    """``command`` run by ``setpriv --pdeathsig KILL`` (util-linux), so that the kernel kills the run when the
    worker thread that started it dies; ``command`` itself where there is no setpriv.

    A worker killed (SIGKILL, out of memory) left its ``primordia run`` going on, reparented to init:
    it kept a core busy, and the run dask retried on another worker failed at once on the
    directory's "run in progress".  The run is killed rather than asked to stop: a killed run's
    directory is one that ``--overwrite`` clears at once.  setpriv sets the signal and execs the run
    (same process); a ``preexec_fn`` doing it would run Python between fork and exec in a worker
    with several threads, which subprocess documents as unsafe.
    """
    setpriv = shutil.which("setpriv") if sys.platform.startswith("linux") else None
    return [setpriv, "--pdeathsig", "KILL", "--", *command] if setpriv else list(command)


def _failure_reason(returncode: int, stderr: str, directory: Path) -> str:
    """Why ``primordia run`` failed, in one line ("" if it completed)."""
    if returncode == 0:
        return ""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    for line in lines:
        if line.startswith("primordia: error: "):
            return line.removeprefix("primordia: error: ")
    for line in reversed(lines):  # "primordia: interrupted at t = ...": the run's own word, not what followed it
        if line.startswith("primordia: ") and not line.startswith("primordia: warning: "):
            return line
    try:
        status = json.loads((directory / "summary.json").read_text()).get("status", "")
    except (OSError, ValueError):
        status = ""
    if status.startswith("stopped"):
        return status
    if returncode < 0:
        return f"killed by signal {-returncode}"
    return lines[-1] if lines else f"exit status {returncode}"


@contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, timeout: float | None = None):
    """A dask.distributed Client: of the cluster at ``scheduler`` (which must answer within ``timeout``
    seconds, default :data:`SCHEDULER_TIMEOUT`), or of a local cluster of ``workers`` processes."""
    import logging

    from dask.distributed import Client, LocalCluster

    if scheduler:
        timeout = SCHEDULER_TIMEOUT if timeout is None else timeout
        _check_scheduler(scheduler, timeout)
        try:
            client = Client(scheduler, timeout=f"{timeout:g}s")
        except Exception as error:  # noqa: BLE001 - gone between the check and the client: one line
            raise ConfigError(f"cannot reach the dask scheduler at {scheduler}: {one_line(error)}") from None
        with client:
            if not client.scheduler_info().get("workers"):  # dask waits for one, silently, as long as it takes
                warn(f"the dask scheduler at {scheduler} has no workers yet: the runs wait until one joins")
            else:
                _check_workers_primordia(client)
            yield client
        return
    # the scheduler's HTTP routes on any free loopback port (None would mean port 8787, and a warning if taken)
    # preload: Ctrl-C is the sweep's to handle (see dask_setup); logs below CRITICAL silenced: a worker's heartbeat
    # racing the cluster's closing (a Ctrl-C, a refusal) was logged as an ERROR with its traceback on stderr
    with contextlib.ExitStack() as stack:
        started = _workers_starting(stack)
        try:
            cluster = stack.enter_context(LocalCluster(
                n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                dashboard_address="127.0.0.1:0", silence_logs=logging.CRITICAL, preload=[__name__]))
            client = stack.enter_context(Client(cluster))
        except Exception:
            if started.came:  # a worker the Ctrl-C reached before it could leave it to the sweep: "Nanny failed"
                raise KeyboardInterrupt from None
            raise
        started()
        yield client


#: Set while the local cluster starts: a worker process importing primordia (the sweep's main module, which
#: multiprocessing's spawn imports before anything else) leaves a Ctrl-C to the sweep from its first line.
WORKER_STARTING = "PRIMORDIA_SWEEP_WORKER_STARTING"


def _workers_starting(stack: contextlib.ExitStack):
    """Hold a Ctrl-C back from the local cluster's start, until the returned function is called: it raises the
    KeyboardInterrupt then, if one came (``stack`` closes the cluster and restores the handler).

    A Ctrl-C in the cluster's first seconds reached workers still importing primordia, before their preload
    (:func:`dask_setup`) was in place: they died of it, and dask's start and close, interrupted, printed
    40-110 lines of tracebacks. A spawned worker inherits neither a handler (reset by exec) nor a blocked
    SIGINT (spawn resets the mask), and ignoring SIGINT here lost the sweep's own Ctrl-C (a C library's
    thread took it); a worker inherits its environment, which ``primordia/__init__`` reads, and this
    process records the Ctrl-C and raises it once the cluster is whole.
    """
    import signal

    def started():
        os.environ.pop(WORKER_STARTING, None)
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
            if started.came and previous is not signal.SIG_IGN:
                raise KeyboardInterrupt

    os.environ[WORKER_STARTING] = "1"
    stack.callback(os.environ.pop, WORKER_STARTING, None)
    started.came, previous = [], None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGINT, lambda signum, frame: started.came.append(signum))
        stack.callback(signal.signal, signal.SIGINT, previous)
    return started


def primordia_identity() -> tuple[str, str]:
    """(where primordia is imported from, a digest of its source files): what a worker runs."""
    import primordia

    root = Path(primordia.__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return str(root), digest.hexdigest()[:12]


def _check_workers_primordia(client) -> None:
    """One warning per worker of an external cluster that imports no primordia, or another one than this
    process (another checkout or version): its runs would fail, or differ from this one's."""
    here = primordia_identity()
    answers = client.run(primordia_identity, on_error="return")
    for worker, answer in sorted(answers.items()):
        if isinstance(answer, BaseException):
            warn(f"dask worker {worker} cannot run primordia ({one_line(answer)}): its runs will fail")
        elif tuple(answer)[1] != here[1]:
            warn(f"dask worker {worker} runs another primordia ({answer[0]}, sources {answer[1]}) than this "
                 f"sweep ({here[0]}, sources {here[1]}): its runs may differ")


def _check_scheduler(address: str, timeout: float | None = None) -> None:
    """A ConfigError (one line) unless a dask scheduler answers at ``address`` within ``timeout`` seconds.

    ``Client(address, timeout=...)`` raised a bare ValueError or TypeError for a malformed
    address ("nonsense", "host:8786x", "http://..."), and waited forever, whatever its timeout,
    at a port that accepts connections but is no scheduler (the dashboard's HTTP port); a
    server that answers with other bytes made it try to allocate exabytes.  One "identity"
    request under a hard deadline tells all of these apart from a scheduler.
    """
    import asyncio

    from distributed.comm import connect
    from distributed.security import Security

    timeout = SCHEDULER_TIMEOUT if timeout is None else timeout
    _refuse_a_closed_port(address, timeout)

    async def identity():
        comm = await connect(address, timeout=timeout, **Security().get_connection_args("client"))
        try:
            await comm.write({"op": "identity"})
            return await comm.read()
        finally:
            comm.abort()

    try:
        answer = asyncio.run(asyncio.wait_for(identity(), timeout))
    except (TimeoutError, asyncio.TimeoutError):
        raise ConfigError(f"cannot reach the dask scheduler at {address}: no answer within {timeout:g} s "
                          "(is it a dask scheduler's address, not its dashboard's?)") from None
    except MemoryError:  # a length prefix read from bytes that are not dask's protocol
        raise ConfigError(f"{address} is not a dask scheduler (its answer is not dask's protocol)") from None
    except Exception as error:  # noqa: BLE001 - malformed address, refused: one line
        raise ConfigError(f"cannot reach the dask scheduler at {address}: {one_line(error)}") from None
    if not isinstance(answer, dict) or answer.get("type") != "Scheduler":
        kind = answer.get("type") if isinstance(answer, dict) else type(answer).__name__
        raise ConfigError(f"{address} is not a dask scheduler (it answers as {kind!r})")


def _refuse_a_closed_port(address: str, timeout: float) -> None:
    """A ConfigError at once when nothing listens at a tcp ``address``: dask's connect retries a refused
    connection until its timeout (20 s), and then said "Timed out", not that the port was closed."""
    import socket

    from distributed.comm.addressing import get_address_host_port, parse_address

    try:
        scheme, _ = parse_address(address)
        host, port = get_address_host_port(address) if scheme == "tcp" else (None, None)
    except Exception:  # noqa: BLE001 - malformed: dask's own connect says why
        return
    if host is None:
        return
    try:
        socket.create_connection((host, port), timeout=min(timeout, 5.0)).close()
    except ConnectionRefusedError:
        raise ConfigError(f"cannot reach the dask scheduler at {address}: the connection was refused (nothing "
                          f"listens at port {port} of {host}: is the scheduler running?)") from None
    except OSError:  # unreachable, slow, a name that does not resolve: dask's connect says which
        return


def dask_setup(worker) -> None:
    """Preload of the local cluster's worker processes: a Ctrl-C leaves them to the sweep that started them.

    A terminal's Ctrl-C reaches its whole process group, and each worker process printed
    asyncio's KeyboardInterrupt tracebacks (some 60 lines) while the sweep closed the cluster,
    which ends the workers anyway.  A handler that does nothing, not SIG_IGN: a handler is
    not inherited across exec, so each ``primordia run`` still gets the Ctrl-C and stops there,
    as it does on its own.
    """
    import signal
    import threading

    os.environ.pop(WORKER_STARTING, None)  # its runs take a Ctrl-C as a run does
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, _leave_to_the_sweep)


def _leave_to_the_sweep(signum, frame) -> None:
    """SIGINT in a local worker process: nothing (the sweep closes the cluster)."""


def run_sweep(sweep: Sweep, scheduler: str | None = None, workers: int | None = None,
              timeout: float | None = None, progress: bool = False):
    """Run every point not done yet, gather all into ``OUT/sweep.nc`` (:func:`gather`); return the Dataset.

    The Dataset's attributes say how many runs were skipped (done before), run, and failed.
    Paths given to the workers are absolute: a remote worker has a working directory of its own.
    """
    if scheduler:  # a wrong address: one line before OUT is made for the lock
        _check_scheduler(scheduler)
    with _only_sweep_into(sweep.out):
        return _run_sweep(sweep, scheduler, workers, timeout, progress)


@contextmanager
def _only_sweep_into(out: Path):
    """Hold ``OUT/.sweep.lock`` (an flock) for the sweep; a ConfigError if another sweep holds it.

    The same command started twice at once (two terminals, a batch job resubmitted) ran every
    point twice: each run that met the other's in progress was recorded as failed, and the
    sweep.nc of the one that ended last said so of runs that had completed.
    """
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        yield
        return
    from primordia.core.atomic_files import make_directory

    make_directory(out)
    with open(out / LOCK_FILE, "a+") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as error:
            if not isinstance(error, BlockingIOError):  # a file system without locks (some Lustre mounts)
                yield
                return
            lock.seek(0)
            holder = lock.read().strip() or "another process"
            raise ConfigError(f"another sweep is running into {out} ({holder}): let it finish, "
                              "or give this one another --out") from None
        lock.seek(0)
        lock.truncate()
        lock.write(f"process {os.getpid()} on {socket.gethostname()}\n")
        lock.flush()
        try:
            yield
        finally:
            lock.seek(0)
            lock.truncate()


def _run_sweep(sweep: Sweep, scheduler, workers, timeout, progress):
    from dask.distributed import as_completed

    points = sweep.points()
    done = [is_done(p) for p in points]
    todo = [p for p, finished in zip(points, done) if not finished]
    records = {p.directory: _read_record(p.directory) for p, finished in zip(points, done) if finished}
    start = time.perf_counter()
    if todo:
        # the bar once the cluster is there and every run could start: not before a one-line error about
        # its scheduler or the runs
        arguments = (str(sweep.config.resolve()), list(sweep.fixed), str((sweep.out / "runs").resolve()))
        # a local cluster's workers are this machine's: checked here, before the cluster starts (refused right
        # after its start, its closing raced the workers' heartbeats, which dask logged as errors on stderr)
        if not scheduler:
            _refuse_if_every_run_fails(check_runs(*arguments))
        with dask_client(scheduler, workers) as client:
            if scheduler:  # an external cluster's workers: their own backends and plugins
                _refuse_if_every_run_fails(client.submit(check_runs, *arguments, pure=False).result())
            for line in sweep.inert_settings:  # once here, not in each run's log alone; a refusal is one line
                warn(line)
            with _progress_bar(len(points), len(points) - len(todo), progress) as bar:
                token = f"{socket.gethostname()}:{os.getpid()}:{time.time()}"  # this sweep's, for stop_runs
                futures = {client.submit(execute, str(sweep.config.resolve()), list(p.overrides),
                                         str(p.directory.resolve()), p.fingerprint, timeout, token, pure=False): p
                           for p in todo}
                try:
                    for future in as_completed(futures):
                        point = futures[future]
                        try:
                            records[point.directory] = future.result()
                        except Exception as error:  # noqa: BLE001 - e.g. the worker died: record it, go on
                            records[point.directory] = {"status": "failed",
                                                        "reason": f"{type(error).__name__}: {error}"}
                        bar.update(1)
                except KeyboardInterrupt:  # the runs going on stop with a checkpoint, and go on from it next time
                    _stop_the_runs(client, list(futures), token)
                    raise
    ds = gather(sweep, points, records)
    ds.attrs.update({"runs": len(points), "runs_skipped": len(points) - len(todo), "runs_executed": len(todo),
                     "runs_failed": int(np.sum(ds["status"].values != "completed")),
                     "wall_time_s": time.perf_counter() - start})
    from primordia.analysis.patterning import save_dataset

    save_dataset(ds, sweep.out / DATASET_FILE)
    return ds


#: Seconds an interrupted sweep waits for its runs to write their checkpoints and stop.
STOP_GRACE = 60.0


def _stop_the_runs(client, futures, token: str) -> None:
    """Ask every worker's runs to stop and its points not started to stay so (:func:`stop_runs`), and wait up
    to :data:`STOP_GRACE` seconds for them (another signal ends the wait)."""
    from dask.distributed import wait

    client.run(stop_runs, token, on_error="return")
    with contextlib.suppress(Exception):
        wait(futures, timeout=STOP_GRACE)


def _progress_bar(total: int, done: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, initial=done, unit="run", desc="sweep", disable=not enabled, file=sys.stderr,
                dynamic_ncols=True)


def gather(sweep: Sweep, points: Sequence[Point], records: dict):
    """One Dataset over the sweep's dimensions (then time, configuration, species) from the run folders."""
    import xarray as xr

    from primordia.analysis.patterns.metrics import PATTERN_KINDS
    from primordia.analysis.patterns.run import METRICS_FILE, SCALAR_METRICS, predicted_mode

    dims = sweep.dimensions
    names, shape = [name for name, _ in dims], tuple(len(values) for _, values in dims)
    status = np.full(shape, "failed", dtype=object)
    reason = np.full(shape, "not run", dtype=object)
    wall = np.full(shape, np.nan)
    predicted = {name: np.full(shape, np.nan) for name in ("k_max", "wavelength", "rate")}
    metrics = {}
    base = load_config(sweep.config)
    for point in points:
        record = records.get(point.directory, {})
        status[point.index] = record.get("status", "failed")
        reason[point.index] = record.get("reason", "") or ""
        wall[point.index] = record.get("wall_time_s", np.nan)
        mode = predicted_mode(apply_overrides(base, list(point.overrides)))
        for name in predicted:
            predicted[name][point.index] = getattr(mode, name)
        # a failed run's metrics too, at the output times it reached, when they are its own (execute)
        if status[point.index] == "completed" or (record.get("metrics") and _has_metrics(point.directory)):
            with xr.open_dataset(point.directory / METRICS_FILE, engine="scipy") as run:
                metrics[point.index] = run.load()
    ds = xr.Dataset(
        {"status": (names, status.astype(str), {"long_name": "completed or failed"}),
         "reason": (names, reason.astype(str), {"long_name": "why the run failed (empty if it completed)"}),
         "wall_time_s": (names, wall, {"long_name": "wall time of the run and its metrics", "units": "s"}),
         "run_dir": (names, np.array([str(p.directory) for p in points], dtype=str).reshape(shape)),
         # the seed's dimensionless k, lengths and rates: UDUNITS-2's "1", as metrics.nc writes them
         "predicted_wavenumber": (names, predicted["k_max"], {"long_name": "linear analysis: fastest stationary k",
                                                              "units": "1"}),
         "predicted_wavelength": (names, predicted["wavelength"], {"long_name": "linear analysis: 2 pi / k_max",
                                                                   "units": "1"}),
         "predicted_growth_rate": (names, predicted["rate"], {"long_name": "linear analysis: Re phi at k_max",
                                                              "units": "1"})},
        coords={name: (name, *sweep.coordinates[name]) for name, _ in dims},
        # no Conventions, as metrics.nc states none: the configuration and species dimensions (and a text-valued
        # varied key's) are labelled by text, which CF's coordinate variables cannot be (cfchecks: "Possible
        # incorrect declaration of a coordinate variable")
        attrs={"title": f"primordia sweep of {sweep.config.name} over {', '.join(names)}",
               "config": str(sweep.config), "fixed_overrides": " ".join(sweep.fixed),
               "varied": " ".join(f"{a.key}" for a in sweep.axes) + (f" {SEED_KEY}" if sweep.seeds else "")},
    )
    if metrics:
        first = next(iter(metrics.values()))
        # every run's times, configurations and species: runs of another t_final (or output.times) measured
        # at other times, and the first run's alone dropped the others' metrics for NaN
        inner = {"time": np.unique(np.concatenate([run["time"].values for run in metrics.values()])),
                 **{name: np.array(list(dict.fromkeys(value for run in metrics.values() for value in run[name].values)))
                    for name in ("configuration", "species")}}
        full = names + list(inner)
        for variable in [name for name, _, _ in SCALAR_METRICS] + ["pattern"]:
            fill = -1 if variable == "pattern" else np.nan
            array = np.full(shape + tuple(len(v) for v in inner.values()), fill,
                            dtype=np.int8 if variable == "pattern" else float)
            for index, run in metrics.items():
                array[index] = run[variable].reindex(inner, fill_value=fill).transpose(*inner).values
            ds[variable] = (full, array, dict(first[variable].attrs))
        ds["pattern"].attrs.update({"flag_values": np.arange(-1, len(PATTERN_KINDS), dtype=np.int8),
                                    "flag_meanings": "no_result " + " ".join(PATTERN_KINDS)})
        ds = ds.assign_coords({name: (name, values, dict(first[name].attrs)) for name, values in inner.items()})
    return ds


def sweep_picture(ds, sweep: Sweep, path, species: str | None = None) -> Path | None:
    """The simulated patterning map over the two varied keys with the linear analysis over it (None if not 2).

    Without a map (not two keys, or no run completed) a map at ``path`` is removed: an earlier sweep into the
    same folder drew it, and it stood beside a sweep.nc it does not describe, as this sweep's.  Failed runs'
    metrics (the times a time-out reached) give ``ds`` a time without any run completing: they drew a map of
    "failed" alone, titled with a time no run was shown at, where the command said there is none.
    """
    from primordia.analysis.patterns.figures import sweep_figure
    from primordia.analysis.patterns.metrics import PATTERN_KINDS

    if len(sweep.axes) != 2 or "time" not in ds.dims or (ds["status"] != "completed").all():
        Path(path).unlink(missing_ok=True)
        return None
    x, y = (axis.name for axis in sweep.axes)
    species = species or ("m" if "m" in ds["species"].values else str(ds["species"].values[0]))
    final = _last_measured(ds.sel(configuration="reference", species=species))
    failed = final["status"] != "completed"
    # a failed run's metrics (at the times it reached) are in sweep.nc, not on the map of the runs' ends
    kinds = final["pattern"].where(~failed, -1)
    reduced = final[["spacing_mean", "spot_count", "dominant_wavelength"]].where(~failed)
    reduced["dominant_wavelength"] = reduced["dominant_wavelength"].where(kinds > 0)  # no pattern: no wavelength
    ended = final["time"].where(~failed).values  # some run completed (above): its end is finite
    times = np.unique(ended[np.isfinite(ended)])
    if "seed" in ds.dims:
        reduced = reduced.mean("seed", skipna=True)
        failed = failed.all("seed")
        names = np.apply_along_axis(_most_common_kind, kinds.get_axis_num("seed"), kinds.values)
    else:
        names = np.vectorize(lambda code: PATTERN_KINDS[code] if code >= 0 else "failed", otypes=[object])(
            kinds.values)
    dims = [d for d in kinds.dims if d != "seed"]
    reduced["pattern_name"] = (dims, names)
    reduced["failed"] = failed.transpose(*dims)
    when = (f"t = {times[0]:g}" if len(times) == 1
            else f"the last output time of each run (t = {times[0]:g}-{times[-1]:g})")
    reduced.attrs["title"] = (f"{ds.attrs['title']}: {species} at {when} "
                              f"(reference configuration{', mean over seeds' if 'seed' in ds.dims else ''})")
    return sweep_figure(reduced.transpose(x, y), _linear_map(sweep, x, y), path, x, y)


def _last_measured(ds):
    """``ds`` (time, and the sweep's dimensions) at each run's last output time with a result, the last time where
    none has one: runs of another t_final end at other times, and the sweep's last time drew them "failed"."""
    import xarray as xr

    measured = ds["pattern"] >= 0
    dims = [dim for dim in measured.dims if dim != "time"]
    later_first = np.flip(measured.transpose(*dims, "time").values, axis=-1)
    return ds.isel(time=xr.DataArray(ds.sizes["time"] - 1 - np.argmax(later_first, axis=-1), dims=dims))


def _most_common_kind(codes: np.ndarray) -> str:
    from primordia.analysis.patterns.metrics import PATTERN_KINDS

    found = [PATTERN_KINDS[c] for c in codes if c >= 0]
    return Counter(found).most_common(1)[0][0] if found else "failed"


def _linear_map(sweep: Sweep, x: str, y: str, n: int = 41, nk: int = 256):
    """The linear patterning space over the sweep's two parameters (slightly wider), or None.

    ``nk`` wavenumbers (fine, ~5 s on 41 x 41): the predicted wavelength is the best of them,
    so its contours step where k_max jumps from one to the next.
    """
    from primordia.analysis.patterning import ParameterRange, patterning_space
    from primordia.analysis.patterns.run import linear_model

    if not all(axis.key.startswith("parameters.") for axis in sweep.axes):
        return None
    try:
        params, coupled = linear_model(sweep.base_config)
    except ConfigError:
        return None
    ranges = []
    for axis in sweep.axes:  # half a sweep cell beyond the outer points, where the sign constraint allows
        low, high = min(axis.values), max(axis.values)
        margin = 0.5 * (high - low) / max(len(axis.values) - 1, 1) if high > low else 0.1 * max(abs(low), 1.0)
        try:
            params.replace(**{axis.name: low - margin})
            low -= margin
        except ConfigError:
            pass
        ranges.append(ParameterRange(axis.name, low, high + margin, n))
    try:
        return patterning_space(ranges[0], ranges[1], params=params, coupled=coupled, nk=nk)
    except ConfigError:  # e.g. a swept value outside the parameter's sign constraint
        return None


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``sweep`` subcommand to an argparse ``subparsers`` object; sets ``func``."""
    parser = subparsers.add_parser(
        "sweep", help="run a parameter sweep on a dask cluster and map the patterns it forms",
        description=__doc__.split("\n\n")[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("config", help="TOML configuration file")
    parser.add_argument("--vary", action="append", default=[], metavar="SECTION.KEY=LO:HI:N",
                        help="vary a config value over N values from LO to HI (repeatable), "
                             "e.g. parameters.m0=0.5:1.5:5")
    parser.add_argument("--seeds", type=int, default=0, metavar="N",
                        help=f"run each point with seeds 1..N of the random initial perturbation ({SEED_KEY})")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="override a config value for every run (repeatable), e.g. --set mesh.cells=[43,43]")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="an existing dask scheduler, e.g. tcp://host:8786")
    parser.add_argument("--workers", type=int, metavar="N", help="worker processes of the local cluster "
                                                                 "(default: one per core)")
    parser.add_argument("--timeout", type=float, metavar="SECONDS", help="stop (and record as failed) a run after this")
    parser.add_argument("--out", help="output directory (default: out/sweep_<config name>)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=command_sweep)
    return parser


def command_sweep(args) -> int:
    """Entry point of ``primordia sweep``; returns the exit code."""
    number(args.seeds, "--seeds", integer=True, at_least=0)
    if args.workers is not None:
        number(args.workers, "--workers", integer=True, at_least=1)
        if args.scheduler:
            raise ConfigError("--workers applies to the local cluster only (not with --scheduler)")
    if args.timeout is not None:
        number(args.timeout, "--timeout", above=0, hint="seconds")
    if args.out is not None and not args.out.strip():  # as primordia run: not the default folder, unsaid
        raise ConfigError("--out needs a directory name")
    config = Path(args.config)
    sweep = Sweep(config, tuple(Axis.parse(text) for text in args.vary), tuple(range(1, args.seeds + 1)),
                  tuple(args.overrides), Path(args.out) if args.out is not None else None)
    print(f"primordia sweep: {len(sweep.points())} runs of {config} over "
          + " x ".join(f"{name} ({len(values)})" for name, values in sweep.dimensions) + f" -> {sweep.out}")
    try:
        ds = run_sweep(sweep, args.scheduler, args.workers, args.timeout, progress=not args.no_progress)
    except KeyboardInterrupt as interrupted:  # said as a sweep's, not as a run's "during start-up"
        raise _sweep_interrupted(interrupted, sweep) from None
    print(f"  {ds.attrs['runs_skipped']} done before (skipped), {ds.attrs['runs_executed']} run, "
          f"{ds.attrs['runs_failed']} failed, in {ds.attrs['wall_time_s']:.1f} s")
    for text, count in Counter(ds["reason"].values[ds["status"].values != "completed"]).most_common():
        print(f"  failed ({count}): {text}")
    try:
        picture = sweep_picture(ds, sweep, sweep.out / PICTURE_FILE)
    except KeyboardInterrupt as interrupted:
        raise _sweep_interrupted(interrupted, sweep, f"after writing {sweep.out / DATASET_FILE}, "
                                                    "before drawing its map") from None
    why = "it needs exactly two --vary keys" if len(sweep.axes) != 2 else "no run completed"
    print(f"  wrote {sweep.out / DATASET_FILE}" + (f" and {picture}" if picture else f" (no map: {why})"))
    if ds["status"].size and (ds["status"].values != "completed").all():
        # some failed points are a finding (a region of parameters that blows up); none completed is a sweep
        # that did not work, and a batch script's `primordia sweep ... && ...` went on as if it had (exit 0)
        raise PrimordiaError(f"none of the sweep's {ds['status'].size} runs completed ({DATASET_FILE} and each "
                             f"run's run.log say why)")
    return 0


def _sweep_interrupted(interrupted: KeyboardInterrupt, sweep: Sweep, where: str = ""):
    """The InterruptedRun that says how far the sweep got and how to go on (cli's "interrupted" line).

    Without it the CLI said "interrupted (Ctrl-C) during start-up, before the first step", a run's words.
    """
    import signal

    from primordia.core.errors import InterruptedRun
    from primordia.core.signals import INTERRUPTS, signal_name

    signum = getattr(interrupted, "signum", None) or INTERRUPTS.received or signal.SIGINT
    points = sweep.points()
    done = sum(is_done(point) for point in points)
    return InterruptedRun(signum, f"interrupted ({signal_name(signum)}) {where or 'while running the sweep'}: "
                                  f"{done} of {len(points)} runs done and kept in {sweep.out / 'runs'}; "
                                  "the same command goes on from there")
