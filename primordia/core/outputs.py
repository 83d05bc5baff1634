"""What a run writes, as output plugins (registered through ``primordia_outputs``).

Each :class:`Output` contributes its own files: it is told when the run starts,
at every output time, and when the run ends (normally or not).  Every file is
written atomically (:mod:`primordia.core.io`), so whatever has been written
stays readable if a run dies part-way.

Built-in outputs: the resolved configuration (``config.toml``), the fields in
XDMF (``fields.xdmf`` + ``fields.h5``), the scalar time series
(``series.nc``), the pictures (``m_t0160.png``..., ``m_snapshots.png``,
``final_fields.png``) and the run summary (``summary.json``).
"""

from __future__ import annotations

import numpy as np

from primordia.core import io
from primordia.core.plugins import hookimpl


class Output:
    """Base class: override the moments you write at (all run on every rank)."""

    name: str

    def start(self, run) -> None:
        """Before the first step (after initial conditions are set)."""

    def record(self, run) -> None:
        """At a series time (every ``output.series_every`` steps and at snapshots)."""

    def snapshot(self, run) -> None:
        """At a field snapshot time (``output.times``)."""

    def finish(self, run, status: str) -> None:
        """After the last step, or when the run stops early (``status`` says why)."""


class ResolvedConfig(Output):
    name = "config"

    def start(self, run):
        if run.is_root:
            io.write_toml(run.out_dir / "config.toml", run.model.resolved_config())


class FieldsXdmf(Output):
    """All fields at the snapshot times, readable by ParaView and meshio."""

    name = "xdmf"

    def start(self, run):
        self.series = io.XdmfSeries(run.out_dir, run.mesh_data, name="fields") if run.is_root else None

    def snapshot(self, run):
        values = run.vertex_values()
        if run.is_root:
            self.series.write(run.time, values)


class ScalarSeriesNetcdf(Output):
    """Per recorded time: integral, min and max of each field, solver iterations."""

    name = "series"

    def start(self, run):
        self.series = io.ScalarSeries(run.out_dir / "series.nc") if run.is_root else None
        self.record(run)

    def record(self, run):
        row = {"step": run.step_index}
        for name, stats in run.field_statistics().items():
            row.update({f"{name}_integral": stats["integral"], f"{name}_min": stats["min"],
                        f"{name}_max": stats["max"]})
        row.update(run.diagnostic_values())
        row.update(run.iteration_counts())
        if run.is_root and (not self.series.times or run.time > self.series.times[-1]):
            self.series.append(run.time, row)


class Pictures(Output):
    """PNGs of the snapshot fields at every snapshot time, and of every field at the end.

    Vector fields are drawn as their magnitude.  When the model has a displacement
    ``u``, fields are drawn on the deformed configuration, magnified by
    ``output.displacement_scale`` (stated on the picture).
    """

    name = "pictures"

    def start(self, run):
        self.snapshots: dict[str, dict[str, object]] = {}
        self.snapshot_displacements: dict[str, dict[str, object]] = {}

    @staticmethod
    def _scalar(values):
        return np.linalg.norm(values, axis=1) if values.ndim == 2 else values

    def snapshot(self, run):
        if not run.model.output["pictures"]:
            return
        values = run.vertex_values()
        if not run.is_root:
            return
        displacement, scale = values.get("u"), run.model.output["displacement_scale"]
        for name in run.model.output["snapshot_fields"]:
            label = f"{name}, t = {run.time:g}"
            field = self._scalar(values[name])
            io.plot_field(run.out_dir / f"{name}_t{run.time:07.2f}.png", run.mesh_data, field, title=label,
                          displacement=displacement, displacement_scale=scale)
            self.snapshots.setdefault(name, {})[label] = field
            if displacement is not None:
                self.snapshot_displacements.setdefault(name, {})[label] = displacement
            io.plot_fields_grid(run.out_dir / f"{name}_snapshots.png", run.mesh_data, self.snapshots[name],
                                title=f"{name} at the snapshot times",
                                displacements=self.snapshot_displacements.get(name), displacement_scale=scale)

    def finish(self, run, status):
        if not run.model.output["pictures"]:
            return
        values = run.vertex_values()
        if run.is_root:
            fields = {(f"|{name}|" if v.ndim == 2 else name): self._scalar(v) for name, v in values.items()}
            displacement = values.get("u")
            displacements = None if displacement is None else {key: displacement for key in fields}
            io.plot_fields_grid(run.out_dir / "final_fields.png", run.mesh_data, fields,
                                title=f"all fields at t = {run.time:g} ({status})", shared_colour_scale=False,
                                displacements=displacements, displacement_scale=run.model.output["displacement_scale"])


class Summary(Output):
    """``summary.json``: sizes, steps, wall time, final statistics, mean iterations."""

    name = "summary"

    def start(self, run):
        self._write(run, "running")

    def snapshot(self, run):
        self._write(run, "running")

    def finish(self, run, status):
        self._write(run, status)

    def _write(self, run, status):
        summary = run.summary(status)
        if run.is_root:
            io.write_json(run.out_dir / "summary.json", summary)


@hookimpl
def primordia_outputs():
    return [ResolvedConfig, FieldsXdmf, ScalarSeriesNetcdf, Pictures, Summary]
