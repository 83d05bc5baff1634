"""Patterning spaces (seed Figures 3.1-3.3) and dispersion curves as xarray Datasets / NetCDF.

A patterning space maps, over a grid of two parameters (the others fixed),
where the steady state (2.6) is Turing-unstable, computed two independent ways:

* from the conditions: ``unstable_conditions`` is the exact "a_0 (uncoupled) or
  d_0 (coupled) < 0 for some k" criterion, ``seed_conditions`` the region the
  seed's inequalities describe, and one variable per seed condition whose zero
  level is its boundary curve (``condition_3_7a`` ..., by the seed's printed numbers);
* from the growth rates: ``turing_growth_rate`` = max over k and over real
  roots of phi (the eigenvalue solver of :mod:`primordia.analysis.dispersion`),
  ``unstable_numerical`` = it is > 0; oscillatory growth is kept apart
  (``oscillatory_growth_rate``), as the seed considers Turing patterns only.

With the map come the seed's second and third panels: a_0(k^2) (or d_0) and
the dispersion curve max Re phi(k^2) at the critical value of one parameter and
at 50%, 75%, 125% and 150% of it.  All quantities are dimensionless.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from primordia.analysis.conditions import instability_conditions as evaluate_conditions
from primordia.analysis.conditions import critical_value, most_negative_k_squared
from primordia.analysis.dispersion import (
    default_wavenumbers,
    fastest_growing_mode,
    growth_rates,
    longitudinal_rates,
    max_growth_of_kind,
)
from primordia.analysis.linearisation import linearise, wave_vectors
from primordia.analysis.polynomials import a0, a0_quadratic, d0, d0_quadratic
from primordia.core.atomic_files import atomic_path, make_directory
from primordia.core.errors import ConfigError
from primordia.physics.seed_parameters import seed_parameters

#: Multiples of the critical value drawn in the seed's panels (2) and (3).
CRITICAL_SCALES = (0.5, 0.75, 1.0, 1.25, 1.5)
#: Peak bytes of a patterning space per (y value, wavenumber searched) of a row, and per grid cell (measured:
#: about 4 kB and well under 1 kB; 81 x 81 at 64 wavenumbers peaks near 200 MB).
BYTES_PER_ROW_RATE = 5_000
BYTES_PER_CELL = 1_000

#: The seed's boundary curves: variable, label, matplotlib style (Figures 3.1, 3.2 captions).
UNCOUPLED_CURVES = (
    ("condition_3_7a", "(3.7a)", {"color": "green", "linestyle": "-"}),
    ("condition_3_7b", "(3.7b)", {"color": "red", "linestyle": "--"}),
    ("condition_3_7c", "(3.7c)", {"color": "blue", "linestyle": "-."}),
)
COUPLED_CURVES = (
    ("condition_3_8a_theta_1", "(3.8a) theta_1", {"color": "black", "linestyle": "-"}),
    ("condition_3_8a_theta_2", "(3.8a) theta_2", {"color": "green", "linestyle": "--"}),
    ("condition_3_8a_theta_3", "(3.8a) theta_3", {"color": "orange", "linestyle": "--"}),
    ("condition_3_8b", "(3.8b)", {"color": "red", "linestyle": ":"}),
    ("condition_3_8c", "(3.8c)", {"color": "blue", "linestyle": "-."}),
    ("condition_3_9", "(3.9) as printed", {"color": "magenta", "linestyle": (0, (3, 1, 1, 1, 1, 1))}),
)
#: With the corrected theta_1 = 0 the theta_1, (3.8c) and (3.9) curves vanish; these describe d_0.
COUPLED_CORRECTED_CURVES = (
    ("condition_3_7a_d0", "theta_3 = 0 (X_c = 0)", {"color": "green", "linestyle": "-"}),
    ("condition_3_7b_d0", "theta_2 = 0 (Y_c = 0)", {"color": "red", "linestyle": "--"}),
    ("condition_3_7c_d0", "theta_3^2 = 4 theta_4 theta_2", {"color": "blue", "linestyle": "-."}),
)


@dataclass(frozen=True)
class ParameterRange:
    """``n`` values of parameter ``name`` from ``low`` to ``high`` (inclusive, linear)."""

    name: str
    low: float
    high: float
    n: int

    @classmethod
    def parse(cls, text: str) -> "ParameterRange":
        """``"NAME:LO:HI:N"``, e.g. ``"m0:0.1:4:81"``; malformed text is a :class:`ConfigError`."""
        parts = str(text).split(":")
        if len(parts) != 4 or not parts[0].strip():
            raise ConfigError(f"parameter range must be NAME:LO:HI:N (e.g. m0:0.1:4:81), got {text!r}")
        name = parts[0].strip()
        try:
            low, high = float(parts[1]), float(parts[2])
        except ValueError:
            raise ConfigError(f"parameter range {text!r}: LO and HI must be numbers") from None
        try:
            n = int(parts[3])
        except ValueError:
            raise ConfigError(f"parameter range {text!r}: N must be an integer") from None
        return cls(name, low, high, n)

    def __post_init__(self):
        if not (np.isfinite(self.low) and np.isfinite(self.high)) or self.high <= self.low:
            raise ConfigError(f"parameter range {self.name}: need LO < HI, got {self.low:g}:{self.high:g}")
        if self.n < 2:
            raise ConfigError(f"parameter range {self.name}: need N >= 2 points, got {self.n}")

    @property
    def values(self) -> np.ndarray:
        return np.linspace(self.low, self.high, self.n)

    def __str__(self) -> str:
        return f"{self.name}:{self.low:g}:{self.high:g}:{self.n}"


def as_range(spec) -> ParameterRange:
    """A :class:`ParameterRange` from itself, ``"NAME:LO:HI:N"`` or ``(name, lo, hi, n)``."""
    if isinstance(spec, ParameterRange):
        return spec
    if isinstance(spec, str):
        return ParameterRange.parse(spec)
    try:
        name, low, high, n = spec
    except (TypeError, ValueError):
        raise ConfigError(f"parameter range must be NAME:LO:HI:N or (name, lo, hi, n), got {spec!r}") from None
    return ParameterRange(str(name), float(low), float(high), int(n))


def _checked_base(params, ranges, coupled: bool):
    """The fixed parameters, with every range's endpoints validated by the parameter declarations."""
    base = params if params is not None else seed_parameters()
    if not hasattr(base, "replace"):
        base = seed_parameters(**dict(base))
    for r in ranges:
        base.declaration(r.name)  # unknown name -> ConfigError with suggestions
        base.replace(**{r.name: r.low})  # wrong sign -> ConfigError naming the parameter
        base.replace(**{r.name: r.high})
        if not coupled and r.name in ("xi_f", "tau"):
            raise ConfigError(f"--uncoupled sets xi_f = 0, so {r.name} has no effect; map it with --coupled")
    if len({r.name for r in ranges}) != len(ranges):
        raise ConfigError("the two axes of a patterning space must be different parameters")
    if not coupled:
        base = base.replace(xi_f=0.0)
    return base


