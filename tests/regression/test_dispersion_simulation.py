"""The linear stability analysis against the finite elements (issue 4): one cosine mode, measured.

On a strip (0, L) x (0, h) with zero-flux boundaries, ``primordia run`` starts
the chemotaxis model (seed eqs. (2.2a)-(2.2d)) with the priming wave off
(``w = omega_1``, the state seed section 3 linearises about) from

    m(x, 0) = m0 (1 + A cos(k x)),    k = 2 pi / L,    e, f, b at rest (seed eq. (2.5)).

The cosine meets the zero-flux condition and is an exact eigenvector of the P1
lumped-mass Neumann Laplacian on the grid, so the linearised discrete dynamics
keep the mode a cosine; its amplitude a(t), the projection of m - m0 on cos(k x)
(lumped quadrature over the vertices), is a sum of four exponentials, one per
root of P_2 = det M_22.  Once the others have died out, log|a| is a straight
line of slope Re phi(k), which the test fits and compares with the analysis.

Which root: the chemotaxis-only model is the m, e, f, b block of seed Definition
3.1, so its rates are the four roots of P_2 (``chemotaxis_coefficients``).  The
uncoupled analysis (``growth_rates(params, k, coupled=False)``, xi_f = 0) returns
the seven roots of P_2 P_3, which include the three poroelastic roots of P_3;
at k = 7.5 a damped poroelastic wave (Re phi = -0.044) lies above the slowest
chemical root (-0.2014), so "max Re phi over the uncoupled roots" would predict
-0.044 there, a root the simulated model does not have.  The P_2 roots are checked to be among the
uncoupled roots, then the largest is taken.

Modes (parameters of seed example 1a, ``examples/stability/dispersion_strip.toml``):

* growing: k = k_max = 2.784 (analysis: Re phi = 0.1546), dt = 0.05, 45 cells on
  one wavelength: -0.8% from backward Euler; P1 dispersion is nil to first
  order (d phi / dk = 0 at k_max);
* decaying: k = 7.5 outside the band (0, 5.26) (Re phi = -0.2014), dt = 0.02,
  h = 0.02: +0.9% (time) +0.3% (space, (k h)^2 / 12 amplified 1.7x by d phi / dK).

Both errors are the scheme's, not a modelling gap: the rate of the linearised
discrete step (the 4 x 4 Gauss-Seidel step m, e, f, b of chemotaxis.py with k^2
replaced by (2 sin(k h/2) / h)^2) is 0.1534058 and -0.1990126, the measured
rates 0.1534059 and -0.1990067.

Both run through the installed ``primordia`` command on both backends with the
default (exponentially fitted) flux; at Peclet numbers this small it is the
central scheme, so the plain Galerkin flux must give the same rates.  The 5%
tolerance is the issue's; 10% off in D_m (or alpha) moves the predicted rates by
9-18%, and a flipped chemotaxis sign turns the growing mode into a decaying one.
About 20 s in all.
"""

from __future__ import annotations

import math
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import meshio
import numpy as np
import pytest

from primordia.analysis import chemotaxis_coefficients, fastest_growing_mode, growth_rates
from primordia.analysis.inputs import read_parameters

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "stability" / "dispersion_strip.toml"
PRIMORDIA = Path(sys.executable).parent / "primordia"
BACKENDS = ("fenicsx", "skfem")
TOLERANCE = 0.05  # |measured - predicted| <= 5% |predicted| (issue 4)


@dataclass(frozen=True)
class ModeRun:
    """One cosine mode on one wavelength L = 2 pi / k, and how it is run and measured."""

    name: str
    perturbation: float  #: A in m(0) = m0 (1 + A cos k x): small, so the dynamics stay linear
    cells_along: int  #: squares along x on (0, L); one across
    dt: float
    t_final: float
    output_every: float
    fit_from: float  #: start of the fit window: the other three roots are e^-10 down by then


MODES = {
    # gap to the next root: 0.155 + 1.417 = 1.57, so e^(-1.57 * 8) = 3e-6 at t = 8
    "growing": ModeRun("growing", perturbation=1e-4, cells_along=45, dt=0.05, t_final=24.0,
                       output_every=1.0, fit_from=8.0),
    # gap 2.32 - 0.20 = 2.1 (and a slower start: the e-root is excited most), 1e-4 by t = 6
    "decaying": ModeRun("decaying", perturbation=1e-3, cells_along=42, dt=0.02, t_final=12.0,
                        output_every=0.5, fit_from=6.0),
}
DECAYING_WAVENUMBER = 7.5


