"""Pattern metrics of a finished run directory, as an xarray Dataset (``metrics.nc``).

A run directory (see README, "A run directory holds") has the fields at the
output times in ``fields.xdmf`` and the resolved configuration in
``config.toml``.  :func:`run_metrics` measures every scalar field (species) at
every output time with :func:`~primordia.analysis.patterns.metrics.pattern_metrics`;
when the run has a displacement ``u`` it does so twice, on the reference
configuration ``X`` and on the current one ``x = X + u``.  Beside the
simulated metrics it stores the linear analysis's prediction for the same
configuration (:func:`predicted_mode`).

:func:`analyse_run` also writes ``metrics.nc`` and the pictures into the run directory.
"""

from __future__ import annotations

import socket
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import xarray as xr

from primordia.analysis.patterns.metrics import (
    CLASSIFICATION_RULE,
    MIN_PROMINENCE,
    PATTERN_KINDS,
    GriddedField,
    MeshSampler,
    PatternMetrics,
    pattern_metrics,
)
from primordia.core.errors import ConfigError, one_line, warn
from primordia.core.outputs import ANALYSIS_FILE, SERIES_OWN, run_is_alive

METRICS_FILE = ANALYSIS_FILE

#: The scalar metrics of one snapshot: Dataset variable, PatternMetrics attribute, long name.
SCALAR_METRICS = (
    ("dominant_wavelength", "dominant_wavelength", "2 pi / peak of the radially averaged power spectrum "
     "(NaN: no peak, the spectrum falls across the whole band)"),
    ("dominant_wavenumber", "dominant_wavenumber", "peak of the radially averaged power spectrum "
     "(NaN: no peak, the spectrum falls across the whole band)"),
    ("spectral_prominence", "prominence", "peak power over the spectrum around it (noise, fronts ~1-5; patterns >> 10; "
     f"a pattern needs {MIN_PROMINENCE:g})"),
    ("spot_count", "spot_count", "number of spots (compact regions above the level)"),
    ("spacing_mean", "spacing_mean", "mean distance from a spot to its nearest neighbour"),
    ("spacing_std", "spacing_std", "standard deviation of the nearest-neighbour distances"),
    ("hexatic_order", "hexatic_order", "mean |psi_6| over spots away from the pattern's edge (1: hexagonal)"),
    ("spot_fraction", "spot_fraction", "fraction of the area above the level lying in spots"),
    ("orientation_order", "orientation_order", "nematic order of the gradient (1: parallel stripes)"),
    ("level", "level", "threshold separating high from low phase (halfway between min and max)"),
)

#: CF units of the metrics: lengths and areas are the mesh's, the seed's dimensionless ones ("1"), as the
#: wavenumber's; counts and orders are numbers ("1")
METRIC_UNITS = {name: "1" for name, _, _ in SCALAR_METRICS} | {"spot_x": "1", "spot_y": "1", "spot_area": "1"}


class PredictedMode(NamedTuple):
    """The linear analysis's fastest-growing stationary (Turing) mode.

    ``k_max`` and ``wavelength`` are NaN when no mode grows (``rate`` <= 0 is
    then the largest rate) or when the analysis does not describe the model (all NaN).
    """

    k_max: float
    wavelength: float
    rate: float
    note: str = ""


def linear_model(config: Mapping):
    """The seed's model read as a configuration's: (Table 3.1 parameters with its values, coupled?).

    The linearisation of the model the configuration composes
    (:func:`primordia.analysis.composed.seed_model_values`): xi_f = 0 without the FGF
    sink, tau = 0 without the active stress, coupled with both (seed section 3.4).  A
    ConfigError when the seed's analysis does not describe the model: a plugin's
    kinetics, or a growing tissue (seed section 6).
    """
    from primordia.analysis.composed import linearise_model, seed_model_values

    return seed_model_values(linearise_model(_composed_model(config)))


def _composed_model(config: Mapping):
    """The :class:`~primordia.model.Model` of a configuration's composition (any mesh and times will do)."""
    from primordia.model import Model

    # a run's metadata may lack a mesh or times
    composition = {key: value for key, value in config.items() if key != "output"}
    composition.setdefault("mesh", {"type": "rectangle", "upper": [1.0, 1.0], "cells": [1, 1]})
    composition["time"] = {"dt": 1.0, "t_final": 1.0}
    return Model.from_config(composition)


