"""The ``primordia stability`` command (linear stability analysis, seed section 3).

    primordia stability [CONFIG.toml] [--set parameters.NAME=VALUE ...] [--coupled|--uncoupled] [--d 2|3] [--out DIR]
        verdicts of seed sections 3.2-3.6, the fastest-growing mode (k_max, wavelength 2 pi / k_max),
        and the dispersion curves as DIR/dispersion.nc + DIR/dispersion.png

    primordia stability map [CONFIG.toml] --x NAME:LO:HI:N --y NAME:LO:HI:N [--coupled|--uncoupled]
                            [--critical NAME] [--theta corrected|seed] [--nk N] [--set ...] [--out DIR]
        the patterning space over two parameters, from the conditions and from the growth rates,
        as DIR/patterning_X_Y.nc + .png (seed Figures 3.1-3.3)

``register(subparsers)`` adds the command to the main ``primordia`` parser.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from primordia.core.errors import ConfigError

DEFAULT_OUT = Path("out") / "stability"


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``stability`` subcommand to an argparse ``subparsers`` object; sets ``func``."""
    parser = subparsers.add_parser(
        "stability",
        help="linear stability analysis: dispersion relation, k_max, patterning spaces (seed section 3)",
        description="\n\n".join(__doc__.split("\n\n")[1:3]),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("inputs", nargs="*", metavar="[map] [CONFIG.toml]",
                        help="'map' for a patterning space; a TOML file whose [parameters] table is read")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="parameters.NAME=VALUE",
                        help="override a parameter (repeatable)")
    coupling = parser.add_mutually_exclusive_group()
    coupling.add_argument("--coupled", dest="coupled", action="store_true", default=True,
                          help="full poro-mechano-chemical system (default)")
    coupling.add_argument("--uncoupled", dest="coupled", action="store_false",
                          help="drop the mechano-chemical loop (xi_f = 0, seed section 3.4)")
    parser.add_argument("--d", type=int, choices=(2, 3), default=2, help="space dimension (default 2)")
    parser.add_argument("--out", help=f"output directory (default {DEFAULT_OUT}/...)")
    parser.add_argument("--x", metavar="NAME:LO:HI:N", help="map: first parameter axis")
    parser.add_argument("--y", metavar="NAME:LO:HI:N", help="map: second parameter axis")
    parser.add_argument("--critical", metavar="NAME",
                        help="map: parameter whose critical value gives panels 2-3 (default: the --x one)")
    parser.add_argument("--theta", choices=("corrected", "seed"), default="corrected",
                        help="map, coupled: theta_i of section 3.6 for the boundary curves (default corrected)")
    parser.add_argument("--nk", type=int, default=64, help="map: number of wavenumbers searched (default 64)")
    parser.set_defaults(func=run)
    return parser


def run(args) -> int:
    """Entry point of ``primordia stability``; returns the exit code."""
    from primordia.analysis.inputs import read_parameters

    inputs = list(args.inputs)
    mapping = bool(inputs) and inputs[0] == "map"
    if mapping:
        inputs.pop(0)
    if len(inputs) > 1:
        raise ConfigError(f"stability takes at most one CONFIG.toml, got {' '.join(inputs)}")
    config = inputs[0] if inputs else None
    params = read_parameters(config, args.overrides)
    stem = Path(config).stem if config else None
    if mapping:
        return _run_map(args, params, stem)
    if args.x or args.y or args.critical:
        raise ConfigError("--x, --y and --critical apply to 'primordia stability map'")
    return _run_dispersion(args, params, stem)


def _output_directory(args, *parts) -> Path:
    if args.out:
        return Path(args.out)
    return DEFAULT_OUT.joinpath(*[p for p in parts if p])


def _describe(params) -> str:
    changed = [f"{name}={params[name]:g}" for name in params
               if params[name] != params.declaration(name).default]
    return "Table 3.1" + (f" with {', '.join(changed)}" if changed else "")


