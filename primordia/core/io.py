"""Crash-safe output files: field time series, scalar time series, pictures, JSON, TOML.

A run may die at any moment (killed job, full disk, diverged solver), and the
results it has already written must survive it whole.  So no output file is
ever written in place: every writer here writes a temporary file in the same
directory and ``os.replace``\\ s it over the final name, which POSIX makes
atomic.  A reader therefore sees either the previous complete file or the new
complete file, never a half-written one; a writer that fails removes its
temporary file and leaves the previous file untouched.

Writers are serial: call them on one MPI rank (rank 0, where backends gather
vertex values in :class:`~primordia.core.mesh.MeshData` vertex order).

* :func:`atomic_path`, :func:`atomic_write_text`, :func:`atomic_write_bytes`
  -- the building blocks;
* :class:`XdmfSeries` -- vertex fields over time, for ParaView and meshio;
* :class:`ScalarSeries` -- one row of named scalars per output time (netCDF);
* :func:`plot_field`, :func:`plot_fields_grid` -- PNG pictures of fields;
* :func:`write_json`, :func:`write_toml` -- run metadata and resolved configs.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import secrets
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping, Sequence
from datetime import date, datetime
from pathlib import Path

import numpy as np

from primordia.core.errors import PrimordiaError
from primordia.core.mesh import MeshData
from primordia.core.meshes import exterior_facets

# ---------------------------------------------------------------------------
# Atomic files
# ---------------------------------------------------------------------------


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it replaces ``path``.

    The temporary name keeps the suffix of ``path`` (libraries that choose a
    format by extension still work) and starts with a dot.  If the block
    raises, the temporary file is removed, ``path`` is left as it was and the
    exception propagates.  The parent directory must exist.
    """
    path = _writable_target(path)
    temporary = path.with_name(f".{path.stem}.tmp-{secrets.token_hex(4)}{path.suffix}")
    try:
        yield temporary
        if not temporary.is_file():
            raise PrimordiaError(f"cannot write {path}: nothing was written to its temporary file")
        _fsync_file(temporary)
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            temporary.unlink()
        raise
    _fsync_directory(path.parent)


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return ``path``."""
    with atomic_path(path) as temporary:
        temporary.write_bytes(data)
    return Path(path)


def atomic_write_text(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically; return ``path``."""
    return atomic_write_bytes(path, text.encode(encoding))


def _writable_target(path: str | Path) -> Path:
    """``path`` as a Path whose directory exists and which is not itself a directory."""
    if not isinstance(path, (str, os.PathLike)) or not str(path):
        raise PrimordiaError(f"cannot write to {path!r}: not a file path")
    path = Path(path)
    if path.is_dir():
        raise PrimordiaError(f"cannot write {path}: it is a directory")
    if not path.parent.is_dir():
        raise PrimordiaError(f"cannot write {path}: directory {path.parent} does not exist")
    if not os.access(path.parent, os.W_OK | os.X_OK):
        raise PrimordiaError(f"cannot write {path}: directory {path.parent} is not writable")
    return path


def _fsync_file(path: Path) -> None:
    """Flush ``path`` to disk so the rename never exposes an empty file after a power cut."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_directory(directory: Path) -> None:
    """Make a rename in ``directory`` durable (a no-op where directories cannot be opened)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _make_directory(directory: str | Path) -> Path:
    """``directory``, created (with parents) if missing; PrimordiaError if impossible."""
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise PrimordiaError(f"cannot use {directory} as an output directory: it is a file") from None
    except OSError as error:
        raise PrimordiaError(f"cannot create output directory {directory}: {error.strerror}") from None
    return directory


# ---------------------------------------------------------------------------
# XDMF time series of vertex fields
# ---------------------------------------------------------------------------

_XDMF_TOPOLOGY = {"triangle": "Triangle", "tetra": "Tetrahedron"}
_SAFE_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.+-]*$")