def _attrs_of(params: Mapping) -> dict:
    return {f"parameter_{name}": float(value) for name, value in params.items()}


def _check_affordable(x: "ParameterRange", y: "ParameterRange", nk: int) -> None:
    """ConfigError when the grid would need more memory than this machine has available (refused before
    anything is allocated: ``--y alpha:0:12:100000000`` had the kernel kill the process at 24 GB)."""
    from primordia.core.meshes import _bytes_text, available_memory

    needed = y.n * (int(nk) + 1) * BYTES_PER_ROW_RATE + x.n * y.n * BYTES_PER_CELL
    available = available_memory()
    if needed > available:
        raise ConfigError(f"a patterning space of {x.n:,} x {y.n:,} points and {int(nk):,} wavenumbers needs about "
                          f"{_bytes_text(needed)} of memory, more than the {_bytes_text(available)} available: "
                          f"use fewer points")


def _check_finite(coefficients, x: "ParameterRange", y: "ParameterRange") -> None:
    """ConfigError naming the first grid point whose linearisation is not finite (a Hill exponent P_2 = 3000
    overflows K_2^P_2): its NaNs stopped the eigenvalue search with an AssertionError."""
    import dataclasses

    finite = np.ones((x.n, y.n), dtype=bool)
    for field in dataclasses.fields(coefficients):
        value = np.asarray(getattr(coefficients, field.name))
        if np.issubdtype(value.dtype, np.number):
            finite &= np.broadcast_to(np.isfinite(value), finite.shape)
    if not finite.all():
        i, j = (int(index[0]) for index in np.nonzero(~finite))
        raise ConfigError(f"the linearisation is not finite at {x.name} = {x.values[i]:g}, {y.name} = {y.values[j]:g} "
                          f"(its rates overflow): narrow the parameter ranges")


