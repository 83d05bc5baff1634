"""Pattern metrics on synthetic fields with known answers (primordia.analysis.patterns).

Each field is given at the vertices of a triangle mesh of (0, 20)^2, as a run writes it:
* a hexagonal lattice of Gaussian spots at spacing a: count, centres, areas, spacing a,
  |psi_6| = 1, dominant wavelength sqrt(3) a / 2 (the distance between rows), kind "spots";
* plane stripes of wavelength lambda: wavelength lambda, no spots, kind "stripes";
* a random superposition of waves of one wavelength, saturated: a labyrinth;
* white noise (large and small amplitude) and a constant: kind "none", no spots;
* point sets with known |psi_6|: a square lattice (0), random points (well below 1);
* a run directory written like a run's, with a displacement u = (s - 1) X: the spacing is
  a on the reference configuration and s a on the current one.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import xarray as xr

from primordia.analysis.patterns.metrics import (
    hexatic_order,
    mesh_pattern_metrics,
    nearest_neighbour_distances,
)
from primordia.analysis.patterns.run import analyse_run, pattern_kind, predicted_mode
from primordia.core.json_toml import write_json, write_toml
from primordia.core.meshes import rectangle
from primordia.core.xdmf import XdmfSeries

SIDE = 20.0
MESH = rectangle((0.0, 0.0), (SIDE, SIDE), cells=(100, 100))


def hexagonal_lattice(spacing: float, margin: float) -> np.ndarray:
    """Lattice points (rows along x, rows sqrt(3)/2 spacing apart) inside [margin, SIDE - margin]^2."""
    rows = np.arange(0.0, SIDE, spacing * np.sqrt(3) / 2)
    points = [(x, y) for j, y in enumerate(rows) for x in np.arange(0.0, SIDE, spacing) + (j % 2) * spacing / 2]
    points = np.array(points)
    inside = np.all((points >= margin) & (points <= SIDE - margin), axis=1)
    return points[inside]


def gaussian_spots(points: np.ndarray, centres: np.ndarray, width: float) -> np.ndarray:
    squared = ((points[:, None, :] - centres[None, :, :]) ** 2).sum(axis=-1)
    return np.exp(-squared / (2 * width**2)).sum(axis=1)


def measure(values):
    return mesh_pattern_metrics(MESH.points, MESH.cells, values)[0]


@pytest.mark.parametrize("spacing", [2.5, 3.5])
def test_hexagonal_lattice_of_spots(spacing):
    width = spacing / 6
    centres = hexagonal_lattice(spacing, margin=3 * width)
    metrics = measure(gaussian_spots(MESH.points, centres, width))
    assert metrics.kind == "spots"
    assert metrics.spot_count == len(centres)
    # every detected centre sits on a lattice point
    offsets = np.min(np.linalg.norm(metrics.spot_centres[:, None] - centres[None], axis=-1), axis=1)
    assert offsets.max() < 0.02 * spacing
    assert metrics.spacing_mean == pytest.approx(spacing, rel=0.01)
    assert metrics.spacing_std < 0.01 * spacing
    assert metrics.hexatic_order > 0.99
    assert metrics.dominant_wavelength == pytest.approx(np.sqrt(3) / 2 * spacing, rel=0.03)
    # area above half the maximum: a disc of radius width sqrt(2 ln 2)
    assert np.median(metrics.spot_areas) == pytest.approx(2 * np.pi * np.log(2) * width**2, rel=0.1)


def test_stripes_of_known_wavelength():
    wavelength, angle = 3.0, np.deg2rad(30)
    direction = np.array([np.cos(angle), np.sin(angle)])
    metrics = measure(np.cos(2 * np.pi / wavelength * MESH.points @ direction))
    assert metrics.kind == "stripes"
    assert metrics.dominant_wavelength == pytest.approx(wavelength, rel=0.02)
    assert metrics.spot_count == 0
    assert metrics.orientation_order > 0.9


def test_the_dominant_wavelength_of_stripes_is_within_what_the_readme_states():
    """README ("Pattern metrics"): on the 20 x 20 box, plane stripes of wavelength 2 to 4 at 0 to 90 degrees
    give it within 2.6%, median 1.0% (the spectrum resolves k to about 2 pi / 20)."""
    errors = []
    for wavelength in np.linspace(2.0, 4.0, 9):
        for angle in np.deg2rad([0, 30, 60, 90]):
            direction = np.array([np.cos(angle), np.sin(angle)])
            metrics = measure(np.cos(2 * np.pi / wavelength * MESH.points @ direction))
            errors.append(abs(metrics.dominant_wavelength / wavelength - 1))
    assert np.median(errors) < 0.011 and max(errors) < 0.027


def test_stripes_at_any_angle_have_no_spots_where_the_edge_cuts_them_off():
    """Oblique stripes counted 1-2 "spots" at the corners, where the box's walls cut a stripe's end off: 124 of
    14 of these 60 fields (the compact ends count in a pattern of spots, where they are spots halved by a wall)."""
    counted = []
    for wavelength in (2.0, 3.0, 4.0):
        for angle in np.deg2rad(np.arange(0, 91, 10)):
            for phase in (0.0, 1.0):
                direction = np.array([np.cos(angle), np.sin(angle)])
                metrics = measure(np.cos(2 * np.pi / wavelength * MESH.points @ direction + phase))
                assert metrics.kind == "stripes", (wavelength, angle, phase)
                counted.append(metrics.spot_count)
    assert max(counted) == 0


def test_spots_halved_by_the_walls_are_counted():
    spacing = 3.0
    centres = hexagonal_lattice(spacing, margin=0.0)  # rows on the walls y = 0 and x = 0
    metrics = measure(gaussian_spots(MESH.points, centres, spacing / 6))
    assert metrics.kind == "spots"
    assert metrics.spot_count == len(centres)


def test_labyrinth_from_random_waves_of_one_wavelength():
    wavelength = 3.0
    rng = np.random.default_rng(3)
    field = np.zeros(MESH.num_vertices)
    for angle, phase in zip(rng.uniform(0, np.pi, 40), rng.uniform(0, 2 * np.pi, 40)):
        field += np.cos(2 * np.pi / wavelength * MESH.points @ [np.cos(angle), np.sin(angle)] + phase)
    metrics = measure(np.tanh(3 * field))
    assert metrics.kind == "labyrinth"
    assert metrics.dominant_wavelength == pytest.approx(wavelength, rel=0.05)
    assert metrics.spot_fraction < 0.5
    assert metrics.orientation_order < 0.5


@pytest.mark.parametrize("seed", range(3))
def test_noise_is_no_pattern(seed):
    rng = np.random.default_rng(seed)
    for field in (rng.normal(size=MESH.num_vertices),  # white noise
                  0.75 * (1 + 0.01 * rng.uniform(-1, 1, MESH.num_vertices))):  # a run's initial m
        metrics = measure(field)
        assert metrics.kind == "none"
        assert metrics.prominence < 5
        assert metrics.spot_count == 0
        assert np.isnan(metrics.spacing_mean) and np.isnan(metrics.hexatic_order)


def test_uniform_field_is_no_pattern():
    metrics = measure(np.full(MESH.num_vertices, 0.75))
    assert metrics.kind == "none"
    assert np.isnan(metrics.dominant_wavelength)


def test_a_lone_front_is_no_pattern():
    """A smooth front (the priming wave) has no spectral peak of its own: not stripes."""
    metrics = measure(np.tanh(MESH.points[:, 1] - 8.0))
    assert metrics.kind == "none"


@pytest.mark.parametrize("shape", ["front", "gradient", "lone spot"])
def test_a_spectrum_that_only_falls_has_no_dominant_wavelength(shape):
    """Fields whose spectrum falls across the whole band had the band's long-wave end for their "peak": a dominant
    wavelength of about half the box (9.3-11.1 here; 10.0, L / 2, in example 1a's flat species at 40 x 40), which a
    sweep's wavelength over its points showed as a number where there was no pattern."""
    x, y = MESH.points.T
    field = {"front": np.tanh(y - 8.0), "gradient": x,
             "lone spot": np.exp(-((x - 10.0) ** 2 + (y - 10.0) ** 2) / 0.5)}[shape]
    metrics = measure(field)
    assert metrics.kind == "none"
    assert np.isnan(metrics.dominant_wavenumber) and np.isnan(metrics.dominant_wavelength)
    assert metrics.prominence == 1.0  # nothing stands above its surroundings: measured, not missing


@pytest.mark.parametrize("shape", ["gradient", "hump"])
@pytest.mark.parametrize("upper", [(40.0, 10.0), (10.0, 40.0)])
def test_a_trend_along_a_long_narrow_box_is_no_pattern(shape, upper):
    """On a 40 x 10 box a gradient along the long side was "stripes" of wavelength 4.16 with prominence 39, and one
    hump of it (cos^2) 86: the short side's window leaked the trend into a side lobe at 2.5 periods of the short
    side, which the band searches (from 4 pi / 10) and where nothing else has power."""
    mesh = rectangle((0.0, 0.0), upper, cells=(160, 40) if upper[0] > upper[1] else (40, 160))
    along = mesh.points[:, 0 if upper[0] > upper[1] else 1]
    field = {"gradient": along / max(upper), "hump": np.cos(np.pi * along / max(upper)) ** 2}[shape]
    metrics = mesh_pattern_metrics(mesh.points, mesh.cells, field)[0]
    assert metrics.kind == "none"
    assert 1 <= metrics.prominence < 2  # nothing stands above what the trend leaks: 1, as for a front
    # a pattern on the same trend still stands out
    stripes = np.cos(2 * np.pi / 3.0 * along) + field
    metrics = mesh_pattern_metrics(mesh.points, mesh.cells, stripes)[0]
    assert metrics.kind == "stripes"
    assert metrics.dominant_wavelength == pytest.approx(3.0, rel=0.05)


def test_hexatic_order_of_known_point_sets():
    hexagonal = hexagonal_lattice(2.0, margin=0.0)
    assert hexatic_order(hexagonal)[0] == pytest.approx(1.0, abs=1e-9)
    # square: the four bonds at 0, 90, 180, 270 degrees cancel in exp(6 i theta); only Delaunay's diagonals remain
    square = np.array([(x, y) for x in range(10) for y in range(10)], dtype=float)
    assert hexatic_order(square)[0] < 0.1
    scattered = np.random.default_rng(0).uniform(0, SIDE, (300, 2))
    assert 0.2 < hexatic_order(scattered)[0] < 0.5
    assert np.isnan(hexatic_order(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]))[0])


