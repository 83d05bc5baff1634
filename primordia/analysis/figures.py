"""Figures in the layout of seed Figures 3.1-3.3 (matplotlib ``Figure`` objects, no pyplot).

:func:`patterning_figure` draws one row of the seed's figures from a
:func:`~primordia.analysis.patterning.patterning_space` Dataset:

1. the patterning space: the region where a_0 (d_0) < 0 for some k filled in
   light grey, the boundary found from the growth rates (max real root = 0) in
   thick black, and each seed condition's boundary curve in the seed's style;
2. a_0(k^2) (or d_0) at the critical value of one parameter and at 50%, 75%,
   125%, 150% of it (critical curve green, as in the seed);
3. the dispersion curves max Re phi(k^2) for the same values.

:func:`dispersion_figure` draws the growth rates of one parameter set.

The figures are ``matplotlib.figure.Figure`` objects saved by file name: no pyplot,
so importing this module chooses no GUI backend and changes nothing global, and
figures are drawn the same with or without a display.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from primordia.analysis.patterning import (
    COUPLED_CORRECTED_CURVES,
    COUPLED_CURVES,
    CRITICAL_SCALES,
    UNCOUPLED_CURVES,
)
from primordia.core.atomic_files import atomic_path, make_directory

#: Colours of the curves at 50%, 75%, 100% (critical, green as in the seed), 125%, 150%.
SCALE_COLOURS = ("tab:blue", "tab:cyan", "tab:green", "tab:orange", "tab:red")


def _boundary_curves(ds: xr.Dataset):
    if not ds.attrs.get("coupled"):
        return UNCOUPLED_CURVES
    return COUPLED_CURVES if ds.attrs.get("theta_variant") == "seed" else COUPLED_CORRECTED_CURVES


def _changes_sign(values: np.ndarray) -> bool:
    finite = values[np.isfinite(values)]
    return finite.size > 0 and finite.min() < 0 < finite.max()


def draw_patterning_space(ax, ds: xr.Dataset) -> None:
    """Panel 1: predicted region (grey), numerical boundary (black), seed condition curves."""
    xname, yname = ds.attrs["x"], ds.attrs["y"]
    x, y = ds[xname].values, ds[yname].values
    handles = []
    region = ds["unstable_conditions"].values.T.astype(float)
    if region.max() > 0:
        ax.contourf(x, y, region, levels=[0.5, 1.5], colors=["0.85"])
    handles.append(Patch(color="0.85", label=f"{'d_0' if ds.attrs['coupled'] else 'a_0'} < 0 for some k"))
    # The growth rate is ~0 all over the stable side (the conserved cell mode at small k), so
    # its zero contour is ill-defined; the 0/1 flag's 0.5 contour is exact to one grid cell.
    numerical = ds["unstable_numerical"].values.T.astype(float)
    if 0 < numerical.mean() < 1:
        ax.contour(x, y, numerical, levels=[0.5], colors="black", linewidths=2.6)
    handles.append(Line2D([], [], color="black", linewidth=2.6, label="max real root = 0 (eigenvalues)"))
    oscillatory = ds["oscillatory_growth_rate"].values.T
    if _changes_sign(oscillatory):
        ax.contour(x, y, np.where(np.isfinite(oscillatory), oscillatory, -1.0), levels=[0.0], colors="0.4",
                   linewidths=1.0, linestyles=":")
        handles.append(Line2D([], [], color="0.4", linestyle=":", label="oscillatory Re phi = 0"))
    for variable, label, style in _boundary_curves(ds):
        values = ds[variable].values.T
        if _changes_sign(values):
            ax.contour(x, y, values, levels=[0.0], colors=style["color"], linestyles=[style["linestyle"]],
                       linewidths=1.4)
            handles.append(Line2D([], [], linewidth=1.4, label=label, **style))
    base_x, base_y = ds.attrs.get(f"parameter_{xname}"), ds.attrs.get(f"parameter_{yname}")
    if base_x is not None and x.min() <= base_x <= x.max() and y.min() <= base_y <= y.max():
        ax.plot(base_x, base_y, marker="*", color="gold", markeredgecolor="black", markersize=12, linestyle="")
        handles.append(Line2D([], [], marker="*", color="gold", markeredgecolor="black", markersize=10,
                              linestyle="", label="fixed parameters"))
    ax.set_xlim(x.min(), x.max())
    ax.set_ylim(y.min(), y.max())
    ax.set_xlabel(xname)
    ax.set_ylabel(yname)
    kind = "coupled" if ds.attrs["coupled"] else "uncoupled"
    variant = f", {ds.attrs['theta_variant']} theta" if ds.attrs["coupled"] else ""
    ax.set_title(f"patterning space ({kind}{variant})", fontsize=10)
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2,
              frameon=False)


def _constant_term_scale(ax, curves, K, k_c):
    """Linear near the critical curve's tangency, logarithmic beyond (a_0 ~ k^6, d_0 ~ k^10 far out)."""
    critical = curves[CRITICAL_SCALES.index(1.0)]
    near = np.abs(critical[(K > 0) & (K <= max(3.0 * k_c**2, 0.1 * K.max()))])
    scale = float(np.nanmax(near)) if near.size and np.nanmax(near) > 0 else 1.0
    if np.nanmax(np.abs(curves)) > 50 * scale:
        ax.set_yscale("symlog", linthresh=scale)
    else:
        low = float(np.nanmin(curves))
        ax.set_ylim(1.15 * low if low < 0 else -0.25 * scale, 1.5 * max(scale, -low))