def patterning_space(x, y, params=None, coupled: bool = True, k=None, nk: int = 96,
                     critical_parameter: str | None = None, theta_variant: str = "corrected") -> xr.Dataset:
    """The patterning space over parameters ``x`` and ``y`` (seed Figures 3.1-3.3, panel 1 and 2-3).

    ``x``, ``y``: ``"NAME:LO:HI:N"``, ``(name, lo, hi, n)`` or :class:`ParameterRange`.
    ``params``: the fixed parameters (Table 3.1 by default).  ``coupled=False``
    drops the mechano-chemical loop (xi_f = 0).  ``k``: wavenumbers searched
    (default: log-spaced, ``nk`` of them, past the widest predicted band).
    ``critical_parameter`` (default: ``x``'s) is the one whose critical value
    and +-25%, +-50% curves make panels 2-3; ``theta_variant`` chooses the
    theta_i for the coupled conditions ("corrected" or the seed's "seed").
    """
    x, y = as_range(x), as_range(y)
    _check_affordable(x, y, nk if k is None else np.size(k))
    base = _checked_base(params, (x, y), coupled)
    grid = dict(base)
    grid[x.name] = x.values[:, None]
    grid[y.name] = y.values[None, :]
    with np.errstate(all="ignore"):
        coefficients = linearise(grid)
    _check_finite(coefficients, x, y)
    k = default_wavenumbers(coefficients, nk, coupled) if k is None else np.asarray(k, dtype=float)

    found = evaluate_conditions(coefficients, coupled, theta_variant)
    quadratic = d0_quadratic if coupled else a0_quadratic
    stationary = np.empty((x.n, y.n))
    oscillatory = np.empty((x.n, y.n))
    any_growth = np.empty((x.n, y.n))
    k_turing = np.full((x.n, y.n), np.nan)
    for i, xv in enumerate(x.values):  # one row at a time keeps memory at ny * nk * 7 * 7 numbers
        row = dict(grid)
        row[x.name] = xv
        row[y.name] = y.values
        row_coefficients = linearise(row)
        rates = longitudinal_rates(row_coefficients, k, coupled=True)  # xi_f = 0 already if uncoupled
        # also at each cell's own k where a_0 (d_0) is most negative, so a narrow band between grid
        # wavenumbers is not missed; the eigenvalues there still decide independently
        k_cell = np.sqrt(most_negative_k_squared(*quadratic(row_coefficients)))
        at_cell = longitudinal_rates(row_coefficients, k_cell, coupled=True, paired=True)
        rates = np.concatenate([rates, at_cell[:, None, :]], axis=1)
        searched = np.concatenate([np.broadcast_to(k, (y.n, k.size)), k_cell[:, None]], axis=1)
        per_k = max_growth_of_kind(rates, "stationary")
        stationary[i] = per_k.max(axis=-1)
        best = per_k.argmax(axis=-1)
        k_turing[i] = np.where(stationary[i] > 0, searched[np.arange(y.n), best], np.nan)
        oscillatory[i] = max_growth_of_kind(rates, "oscillatory").max(axis=-1)
        any_growth[i] = max_growth_of_kind(rates, "any").max(axis=-1)

    dims = (x.name, y.name)
    # CF: the flag values of the variable's own type (the text "0 1" was an error to cfchecks)
    flag = {"flag_values": np.array([0, 1], dtype=np.int8), "flag_meanings": "no yes"}
    ds = xr.Dataset(
        {
            "turing_growth_rate": (dims, stationary, {
                "long_name": "max over k of the largest real root phi (stationary modes)"}),
            "oscillatory_growth_rate": (dims, oscillatory, {
                "long_name": "max over k of Re phi of complex roots (travelling/oscillating modes)"}),
            "max_growth_rate": (dims, any_growth, {"long_name": "max over k and all roots of Re phi"}),
            "turing_wavenumber": (dims, k_turing, {"long_name": "k of the fastest real root (NaN if stable)"}),
            "unstable_numerical": (dims, (stationary > 0).astype(np.int8), {
                "long_name": "Turing-unstable from the growth rates (max real root > 0)", **flag}),
            "unstable_conditions": (dims, np.asarray(found.region, dtype=np.int8), {
                "long_name": f"{'d_0' if coupled else 'a_0'} < 0 for some k > 0 (exact criterion)", **flag}),
            "seed_conditions": (dims, np.asarray(found.seed_region, dtype=np.int8), {
                "long_name": "region described by the seed's conditions: " + _seed_region_text(coupled, theta_variant),
                **flag}),
        },
        coords={
            x.name: (x.name, x.values, {"long_name": base.declaration(x.name).description,
                                        "units": "1"}),
            y.name: (y.name, y.values, {"long_name": base.declaration(y.name).description,
                                        "units": "1"}),
            "k": ("k", k, {"long_name": "wavenumbers searched", "units": "1"}),
        },
        attrs={
            "title": f"primordia patterning space over ({x.name}, {y.name})",
            "Conventions": "CF-1.8",  # cfchecks 4.1: no error or warning (units "dimensionless" and text
            # flag_values were errors until 2026-12-05)
            "coupled": int(coupled),
            "theta_variant": theta_variant if coupled else "",
            "x": x.name,
            "y": y.name,
            "conventions": "seed = Barnafi et al., section 3; corrections in primordia/analysis/polynomials.py",
            **_attrs_of(base),
        },
    )
    for name, value in found.values.items():
        var = "condition_" + name.replace(".", "_").replace(":", "_")
        ds[var] = (dims, np.broadcast_to(value, (x.n, y.n)).astype(float),
                   {"long_name": f"left side of seed condition ({name}); boundary where it is 0"})
    _add_critical_curves(ds, base, critical_parameter or x.name, coupled)
    return ds


