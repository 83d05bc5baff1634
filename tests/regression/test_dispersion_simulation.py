"""The linear stability analysis against the finite elements: one cosine mode, measured, for every kinetics.

On a strip (0, L) x (0, h) with zero-flux boundaries, ``primordia run`` starts a
model at its homogeneous steady state (painter2018: the priming wave off,
``w = omega_1``, the state seed section 3 linearises about) with its perturbed
species (painter2018: m; schnakenberg: u) set to

    c(x, 0) = c_0 (1 + A cos(k x)),    k = 2 pi / L,    the other species at rest.

The cosine meets the zero-flux condition and is an exact eigenvector of the P1
lumped-mass Neumann Laplacian on the grid, so the linearised discrete dynamics
keep the mode a cosine; its amplitude a(t), the projection of c - c_0 on cos(k x)
(lumped quadrature over the vertices), is a sum of exponentials, one per root of
det M(phi, k).  Once the others have died out, log|a| is a straight line of slope
Re phi(k), which the test fits and compares with the analysis.

The prediction is the derived analysis of the very model that runs
(``linearise_model(Model.from_file(config, overrides))``: steady state and reaction
Jacobian from the kinetics' own code, transport from its species declarations), for

* ``painter2018`` (seed example 1a's parameters, ``examples/stability/dispersion_strip.toml``):
  growing k = k_max = 2.784 (Re phi = 0.1546), dt = 0.05, 45 cells on one wavelength:
  -0.8% from backward Euler; decaying k = 7.5 outside the band (Re phi = -0.2014),
  dt = 0.02, h = 0.02: +0.9% (time) +0.3% (space).  Both errors are the scheme's: the
  rate of the linearised discrete step (the 4 x 4 Gauss-Seidel step of chemotaxis.py
  with k^2 replaced by (2 sin(k h/2) / h)^2) is 0.1534058 and -0.1990126, the measured
  rates 0.1534059 and -0.1990067.  There the derived roots are also checked to be the
  roots of the seed's hand-derived P_2 = det M_22 (its uncoupled det M also has the
  poroelastic roots of P_3, which the chemotaxis-only model does not);
* ``painter2018_logistic`` (plugins/primordia-logistic) with r_m = 0.05 and m_cap = m0 =
  0.75, so that the rest state is a steady state: the proliferation term moves k_max to
  2.854 and the rate to 0.1253 (the painter2018 rate at that k is 0.15: the test tells
  them apart);
* ``schnakenberg`` (plugins/primordia-schnakenberg, ``examples/schnakenberg.toml``):
  k_max = 2.176, Re phi = 0.2632, no chemotaxis;
* ``painter2018`` on a poroelastic strip (seed example 1b's composition: poroelasticity, active
  stress, FGF sink) with slip walls (``normal_displacement`` all round, under which the cosine is
  the strip's exact mode) and couplings strong enough to matter, tau = 1, xi_f = 0.15: k_max =
  3.119, Re phi = 0.2295 (0.1546 at 2.784 without the mechanics), and k = 7.5 decaying at -0.1369
  (-0.2014 without).  Its leading roots at k = 7.5 are the poroelastic waves (Im phi ~ 1900), which
  backward Euler damps at any dt that resolves the chemistry: the prediction is the largest real root.

Every run goes through the installed ``primordia`` command on both backends.  With
the painter2018 chemotaxis the default flux is exponentially fitted; at Peclet numbers
this small it is the central scheme, so the plain Galerkin flux must give the same
rates.  The 5% tolerance is the issue's; 10% off in D_m (or alpha) moves the
predicted rates by 9-18%, and a flipped chemotaxis sign turns the growing mode into a
decaying one.  About 40 s in all.
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

from primordia.analysis import chemotaxis_coefficients, linearise_model
from primordia.analysis.inputs import read_parameters
from primordia.model import Model

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
STRIP = EXAMPLES / "stability" / "dispersion_strip.toml"
PRIMORDIA = Path(sys.executable).parent / "primordia"
BACKENDS = ("fenicsx", "skfem")
TOLERANCE = 0.05  # |measured - predicted| <= 5% |predicted| (issue 4)


@dataclass(frozen=True)
class ModeRun:
    """One cosine mode on one wavelength L = 2 pi / k, and how it is run and measured."""

    kinetics: str
    config: Path
    overrides: tuple  #: the model, beyond the strip, the cosine and the times
    wavenumber: float | None  #: None: k_max of the analysis
    perturbation: float  #: A in c(0) = c_0 (1 + A cos k x): small, so the dynamics stay linear
    cells_along: int  #: squares along x on (0, L); one across
    dt: float
    t_final: float
    output_every: float
    fit_from: float  #: start of the fit window: the other roots are e^-10 down by then

    def model(self) -> Model:
        return Model.from_file(self.config, list(self.overrides))


PAINTER2018 = ("kinetics.priming_wave=false",)
#: seed example 1b's composition on the strip, slip walls all round, couplings that move the rates
POROELASTIC = PAINTER2018 + (
    'model.physics=["chemotaxis", "poroelasticity", "active_stress", "mechanochemical"]',
    "physics.poroelasticity.boundary=[" + ", ".join(f'{{boundary = "{side}", type = "normal_displacement"}}'
                                                    for side in ("left", "right", "bottom", "top")) + "]",
    "parameters.tau=1.0", "parameters.xi_f=0.15")
MODES = {
    # gap to the next root: 0.155 + 1.417 = 1.57, so e^(-1.57 * 8) = 3e-6 at t = 8
    "painter2018-growing": ModeRun("painter2018", STRIP, PAINTER2018, None, perturbation=1e-4, cells_along=45,
                                   dt=0.05, t_final=24.0, output_every=1.0, fit_from=8.0),
    # gap 2.32 - 0.20 = 2.1 (and a slower start: the e-root is excited most), 1e-4 by t = 6
    "painter2018-decaying": ModeRun("painter2018", STRIP, PAINTER2018, 7.5, perturbation=1e-3, cells_along=42,
                                    dt=0.02, t_final=12.0, output_every=0.5, fit_from=6.0),
    # as painter2018, the cells now proliferating back to m_cap = m0
    "painter2018_logistic-growing": ModeRun(
        "painter2018_logistic", STRIP,
        PAINTER2018 + ('kinetics.name="painter2018_logistic"', "parameters.r_m=0.05", "parameters.m_cap=0.75"),
        None, perturbation=1e-4, cells_along=45, dt=0.05, t_final=24.0, output_every=1.0, fit_from=8.0),
    # the composed model: gap to the next root 0.23 + 1.58, e^-14 by t = 8; A = 3e-5 keeps a(16) at 5e-4
    "painter2018_poroelastic-growing": ModeRun("painter2018", STRIP, POROELASTIC, None, perturbation=3e-5,
                                               cells_along=45, dt=0.05, t_final=16.0, output_every=1.0, fit_from=8.0),
    "painter2018_poroelastic-decaying": ModeRun("painter2018", STRIP, POROELASTIC, 7.5, perturbation=1e-3,
                                                cells_along=42, dt=0.02, t_final=12.0, output_every=0.5, fit_from=6.0),
    # gap to the other root 0.26 + 5.4: it is gone by t = 2; A e^(0.26 * 16) = 6e-4 stays linear
    "schnakenberg-growing": ModeRun("schnakenberg", EXAMPLES / "schnakenberg.toml", (), None, perturbation=1e-5,
                                    cells_along=45, dt=0.02, t_final=16.0, output_every=0.5, fit_from=4.0),
}


# -- the analysis side --------------------------------------------------------------------


@pytest.fixture(scope="module")
def analyses():
    """mode name -> (the derived analysis of the model that runs, the mode's wavenumber)."""
    found = {}
    for name, mode in MODES.items():
        linear = linearise_model(mode.model())
        fastest = linear.fastest_mode(kind="stationary")
        if mode.wavenumber is None:
            k = fastest.k_max
        else:
            k = mode.wavenumber
            assert fastest.band[1] < k, fastest.band  # really outside the band
        found[name] = (linear, k)
    return found


def predicted_rate(linear, k: float) -> float:
    """The largest real root phi(k): the leading root at every mode here but the poroelastic waves."""
    roots = linear.rates(np.array([k]))[0]
    real = roots[np.abs(roots.imag) <= 1e-10 * np.abs(roots)]
    if linear.mechanics is None:
        leading = roots[np.nanargmax(roots.real)]
        assert abs(leading.imag) <= 1e-10 * abs(leading), f"leading root {leading} is not real"
    return float(np.nanmax(real.real))


def perturbed_species(linear) -> str:
    (species,) = [s.name for s in linear_kinetics(linear).species if s.perturbed]
    return species


def linear_kinetics(linear):
    from primordia.core.plugins import lookup

    return lookup("kinetics", linear.kinetics)


# -- the simulation side --------------------------------------------------------------------


def run_mode(mode: ModeRun, k: float, backend: str, out: Path, flux_scheme: str | None = None) -> Path:
    """``primordia run`` the mode's config with its strip, wavenumber and output times."""
    length = 2.0 * math.pi / k
    h = length / mode.cells_along
    steps_per_frame = round(mode.output_every / mode.dt)
    frames = round(mode.t_final / mode.output_every)
    times = [round(i * steps_per_frame * mode.dt, 12) for i in range(1, frames + 1)]
    overrides = list(mode.overrides) + [
        f"physics.chemotaxis.wavenumber=[{k!r}, 0.0]",
        f"physics.chemotaxis.perturbation={mode.perturbation!r}",
        'physics.chemotaxis.perturbation_shape="cosine"',
        "mesh.lower=[0.0, 0.0]",
        f"mesh.upper=[{length!r}, {h!r}]",
        f"mesh.cells=[{mode.cells_along}, 1]",
        f"time.dt={mode.dt!r}",
        f"time.t_final={mode.t_final!r}",
        f"output.times=[{', '.join(map(repr, times))}]",
        "output.pictures=false",
    ]
    if flux_scheme is not None:
        overrides.append(f'physics.chemotaxis.flux_scheme="{flux_scheme}"')
    command = [str(PRIMORDIA), "run", str(mode.config), "--backend", backend, "--out", str(out), "--no-progress"]
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


def cosine_amplitudes(fields_xdmf: Path, species: str, rest: float, k: float) -> tuple[np.ndarray, np.ndarray]:
    """(t, a(t)): the L2 projection, in lumped quadrature, of c - c_0 on cos(k x) at each output time."""
    with meshio.xdmf.TimeSeriesReader(fields_xdmf) as reader:
        points, cells = reader.read_points_cells()
        frames = [reader.read_data(i) for i in range(reader.num_steps)]
    weights = lumped_weights(points, cells[0].data)
    mode = np.cos(k * points[:, 0])
    times = np.array([t for t, _, _ in frames])
    amplitudes = np.array([np.sum(weights * (data[species].ravel() - rest) * mode) for _, data, _ in frames])
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
def measure(tmp_path_factory, analyses):
    """``measure(mode, backend, flux_scheme=None)`` -> :class:`Measurement`, each run once per module."""
    cache: dict = {}

    def run(mode_name: str, backend: str, flux_scheme: str | None = None) -> Measurement:
        key = (mode_name, backend, flux_scheme)
        if key not in cache:
            mode, (linear, k) = MODES[mode_name], analyses[mode_name]
            species = perturbed_species(linear)
            out = tmp_path_factory.mktemp(f"{mode_name}_{backend}_{flux_scheme or 'default'}")
            times, amplitudes = cosine_amplitudes(run_mode(mode, k, backend, out, flux_scheme), species,
                                                  linear.steady_state.values[species], k)
            cache[key] = Measurement.fit(times, amplitudes, mode.fit_from)
        return cache[key]

    return run


# -- the checks ---------------------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("mode_name", list(MODES))
def test_cosine_mode_grows_at_the_rate_of_the_dispersion_relation(mode_name, backend, analyses, measure):
    linear, k = analyses[mode_name]
    predicted = predicted_rate(linear, k)
    measured = measure(mode_name, backend)
    error = (measured.rate - predicted) / abs(predicted)
    print(f"\n{mode_name:>28} k = {k:.4f} on {backend:<7}: measured Re phi = {measured.rate:+.5f}, "
          f"predicted {predicted:+.5f} (relative error {error:+.2%}; log-fit misfit {measured.misfit:.1e})")
    assert (predicted > 0) == mode_name.endswith("growing")
    assert abs(measured.rate - predicted) <= TOLERANCE * abs(predicted), (
        f"{mode_name} on {backend}: measured {measured.rate:.5f}, predicted {predicted:.5f} ({error:+.2%})")
    # what makes the slope a growth rate: one real root dominates (a keeps its sign, log|a| is
    # a straight line over the window) and the amplitude stays in the linear regime
    window = measured.times >= MODES[mode_name].fit_from - 1e-9
    assert np.all(measured.amplitudes[window] > 0), f"a(t) changes sign: {measured.amplitudes[window]}"
    assert measured.misfit < 1e-3, f"log|a| is not a straight line over the window (misfit {measured.misfit:.1e})"
    species = perturbed_species(linear)
    assert np.max(np.abs(measured.amplitudes)) < 3e-3 * linear.steady_state.values[species]


@pytest.mark.parametrize("mode_name", list(MODES))
def test_backends_measure_the_same_rate(mode_name, measure):
    """Same mesh, same scheme: the two backends' amplitudes agree to solver tolerance."""
    fenicsx, skfem = (measure(mode_name, backend) for backend in BACKENDS)
    np.testing.assert_allclose(skfem.amplitudes, fenicsx.amplitudes, rtol=1e-6)
    assert skfem.rate == pytest.approx(fenicsx.rate, rel=1e-6)


@pytest.mark.parametrize("mode_name", ["painter2018-growing", "painter2018-decaying"])
def test_exponential_fitting_is_the_central_scheme_at_small_peclet(mode_name, measure):
    """Linearised, the fitted flux B(-Pe) m_i - B(Pe) m_j is the Galerkin one: same rate to O(A)."""
    fitted = measure(mode_name, "fenicsx")
    galerkin = measure(mode_name, "fenicsx", flux_scheme="galerkin")
    print(f"\n{mode_name:>20}: exponential fitting {fitted.rate:+.7f}, galerkin {galerkin.rate:+.7f}")
    assert galerkin.rate == pytest.approx(fitted.rate, rel=1e-5)


@pytest.mark.parametrize("mode_name", ["painter2018-growing", "painter2018-decaying"])
def test_painter2018_rates_are_the_roots_of_the_seeds_P_2(mode_name, analyses):
    """The derived roots are those of the hand-derived chemotaxis block P_2 = det M_22 (seed Definition 3.2)."""
    linear, k = analyses[mode_name]
    params = read_parameters(STRIP)
    expected = np.sort_complex(np.roots(np.array(chemotaxis_coefficients(params, k), dtype=float)[::-1]))
    derived = np.sort_complex(linear.rates(np.array([k]))[0])
    np.testing.assert_allclose(derived, expected, rtol=1e-9, atol=1e-12)


def test_the_modes_tell_the_kinetics_apart(analyses):
    """The logistic term moves the growing mode: predicting it with painter2018 would miss by more than 5%."""
    painter, _ = analyses["painter2018-growing"]
    logistic, k = analyses["painter2018_logistic-growing"]
    assert logistic.steady_state.values["m"] == pytest.approx(0.75, rel=1e-12)  # m_cap = m0: at rest
    assert abs(predicted_rate(painter, k) - predicted_rate(logistic, k)) > 2 * TOLERANCE * predicted_rate(logistic, k)


@pytest.mark.parametrize("state", ["growing", "decaying"])
def test_the_modes_tell_the_mechanics_apart(state, analyses):
    """The poroelastic modes' rates are not the chemistry's: leaving out a coupling would miss by more than 5%."""
    linear, k = analyses[f"painter2018_poroelastic-{state}"]
    assert linear.coupled and linear.mechanics is not None
    chemistry = linearise_model(MODES[f"painter2018_poroelastic-{state}"].model(), chemistry_only=True)
    predicted = predicted_rate(linear, k)
    assert abs(predicted_rate(chemistry, k) - predicted) > 2 * TOLERANCE * abs(predicted)


def test_the_example_is_the_growing_mode(analyses):
    """examples/stability/dispersion_strip.toml, run as shipped, is the growing case on one wavelength."""
    with STRIP.open("rb") as stream:
        config = tomllib.load(stream)
    linear, k_max = analyses["painter2018-growing"]
    k = config["physics"]["chemotaxis"]["wavenumber"][0]
    assert k == pytest.approx(k_max, rel=1e-7)  # the Brent search places a flat maximum to ~1e-8
    assert config["mesh"]["upper"][0] == pytest.approx(2.0 * math.pi / k, rel=1e-12)
    assert config["kinetics"]["priming_wave"] is False
    assert predicted_rate(linear, k) == pytest.approx(0.1546, abs=1e-4)