def draw_critical_curves(ax_constant, ax_dispersion, ds: xr.Dataset) -> None:
    """Panels 2 and 3: a_0 (d_0) and max Re phi against k^2 at the critical value x 0.5 ... 1.5."""
    name = ds.attrs.get("critical_parameter", "?")
    if "constant_term" not in ds:
        for ax in (ax_constant, ax_dispersion):
            ax.text(0.5, 0.5, ds.attrs.get("critical_note", "no critical value"), ha="center", va="center",
                    transform=ax.transAxes, fontsize=8, wrap=True)
        return
    K = ds["k_squared"].values
    critical = ds.attrs["critical_value"]
    symbol = "d_0" if ds.attrs["coupled"] else "a_0"
    constant = ds["constant_term"].values
    growth = ds["dispersion_max_real"].values
    for i, scale in enumerate(CRITICAL_SCALES):
        label = f"{name} = {scale:g} x {critical:.4g}"
        width = 2.2 if scale == 1.0 else 1.3
        ax_constant.plot(K, constant[i], color=SCALE_COLOURS[i], linewidth=width, label=label)
        ax_dispersion.plot(K, growth[i], color=SCALE_COLOURS[i], linewidth=width, label=label)
    for ax in (ax_constant, ax_dispersion):
        ax.axhline(0.0, color="black", linewidth=0.7)
        ax.set_xlabel("k^2")
        ax.set_xlim(K.min(), K.max())
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3, frameon=False)
    _constant_term_scale(ax_constant, constant, K, ds.attrs["critical_wavenumber"])
    ax_constant.set_ylabel(symbol)
    ax_constant.set_title(f"{symbol}(k^2) around the critical {name} (k_c = {ds.attrs['critical_wavenumber']:.3g})",
                          fontsize=10)
    finite = growth[np.isfinite(growth)]
    high = max(finite.max(), 1e-3 * abs(finite.min())) if finite.size else 1.0
    ax_dispersion.set_ylim(-0.6 * high if finite.min() < -0.6 * high else finite.min() * 1.1, 1.15 * high)
    ax_dispersion.set_ylabel("max Re phi")
    ax_dispersion.set_title("dispersion relation", fontsize=10)


