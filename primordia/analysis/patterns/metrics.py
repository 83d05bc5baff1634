"""Pattern metrics of one scalar field: wavelength, spots, spacing, hexagonal order, kind.

A snapshot of one species is given at the vertices of a triangle mesh.  It is
first interpolated linearly onto a uniform grid (:func:`to_grid`); everything
else works on that grid:

* :func:`radial_spectrum` -- the radially averaged power spectrum |F(k)|^2 of
  the field minus its mean (Hann-windowed, zero-padded FFT);
  :func:`dominant_wavenumber` -- its peak, and how far the peak stands above
  the spectrum around it (``prominence``: ~1-5 for noise or a front, >> 10
  for a pattern); NaN, and prominence 1, where the spectrum has no peak (it
  falls across the whole band: a front, a gradient, a lone spot); a peak
  stands above what the long waves leak into the band (:func:`long_wave_leakage`);
* :func:`find_blobs` -- connected regions above ``level`` (halfway between the
  field's minimum and maximum).  A region is a *spot* if it is compact: its
  second-moment aspect ratio is below :data:`MAX_SPOT_ASPECT` and its area
  below one dominant wavelength squared.  Its centre is the position of its
  maximum, refined between pixels by a parabola (a spot cut in half by a
  zero-flux wall keeps its centre on the wall, where a centroid would not);
* :func:`nearest_neighbour_distances` -- spacing between spot centres;
* :func:`hexatic_order` -- |psi_6| = |mean over Delaunay neighbours of
  exp(6 i theta)| per spot, averaged over the spots away from the edge of the
  spot set and of the domain (1 hexagonal, ~0.07 square, ~0.36 random);
* :func:`orientation_order` -- nematic order of the field's gradient
  (1 for parallel stripes, ~0 for isotropic patterns);
* :func:`classify` -- none / spots / stripes / labyrinth from those numbers.

:func:`pattern_metrics` runs them all.  Lengths are in the units of the mesh
coordinates (the seed's dimensionless length); wavenumbers are 2 pi / length.
For a hexagonal lattice of spots at nearest-neighbour distance ``a`` the
spectrum peaks at k = 4 pi / (sqrt(3) a): the dominant wavelength is the
distance between rows of spots, sqrt(3) a / 2, not ``a``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.fft
from scipy import ndimage
from scipy.spatial import ConvexHull, Delaunay, QhullError, cKDTree

#: Pattern kinds, in the order of their integer codes in NetCDF files.
PATTERN_KINDS = ("none", "spots", "stripes", "labyrinth")

#: A spectral peak of lower prominence (see :func:`dominant_wavenumber`) is noise or a front, not a pattern.
MIN_PROMINENCE = 10.0
#: A region above the level is a spot if its long axis is less than this many times its short axis ...
MAX_SPOT_ASPECT = 2.0
#: ... and its area is below this many dominant wavelengths squared.
MAX_SPOT_AREA = 1.0
#: The level separating high from low phase, as a fraction of the field's range above its minimum.
LEVEL_FRACTION = 0.5
#: A pattern is "spots" when at least this fraction of the high phase lies in spots.
MIN_SPOT_FRACTION = 0.5
#: A non-spot pattern is "stripes" when the nematic order of its gradient reaches this.
MIN_STRIPE_ORDER = 0.5
#: Spots closer than this many median spacings to the convex hull of all spots are edge spots.
EDGE_MARGIN = 0.5
#: Points along a Delaunay bond checked to lie in the domain (:func:`hexatic_order`'s ``inside``).
BOND_SAMPLES = 16
#: Pixels of the interpolation grid per side: at least this many, at most ``MAX_PIXELS``.
MIN_PIXELS, MAX_PIXELS = 128, 1024
#: The spectrum is computed on a zero-padded grid of at least this many points per side (finer k bins).
PADDED_SIZE = 1024


@dataclass(frozen=True)
class GriddedField:
    """A field sampled at pixel centres of a uniform grid; NaN outside the mesh."""

    values: np.ndarray  #: (ny, nx)
    origin: tuple[float, float]  #: coordinates of the lower-left corner of pixel [0, 0]
    spacing: tuple[float, float]  #: pixel size (hx, hy)

    @property
    def x(self) -> np.ndarray:
        return self.origin[0] + self.spacing[0] * (np.arange(self.values.shape[1]) + 0.5)

    @property
    def y(self) -> np.ndarray:
        return self.origin[1] + self.spacing[1] * (np.arange(self.values.shape[0]) + 0.5)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(left, right, bottom, top), for ``imshow``."""
        ny, nx = self.values.shape
        return (self.origin[0], self.origin[0] + nx * self.spacing[0],
                self.origin[1], self.origin[1] + ny * self.spacing[1])

    @property
    def pixel_area(self) -> float:
        return self.spacing[0] * self.spacing[1]

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Whether each point (n, 2) lies in a pixel of the mesh (one with a value); a point on the grid's frame
        counts in the pixel beside it."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        ny, nx = self.values.shape
        cols = np.clip(np.floor((points[:, 0] - self.origin[0]) / self.spacing[0]).astype(int), 0, nx - 1)
        rows = np.clip(np.floor((points[:, 1] - self.origin[1]) / self.spacing[1]).astype(int), 0, ny - 1)
        return np.isfinite(self.values[rows, cols])