class XdmfSeries:
    """Vertex fields over time as ``<name>.xdmf`` plus HDF5 heavy data, for ParaView and meshio.

    Layout in ``directory``::

        fields.xdmf              the light XML index of all times written
        fields_h5/mesh.h5        /geometry (n_vertices, gdim), /topology (n_cells, gdim + 1)
        fields_h5/t000000.h5     one dataset per field at the first output time
        fields_h5/t000001.h5     ... one file per output time

    Each :meth:`write` writes its own time's ``.h5`` atomically, then
    atomically replaces the ``.xdmf`` with one listing every time written so
    far; the ``.xdmf`` on disk therefore only ever names complete heavy-data
    files, and a write costs the same at the 400th output as at the first.
    The XML follows dolfinx's ``XDMFFile`` layout (a ``mesh`` grid plus a
    temporal collection whose grids ``xi:include`` its topology and geometry),
    which ParaView's XDMF3 reader and ``meshio.xdmf.TimeSeriesReader`` read.

    Field values are vertex values in MeshData vertex order: shape
    (n_vertices,) for a scalar, (n_vertices, gdim) for a vector (written with
    3 components, z = 0 in 2D, so ParaView can warp by it), (n_vertices, gdim,
    gdim) for a tensor (written as 9 components).  Times must increase.

    A new series replaces any series of the same name in ``directory``: its
    first write removes the old ``.xdmf`` before writing new heavy data, so the
    old index is never read against new data.
    """

    def __init__(self, directory: str | Path, mesh: MeshData, name: str = "fields"):
        if not isinstance(name, str) or not _SAFE_NAME.match(name):
            raise PrimordiaError(f"XDMF series name must be letters, digits, '_', '.', '+' or '-', got {name!r}")
        self.directory = _make_directory(directory)
        self.mesh = mesh
        self.name = name
        self.path = self.directory / f"{name}.xdmf"
        self.heavy_directory = self.directory / f"{name}_h5"
        self._steps: list[tuple[float, dict[str, tuple[str, tuple[int, ...]]]]] = []

    @property
    def times(self) -> list[float]:
        """Output times written so far."""
        return [t for t, _ in self._steps]

    def write(self, t: float, fields: Mapping[str, np.ndarray]) -> None:
        """Add the vertex ``fields`` at time ``t``; on return the series on disk holds every time so far."""
        t = self._check_time(t)
        arrays = {name: self._vertex_array(name, values) for name, values in fields.items()}
        if not arrays:
            raise PrimordiaError(f"XDMF series {self.path}: no fields given at t = {t:g}")
        if not self._steps:
            self._start_series()
        step_file = f"t{len(self._steps):06d}.h5"
        _write_h5(self.heavy_directory / step_file, arrays)
        self._steps.append((t, {name: (step_file, array.shape) for name, array in arrays.items()}))
        atomic_write_bytes(self.path, self._xdmf_document())

    def state(self) -> dict:
        """What :meth:`restore` needs to continue this series (the times and datasets written so far)."""
        return {"steps": [[t, {name: [step_file, list(shape)] for name, (step_file, shape) in fields.items()}]
                          for t, fields in self._steps]}

    def restore(self, state: Mapping) -> None:
        """Continue from ``state``: the index on disk lists exactly its times again.

        Heavy-data files written after ``state`` stay on disk unlisted until the
        continued series writes over them.
        """
        self._steps = [(float(t), {name: (step_file, tuple(shape)) for name, (step_file, shape) in fields.items()})
                       for t, fields in state["steps"]]
        if not self._steps:
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()
            return
        if not (self.heavy_directory / "mesh.h5").is_file():
            raise PrimordiaError(f"XDMF series {self.path}: cannot continue, {self.heavy_directory / 'mesh.h5'} "
                                 f"is missing")
        atomic_write_bytes(self.path, self._xdmf_document())

    def _check_time(self, t) -> float:
        if isinstance(t, bool) or not isinstance(t, (int, float, np.number)) or not math.isfinite(t):
            raise PrimordiaError(f"XDMF series {self.path}: time must be a finite number, got {t!r}")
        t = float(t)
        if self._steps and t <= self._steps[-1][0]:
            raise PrimordiaError(
                f"XDMF series {self.path}: time {t:g} does not follow the last written time {self._steps[-1][0]:g}"
            )
        return t

    def _vertex_array(self, name: str, values) -> np.ndarray:
        """Values as float64 with vectors padded to 3 and tensors to 3 x 3 (flattened to 9)."""
        if not isinstance(name, str) or not _SAFE_NAME.match(name):
            raise PrimordiaError(f"XDMF field name must be letters, digits, '_', '.', '+' or '-', got {name!r}")
        array = np.asarray(values, dtype=np.float64)
        n, gdim = self.mesh.num_vertices, self.mesh.gdim
        if array.shape == (n,):
            return array
        if array.shape == (n, gdim):
            return _pad_components(array, (3,))
        if array.shape == (n, gdim, gdim):
            return _pad_components(array, (3, 3)).reshape(n, 9)
        raise PrimordiaError(
            f"field {name!r} has shape {array.shape}; expected vertex values of shape "
            f"({n},), ({n}, {gdim}) or ({n}, {gdim}, {gdim})"
        )

    def _start_series(self) -> None:
        """Remove an older series' index, then write the mesh heavy data."""
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()
        _make_directory(self.heavy_directory)
        _write_h5(
            self.heavy_directory / "mesh.h5",
            {"geometry": self.mesh.points, "topology": self.mesh.cells},
        )

    def _xdmf_document(self) -> bytes:
        """The whole XDMF index as bytes."""
        root = ET.Element("Xdmf", {"Version": "3.0", "xmlns:xi": "http://www.w3.org/2001/XInclude"})
        domain = ET.SubElement(root, "Domain")
        self._mesh_grid(domain)
        collection = ET.SubElement(
            domain, "Grid", Name=self.name, GridType="Collection", CollectionType="Temporal"
        )
        include = "xpointer(/Xdmf/Domain/Grid[@Name='mesh']/*[self::Topology or self::Geometry])"
        for t, fields in self._steps:
            grid = ET.SubElement(collection, "Grid", Name=f"{self.name}_{t!r}", GridType="Uniform")
            ET.SubElement(grid, "xi:include", xpointer=include)
            ET.SubElement(grid, "Time", Value=repr(t))
            for field_name, (step_file, shape) in fields.items():
                attribute = ET.SubElement(
                    grid, "Attribute", Name=field_name, AttributeType=_attribute_type(shape), Center="Node"
                )
                _data_item(attribute, f"{step_file}:/{field_name}", shape, np.float64, self.heavy_directory.name)
        ET.indent(root)
        return b'<?xml version="1.0"?>\n' + ET.tostring(root) + b"\n"

    def _mesh_grid(self, domain: ET.Element) -> None:
        grid = ET.SubElement(domain, "Grid", Name="mesh", GridType="Uniform")
        topology = ET.SubElement(
            grid,
            "Topology",
            TopologyType=_XDMF_TOPOLOGY[self.mesh.cell_type],
            NumberOfElements=str(self.mesh.num_cells),
        )
        heavy = self.heavy_directory.name
        _data_item(topology, "mesh.h5:/topology", self.mesh.cells.shape, np.int64, heavy)
        geometry = ET.SubElement(grid, "Geometry", GeometryType="XY" if self.mesh.gdim == 2 else "XYZ")
        _data_item(geometry, "mesh.h5:/geometry", self.mesh.points.shape, np.float64, heavy)