@pytest.mark.parametrize("spacing, cut, before, now", [
    (2.5, "notch", 0.950, 0.999),  # an L-shape: (0, 20)^2 without its upper right quarter
    (3.5, "hole", 0.683, 0.89),  # a hole of radius 4 in the middle
])
def test_the_hexatic_order_leaves_out_bonds_across_a_hole_or_a_notch(spacing, cut, before, now):
    """Delaunay bonds span the domain's holes and notches, which the spots' convex hull does not see: a perfect
    lattice on an L-shape had |psi_6| 0.950, around a hole 0.683.  The spots next to the hole still have bonds
    that skip the lattice points the hole removed, in the domain: 0.90, not 1."""
    width = spacing / 6
    centres = hexagonal_lattice(spacing, margin=3 * width)
    x, y = MESH.points[MESH.cells].mean(axis=1).T
    removed = {"notch": lambda x, y: (x > SIDE / 2) & (y > SIDE / 2),
               "hole": lambda x, y: np.hypot(x - SIDE / 2, y - SIDE / 2) < 4.0}[cut]
    kept = centres[~removed(*centres.T)]
    metrics = mesh_pattern_metrics(MESH.points, MESH.cells[~removed(x, y)], gaussian_spots(MESH.points, kept, width))[0]
    assert metrics.kind == "spots" and metrics.spot_count == len(kept)
    assert metrics.hexatic_order > now > before


