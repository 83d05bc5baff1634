"""Pictures of pattern metrics (matplotlib ``Figure`` objects, no pyplot state: safe in worker threads).

* :func:`metrics_figure` -- one species of one run: per output time, the field
  with its detected spots circled, and its radially averaged power spectrum
  with the detected peak and the linear analysis's k_max marked;
* :func:`sweep_figure` -- a sweep over two parameters: the simulated spot
  spacing, spot count and dominant wavelength over the parameter plane, with
  the linear analysis's patterning boundary (max Re phi = 0) and its predicted
  wavelength 2 pi / k_max drawn over them.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator

from primordia.analysis.patterns.metrics import no_pattern_reason, spots_text
from primordia.core.atomic_files import atomic_path


def _save(figure: Figure, path) -> Path:
    path = Path(path)
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png", dpi=110)
    return path


def metrics_figure(measurements: Sequence, predicted, path) -> Path:
    """Field + spots (top) and spectrum + k_max (bottom) for each output time of one species."""
    columns = len(measurements)
    width = 4.4 * columns + 0.6
    height = 8.0
    figure = Figure(figsize=(width, height))
    axes = figure.subplots(2, columns, squeeze=False)
    # the linear analysis's note is long (a coupled model's, or why there is none): wrapped to the figure's width,
    # about 12 characters an inch at 10 points, it ran off both sides of a one- or two-time picture
    title = textwrap.fill(f"pattern metrics ({predicted.note or 'linear analysis'})", width=int(12 * width))
    lines = title.count("\n") + 1
    # fixed margins (in inches at the sides and top): constrained layout triples the drawing time
    figure.subplots_adjust(left=0.8 / width, right=1 - 0.3 / width, bottom=0.07, top=1 - (0.8 + 0.18 * lines) / height,
                           wspace=0.4, hspace=0.3)
    for (top, bottom), m in zip(axes.T, measurements):
        metrics, grid = m.metrics, m.grid
        image = top.imshow(grid.values, origin="lower", extent=grid.extent, cmap="viridis", interpolation="nearest")
        figure.colorbar(image, ax=top, shrink=0.8)
        if metrics.spot_count:
            radii = np.sqrt(metrics.spot_areas / np.pi)
            for (x, y), r in zip(metrics.spot_centres, radii):
                top.add_patch(_circle((x, y), r))
            top.plot(*metrics.spot_centres.T, "r+", markersize=5)
        # the field's own extent: the circle of a spot the walls halve widened this panel past the domain, white
        # margins beside a field its neighbours drew edge to edge
        top.set_xlim(grid.extent[:2])
        top.set_ylim(grid.extent[2:])
        # a field with no spots read "0 spots, spacing nan +- nan, |psi6| nan"; a field of no pattern says why
        kind = (f"none ({no_pattern_reason(metrics.prominence, metrics.dominant_wavelength)})"
                if metrics.kind == "none" else metrics.kind)
        top.set_title(f"{m.species}, t = {m.time:g} ({m.configuration}): {kind}\n"
                      + spots_text(metrics.spot_count, metrics.spacing_mean, metrics.spacing_std,
                                   metrics.hexatic_order), fontsize=8)
        top.set_aspect("equal")
        top.set_xlabel("x")
        top.set_ylabel("y")
        k, power = metrics.wavenumbers, metrics.power
        shown = k > 0
        bottom.semilogy(k[shown], np.maximum(power[shown], 1e-300), color="tab:blue", linewidth=1)
        if np.isfinite(metrics.dominant_wavenumber):
            bottom.axvline(metrics.dominant_wavenumber, color="black", linestyle=":", label=f"peak k = "
                           f"{metrics.dominant_wavenumber:.3g} (wavelength {metrics.dominant_wavelength:.3g})")
        else:  # a spectrum that falls across the band: its long-wave end was marked as a "peak"
            bottom.plot([], [], " ", label="no spectral peak")
        if np.isfinite(predicted.k_max):
            bottom.axvline(predicted.k_max, color="tab:red", linestyle="--",
                           label=f"linear k_max = {predicted.k_max:.3g} (wavelength {predicted.wavelength:.3g})")
        upper = 3.0 * np.nanmax([metrics.dominant_wavenumber, predicted.k_max, 1.0])
        bottom.set_xlim(0.0, min(upper, float(k.max())))
        positive = power[shown & (k <= upper)]
        positive = positive[positive > 0]
        if positive.size:
            bottom.set_ylim(positive.max() * 1e-6, positive.max() * 3.0)
        bottom.set_xlabel("k")
        bottom.set_ylabel("radially averaged power")
        bottom.legend(fontsize=7, loc="upper right")
    figure.suptitle(title, fontsize=10)
    return _save(figure, path)


def _circle(centre, radius):
    from matplotlib.patches import Circle

    return Circle(centre, radius, fill=False, edgecolor="white", linewidth=0.8)


#: Panels of the sweep figure: variable, title.
SWEEP_PANELS = (
    ("spacing_mean", "spot spacing (nearest neighbour)"),
    ("spot_count", "spot count"),
    ("dominant_wavelength", "dominant wavelength (spectrum)"),
)


def sweep_figure(ds: xr.Dataset, linear: xr.Dataset | None, path, x: str, y: str) -> Path:
    """Simulated metrics over the (x, y) parameter plane with the linear analysis drawn over them.

    ``ds``: the sweep's metrics already reduced to dims (x, y) (seed mean, one
    time, species and configuration), with a ``pattern_name`` variable (kind
    as text) and ``failed`` (0/1).  ``linear``: a
    :func:`~primordia.analysis.patterning.patterning_space` Dataset over the
    same two parameters (or None when they are not both model parameters).
    """
    figure = Figure(figsize=(5.2 * len(SWEEP_PANELS), 4.8), layout="constrained")
    axes = figure.subplots(1, len(SWEEP_PANELS))
    xs, ys = ds[x].values, ds[y].values
    for ax, (name, title) in zip(axes, SWEEP_PANELS):
        values = ds[name].transpose(y, x).values
        # a count's scale starts at 0: a sweep without a spot drew its zeros on a colour bar from -0.1 to 0.1
        limits = {"vmin": 0.0, "vmax": max(1.0, np.nanmax(values, initial=0.0))} if name == "spot_count" else {}
        mesh = ax.pcolormesh(_edges(xs), _edges(ys), np.ma.masked_invalid(values), cmap="viridis", shading="flat",
                             **limits)
        if np.isfinite(values).any():  # a panel with no value at all had a colour bar from -0.1 to 0.1
            figure.colorbar(mesh, ax=ax, shrink=0.85)
        else:
            title = f"{title}: no run has one"
        for i, xv in enumerate(xs):
            for j, yv in enumerate(ys):
                label = "failed" if ds["failed"].transpose(y, x).values[j, i] else ds["pattern_name"].transpose(
                    y, x).values[j, i]
                ax.text(xv, yv, label, ha="center", va="center", fontsize=6, color="white",
                        bbox={"boxstyle": "round,pad=0.15", "facecolor": "black", "alpha": 0.35, "linewidth": 0})
        handles = []
        if linear is not None:
            handles = _draw_linear(ax, linear, x, y, wavelength=name != "spot_count")
        ax.set_xlabel(x)
        ax.set_ylabel(y)
        ax.set_title(title, fontsize=10)
        ax.set_xlim(_edges(xs)[[0, -1]])
        ax.set_ylim(_edges(ys)[[0, -1]])
        if handles:
            ax.legend(handles=handles, fontsize=7, loc="upper left")
    figure.suptitle(ds.attrs.get("title", "sweep"), fontsize=10)
    return _save(figure, path)


def _draw_linear(ax, linear: xr.Dataset, x: str, y: str, wavelength: bool) -> list:
    """The Turing boundary (max real root = 0) and, optionally, contours of 2 pi / k_max."""
    lx, ly = linear[x].values, linear[y].values
    rate = linear["turing_growth_rate"].transpose(y, x).values
    handles = []
    if np.nanmin(rate) < 0 < np.nanmax(rate):
        ax.contour(lx, ly, rate, levels=[0.0], colors="red", linewidths=2.0)
        handles.append(Line2D([], [], color="red", linewidth=2.0, label="linear: max Re phi = 0"))
    if wavelength:
        k = linear["turing_wavenumber"].transpose(y, x).values
        predicted = np.where(k > 0, 2.0 * np.pi / k, np.nan)
        finite = predicted[np.isfinite(predicted)]
        if finite.size > 3:  # levels over the bulk: near the boundary the wavelength grows without bound
            levels = MaxNLocator(6).tick_values(finite.min(), np.percentile(finite, 80))
            lines = ax.contour(lx, ly, predicted, levels=levels, colors="tab:orange", linewidths=1.0, linestyles="--")
            ax.clabel(lines, fontsize=7, fmt="%.2g")
            handles.append(Line2D([], [], color="tab:orange", linestyle="--", label="linear: 2 pi / k_max"))
    return handles


def _edges(centres: np.ndarray) -> np.ndarray:
    """Cell edges around sorted cell centres (for pcolormesh)."""
    centres = np.asarray(centres, dtype=float)
    if centres.size == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    middle = 0.5 * (centres[1:] + centres[:-1])
    return np.concatenate([[2 * centres[0] - middle[0]], middle, [2 * centres[-1] - middle[-1]]])
