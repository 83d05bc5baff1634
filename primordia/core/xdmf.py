"""Vertex fields over time as XDMF + HDF5, for ParaView and meshio (:class:`XdmfSeries`).

Serial: write on one MPI rank (rank 0, where backends gather vertex values in
:class:`~primordia.core.mesh_data.MeshData` vertex order).  Every file is written
atomically (:mod:`primordia.core.atomic_files`).
"""

from __future__ import annotations

import contextlib
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from primordia.core.atomic_files import atomic_write_bytes, make_directory
from primordia.core.errors import PrimordiaError
from primordia.core.mesh_data import MeshData
from primordia.core.validation import is_number


_XDMF_TOPOLOGY = {"triangle": "Triangle", "tetra": "Tetrahedron"}
#: XDMF dataset and series names: letters, digits and a few safe signs (they become file names).
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
        self.directory = make_directory(directory)
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
        for _, fields in self._steps:
            self._check_heavy_file(fields)
        atomic_write_bytes(self.path, self._xdmf_document())

    def _check_heavy_file(self, fields: Mapping[str, tuple[str, tuple[int, ...]]]) -> None:
        """Refuse to list a time whose heavy-data file is gone or damaged: a restart did so without a word, and
        the index it rewrote could not be opened (meshio: "truncated file"; ParaView reads none of its times)."""
        import h5py

        (step_file,) = {step_file for step_file, _ in fields.values()}
        path = self.heavy_directory / step_file
        if not path.is_file():
            raise PrimordiaError(f"XDMF series {self.path}: cannot continue, {path} is missing")
        try:
            with h5py.File(path, "r") as h5:
                damaged = [name for name, (_, shape) in fields.items() if name not in h5 or h5[name].shape != shape]
        except OSError as error:
            raise PrimordiaError(f"XDMF series {self.path}: cannot continue, {path} cannot be read "
                                 f"({str(error).splitlines()[0]})") from None
        if damaged:
            raise PrimordiaError(f"XDMF series {self.path}: cannot continue, {path} lacks {', '.join(damaged)}")

    def _check_time(self, t) -> float:
        if not is_number(t):
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
        make_directory(self.heavy_directory)
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
    """Write ``datasets`` into a new HDF5 file at ``path``, atomically.

    The file is made in memory and written by Python: HDF5 writing to a full disk itself left its file
    half-closed, and h5py's clean-up of it later crashed the process (a segmentation fault, MPI_ABORT
    under mpirun: example 1a at 20 x 20 into a 120 kB tmpfs), where a Python write fails with ENOSPC.
    One time's vertex fields are small beside the run (1a at 171^2: 29,584 vertices x 4 fields, 0.95 MB).
    """
    import io

    import h5py

    memory = io.BytesIO()
    with h5py.File(memory, "w") as h5:
        for name, data in datasets.items():
            h5.create_dataset(name, data=data)
    atomic_write_bytes(path, memory.getbuffer())