def median_edge_length(points: np.ndarray, triangles: np.ndarray) -> float:
    """The median length of the mesh's triangle edges (its resolution)."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    return float(np.median(np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1)))


class MeshSampler:
    """Linear interpolation from the vertices of a triangle mesh onto a uniform grid over its bounding box.

    The grid points are located in the mesh once (triangle and barycentric
    weights); each call then samples one vertex field.  ``pixel``: the grid
    spacing (default: half the median edge length, with between
    :data:`MIN_PIXELS` and :data:`MAX_PIXELS` pixels along the longer side).
    """

    def __init__(self, points: np.ndarray, triangles: np.ndarray, pixel: float | None = None):
        from matplotlib.tri import Triangulation

        points = np.asarray(points, dtype=float)[:, :2]
        triangles = np.asarray(triangles)
        lower, upper = points.min(axis=0), points.max(axis=0)
        size = upper - lower
        self.resolution = median_edge_length(points, triangles)
        if pixel is None:
            pixel = np.clip(0.5 * self.resolution, size.max() / MAX_PIXELS, size.max() / MIN_PIXELS)
        counts = np.maximum(np.rint(size / pixel).astype(int), 1)
        self.origin = (float(lower[0]), float(lower[1]))
        self.spacing = tuple(float(s) for s in size / counts)
        x = lower[0] + self.spacing[0] * (np.arange(counts[0]) + 0.5)
        y = lower[1] + self.spacing[1] * (np.arange(counts[1]) + 0.5)
        grid = np.stack(np.meshgrid(x, y), axis=-1)
        cell = Triangulation(points[:, 0], points[:, 1], triangles).get_trifinder()(grid[..., 0], grid[..., 1])
        self.shape = cell.shape
        self.inside = cell >= 0
        self.corners = triangles[cell[self.inside]]  # (m, 3) vertices of the triangle around each grid point
        first = points[self.corners[:, 0]]
        edges = np.stack([points[self.corners[:, 1]] - first, points[self.corners[:, 2]] - first], axis=-1)
        local = np.linalg.solve(edges, (grid[self.inside] - first)[..., None])[..., 0]
        self.weights = np.column_stack([1.0 - local.sum(axis=1), local])

    def __call__(self, values: np.ndarray) -> GriddedField:
        gridded = np.full(self.shape, np.nan)
        gridded[self.inside] = np.einsum("ij,ij->i", np.asarray(values, dtype=float)[self.corners], self.weights)
        return GriddedField(gridded, self.origin, self.spacing)


def to_grid(points: np.ndarray, triangles: np.ndarray, values: np.ndarray,
            pixel: float | None = None) -> GriddedField:
    """Interpolate vertex ``values`` linearly onto a uniform grid over the mesh's bounding box (:class:`MeshSampler`)."""
    return MeshSampler(points, triangles, pixel)(values)