def test_nearest_neighbour_distances():
    points = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 3.0]])
    assert nearest_neighbour_distances(points) == pytest.approx([1.0, 1.0, 3.0])
    assert nearest_neighbour_distances(points[:1]).size == 0


def write_run(directory, stretch: float, spacing: float = 3.0, times=(10.0, 20.0)):
    """A run directory as ``primordia run`` writes it: spots in m, noise in b, displacement u = (s - 1) X."""
    width = spacing / 6
    spots = gaussian_spots(MESH.points, hexagonal_lattice(spacing, 3 * width), width)
    noise = 0.5 + 0.01 * np.random.default_rng(0).uniform(-1, 1, MESH.num_vertices)
    series = XdmfSeries(directory, MESH)
    for t, amplitude in zip(times, (0.5, 1.0, 1.0)):
        series.write(t, {"m": amplitude * spots, "b": noise, "u": (stretch - 1.0) * MESH.points})
    write_toml(directory / "config.toml", {"model": {"physics": ["chemotaxis"]},
                                              "parameters": {"m0": 0.75, "D_m": 0.03}})
    write_json(directory / "summary.json", {"status": "completed"})


def test_run_directory_in_reference_and_current_configuration(tmp_path):
    stretch, spacing = 1.2, 3.0
    write_run(tmp_path, stretch, spacing)
    ds = analyse_run(tmp_path)
    assert set(ds["configuration"].values) == {"reference", "current"}
    assert list(ds["time"].values) == [10.0, 20.0]
    m = ds.sel(species="m", time=20.0)
    assert float(m["spacing_mean"].sel(configuration="reference")) == pytest.approx(spacing, rel=0.01)
    assert float(m["spacing_mean"].sel(configuration="current")) == pytest.approx(stretch * spacing, rel=0.01)
    assert pattern_kind(ds, species="b").ravel().tolist() == ["none"] * 4
    assert pattern_kind(ds, species="m", time=20.0, configuration="current").item() == "spots"
    # the linear analysis of the same config (uncoupled: no mechano-chemical couplings)
    assert float(ds["predicted_wavenumber"]) == pytest.approx(2.784, abs=1e-3)
    # written, and readable with every spot
    saved = xr.open_dataset(tmp_path / "metrics.nc")
    # units a tool can read (UDUNITS), and the series' own for the time: "2 pi / length" and "dimensionless
    # (seed scaling)" were neither
    assert saved["wavenumber"].attrs["units"] == "1" and saved["time"].attrs["units"] == "1"  # "dimensionless" was not
    # the lengths and areas had none, and until 2026-12-05 neither had the spectrum and the linear analysis's mode
    assert all(saved[name].attrs["units"] == "1" for name in ("dominant_wavelength", "spacing_mean", "spot_x",
                                                             "spot_area", "spot_count", "power_spectrum",
                                                             "predicted_wavenumber", "predicted_wavelength",
                                                             "predicted_growth_rate"))
    count = int(saved["spot_count"].sel(species="m", time=20.0, configuration="reference"))
    assert count > 20
    assert np.isfinite(saved["spot_x"].sel(species="m", time=20.0, configuration="reference").values).sum() == count
    saved.close()
    for picture in ("metrics_m.png", "metrics_m_current.png", "metrics_b.png"):
        assert (tmp_path / picture).stat().st_size > 10_000