def patterning_figure(ds: xr.Dataset, path=None):
    """One row of seed Figures 3.1/3.2: patterning space, a_0 (d_0) curves, dispersion curves."""
    fig = Figure(figsize=(16, 4.8), layout="constrained")
    axes = fig.subplots(1, 3)
    draw_patterning_space(axes[0], ds)
    draw_critical_curves(axes[1], axes[2], ds)
    return _finish(fig, path)


def dispersion_figure(ds: xr.Dataset, path=None, branches: int = 4):
    """Re phi(k) and Im phi(k) of the leading roots, and the constant term: det M(0, k) (derived analysis), or
    a_0, d_0 (seed's, as a_0/k^2, d_0/((kappa/eta)(2mu+lambda)k^6))."""
    fig = Figure(figsize=(16, 4.8), layout="constrained")
    axes = fig.subplots(1, 3)
    k = ds["k"].values
    real, imag = ds["growth_rate_real"].values, ds["growth_rate_imag"].values
    for b in range(min(branches, real.shape[1])):
        axes[0].plot(k, real[:, b], linewidth=2.0 if b == 0 else 1.0, label=f"branch {b}")
        axes[1].plot(k, imag[:, b], linewidth=2.0 if b == 0 else 1.0, label=f"branch {b}")
    # rates span ~1e-7 (slow modes at small k) to ~1e3 (elastic waves): symmetric log scales
    axes[0].set_yscale("symlog", linthresh=1e-6)
    axes[1].set_yscale("symlog", linthresh=1e-3)
    axes[0].axhline(0.0, color="black", linewidth=0.7)
    for prefix, style in (("turing", "-"), ("fastest", ":")):
        if ds.attrs.get(f"{prefix}_unstable"):
            axes[0].axvline(ds.attrs[f"{prefix}_k_max"], color="gray", linestyle=style,
                            label=f"{prefix} k_max = {ds.attrs[f'{prefix}_k_max']:.3g}")
    seed = "a0" in ds  # the hand-derived seed analysis: P_1 + P_2 P_3, a_0 and d_0
    axes[0].set_title(f"Re phi (leading roots{' of P_1 + P_2 P_3' if seed else ''}; symlog, linear below 1e-6)",
                      fontsize=10)
    axes[1].set_title("Im phi", fontsize=10)
    K = k**2
    with np.errstate(divide="ignore", invalid="ignore"):
        if seed:
            modulus = ds.attrs["parameter_kappa"] / ds.attrs["parameter_eta"]
            axes[2].plot(k, ds["a0"].values / K, label="a_0 / k^2 (uncoupled)")
            from primordia.physics.seed_parameters import lame

            mu, lam = lame({"E": ds.attrs["parameter_E"], "nu": ds.attrs["parameter_nu"]})
            axes[2].plot(k, ds["d0"].values / (modulus * (2 * mu + lam) * K**3),
                         label="d_0 / ((kappa/eta)(2mu+lambda) k^6) (coupled)")
        else:
            axes[2].plot(k, ds["constant_term"].values, label="det M(0, k) / prod |row i of M(0, k)| (in [-1, 1])")
    if seed:
        small_k = [abs(line.get_ydata()[0]) for line in axes[2].get_lines()]
        axes[2].set_yscale("symlog", linthresh=max(min(small_k), 1e-12))  # the sign at small k matters
    axes[2].axhline(0.0, color="black", linewidth=0.7)
    axes[2].set_title("constant terms (negative: a real positive root)", fontsize=10)
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("k")
        ax.legend(fontsize=7, loc="best")
    return _finish(fig, path)


def _finish(fig, path):
    """Save to ``path`` atomically (never a half-written picture) when given; return the figure."""
    if path is not None:
        path = Path(path)
        make_directory(path.parent)
        with atomic_path(path) as temporary:
            fig.savefig(temporary, dpi=130, format=path.suffix.lstrip(".") or "png")
    return fig
