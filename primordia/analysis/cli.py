"""The ``primordia stability`` command (linear stability analysis, seed section 3).

    primordia stability [CONFIG.toml] [--set section.key=value ...] [--uncoupled] [--chemistry-only] [--d 2|3]
                        [--domain L1,L2[,L3]] [--out DIR]
        the analysis of the model CONFIG composes (the one `primordia run CONFIG` runs), derived from its
        own equations: homogeneous steady state, fastest-growing mode (k_max, wavelength 2 pi / k_max),
        the dispersion curves as DIR/dispersion.nc + DIR/dispersion.png; for the seed's kinetics also
        the cross-check with the seed's hand-derived matrix and the verdicts of seed sections 3.2-3.6.
        On a box (the mesh's, or --domain) also the zero-flux cosine modes in the unstable band.
        A file without [model] (or none) is a parameter set of the seed's full model.

    primordia stability map [CONFIG.toml] --x NAME:LO:HI:N --y NAME:LO:HI:N [--coupled|--uncoupled]
                            [--chemistry-only] [--critical NAME] [--theta corrected|seed] [--nk N] [--set ...]
                            [--out DIR]
        the patterning space over two parameters of the seed's model, from the conditions and from the
        growth rates, as DIR/patterning_X_Y.nc + .png (seed Figures 3.1-3.3)

``register(subparsers)`` adds the command to the main ``primordia`` parser.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from primordia.core.errors import ConfigError
from primordia.core.validation import number

DEFAULT_OUT = Path("out") / "stability"
#: The map's defaults (its options are None unless given: outside the map they are a mistake).
DEFAULT_THETA, DEFAULT_NK = "corrected", 64


def register(subparsers) -> argparse.ArgumentParser:
    """Add the ``stability`` subcommand to an argparse ``subparsers`` object; sets ``func``."""
    parser = subparsers.add_parser(
        "stability",
        help="linear stability analysis: dispersion relation, k_max, patterning spaces (seed section 3)",
        description="\n\n".join(__doc__.split("\n\n")[1:3]),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("inputs", nargs="*", metavar="[map] [CONFIG.toml]",
                        help="'map' for a patterning space; a run configuration, or a file of [parameters]")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="override a config value, e.g. parameters.D_m=0.03 (repeatable)")
    coupling = parser.add_mutually_exclusive_group()
    coupling.add_argument("--coupled", dest="coupled", action="store_true", default=None,
                          help="the full poro-mechano-chemical loop (default: as the model is composed; "
                               "the seed's full model without a run configuration); a model without it is refused")
    coupling.add_argument("--uncoupled", dest="coupled", action="store_false",
                          help="drop the mechano-chemical loop (xi_f = 0, seed section 3.4)")
    parser.add_argument("--chemistry-only", action="store_true",
                        help="analyse the kinetics and the transport of its species alone, without the mechanics "
                             "(the only analysis of a finite-strain growth model)")
    parser.add_argument("--d", type=int, choices=(2, 3), default=None,
                        help="space dimension (default: the mesh's, else 2)")
    parser.add_argument("--domain", metavar="L1,L2[,L3]",
                        help="the box whose zero-flux modes are listed (default: the mesh's, if it is a box)")
    parser.add_argument("--out", help=f"output directory (default {DEFAULT_OUT}/...)")
    parser.add_argument("--x", metavar="NAME:LO:HI:N", help="map: first parameter axis")
    parser.add_argument("--y", metavar="NAME:LO:HI:N", help="map: second parameter axis")
    parser.add_argument("--critical", metavar="NAME",
                        help="map: parameter whose critical value gives panels 2-3 (default: the --x one)")
    parser.add_argument("--theta", choices=("corrected", "seed"), default=None,
                        help=f"map, coupled: theta_i of section 3.6 for the boundary curves (default {DEFAULT_THETA})")
    parser.add_argument("--nk", type=int, default=None,
                        help=f"map: number of wavenumbers searched (default {DEFAULT_NK})")
    parser.set_defaults(func=run)
    return parser


def run(args) -> int:
    """Entry point of ``primordia stability``; returns the exit code."""
    inputs = list(args.inputs)
    mapping = bool(inputs) and inputs[0] == "map"
    if mapping:
        inputs.pop(0)
    if len(inputs) > 1:
        raise ConfigError(f"stability takes at most one CONFIG.toml, got {' '.join(inputs)}")
    config = inputs[0] if inputs else None
    stem = Path(config).stem if config else None
    from primordia.core.outputs import directory_problem

    problem = directory_problem(args.out or DEFAULT_OUT)  # before the analysis, not after printing it
    if problem is not None:
        raise ConfigError(problem)
    if mapping:
        if args.domain:
            raise ConfigError("--domain applies to 'primordia stability' (the dispersion relation), not to map")
        return _run_map(args, config, stem)
    if args.x or args.y or args.critical or args.theta is not None or args.nk is not None:
        raise ConfigError("--x, --y, --critical, --theta and --nk apply to 'primordia stability map'")
    return _run_dispersion(args, config, stem)


def _compose(args, config):
    """(the model's linearisation, its parameters, the space dimension, its box) from the command line.

    The box: the side lengths the admissible modes are those of (``--domain``, else the
    model's mesh if it fills its bounding box), or a string saying why there are none.
    """
    from primordia.analysis.composed import linearise_model, linearise_seed
    from primordia.analysis.domain import box_lengths, parse_lengths
    from primordia.analysis.inputs import read_model, read_parameters

    model = read_model(config, args.overrides) if config is not None else None
    uncoupled = args.coupled is False
    if model is None:
        params = read_parameters(config, args.overrides)
        d = args.d or (len(args.domain.split(",")) if args.domain else 2)
        box = parse_lengths(args.domain, d) if args.domain else None
        return _closed_loop(args, linearise_seed(params, args.chemistry_only, uncoupled)), params, d, box
    linear = _closed_loop(args, linearise_model(model, args.chemistry_only, uncoupled))
    gdim = model.mesh_data.points.shape[1]
    d = args.d or gdim
    if args.domain:
        box = parse_lengths(args.domain, d)
    elif any(module.finite_strain for module in model.physics_objects):
        box = "the tissue grows, and its modes with it"
    elif d != gdim:
        box = f"the mesh is {gdim}D; --domain {','.join(f'L{i}' for i in range(1, d + 1))} gives a box"
    else:
        box = box_lengths(model.mesh_data) or "the mesh does not fill its bounding box; --domain gives a box"
    return linear, model.parameters, d, box


def _closed_loop(args, linear):
    """``linear``, or one line when ``--coupled`` asks for a loop it does not close: the analysis of the model as
    composed was printed under the flag without a word (ex01a's chemistry alone), as the map once labelled it."""
    if args.coupled and not linear.coupled:
        reason = "--chemistry-only leaves the mechanics out" if args.chemistry_only else (
            f"the model {linear.name} has no closed mechano-chemical loop (the FGF sink mechanochemical and "
            f"active_stress, with poroelasticity)")
        raise ConfigError(f"--coupled: {reason}; drop --coupled")
    return linear


def _output_directory(args, *parts) -> Path:
    if args.out:
        return Path(args.out)
    return DEFAULT_OUT.joinpath(*[p for p in parts if p])


def _describe(params, defaults: str = "Table 3.1") -> str:
    changed = [f"{name}={params[name]:g}" for name in params
               if params[name] != params.declaration(name).default]
    return defaults + (f" with {', '.join(changed)}" if changed else "")


def _run_dispersion(args, config, stem) -> int:
    from primordia.analysis.composed import seed_cross_check
    from primordia.analysis.domain import domain_modes, with_domain_modes
    from primordia.analysis.figures import dispersion_figure
    from primordia.analysis.patterning import model_dispersion_relation, save_dataset

    start = time.perf_counter()
    linear, params, d, box = _compose(args, config)
    print(f"primordia stability: {linear.name or 'model'}: {linear.describe()}; d = {d}")
    defaults = "Table 3.1" if linear.kinetics == "painter2018" else f"the defaults of {linear.kinetics}"
    print(f"  parameters: {_describe(params, defaults)}")
    for note in linear.notes:
        print(f"  {note}")
    rest = linear.steady_state
    held = f" ({', '.join(rest.conserved)} conserved, held at the initial value)" if rest.conserved else ""
    print(f"  homogeneous steady state: {rest}{held}")
    print(f"  fastest-growing mode: {_mode_text(linear.fastest_mode())}")
    turing = linear.fastest_mode("stationary")
    print(f"  fastest stationary (Turing) mode: {_mode_text(turing)}")
    modes = None
    if isinstance(box, tuple):
        try:
            modes = domain_modes(linear.rates, box, turing.band)
        except ConfigError as dense:  # a box far larger than the wavelengths: the continuous analysis says it all
            box = str(dense)
        else:
            walls = "; with mechanics, exact for slip walls only" if linear.mechanics is not None else ""
            print(f"  {modes.describe()}{walls}")
            fastest = linear.fastest_mode()
            if fastest.unstable and not fastest.stationary:  # the box's say on it too: its wavelength may not fit
                try:
                    print(f"  {domain_modes(linear.rates, box, fastest.band, kind='oscillatory').describe()}")
                except ConfigError as dense:  # as for the stationary ones: said, and the files still written
                    print(f"  admissible oscillatory modes: none listed ({dense})")
    if isinstance(box, str):
        print(f"  admissible modes: none listed ({box})")
    difference = seed_cross_check(linear, d=d)
    if difference is not None:
        print(f"  cross-check: the seed's hand-derived M(phi, k) (Definition 3.1, corrected) equals the derived one "
              f"to {difference:.1e} (relative)")
        for verdict in _seed_verdicts(linear, params):
            print(f"  {verdict}")
    ds = model_dispersion_relation(linear, d=d)
    if modes is not None:
        ds = with_domain_modes(ds, modes)
    out = _output_directory(args, stem)
    netcdf = save_dataset(ds, out / "dispersion.nc")
    figure = out / "dispersion.png"
    dispersion_figure(ds, figure)
    print(f"  wrote {netcdf} and {figure} ({time.perf_counter() - start:.1f} s)")
    return 0


def _seed_verdicts(linear, params) -> list:
    """The verdicts of seed sections 3.2-3.6 where the seed's model is the one analysed (hand-derived)."""
    from primordia.analysis.composed import SEED_PHYSICS, seed_values
    from primordia.analysis.conditions import uncoupled_verdict, verdicts

    values = seed_values(params)
    if linear.mechanics is None:
        return [uncoupled_verdict(values)]
    if set(linear.physics) == set(SEED_PHYSICS):
        return verdicts(values if linear.coupled else values.replace(xi_f=0.0))
    return []


def _mode_text(mode) -> str:
    if not np.isfinite(mode.growth_rate):
        return f"none: no {mode.kind} root at any k searched"
    if not mode.unstable:
        return f"none grows (largest Re phi {mode.growth_rate:.3g} at k = {mode.k_max:.3g})"
    nature = "stationary" if mode.stationary else f"oscillatory, frequency {mode.frequency:.4g}"
    edge = "; at the end of the k range searched" if mode.at_edge else ""
    if mode.k_max == 0:
        where = "k_max = 0: the well-mixed kinetics are unstable on their own (homogeneous, not a pattern)"
    else:
        where = f"k_max = {mode.k_max:.4g}, wavelength 2 pi / k_max = {mode.wavelength:.4g}"
    return (f"{where}, "
            f"growth rate {mode.growth_rate:.4g} ({nature}; unstable band k in "
            f"[{mode.band[0]:.3g}, {mode.band[1]:.3g}]{edge})")


def _run_map(args, config, stem) -> int:
    from primordia.analysis.figures import patterning_figure
    from primordia.analysis.patterning import (
        ParameterRange,
        boundary_agreement,
        patterning_space,
        save_dataset,
    )

    if not args.x or not args.y:
        raise ConfigError("stability map needs --x NAME:LO:HI:N and --y NAME:LO:HI:N")
    nk = number(DEFAULT_NK if args.nk is None else args.nk, "--nk", integer=True, at_least=2)
    params, coupled = _seed_map_parameters(args, config)
    x, y = ParameterRange.parse(args.x), ParameterRange.parse(args.y)
    if args.critical is not None:
        params.declaration(args.critical)
    start = time.perf_counter()
    kind = "coupled" if coupled else "uncoupled"
    ds = patterning_space(x, y, params=params, coupled=coupled, nk=nk,
                          critical_parameter=args.critical, theta_variant=args.theta or DEFAULT_THETA)
    print(f"primordia stability map: {x.name} x {y.name} ({x.n} x {y.n}), {kind}, seed's model, "
          f"parameters: {_describe(params)}")
    k = ds["k"].values
    print(f"  {k.size} wavenumbers in [{k.min():.3g}, {k.max():.3g}]")
    symbol = "d_0" if coupled else "a_0"
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


def _seed_map_parameters(args, config):
    """(seed parameters, coupled?) of a map: the seed's model, coupled as the config's model is (or --coupled)."""
    from primordia.analysis.composed import linearise_model, seed_model_values
    from primordia.analysis.inputs import read_model, read_parameters

    model = read_model(config, args.overrides) if config is not None else None
    if model is None:
        return read_parameters(config, args.overrides), args.coupled is not False
    linear = linearise_model(model, args.chemistry_only, args.coupled is False)
    if linear.kinetics != "painter2018":
        raise ConfigError(f"stability map draws patterning spaces of the seed's model (kinetics painter2018); "
                          f"{config} uses kinetics {linear.kinetics}: primordia stability {config} analyses it")
    values, coupled = seed_model_values(linear)  # a coupling the model lacks is 0, not Table 3.1's value
    if args.coupled and not coupled:  # its couplings are 0: a "coupled" map would be the uncoupled one, mislabelled
        raise ConfigError(f"--coupled: the model of {config} has no closed mechano-chemical loop (the FGF sink "
                          f"mechanochemical and active_stress); drop --coupled, or give no config to map the "
                          f"seed's coupled model with Table 3.1")
    return values, coupled if args.coupled is None else args.coupled


def _percent(flag) -> str:
    return f"{100.0 * float(np.mean(flag.values)):.1f}%"