def test_predicted_mode_of_example_1a():
    mode = predicted_mode("examples/ex01a.toml")  # primordia stability examples/ex01a.toml
    assert mode.k_max == pytest.approx(2.784, abs=1e-3)
    assert mode.wavelength == pytest.approx(2.257, abs=1e-3)
    assert mode.rate > 0
    assert "no mechanics" in mode.note
    assert "with mechanics" in predicted_mode("examples/ex01b.toml").note
    growing = predicted_mode("examples/ex02a.toml")  # no linear analysis at finite strain: the chemistry alone
    assert growing.k_max == pytest.approx(2.784, abs=1e-3) and "chemistry alone" in growing.note
    stable = predicted_mode({"model": {"physics": ["chemotaxis"]}, "parameters": {"m0": 0.25, "alpha": 1.0}})
    assert np.isnan(stable.k_max) and np.isnan(stable.wavelength) and stable.rate <= 0 and "stable" in stable.note


def test_predicted_mode_when_the_homogeneous_state_grows_fastest(monkeypatch):
    """Kinetics whose real root at k = 0 grows fastest: the fastest stationary mode is at k = 0 (no longer the
    grid's first k, 0.001), which has no wavelength; 2 pi / k_max must not divide by zero."""
    from primordia.analysis.composed import LinearisedModel
    from primordia.analysis.dispersion import FastestMode

    homogeneous = FastestMode(k_max=0.0, growth_rate=0.3, frequency=0.0, band=(0.0, 1.0), at_edge=False,
                              kind="stationary")
    monkeypatch.setattr(LinearisedModel, "fastest_mode", lambda self, kind="any", k=None: homogeneous)
    mode = predicted_mode("examples/ex01a.toml")
    assert mode.k_max == 0.0 and mode.wavelength == np.inf and mode.rate == 0.3
    assert "homogeneous state itself is unstable" in mode.note


def test_analyse_command(tmp_path, primordia_cli):
    write_run(tmp_path, stretch=1.0)
    result = primordia_cli("analyse", tmp_path, "--species", "m", "--no-pictures")
    assert result.returncode == 0, result.stderr
    assert "t = 20 m (reference): spots" in result.stdout
    assert "k_max = 2.784" in result.stdout
    assert (tmp_path / "metrics.nc").is_file() and not (tmp_path / "metrics_m.png").exists()


@pytest.mark.parametrize("arguments, message", [
    (["analyse", "no/such/run"], "no/such/run does not exist"),  # said "no fields.xdmf (not a run directory..."
    (["analyse", "RUN/config.toml"], "config.toml is a file, not a run directory"),
    (["analyse", "RUN/nothing"], "no fields.xdmf"),
    (["analyse", "RUN", "--species", "q"], "no scalar field 'q'"),
])
def test_analyse_bad_input_is_one_line(tmp_path, primordia_cli, arguments, message):
    write_run(tmp_path, stretch=1.0)
    (tmp_path / "nothing").mkdir()
    result = primordia_cli(*[a.replace("RUN", str(tmp_path)) for a in arguments])
    assert result.returncode == 2
    assert result.stderr.startswith("primordia: error: ") and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def _truncate_xdmf(directory):
    xdmf = directory / "fields.xdmf"
    xdmf.write_text(xdmf.read_text()[:300])


def _remove_h5(directory):
    import shutil

    for h5 in [*directory.glob("*.h5"), *directory.glob("*_h5")]:
        shutil.rmtree(h5) if h5.is_dir() else h5.unlink()


@pytest.mark.parametrize("damage, message", [
    (_truncate_xdmf, "fields.xdmf (or the HDF5 files it names) cannot be read"),
    (_remove_h5, "fields.xdmf (or the HDF5 files it names) cannot be read"),
    (lambda directory: (directory / "config.toml").write_text("garbage[\n"), "config.toml cannot be read"),
], ids=["truncated-xdmf", "no-h5", "broken-config"])
def test_a_damaged_run_directory_is_one_line(tmp_path, primordia_cli, damage, message):
    """A run directory with a truncated fields.xdmf, its HDF5 data gone or a broken config.toml gave a traceback."""
    write_run(tmp_path, stretch=1.0)
    damage(tmp_path)
    result = primordia_cli("analyse", tmp_path, "--no-pictures")
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("primordia: error: ") and message in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_broken_summary_only_loses_the_run_status(tmp_path):
    write_run(tmp_path, stretch=1.0)
    (tmp_path / "summary.json").write_text("[1, 2")
    assert analyse_run(tmp_path, species=["m"], pictures=False).attrs["run_status"] == "unknown"


def test_a_run_whose_process_is_gone_is_called_killed_not_running(tmp_path):
    """A run killed without a word (a sweep's --timeout kills it) left summary.json saying "running", and analyse
    said "(run running)" of it; a run whose process is alive is still running."""
    import os
    import socket

    from primordia.core.outputs import process_start

    write_run(tmp_path, stretch=1.0)
    gone = {"host": socket.gethostname(), "pid": 2**22 + 1, "started": 1}
    write_json(tmp_path / "summary.json", {"status": "running", "process": gone})
    assert analyse_run(tmp_path, species=["m"], pictures=False).attrs["run_status"] == "killed"
    parent = os.getppid()  # alive, and not this process (which wrote no run)
    alive = {"host": socket.gethostname(), "pid": parent, "started": process_start(parent)}
    write_json(tmp_path / "summary.json", {"status": "running", "process": alive})
    assert analyse_run(tmp_path, species=["m"], pictures=False).attrs["run_status"] == "running"
    # a run on another machine (a sweep's worker, a shared file system) cannot be told from here
    write_json(tmp_path / "summary.json", {"status": "running", "process": gone | {"host": "another-host"}})
    assert analyse_run(tmp_path, species=["m"], pictures=False).attrs["run_status"] == "running"


