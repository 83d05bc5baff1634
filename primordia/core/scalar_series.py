"""Named scalars per output time in one netCDF file (:class:`ScalarSeries`).

Serial: write on one MPI rank.  The file is rewritten atomically at every row
(:mod:`primordia.core.atomic_files`), or at most every ``min_interval`` seconds.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from primordia.core.atomic_files import atomic_path, writable_target
from primordia.core.errors import PrimordiaError
from primordia.core.signals import INTERRUPTS
from primordia.core.validation import is_number

#: netCDF variable names primordia writes: letters, digits and a few safe signs.
_SAFE_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.+-]*$")


class ScalarSeries:
    """Named scalars per output time in one netCDF file (``series.nc``), rewritten atomically.

    ``append(t, {"m_integral": ..., "m_min": ..., "linear_iterations": ...})``
    adds a row; the file then has dimension ``time`` and one float64 variable
    per key.  A key first seen at a later row is NaN in the earlier rows, and
    a row that omits a known key is NaN there.  ``attrs`` maps a key (or
    ``"time"``) to netCDF attributes such as ``{"units": "dimensionless",
    "description": "integral of m over the domain"}``; ``global_attrs`` are the file's
    own (``title``, ``source``, ...).

    Events that do not fall on the rows (e.g. every rejected time step) go to
    their own dimension: ``add_event("rejection", {"time": 0.4, "dt": 0.1,
    "reason": "..."})`` gives variables ``rejection_time``, ``rejection_dt`` and
    ``rejection_reason`` along the dimension ``rejection`` (numbers as float64,
    text as strings).

    With ``min_interval`` > 0 a row appended less than that many seconds after the last
    rewrite waits in memory for the next row or event, or for :meth:`flush`: a run that
    records a row every few milliseconds does not spend its time rewriting the file
    (example 1a's 261 rows of 21 columns: 4.8 ms a rewrite, 7.8 ms when xarray wrote them; it records a
    row every 10 steps of 20 ms).  The file
    is still whole at every moment; it lacks at most the rows of the last ``min_interval``
    seconds and of the time to the next row (a slow run, whose rows come further apart,
    writes each at once).
    """

    def __init__(self, path: str | Path, attrs: Mapping[str, Mapping[str, str]] | None = None,
                 min_interval: float = 0.0, global_attrs: Mapping[str, str] | None = None):
        self.path = writable_target(path)
        self.global_attrs = {str(k): str(v) for k, v in (global_attrs or {}).items()}
        self.min_interval = float(min_interval)
        self._written_at: float | None = None  # time.monotonic() of the last rewrite
        self._pending = False  # rows appended since the last rewrite
        self._times: list[float] = []
        self._columns: dict[str, list[float]] = {}
        self._attrs: dict[str, dict[str, str]] = {}
        self._events: dict[str, list[dict]] = {}
        self._add_attrs(attrs)

    @property
    def times(self) -> list[float]:
        return list(self._times)

    @property
    def written_at(self) -> float | None:
        """``time.monotonic()`` of the file's last rewrite (None before the first)."""
        return self._written_at

    def append(self, t: float, row: Mapping[str, float], attrs: Mapping[str, Mapping[str, str]] | None = None) -> None:
        """Add the scalars of ``row`` at time ``t`` and rewrite the file."""
        t = self._check_time(t)
        values = {key: _scalar(key, value) for key, value in row.items()}
        self._add_attrs(attrs)
        # whole or not at all: a second Ctrl-C raises where the program is, and one between the time and its
        # columns left rows of different lengths in the stop's checkpoint (its restart disabled the series)
        with INTERRUPTS.mode_of("shielded"):
            for key in values:
                self._columns.setdefault(key, [math.nan] * len(self._times))
            self._times.append(t)
            for key, column in self._columns.items():
                column.append(values.get(key, math.nan))
        if self._written_at is not None and time.monotonic() - self._written_at < self.min_interval:
            self._pending = True
        else:
            self._write()

    def flush(self) -> None:
        """Rewrite the file now if rows wait in memory (see ``min_interval``)."""
        if self._pending:
            self._write()

    def add_event(self, dimension: str, event: Mapping[str, float | str]) -> None:
        """Record one event along ``dimension`` (numbers and strings by name) and rewrite the file."""
        if _variable_name(dimension) == "time":
            raise PrimordiaError("scalar series: 'time' is the dimension of the rows, not of events")
        row = {}
        for key, value in event.items():
            _variable_name(f"{dimension}_{key}")
            row[key] = value if isinstance(value, str) else _scalar(f"{dimension}_{key}", value)
        self._events.setdefault(dimension, []).append(row)
        self._write()

    def dataset(self):
        """The series so far as an ``xarray.Dataset`` (what reading ``series.nc`` with xarray gives)."""
        import xarray as xr

        variables = self._variables()
        time = variables.pop("time")
        return xr.Dataset(variables, coords={"time": time}, attrs=self.global_attrs)

    def _variables(self) -> dict[str, tuple[str, np.ndarray, dict]]:
        """Every variable of the file: name -> (dimension, values, attributes), the time coordinate first."""
        variables = {"time": ("time", np.asarray(self._times, dtype=np.float64), self._attrs.get("time", {}))}
        for key, column in self._columns.items():
            variables[key] = ("time", np.asarray(column, dtype=np.float64), self._attrs.get(key, {}))
        for dimension, events in self._events.items():
            for key in dict.fromkeys(k for event in events for k in event):
                values = [event.get(key) for event in events]
                text = any(isinstance(v, str) for v in values)
                column = (np.array(["" if v is None else str(v) for v in values], dtype=str) if text
                          else np.array([math.nan if v is None else v for v in values], dtype=np.float64))
                variables[f"{dimension}_{key}"] = (dimension, column, self._attrs.get(f"{dimension}_{key}", {}))
        return variables

    def state(self) -> dict:
        """The rows and events so far (what :meth:`restore` takes back)."""
        return {"times": list(self._times), "columns": {k: list(v) for k, v in self._columns.items()},
                "attrs": {k: dict(v) for k, v in self._attrs.items()},
                "events": {k: [dict(e) for e in v] for k, v in self._events.items()}}

    def restore(self, state: Mapping) -> None:
        """Continue from ``state`` and rewrite the file: rows written after it are gone."""
        self._times = [float(t) for t in state["times"]]
        self._columns = {k: [float(x) for x in v] for k, v in state["columns"].items()}
        self._attrs = {k: dict(v) for k, v in state["attrs"].items()}
        self._events = {k: [dict(e) for e in v] for k, v in state.get("events", {}).items()}
        self._write()

    def _write(self) -> None:
        variables = self._variables()
        with atomic_path(self.path) as temporary:
            _write_netcdf(temporary, variables, self.global_attrs)
        self._written_at, self._pending = time.monotonic(), False

    def _check_time(self, t) -> float:
        if not is_number(t):
            raise PrimordiaError(f"scalar series {self.path}: time must be a finite number, got {t!r}")
        t = float(t)
        if self._times and t <= self._times[-1]:
            raise PrimordiaError(
                f"scalar series {self.path}: time {t:g} does not follow the last written time {self._times[-1]:g}"
            )
        return t

    def _add_attrs(self, attrs) -> None:
        for key, key_attrs in (attrs or {}).items():
            if not isinstance(key_attrs, Mapping):
                raise PrimordiaError(f"scalar series attributes of {key!r} must be a mapping, got {key_attrs!r}")
            self._attrs.setdefault(_variable_name(key), {}).update({str(k): str(v) for k, v in key_attrs.items()})


