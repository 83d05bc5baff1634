"""Mesh generators and the mesh-file reader, all returning :class:`MeshData`.

* :func:`rectangle` -- a structured triangle mesh of ``[x0, x1] x [y0, y1]``
  (the seed's domain is ``(0, 20)^2`` with 171 x 171 squares, i.e. 58,482
  triangles), boundaries ``left``/``right``/``bottom``/``top``;
* :func:`box` -- a structured tetrahedral mesh of a cuboid, each hexahedron
  split into 6 tetrahedra, boundaries ``left``/``right`` (x), ``bottom``/``top``
  (y), ``front``/``back`` (z);
* :func:`read_mesh` -- any linear triangle / tetrahedron mesh meshio can read;
  Gmsh physical names become named boundaries;
* :func:`mesh_from_config` -- one of the above from a TOML ``[mesh]`` table.

Lengths are in the units of the coordinates (dimensionless in the seed's
scaling).  Every returned cell is positively oriented (counter-clockwise
triangles, tetrahedra of positive signed volume), so backends may rely on it.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from primordia.core.errors import ConfigError, MeshError
from primordia.core.mesh_data import CELL_TYPES, FACET_TYPES, MeshData
from primordia.core.validation import is_integer, is_number

#: Ways of splitting each square of :func:`rectangle` (dolfinx's ``DiagonalType`` names).
DIAGONALS = ("right", "left", "crossed")

#: Boundary names of the generators: name -> (axis, "lower" or "upper" end).
RECTANGLE_SIDES = {"left": (0, 0), "right": (0, 1), "bottom": (1, 0), "top": (1, 1)}
BOX_SIDES = {**RECTANGLE_SIDES, "front": (2, 0), "back": (2, 1)}

#: Keys a ``[mesh]`` config table may hold, by mesh type (``type`` itself aside).
CONFIG_KEYS = {
    "rectangle": {"required": ("upper", "cells"), "optional": ("lower", "diagonal")},
    "box": {"required": ("upper", "cells"), "optional": ("lower",)},
    "file": {"required": ("path",), "optional": ()},
}

#: Lower-dimensional cell blocks a mesh file may carry besides its cells (Gmsh
#: keeps physical points and curves as ``vertex`` / ``line`` blocks).
_AUXILIARY_CELL_TYPES = {2: {"vertex", "line"}, 3: {"vertex", "line", "triangle"}}

#: XDMF topology types of the cells and of the facets an XDMF file of several grids is read for.
_XDMF_CELLS = {"Triangle": "triangle", "Tetrahedron": "tetra"}
_XDMF_FACETS = {"PolyLine": "line", "Triangle": "triangle"}

#: A triangle mesh with 3 coordinates is plane when its z spans at most this fraction of its x, y extent:
#: a plane mesh rotated or moved by another tool keeps z = constant only to round-off.
_FLAT_Z_FRACTION = 1e-12

#: A cell counts as degenerate below this fraction of (bounding-box diagonal)^tdim.
_DEGENERATE_VOLUME_FRACTION = 1e-13

#: Coordinates beyond this size (or a domain smaller than its inverse) are not a dimensionless
#: domain (seed section 2): squares and cubes of lengths would overflow or vanish in assembly.
ABSURD_COORDINATE = 1e50

#: What a run needs per cell at the very least (mesh, connectivity, one P1 field's matrices),
#: measured at a small fraction of example 1a's 10 kB per triangle: a mesh needing more than
#: the memory available is refused before anything is allocated.
MIN_BYTES_PER_CELL = {2: 2_000, 3: 4_000}


# ---------------------------------------------------------------------------
# Generators
# ---------------------------------------------------------------------------


def rectangle(
    lower: Sequence[float] = (0.0, 0.0),
    upper: Sequence[float] = (1.0, 1.0),
    cells: Sequence[int] = (10, 10),
    diagonal: str = "right",
) -> MeshData:
    """Triangle mesh of the rectangle ``[lower, upper]`` with ``nx x ny`` squares.

    ``diagonal`` splits each square like dolfinx's ``DiagonalType``: ``"right"``
    along the diagonal from its lower-left to upper-right corner, ``"left"``
    from lower-right to upper-left (2 triangles per square), ``"crossed"``
    through an extra centre vertex (4 triangles per square).  Vertices of the
    grid come first, x running fastest; ``crossed`` centres follow.
    """
    lower, upper = _check_extent(lower, upper, 2)
    nx, ny = _check_cell_counts(cells, 2)
    check_affordable((2 if diagonal != "crossed" else 4) * nx * ny, 2)
    if diagonal not in DIAGONALS:
        raise MeshError(f"unknown rectangle diagonal {diagonal!r} (choose one of: {', '.join(DIAGONALS)})")
    points = _grid_points(lower, upper, (nx, ny))
    corners = _square_corners(nx, ny)
    if diagonal == "crossed":
        points, triangles = _crossed_triangles(points, corners)
    else:
        triangles = _split_squares(corners, diagonal)
    description = f"rectangle {_extent_text(lower, upper)}, {nx} x {ny} squares, diagonal {diagonal}"
    return _structured_mesh(points, triangles, lower, upper, RECTANGLE_SIDES, description).remember_source(
        {"type": "rectangle", "lower": lower.tolist(), "upper": upper.tolist(), "cells": [nx, ny],
         "diagonal": diagonal})


def box(
    lower: Sequence[float] = (0.0, 0.0, 0.0),
    upper: Sequence[float] = (1.0, 1.0, 1.0),
    cells: Sequence[int] = (4, 4, 4),
) -> MeshData:
    """Tetrahedral mesh of the cuboid ``[lower, upper]`` with ``nx x ny x nz`` hexahedra.

    Each hexahedron is split into the 6 tetrahedra around its main diagonal
    (the Kuhn split, as dolfinx's ``create_box``); neighbouring hexahedra are
    split alike, so their shared faces match and the mesh is conforming.
    """
    lower, upper = _check_extent(lower, upper, 3)
    counts = _check_cell_counts(cells, 3)
    check_affordable(6 * math.prod(counts), 3)
    points = _grid_points(lower, upper, counts)
    tetrahedra = _kuhn_tetrahedra(*counts)
    description = f"box {_extent_text(lower, upper)}, {' x '.join(map(str, counts))} hexahedra"
    return _structured_mesh(points, tetrahedra, lower, upper, BOX_SIDES, description).remember_source(
        {"type": "box", "lower": lower.tolist(), "upper": upper.tolist(), "cells": [int(n) for n in counts]})


def _check_extent(lower, upper, gdim: int) -> tuple[np.ndarray, np.ndarray]:
    """Corners as float arrays of length ``gdim`` with ``upper > lower``, else MeshError."""
    lower = _real_vector(lower, gdim, "lower corner")
    upper = _real_vector(upper, gdim, "upper corner")
    for axis in range(gdim):
        if not upper[axis] > lower[axis]:
            raise MeshError(
                f"mesh upper corner must exceed the lower corner along {'xyz'[axis]}, "
                f"got lower {lower[axis]:g} and upper {upper[axis]:g}"
            )
    _check_coordinate_range(np.vstack([lower, upper]), "the mesh corners")
    return lower, upper


def _check_coordinate_range(points: np.ndarray, what: str) -> None:
    """MeshError unless coordinates are finite, below :data:`ABSURD_COORDINATE` and span more than its inverse."""
    if not np.all(np.isfinite(points)):
        raise MeshError(f"{what}: some coordinates are not finite (nan or inf)")
    largest = float(np.max(np.abs(points)))
    if largest > ABSURD_COORDINATE:
        raise MeshError(f"{what}: coordinates reach {largest:.3g}, beyond {ABSURD_COORDINATE:g}: lengths are "
                        f"dimensionless (seed section 2), and their squares would overflow; rescale the domain")
    extent = float(np.max(np.ptp(points, axis=0)))
    if extent < 1.0 / ABSURD_COORDINATE:
        raise MeshError(f"{what}: the domain spans only {extent:.3g}, below {1.0 / ABSURD_COORDINATE:g}: "
                        f"its cell volumes would vanish; rescale the domain")


def check_affordable(n_cells: int, tdim: int, per_cell: int | None = None, needing: str = "",
                     nodes: int = 1) -> None:
    """MeshError when a run on ``n_cells`` cells would need more memory than this machine has available.

    ``per_cell``: bytes a cell needs at least (default :data:`MIN_BYTES_PER_CELL`, whatever the model), for
    ``needing`` (e.g. "physics poroelastic_growth"); ``nodes``: machines of this one's memory the run spans.
    """
    per_cell = MIN_BYTES_PER_CELL[tdim] if per_cell is None else per_cell
    needed, available = n_cells * per_cell, nodes * available_memory()
    if needed > available:
        where = f"available on its {nodes} nodes" if nodes > 1 else "available"
        raise MeshError(f"a mesh of {n_cells:,} cells needs at least {_bytes_text(needed)} of memory"
                        f"{f' for {needing}' if needing else ''} ({per_cell // 1000} kB per cell), more than the "
                        f"{_bytes_text(available)} {where}: use fewer cells" + (" or more nodes" if needing else ""))


def available_memory() -> int:
    """Bytes of memory available to a new allocation (MemAvailable on Linux, else the physical memory)."""
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    with contextlib.suppress(OSError, ValueError, AttributeError):
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    return 1 << 62


def _bytes_text(count: int) -> str:
    for unit, size in (("EB", 1 << 60), ("PB", 1 << 50), ("TB", 1 << 40), ("GB", 1 << 30), ("MB", 1 << 20)):
        if count >= size:
            return f"{count / size:.3g} {unit}"
    return f"{count / 1024:.3g} kB"


def _real_vector(values, length: int, what: str) -> np.ndarray:
    """``values`` as a finite float array of ``length`` entries, else MeshError."""
    if isinstance(values, (str, bytes)) or not isinstance(values, (Sequence, np.ndarray)):
        raise MeshError(f"mesh {what} must be a list of {length} numbers, got {values!r}")
    if len(values) != length or any(not is_number(v) and not _non_finite(v) for v in values):
        raise MeshError(f"mesh {what} must be a list of {length} numbers, got {list(values)!r}")
    vector = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(vector)):
        raise MeshError(f"mesh {what} must be finite, got {list(values)!r}")
    return vector


def _non_finite(value) -> bool:
    """inf or NaN (a number, reported as not finite rather than as not a number)."""
    return isinstance(value, (float, np.floating)) and not math.isfinite(value)


def _check_cell_counts(cells, gdim: int) -> tuple[int, ...]:
    """Cell counts per axis as positive ints, else MeshError."""
    if isinstance(cells, (str, bytes)) or not isinstance(cells, (Sequence, np.ndarray)) or len(cells) != gdim:
        raise MeshError(f"mesh cells must be a list of {gdim} positive integers, got {cells!r}")
    counts = []
    for count in cells:
        if not is_integer(count) or count <= 0:
            raise MeshError(f"mesh cells must be a list of {gdim} positive integers, got {list(cells)!r}")
        counts.append(int(count))
    return tuple(counts)


def _extent_text(lower: np.ndarray, upper: np.ndarray) -> str:
    return " x ".join(f"[{a:g}, {b:g}]" for a, b in zip(lower, upper))


def _grid_points(lower: np.ndarray, upper: np.ndarray, counts: Sequence[int]) -> np.ndarray:
    """Vertices of a structured grid, x fastest, then y, then z."""
    axes = [np.linspace(lo, hi, n + 1) for lo, hi, n in zip(lower, upper, counts)]
    mesh = np.meshgrid(*axes, indexing="ij")
    # Fortran order makes the first axis (x) run fastest.
    return np.column_stack([coordinate.ravel(order="F") for coordinate in mesh])


def _square_corners(nx: int, ny: int) -> np.ndarray:
    """(nx*ny, 4) vertex indices of each square: lower-left, lower-right, upper-left, upper-right."""
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    v0 = (iy * (nx + 1) + ix).ravel()
    return np.column_stack([v0, v0 + 1, v0 + nx + 1, v0 + nx + 2])


def _split_squares(corners: np.ndarray, diagonal: str) -> np.ndarray:
    """Two counter-clockwise triangles per square, cut along the chosen diagonal."""
    v0, v1, v2, v3 = corners.T
    if diagonal == "right":
        first, second = (v0, v1, v3), (v0, v3, v2)
    else:
        first, second = (v0, v1, v2), (v1, v3, v2)
    return np.column_stack([np.column_stack(first), np.column_stack(second)]).reshape(-1, 3)


def _crossed_triangles(points: np.ndarray, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Four counter-clockwise triangles per square around a new centre vertex."""
    centres = points[corners].mean(axis=1)
    c = len(points) + np.arange(len(corners))
    v0, v1, v2, v3 = corners.T
    fan = [(v0, v1, c), (v1, v3, c), (v3, v2, c), (v2, v0, c)]
    triangles = np.column_stack([np.column_stack(t) for t in fan]).reshape(-1, 3)
    return np.vstack([points, centres]), triangles


def _kuhn_tetrahedra(nx: int, ny: int, nz: int) -> np.ndarray:
    """Six tetrahedra per hexahedron, all sharing its diagonal from corner 0 to corner 7."""
    ix, iy, iz = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    v0 = (iz * (ny + 1) * (nx + 1) + iy * (nx + 1) + ix).ravel(order="F")
    layer = (nx + 1) * (ny + 1)
    v = [v0, v0 + 1, v0 + nx + 1, v0 + nx + 2]
    v += [corner + layer for corner in v]
    split = [(0, 1, 3, 7), (0, 1, 7, 5), (0, 5, 7, 4), (0, 3, 2, 7), (0, 6, 4, 7), (0, 2, 6, 7)]
    return np.column_stack([np.column_stack([v[i] for i in tet]) for tet in split]).reshape(-1, 4)


def _structured_mesh(points, cells, lower, upper, sides: Mapping[str, tuple[int, int]], description) -> MeshData:
    """MeshData of a generated mesh, with its boundary facets named by the side they lie on."""
    volumes = np.abs(signed_volumes(points, cells))
    if not np.all(volumes > 0) or not np.all(np.isfinite(volumes)):
        raise MeshError(f"mesh {description}: cells so small or so large that their volumes are "
                        f"{'0' if not np.all(volumes > 0) else 'not finite'}; use fewer cells or rescale the domain")
    _check_not_degenerate(points, cells, f"mesh {description}")  # a side too thin for the others, as for a file
    cells = orient_cells(points, cells)
    facets = exterior_facets(cells)
    extent = np.max(upper - lower)
    boundaries = {}
    for name, (axis, end) in sides.items():
        plane = (lower, upper)[end][axis]
        on_plane = np.all(np.abs(points[facets, axis] - plane) <= 1e-12 * extent, axis=1)
        boundaries[name] = facets[on_plane]
    return MeshData(points, cells, boundaries, description=description)


# ---------------------------------------------------------------------------
# Topology helpers (also used by the plotting code in primordia.core.pictures)
# ---------------------------------------------------------------------------


def signed_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Signed cell volumes (areas in 2D); positive for counter-clockwise triangles."""
    x = points[cells]
    edges = x[:, 1:, :] - x[:, :1, :]
    return np.linalg.det(edges) / math.factorial(cells.shape[1] - 1)


def orient_cells(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """``cells`` with the last two vertices of each negatively oriented cell swapped."""
    cells = np.array(cells, dtype=np.int64)
    flip = signed_volumes(points, cells) < 0
    cells[flip, -2:] = cells[flip, :-3:-1]
    return cells


def top_face(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The upper surface of a tetrahedral mesh, seen from above: (its vertices, its triangles numbered in them).

    The exterior facets whose outward normal points up: the face z = z_max of a slab, and the whole
    sloped or curved top of a mesh that has no face at z_max (only a vertex or an edge there).
    """
    facets, opposite = _exterior_facets_and_opposite_vertices(cells)
    corner = points[facets[:, 0]]
    normal = np.cross(points[facets[:, 1]] - corner, points[facets[:, 2]] - corner)
    normal *= -np.sign(np.einsum("ij,ij->i", normal, points[opposite] - corner))[:, None]  # outward
    top = facets[normal[:, 2] > 1e-10 * np.linalg.norm(normal, axis=1)]  # the sides of a box: 0 exactly
    vertices, local = np.unique(top, return_inverse=True)
    return vertices, local.reshape(top.shape)


def height_text(z: np.ndarray) -> str:
    """The height of a flat top face (``1``), or the span of a sloped or curved one (``1 to 1.1``)."""
    low, high = f"{np.min(z):g}", f"{np.max(z):g}"
    return high if low == high else f"{low} to {high}"


def exterior_facets(cells: np.ndarray) -> np.ndarray:
    """Facets (vertex-index rows) that belong to exactly one cell, i.e. the mesh boundary."""
    return _exterior_facets_and_opposite_vertices(cells)[0]


def _exterior_facets_and_opposite_vertices(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The exterior facets, and of each the vertex of its cell that is not on it."""
    n_vertices = cells.shape[1]
    facets = np.vstack([np.delete(cells, i, axis=1) for i in range(n_vertices)])
    opposite = cells.T.ravel()  # facet i of each cell lies opposite its vertex i
    keys = np.sort(facets, axis=1)
    _, first, counts = np.unique(keys, axis=0, return_index=True, return_counts=True)
    exterior = np.sort(first[counts == 1])
    return facets[exterior], opposite[exterior]


# ---------------------------------------------------------------------------
# Reader
# ---------------------------------------------------------------------------


def read_mesh(path: str | Path) -> MeshData:
    """Read a linear triangle (2D) or tetrahedron (3D) mesh from any meshio format.

    Gmsh files (``.msh`` v2 or v4): facet blocks (``line`` in 2D, ``triangle``
    in 3D) tagged by ``gmsh:physical`` become named boundaries, named after
    the physical names in ``field_data`` (``boundary_<tag>`` when a tag has no
    name).  An XDMF file of dolfinx's ``XDMFFile`` (a mesh grid and a facet tags
    grid) gives each tag the boundary ``boundary_<tag>``.  Other formats load
    without boundaries unless their facet blocks carry such tags.  A 2D mesh
    stored with a constant z (normally 0) comes back with gdim 2.  Vertices no cell uses (e.g. Gmsh geometry points) are
    dropped and the rest renumbered; cells are reoriented to positive volume.
    """
    path = Path(path)
    raw = _read_with_meshio(path)
    if len(raw.points) == 0 or not any(len(block.data) for block in raw.cells):
        raise MeshError(f"mesh file {path} is empty (no points or no cells)")
    tdim = _topological_dimension(raw, path)
    cells = _cells_of_type(raw, CELL_TYPES[tdim])
    check_affordable(len(cells), tdim)  # before the checks and the run allocate more, as for a generated mesh
    points = _points_in_dimension(np.asarray(raw.points, dtype=np.float64), tdim, path)
    boundaries = _tagged_facets(raw, tdim, path)
    _check_vertex_indices(cells, boundaries, len(points), path)
    what = f"mesh file {path}"
    points, cells, boundaries = _drop_unused_points(points, cells, boundaries, what)
    check_mesh(MeshData(points, cells, boundaries), what)
    return MeshData(points, orient_cells(points, cells), boundaries, description=f"read from {path}").remember_source(
        {"type": "file", "path": str(path.expanduser().resolve())})


def _read_with_meshio(path: Path):
    """The meshio.Mesh in ``path``, or a one-line MeshError saying why not."""
    if not path.exists():
        raise MeshError(f"mesh file {path} does not exist")
    if not path.is_file():
        raise MeshError(f"mesh file {path} is not a file")
    reasons = []
    for file_format in _candidate_formats(path):
        mesh, reason = _try_meshio_format(path, file_format)
        if mesh is None and file_format == "xdmf":  # meshio reads one grid, dolfinx writes a mesh and its tags as two
            mesh, grids_reason = _xdmf_mesh_and_tags(path)
            reason = grids_reason or reason
        if mesh is not None:
            return mesh
        reasons.append(f"as {file_format}: {reason}")
    if _vtk_xml_without_cells(path):  # meshio's reason for it was "need at least one array to concatenate"
        raise MeshError(f"mesh file {path} is empty (no points or no cells)")
    raise MeshError(f"cannot read mesh file {path} ({'; '.join(reasons)})")


def _vtk_xml_without_cells(path: Path) -> bool:
    """Whether ``path`` is a VTK XML file whose pieces all declare no points or no cells."""
    import xml.etree.ElementTree as ET

    pieces = []
    try:
        for _, element in ET.iterparse(path, events=("start",)):
            if element.tag == "Piece":
                pieces.append(element.get("NumberOfPoints", "0") == "0" or element.get("NumberOfCells", "0") == "0")
    except (ET.ParseError, OSError):
        return False
    return bool(pieces) and all(pieces)


def _candidate_formats(path: Path) -> list[str]:
    """meshio format names for the file's extension, Gmsh first for ``.msh``."""
    import meshio

    formats = meshio.extension_to_filetypes.get(path.suffix.lower())
    if not formats:
        raise MeshError(f"cannot read mesh file {path}: meshio knows no mesh format with extension {path.suffix!r}")
    return sorted(formats, key=lambda name: name != "gmsh")


def _try_meshio_format(path: Path, file_format: str):
    """(mesh, None) if meshio reads ``path`` as ``file_format``, else (None, reason)."""
    import io

    import meshio

    chatter = io.StringIO()
    try:
        with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
            return meshio.read(path, file_format=file_format), None
    except SystemExit:
        # meshio prints a failed reader's message and exits the interpreter.
        return None, _one_line(chatter.getvalue()) or "not readable"
    except KeyError as error:  # a tag or name the file uses and does not define; its bare key said nothing
        key = f" {error.args[0]!r}" if error.args else ""
        return None, f"it refers to{key}, which it does not define (KeyError)"
    except Exception as error:  # readers raise many kinds for malformed files
        return None, _one_line(str(error)) or type(error).__name__


def _xdmf_mesh_and_tags(path: Path):
    """(the meshio.Mesh of an XDMF file that holds its mesh beside other grids, None), else (None, why not or None).

    dolfinx's ``XDMFFile`` writes a mesh and its facet tags as two grids (``write_mesh``,
    ``write_meshtags``), and a run's ``fields.xdmf`` its mesh beside a temporal collection.
    The one grid of cells with a geometry of its own is the mesh; a grid of its facets with
    values on them gives their tags (``gmsh:physical``: boundaries ``boundary_<tag>``).
    A file of one grid, or of no such mesh grid, gives (None, None): meshio's reason stands.
    """
    import xml.etree.ElementTree as ET

    import meshio

    try:
        all_grids = ET.parse(path).getroot().find("Domain").findall("Grid")
    except (OSError, AttributeError, ET.ParseError):
        return None, None
    grids = [grid for grid in all_grids
             if grid.get("GridType", "Uniform") == "Uniform" and grid.find("Topology") is not None]
    meshes = [grid for grid in grids
              if grid.find("Geometry") is not None and grid.find("Topology").get("TopologyType") in _XDMF_CELLS]
    if len(all_grids) < 2 or len(meshes) != 1:
        return None, None
    (mesh,) = meshes
    try:
        cell_type = _XDMF_CELLS[mesh.find("Topology").get("TopologyType")]
        facet_type = FACET_TYPES[3 if cell_type == "tetra" else 2]
        blocks = [(cell_type, _xdmf_data(mesh.find("Topology/DataItem"), path.parent))]
        tags = [np.zeros(len(blocks[0][1]), dtype=np.int64)]
        for grid in grids:
            topology, values = grid.find("Topology"), grid.find("Attribute[@Center='Cell']/DataItem")
            if grid is not mesh and values is not None and _XDMF_FACETS.get(topology.get("TopologyType")) == facet_type:
                blocks.append((facet_type, _xdmf_data(topology.find("DataItem"), path.parent)))
                tags.append(_xdmf_data(values, path.parent).ravel())
        points = _xdmf_data(mesh.find("Geometry/DataItem"), path.parent, np.float64)
        return meshio.Mesh(points, blocks, cell_data={"gmsh:physical": tags}), None
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:  # e.g. its HDF5 file is gone
        return None, _one_line(str(error)) or type(error).__name__


def _xdmf_data(item, folder: Path, dtype=np.int64) -> np.ndarray:
    """The array of an XDMF DataItem: in an HDF5 file (``file.h5:/dataset``, next to the XDMF file) or inline."""
    shape = [int(size) for size in item.get("Dimensions").split()]
    text = item.text.strip()
    if item.get("Format", "XML") == "HDF":
        import h5py

        file_name, dataset = text.rsplit(":", 1)
        with h5py.File(folder / file_name, "r") as h5:
            return np.asarray(h5[dataset], dtype=dtype).reshape(shape)
    return np.array(text.split(), dtype=np.float64).astype(dtype).reshape(shape)


def _one_line(text: str) -> str:
    """The first non-empty line of ``text``, whitespace collapsed."""
    lines = [" ".join(line.split()) for line in text.splitlines()]
    return next((line for line in lines if line and not line.startswith("Error")), "")


def _topological_dimension(raw, path: Path) -> int:
    """3 if the file holds tetrahedra, 2 if triangles; MeshError for other cell kinds."""
    types = {block.type for block in raw.cells if len(block.data)}
    tdim = 3 if "tetra" in types else 2 if "triangle" in types else None
    if tdim is None:
        found = ", ".join(sorted(types)) or "none"
        raise MeshError(f"mesh file {path} has no triangle or tetra cells (found: {found})")
    unsupported = types - {CELL_TYPES[tdim]} - _AUXILIARY_CELL_TYPES[tdim]
    if unsupported:
        raise MeshError(
            f"mesh file {path} mixes {CELL_TYPES[tdim]} cells with unsupported cell types "
            f"{', '.join(sorted(unsupported))} (only linear triangle or tetra meshes are supported)"
        )
    return tdim


def _cells_of_type(raw, cell_type: str) -> np.ndarray:
    return np.vstack([block.data for block in raw.cells if block.type == cell_type]).astype(np.int64)


def _points_in_dimension(points: np.ndarray, tdim: int, path: Path) -> np.ndarray:
    """Points with ``tdim`` coordinates: a flat 2D mesh loses its z = constant column (to round-off)."""
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshError(f"mesh file {path} has points of shape {points.shape}, expected 2 or 3 coordinates")
    if tdim == 3 and points.shape[1] != 3:
        raise MeshError(f"mesh file {path} has tetrahedra but only {points.shape[1]} coordinates per point")
    if tdim == 2 and points.shape[1] == 3:
        z, extent = points[:, 2], float(np.max(np.ptp(points[:, :2], axis=0)))
        if not np.all(np.isfinite(z)):  # x and y are checked with the vertices the cells use
            raise MeshError(f"mesh file {path}: some coordinates are not finite (nan or inf)")
        if np.ptp(z) > _FLAT_Z_FRACTION * extent:
            raise MeshError(f"mesh file {path} has triangles that are not in a z = constant plane (a surface mesh)")
        points = points[:, :2]
    return points


def _tagged_facets(raw, tdim: int, path: Path) -> dict[str, np.ndarray]:
    """Boundary name -> facets, from facet blocks tagged by ``gmsh:physical``, in tag order (0, no group, aside)."""
    tags = raw.cell_data.get("gmsh:physical")
    if tags is None:
        return {}
    facets_by_tag: dict[int, list[np.ndarray]] = {}
    for block, block_tags in zip(raw.cells, tags):
        if block.type != FACET_TYPES[tdim]:
            continue
        block_tags = np.asarray(block_tags).ravel()
        # tag 0 is no group: Gmsh's mark of an element in no physical group (a file saved with Mesh.SaveAll)
        for tag in np.unique(block_tags[block_tags != 0]):
            facets_by_tag.setdefault(int(tag), []).append(block.data[block_tags == tag])
    names = _physical_names(raw.field_data, dim=tdim - 1)
    _warn_of_shared_groups(raw, tdim, names, facets_by_tag, path)
    return {
        names.get(tag, f"boundary_{tag}"): np.vstack(facets_by_tag[tag]).astype(np.int64)
        for tag in sorted(facets_by_tag)
    }


def _warn_of_shared_groups(raw, tdim: int, names: dict, facets_by_tag: dict, path: Path) -> None:
    """One warning per named group whose facets are also in another: Gmsh 4.1 lets an entity be in several
    physical groups, a facet carries one boundary name here, and meshio keeps the entity's first group
    (a curve in "left" and "walls" was "left" only, and "walls" went missing without a word)."""
    from primordia.core.errors import warn

    for tag, name in sorted(names.items()):
        sets = raw.cell_sets.get(name)
        if sets is None or len(sets) != len(raw.cells):
            continue
        members = sum(len(indices) for block, indices in zip(raw.cells, sets) if block.type == FACET_TYPES[tdim])
        kept = sum(len(facets) for facets in facets_by_tag.get(tag, []))
        if members > kept:
            left = "is left out" if kept == 0 else f"keeps {kept}"
            warn(f"mesh file {path}: physical group '{name}' shares {members - kept} of its {members} facets with "
                 f"other groups; a facet carries one boundary name, its entity's first group's, so '{name}' {left}")


def _physical_names(field_data: Mapping, dim: int) -> dict[int, str]:
    """Physical tag -> name of the Gmsh physical groups of dimension ``dim``."""
    names = {}
    for name, value in field_data.items():
        value = np.asarray(value).ravel()
        if len(value) == 2 and int(value[1]) == dim:
            names[int(value[0])] = name
    return names


def _check_vertex_indices(cells, boundaries, n_points: int, path: Path) -> None:
    """MeshError if a cell or facet refers to a vertex the file does not hold."""
    for what, indices in [("cells", cells), *((f"boundary {name!r}", f) for name, f in boundaries.items())]:
        if len(indices) and (indices.min() < 0 or indices.max() >= n_points):
            raise MeshError(f"mesh file {path}: {what} refer to vertices that do not exist")


def _drop_unused_points(points, cells, boundaries, what: str):
    """Remove vertices no cell refers to, renumbering cells and boundary facets; MeshError for a facet on one.

    Such a facet is no side of a cell (a curve an exporter gave nodes of its own): dropping it with the
    vertices emptied its boundary, and a condition on it was lost without a word.
    """
    used = np.zeros(len(points), dtype=bool)
    used[cells.ravel()] = True
    if used.all():
        return points, cells, boundaries
    for name, facets in boundaries.items():
        off = np.count_nonzero(~used[facets].all(axis=1))
        if off:
            raise MeshError(f"{what}: boundary '{name}' has {_facets_text(off)} that no cell has as a side "
                            f"(on vertices no cell uses)")
    new_index = np.cumsum(used) - 1
    return points[used], new_index[cells], {name: new_index[facets] for name, facets in boundaries.items()}


def _check_boundary_facets(cells: np.ndarray, boundaries: Mapping[str, np.ndarray], what: str) -> None:
    """MeshError unless every named facet is an exterior facet of the cells, in one named boundary only.

    A boundary condition acts on exterior facets, and a facet carries one boundary tag: a
    tagged facet inside the domain, one that is no side of any cell, or one in two boundaries
    was kept by one backend and dropped (or given the other name) by the other, so the same
    file gave two results, or a traction was silently lost.
    """
    names = [name for name, facets in boundaries.items() if len(facets)]
    if not names:
        return
    cell_facets = np.sort(np.vstack([np.delete(cells, i, axis=1) for i in range(cells.shape[1])]), axis=1)
    named = [np.unique(np.sort(boundaries[name], axis=1), axis=0) for name in names]  # repeats are harmless
    _, ids, counts = np.unique(np.vstack([cell_facets, *named]), axis=0, return_inverse=True, return_counts=True)
    ids = ids.ravel()
    in_cells = np.bincount(ids[: len(cell_facets)], minlength=len(counts))
    owner = np.full(len(counts), -1)
    offset = len(cell_facets)
    for index, (name, facets) in enumerate(zip(names, named)):
        mine = ids[offset: offset + len(facets)]
        offset += len(facets)
        for count, problem in ((0, "that no cell has as a side"),
                               (2, "inside the domain (shared by two cells); boundary conditions act on the "
                                   "mesh's boundary only")):
            bad = np.count_nonzero(in_cells[mine] == count)
            if bad:
                raise MeshError(f"{what}: boundary '{name}' has {_facets_text(bad)} {problem}")
        shared = owner[mine] >= 0
        if shared.any():
            other = names[owner[mine][shared][0]]
            raise MeshError(f"{what}: {_facets_text(np.count_nonzero(shared))} in both boundary '{other}' "
                            f"and boundary '{name}' (a facet can carry one boundary name)")
        owner[mine] = index


def check_mesh(mesh: MeshData, what: str = "the model's MeshData") -> None:
    """The checks of a mesh file (:func:`read_mesh`) and of a mesh built by hand: one MeshError line.

    Finite coordinates of a sensible range, no duplicated vertices, no degenerate or overlapping cells, named
    facets that are exterior facets of the cells, each in one boundary, and every vertex in a cell.
    """
    _check_coordinate_range(mesh.points, what)
    _check_no_coincident_vertices(mesh.points, mesh.cells, what)
    _check_not_degenerate(mesh.points, mesh.cells, what)
    _check_not_overlapping(orient_cells(mesh.points, mesh.cells), what)
    _check_boundary_facets(mesh.cells, mesh.boundaries, what)
    _check_every_vertex_used(mesh.points, mesh.cells, what)


def _facets_text(count: int) -> str:
    return f"{count} facet" if count == 1 else f"{count} facets"


def _check_every_vertex_used(points: np.ndarray, cells: np.ndarray, what: str) -> None:
    """MeshError for a vertex no cell uses (a file's are dropped on reading, by :func:`_drop_unused_points`).

    Built by hand, one ran: the backends gave it the value 0, which the pictures then drew, their colour
    range stretched from m's 0.73-0.80 down to 0 and their extent out to the stray vertex.
    """
    used = np.zeros(len(points), dtype=bool)
    used[cells.ravel()] = True
    if not used.all():
        unused = np.flatnonzero(~used)
        where = ", ".join(f"{c:g}" for c in points[unused[0]])
        count = f"{len(unused)} {'vertex' if len(unused) == 1 else 'vertices'}"
        raise MeshError(f"{what} has {count} that no cell uses (vertex {unused[0]} at ({where})): "
                        f"leave them out of the points, and renumber the cells and boundaries")


def _check_no_coincident_vertices(points: np.ndarray, cells: np.ndarray, what: str) -> None:
    """MeshError if two vertices cells use share their coordinates (duplicated nodes).

    The cells on either side of such vertices are not joined there: the mesh is cut, and each
    field evolves on each side blind to the other, its zero-flux condition holding along the cut.
    """
    used = np.unique(cells)
    _, first, inverse = np.unique(points[used], axis=0, return_index=True, return_inverse=True)
    original = used[first[inverse.ravel()]]  # of each vertex, the first at its coordinates
    copies = np.flatnonzero(original != used)
    if len(copies):
        copy = used[copies[0]]
        where = ", ".join(f"{c:g}" for c in points[copy])
        raise MeshError(f"{what} has {len(copies)} {'vertex' if len(copies) == 1 else 'vertices'} at the "
                        f"coordinates of another (duplicated nodes, e.g. vertex {copy} at ({where}), as vertex "
                        f"{original[copies[0]]}): the cells on either side are not joined there; merge them")


def _check_not_degenerate(points: np.ndarray, cells: np.ndarray, what: str) -> None:
    """MeshError if any cell has (numerically) zero volume."""
    diagonal = np.linalg.norm(points.max(axis=0) - points.min(axis=0))
    volumes = np.abs(signed_volumes(points, cells))
    degenerate = np.count_nonzero(volumes <= _DEGENERATE_VOLUME_FRACTION * diagonal ** points.shape[1])
    if degenerate:
        kind = "area" if points.shape[1] == 2 else "volume"
        raise MeshError(f"{what} has {degenerate} degenerate (zero-{kind}) cells")


def _check_not_overlapping(cells: np.ndarray, what: str) -> None:
    """MeshError if cells overlap: a facet shared by more than two cells, or two cells on the same side of one.

    Each facet of a positively oriented cell inherits an orientation (the boundary
    operator: facet i, without vertex i, has sign (-1)^i); the two cells of a
    conforming mesh that share a facet induce opposite orientations on it.  A
    duplicated cell, or a fold where one cell lies on top of its neighbour, gives
    equal orientations (or a facet shared three or more times).
    """
    facets, signs = [], []
    for i in range(cells.shape[1]):
        facet = np.delete(cells, i, axis=1)
        inversions = sum((facet[:, a] > facet[:, b]).astype(np.int64)
                         for a in range(facet.shape[1]) for b in range(a + 1, facet.shape[1]))
        facets.append(np.sort(facet, axis=1))
        signs.append((-1) ** i * (1 - 2 * (inversions % 2)))
    keys = np.vstack(facets)
    signs = np.concatenate(signs)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    orientation = np.bincount(inverse, weights=signs, minlength=len(counts))
    shared = counts[inverse] == 2
    folded = np.unique(inverse[shared & (orientation[inverse] != 0)])
    crowded = np.flatnonzero(counts > 2)
    if len(folded) or len(crowded):
        cell_of = np.tile(np.arange(len(cells)), cells.shape[1])
        bad = np.concatenate([folded, crowded])
        example = np.unique(cell_of[np.isin(inverse, bad)])[:2]
        raise MeshError(f"{what} has overlapping cells ({len(bad)} facets shared by cells on the same "
                        f"side or by more than two cells, e.g. cells {', '.join(map(str, example))}): "
                        f"a duplicated or folded element")


# ---------------------------------------------------------------------------
# Config
# ---------------------------------------------------------------------------


def mesh_from_config(table: Mapping, base_dir: str | Path = ".") -> MeshData:
    """Build the mesh a config ``[mesh]`` table describes.

    ``{type = "rectangle", lower = [0, 0], upper = [20, 20], cells = [171, 171], diagonal = "right"}``,
    ``{type = "box", lower = [0, 0, 0], upper = [1, 1, 1], cells = [4, 4, 4]}`` or
    ``{type = "file", path = "mesh.msh"}`` (a relative path is taken from
    ``base_dir``, normally the config file's directory).  ``lower`` defaults to
    the origin and ``diagonal`` to ``"right"``; ``upper`` and ``cells`` are required.
    """
    if not isinstance(table, Mapping):
        raise ConfigError(f"[mesh] must be a table, got {table!r}")
    mesh_type = table.get("type")
    if mesh_type == "in-memory":
        raise ConfigError("[mesh] type 'in-memory' is the description of a mesh made in Python, which a config "
                          "cannot rebuild: give [mesh] as type = \"rectangle\", \"box\" or \"file\"")
    if not isinstance(mesh_type, str) or mesh_type not in CONFIG_KEYS:
        raise ConfigError(f"[mesh] type must be one of {', '.join(map(repr, CONFIG_KEYS))}, got {mesh_type!r}")
    _check_config_keys(table, mesh_type)
    if mesh_type == "file":
        return read_mesh(_config_path(table["path"], base_dir))
    gdim = 2 if mesh_type == "rectangle" else 3
    lower = table.get("lower", [0] * gdim)
    _check_config_list(table, "lower", lower, gdim, "numbers")
    _check_config_list(table, "upper", table["upper"], gdim, "numbers")
    _check_config_list(table, "cells", table["cells"], gdim, "positive integers")
    if mesh_type == "rectangle":
        return rectangle(lower, table["upper"], table["cells"], table.get("diagonal", "right"))
    return box(lower, table["upper"], table["cells"])


def _check_config_keys(table: Mapping, mesh_type: str) -> None:
    keys = CONFIG_KEYS[mesh_type]
    allowed = {"type", *keys["required"], *keys["optional"]}
    for key in table:
        if key not in allowed:
            raise ConfigError(
                f"[mesh] unknown key {key!r} for type {mesh_type!r} (allowed: {', '.join(sorted(allowed))})"
            )
    for key in keys["required"]:
        if key not in table:
            raise ConfigError(f"[mesh] of type {mesh_type!r} needs {key!r}")


def _check_config_list(table: Mapping, key: str, value, length: int, kind: str) -> None:
    """ConfigError unless ``value`` is a list of ``length`` entries (the generators check the entries)."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != length:
        raise ConfigError(f"[mesh] {key} must be a list of {length} {kind} for type {table['type']!r}, got {value!r}")


def _config_path(value, base_dir: str | Path) -> Path:
    if not isinstance(value, str) or not value:
        raise ConfigError(f"[mesh] path must be a file name, got {value!r}")
    path = Path(value).expanduser()
    return path if path.is_absolute() else Path(base_dir) / path