def test_a_run_without_its_config_predicts_nothing(tmp_path):
    """Without config.toml the prediction came from Table 3.1's defaults: another model's wavelength."""
    write_run(tmp_path, stretch=1.0)
    (tmp_path / "config.toml").unlink()
    ds = analyse_run(tmp_path, species=["m"], pictures=False)
    assert np.isnan(float(ds["predicted_wavelength"])) and np.isnan(float(ds["predicted_wavenumber"]))
    assert "no config.toml" in ds.attrs["linear_analysis"]


def test_a_slab_is_measured_on_its_top_face(tmp_path):
    """A tetrahedral slab (example 4's shape) was refused; its top face z = 1, where the pictures show the
    pattern, is measured: spots at spacing a on the reference face, s a on the face moved by u = (s - 1) (x, y, 0)."""
    from primordia.core.meshes import box

    slab = box((0.0, 0.0, 0.0), (SIDE, SIDE, 1.0), cells=(80, 80, 1))
    stretch, spacing = 1.2, 3.0
    width = spacing / 6
    spots = gaussian_spots(slab.points[:, :2], hexagonal_lattice(spacing, 3 * width), width)
    displacement = np.column_stack([(stretch - 1.0) * slab.points[:, :2], 0.1 * slab.points[:, 2]])
    series = XdmfSeries(tmp_path, slab)
    series.write(20.0, {"m": spots * (1.0 + 0.2 * slab.points[:, 2]), "u": displacement})
    write_toml(tmp_path / "config.toml", {"model": {"physics": ["chemotaxis"]}, "parameters": {"m0": 0.75, "D_m": 0.03}})
    ds = analyse_run(tmp_path, pictures=False)
    assert ds.attrs["surface"] == "the top face z = 1"
    m = ds.sel(species="m", time=20.0)
    assert float(m["spacing_mean"].sel(configuration="reference")) == pytest.approx(spacing, rel=0.01)
    assert float(m["spacing_mean"].sel(configuration="current")) == pytest.approx(stretch * spacing, rel=0.01)
    assert pattern_kind(ds, species="m", time=20.0, configuration="reference").item() == "spots"


def test_a_slab_whose_top_slopes_is_measured_on_its_upper_surface(tmp_path):
    """A slab read from a file with a sloped top has no face at z = z_max: analyse refused it ("no face at its
    largest z"), and its run's pictures failed.  Its upper surface is measured, seen from above."""
    from primordia.core.meshes import box

    slab = box((0.0, 0.0, 0.0), (SIDE, SIDE, 1.0), cells=(80, 80, 1))
    slab.points[:, 2] *= 1.0 + 0.005 * slab.points[:, 0]  # z = 1 at x = 0, 1.1 at x = 20
    spacing = 3.0
    spots = gaussian_spots(slab.points[:, :2], hexagonal_lattice(spacing, spacing / 2), spacing / 6)
    XdmfSeries(tmp_path, slab).write(20.0, {"m": spots})
    ds = analyse_run(tmp_path, pictures=False)
    assert ds.attrs["surface"] == "the top face z = 1 to 1.1"
    assert float(ds["spacing_mean"].sel(species="m", time=20.0, configuration="reference")) == pytest.approx(
        spacing, rel=0.01)


def test_a_restart_says_the_analysis_in_the_run_directory_is_of_the_run_before_it(tmp_path, small_config,
                                                                                      primordia_cli):
    """metrics.nc and its pictures stayed beside a run a restart extended, describing fewer times than its
    fields, without a word (mesh/outputs QA pass)."""
    out = tmp_path / "run"
    assert primordia_cli("run", small_config(), "--out", out, "--no-progress").returncode == 0
    assert primordia_cli("analyse", out, "--no-pictures").returncode == 0
    extended = primordia_cli("run", "--restart", out, "--set", "time.t_final=1.4", "--no-progress")
    assert extended.returncode == 0, extended.stderr
    assert extended.stderr.splitlines() == [
        f"primordia: warning: {out / 'metrics.nc'} (primordia analyse) measures the run as it was before this "
        f"restart; run primordia analyse {out} again when it ends"]


def test_the_metrics_picture_shows_its_whole_title_and_names_its_axes(tmp_path, monkeypatch):
    """A coupled model's note (example 1b's, 136 characters) ran off both sides of a picture of two output
    times, and the field's axes had no names."""
    from primordia.analysis.patterns import figures
    from primordia.analysis.patterns.run import PredictedMode, measure, read_run

    drawn = []
    save = figures._save
    monkeypatch.setattr(figures, "_save", lambda figure, path: (drawn.append(figure), save(figure, path))[1])
    write_run(tmp_path, stretch=1.0)
    note = ("physics chemotaxis, poroelasticity, active_stress, mechanochemical; kinetics painter2018 "
            "(species m, e, f, b); with mechanics")
    for times in (1, 2):
        chosen = [m for m in measure(read_run(tmp_path), ["m"]) if m.configuration == "reference"][:times]
        figures.metrics_figure(chosen, PredictedMode(2.78, 2.26, 0.1, note), tmp_path / "metrics_m.png")
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    assert len(drawn) == 2
    for figure in drawn:
        renderer = FigureCanvasAgg(figure).get_renderer()
        title = figure._suptitle.get_window_extent(renderer)
        assert title.x0 >= 0 and title.x1 <= figure.bbox.x1 and title.y1 <= figure.bbox.y1
        field = figure.axes[0]  # the first time's field, with its own title above it
        assert title.y0 > field.get_tightbbox(renderer).y1
        assert (field.get_xlabel(), field.get_ylabel()) == ("x", "y")


