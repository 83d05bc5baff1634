"""The ``primordia`` command.

    primordia run CONFIG.toml [--backend NAME] [--out DIR] [--set section.key=value ...]
    primordia plugins
    primordia stability [CONFIG.toml] [--set ...] [--out DIR]
    primordia stability map --x NAME:LO:HI:N --y NAME:LO:HI:N [--coupled|--uncoupled]
    primordia analyse RUN_DIR
    primordia sweep CONFIG.toml --vary SECTION.KEY=LO:HI:N ... [--seeds N] [--scheduler ADDRESS]

A user's mistake (unknown parameter, wrong sign, missing file, impossible mesh,
unknown backend or plugin) is printed as one line ``primordia: error: ...`` and
exits with status 2; outputs already written stay on disk.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from primordia.core.errors import PrimordiaError

EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own usage errors: one line, status 2
        print(f"primordia: error: {message}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="primordia", description=__doc__.split("\n\n")[0])
    parser.add_argument("--version", action="version", version=f"primordia {_version()}")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = commands.add_parser("run", help="run a model from a TOML configuration")
    run.add_argument("config", help="TOML configuration file")
    run.add_argument("--backend", help="finite element backend (default: [model] backend, else fenicsx)")
    run.add_argument("--out", help="output directory (default: out/<config name>)")
    run.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                     help="override a config value, e.g. --set parameters.D_m=0.03 (repeatable)")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.set_defaults(func=command_run)

    plugins = commands.add_parser("plugins", help="list every registered piece and where it came from")
    plugins.set_defaults(func=command_plugins)

    try:
        from primordia.analysis.cli import register
    except ImportError:
        register = None
    if register is not None:
        register(commands)
    from primordia.analysis.patterns.cli import register as register_analyse
    from primordia.sweep import register as register_sweep

    register_analyse(commands)
    register_sweep(commands)
    return parser


def _version() -> str:
    from primordia import __version__

    return __version__


def command_run(args) -> int:
    from primordia.model import Model

    overrides = list(args.overrides)
    if args.backend:
        overrides.append(f"model.backend={args.backend}")
    model = Model.from_file(args.config, overrides)
    out = Path(args.out) if args.out else Path("out") / Path(args.config).stem
    sim = model.run(out=out, progress=not args.no_progress)
    final = sim.summary(sim.status)  # collective (reductions over ranks): every rank calls it
    if sim.is_root:
        print(f"primordia: {sim.status}: {sim.step_index} steps on {final['backend']} "
              f"({final['cells']} cells, {final['dofs_total']} dofs) in {sim.wall_time:.1f} s -> {out}")
    return 0


def command_plugins(args) -> int:
    from primordia.core.plugins import KINDS, get_plugin_manager, registry

    pm = get_plugin_manager()
    for kind in KINDS:
        table = registry(kind, pm)
        print(f"{kind}:")
        for name, (piece, origin) in sorted(table.items()):
            note = ""
            if kind == "backends":
                reason = piece.availability()
                note = "  [available]" if reason is None else f"  [unavailable: {reason}]"
            print(f"  {name:<22} {origin}{note}")
    for failure in pm.load_report.failures:
        print(f"failed: {failure}")
    return 0


def _is_root() -> bool:
    """Whether this is MPI rank 0 (errors are printed once, not once per rank)."""
    if "mpi4py.MPI" in sys.modules:
        return sys.modules["mpi4py.MPI"].COMM_WORLD.rank == 0
    rank = os.environ.get("OMPI_COMM_WORLD_RANK") or os.environ.get("PMI_RANK") or "0"
    return rank == "0"


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except PrimordiaError as exc:
        if _is_root():
            print(f"primordia: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("primordia: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