def predicted_mode(config: Mapping | str | Path) -> PredictedMode:
    """k_max, wavelength 2 pi / k_max and growth rate of the linear analysis for a run's configuration.

    ``config``: a configuration mapping (e.g. a run's resolved ``config.toml``) or
    a path to one.  The analysis is derived from the very model the configuration
    composes (:func:`primordia.analysis.composed.linearise_model`): its kinetics,
    species and mechanics, whatever plugins they come from.  A finite-strain growth
    model has no linear analysis (seed section 6): its chemistry alone is analysed,
    which predicts the wavelength in the current configuration (where, in 2D, the
    growing tissue's chemistry keeps its diffusivities).
    """
    from primordia.analysis.composed import linearise_model

    if not isinstance(config, Mapping):
        from primordia.core.config import load_config

        config = load_config(config)
    try:
        model = _composed_model(config)
        growing = any(module.finite_strain for module in model.physics_objects)
        linear = linearise_model(model, chemistry_only=growing)
    except ConfigError as error:
        return PredictedMode(np.nan, np.nan, np.nan, f"no linear analysis for this model: {error}")
    mode = linear.fastest_mode("stationary")
    note = ("chemistry alone (a growing tissue has no linear analysis): the current configuration's wavelength"
            if growing else linear.describe())
    if not mode.unstable:  # no wavelength is selected; the largest (negative) rate still says how stable
        return PredictedMode(np.nan, np.nan, mode.growth_rate, f"{note}, stable: no Turing mode grows")
    if mode.k_max == 0:  # the well-mixed kinetics run away: no wavelength is selected (mode.wavelength is inf)
        note += ", the homogeneous state itself is unstable (k = 0)"
    return PredictedMode(mode.k_max, mode.wavelength, mode.growth_rate, note)


@dataclass(frozen=True)
class RunFields:
    """The vertex fields of a run directory at its output times."""

    directory: Path
    points: np.ndarray  #: (n_vertices, 2), reference configuration (of a slab, its top face's)
    triangles: np.ndarray  #: (n_cells, 3)
    times: tuple[float, ...]
    snapshots: tuple[dict[str, np.ndarray], ...]  #: per time, field name -> vertex values
    config: dict  #: the resolved config.toml (empty if absent)
    status: str  #: summary.json's status ("killed": "running" by a process gone from this host), or "unknown"
    surface: str = "the mesh"  #: what is measured: the 2D mesh, or a slab's top face

    @property
    def scalar_fields(self) -> list[str]:
        return [name for name, values in self.snapshots[0].items() if values.ndim == 1]

    @property
    def configurations(self) -> tuple[str, ...]:
        return ("reference", "current") if "u" in self.snapshots[0] else ("reference",)

    def points_in(self, configuration: str, index: int) -> np.ndarray:
        """Vertex coordinates in the reference configuration, or the current one X + u at output ``index``."""
        if configuration == "reference":
            return self.points
        return self.points + self.snapshots[index]["u"][:, : self.points.shape[1]]


def read_run(directory: str | Path) -> RunFields:
    """The mesh, output times and fields of a run directory; a missing or empty one is a ConfigError."""
    import json

    import meshio

    directory = Path(directory)
    xdmf = directory / "fields.xdmf"
    if not directory.exists():
        raise ConfigError(f"{directory} does not exist")
    if not directory.is_dir():
        raise ConfigError(f"{directory} is a file, not a run directory")
    if not xdmf.is_file():
        raise ConfigError(f"{directory}: no fields.xdmf (not a run directory, or the run wrote no output time yet)")
    try:  # a damaged run directory (a truncated fields.xdmf, fields_h5/ gone) is named, not a traceback
        reader = meshio.xdmf.TimeSeriesReader(str(xdmf))
        points, blocks = reader.read_points_cells()
        points = np.asarray(points)
        triangles = [block.data for block in blocks if block.type == "triangle"]
        tetrahedra = [block.data for block in blocks if block.type == "tetra"]
        if triangles:
            vertices, triangles, surface = slice(None), triangles[0], "the mesh"
        elif tetrahedra:  # a slab (example 4): its top face, where the pictures show the pattern
            from primordia.core.meshes import height_text, top_face

            vertices, triangles = top_face(points, np.asarray(tetrahedra[0]))
            if not len(triangles):
                raise ConfigError(f"{xdmf}: the tetrahedral mesh has no face facing up to measure patterns on")
            surface = f"the top face z = {height_text(points[vertices, 2])}"
        else:
            raise ConfigError(f"{xdmf}: pattern metrics need a triangle or tetrahedron mesh; found "
                              f"{[b.type for b in blocks]}")
        times, snapshots = [], []
        for index in range(reader.num_steps):
            t, fields, _ = reader.read_data(index)
            times.append(float(t))
            snapshots.append({name: np.asarray(values)[vertices] for name, values in fields.items()})
    except (OSError, ValueError, KeyError, IndexError, TypeError, AttributeError, SyntaxError) as error:
        reason = one_line(error, named=False)
        raise ConfigError(f"{xdmf} (or the HDF5 files it names) cannot be read: {reason}") from None
    if not snapshots:
        raise ConfigError(f"{xdmf}: no output time written")
    config_path, summary_path = directory / "config.toml", directory / "summary.json"
    try:
        config = tomllib.loads(config_path.read_text()) if config_path.is_file() else {}
    except (OSError, ValueError) as error:
        raise ConfigError(f"{config_path} cannot be read: {one_line(error, named=False)}") from None
    try:
        summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
        status = str(summary.get("status", "unknown"))
        # a run killed without a word (SIGKILL, a sweep's --timeout, the machine) left "running" behind: "run
        # running" was said of it, as if more output times were to come; one on another host cannot be told
        process = summary.get("process") or {}
        if status == "running" and process.get("host") == socket.gethostname() and not run_is_alive(process):
            status = "killed"
    except (OSError, ValueError, AttributeError):
        status = "unknown"  # only the run's status is read from it, for the report
    return RunFields(directory, points[vertices][:, :2], triangles, tuple(times), tuple(snapshots), config, status,
                     surface)