def _pad_components(array: np.ndarray, target: tuple[int, ...]) -> np.ndarray:
    """Zero-pad the component axes of ``array`` (vertex axis first) to ``target``."""
    padded = np.zeros((len(array), *target))
    padded[(slice(None), *(slice(0, k) for k in array.shape[1:]))] = array
    return padded


def _attribute_type(shape: tuple[int, ...]) -> str:
    return {1: "Scalar", 3: "Vector", 9: "Tensor"}[1 if len(shape) == 1 else shape[1]]


def _data_item(parent: ET.Element, reference: str, shape, dtype, heavy_directory: str) -> None:
    """An HDF ``DataItem`` pointing at ``<heavy_directory>/<file>:/<dataset>``."""
    number_type = "Int" if np.issubdtype(dtype, np.integer) else "Float"
    item = ET.SubElement(
        parent,
        "DataItem",
        DataType=number_type,
        Dimensions=" ".join(map(str, shape)),
        Format="HDF",
        Precision=str(np.dtype(dtype).itemsize),
    )
    item.text = f"{heavy_directory}/{reference}"


def _write_h5(path: Path, datasets: Mapping[str, np.ndarray]) -> None:
    """Write ``datasets`` into a new HDF5 file at ``path``, atomically."""
    import h5py

    with atomic_path(path) as temporary:
        with h5py.File(temporary, "w") as h5:
            for name, data in datasets.items():
                h5.create_dataset(name, data=data)


