"""Backend-neutral meshes: what a domain is before any backend sees it.

A :class:`MeshData` is plain numpy: vertex coordinates, simplex cells, and named
boundary facets.  Backends build their own mesh objects from it (dolfinx
distributes it over MPI ranks; scikit-fem wraps it), and every output writer
reads vertex values in the vertex order of the :class:`MeshData`, so results
from either backend line up entry by entry.

Generators (:func:`rectangle`, :func:`box`) and the meshio reader
(:func:`read_mesh`) live in :mod:`primordia.core.meshes`.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from primordia.core.errors import MeshError

#: meshio / VTK names of the simplex cells primordia supports, by topological dimension.
CELL_TYPES = {2: "triangle", 3: "tetra"}
FACET_TYPES = {2: "line", 3: "triangle"}


@dataclass
class MeshData:
    """A simplex mesh with named boundaries.

    ``points``: (n_vertices, gdim) float array; ``cells``: (n_cells, tdim + 1)
    int array of vertex indices; ``boundaries``: boundary name -> (n_facets,
    tdim) int array of the vertex indices of its facets.  Each boundary name
    gets a positive integer id (``boundary_ids``) used in facet tags.
    """

    points: np.ndarray
    cells: np.ndarray
    boundaries: dict[str, np.ndarray] = field(default_factory=dict)
    description: str = ""

    def __post_init__(self):
        self.points = _coordinates(self.points)
        self.cells = _vertex_indices(self.cells, "mesh cells")
        if self.points.ndim != 2 or self.points.shape[1] not in (2, 3):
            raise MeshError(f"mesh points must be an (n, 2) or (n, 3) array, got shape {self.points.shape}")
        if self.cells.ndim != 2 or self.cells.shape[1] != self.gdim + 1:
            raise MeshError(
                f"a {self.gdim}D mesh needs {CELL_TYPES[self.gdim]} cells with {self.gdim + 1} vertices, "
                f"got cells of shape {self.cells.shape}"
            )
        if len(self.cells) == 0:
            raise MeshError("the mesh has no cells")
        if self.cells.min() < 0 or self.cells.max() >= len(self.points):
            raise MeshError("mesh cells refer to vertices that do not exist")
        if not isinstance(self.boundaries, Mapping):
            raise MeshError(f"mesh boundaries must be a mapping of boundary name -> facets, got "
                            f"{type(self.boundaries).__name__}")
        if not isinstance(self.description, str):
            raise MeshError(f"a mesh's description must be a string, got {self.description!r}")
        self.boundaries = {_boundary_name(name): self._facets(name, facets) for name, facets in self.boundaries.items()}

    def _facets(self, name: str, facets) -> np.ndarray:
        """Boundary ``name``'s facets as an (n, tdim) array of vertex indices; any other shape is refused (an
        (n, 4) array in 2D was read as 2n facets)."""
        facets = _vertex_indices(facets, f"boundary '{name}'")
        if facets.size == 0:
            return facets.reshape(0, self.gdim)
        if facets.ndim != 2 or facets.shape[1] != self.gdim:
            raise MeshError(f"boundary '{name}' must be an (n, {self.gdim}) array of the vertex indices of its "
                            f"facets ({self.gdim} vertices each in {self.gdim}D), got shape {facets.shape}")
        return facets

    def __repr__(self) -> str:
        """Sizes and boundary names, not every coordinate (the dataclass repr printed the arrays)."""
        described = f", description={self.description!r}" if self.description else ""
        cells = "triangles" if self.gdim == 2 else "tetrahedra"
        return (f"MeshData({self.gdim}D, {len(self.points)} vertices, {len(self.cells)} {cells}, "
                f"boundaries={sorted(self.boundaries)}{described})")

    def remember_source(self, table: dict) -> "MeshData":
        """Record the ``[mesh]`` table that builds this mesh (a generator's or the reader's arguments).

        The resolved configuration of a run on this mesh then writes that table, and running from it
        reproduces the run, as long as the mesh is unchanged: points, cells and boundaries changed
        after this call (or a ``dataclasses.replace`` copy) make it an in-memory mesh again.
        """
        self._source = (dict(table), self._fingerprint())
        return self

    def source(self) -> dict | None:
        """The ``[mesh]`` table that builds this very mesh, or None (see :meth:`remember_source`)."""
        recorded = getattr(self, "_source", None)
        if recorded is None or recorded[1] != self._fingerprint():
            return None
        return dict(recorded[0])

    def fingerprint(self) -> str:
        """A digest of the points, cells and boundaries (hex): equal for the same mesh, bit for bit."""
        return self._fingerprint().hex()

    def _fingerprint(self) -> bytes:
        digest = hashlib.blake2b(digest_size=16)
        for array in (self.points, self.cells):
            digest.update(repr((array.dtype.str, array.shape)).encode())
            digest.update(np.ascontiguousarray(array).tobytes())
        for name, facets in self.boundaries.items():
            digest.update(repr((name, facets.shape)).encode())
            digest.update(np.ascontiguousarray(facets, dtype=np.int64).tobytes())
        return digest.digest()

    @property
    def gdim(self) -> int:
        return self.points.shape[1]

    @property
    def cell_type(self) -> str:
        return CELL_TYPES[self.gdim]

    @property
    def num_vertices(self) -> int:
        return len(self.points)

    @property
    def num_cells(self) -> int:
        return len(self.cells)

    @property
    def boundary_ids(self) -> dict[str, int]:
        """Facet tag of each named boundary (1, 2, ... in declaration order)."""
        return {name: i + 1 for i, name in enumerate(self.boundaries)}

    def boundary_id(self, name: str) -> int:
        try:
            return self.boundary_ids[name]
        except KeyError:
            known = ", ".join(self.boundaries) or "none"
            raise MeshError(f"unknown boundary '{name}' (this mesh has: {known})") from None

    def cell_volumes(self) -> np.ndarray:
        """Signed-free volumes (areas in 2D) of the cells."""
        x = self.points[self.cells]
        edges = x[:, 1:, :] - x[:, :1, :]
        factor = 2.0 if self.gdim == 2 else 6.0
        return np.abs(np.linalg.det(edges)) / factor


def _coordinates(points) -> np.ndarray:
    """Vertex coordinates as float64: real numbers only (complex ones lost their imaginary part, with a numpy
    warning; strings were one numpy traceback)."""
    try:
        array = np.asarray(points)
    except ValueError:  # a ragged list
        raise MeshError("mesh points must be an (n, 2) or (n, 3) array of coordinates, got rows of "
                        "different lengths") from None
    if array.dtype.kind not in "iuf":
        raise MeshError(f"mesh points must be real numbers, got an array of {array.dtype} "
                        f"(e.g. {array.ravel()[:1].tolist()})")
    return np.ascontiguousarray(array, dtype=np.float64)


def _vertex_indices(values, what: str) -> np.ndarray:
    """Vertex indices as int64: integers, or floats with integer values (as some readers give them); a
    fractional index was truncated to another vertex without a word."""
    try:
        array = np.asarray(values)
    except ValueError:
        raise MeshError(f"{what} must be an array of vertex indices, got rows of different lengths") from None
    if array.size and array.dtype.kind not in "iu":
        numeric = array.dtype.kind == "f"
        fractional = ~np.isfinite(array) | (array != np.round(array)) if numeric else None
        if not numeric or fractional.any():
            example = array[fractional][0] if numeric else array.ravel()[0]
            raise MeshError(f"{what} must be integer vertex indices, got {array.dtype} values such as {example!r}")
    return np.ascontiguousarray(array, dtype=np.int64)


def _boundary_name(name) -> str:
    """A boundary's name, as configs name it (``boundary = "top"``): a non-empty string."""
    if not isinstance(name, str) or not name.strip():
        raise MeshError(f"mesh boundary names must be non-empty strings (configs name boundaries by them), "
                        f"got {name!r}")
    return name
