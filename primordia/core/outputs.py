"""What a run writes, as output plugins (registered through ``primordia_outputs``).

Each :class:`Output` contributes its own files: it is told when the run starts,
at every output time, and when the run ends (normally or not).  Every file is
written atomically (:mod:`primordia.core.atomic_files`), so whatever has been written
stays readable if a run dies part-way.

Built-in outputs: the resolved configuration (``config.toml``), the fields in
XDMF (``fields.xdmf`` + ``fields.h5``), the scalar time series
(``series.nc``), the pictures (``m_t0160.png``..., ``m_snapshots.png``,
``final_fields.png``) and the run summary (``summary.json``).

A run continued from a checkpoint (``primordia run --restart``) calls
:meth:`Output.resume` instead of :meth:`Output.start`, with what
:meth:`Output.state` returned when the checkpoint was written: the files then
continue from the checkpoint, whatever the killed run wrote after it.
:func:`existing_run` and :func:`clear_run` say whether a directory already holds a
run and remove one, so old and new files never mix.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import shutil
import socket
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from primordia.core.atomic_files import StorageError, nearest_existing, reason_of, refusal_to_write
from primordia.core.checkpoint import CHECKPOINT_FILE, read_meta
from primordia.core.errors import ConfigError, PluginError, PrimordiaError
from primordia.core.json_toml import write_json, write_toml
from primordia.core.pictures import plot_field, plot_fields_grid
from primordia.core.plugins import hookimpl
from primordia.core.scalar_series import ScalarSeries
from primordia.core.validation import flag, number
from primordia.core.xdmf import XdmfSeries


@dataclass(frozen=True)
class OutputOption:
    """One key of the run's ``[output]`` table that an output reads: its default, its check, what it means.

    ``check(value, "output.KEY")`` returns the value to use or raises one
    :class:`~primordia.core.errors.ConfigError` naming the key; the checks of
    :mod:`primordia.core.validation` fit as they are (``flag``) or with their bounds
    (``partial(number, at_least=0)``).  The default is used as it is, and must pass the
    check (:func:`declared_options` refuses the output otherwise, as a plugin's bug), except
    ``None`` for an option that ``names_fields``.
    """

    default: Any
    check: Callable[[Any, str], Any]
    help: str = ""
    #: The value names fields of the model: the model checks each name once its fields are known,
    #: and a ``None`` value becomes its first field.
    names_fields: bool = False


def field_names(value, where: str) -> list[str]:
    """The check of an option that lists field names (their existence is the model's check)."""
    if not isinstance(value, (list, tuple)) or not all(isinstance(name, str) for name in value):
        raise ConfigError(f"{where} must be a list of field names, got {value!r}")
    return list(value)


class Output:
    """Base class: override the moments you write at (all run on every rank).

    An output that can be configured declares its keys of ``[output]`` in
    :attr:`options`; the model then accepts them, fills in their defaults and checks
    them before the run, and the output reads them from ``run.model.output``.
    """

    name: str
    #: The keys of ``[output]`` this output reads (none by default); a key belongs to one output.
    options: ClassVar[Mapping[str, OutputOption]] = {}
    #: Whether :meth:`finish` comes after the other outputs' (slow work that nothing else describes,
    #: such as pictures): ``summary.json`` then says why the run stopped before it starts.  mpirun
    #: sends its ranks SIGTERM one second after its own Ctrl-C or SIGTERM, and SIGKILL a second later.
    finishes_last: ClassVar[bool] = False

    def start(self, run) -> None:
        """Before the first step (after initial conditions are set)."""

    def record(self, run) -> None:
        """At a series time (every ``output.series_every`` steps and at snapshots)."""

    def snapshot(self, run) -> None:
        """At a field snapshot time (``output.times``)."""

    def rejection(self, run, event: dict) -> None:
        """A time step was rejected and is retried smaller (``event``: time, dt, reason)."""

    def finish(self, run, status: str) -> None:
        """After the last step, or when the run stops early (``status`` says why)."""

    def flush(self, run) -> None:
        """Write now what waits in memory, on this rank alone: the run ends without :meth:`finish` (an MPI_Abort
        after a failure on one rank, or a second signal under MPI, when the ranks may be anywhere).  No collective
        call; a failure is ignored."""

    def state(self) -> dict:
        """What this output must remember across a restart (numbers, strings, lists, dicts, numpy arrays)."""
        return {}

    def resume(self, run, state: dict) -> None:
        """Continue a restarted run from ``state`` (what :meth:`state` returned at the checkpoint).

        By default the output starts afresh, as at the start of a run.
        """
        self.start(run)


class ResolvedConfig(Output):
    name = "config"

    def start(self, run):
        if run.is_root:
            write_toml(run.out_dir / "config.toml", run.resolved_config())


class FieldsXdmf(Output):
    """All fields at the snapshot times, readable by ParaView and meshio."""

    name = "xdmf"

    def start(self, run):
        self.series = XdmfSeries(run.out_dir, run.mesh_data, name="fields") if run.is_root else None

    def snapshot(self, run):
        values = run.vertex_values()
        if run.is_root:
            self.series.write(run.time, values)

    def state(self):
        return self.series.state() if self.series is not None else {}

    def resume(self, run, state):
        self.series = XdmfSeries(run.out_dir, run.mesh_data, name="fields") if run.is_root else None
        if run.is_root:
            self.series.restore(state)


class ScalarSeriesNetcdf(Output):
    """Per recorded time: integral, min and max of each field, solver iterations, the time step.

    Rejected time steps are recorded as they happen, along the dimension ``rejection``
    (``rejection_time``, ``rejection_dt``, ``rejection_reason``).
    """

    name = "series"
    series: ScalarSeries | None = None  # made at start or resume (on the root rank)
    described: frozenset = frozenset()  # the variables given their attributes (long_name, units)

    def start(self, run):
        self.series = self._series(run)
        self.record(run)

    @staticmethod
    def _series(run) -> ScalarSeries | None:
        """The root rank's series file, with attributes saying what wrote it (None on the other ranks)."""
        if not run.is_root:
            return None
        from primordia import __version__

        model = f"model {run.model.name!r}" if run.model.name else "an unnamed model"
        about = {"title": f"primordia scalar series of {model} ({run.out_dir.name})",
                 "source": f"primordia {__version__}, backend {run.backend.name}, {run.comm.size} MPI rank(s), "
                           f"splitting scheme {run.scheme.name}",
                 "references": "the run's configuration: config.toml beside this file",
                 "Conventions": "CF-1.8"}  # its units are UDUNITS-2's (SERIES_OWN), its attributes CF's
        return ScalarSeries(run.out_dir / "series.nc", min_interval=SERIES_INTERVAL, global_attrs=about)

    def record(self, run):
        row = {"step": run.step_index}
        for name, stats in run.field_statistics().items():
            row.update({f"{name}_integral": stats["integral"], f"{name}_min": stats["min"],
                        f"{name}_max": stats["max"]})
        row.update(run.diagnostic_values())
        row.update(run.iteration_counts())
        row.update(run.step_sizes())
        row.update(run.memory_use())
        if run.is_root and (not self.series.times or run.time > self.series.times[-1]):
            events = ("rejection_time", "rejection_dt", "rejection_reason")
            attrs = series_attributes(run, [key for key in ("time", *events, *row) if key not in self.described])
            self.described = self.described | set(attrs)
            self.series.append(run.time, row, attrs)

    def rejection(self, run, event: dict):
        """A time step was rejected (``event``: time, dt, reason)."""
        if run.is_root:
            self.series.add_event("rejection", event)

    def state(self):
        return self.series.state() if self.series is not None else {}

    def resume(self, run, state):
        self.series = self._series(run)
        if run.is_root:
            self.series.restore(state)

    def finish(self, run, status):
        self.flush(run)

    def flush(self, run):
        if self.series is not None:  # None also when a signal stopped the run before start
            self.series.flush()


#: (long_name, units) of the series' time and of the rejected sub-steps' variables (along ``rejection``).
#: Units are UDUNITS-2's, as CF asks: "1" for the seed's dimensionless times and counts (UDUNITS knows no
#: "dimensionless": ``udunits2 -H dimensionless`` answers 'Don't recognize "dimensionless"').
SERIES_OWN = {"time": ("time (dimensionless, seed section 2)", "1"),
              "step": ("time steps taken", "1"),
              "rejection_time": ("the start of a rejected sub-step", "1"),
              "rejection_dt": ("the length of a rejected sub-step", "1"),
              "rejection_reason": ("why the sub-step was rejected", None)}


def series_attributes(run, keys) -> dict[str, dict[str, str]]:
    """NetCDF attributes (``long_name``, ``units``) of the series' ``keys``: each described by what produced it
    (the fields' statistics, the modules' diagnostics, the run's counts, sizes and memory)."""
    if not keys:
        return {}
    vectors = {name for name, spec in run.field_specs().items() if spec.vector}
    fields = {name: f"|{name}|" if name in vectors else name for name in run.field_specs()}
    diagnostics = {diagnostic.name: diagnostic for diagnostic in run.diagnostics}
    described = {**SERIES_OWN, **run.series_descriptions()}
    attrs = {}
    for key in keys:
        name, unit = described.get(key, (None, None))
        field, _, statistic = key.rpartition("_")
        if name is None and field in fields and statistic in ("integral", "min", "max"):
            # a vector's extrema are its components' (the backends' vertex_extrema), not its magnitude's:
            # "minimum of |u|" stood over example 1b's u_min = -0.056
            extrema_of = f"the components of {field}" if field in vectors else field
            name = {"integral": f"integral of {fields[field]} over the reference domain",
                    "min": f"minimum of {extrema_of} at the vertices",
                    "max": f"maximum of {extrema_of} at the vertices"}[statistic]
        if name is None:
            diagnostic = diagnostics.get(key) or (diagnostics.get(field) if statistic in ("min", "max") else None)
            if diagnostic is not None and diagnostic.description:
                name = diagnostic.description + (f" ({statistic}imum at the vertices)" if diagnostic.kind == "extrema"
                                                 else "")
        if name is not None:
            attrs[key] = {"long_name": name, **({"units": unit} if unit else {})}
    return attrs


#: series.nc is rewritten at most this often (seconds) while a run goes on, and at its end: every row
#: of a fast run would otherwise rewrite the file (example 1a: 4.8 ms a rewrite
#: of its 261 rows of 21 columns, 7.8 ms when xarray wrote them; a row every 10 steps of 20 ms).
SERIES_INTERVAL = 2.0

#: summary.json is rewritten at a series time at most this often (seconds), unless series.nc was just rewritten.
SUMMARY_INTERVAL = 0.5


class Pictures(Output):
    """PNGs of the snapshot fields at every snapshot time, and at the end their grids and every field.

    Vector fields are drawn as their magnitude.  When a physics module declares a
    field the tissue's displacement (``FieldSpec.displacement``), fields are drawn
    on the deformed configuration, magnified by ``output.displacement_scale``
    (stated on the picture).

    Each snapshot time writes one PNG per snapshot field (``m_t0160.00.png``; more decimals when the
    output times need them, :func:`picture_time`).  The grid of
    every snapshot time (``m_snapshots.png``, the seed's Figure 5.1) is drawn once, when the
    run ends (completed or stopped), with ``final_fields.png``.  Redrawn at every snapshot, as
    it was, its cost grew with the square of the number of snapshots: the pictures of example
    1a took 4.2 s of its serial run, and take 2.5 s.  Under MPI the pictures of one moment are
    shared out over the ranks (:func:`_draw_shared`): rank 0 holds the gathered fields and hands
    each rank its pictures' (1a on 2 ranks: 3.8 s of pictures before these two changes, 2.1 s).
    """

    name = "pictures"
    finishes_last = True  # the final grids take about a second: summary.json says why the run stopped first
    options = {
        "pictures": OutputOption(True, flag, "draw the PNGs (false: none)"),
        "displacement_scale": OutputOption(1.0, partial(number, at_least=0),
                                           "magnification of the displacement the fields are drawn on"),
        "snapshot_fields": OutputOption(None, field_names, "the fields drawn at each output time "
                                        "(default: the first field)", names_fields=True),
    }

    def __init__(self):
        # the snapshot fields at each time, by field and label (for the grids at the end); rank 0's
        self.snapshots: dict[str, dict[str, object]] = {}
        self.snapshot_displacements: dict[str, dict[str, object]] = {}

    @staticmethod
    def _drawn(name: str, values) -> tuple[str, np.ndarray]:
        """(its label, what is drawn) of a field's vertex values: a vector as its magnitude, |u|."""
        if values.ndim == 2:
            return f"|{name}|", np.linalg.norm(values, axis=1)
        return name, values

    def snapshot(self, run):
        if not run.model.output["pictures"]:
            return
        values = run.vertex_values()

        def pictures():
            displacement, scale = values.get(run.displacement_field), run.model.output["displacement_scale"]
            stamp = picture_time(run.time, run.model.output["times"])
            for name in run.model.output["snapshot_fields"]:
                shown, field = self._drawn(name, values[name])
                label = f"{shown}, t = {time_label(run.time)}"
                self.snapshots.setdefault(name, {})[label] = field
                if displacement is not None:
                    self.snapshot_displacements.setdefault(name, {})[label] = displacement
                yield 1, plot_field, run.out_dir / f"{name}_t{stamp}.png", dict(
                    values=field, title=label, displacement=displacement, displacement_scale=scale)

        _draw_shared(run, pictures)

    def state(self):
        return {"snapshots": self.snapshots, "displacements": self.snapshot_displacements}

    def resume(self, run, state):
        self.snapshots = {name: dict(frames) for name, frames in state.get("snapshots", {}).items()}
        self.snapshot_displacements = {name: dict(frames) for name, frames in state.get("displacements", {}).items()}

    def finish(self, run, status):
        if not run.model.output["pictures"]:
            return
        values = run.vertex_values()

        def pictures():
            scale = run.model.output["displacement_scale"]
            for name, frames in self.snapshots.items():
                yield len(frames), plot_fields_grid, run.out_dir / f"{name}_snapshots.png", dict(
                    fields=frames, title=f"{name} at the snapshot times",
                    displacements=self.snapshot_displacements.get(name), displacement_scale=scale)
            fields = dict(self._drawn(name, v) for name, v in values.items())
            displacement = values.get(run.displacement_field)
            yield len(fields), plot_fields_grid, run.out_dir / "final_fields.png", dict(
                fields=fields, title=f"all fields at t = {step_time_label(run.time)} ({status})",
                shared_colour_scale=False,
                displacements=None if displacement is None else {key: displacement for key in fields},
                displacement_scale=scale)

        _draw_shared(run, pictures)


def picture_time(t: float, times: Iterable[float]) -> str:
    """``t`` as the snapshot pictures' file names write it: ``0160.00``, with more decimals when the output
    times need them (dt = 0.001: ``0000.001``), so that no two output times share a file, and more digits
    before the point when the largest needs them (``05000.00``, ``20000.00``), so that the names sort in time
    order (four digits for every time wrote ``5000.00`` after ``20000.00``).  A time before 0 has its sign
    before as many digits (``-0000.50`` beside ``0000.50``; the sign took a digit: ``-000.50``); such names sort
    before the others, but among themselves from the latest (``-0000.50`` before ``-0001.00``), as any name
    that writes the time does."""
    every = tuple(sorted({float(time) for time in (*times, t)}))
    decimals = _picture_decimals(every)
    digits = max(4, *(len(f"{abs(time):.{decimals}f}".partition(".")[0]) for time in (every[0], every[-1])))
    return ("-" if t < 0 else "") + f"{abs(t):0{digits + 1 + decimals}.{decimals}f}"


@functools.lru_cache(maxsize=8)
def _picture_decimals(times: tuple[float, ...]) -> int:
    """The fewest decimals (at least 2) that write every one of ``times`` exactly, else that tell them apart."""
    exact = next((d for d in range(2, 18) if all(round(time, d) == time for time in times)), None)
    if exact is not None:
        return exact
    return next((d for d in range(2, 18) if len({f"{time:.{d}f}" for time in times}) == len(times)), 17)


def time_label(t: float) -> str:
    """``t`` on a picture: ``%g`` when that is the time, else every digit (1.0000001 is not ``1``)."""
    t = float(t)
    return f"{t:g}" if float(f"{t:g}") == t else repr(t)


def step_time_label(t: float) -> str:
    """A time the run stepped to, t_start + k dt, on a picture: :func:`time_label` of it to 15 significant digits,
    without the round-off of the sum (a run stopped by SIGTERM after 629 steps of 0.2 was drawn "at t =
    125.80000000000001", beside its status "interrupted at t = 125.8"); 1.0000001 is still not ``1``."""
    return time_label(float(f"{float(t):.15g}"))


def _draw_shared(run, pictures: Callable[[], Iterable[tuple]]) -> None:
    """Draw the pictures rank 0's ``pictures()`` lists, (panels, function, path, its other arguments),
    shared out over the ranks (collective; only rank 0 calls ``pictures``, it holds the gathered fields).

    Largest first, each to the rank with the fewest panels so far: a rank draws while the others
    draw theirs, instead of all waiting for rank 0.  A failure on any rank reaches every rank
    through the run's output protocol (``Simulation._call_output`` gathers them); one in
    ``pictures`` itself is raised once the others have their (empty) shares, so none waits.
    """
    mine, failure = [], None
    if run.is_root:
        try:
            mine = list(pictures())
        except Exception as error:  # noqa: BLE001 - raised below, after the scatter
            mine, failure = [], error
    if run.comm.size > 1:
        shares = None
        if run.is_root:
            shares, panels = [[] for _ in range(run.comm.size)], [0] * run.comm.size
            for picture in sorted(mine, key=lambda picture: -picture[0]):
                rank = panels.index(min(panels))
                shares[rank].append(picture)
                panels[rank] += picture[0]
        mine = run.comm.scatter(shares, root=0)
    if failure is not None:
        raise failure
    for _, draw, path, arguments in mine:
        draw(path, run.mesh_data, **arguments)


class Summary(Output):
    """``summary.json``: status, sizes, steps, wall time, final statistics, mean iterations.

    Rewritten whenever the built-in outputs write (it is the last output), so it
    never describes less than the files next to it, and at the end with the
    reason the run stopped: at the start, at every snapshot, and at a series time
    when ``series.nc`` was just rewritten or ``SUMMARY_INTERVAL`` seconds after
    its own last rewrite (it shows a run's progress sooner than the series).  Each
    rewrite costs two fsyncs (slow on a cluster's shared file system) and the run's
    statistics (collective): example 1a recorded 261 rows and rewrote the summary
    at each, where it now does so about every third.  While the run goes on its
    status is ``"running"``, with the process id and host: :func:`existing_run`
    tells a run that was killed without a word (SIGKILL, a node failure) from one
    still running.
    """

    name = "summary"

    def __init__(self):
        self._written_at: float | None = None  # time.monotonic() of the last rewrite (rank 0)

    def start(self, run):
        self._write(run, "running")

    def record(self, run):
        if self._due(run):
            self._write(run, "running")

    def _due(self, run) -> bool:
        """Whether a series time rewrites the summary: rank 0 decides, for every rank (the summary is collective)."""
        due = None
        if run.is_root:
            now = time.monotonic()
            series = [output.series.written_at for output in run.outputs
                      if isinstance(output, ScalarSeriesNetcdf) and output.series is not None]
            due = (self._written_at is None or now - self._written_at >= SUMMARY_INTERVAL
                   or any(at is not None and at > self._written_at for at in series))
        return run.comm.bcast(due, root=0) if run.comm.size > 1 else due

    def snapshot(self, run):
        self._write(run, "running")

    def resume(self, run, state):
        self._write(run, "running")

    def finish(self, run, status):
        self._write(run, status)

    def _write(self, run, status):
        summary = run.summary(status)
        if run.is_root:
            if status == "running":
                summary["process"] = {"pid": os.getpid(), "host": socket.gethostname(),
                                      "started": process_start(os.getpid())}
                write_json(run.out_dir / "summary.json", summary)
                if self._written_at is None:
                    reserve_room(run.out_dir)
            else:
                write_last_summary(run.out_dir, summary)
            self._written_at = time.monotonic()


#: A scratch file of the run's folder holding room for the last rewrite of summary.json.  On a disk that fills the
#: refused write's temporary file is removed, but an atomic rewrite of the summary needs room beside the old one:
#: on a 100 kB tmpfs a restart's fields.xdmf was refused, then the summary saying so, which kept saying "running"
#: (the next run into the folder called the run "killed without a word").  Removed when the run ends.
SUMMARY_RESERVE = ".summary.reserve"
#: Its size (bytes): twice example 1a's summary.json (2.6 kB), in whole 4 kB blocks.
SUMMARY_RESERVE_BYTES = 8192


def reserve_room(directory: Path) -> None:
    """Hold :data:`SUMMARY_RESERVE_BYTES` in :data:`SUMMARY_RESERVE` (a disk too full for it holds less, or none)."""
    path = Path(directory) / SUMMARY_RESERVE
    try:
        with open(path, "wb") as reserve:  # written out, not sparse: its blocks are allocated
            reserve.write(bytes(SUMMARY_RESERVE_BYTES))
            reserve.flush()
            os.fsync(reserve.fileno())
    except OSError:
        pass  # what was written holds what room it could


def write_last_summary(directory: Path, summary: dict) -> None:
    """Write the summary that says why the run stopped, into the room :func:`reserve_room` held if the disk has
    none left; the reserve goes either way."""
    reserve = Path(directory) / SUMMARY_RESERVE
    try:
        write_json(Path(directory) / "summary.json", summary)
    except StorageError:
        if not reserve.exists():
            raise
        reserve.unlink()
        write_json(Path(directory) / "summary.json", summary)
    finally:
        reserve.unlink(missing_ok=True)


@hookimpl
def primordia_outputs():
    return [ResolvedConfig, FieldsXdmf, ScalarSeriesNetcdf, Pictures, Summary]


def declared_options(outputs: Iterable[type[Output]], reserved: Iterable[str] = ()) -> dict[str, OutputOption]:
    """Every ``[output]`` key the ``outputs`` declare; a key declared by two of them is one ConfigError.

    An output whose options are not a table of :class:`OutputOption`, that declares one of the ``reserved``
    keys (the schedule's, which the model checks itself) or a default its own check refuses, is one
    :class:`PluginError` naming it.
    """
    declared: dict[str, OutputOption] = {}
    owner: dict[str, str] = {}
    reserved = set(reserved)
    for output in outputs:
        if not isinstance(output.options, Mapping) or not all(isinstance(option, OutputOption)
                                                               for option in output.options.values()):
            raise PluginError(f"output {output.name}: its options must be a table of "
                              f"primordia.core.outputs.OutputOption, got {output.options!r}")
        for key, option in output.options.items():
            if key in reserved:
                raise PluginError(f"output {output.name} declares output.{key}, a key of the output schedule "
                                  f"({', '.join(sorted(reserved))}): it must rename its option")
            if key in owner:
                raise ConfigError(f"output option {key!r} is declared by two outputs, {owner[key]!r} and "
                                  f"{output.name!r}: one of them must rename it")
            if not (option.names_fields and option.default is None):
                try:  # a default its own check refuses reached the output as it was (a plugin's -1 scale)
                    option.check(option.default, f"output.{key}")
                except ConfigError as error:
                    raise PluginError(f"output {output.name} declares output.{key} with the default "
                                      f"{option.default!r}, not a valid value of it: {error}") from None
            declared[key], owner[key] = option, output.name
    return declared


# -- a directory that already holds a run -----------------------------------------------------------

#: Files whose presence means a directory holds a run.
RUN_FILES = ("summary.json", "config.toml", "series.nc", "fields.xdmf", CHECKPOINT_FILE)
#: What ``primordia analyse`` writes into a run's directory (:mod:`primordia.analysis.patterns.run`).
ANALYSIS_FILE = "metrics.nc"
#: What a run (and ``primordia analyse`` of it) writes besides: removed with it by :func:`clear_run`.  Its
#: pictures by their names (:class:`Pictures`, ``metrics_<species>.png``): ``*.png`` also took the user's own.
RUN_LEFTOVERS = ("fields_h5", "*_t[0-9]*.png", "*_t-[0-9]*.png", "*_snapshots.png", "final_fields.png",
                 "metrics_*.png", ANALYSIS_FILE, ".*.tmp-*", SUMMARY_RESERVE)


def existing_run(directory: str | Path) -> str | None:
    """None if ``directory`` holds no run; else how that run ended, in a few words.

    A summary saying ``"running"`` whose process is gone (on this host) is reported
    as killed; one whose process is alive as running (``"running in process N"``).
    """
    directory = Path(directory)
    if not directory.is_dir() or not any((directory / name).exists() for name in RUN_FILES):
        return None
    try:
        summary = json.loads((directory / "summary.json").read_text())
        status = str(summary["status"])
    except (OSError, ValueError, KeyError, TypeError):
        return "a run without a readable summary.json"
    where = f"{summary.get('steps', '?')} steps, t = {summary.get('time', '?')}"
    if status != "running":
        return f"a run that ended: {status} ({where})"
    process = summary.get("process") or {}
    if run_is_alive(process):
        return f"a run in progress (process {process.get('pid')} on {process.get('host')})"
    return (f"a run that was killed without a word after {_last_seen(directory, summary)} (its process "
            f"{process.get('pid', '?')} is gone)")


def continued_from_checkpoint(directory: str | Path, hint: str) -> str | None:
    """``"HINT continues it from its checkpoint at t = T"`` for the run in ``directory``, or None when it holds no
    readable checkpoint: the words of every line that says how a stopped run goes on (``HINT``: the command or
    Python call that continues it)."""
    try:
        time = read_meta(Path(directory) / CHECKPOINT_FILE)["run"]["time"]
        return f"{hint} continues it from its checkpoint at t = {step_time_label(time)}"
    except (PrimordiaError, KeyError, TypeError):
        return None


def _last_seen(directory: Path, summary: dict) -> str:
    """How far a killed run got, as far as its files tell: its summary's last rewrite, or its checkpoint if later.

    The summary is rewritten at series times, at most every SUMMARY_INTERVAL seconds: a run killed after 20
    steps was said "killed without a word at 0 steps, t = 0.0" beside a checkpoint of step 20."""
    steps, t = summary.get("steps", "?"), summary.get("time", "?")
    with contextlib.suppress(Exception):  # noqa: BLE001 - none, or unreadable: the summary's word stands
        run = read_meta(directory / CHECKPOINT_FILE)["run"]
        if not isinstance(steps, int) or int(run["step"]) > steps:
            steps, t = int(run["step"]), step_time_label(float(run["time"]))
    return f"{steps} steps, t = {t}"


def run_is_alive(process: dict) -> bool:
    """Whether the process that wrote a "running" summary is still running (on this host).

    A recycled pid belongs to a process started at another time (``started``, :func:`process_start`).  A summary
    without it (written before 2026-12-05) is told by the program's command line, which names primordia for the
    command alone: a run from Python (a script, a Jupyter kernel) was called killed while it ran, and another
    process's --overwrite cleared its folder under it.
    """
    pid = process.get("pid")
    if not isinstance(pid, int) or process.get("host") != socket.gethostname() or pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    with contextlib.suppress(OSError, IndexError):  # a zombie (killed, not yet reaped) is not running
        if Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] in "ZX":
            return False
    started = process_start(pid)
    if process.get("started") is not None and started is not None:
        return started == process.get("started")
    with contextlib.suppress(OSError):  # a recycled pid belongs to some other program
        return b"primordia" in Path(f"/proc/{pid}/cmdline").read_bytes()
    return True


def process_start(pid: int) -> int | None:
    """When process ``pid`` started, in clock ticks since the boot (Linux's /proc; None elsewhere, or if it is gone):
    with the pid, it names one process, a recycled pid another."""
    with contextlib.suppress(OSError, IndexError, ValueError):
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19])  # field 22, starttime
    return None


def clear_run(directory: str | Path) -> None:
    """Remove the files of the run in ``directory`` (and nothing else)."""
    directory = Path(directory)
    for name in RUN_FILES:
        with contextlib.suppress(FileNotFoundError):
            (directory / name).unlink()
    for pattern in RUN_LEFTOVERS:
        for path in directory.glob(pattern):
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink(missing_ok=True)


def directory_problem(directory: str | Path) -> str | None:
    """Why ``directory`` cannot be a run's output directory (None: it is one, or can be created)."""
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        return f"the output directory {directory} is a file, not a directory"
    parent = nearest_existing(directory)
    if not parent.is_dir():
        return f"the output directory {directory} lies inside {parent}, which is a file"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"the output directory {directory} cannot be written ({parent} is not writable)"
    refusal = refusal_to_write(parent)
    if refusal is not None:
        return f"the output directory {directory} cannot be created in {parent} ({reason_of(refusal)})"
    return None