def _seed_region_text(coupled: bool, theta_variant: str) -> str:
    if not coupled:
        return "((3.7a) or (3.7b)) and (3.7c)"
    if theta_variant == "seed":
        return "(3.8a)-(3.8c) violated, printed theta"
    return "((3.7a) or (3.7b)) and (3.7c) on d_0, i.e. (3.8a)-(3.9) on d_0'/k^2 with theta_1 = 0"


def _add_critical_curves(ds: xr.Dataset, base, name: str, coupled: bool) -> None:
    """Panels 2-3 of the seed's figures: a_0 (d_0) and max Re phi vs k^2 at the critical value x scales."""
    critical = critical_value(base, name, coupled=coupled)
    ds.attrs["critical_parameter"] = name
    if critical is None:
        ds.attrs["critical_value"] = np.nan
        ds.attrs["critical_note"] = f"no sign change of min_k {'d_0' if coupled else 'a_0'} found for {name}"
        return
    ds.attrs["critical_value"] = critical.value
    ds.attrs["critical_wavenumber"] = critical.k_c
    quadratic = d0_quadratic if coupled else a0_quadratic
    values = [critical.value * s for s in CRITICAL_SCALES]
    trials = [dict(base) | {name: v} for v in values]
    ends = []  # where each curve's unstable band (a_0 < 0) ends, for the 75% ... 125% curves
    for trial in trials[1:-1]:
        alpha, X, Y = quadratic(linearise(trial))
        disc = max(float(X**2 - 4 * alpha * Y), 0.0)
        ends.append((-X + np.sqrt(disc)) / (2 * alpha))
    K_c = critical.k_c**2
    K_high = 1.3 * max([e for e in ends if np.isfinite(e) and e > 0] + [3 * K_c, 1.0])
    if K_c > 0:  # keep the critical tangency readable when a neighbouring curve is deep in the unstable region
        K_high = float(np.clip(K_high, 3 * K_c, 10 * K_c))
    K = np.linspace(0.0, K_high, 241)
    k = np.sqrt(K)
    constant_term = [d0(linearise(t), k) if coupled else a0(linearise(t), k) for t in trials]
    growth = [max_growth_of_kind(longitudinal_rates(linearise(t), k, coupled=True), "any") for t in trials]
    turing = [max_growth_of_kind(longitudinal_rates(linearise(t), k, coupled=True), "stationary") for t in trials]
    ds.coords["scale"] = ("scale", np.array(CRITICAL_SCALES), {"long_name": f"{name} / critical {name}"})
    ds.coords["k_squared"] = ("k_squared", K, {"long_name": "k^2", "units": "1"})
    ds[f"critical_{name}"] = ("scale", np.array(values), {"long_name": f"value of {name} on each curve"})
    ds["constant_term"] = (("scale", "k_squared"), np.array(constant_term), {
        "long_name": ("d_0(k^2) = a_0 c_0 + b_0" if coupled else "a_0(k^2)") + " (seed panels 2)"})
    ds["dispersion_max_real"] = (("scale", "k_squared"), np.array(growth), {
        "long_name": "max Re phi(k^2) over all roots (seed panels 3)"})
    ds["dispersion_max_real_stationary"] = (("scale", "k_squared"), np.array(turing), {
        "long_name": "largest real root phi(k^2); -inf where none is real"})


