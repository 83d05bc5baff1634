"""PNG pictures of vertex fields: :func:`plot_field`, :func:`plot_fields_grid`.

Drawn on a ``matplotlib.figure.Figure`` (no pyplot, so no GUI backend is chosen
and nothing global changes), saved atomically (:mod:`primordia.core.atomic_files`).
Serial: draw on one MPI rank.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from itertools import combinations
from pathlib import Path

import numpy as np

from primordia.core.atomic_files import atomic_path, writable_target
from primordia.core.errors import PrimordiaError
from primordia.core.mesh_data import MeshData
from primordia.core.meshes import height_text, top_face


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
    the x-axis label says "displacement x<scale>".  A 3D mesh is drawn as its upper
    surface (the boundary facets facing up: a slab's face z = z_max) seen from above.
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


#: Panels in a row of :func:`plot_fields_grid` unless its caller says otherwise (the seed's snapshot rows are four).
MAX_COLUMNS = 4


def default_columns(panels: int) -> int:
    """Columns for ``panels`` panels: one row up to :data:`MAX_COLUMNS`, then rows as even as they come."""
    rows = -(-panels // MAX_COLUMNS)
    return -(-panels // rows)  # 5: 3 + 2, 7: 4 + 3, 9: 3 + 3 + 3


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
    panels in one row up to four, and to rows of at most four, as even as they come,
    beyond (seven fields: four and three; a row of seven panels was 3,234 x 462 pixels,
    each panel too small to read in a page).  A 3D mesh gets two rows of panels: its top face seen
    from above, and the vertical slice through the middle of its y extent
    (the seed's Figure 5.5 shows both), cut through the cells whatever the mesh.
    """
    from matplotlib.figure import Figure

    if not fields:
        raise PrimordiaError(f"cannot plot {path}: no fields given")
    target = writable_target(path)
    views = [_plot_surface(mesh)] if mesh.gdim == 2 else [_plot_surface(mesh), _slice_surface(mesh)]
    panels = {}
    for view in views:
        for key, values in fields.items():
            label = key if len(views) == 1 else f"{key} ({view.label})"
            panels[label] = (view, _panel_data(mesh, view, key, values, (displacements or {}).get(key),
                                               displacement_scale))
    if shared_colour_scale:
        vmin, vmax = _colour_range([v for _, (_, v) in panels.values()], vmin, vmax)
    ncols = default_columns(len(fields)) if ncols is None else max(1, min(int(ncols), len(fields)))
    rows_per_view = -(-len(fields) // ncols)
    nrows = rows_per_view * len(views)
    # each view's rows as tall as its drawn extent needs (a slice of a thin slab is a thin strip)
    heights = [max(0.25, view.aspect(mesh)) for view in views for _ in range(rows_per_view)]
    width = 4.2 * ncols + (0.8 if shared_colour_scale else 0.0)
    figure = Figure(figsize=(width, 0.6 + 3.6 * sum(heights)), layout="constrained")
    axes = figure.subplots(nrows, ncols, squeeze=False, gridspec_kw={"height_ratios": heights})
    slots = [axes[v * rows_per_view + i // ncols, i % ncols] for v in range(len(views)) for i in range(len(fields))]
    used = {id(ax) for ax in slots}
    for ax in axes.ravel():
        if id(ax) not in used:
            ax.set_axis_off()
    image, axes_of_view = None, {}
    for ax, (label, (view, (triangulation, values))), key in zip(slots, panels.items(), list(fields) * len(views)):
        image = _draw_panel(ax, triangulation, values, label, cmap, vmin, vmax, view.axis_names)
        axes_of_view.setdefault(id(view), []).append(ax)
        if (displacements or {}).get(key) is not None:
            _draw_outline(ax, mesh, view)
            ax.set_xlabel(f"{view.axis_names[0]}    (displacement x{displacement_scale:g})")
        if not shared_colour_scale:
            figure.colorbar(image, ax=ax, shrink=0.85)
    for same_view in axes_of_view.values():
        _share_extent(same_view)
    if shared_colour_scale:
        figure.colorbar(image, ax=slots, shrink=0.85)
    if title:  # wrapped to the picture's width, about 10 characters an inch at 12 points: the title of a run
        # that failed holds its error, and ran off both sides of final_fields.png
        figure.suptitle(textwrap.fill(title, width=int(10 * width)))
    with atomic_path(target) as temporary:
        figure.savefig(temporary, format="png", dpi=110)
    return target


def _share_extent(axes) -> None:
    """One extent for the panels of one view, the union of theirs: a growing tissue's snapshots are drawn to one
    scale.  Each panel fitted to its own drew the smaller, earlier tissue larger, and the constrained layout,
    laying out equal-aspect panels of different shapes, put one panel's x label below the picture's edge."""
    lows, highs = np.array([[ax.get_xlim()[0], ax.get_ylim()[0]] for ax in axes]), np.array(
        [[ax.get_xlim()[1], ax.get_ylim()[1]] for ax in axes])
    for ax in axes:
        ax.set_xlim(lows[:, 0].min(), highs[:, 0].max())
        ax.set_ylim(lows[:, 1].min(), highs[:, 1].max())


class _View:
    """A drawn 2D surface of a mesh: its points, triangles (in the points' indices) and plane axes.

    Each point of the view is a weighted sum of mesh vertices (``weights``, sparse, one row per
    point): a vertex itself on a face of the mesh, a point of an edge on a cut through the cells.
    """

    def __init__(self, weights, triangles: np.ndarray, axes: tuple[int, int], label: str):
        self.weights, self.triangles, self.axes, self.label = weights, triangles, axes, label

    @classmethod
    def of_vertices(cls, vertices: np.ndarray, num_vertices: int, triangles, axes, label) -> "_View":
        """The view whose points are the mesh vertices ``vertices``."""
        from scipy.sparse import csr_matrix

        ones = np.ones(len(vertices))
        weights = csr_matrix((ones, (np.arange(len(vertices)), vertices)), shape=(len(vertices), num_vertices))
        return cls(weights, triangles, axes, label)

    def at_points(self, vertex_values: np.ndarray) -> np.ndarray:
        """Vertex values (one per mesh vertex, or rows of them) at the view's points: linear along edges."""
        return np.asarray(self.weights @ vertex_values)

    @property
    def axis_names(self) -> tuple[str, str]:
        return tuple("xyz"[a] for a in self.axes)

    def aspect(self, mesh: MeshData) -> float:
        """Height over width of the undeformed view."""
        extent = np.ptp(self.at_points(mesh.points[:, self.axes]), axis=0)
        return float(extent[1] / extent[0]) if extent[0] > 0 else 1.0


def _plot_surface(mesh: MeshData) -> _View:
    """The whole mesh (2D), or the upper surface of a 3D mesh (a slab's face z = z_max) seen from above."""
    if mesh.gdim == 2:
        return _View.of_vertices(np.arange(mesh.num_vertices), mesh.num_vertices, mesh.cells, (0, 1), "")
    vertices, triangles = top_face(mesh.points, mesh.cells)
    label = f"top, z = {height_text(mesh.points[vertices, 2])}"
    return _View.of_vertices(vertices, mesh.num_vertices, triangles, (0, 1), label)


def _slice_surface(mesh: MeshData) -> _View:
    """The cut of a 3D mesh by the vertex plane y = const nearest the middle of its y extent, seen along y.

    Every tetrahedron the plane crosses is cut into a triangle or a quadrilateral (two
    triangles) whose corners are vertices on the plane or points of edges crossing it, where
    fields are interpolated linearly (exact for P1).  A structured box is cut along its faces;
    an unstructured mesh, whose faces seldom lie in one plane, through its cells (drawing only
    the faces in the plane showed scattered triangles of it).
    """
    y = mesh.points[:, 1]
    tolerance = 1e-10 * np.ptp(mesh.points, axis=0).max()
    middle = 0.5 * (y.min() + y.max())
    level = float(y[np.argmin(np.abs(y - middle))])
    side = y - level
    side[np.abs(side) <= 10 * tolerance] = 0.0
    ends, triangles = _plane_cut(mesh.points[:, [0, 2]], mesh.cells, side)
    if len(triangles) == 0:
        raise PrimordiaError(f"cannot draw a slice of the mesh: no cell is cut by the plane y = {level:g}")
    from scipy.sparse import csr_matrix

    share = _edge_share(side, ends)
    rows = np.repeat(np.arange(len(ends)), 2)
    weights = csr_matrix((np.column_stack([1.0 - share, share]).ravel(), (rows, ends.ravel())),
                         shape=(len(ends), mesh.num_vertices))  # a vertex on the plane: 1 + 0, summed
    return _View(weights, triangles, (0, 2), f"slice y = {level:g}")


def _edge_share(side: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """t of each cut point (1 - t) x_a + t x_b on its edge (a, b) (rows of ``ends``): where ``side`` is 0; 0 for a
    vertex on the plane (a == b)."""
    a, b = np.asarray(ends).T
    return np.divide(side[a], side[a] - side[b], out=np.zeros(len(a)), where=a != b)


def _plane_cut(plane_xy: np.ndarray, cells: np.ndarray, side: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cut of tetrahedra by the plane side = 0: (its points as the two ends (a, b) of the edge they lie
    on, a == b for a vertex on the plane, numbered in the order the cells first meet them; its triangles in
    the points' indices, each once, sorted).

    ``side`` is the signed distance of each vertex from the plane (exactly 0 on it), ``plane_xy`` the
    vertices' coordinates in the plane, which order a quadrilateral's corners around its centre.  A cell
    has up to ten corner candidates (its four vertices on the plane, its six edges crossing it): three or
    four of them make its cut, fewer mean the plane touches it at a vertex or along an edge.
    """
    on = side[cells] == 0
    lowest, highest = side[cells].min(axis=1), side[cells].max(axis=1)
    crossed = cells[(lowest <= 0) & (highest >= 0) & (np.count_nonzero(on, axis=1) < 4)]
    pairs = np.array([(i, i) for i in range(4)] + list(combinations(range(4), 2)))
    a, b = crossed[:, pairs[:, 0]], crossed[:, pairs[:, 1]]
    corner = np.concatenate([side[a[:, :4]] == 0, side[a[:, 4:]] * side[b[:, 4:]] < 0], axis=1)
    count = np.count_nonzero(corner, axis=1)
    cut = count >= 3
    corner, count = corner[cut], count[cut]
    lo, hi = np.minimum(a[cut], b[cut]), np.maximum(a[cut], b[cut])
    # each cell's corners in its candidates' order, padded with its first corner to four
    slot = np.argsort(~corner, axis=1, kind="stable")[:, :4]
    slot = np.where(np.arange(4) < count[:, None], slot, slot[:, :1])
    rows = np.arange(len(slot))[:, None]
    ends = np.stack([lo[rows, slot], hi[rows, slot]], axis=-1)  # (cells, 4, 2)
    listed = ends[np.arange(4) < count[:, None]]  # every cell's corners in turn
    keys, first, point = np.unique(listed[:, 0] * len(side) + listed[:, 1], return_index=True,
                                   return_inverse=True)
    numbering = np.empty(len(keys), dtype=np.int64)
    numbering[np.argsort(first, kind="stable")] = np.arange(len(keys))
    ids = np.zeros(slot.shape, dtype=np.int64)
    ids[np.arange(4) < count[:, None]] = numbering[point]
    ids = np.where(np.arange(4) < count[:, None], ids, ids[:, :1])
    quad = count == 4  # its corners in turn around the centre, then two triangles
    t = _edge_share(side, ends[quad].reshape(-1, 2)).reshape(-1, 4, 1)
    xy = (1 - t) * plane_xy[ends[quad][..., 0]] + t * plane_xy[ends[quad][..., 1]]
    offset = xy - xy.mean(axis=1, keepdims=True)
    turn = np.argsort(np.arctan2(offset[..., 1], offset[..., 0]), axis=1)
    around = np.take_along_axis(ids[quad], turn, axis=1)
    triangles = np.concatenate([ids[~quad][:, :3], around[:, :3], around[:, [0, 2, 3]]])
    triangles = np.unique(np.sort(triangles, axis=1), axis=0).reshape(-1, 3)
    points = np.empty((len(keys), 2), dtype=np.int64)
    points[numbering] = np.column_stack([keys // len(side), keys % len(side)])
    return points, triangles


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
    xy = view.at_points(xy)
    return Triangulation(xy[:, 0], xy[:, 1], view.triangles), view.at_points(values)


def _draw_outline(ax, mesh: MeshData, view: _View) -> None:
    """The boundary of the undeformed view, in grey (where the tissue started)."""
    from matplotlib.collections import LineCollection

    edges = np.sort(view.triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    boundary = unique[counts == 1]
    xy = view.at_points(mesh.points[:, view.axes])
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