def radial_spectrum(field: GriddedField) -> tuple[np.ndarray, np.ndarray]:
    """Wavenumbers k and the radially averaged power spectrum P(k) of the field minus its mean.

    The field is multiplied by a 2D Hann window (no leakage from the
    non-periodic edges) and zero-padded to at least :data:`PADDED_SIZE` points
    per side; P(k) is the mean of |F|^2 over annuli one padded k-step wide, up
    to the grid's Nyquist wavenumber.  It is normalised so that its sum over the
    whole k plane is the window-weighted variance of the field.
    """
    values = field.values
    valid = np.isfinite(values)
    if not valid.any():
        return np.zeros(1), np.zeros(1)
    ny, nx = values.shape
    window = np.outer(np.hanning(ny), np.hanning(nx))
    centred = np.where(valid, values - values[valid].mean(), 0.0) * window
    shape = tuple(scipy.fft.next_fast_len(max(4 * n, PADDED_SIZE)) for n in (ny, nx))
    power = np.abs(scipy.fft.rfft2(centred, s=shape)) ** 2
    power /= shape[0] * shape[1] * max(float(np.sum(window[valid] ** 2)), np.finfo(float).tiny)
    hx, hy = field.spacing
    kx = 2.0 * np.pi * scipy.fft.rfftfreq(shape[1], hx)
    ky = 2.0 * np.pi * scipy.fft.fftfreq(shape[0], hy)
    step = min(kx[1], abs(ky[1]))
    ring = np.rint(np.hypot(kx[None, :], ky[:, None]) / step).astype(int)
    last = int(min(np.pi / hx, np.pi / hy) / step)
    inside = ring <= last
    counts = np.bincount(ring[inside], minlength=last + 1)
    sums = np.bincount(ring[inside], weights=power[inside], minlength=last + 1)
    return step * np.arange(last + 1), sums / np.maximum(counts, 1)


def long_wave_leakage(field: GriddedField, k_low: float) -> np.ndarray:
    """The radial spectrum (:func:`radial_spectrum`'s k) of the field's waves longer than 2 pi / ``k_low`` alone.

    The window multiplies the field, so each wave's power spreads into side lobes about 2 pi / L apart, L the
    box's side along which they lie.  On a long, narrow box a trend along the long side (a gradient, a front,
    one hump) leaks through the side lobes of the short side's window into wavenumbers far above its own,
    4 pi / L_short and up, where :func:`dominant_wavenumber` looks for peaks: a gradient along a 40 x 10 box
    had a "peak" at wavelength 4.16 with prominence 39 (stripes).  These waves are the field's cosine modes
    (its zero-flux walls' own series, so a trend has no edges to ring at) below ``k_low``.
    """
    values = field.values
    valid = np.isfinite(values)
    if not valid.any():
        return radial_spectrum(field)[1]
    modes = scipy.fft.dctn(np.where(valid, values - values[valid].mean(), 0.0), type=2, norm="ortho")
    ny, nx = values.shape
    width, height = nx * field.spacing[0], ny * field.spacing[1]
    k = np.pi * np.hypot(np.arange(nx)[None, :] / width, np.arange(ny)[:, None] / height)
    trend = scipy.fft.idctn(np.where(k < k_low, modes, 0.0), type=2, norm="ortho")
    return radial_spectrum(GriddedField(np.where(valid, trend, np.nan), field.origin, field.spacing))[1]


def dominant_wavenumber(k: np.ndarray, power: np.ndarray, k_low: float, k_high: float,
                        leakage: np.ndarray | None = None) -> tuple[float, float]:
    """The peak of P(k) in [k_low, k_high] (parabolic refinement) and its prominence.

    The prominence is the peak power over the larger of the band's median
    power, the lowest power between ``k_low`` and the peak, and the power
    ``leakage`` (:func:`long_wave_leakage`) says the waves below ``k_low``
    put there: a peak that is only the end of a long-wave trend (a front, a
    gradient), or its window's side lobe, has prominence ~1.
    ``k_low`` keeps out trends longer than half the domain; ``k_high`` (the
    mesh's Nyquist wavenumber) keeps the median out of the band the mesh cannot resolve.
    When the spectrum has no peak in the band, only a trend that keeps rising past
    ``k_low`` (a front, a gradient, a lone spot: P falls across the whole band), the
    wavenumber is NaN and the prominence 1: its k_low was taken for a wavelength of
    half the domain (10 on the 20 x 20 box) in fields with no pattern.
    """
    band = np.flatnonzero((k >= k_low) & (k <= k_high))
    if band.size < 3 or not np.any(power[band] > 0):
        return np.nan, np.nan
    i = band[np.argmax(power[band])]
    if i == band[0] and i > 0 and power[i - 1] >= power[i]:  # the tail of a longer-wave trend, not a peak
        return np.nan, 1.0
    k_peak = float(k[i])
    if 0 < i < k.size - 1:
        left, centre, right = power[i - 1], power[i], power[i + 1]
        curvature = left - 2.0 * centre + right
        if curvature < 0:
            k_peak += 0.5 * (left - right) / curvature * (k[1] - k[0])
    leaked = min(float(leakage[i]), float(power[i])) if leakage is not None else 0.0  # explains all of it at most
    background = max(float(np.median(power[band])), float(power[band[0]:i + 1].min()), leaked, np.finfo(float).tiny)
    return k_peak, float(power[i] / background)