# -- the analysis side --------------------------------------------------------------------


@pytest.fixture(scope="module")
def params():
    """The parameters the simulation reads: the example's [parameters] over Table 3.1."""
    return read_parameters(EXAMPLE)


@pytest.fixture(scope="module")
def wavenumbers(params):
    fastest = fastest_growing_mode(params, coupled=False, kind="stationary")
    assert fastest.band[1] < DECAYING_WAVENUMBER, fastest.band  # k = 7.5 really is outside the band
    return {"growing": fastest.k_max, "decaying": DECAYING_WAVENUMBER}


def chemotaxis_rates(params, k: float) -> np.ndarray:
    """The four roots of P_2 (the m, e, f, b block), checked to be roots of the uncoupled det M."""
    roots = np.roots(np.array(chemotaxis_coefficients(params, k), dtype=float)[::-1])
    uncoupled = growth_rates(params, [k], coupled=False).rates[0]
    for root in roots:
        assert np.min(np.abs(uncoupled - root)) <= 1e-8 * (1.0 + abs(root)), (root, uncoupled)
    return roots


def predicted_rate(params, k: float) -> float:
    """max Re phi(k) of the chemotaxis model: a real (stationary) root at both modes here."""
    roots = chemotaxis_rates(params, k)
    leading = roots[np.argmax(roots.real)]
    assert abs(leading.imag) <= 1e-10 * abs(leading), f"leading root {leading} is not real"
    return float(leading.real)


# -- the simulation side --------------------------------------------------------------------


def run_mode(mode: ModeRun, k: float, backend: str, out: Path, flux_scheme: str | None = None) -> Path:
    """``primordia run`` the example with this mode's strip, wavenumber and output times."""
    length = 2.0 * math.pi / k
    h = length / mode.cells_along
    steps_per_frame = round(mode.output_every / mode.dt)
    frames = round(mode.t_final / mode.output_every)
    times = [round(i * steps_per_frame * mode.dt, 12) for i in range(1, frames + 1)]
    overrides = [
        f"physics.chemotaxis.wavenumber=[{k!r}, 0.0]",
        f"physics.chemotaxis.perturbation={mode.perturbation!r}",
        'physics.chemotaxis.perturbation_shape="cosine"',
        "kinetics.priming_wave=false",
        f"mesh.upper=[{length!r}, {h!r}]",
        f"mesh.cells=[{mode.cells_along}, 1]",
        f"time.dt={mode.dt!r}",
        f"time.t_final={mode.t_final!r}",
        f"output.times=[{', '.join(map(repr, times))}]",
        "output.pictures=false",
    ]
    if flux_scheme is not None:
        overrides.append(f'physics.chemotaxis.flux_scheme="{flux_scheme}"')
    command = [str(PRIMORDIA), "run", str(EXAMPLE), "--backend", backend, "--out", str(out), "--no-progress"]
    for assignment in overrides:
        command += ["--set", assignment]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "primordia: completed" in done.stdout, done.stdout
    return out / "fields.xdmf"