def dispersion_relation(params=None, k=None, d: int = 2, coupled: bool = True, nk: int = 241) -> xr.Dataset:
    """Growth rates phi(k) of one parameter set of the seed's model (hand-derived, seed eq. (3.3)).

    Variables: ``growth_rate_real``/``_imag`` (k, branch: the 7 roots of
    P_1 + P_2 P_3 by descending real part), ``transverse_real``/``_imag`` (the
    2(d-1) roots of B^(d-1)), ``max_growth_rate``, ``turing_growth_rate``,
    ``a0`` and ``d0``; attributes: the fastest modes (any root and real roots
    only), their wavelengths 2 pi / k_max, and the parameters.
    """
    base = params if params is not None else seed_parameters()
    c = linearise(base)
    k = default_wavenumbers(c, nk, coupled) if k is None else np.asarray(k, dtype=float)
    ds = _rates_dataset(growth_rates(c, k, d=d, coupled=coupled), fastest_growing_mode(c, coupled=coupled),
                        fastest_growing_mode(c, coupled=coupled, kind="stationary"), base,
                        title="primordia dispersion relation (seed section 3)", coupled=int(coupled))
    ds["a0"] = ("k", a0(c, k), {"long_name": "a_0(k^2) = P_2(0)"})
    ds["d0"] = ("k", d0(c, k), {"long_name": "d_0(k^2) = P_1(0) + P_2(0) P_3(0)"})
    return ds