@dataclass(frozen=True)
class Measurement:
    """The metrics of one field at one output time in one configuration, and the grid they were measured on."""

    time: float
    configuration: str
    species: str
    metrics: PatternMetrics
    grid: GriddedField


def measure(run: RunFields, species: Sequence[str] | None = None) -> list[Measurement]:
    """:func:`pattern_metrics` of each species at each output time in each configuration."""
    names = _chosen_species(run, species)
    found = []
    reference = MeshSampler(run.points, run.triangles)
    not_finite: dict[str, list[tuple[float, int]]] = {}
    for index, (t, fields) in enumerate(zip(run.times, run.snapshots)):
        values = dict(fields)
        for name in names:
            finite = np.isfinite(fields[name])
            if not finite.all():
                values[name] = np.where(finite, fields[name], np.nan)  # +-inf too
                not_finite.setdefault(name, []).append((t, int(np.count_nonzero(~finite))))
        for configuration in run.configurations:
            sampler = (reference if configuration == "reference"
                       else _current_sampler(run, configuration, index, not_finite))
            for name in names:
                grid = sampler(values[name])
                found.append(Measurement(t, configuration, name, pattern_metrics(grid, sampler.resolution), grid))
    for name, where in not_finite.items():  # a run never writes them (it rejects the step): a file made or damaged
        counts = ", ".join(f"{count} at t = {t:g}" for t, count in where)
        warn(f"{run.directory}: field {name} has vertex values that are not finite ({counts}): they are measured "
             "as holes in the tissue" + (" of the current configuration" if name == "u" else ""))
    return found


def _current_sampler(run: RunFields, configuration: str, index: int, not_finite: dict) -> MeshSampler:
    """The sampler of the current configuration at output ``index``, the triangles around a vertex whose
    displacement is not finite left out as holes (counted in ``not_finite["u"]``): its position NaN or inf made
    matplotlib's triangulation invalid, a traceback where the fields' own such values are holes with a warning."""
    points = run.points_in(configuration, index)
    placed = np.isfinite(points).all(axis=1)
    if placed.all():
        return MeshSampler(points, run.triangles)
    not_finite.setdefault("u", []).append((run.times[index], int(np.count_nonzero(~placed))))
    triangles = run.triangles[placed[run.triangles].all(axis=1)]
    if not triangles.size:
        raise ConfigError(f"{run.directory}: the displacement u at t = {run.times[index]:g} is not finite at any "
                          "triangle: the current configuration cannot be measured")
    return MeshSampler(np.where(placed[:, None], points, run.points), triangles)  # unused: placed anywhere finite


def _chosen_species(run: RunFields, species: Sequence[str] | None) -> list[str]:
    """The fields to measure, each once: ``--species m m`` measured m twice, and its picture drew every time
    twice over."""
    available = run.scalar_fields
    if not species:
        return available
    for name in species:
        if name not in available:
            raise ConfigError(f"{run.directory}: no scalar field '{name}' (fields: {', '.join(available)})")
    return list(dict.fromkeys(species))