@dataclass(frozen=True)
class Blobs:
    """Connected regions of the field above ``level``; ``spot`` marks the compact ones."""

    level: float
    centres: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  #: (n, 2) positions of the maxima
    areas: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: (n,) area above the level
    aspects: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: (n,) long / short second-moment axis
    spot: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))  #: (n,) compact
    #: (n,) the region reaches the domain's edge (the grid's frame or a pixel outside the mesh)
    at_edge: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    @property
    def spot_fraction(self) -> float:
        """The fraction of the area above the level that lies in spots (NaN if none is above)."""
        total = float(self.areas.sum())
        return float(self.areas[self.spot].sum()) / total if total > 0 else np.nan


def threshold_level(field: GriddedField) -> float:
    """Halfway (:data:`LEVEL_FRACTION`) between the field's minimum and maximum."""
    values = field.values[np.isfinite(field.values)]
    low, high = float(values.min()), float(values.max())
    return low + LEVEL_FRACTION * (high - low)


def find_blobs(field: GriddedField, level: float, max_spot_area: float = np.inf) -> Blobs:
    """Connected (8-neighbour) regions above ``level``, with their centre, area and shape."""
    values = field.values
    high = np.isfinite(values) & (values > level)
    labels, count = ndimage.label(high, structure=np.ones((3, 3), dtype=bool))
    if count == 0:
        return Blobs(level)
    hx, hy = field.spacing
    rows, cols = np.nonzero(labels)
    which = labels[rows, cols] - 1
    x = field.origin[0] + hx * (cols + 0.5)
    y = field.origin[1] + hy * (rows + 0.5)

    def per_blob(quantity):
        return np.bincount(which, weights=quantity, minlength=count)

    pixels = per_blob(np.ones_like(x))
    peaks = np.array(ndimage.maximum_position(values, labels, np.arange(1, count + 1)), dtype=int).reshape(-1, 2)
    centres = np.column_stack([
        field.origin[0] + hx * (peaks[:, 1] + 0.5 + _parabola_offset(values, peaks, axis=1)),
        field.origin[1] + hy * (peaks[:, 0] + 0.5 + _parabola_offset(values, peaks, axis=0)),
    ])
    mean_x, mean_y = per_blob(x) / pixels, per_blob(y) / pixels
    # second moments of the region's shape (one pixel alone: a square's hx^2 / 12)
    sxx = per_blob(x * x) / pixels - mean_x**2 + hx**2 / 12
    syy = per_blob(y * y) / pixels - mean_y**2 + hy**2 / 12
    sxy = per_blob(x * y) / pixels - mean_x * mean_y
    half_trace, root = 0.5 * (sxx + syy), np.sqrt(0.25 * (sxx - syy) ** 2 + sxy**2)
    aspects = np.sqrt((half_trace + root) / np.maximum(half_trace - root, 1e-300))
    areas = pixels * field.pixel_area
    spot = (aspects < MAX_SPOT_ASPECT) & (areas < max_spot_area)
    outside = np.pad(~np.isfinite(values), 1, constant_values=True)
    edge = ndimage.binary_dilation(outside, structure=np.ones((3, 3), dtype=bool))[1:-1, 1:-1]
    at_edge = per_blob(edge[rows, cols].astype(float)) > 0
    return Blobs(level, centres, areas, aspects, spot, at_edge)


def _parabola_offset(values: np.ndarray, peaks: np.ndarray, axis: int) -> np.ndarray:
    """Sub-pixel offset of each peak along ``axis`` from a parabola through it and its two neighbours."""
    offsets = np.zeros(len(peaks))
    step = np.eye(2, dtype=int)[axis]
    for n, peak in enumerate(peaks):
        before, after = peak - step, peak + step
        if before[axis] < 0 or after[axis] >= values.shape[axis]:
            continue  # at the grid's edge: keep the pixel centre
        left, centre, right = values[tuple(before)], values[tuple(peak)], values[tuple(after)]
        curvature = left - 2.0 * centre + right
        if curvature < 0:
            offsets[n] = np.clip(0.5 * (left - right) / curvature, -0.5, 0.5)
    return offsets