# ---------------------------------------------------------------------------
# Scalar time series (netCDF)
# ---------------------------------------------------------------------------


class ScalarSeries:
    """Named scalars per output time in one netCDF file (``series.nc``), rewritten atomically.

    ``append(t, {"m_integral": ..., "m_min": ..., "linear_iterations": ...})``
    adds a row; the file then has dimension ``time`` and one float64 variable
    per key.  A key first seen at a later row is NaN in the earlier rows, and
    a row that omits a known key is NaN there.  ``attrs`` maps a key (or
    ``"time"``) to netCDF attributes such as ``{"units": "dimensionless",
    "description": "integral of m over the domain"}``.

    Events that do not fall on the rows (e.g. every rejected time step) go to
    their own dimension: ``add_event("rejection", {"time": 0.4, "dt": 0.1,
    "reason": "..."})`` gives variables ``rejection_time``, ``rejection_dt`` and
    ``rejection_reason`` along the dimension ``rejection`` (numbers as float64,
    text as strings).
    """

    def __init__(self, path: str | Path, attrs: Mapping[str, Mapping[str, str]] | None = None):
        self.path = _writable_target(path)
        self._times: list[float] = []
        self._columns: dict[str, list[float]] = {}
        self._attrs: dict[str, dict[str, str]] = {}
        self._events: dict[str, list[dict]] = {}
        self._add_attrs(attrs)

    @property
    def times(self) -> list[float]:
        return list(self._times)

    def append(self, t: float, row: Mapping[str, float], attrs: Mapping[str, Mapping[str, str]] | None = None) -> None:
        """Add the scalars of ``row`` at time ``t`` and rewrite the file."""
        t = self._check_time(t)
        values = {key: _scalar(key, value) for key, value in row.items()}
        self._add_attrs(attrs)
        for key in values:
            self._columns.setdefault(key, [math.nan] * len(self._times))
        self._times.append(t)
        for key, column in self._columns.items():
            column.append(values.get(key, math.nan))
        self._write()

    def add_event(self, dimension: str, event: Mapping[str, float | str]) -> None:
        """Record one event along ``dimension`` (numbers and strings by name) and rewrite the file."""
        _variable_name(dimension)
        row = {}
        for key, value in event.items():
            _variable_name(f"{dimension}_{key}")
            row[key] = value if isinstance(value, str) else _scalar(f"{dimension}_{key}", value)
        self._events.setdefault(dimension, []).append(row)
        self._write()

    def dataset(self):
        """The series so far as an ``xarray.Dataset``."""
        import xarray as xr

        data_vars = {
            key: ("time", np.asarray(column, dtype=np.float64), self._attrs.get(key, {}))
            for key, column in self._columns.items()
        }
        for dimension, events in self._events.items():
            for key in dict.fromkeys(k for event in events for k in event):
                values = [event.get(key) for event in events]
                text = any(isinstance(v, str) for v in values)
                column = (np.array(["" if v is None else str(v) for v in values], dtype=str) if text
                          else np.array([math.nan if v is None else v for v in values], dtype=np.float64))
                data_vars[f"{dimension}_{key}"] = (dimension, column)
        coords = {"time": ("time", np.asarray(self._times, dtype=np.float64), self._attrs.get("time", {}))}
        return xr.Dataset(data_vars, coords=coords)

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
        dataset = self.dataset()
        with atomic_path(self.path) as temporary:
            dataset.to_netcdf(temporary, engine="scipy")

    def _check_time(self, t) -> float:
        if isinstance(t, bool) or not isinstance(t, (int, float, np.number)) or not math.isfinite(t):
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


# ---------------------------------------------------------------------------
# Pictures
# ---------------------------------------------------------------------------


def plot_field(
    path: str | Path,
    mesh: MeshData,
    values,
    title: str = "",
    displacement=None,
    displacement_scale: float = 1.0,
    cmap: str = "viridis",
    vmin: float | None = None,
    vmax: float | None = None,
) -> Path:
    """Draw vertex ``values`` as a smoothly shaded (gouraud) PNG with a colorbar.

    With ``displacement`` (n_vertices, gdim) the field is drawn on the
    deformed configuration ``points + displacement_scale * displacement`` and
    the x-axis label says "displacement x<scale>".  A 3D mesh is drawn as its top
    face (the boundary facets on z = z_max) seen from above.
    """
    return plot_fields_grid(
        path,
        mesh,
        {title: values},
        title="",
        displacements=None if displacement is None else {title: displacement},
        displacement_scale=displacement_scale,
        cmap=cmap,
        vmin=vmin,
        vmax=vmax,
        shared_colour_scale=False,
    )


