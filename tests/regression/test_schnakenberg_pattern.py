"""The Schnakenberg plugin's simulation forms its pattern at the predicted wavelength, the same on both backends.

``examples/schnakenberg.toml`` (plugins/primordia-schnakenberg: activator u, inhibitor v,
d = D_v / D_u = 20 > d_c = 8.57) is run on a strip (0, L) x (0, h), one cell across,
L = 16 predicted wavelengths 2 pi / k_max, 12 cells per wavelength, from u_0 with 1%
seeded noise, to t = 100 (26 e-foldings of the fastest mode: the pattern has
saturated).  The zero-flux strip has the modes cos(n pi x / L), n pi / L = k_max n / 32,
so the dominant mode of the final activator profile measures the pattern's wavenumber
to 3%.  A stationary pattern keeps a wavenumber inside the unstable band but not
always the fastest one (the growth rate is flat at its top: 1% lower 6% away); the
test allows 10%.  Mistaking the analysis by a factor sqrt(D_v/D_u) or sqrt(gamma) would
miss by far more.

The two backends run the same scheme on the same mesh: every snapshot of both
species agrees to 1e-6 in relative L2 (the cross-validation of the plugin's model).
About 15 s.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest
import scipy.fft

from primordia.analysis import linearise_model
from primordia.model import Model

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "schnakenberg.toml"
PRIMORDIA = Path(sys.executable).parent / "primordia"
BACKENDS = ("fenicsx", "skfem")
WAVELENGTHS, CELLS_PER_WAVELENGTH = 16, 12
TIMES = (20.0, 50.0, 100.0)


@pytest.fixture(scope="module")
def mode():
    """The fastest stationary mode of the example's model, by the derived analysis."""
    return linearise_model(Model.from_file(EXAMPLE)).fastest_mode(kind="stationary")


@pytest.fixture(scope="module")
def strip_runs(mode, tmp_path_factory):
    """backend -> [(t, fields)] of the example on the strip, through the installed command."""
    length = WAVELENGTHS * mode.wavelength
    cells = WAVELENGTHS * CELLS_PER_WAVELENGTH
    overrides = [f"mesh.upper=[{length!r}, {length / cells!r}]", f"mesh.cells=[{cells}, 1]", "time.dt=0.1",
                 f"time.t_final={TIMES[-1]!r}", f"output.times=[{', '.join(map(repr, TIMES))}]",
                 "output.pictures=false"]
    runs = {}
    for backend in BACKENDS:
        out = tmp_path_factory.mktemp(f"schnakenberg_{backend}")
        command = [str(PRIMORDIA), "run", str(EXAMPLE), "--backend", backend, "--out", str(out), "--no-progress"]
        for assignment in overrides:
            command += ["--set", assignment]
        done = subprocess.run(command, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        with meshio.xdmf.TimeSeriesReader(out / "fields.xdmf") as reader:
            points, _ = reader.read_points_cells()
            runs[backend] = (points, [reader.read_data(i)[:2] for i in range(reader.num_steps)])
    return runs, length, cells


def dominant_wavenumber(points, values, length: float, cells: int) -> float:
    """n pi / L of the largest cosine mode of the profile along the bottom edge (DCT-I of the vertex values)."""
    bottom = np.flatnonzero(np.abs(points[:, 1]) < 1e-12)
    bottom = bottom[np.argsort(points[bottom, 0])]
    assert bottom.size == cells + 1
    profile = values.ravel()[bottom]
    power = scipy.fft.dct(profile - profile.mean(), type=1) ** 2
    n = 1 + int(np.argmax(power[1:]))  # n = 0 is the mean
    return n * np.pi / length


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_pattern_forms_at_the_predicted_wavelength(backend, mode, strip_runs):
    runs, length, cells = strip_runs
    points, frames = runs[backend]
    t, fields = frames[-1]
    activator = fields["activator"].ravel()
    k = dominant_wavenumber(points, activator, length, cells)
    print(f"\n{backend}: t = {t:g}, activator in [{activator.min():.3f}, {activator.max():.3f}], dominant k = "
          f"{k:.4f}, wavelength {2 * math.pi / k:.4f}; predicted k_max = {mode.k_max:.4f}, "
          f"wavelength {mode.wavelength:.4f}, band [{mode.band[0]:.3f}, {mode.band[1]:.3f}]")
    assert activator.max() - activator.min() > 1.0  # a pattern, not noise: u_0 = 1
    assert mode.band[0] < k < mode.band[1]
    assert abs(k - mode.k_max) <= 0.10 * mode.k_max


def test_both_backends_run_the_same_model(strip_runs):
    runs, _, _ = strip_runs
    frames = {backend: runs[backend][1] for backend in BACKENDS}
    assert [t for t, _ in frames["fenicsx"]] == [t for t, _ in frames["skfem"]] == list(TIMES)
    report = []
    for (t, reference), (_, other) in zip(frames["fenicsx"], frames["skfem"]):
        assert set(reference) == set(other) == {"activator", "inhibitor"}
        for name in sorted(reference):
            assert np.ptp(reference[name]) > 0.0
            difference = np.linalg.norm(other[name] - reference[name]) / np.linalg.norm(reference[name])
            report.append(f"t = {t:g} {name}: relative L2 difference {difference:.1e}")
            assert difference < 1e-6, "\n".join(report)
    print("\n" + "\n".join(report))