def nearest_neighbour_distances(centres: np.ndarray) -> np.ndarray:
    """For each point, the distance to the nearest other point (empty if fewer than two points)."""
    if len(centres) < 2:
        return np.zeros(0)
    distances, _ = cKDTree(centres).query(centres, k=2)
    return distances[:, 1]


def hexatic_order(centres: np.ndarray, inside=None) -> tuple[float, np.ndarray]:
    """Mean |psi_6| over the spots away from the pattern's edge, and psi_6 per spot (NaN at the edge).

    psi_6(j) = mean over the bonds j-l of exp(6 i theta_jl); the bonds are the
    Delaunay edges (no distance cutoff: a cutoff leaves disordered points with
    one or two bonds each, and a single bond has |psi_6| = 1).  Spots within
    :data:`EDGE_MARGIN` median spacings of the convex hull of all spots lack
    neighbours on one side and are left out of the mean.  1 for a hexagonal
    lattice, ~0.07 for a square one, ~0.36 for random points.  ``inside`` maps
    points (n, 2) to whether they lie in the domain: a spot with a bond that
    leaves it, across a hole or a notch the hull does not see, is at the domain's
    edge too (a hexagonal lattice on an annulus had 0.89, on an L-shape 0.94).
    """
    psi = np.full(len(centres), np.nan, dtype=complex)
    spacing = nearest_neighbour_distances(centres)
    if len(centres) < 4:
        return np.nan, psi
    try:
        triangulation = Delaunay(centres)
        hull = ConvexHull(centres)
    except QhullError:  # all spots on a line
        return np.nan, psi
    typical = float(np.median(spacing))
    to_hull = -np.max(centres @ hull.equations[:, :2].T + hull.equations[:, 2], axis=1)
    pointers, neighbours = triangulation.vertex_neighbor_vertices
    fractions = (np.arange(BOND_SAMPLES) + 0.5)[:, None, None] / BOND_SAMPLES
    for j in np.flatnonzero(to_hull > EDGE_MARGIN * typical):
        bonds = centres[neighbours[pointers[j]:pointers[j + 1]]] - centres[j]
        if inside is not None and not inside((centres[j] + fractions * bonds).reshape(-1, 2)).all():
            continue
        psi[j] = np.mean(np.exp(6j * np.arctan2(bonds[:, 1], bonds[:, 0])))
    inner = np.isfinite(psi)
    return (float(np.mean(np.abs(psi[inner]))) if inner.any() else np.nan), psi


def orientation_order(field: GriddedField) -> float:
    """Nematic order of the gradient directions, |sum (g_x + i g_y)^2| / sum |g|^2: 1 for parallel stripes."""
    gy, gx = np.gradient(field.values, *field.spacing[::-1])
    squared = (gx + 1j * gy) ** 2
    finite = np.isfinite(squared)
    magnitude = float(np.sum(np.abs(squared[finite])))
    return float(abs(np.sum(squared[finite])) / magnitude) if magnitude > 0 else np.nan


#: The rule of :func:`classify` and of the spots, in words, for metrics.nc and the command's lines.
CLASSIFICATION_RULE = (
    f"none: spectral_prominence below {MIN_PROMINENCE:g} (no spectral peak stands out: noise, a front, a lone "
    f"spot or a few, or a pattern at the mesh's scale); its spots are not counted. Else spots if "
    f"spot_fraction >= {MIN_SPOT_FRACTION:g}, stripes if orientation_order >= {MIN_STRIPE_ORDER:g}, else "
    f"labyrinth. A spot is a connected region above the level with a second-moment aspect ratio below "
    f"{MAX_SPOT_ASPECT:g} and an area below {MAX_SPOT_AREA:g} dominant wavelength squared")


def classify(prominence: float, spot_fraction: float, orientation: float) -> str:
    """none (no spectral peak), spots (mostly compact blobs), stripes (aligned), else labyrinth
    (:data:`CLASSIFICATION_RULE`)."""
    if not prominence >= MIN_PROMINENCE:
        return "none"
    if spot_fraction >= MIN_SPOT_FRACTION:
        return "spots"
    if orientation >= MIN_STRIPE_ORDER:
        return "stripes"
    return "labyrinth"


def no_pattern_reason(prominence: float, wavelength: float) -> str:
    """Why a field is of kind "none", with the threshold it missed (:data:`MIN_PROMINENCE`)."""
    if not np.isfinite(wavelength):
        return "no spectral peak"
    return f"spectral prominence {prominence:.3g} < {MIN_PROMINENCE:g}"


