"""Pattern metrics of simulations: what formed, how far apart, and what the linear analysis predicted.

From Python::

    from primordia.analysis.patterns import analyse_run, predicted_mode, run_metrics

    ds = analyse_run("out/ex01a")                     # writes out/ex01a/metrics.nc and metrics_<species>.png
    ds["spacing_mean"].sel(species="m").values        # per output time and configuration
    predicted_mode("examples/ex01a.toml")             # (k_max, wavelength, rate, note) of the linear analysis

and from the shell: ``primordia analyse RUN_DIR`` (``primordia.analysis.patterns.cli``).

Modules: :mod:`.metrics` (the metrics of one gridded field, and what each
threshold is), :mod:`.run` (run directories -> Datasets, the linear
prediction), :mod:`.figures` (field + spots, spectrum + k_max, sweep maps).
Parameter sweeps that gather these metrics live in :mod:`primordia.sweep`.
"""

from __future__ import annotations

#: Public names, and the module holding them; imported on first use, so the CLI
#: (which imports ``.cli`` to build its parser) does not load scipy and xarray.
_MODULES = {
    "metrics": ("PATTERN_KINDS", "GriddedField", "PatternMetrics", "mesh_pattern_metrics", "pattern_metrics",
                "to_grid"),
    "run": ("METRICS_FILE", "PredictedMode", "RunFields", "analyse_run", "pattern_kind", "predicted_mode",
            "read_run", "run_metrics"),
}
__all__ = sorted(name for names in _MODULES.values() for name in names)


def __getattr__(name: str):
    import importlib

    for module, names in _MODULES.items():
        if name in names:
            return getattr(importlib.import_module(f"{__name__}.{module}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