def metrics_dataset(run: RunFields, measurements: Sequence[Measurement], predicted: PredictedMode) -> xr.Dataset:
    """The measurements as a Dataset over (time, configuration, species), spots padded along ``spot``."""
    times = sorted({m.time for m in measurements})
    configurations = [c for c in run.configurations if any(m.configuration == c for m in measurements)]
    species = list(dict.fromkeys(m.species for m in measurements))
    shape = (len(times), len(configurations), len(species))
    dims = ("time", "configuration", "species")
    spots = max(1, max(m.metrics.spot_count for m in measurements))  # NetCDF3: no zero-length dimension
    wavenumbers = measurements[0].metrics.wavenumbers
    scalars = {name: np.full(shape, np.nan) for name, _, _ in SCALAR_METRICS}
    kind = np.zeros(shape, dtype=np.int8)
    spot_arrays = {name: np.full(shape + (spots,), np.nan) for name in ("spot_x", "spot_y", "spot_area")}
    spectrum = np.full(shape + (wavenumbers.size,), np.nan)
    for m in measurements:
        at = (times.index(m.time), configurations.index(m.configuration), species.index(m.species))
        for name, attribute, _ in SCALAR_METRICS:
            scalars[name][at] = getattr(m.metrics, attribute)
        kind[at] = PATTERN_KINDS.index(m.metrics.kind)
        count = m.metrics.spot_count
        spot_arrays["spot_x"][at][:count] = m.metrics.spot_centres[:, 0]
        spot_arrays["spot_y"][at][:count] = m.metrics.spot_centres[:, 1]
        spot_arrays["spot_area"][at][:count] = m.metrics.spot_areas
        spectrum[at] = np.interp(wavenumbers, m.metrics.wavenumbers, m.metrics.power, right=np.nan)
    ds = xr.Dataset(
        {name: (dims, scalars[name], {"long_name": text, "units": METRIC_UNITS[name]})
         for name, _, text in SCALAR_METRICS},
        coords={"time": ("time", np.array(times), {"long_name": SERIES_OWN["time"][0], "units": SERIES_OWN["time"][1]}),
                "configuration": ("configuration", configurations, {
                    "long_name": "reference: on X; current: on x = X + u"}),
                "species": ("species", species),
                "wavenumber": ("wavenumber", wavenumbers, {  # radians per length, both dimensionless
                    "long_name": "wavenumber k = 2 pi / wavelength (dimensionless, seed section 2)", "units": "1"})},
    )
    ds["pattern"] = (dims, kind, {"long_name": "pattern kind", "flag_values": np.arange(len(PATTERN_KINDS),
                                                                                        dtype=np.int8),
                                  "flag_meanings": " ".join(PATTERN_KINDS), "comment": CLASSIFICATION_RULE})
    for name, text in (("spot_x", "x of the spot's maximum"), ("spot_y", "y of the spot's maximum"),
                       ("spot_area", "area of the spot above the level")):
        ds[name] = (dims + ("spot",), spot_arrays[name], {"long_name": text + " (NaN past spot_count)",
                                                          "units": METRIC_UNITS[name]})
    # the fields, lengths and times are the seed's dimensionless ones: the spectrum (the field's units squared: its
    # sum over the k plane is the field's windowed variance) and the linear analysis's k, wavelength and rate too
    ds["power_spectrum"] = (dims + ("wavenumber",), spectrum, {
        "long_name": "radially averaged power spectrum of the field minus its mean (Hann window)", "units": "1"})
    ds["predicted_wavenumber"] = ((), predicted.k_max, {"long_name": "linear analysis: fastest stationary k",
                                                        "units": "1"})
    ds["predicted_wavelength"] = ((), predicted.wavelength, {"long_name": "linear analysis: 2 pi / k_max",
                                                             "units": "1"})
    ds["predicted_growth_rate"] = ((), predicted.rate, {"long_name": "linear analysis: Re phi at k_max (per unit of "
                                                        "time)", "units": "1"})
    ds.attrs.update({"title": f"primordia pattern metrics of {run.directory}", "run_status": run.status,
                     "surface": run.surface,
                     "linear_analysis": predicted.note,
                     "method": "primordia.analysis.patterns.metrics (module docstring)"})
    return ds


def pattern_kind(ds: xr.Dataset, **where) -> np.ndarray:
    """The ``pattern`` codes of ``ds`` (optionally ``.sel(**where)``) as their names."""
    codes = ds["pattern"].sel(**where).values if where else ds["pattern"].values
    codes = np.asarray(codes, dtype=int)
    return np.asarray(PATTERN_KINDS, dtype=object)[codes.ravel()].reshape(codes.shape)


def run_metrics(directory: str | Path, species: Sequence[str] | None = None) -> xr.Dataset:
    """The pattern metrics of a run directory (nothing is written)."""
    run = read_run(directory)
    return metrics_dataset(run, measure(run, species), _prediction(run))


