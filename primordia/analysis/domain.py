"""The modes a bounded domain admits: the linear analysis on the box a run is solved on.

The analysis of seed section 3 takes any wavenumber k.  On the box [0, L_1] x ... x [0, L_d]
with zero-flux walls, which the species always have (chemotaxis poses no other condition),
the perturbations are sums of cosine modes

    cos(n_1 pi x_1 / L_1) ... cos(n_d pi x_d / L_d),   k = pi |(n_1 / L_1, ..., n_d / L_d)|,

each growing at the rate phi(k) of the unbounded analysis.  Only these k can grow: a
box smaller than the unstable band's wavelengths forms no pattern, and the fastest
admissible mode, not k_max, is the one that first emerges from small noise.  For
the chemistry alone the cosines are the box's exact modes; with mechanics they are the
exact modes only if the walls are slip walls (zero normal displacement and shear
traction), and an approximation under other conditions (e.g. example 1b's clamped base).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from primordia.analysis.dispersion import max_growth_of_kind
from primordia.core.errors import ConfigError

#: Above this many modes in the unstable band the listing stops (a box far larger than the wavelength:
#: the admissible k are then dense, and the continuous analysis says it all).
MAX_MODES = 2_000_000
#: A box mesh's volume equals its bounding box's to this relative tolerance.
BOX_TOLERANCE = 1e-9


@dataclass(frozen=True)
class DomainModes:
    """The admissible modes of a box with k up to the unstable band's end, and their growth rates."""

    lengths: tuple[float, ...]
    indices: np.ndarray  #: (modes, d) integers n_i
    k: np.ndarray  #: (modes,) pi |n / L|
    growth: np.ndarray  #: (modes,) largest Re phi of the roots of ``kind``; -inf where none
    kind: str
    band_end: float = 0.0  #: the highest unstable k of ``kind`` (0 when none grows)

    @property
    def unstable(self) -> np.ndarray:
        return self.growth > 0

    @property
    def fastest(self) -> int:
        """Index of the fastest-growing mode (the first of modes that tie, e.g. (n, m) and (m, n))."""
        return int(np.argmax(self.growth))

    def ties(self, index: int) -> list[tuple[int, ...]]:
        """The modes with the same k as mode ``index`` (on a square, (n, m) and (m, n))."""
        same = np.isclose(self.k, self.k[index], rtol=1e-12, atol=0.0)
        return [tuple(int(n) for n in row) for row in self.indices[same]]

    def describe(self) -> str:
        box = " x ".join(f"{length:g}" for length in self.lengths)
        if not np.any(self.unstable):
            article = "an" if self.kind[0] in "aeiou" else "a"
            why = (f" (its unstable band ends at k = {self.band_end:.4g}, below the box's lowest k, pi / "
                   f"{max(self.lengths):g} = {np.pi / max(self.lengths):.4g})" if self.band_end > 0 and self.k.size <= 1
                   else "")
            return (f"on the {box} box (zero-flux cosine modes) no admissible mode grows as {article} {self.kind} "
                    f"mode{why}")
        best = self.fastest
        modes = ", ".join(str(mode) for mode in self.ties(best)[:4])
        wavelength = (f"wavelength {2.0 * np.pi / self.k[best]:.4g}" if self.k[best] > 0 else
                      "the homogeneous mode")  # n = 0: the box's whole, no wavelength (it said "inf", warning)
        return (f"on the {box} box (zero-flux cosine modes) the fastest is n = {modes}: k = {self.k[best]:.4g}, "
                f"{wavelength}, growth rate {self.growth[best]:.4g}; "
                f"{int(np.count_nonzero(self.unstable))} admissible modes grow")


def domain_modes(rates_at, lengths, band, kind: str = "stationary") -> DomainModes:
    """The box's modes with k <= the band's upper end and their growth rates.

    ``rates_at(k) -> roots`` is the dispersion relation (:meth:`LinearisedModel.rates`);
    ``band`` the unstable band (lowest, highest k) of ``kind``, NaN when none grows.
    """
    lengths = tuple(float(length) for length in lengths)
    k_high = float(band[1]) if np.isfinite(band[1]) else 0.0
    counts = [int(np.floor(k_high * length / np.pi)) + 1 for length in lengths]
    if np.prod(np.asarray(counts, dtype=float)) > MAX_MODES:
        raise ConfigError(f"the {' x '.join(f'{length:g}' for length in lengths)} box admits more than "
                          f"{MAX_MODES} modes below k = {k_high:.4g}: they are dense, as the continuous analysis "
                          f"assumes")
    indices = np.array(list(itertools.product(*(range(count) for count in counts))), dtype=int)
    k = np.pi * np.linalg.norm(indices / np.asarray(lengths), axis=1)
    inside = k <= k_high
    indices, k = indices[inside], k[inside]
    distinct, which = np.unique(np.round(k, 12), return_inverse=True)  # modes of one k share their rates
    growth = max_growth_of_kind(rates_at(distinct), kind)[which]
    return DomainModes(lengths=lengths, indices=indices, k=k, growth=growth, kind=kind, band_end=k_high)


def box_lengths(mesh_data) -> tuple[float, ...] | None:
    """The side lengths of a mesh that fills its bounding box (a rectangle or a box), else None."""
    points = mesh_data.points
    lengths = points.max(axis=0) - points.min(axis=0)
    volume = float(np.prod(lengths))
    if volume <= 0 or abs(float(np.sum(mesh_data.cell_volumes())) - volume) > BOX_TOLERANCE * volume:
        return None
    return tuple(float(length) for length in lengths)


def parse_lengths(text: str, d: int) -> tuple[float, ...]:
    """``"20,20"`` -> (20.0, 20.0): d positive side lengths, or one line naming the problem."""
    try:
        lengths = tuple(float(part) for part in str(text).split(","))
    except ValueError:
        raise ConfigError(f"--domain expects the box's side lengths L1,L2[,L3], got {text!r}") from None
    if len(lengths) != d:
        raise ConfigError(f"--domain {text}: {len(lengths)} side lengths for d = {d} (--d sets the dimension)")
    if not all(np.isfinite(length) and length > 0 for length in lengths):
        raise ConfigError(f"--domain {text}: side lengths must be positive and finite")
    return lengths


def with_domain_modes(ds, modes: DomainModes):
    """``ds`` (a dispersion Dataset) with the box's admissible modes: ``mode_k``, ``mode_growth_rate``, ``mode_n``."""
    best = modes.fastest
    attrs = {"domain_lengths": np.asarray(modes.lengths),
             "domain_unstable_modes": int(np.count_nonzero(modes.unstable)),
             "domain_fastest_n": modes.indices[best], "domain_fastest_k": float(modes.k[best]),
             "domain_fastest_growth_rate": float(modes.growth[best])}
    return ds.assign(
        mode_k=("mode", modes.k, {"long_name": "pi |n / L| of the box's zero-flux cosine mode n"}),
        mode_growth_rate=("mode", modes.growth, {
            "long_name": f"largest Re phi of the {modes.kind} roots at the mode's k; -inf where none"}),
        mode_n=(("mode", "axis"), modes.indices, {"long_name": "the mode's n_i: cos(n_i pi x_i / L_i)"}),
    ).assign_attrs(attrs)
