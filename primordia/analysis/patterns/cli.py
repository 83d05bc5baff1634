"""The ``primordia analyse`` command: pattern metrics of a finished run.

    primordia analyse RUN_DIR [--species m ...] [--no-pictures]
        per output time and species: pattern kind, spots (count, spacing), |psi_6|,
        dominant wavelength, beside the linear analysis's k_max; writes RUN_DIR/metrics.nc
        and RUN_DIR/metrics_<species>.png (also *_current.png for runs with a displacement u)

``register(subparsers)`` adds the command to the main ``primordia`` parser.
"""

from __future__ import annotations

import argparse
import time


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``analyse`` subcommand to an argparse ``subparsers`` object; sets ``func``."""
    parser = subparsers.add_parser(
        "analyse", help="pattern metrics of a finished run: spots, spacing, |psi_6|, wavelength vs linear k_max",
        description=__doc__.split("\n\n")[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", metavar="RUN_DIR", help="a run directory (fields.xdmf, config.toml, ...)")
    parser.add_argument("--species", nargs="+", metavar="NAME", help="only these scalar fields (default: all)")
    parser.add_argument("--no-pictures", action="store_true", help="write metrics.nc only")
    parser.set_defaults(func=run)
    return parser


def run(args) -> int:
    """Entry point of ``primordia analyse``; returns the exit code."""
    from primordia.analysis.patterns.run import METRICS_FILE, analyse_run_keeping, pattern_kind

    start = time.perf_counter()
    ds, kept = analyse_run_keeping(args.run_dir, species=args.species, pictures=not args.no_pictures)
    predicted = ds["predicted_wavelength"].item()
    surface = "" if ds.attrs["surface"] == "the mesh" else f", measured on {ds.attrs['surface']}"
    print(f"primordia analyse: {args.run_dir} (run {ds.attrs['run_status']}{surface}); linear analysis, "
          f"{ds.attrs['linear_analysis']}: k_max = {ds['predicted_wavenumber'].item():.4g}, "
          f"wavelength {predicted:.4g}, growth rate {ds['predicted_growth_rate'].item():.3g}")
    for t in ds["time"].values:
        for configuration in ds["configuration"].values:
            for species in ds["species"].values:
                at = {"time": t, "configuration": configuration, "species": species}
                print("  " + describe(ds.sel(**at), pattern_kind(ds, **at).item()))
    print(f"  wrote {args.run_dir}/{METRICS_FILE}" + (f" (with {', '.join(kept)} kept from its earlier analysis)"
                                                     if kept else "")
          + ("" if args.no_pictures else " and metrics_*.png") + f" ({time.perf_counter() - start:.1f} s)")
    return 0


def describe(point, kind: str) -> str:
    """One line for one (time, configuration, species) of a metrics Dataset."""
    text = f"t = {point['time'].item():g} {point['species'].item()} ({point['configuration'].item()}): {kind}"
    from primordia.analysis.patterns.metrics import no_pattern_reason, spots_text

    if kind == "none":  # the spectrum's highest point is no pattern's wavelength
        reason = no_pattern_reason(point["spectral_prominence"].item(), point["dominant_wavelength"].item())
        return text + f" ({reason})"
    text += f"; wavelength {point['dominant_wavelength'].item():.4g}"
    count = int(point["spot_count"].item())
    if count:
        text += "; " + spots_text(count, *(point[name].item() for name in ("spacing_mean", "spacing_std",
                                                                           "hexatic_order")))
    return text