def test_a_sweep_map_panel_without_any_value_has_no_colour_bar(tmp_path, monkeypatch):
    """A sweep where no run formed spots (a coarse or short one) drew the spacing and wavelength panels
    empty, each with a colour bar from -0.1 to 0.1: a scale for values that are not there."""
    from primordia.analysis.patterns import figures

    drawn = []
    save = figures._save
    monkeypatch.setattr(figures, "_save", lambda figure, path: (drawn.append(figure), save(figure, path))[1])
    grid = {"m0": [0.5, 1.0], "alpha": [2.0, 4.0]}
    nothing = xr.DataArray(np.full((2, 2), np.nan), coords=grid, dims=("m0", "alpha"))
    ds = xr.Dataset({"spacing_mean": nothing, "spot_count": nothing.fillna(0.0), "dominant_wavelength": nothing,
                     "pattern_name": nothing.astype(object).fillna("none"), "failed": nothing.fillna(0).astype(bool)})
    figures.sweep_figure(ds, None, tmp_path / "sweep_map.png", "m0", "alpha")
    (figure,) = drawn
    panels = [ax for ax in figure.axes if ax.get_label() != "<colorbar>"]
    assert len(figure.axes) - len(panels) == 1, "a colour bar for the spot count only"
    assert [ax.get_title() for ax in panels] == ["spot spacing (nearest neighbour): no run has one", "spot count",
                                                 "dominant wavelength (spectrum): no run has one"]


def test_the_metrics_picture_draws_the_field_to_its_own_extent_with_spots_on_the_walls(tmp_path, monkeypatch):
    """The circles of spots the walls halve reached past the domain and widened the field's panel: example 1a at
    60 x 60 squares, t = 400, drew its field with white margins beside it, the t = 200 panel edge to edge."""
    from primordia.analysis.patterns import figures
    from primordia.analysis.patterns.run import Measurement, PredictedMode

    drawn = []
    save = figures._save
    monkeypatch.setattr(figures, "_save", lambda figure, path: (drawn.append(figure), save(figure, path))[1])
    spacing = 3.0
    centres = hexagonal_lattice(spacing, margin=0.0)  # rows on the walls y = 0 and x = 0
    metrics, grid = mesh_pattern_metrics(MESH.points, MESH.cells, gaussian_spots(MESH.points, centres, spacing / 6))
    assert metrics.spot_count == len(centres)
    figures.metrics_figure([Measurement(20.0, "reference", "m", metrics, grid)],
                           PredictedMode(2.78, 2.26, 0.1, "linear analysis"), tmp_path / "metrics_m.png")
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    (figure,) = drawn
    figure.draw(FigureCanvasAgg(figure).get_renderer())
    field = figure.axes[0]
    assert field.get_xlim() == pytest.approx(grid.extent[:2]) and field.get_ylim() == pytest.approx(grid.extent[2:])


def test_the_spot_count_of_a_sweep_map_is_drawn_from_zero(tmp_path, monkeypatch):
    """A sweep where no run formed spots drew its spot counts, all 0, on a colour bar from -0.1 to 0.1 (example 1a
    at 30 x 30 over alpha and m0 to t = 200): a scale of negative counts."""
    from primordia.analysis.patterns import figures

    drawn = []
    save = figures._save
    monkeypatch.setattr(figures, "_save", lambda figure, path: (drawn.append(figure), save(figure, path))[1])
    grid = {"m0": [0.5, 1.0], "alpha": [2.0, 4.0]}
    for counts in ([[0.0, 0.0], [0.0, 0.0]], [[0.0, 3.0], [12.0, np.nan]]):
        count = xr.DataArray(counts, coords=grid, dims=("m0", "alpha"))
        ds = xr.Dataset({"spacing_mean": count * np.nan, "spot_count": count, "dominant_wavelength": count * np.nan,
                         "pattern_name": count.astype(object).fillna("none"), "failed": count.isnull()})
        figures.sweep_figure(ds, None, tmp_path / "sweep_map.png", "m0", "alpha")
    for figure, top in zip(drawn, (1.0, 12.0)):
        (bar,) = [ax for ax in figure.axes if ax.get_label() == "<colorbar>"]
        assert bar.get_ylim() == (0.0, top)