def spots_text(count: int, spacing_mean: float, spacing_std: float, hexatic: float) -> str:
    """The spots in words: count, and the spacing and |psi_6| where they have a value (two spots have a spacing,
    four off a line a |psi_6|); "no spots" rather than "0 spots, spacing nan +- nan, |psi6| nan"."""
    if not count:
        return "no spots"
    text = f"{count} spot" + ("s" if count > 1 else "")
    if np.isfinite(spacing_mean):
        text += f", spacing {spacing_mean:.4g} +- {spacing_std:.2g}"
    if np.isfinite(hexatic):
        text += f", |psi_6| {hexatic:.3f}"
    return text


@dataclass(frozen=True)
class PatternMetrics:
    """Every metric of one snapshot of one field (lengths in mesh units)."""

    kind: str
    dominant_wavenumber: float
    prominence: float
    level: float
    spot_centres: np.ndarray
    spot_areas: np.ndarray
    spacing_mean: float
    spacing_std: float
    hexatic_order: float
    spot_fraction: float
    orientation_order: float
    wavenumbers: np.ndarray
    power: np.ndarray

    @property
    def dominant_wavelength(self) -> float:
        return 2.0 * np.pi / self.dominant_wavenumber if self.dominant_wavenumber > 0 else np.nan

    @property
    def spot_count(self) -> int:
        return len(self.spot_centres)


def pattern_metrics(field: GriddedField, resolution: float | None = None) -> PatternMetrics:
    """All metrics of a gridded field.

    ``resolution``: the length the data resolve (the mesh's edge length;
    default two pixels); wavenumbers above pi / resolution are not searched.
    A field classified "none" has no spots.
    """
    k, power = radial_spectrum(field)
    size = min(field.extent[1] - field.extent[0], field.extent[3] - field.extent[2])
    resolution = 2.0 * max(field.spacing) if resolution is None else resolution
    k_low = 4.0 * np.pi / size
    k_peak, prominence = dominant_wavenumber(k, power, k_low, np.pi / resolution, long_wave_leakage(field, k_low))
    level = threshold_level(field) if np.isfinite(field.values).any() else np.nan
    if not level > np.nanmin(field.values) + 1e-9 * max(abs(level), 1e-300):  # uniform: no spectrum to speak of
        k_peak, prominence = np.nan, np.nan
    wavelength = 2.0 * np.pi / k_peak if k_peak > 0 else np.inf
    blobs = find_blobs(field, level, MAX_SPOT_AREA * wavelength**2)
    orientation = orientation_order(field)
    kind = classify(prominence, blobs.spot_fraction, orientation)
    # in stripes or a labyrinth, a compact region the domain's edge cuts off is a stripe's end, not a spot: oblique
    # stripes counted 1-2 "spots" at the corners (124 of 513 stripes of wavelength 2-4 at 0-90 degrees on the
    # 20 x 20 box); in a pattern of spots, one the edge cuts is a spot on a no-flux wall, and counted
    counted = blobs.spot & ~blobs.at_edge if kind in ("stripes", "labyrinth") else blobs.spot
    centres = blobs.centres[counted] if kind != "none" else np.zeros((0, 2))
    areas = blobs.areas[counted] if kind != "none" else np.zeros(0)
    spacing = nearest_neighbour_distances(centres)
    return PatternMetrics(
        kind=kind, dominant_wavenumber=k_peak, prominence=prominence, level=level,
        spot_centres=centres, spot_areas=areas,
        spacing_mean=float(spacing.mean()) if spacing.size else np.nan,
        spacing_std=float(spacing.std()) if spacing.size else np.nan,
        hexatic_order=hexatic_order(centres, field.inside)[0],
        spot_fraction=blobs.spot_fraction, orientation_order=orientation,
        wavenumbers=k, power=power,
    )


def mesh_pattern_metrics(points: np.ndarray, triangles: np.ndarray, values: np.ndarray,
                         pixel: float | None = None) -> tuple[PatternMetrics, GriddedField]:
    """:func:`pattern_metrics` of vertex ``values`` on a triangle mesh, and the grid it was measured on."""
    sampler = MeshSampler(points, triangles, pixel)
    gridded = sampler(values)
    return pattern_metrics(gridded, resolution=sampler.resolution), gridded