def plot_fields_grid(
    path: str | Path,
    mesh: MeshData,
    fields: Mapping[str, np.ndarray],
    title: str = "",
    displacements: Mapping[str, np.ndarray] | None = None,
    displacement_scale: float = 1.0,
    cmap: str = "viridis",
    vmin: float | None = None,
    vmax: float | None = None,
    ncols: int | None = None,
    shared_colour_scale: bool = True,
) -> Path:
    """Draw several vertex fields side by side in one PNG, each panel titled by its key.

    Made for snapshot rows such as the seed's figures of m at t = 160, 280,
    400, 520: ``{"t = 160": m160, "t = 280": m280, ...}``.  With
    ``shared_colour_scale`` all panels use one colour range (``vmin``/``vmax``
    or the range of all values) and one colorbar; otherwise each panel gets
    its own.  ``displacements`` maps panel keys to (n_vertices, gdim)
    displacements: those panels are drawn on the deformed configuration, as in
    :func:`plot_field`, with the outline of the undeformed domain in grey and
    their x label saying "displacement x<scale>".  ``ncols`` defaults to all
    panels in one row.  A 3D mesh gets two rows of panels: its top face seen
    from above, and the vertical slice through the middle of its y extent
    (the seed's Figure 5.5 shows both).
    """
    from matplotlib.figure import Figure

    if not fields:
        raise PrimordiaError(f"cannot plot {path}: no fields given")
    target = _writable_target(path)
    views = [_plot_surface(mesh)] if mesh.gdim == 2 else [_plot_surface(mesh), _slice_surface(mesh)]
    panels = {}
    for view in views:
        for key, values in fields.items():
            label = key if len(views) == 1 else f"{key} ({view.label})"
            panels[label] = (view, _panel_data(mesh, view, key, values, (displacements or {}).get(key),
                                               displacement_scale))
    if shared_colour_scale:
        vmin, vmax = _colour_range([v for _, (_, v) in panels.values()], vmin, vmax)
    ncols = len(fields) if ncols is None else max(1, min(int(ncols), len(fields)))
    rows_per_view = -(-len(fields) // ncols)
    nrows = rows_per_view * len(views)
    # each view's rows as tall as its drawn extent needs (a slice of a thin slab is a thin strip)
    heights = [max(0.25, view.aspect(mesh)) for view in views for _ in range(rows_per_view)]
    figure = Figure(figsize=(4.2 * ncols + (0.8 if shared_colour_scale else 0.0), 0.6 + 3.6 * sum(heights)),
                    layout="constrained")
    axes = figure.subplots(nrows, ncols, squeeze=False, gridspec_kw={"height_ratios": heights})
    slots = [axes[v * rows_per_view + i // ncols, i % ncols] for v in range(len(views)) for i in range(len(fields))]
    used = {id(ax) for ax in slots}
    for ax in axes.ravel():
        if id(ax) not in used:
            ax.set_axis_off()
    image = None
    for ax, (label, (view, (triangulation, values))), key in zip(slots, panels.items(), list(fields) * len(views)):
        image = _draw_panel(ax, triangulation, values, label, cmap, vmin, vmax, view.axis_names)
        if (displacements or {}).get(key) is not None:
            _draw_outline(ax, mesh, view)
            ax.set_xlabel(f"{view.axis_names[0]}    (displacement x{displacement_scale:g})")
        if not shared_colour_scale:
            figure.colorbar(image, ax=ax, shrink=0.85)
    if shared_colour_scale:
        figure.colorbar(image, ax=slots, shrink=0.85)
    if title:
        figure.suptitle(title)
    with atomic_path(target) as temporary:
        figure.savefig(temporary, format="png", dpi=110)
    return target


class _View:
    """A drawn 2D surface of a mesh: its vertices, triangles (in local indices) and plane axes."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, axes: tuple[int, int], label: str):
        self.vertices, self.triangles, self.axes, self.label = vertices, triangles, axes, label

    @property
    def axis_names(self) -> tuple[str, str]:
        return tuple("xyz"[a] for a in self.axes)

    def aspect(self, mesh: MeshData) -> float:
        """Height over width of the undeformed view."""
        extent = np.ptp(mesh.points[self.vertices][:, self.axes], axis=0)
        return float(extent[1] / extent[0]) if extent[0] > 0 else 1.0


def _plot_surface(mesh: MeshData) -> _View:
    """The whole mesh (2D), or the top face z = z_max of a 3D mesh seen from above."""
    if mesh.gdim == 2:
        return _View(np.arange(mesh.num_vertices), mesh.cells, (0, 1), "")
    facets = exterior_facets(mesh.cells)
    z = mesh.points[:, 2]
    tolerance = 1e-10 * np.ptp(mesh.points, axis=0).max()
    top = facets[np.all(np.abs(z[facets] - z.max()) <= tolerance, axis=1)]
    vertices, local = np.unique(top, return_inverse=True)
    return _View(vertices, local.reshape(top.shape), (0, 1), f"top, z = {z.max():g}")


def _slice_surface(mesh: MeshData) -> _View:
    """The faces of a 3D mesh lying in the vertex plane y = const nearest the middle, seen along y.

    Structured boxes (and any mesh with a plane of faces there) are cut exactly; the
    plane is the one holding most vertices among those nearest the middle.
    """
    y = mesh.points[:, 1]
    tolerance = 1e-10 * np.ptp(mesh.points, axis=0).max()
    levels = np.unique(np.round(y / max(tolerance, 1e-300)) * tolerance)
    middle = 0.5 * (y.min() + y.max())
    level = levels[np.argmin(np.abs(levels - middle))]
    on_plane = np.abs(y - level) <= 10 * tolerance
    faces = np.sort(mesh.cells[:, [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]].reshape(-1, 3), axis=1)
    faces = np.unique(faces[np.all(on_plane[faces], axis=1)], axis=0)
    if len(faces) == 0:
        raise PrimordiaError(f"cannot draw a slice of the mesh: no cell faces lie in the plane y = {level:g}")
    vertices, local = np.unique(faces, return_inverse=True)
    return _View(vertices, local.reshape(faces.shape), (0, 2), f"slice y = {level:g}")


def _panel_data(mesh: MeshData, view: _View, key, values, displacement, scale):
    """A matplotlib Triangulation of the (deformed) view and the values on it."""
    from matplotlib.tri import Triangulation

    values = np.asarray(values, dtype=np.float64)
    if values.shape != (mesh.num_vertices,):
        raise PrimordiaError(
            f"cannot plot field {key!r}: expected {mesh.num_vertices} vertex values, got shape {values.shape}"
        )
    xy = mesh.points[:, view.axes]
    if displacement is not None:
        displacement = np.asarray(displacement, dtype=np.float64)
        if displacement.shape != (mesh.num_vertices, mesh.gdim):
            raise PrimordiaError(
                f"cannot plot field {key!r}: displacement must have shape "
                f"({mesh.num_vertices}, {mesh.gdim}), got {displacement.shape}"
            )
        xy = xy + scale * displacement[:, view.axes]
    xy = xy[view.vertices]
    return Triangulation(xy[:, 0], xy[:, 1], view.triangles), values[view.vertices]


def _draw_outline(ax, mesh: MeshData, view: _View) -> None:
    """The boundary of the undeformed view, in grey (where the tissue started)."""
    from matplotlib.collections import LineCollection

    edges = np.sort(view.triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    boundary = unique[counts == 1]
    xy = mesh.points[view.vertices][:, view.axes]
    ax.add_collection(LineCollection(xy[boundary], colors="0.45", linewidths=0.8, linestyles="--"))
    ax.autoscale_view()


def _colour_range(all_values: Sequence[np.ndarray], vmin, vmax) -> tuple[float | None, float | None]:
    """``vmin``/``vmax`` if given, else the finite range of all values."""
    finite = np.concatenate([v[np.isfinite(v)] for v in all_values])
    if finite.size == 0:
        return vmin, vmax
    return (float(finite.min()) if vmin is None else vmin), (float(finite.max()) if vmax is None else vmax)


def _draw_panel(ax, triangulation, values, title, cmap, vmin, vmax, axis_names=("x", "y")):
    image = ax.tripcolor(triangulation, values, shading="gouraud", cmap=cmap, vmin=vmin, vmax=vmax)
    ax.set_aspect("equal")
    ax.set_title(str(title))
    ax.set_xlabel(axis_names[0])
    ax.set_ylabel(axis_names[1])
    return image


# ---------------------------------------------------------------------------
# JSON and TOML
# ---------------------------------------------------------------------------


def write_json(path: str | Path, obj) -> Path:
    """Write ``obj`` as indented JSON with sorted keys, atomically.

    numpy scalars and arrays become numbers and lists, paths strings.
    Non-finite floats are written as ``NaN`` / ``Infinity`` (what Python's
    ``json`` reads back), since a diverged run's metrics must still be saved.
    """
    text = json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n"
    return atomic_write_text(path, text)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise PrimordiaError(f"cannot write {type(value).__name__} value {value!r} to JSON")


def write_toml(path: str | Path, mapping: Mapping) -> Path:
    """Write ``mapping`` as TOML, atomically.

    Values may be str, int, float (incl. inf / nan), bool, dates, lists of
    these, nested mappings (written as ``[tables]``) and lists of mappings
    (``[[arrays of tables]]``); numpy scalars and arrays are converted.
    """
    if not isinstance(mapping, Mapping):
        raise PrimordiaError(f"cannot write {path} as TOML: expected a mapping, got {type(mapping).__name__}")
    return atomic_write_text(path, "".join(_toml_table(mapping, ())))


def _toml_table(table: Mapping, prefix: tuple[str, ...]) -> Iterator[str]:
    """Lines of a TOML table: its plain keys first, then its sub-tables."""
    plain = {k: v for k, v in table.items() if not _is_table(v) and not _is_table_array(v)}
    for key, value in plain.items():
        yield f"{_toml_key(key)} = {_toml_value(value, prefix + (key,))}\n"
    for key, value in table.items():
        if _is_table(value):
            name = ".".join(map(_toml_key, prefix + (key,)))
            yield f"\n[{name}]\n"
            yield from _toml_table(value, prefix + (key,))
        elif _is_table_array(value):
            name = ".".join(map(_toml_key, prefix + (key,)))
            for item in value:
                yield f"\n[[{name}]]\n"
                yield from _toml_table(item, prefix + (key,))


def _is_table(value) -> bool:
    return isinstance(value, Mapping)


def _is_table_array(value) -> bool:
    return isinstance(value, (list, tuple)) and len(value) > 0 and all(isinstance(v, Mapping) for v in value)


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _toml_key(key) -> str:
    if not isinstance(key, str):
        raise PrimordiaError(f"TOML keys must be strings, got {key!r}")
    return key if _BARE_KEY.match(key) else _toml_string(key)


def _toml_string(text: str) -> str:
    """A TOML basic string with the escapes TOML requires."""
    escaped = []
    for char in text:
        if char in '"\\':
            escaped.append("\\" + char)
        elif char in "\b\t\n\f\r":
            escaped.append({"\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}[char])
        elif ord(char) < 0x20 or ord(char) == 0x7F:
            escaped.append(f"\\u{ord(char):04x}")
        else:
            escaped.append(char)
    return '"' + "".join(escaped) + '"'


def _toml_value(value, where: tuple[str, ...]) -> str:
    """One TOML value (inline), or a PrimordiaError naming the dotted key."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return _toml_float(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, Path):
        return _toml_string(str(value))
    if isinstance(value, (datetime, date)):
        return value.isoformat()
    if isinstance(value, (list, tuple)):
        if any(isinstance(item, Mapping) for item in value):
            return "[" + ", ".join(_inline_table(item, where) for item in value) + "]"
        return "[" + ", ".join(_toml_value(item, where) for item in value) + "]"
    raise PrimordiaError(f"cannot write {'.'.join(where)} = {value!r} to TOML ({type(value).__name__})")


def _inline_table(value, where: tuple[str, ...]) -> str:
    if not isinstance(value, Mapping):
        return _toml_value(value, where)
    items = ", ".join(f"{_toml_key(k)} = {_inline_table(v, where + (k,))}" for k, v in value.items())
    return "{" + items + "}"


def _toml_float(value: float) -> str:
    if math.isnan(value):
        return "nan"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    text = repr(value)
    return text if any(c in text for c in ".en") else text + ".0"