def lumped_weights(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Vertex quadrature weights: a third of each triangle's area to each of its vertices."""
    corners = points[triangles, :2]
    edge_1, edge_2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    area = 0.5 * np.abs(edge_1[:, 0] * edge_2[:, 1] - edge_1[:, 1] * edge_2[:, 0])
    weights = np.zeros(len(points))
    np.add.at(weights, triangles.ravel(), np.repeat(area / 3.0, 3))
    return weights


def cosine_amplitudes(fields_xdmf: Path, m0: float, k: float) -> tuple[np.ndarray, np.ndarray]:
    """(t, a(t)): the L2 projection, in lumped quadrature, of m - m0 on cos(k x) at each output time."""
    with meshio.xdmf.TimeSeriesReader(fields_xdmf) as reader:
        points, cells = reader.read_points_cells()
        frames = [reader.read_data(i) for i in range(reader.num_steps)]
    weights = lumped_weights(points, cells[0].data)
    mode = np.cos(k * points[:, 0])
    times = np.array([t for t, _, _ in frames])
    amplitudes = np.array([np.sum(weights * (data["m"].ravel() - m0) * mode) for _, data, _ in frames])
    return times, amplitudes / np.sum(weights * mode**2)


@dataclass(frozen=True)
class Measurement:
    times: np.ndarray
    amplitudes: np.ndarray
    rate: float  #: slope of the least-squares line through log|a| over the fit window
    misfit: float  #: max |log|a| - line| over the window: ~0 for one pure exponential

    @classmethod
    def fit(cls, times, amplitudes, fit_from: float) -> "Measurement":
        window = times >= fit_from - 1e-9
        assert np.count_nonzero(window) >= 5, times
        log_amplitude = np.log(np.abs(amplitudes[window]))
        slope, intercept = np.polyfit(times[window], log_amplitude, 1)
        misfit = float(np.max(np.abs(log_amplitude - (slope * times[window] + intercept))))
        return cls(times, amplitudes, float(slope), misfit)


@pytest.fixture(scope="module")
def measure(tmp_path_factory, params, wavenumbers):
    """``measure(mode, backend, flux_scheme=None)`` -> :class:`Measurement`, each run once per module."""
    cache: dict = {}

    def run(mode_name: str, backend: str, flux_scheme: str | None = None) -> Measurement:
        key = (mode_name, backend, flux_scheme)
        if key not in cache:
            mode, k = MODES[mode_name], wavenumbers[mode_name]
            out = tmp_path_factory.mktemp(f"{mode_name}_{backend}_{flux_scheme or 'default'}")
            times, amplitudes = cosine_amplitudes(run_mode(mode, k, backend, out, flux_scheme), params["m0"], k)
            cache[key] = Measurement.fit(times, amplitudes, mode.fit_from)
        return cache[key]

    return run


# -- the checks ---------------------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("mode_name", list(MODES))
def test_cosine_mode_grows_at_the_rate_of_the_dispersion_relation(mode_name, backend, params, wavenumbers, measure):
    k = wavenumbers[mode_name]
    predicted = predicted_rate(params, k)
    measured = measure(mode_name, backend)
    error = (measured.rate - predicted) / abs(predicted)
    print(f"\n{mode_name:>8} k = {k:.4f} on {backend:<7}: measured Re phi = {measured.rate:+.5f}, "
          f"predicted {predicted:+.5f} (relative error {error:+.2%}; log-fit misfit {measured.misfit:.1e})")
    assert (predicted > 0) == (mode_name == "growing")
    assert abs(measured.rate - predicted) <= TOLERANCE * abs(predicted), (
        f"{mode_name} mode on {backend}: measured {measured.rate:.5f}, predicted {predicted:.5f} ({error:+.2%})")
    # what makes the slope a growth rate: one real root dominates (a keeps its sign, log|a| is
    # a straight line over the window) and the amplitude stays in the linear regime
    window = measured.times >= MODES[mode_name].fit_from - 1e-9
    assert np.all(measured.amplitudes[window] > 0), f"a(t) changes sign: {measured.amplitudes[window]}"
    assert measured.misfit < 1e-3, f"log|a| is not a straight line over the window (misfit {measured.misfit:.1e})"
    assert np.max(np.abs(measured.amplitudes)) < 3e-3 * params["m0"]


@pytest.mark.parametrize("mode_name", list(MODES))
def test_backends_measure_the_same_rate(mode_name, measure):
    """Same mesh, same scheme: the two backends' amplitudes agree to solver tolerance."""
    fenicsx, skfem = (measure(mode_name, backend) for backend in BACKENDS)
    np.testing.assert_allclose(skfem.amplitudes, fenicsx.amplitudes, rtol=1e-6)
    assert skfem.rate == pytest.approx(fenicsx.rate, rel=1e-6)


@pytest.mark.parametrize("mode_name", list(MODES))
def test_exponential_fitting_is_the_central_scheme_at_small_peclet(mode_name, measure):
    """Linearised, the fitted flux B(-Pe) m_i - B(Pe) m_j is the Galerkin one: same rate to O(A)."""
    fitted = measure(mode_name, "fenicsx")
    galerkin = measure(mode_name, "fenicsx", flux_scheme="galerkin")
    print(f"\n{mode_name:>8}: exponential fitting {fitted.rate:+.7f}, galerkin {galerkin.rate:+.7f}")
    assert galerkin.rate == pytest.approx(fitted.rate, rel=1e-5)


def test_the_example_is_the_growing_mode(params, wavenumbers):
    """examples/stability/dispersion_strip.toml, run as shipped, is the growing case on one wavelength."""
    with EXAMPLE.open("rb") as stream:
        config = tomllib.load(stream)
    k = config["physics"]["chemotaxis"]["wavenumber"][0]
    assert k == pytest.approx(wavenumbers["growing"], rel=1e-9)
    assert config["mesh"]["upper"][0] == pytest.approx(2.0 * math.pi / k, rel=1e-12)
    assert config["kinetics"]["priming_wave"] is False
    assert predicted_rate(params, k) == pytest.approx(0.1546, abs=1e-4)