def _write_netcdf(path: Path, variables: Mapping[str, tuple[str, np.ndarray, dict]],
                  global_attrs: Mapping[str, str] | None = None) -> None:
    """NetCDF3 with 64-bit offsets, as xarray's scipy engine writes a Dataset of these variables: float64
    with a NaN ``_FillValue``, text as UTF-8 characters along a ``string<N>`` dimension.

    A series is a flat table, so the file is written with scipy's NetCDF writer (the one xarray's scipy
    engine calls) without building an xarray Dataset.  xarray's own write of the first row cost 1.3-1.4 s
    of every run process: importing xarray, pandas and dask, and, in ``to_netcdf``, dask.distributed to
    look for a client.  ``primordia run`` of the 8 x 8 small config (five steps) took 3.4-3.6 s, now
    2.0-2.2.  The results are read with xarray as before, and the tests hold the file to what xarray
    itself writes (values, attributes and encodings).
    """
    from scipy.io import netcdf_file

    with netcdf_file(str(path), "w", version=2) as target:
        # the table itself: "version" or "mode" would be the file's
        target._attributes.update({key: _attribute(value) for key, value in (global_attrs or {}).items()})
        for name, (dimension, values, attrs) in variables.items():
            if dimension not in target.dimensions:
                target.createDimension(dimension, len(values))
            if values.dtype.kind == "U":
                encoded = np.char.encode(values, "utf-8")  # bytes, at least one per entry ("" is b"")
                width = encoded.dtype.itemsize
                characters = f"string{width}"
                if characters not in target.dimensions:
                    target.createDimension(characters, width)
                variable = target.createVariable(name, "c", (dimension, characters))
                variable[:] = encoded.view("S1").reshape(len(values), width)
                variable._attributes["_Encoding"] = "utf-8"
            else:
                variable = target.createVariable(name, "d", (dimension,))
                variable[:] = values
                variable._attributes["_FillValue"] = np.float64(np.nan)
            # into the attribute table itself: setattr would also let an attribute named "shape" hide the variable's
            for key, value in attrs.items():
                variable._attributes[key] = _attribute(value)


def _attribute(value):
    """Text as UTF-8 bytes, as xarray writes it: scipy's writer encodes a str as ASCII and fails on "ü"."""
    return value.encode("utf-8") if isinstance(value, str) else value


def _variable_name(key) -> str:
    if not isinstance(key, str) or not _SAFE_NAME.match(key):
        raise PrimordiaError(f"scalar series name must be letters, digits, '_', '.', '+' or '-', got {key!r}")
    return key


def _scalar(key, value) -> float:
    """``value`` as a float, or a one-line PrimordiaError naming ``key``."""
    if _variable_name(key) == "time":
        raise PrimordiaError("scalar series: 'time' is the series dimension, not a column name")
    if isinstance(value, (bool, np.bool_)):
        return float(value)
    if np.ndim(value) != 0:
        raise PrimordiaError(f"scalar series value {key!r} must be a single number, got shape {np.shape(value)}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise PrimordiaError(f"scalar series value {key!r} must be a number, got {value!r}") from None