def test_the_metrics_picture_marks_no_peak_on_a_spectrum_that_only_falls(tmp_path, monkeypatch):
    """The spectrum of a flat field was marked "peak k = 0.628 (wavelength 10)" at the band's long-wave end, on a
    curve that only falls there (example 1a at 40 x 40, alpha = 6, t = 150: species e, f and b)."""
    from primordia.analysis.patterns import figures
    from primordia.analysis.patterns.run import Measurement, PredictedMode

    drawn = []
    save = figures._save
    monkeypatch.setattr(figures, "_save", lambda figure, path: (drawn.append(figure), save(figure, path))[1])
    metrics, grid = mesh_pattern_metrics(MESH.points, MESH.cells, np.tanh(MESH.points[:, 1] - 8.0))
    figures.metrics_figure([Measurement(150.0, "reference", "e", metrics, grid)],
                           PredictedMode(2.78, 2.26, 0.1, "linear analysis"), tmp_path / "metrics_e.png")
    (figure,) = drawn
    spectrum = figure.axes[1]
    labels = [text.get_text() for text in spectrum.get_legend().get_texts()]
    assert labels[0] == "no spectral peak" and not any("peak k" in label for label in labels)
    assert [line.get_xdata()[0] for line in spectrum.get_lines()[1:] if len(line.get_xdata())] == [2.78]


def test_a_field_of_no_pattern_says_which_criterion_it_missed(tmp_path):
    """Example 1a at 40 x 40, alpha = 6, t = 300: m_snapshots.png shows rows of spots two or three cells across,
    metrics.nc said "pattern = none", 0 spots, prominence 8.5, and nowhere what "none" takes: the threshold
    of 10 was in the module's constants alone."""
    from primordia.analysis.patterns.cli import describe
    from primordia.analysis.patterns.metrics import MIN_PROMINENCE

    write_run(tmp_path, stretch=1.0)
    analyse_run(tmp_path, pictures=False)
    saved = xr.open_dataset(tmp_path / "metrics.nc")
    rule = saved["pattern"].attrs["comment"]
    assert f"none: spectral_prominence below {MIN_PROMINENCE:g}" in rule and "its spots are not counted" in rule
    assert "aspect ratio below 2" in rule and "spot_fraction >= 0.5" in rule
    assert f"a pattern needs {MIN_PROMINENCE:g}" in saved["spectral_prominence"].attrs["long_name"]
    noise = saved.sel(time=20.0, configuration="reference", species="b")
    line = describe(noise, pattern_kind(noise).item())
    assert line == (f"t = 20 b (reference): none (spectral prominence {noise['spectral_prominence'].item():.3g} "
                    f"< {MIN_PROMINENCE:g})")
    flat = noise.copy()
    flat["dominant_wavelength"], flat["spectral_prominence"] = np.nan, 1.0
    assert describe(flat, "none") == "t = 20 b (reference): none (no spectral peak)"


@pytest.mark.parametrize("count, expected", [(0, "no spots"), (1, "1 spot"), (3, "3 spots, spacing 3 +- 0.1"),
                                             (7, "7 spots, spacing 3 +- 0.1, |psi_6| 0.980")])
def test_the_spots_in_words_leave_out_what_has_no_value(count, expected):
    """The metrics picture's titles read "0 spots, spacing nan +- nan, |psi6| nan" for a field with no spots."""
    from primordia.analysis.patterns.metrics import spots_text

    spacing = (3.0, 0.1) if count >= 2 else (np.nan, np.nan)
    assert spots_text(count, *spacing, 0.98 if count >= 4 else np.nan) == expected


def test_the_metrics_picture_titles_say_no_spots_and_why_there_is_no_pattern(tmp_path, monkeypatch):
    from primordia.analysis.patterns import figures
    from primordia.analysis.patterns.run import PredictedMode, measure, read_run

    drawn = []
    save = figures._save
    monkeypatch.setattr(figures, "_save", lambda figure, path: (drawn.append(figure), save(figure, path))[1])
    write_run(tmp_path, stretch=1.0)
    for species in ("b", "m"):
        chosen = [m for m in measure(read_run(tmp_path), [species]) if m.configuration == "reference"]
        figures.metrics_figure(chosen, PredictedMode(2.78, 2.26, 0.1, "linear analysis"), tmp_path / "metrics.png")
    noise, spots = (figure.axes[1].get_title() for figure in drawn)  # t = 20, the right-hand panel
    assert "nan" not in noise
    assert noise.startswith("b, t = 20 (reference): none (spectral prominence ")
    assert noise.endswith(" < 10)\nno spots")
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    for figure in drawn:  # the reason fits above its panel
        title = figure.axes[1].title.get_window_extent(FigureCanvasAgg(figure).get_renderer())
        assert title.x0 >= 0 and title.x1 <= figure.bbox.x1
    assert spots.startswith("m, t = 20 (reference): spots\n42 spots, spacing 2.99") and spots.endswith("|psi_6| 1.000")