def _run_dispersion(args, params, stem) -> int:
    from primordia.analysis.conditions import verdicts
    from primordia.analysis.dispersion import fastest_growing_mode
    from primordia.analysis.figures import dispersion_figure
    from primordia.analysis.patterning import dispersion_relation, save_dataset

    start = time.perf_counter()
    base = params if args.coupled else params.replace(xi_f=0.0)
    print(f"primordia stability: d = {args.d}, {'coupled' if args.coupled else 'uncoupled (xi_f = 0)'}, "
          f"parameters: {_describe(params)}")
    for verdict in verdicts(params):
        print(f"  {verdict}")
    fastest = fastest_growing_mode(base, coupled=args.coupled)
    turing = fastest_growing_mode(base, coupled=args.coupled, kind="stationary")
    print(f"  fastest-growing mode: {_mode_text(fastest)}")
    print(f"  fastest stationary (Turing) mode: {_mode_text(turing)}")
    ds = dispersion_relation(base, d=args.d, coupled=args.coupled)
    out = _output_directory(args, stem)
    netcdf = save_dataset(ds, out / "dispersion.nc")
    figure = out / "dispersion.png"
    dispersion_figure(ds, figure)
    print(f"  wrote {netcdf} and {figure} ({time.perf_counter() - start:.1f} s)")
    return 0


def _mode_text(mode) -> str:
    if not mode.unstable:
        return f"none grows (largest Re phi {mode.growth_rate:.3g} at k = {mode.k_max:.3g})"
    nature = "stationary" if mode.stationary else f"oscillatory, frequency {mode.frequency:.4g}"
    edge = "; at the end of the k range searched" if mode.at_edge else ""
    return (f"k_max = {mode.k_max:.4g}, wavelength 2 pi / k_max = {mode.wavelength:.4g}, "
            f"growth rate {mode.growth_rate:.4g} ({nature}; unstable band k in "
            f"[{mode.band[0]:.3g}, {mode.band[1]:.3g}]{edge})")


def _run_map(args, params, stem) -> int:
    from primordia.analysis.figures import patterning_figure
    from primordia.analysis.patterning import (
        ParameterRange,
        boundary_agreement,
        patterning_space,
        save_dataset,
    )

    if not args.x or not args.y:
        raise ConfigError("stability map needs --x NAME:LO:HI:N and --y NAME:LO:HI:N")
    if args.nk < 2:
        raise ConfigError(f"--nk must be >= 2, got {args.nk}")
    x, y = ParameterRange.parse(args.x), ParameterRange.parse(args.y)
    if args.critical is not None:
        params.declaration(args.critical)
    start = time.perf_counter()
    kind = "coupled" if args.coupled else "uncoupled"
    ds = patterning_space(x, y, params=params, coupled=args.coupled, nk=args.nk,
                          critical_parameter=args.critical, theta_variant=args.theta)
    print(f"primordia stability map: {x.name} x {y.name} ({x.n} x {y.n}), {kind}, parameters: {_describe(params)}")
    k = ds["k"].values
    print(f"  {k.size} wavenumbers in [{k.min():.3g}, {k.max():.3g}]")
    symbol = "d_0" if args.coupled else "a_0"
    agreement = boundary_agreement(ds)
    print(f"  Turing-unstable: {_percent(ds['unstable_numerical'])} of the grid from the eigenvalues, "
          f"{_percent(ds['unstable_conditions'])} from {symbol} < 0 (exact criterion), "
          f"{_percent(ds['seed_conditions'])} inside the seed's conditions")
    print(f"  eigenvalues vs {symbol} criterion: {agreement['disagree']} cells differ, "
          f"{agreement['off_boundary']} of them more than one cell from the {symbol} boundary")
    oscillatory = int(np.sum(ds["oscillatory_growth_rate"].values > 0))
    if oscillatory:
        peak = float(np.max(ds["oscillatory_growth_rate"].values))
        print(f"  oscillatory instability (complex roots, not Turing) in {oscillatory} cells, max Re phi {peak:.3g}")
    name = ds.attrs["critical_parameter"]
    if np.isfinite(ds.attrs["critical_value"]):
        k_c = ds.attrs["critical_wavenumber"]
        print(f"  critical {name} = {ds.attrs['critical_value']:.6g} (others fixed), k_c = {k_c:.4g}"
              + (f", wavelength {2 * np.pi / k_c:.4g}" if k_c > 0 else " (long-wave onset)"))
    else:
        print(f"  critical {name}: {ds.attrs['critical_note']}")
    out = _output_directory(args, stem, f"map_{x.name}_{y.name}_{kind}")
    netcdf = save_dataset(ds, out / f"patterning_{x.name}_{y.name}.nc")
    figure = out / f"patterning_{x.name}_{y.name}.png"
    patterning_figure(ds, figure)
    print(f"  wrote {netcdf} and {figure} ({time.perf_counter() - start:.1f} s)")
    return 0


def _percent(flag) -> str:
    return f"{100.0 * float(np.mean(flag.values)):.1f}%"