def model_dispersion_relation(linear, k=None, d: int = 2, nk: int = 241) -> xr.Dataset:
    """Growth rates phi(k) of a composed model's derived analysis (:mod:`primordia.analysis.composed`).

    ``linear`` is a :class:`~primordia.analysis.composed.LinearisedModel`.  The
    variables of :func:`dispersion_relation` (``branch`` runs over every root but
    the shear waves), with ``constant_term`` = det M(0, k), scaled by the product of
    the norms of its rows, in place of a_0 and d_0 (negative: a real positive root);
    attributes also name the physics, the kinetics and the steady state.  By Hadamard's
    inequality the scaled term lies in [-1, 1]; scaled by the product of the diagonal
    entries, as it was, it spiked wherever one of them crossed zero (Schnakenberg's activator at
    k = 0.894 for a = 0.1, b = 0.9, gamma = 1).
    """
    k = linear.wavenumbers(nk) if k is None else np.asarray(k, dtype=float)
    M0 = linear.pencil(wave_vectors(k, d))[0]
    ds = _rates_dataset(linear.growth_rates(k, d=d), linear.fastest_mode(), linear.fastest_mode("stationary"),
                        linear.parameters, title=f"primordia dispersion relation of {linear.name or 'a model'}",
                        coupled=int(linear.coupled),
                        physics=", ".join(linear.physics), kinetics=linear.kinetics,
                        species=", ".join(linear.species), notes="; ".join(linear.notes),
                        **{f"steady_state_{name}": value for name, value in linear.steady_state.values.items()})
    rows = np.prod(np.linalg.norm(M0, axis=-1), axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ds["constant_term"] = ("k", np.linalg.det(M0).real / rows, {
            "long_name": "det M(0, k) / prod_i |row i of M(0, k)|, in [-1, 1]: negative where a real root "
                         "phi > 0 exists"})
    return ds


def _rates_dataset(roots, fastest, turing, params: Mapping, title: str, **attrs) -> xr.Dataset:
    """The roots of a dispersion relation over k, and its fastest modes, as a Dataset.

    A model without mechanics has no shear waves: it has no ``transverse_*`` variables
    (NetCDF3 has no zero-length dimension; a size-0 one would be written as the
    unlimited dimension, and the file could not be read back).
    """
    variables = {
        "growth_rate_real": (("k", "branch"), roots.rates.real, {"long_name": "Re phi"}),
        "growth_rate_imag": (("k", "branch"), roots.rates.imag, {"long_name": "Im phi"}),
        "max_growth_rate": ("k", max_growth_of_kind(roots.rates, "any"), {
            "long_name": "max Re phi over the roots but the shear waves"}),
        "turing_growth_rate": ("k", max_growth_of_kind(roots.rates, "stationary"), {
            "long_name": "largest real root (stationary mode); -inf where none"}),
    }
    coords = {"k": ("k", roots.k, {"long_name": "wavenumber", "units": "1"}),
              "branch": ("branch", np.arange(roots.rates.shape[-1]), {"long_name": "root of the dispersion relation",
                                                                      "units": "1"})}
    if roots.transverse.shape[-1]:
        variables["transverse_real"] = (("k", "transverse_branch"), roots.transverse.real, {
            "long_name": "Re phi of the roots of B^(d-1) = (rho phi^2 + mu k^2)^(d-1) (neutral)"})
        variables["transverse_imag"] = (("k", "transverse_branch"), roots.transverse.imag, {
            "long_name": "Im phi of the roots of B^(d-1) (shear waves, +- k sqrt(mu / rho))"})
        coords["transverse_branch"] = ("transverse_branch", np.arange(roots.transverse.shape[-1]), {
            "long_name": "root of B^(d-1)", "units": "1"})
    return xr.Dataset(variables, coords=coords,
                      attrs={"title": title, "Conventions": "CF-1.8", "d": roots.d, **attrs,
                             **_mode_attrs("fastest", fastest),
                             **_mode_attrs("turing", turing), **_attrs_of(params)})


def _mode_attrs(prefix: str, mode) -> dict:
    return {
        f"{prefix}_k_max": mode.k_max,
        f"{prefix}_wavelength": mode.wavelength,
        f"{prefix}_growth_rate": mode.growth_rate,
        f"{prefix}_frequency": mode.frequency,
        f"{prefix}_unstable": int(mode.unstable),
        f"{prefix}_at_edge_of_k_range": int(mode.at_edge),
    }


def boundary_agreement(ds: xr.Dataset, numerical: str = "unstable_numerical",
                       predicted: str = "unstable_conditions") -> dict:
    """Compare two 0/1 maps: cells that differ, and those of them not next to ``predicted``'s boundary.

    A cell is "next to the boundary" if ``predicted`` changes value within its
    3 x 3 neighbourhood; disagreement there is grid resolution, elsewhere it is
    a real difference between the two methods.
    """
    a = ds[numerical].values.astype(bool)
    b = ds[predicted].values.astype(bool)
    padded = np.pad(b, 1, mode="edge")
    rows, cols = b.shape
    near = np.zeros_like(b)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            near |= padded[1 + di:1 + di + rows, 1 + dj:1 + dj + cols] != b
    differ = a != b
    return {"disagree": int(differ.sum()), "off_boundary": int((differ & ~near).sum()),
            "cells": int(b.size)}


def save_dataset(ds: xr.Dataset, path) -> Path:
    """Write ``ds`` as NetCDF (scipy engine), atomically.

    NetCDF3 has no zero-length dimension (size 0 marks the unlimited one): a Dataset
    with one would be written as a file no reader opens, so it is refused here.
    """
    path = Path(path)
    empty = sorted(str(name) for name, size in ds.sizes.items() if size == 0)
    if empty:
        raise ValueError(f"cannot write {path}: NetCDF3 has no zero-length dimension ({', '.join(empty)})")
    make_directory(path.parent)
    clean = ds.copy()
    for name, var in clean.variables.items():  # NetCDF3 has no +-inf-safe bool; inf is fine, bool is not
        if var.dtype == bool:
            clean[name] = var.astype(np.int8)
    with atomic_path(path) as temporary:
        clean.to_netcdf(temporary, engine="scipy")
    return path


__all__ = [
    "COUPLED_CURVES",
    "COUPLED_CORRECTED_CURVES",
    "CRITICAL_SCALES",
    "ParameterRange",
    "UNCOUPLED_CURVES",
    "as_range",
    "boundary_agreement",
    "dispersion_relation",
    "model_dispersion_relation",
    "patterning_space",
    "save_dataset",
]