def test_analysing_one_species_keeps_the_others_metrics(tmp_path, primordia_cli, capsys):
    """``primordia analyse RUN --species m`` after a whole analysis rewrote metrics.nc with m alone: b's metrics
    were lost.  They stay, unchanged, while the run's outputs are the same; once they are not, they are left out
    with a warning."""
    write_run(tmp_path, stretch=1.2)
    analyse_run(tmp_path, pictures=False)
    with xr.open_dataset(tmp_path / "metrics.nc") as whole:
        whole = whole.load()
    assert list(whole["species"].values) == ["m", "b"]
    result = primordia_cli("analyse", tmp_path, "--species", "m", "--no-pictures")
    assert result.returncode == 0, result.stderr
    assert "t = 20 b" not in result.stdout and "(with b kept from its earlier analysis)" in result.stdout
    with xr.open_dataset(tmp_path / "metrics.nc") as again:
        xr.testing.assert_identical(again.load(), whole)
    analyse_run(tmp_path, species=["b"], pictures=False)  # the other one alone: the same file again
    with xr.open_dataset(tmp_path / "metrics.nc") as again:
        xr.testing.assert_identical(again.load(), whole)

    time.sleep(0.01)
    write_run(tmp_path, stretch=1.2)  # a restart from an older checkpoint: the same times written again
    capsys.readouterr()
    analyse_run(tmp_path, species=["m"], pictures=False)
    assert "also held b, measured before the run's outputs were last written: left out" in capsys.readouterr().err
    analyse_run(tmp_path, pictures=False)
    write_run(tmp_path, stretch=1.2, times=(10.0, 20.0, 30.0))  # the run went on: b's old metrics lack t = 30
    capsys.readouterr()
    ds = analyse_run(tmp_path, species=["m"], pictures=False)
    assert "also held b, measured on other output times than the run has now: left out" in capsys.readouterr().err
    assert list(ds["species"].values) == ["m"]
    with xr.open_dataset(tmp_path / "metrics.nc") as last:
        assert list(last["species"].values) == ["m"] and list(last["time"].values) == [10.0, 20.0, 30.0]


def test_values_that_are_not_finite_are_measured_as_holes_with_a_warning(tmp_path, capsys):
    """NaN in a hand-made or damaged fields.xdmf was measured as a hole in the tissue without a word."""
    write_run(tmp_path, stretch=1.0)
    series = XdmfSeries(tmp_path, MESH)  # the same outputs again, with m not finite at three vertices at t = 20
    spots = gaussian_spots(MESH.points, hexagonal_lattice(3.0, 1.5), 0.5)
    holed = spots.copy()
    holed[:3] = [np.nan, np.inf, np.nan]
    for t, m in ((10.0, 0.5 * spots), (20.0, holed)):
        series.write(t, {"m": m, "b": np.full(MESH.num_vertices, 0.5), "u": np.zeros_like(MESH.points)})
    capsys.readouterr()
    ds = analyse_run(tmp_path, pictures=False)
    err = capsys.readouterr().err
    assert "field m has vertex values that are not finite (3 at t = 20): they are measured as holes" in err
    assert "field b" not in err and int(ds["spot_count"].sel(species="m", time=20.0, configuration="reference")) > 0


def test_an_earlier_analysis_by_another_version_is_replaced_with_a_warning(tmp_path, capsys):
    """An earlier metrics.nc with other metrics (another primordia version) was merged with this one's, its species
    given NaN for the metrics it lacked, as if measured and empty; they are now left out with a warning."""
    write_run(tmp_path, stretch=1.0)
    whole = analyse_run(tmp_path, pictures=False)
    from primordia.analysis.patterning import save_dataset

    save_dataset(whole.drop_vars("spectral_prominence"), tmp_path / "metrics.nc")  # as an older version wrote it
    capsys.readouterr()
    ds = analyse_run(tmp_path, species=["m"], pictures=False)
    assert "also held b, with other metrics than this version measures: left out" in capsys.readouterr().err
    assert list(ds["species"].values) == ["m"] and "kept_species" not in ds.attrs
    with xr.open_dataset(tmp_path / "metrics.nc") as written:
        assert list(written["species"].values) == ["m"] and "spectral_prominence" in written


def test_a_species_named_twice_is_measured_and_drawn_once(tmp_path, monkeypatch):
    """``primordia analyse RUN --species m m`` measured m twice, and metrics_m.png had each time twice over."""
    from primordia.analysis.patterns import figures

    drawn = []
    monkeypatch.setattr(figures, "metrics_figure", lambda measurements, predicted, path: drawn.append(
        [(m.time, m.species) for m in measurements]))
    write_run(tmp_path, stretch=1.0)
    ds = analyse_run(tmp_path, species=["m", "m"])
    assert list(ds["species"].values) == ["m"]
    assert drawn and all(times == [(10.0, "m"), (20.0, "m")] for times in drawn)  # reference, current


def test_a_displacement_that_is_not_finite_leaves_holes_in_the_current_configuration(tmp_path, capsys):
    """A NaN in u of a hand-made or damaged fields.xdmf ended ``primordia analyse`` with a traceback from
    matplotlib ("Triangulation is invalid"), where a field's NaN is a hole with a warning."""
    write_run(tmp_path, stretch=1.2)
    series = XdmfSeries(tmp_path, MESH)
    spots = gaussian_spots(MESH.points, hexagonal_lattice(3.0, 1.5), 0.5)
    u = 0.2 * MESH.points
    u[:2] = [[np.nan, 0.0], [np.inf, np.inf]]
    for t in (10.0, 20.0):
        series.write(t, {"m": spots, "b": np.full(MESH.num_vertices, 0.5), "u": u})
    capsys.readouterr()
    ds = analyse_run(tmp_path, pictures=False)
    assert ("field u has vertex values that are not finite (2 at t = 10, 2 at t = 20): they are measured as holes "
            "in the tissue of the current configuration") in capsys.readouterr().err
    assert int(ds["spot_count"].sel(species="m", time=20.0, configuration="current")) > 0