def _prediction(run: RunFields) -> PredictedMode:
    """The linear analysis of the run's own configuration; none without its config.toml (Table 3.1's
    defaults would predict another model's wavelength: 4.49 where example 1a's is 2.78)."""
    if not (run.directory / "config.toml").is_file():
        return PredictedMode(np.nan, np.nan, np.nan, "no linear analysis: the run directory has no config.toml")
    return predicted_mode(run.config)


def _with_earlier_species(ds: xr.Dataset, path: Path) -> tuple[xr.Dataset, list[str]]:
    """``ds`` with the species an earlier ``metrics.nc`` measured and ``ds`` did not, and their names.

    ``primordia analyse RUN --species m`` after a whole analysis rewrote the file with m alone: the other
    species' metrics were lost.  They are kept when the earlier file measured the same output times,
    configurations and wavenumbers with the same metrics, after the run last wrote its outputs; otherwise (the
    run went on, or was restarted and wrote them again; another version) they are left out with a warning.
    An earlier file that does not read is replaced, as before.
    """
    if not path.is_file():
        return ds, []
    try:
        with xr.open_dataset(path, engine="scipy") as opened:
            earlier = opened.load()
    except Exception:  # noqa: BLE001  (damaged or another format: replaced by the new measurements)
        return ds, []
    if "species" not in earlier.dims:
        return ds, []
    measured = [str(name) for name in ds["species"].values]
    others = [str(name) for name in earlier["species"].values if str(name) not in measured]
    if not others:
        return ds, []
    differing = [words for name, words in (("time", "output times"), ("configuration", "configurations"),
                                           ("wavenumber", "wavenumbers"))
                 if not (name in earlier.coords and earlier[name].shape == ds[name].shape
                         and np.array_equal(earlier[name].values, ds[name].values))]
    fields = path.parent / "fields.xdmf"
    why = (f"measured on other {' and '.join(differing)} than the run has now" if differing
           else "with other metrics than this version measures" if set(earlier.data_vars) != set(ds.data_vars)
           # a restart from an older checkpoint writes the same output times again, with other values
           else "measured before the run's outputs were last written"
           if fields.is_file() and fields.stat().st_mtime > path.stat().st_mtime else "")
    if why:
        warn(f"{path} also held {', '.join(others)}, {why}: left out (`primordia analyse {path.parent}` measures "
             "every species)")
        return ds, []
    old = earlier.sel(species=others)
    spots = max(ds.sizes.get("spot", 1), old.sizes.get("spot", 1))
    padded = [part.pad(spot=(0, spots - part.sizes["spot"])) if part.sizes["spot"] < spots else part
              for part in (ds, old)]
    for part in padded:
        for variable in part.variables.values():
            variable.encoding = {}
    merged = xr.concat(padded, dim="species", data_vars="minimal", coords="minimal", compat="override",
                       join="exact", combine_attrs="override")
    before = [str(name) for name in earlier["species"].values]
    merged = merged.sel(species=before + [name for name in measured if name not in before])  # the file's order
    merged["pattern"] = merged["pattern"].astype(np.int8)
    return merged, others


def analyse_run(directory: str | Path, species: Sequence[str] | None = None, pictures: bool = True) -> xr.Dataset:
    """Measure a run directory, write ``metrics.nc`` and (``pictures``) ``metrics_<species>[_current].png``; returns
    the measurements of ``species`` (metrics.nc also keeps other species of an earlier analysis of the same
    outputs: :func:`analyse_run_keeping`)."""
    return analyse_run_keeping(directory, species, pictures)[0]


def analyse_run_keeping(directory: str | Path, species: Sequence[str] | None = None,
                        pictures: bool = True) -> tuple[xr.Dataset, list[str]]:
    """:func:`analyse_run`, and the species metrics.nc kept from an earlier analysis (:func:`_with_earlier_species`),
    which ``primordia analyse`` names."""
    from primordia.analysis.patterning import save_dataset

    run = read_run(directory)
    measurements = measure(run, species)
    predicted = _prediction(run)
    ds = metrics_dataset(run, measurements, predicted)
    written, kept = _with_earlier_species(ds, run.directory / METRICS_FILE)
    save_dataset(written, run.directory / METRICS_FILE)
    if pictures:
        from primordia.analysis.patterns.figures import metrics_figure

        for configuration in ds["configuration"].values:
            for name in ds["species"].values:
                chosen = [m for m in measurements if m.species == name and m.configuration == configuration]
                suffix = "" if configuration == "reference" else f"_{configuration}"
                metrics_figure(chosen, predicted, run.directory / f"metrics_{name}{suffix}.png")
    return ds, kept
