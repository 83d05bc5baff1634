"""The ``primordia`` command.

    primordia [-p PLUGIN ...] COMMAND ...     (a plugin not installed: a module name or a .py file)
    primordia run CONFIG.toml [--backend NAME] [--out DIR] [--set section.key=value ...] [--overwrite]
    primordia run --restart OUT_DIR [--set time.t_final=...]
    primordia plugins
    primordia stability [CONFIG.toml] [--set ...] [--out DIR]
    primordia stability map --x NAME:LO:HI:N --y NAME:LO:HI:N [--coupled|--uncoupled]
    primordia analyse RUN_DIR
    primordia sweep CONFIG.toml --vary SECTION.KEY=LO:HI:N ... [--seeds N] [--scheduler ADDRESS]

A user's mistake (unknown parameter, wrong sign, missing file, impossible mesh,
unknown backend or plugin, a system package not installed: petsc4py, mpi4py, h5py) is printed as one line
``primordia: error: ...`` and exits with status 2; outputs already written stay on disk.  Ctrl-C, SIGTERM and
SIGUSR1 (what to send ``mpirun``) stop a run between two steps with a checkpoint
(exit status 128 + the signal: 130, 143, 138); ``--restart OUT_DIR`` continues it in place.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import traceback
from pathlib import Path

from primordia.core import compiled
from primordia.core.errors import (ConfigError, InterruptedRun, PluginError, PrimordiaError, is_root_process,
                                   missing_system_package, mpi_world)
from primordia.core.signals import HANDLED, INTERRUPTS, signal_name

EXIT_USAGE = 2
#: How long a rank that stops on an error waits for the other ranks to stop on it too, under mpirun, before it
#: takes itself for the only one (a plugin that failed on one rank) and aborts the job: errors are decided alike
#: on every rank, so the others come within moments (see _stop_together).
ERROR_PATIENCE_S = 60.0
#: 128 + SIGPIPE, as a shell reports a reader that stopped reading (`primordia plugins | head`).
EXIT_BROKEN_PIPE = 141


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own usage errors: one line and status 2, as any bad input
        raise ConfigError(message)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="primordia", description=__doc__.split("\n\n")[0].replace("``", ""))
    parser.add_argument("--version", action="version", version=f"primordia {_version()}")
    parser.add_argument("-p", "--plugin", dest="plugins", action="append", default=[], metavar="MODULE_OR_FILE",
                        help="load a plugin that is not installed: a module name or a .py file (repeatable; "
                             "added to PRIMORDIA_PLUGINS, so a sweep's runs load it too)")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = commands.add_parser("run", help="run a model from a TOML configuration")
    run.add_argument("config", nargs="?", help="TOML configuration file (with --restart: the run's own, if given)")
    run.add_argument("--backend", help="finite element backend (default: [model] backend, else fenicsx)")
    run.add_argument("--out", help="output directory (default: out/<config name>)")
    run.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                     help="override a config value, e.g. --set parameters.D_m=0.03 (repeatable; an inline "
                          "table {k=v} adds to the table it names)")
    run.add_argument("--restart", metavar="OUT_DIR",
                     help="continue the run in OUT_DIR from its checkpoint, in place (--set may change "
                          "time.t_final, time.adaptive, time.dt_min, output, checkpoint and solver options)")
    run.add_argument("--overwrite", action="store_true",
                     help="replace the run already in the output directory (otherwise it is refused)")
    run.add_argument("--dry-run", action="store_true", help="check the input (config, mesh, formulas) and stop")
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
    from primordia.core import config as config_
    from primordia.model import Model

    if args.restart is not None and args.overwrite:
        raise ConfigError("--restart continues the run in its directory, --overwrite replaces it: choose one")
    if args.restart is not None and args.out is not None and Path(args.out) != Path(args.restart):
        raise ConfigError(f"--restart {args.restart} continues the run in place; --out {args.out} names another "
                          f"directory")
    if args.config is None and args.restart is None:
        raise ConfigError("run needs a config file, CONFIG.toml (or --restart OUT_DIR)")
    compiled.mode()  # a wrong PRIMORDIA_COMPILED stops the run before it starts
    if args.restart is not None and not args.restart.strip():
        raise ConfigError("--restart needs the output directory of the run to continue")
    overrides = list(args.overrides)
    if args.backend is not None:
        if not args.backend.strip():
            raise ConfigError("--backend needs a name (registered backends: see primordia plugins)")
        overrides.append(f"model.backend={args.backend}")
    restart = Path(args.restart) if args.restart is not None else None
    with _start_up_of_a_restart(restart, args.dry_run):  # from the checkpoint's reading to the restart's first step
        if restart is not None:
            out = restart
            config = config_.load_config(args.config) if args.config is not None else _checkpointed_config(out)
            try:
                model = Model.from_config(config_.apply_overrides(config, overrides))
            except PluginError as error:  # e.g. the run's kinetics came from a file given by -p, not given now
                raise PluginError(f"{error}{_plugins_of_the_run(out)}") from None
        else:
            model = Model.from_file(args.config, overrides)
            out = Path(args.out) if args.out is not None else Path("out") / Path(args.config).stem
            if not str(args.out if args.out is not None else out).strip():
                raise ConfigError("--out needs a directory name")
        if args.dry_run:
            existing = "restart" if restart is not None else "overwrite" if args.overwrite else "refuse"
            return _report_dry_run(model, out, existing)
        _warn_about_a_slow_blas()
        sim = model.run(out=out, progress=not args.no_progress, overwrite=args.overwrite,
                        restart=restart is not None, continue_with=f"primordia run --restart {out}")
    final = sim.summary(sim.status)  # collective (reductions over ranks): every rank calls it
    if sim.is_root:
        restarted = f" (restart {sim.restarts})" if sim.restarts else ""
        rejected = f", {final['rejected_steps']} rejected and retried" if final["rejected_steps"] else ""
        print(f"primordia: {sim.status}{restarted}: {sim.step_index} steps{rejected} on {final['backend']} "
              f"({final['cells']} cells, {final['dofs_total']} dofs) in {sim.wall_time:.1f} s -> {out}")
    return 0


@contextlib.contextmanager
def _start_up_of_a_restart(out: Path | None, dry_run: bool = False):
    """A signal before the first step of a restart (of the run in ``out``; None: not a restart) is said as the
    restart's, with how the run goes on: its checkpoint is as it was.  It was said as a new run's, "interrupted
    (SIGTERM) during start-up, before the first step", of a run at t = 400 whose summary.json said where it was."""
    try:
        yield
    except KeyboardInterrupt as interrupted:
        if out is None or dry_run or str(interrupted):  # a run that stepped says where it stopped itself
            raise
        import signal

        from primordia.core.outputs import continued_from_checkpoint

        signum = getattr(interrupted, "signum", None) or INTERRUPTS.received or signal.SIGINT
        how = continued_from_checkpoint(out, f"primordia run --restart {out}")
        how = f"; {how}" if how is not None else ""
        raise InterruptedRun(signum, f"interrupted ({signal_name(signum)}) during the restart's start-up, before "
                                     f"its first step{how}") from None


def _write_line(line: str) -> None:
    """``line`` and its newline to stderr in one write, flushed: ``print`` writes them apart, and under mpirun the
    abort's banner, forwarded between the two, ended the error line ("...flaky_kinetics.py:20)-----")."""
    sys.stderr.write(f"{line}\n")
    sys.stderr.flush()


def _warn_about_a_slow_blas() -> None:
    """One line on stderr when PETSc runs on the reference BLAS (:mod:`primordia.core.blas`); the run goes on."""
    try:
        from petsc4py import PETSc  # noqa: F401  (maps PETSc's BLAS into the process)
    except ImportError:
        return
    from primordia.core.blas import reference_blas_warning

    warning = reference_blas_warning()
    if warning is not None and is_root_process():
        print(f"primordia: warning: {warning}", file=sys.stderr)


def _plugins_of_the_run(out: Path) -> str:
    """A hint naming the plugins the checkpointed run in ``out`` loaded and this process did not: by ``-p``, or
    installed (a distribution uninstalled since, or a venv without it: "unknown kinetics" said nothing more)."""
    from primordia.core import checkpoint
    from primordia.core.plugins import PLUGINS_VARIABLE, get_plugin_manager

    try:
        meta = checkpoint.read_meta(out / checkpoint.CHECKPOINT_FILE)
    except PrimordiaError:
        return ""
    named = meta.get("named_plugins") or ""
    loaded = os.environ.get(PLUGINS_VARIABLE, "").split(",")
    missing = [item for item in named.split(",") if item and item not in loaded]
    if missing:
        return (f" (the run loaded {', '.join(missing)} with -p: give it again, primordia -p {missing[0]} run "
                f"--restart {out})")
    sources = get_plugin_manager().load_report.sources  # the -p ones among them are all loaded again (above)
    plugins = (meta.get("software") or {}).get("plugins") or {}
    gone = [f"{plugin} from {origin}" for plugin, origin in plugins.items() if plugin not in sources]
    return f" (the run was made with the plugin {', '.join(gone)}, not installed here)" if gone else ""


def _checkpointed_config(out: Path) -> dict:
    """The configuration of the run whose checkpoint is in ``out``."""
    from primordia.core import checkpoint
    from primordia.core.outputs import existing_run

    path = out / checkpoint.CHECKPOINT_FILE
    if not path.is_file():
        found = existing_run(out)
        raise ConfigError(f"{out} holds no checkpoint to restart from" + (f" ({found})" if found else
                                                                          " (it holds no run)"))
    tree = checkpoint.read_meta(path)
    config = tree["config"]
    if tree.get("output_times_default"):  # [t_final] by default: at the t_final of this restart, unless --set
        config["output"].pop("times", None)
    return config


def _report_dry_run(model, out: Path, existing: str) -> int:
    """Check what the run would, as far as its forms (``existing``: what the run does with a run already in
    ``out``, as :class:`~primordia.coupling.orchestrator.Simulation` takes it), and say so in one line."""
    from primordia.core.outputs import directory_problem, existing_run
    from primordia.coupling.orchestrator import Simulation
    from primordia.coupling.solver_options import check_table_values

    problem = directory_problem(out)
    if problem is not None:
        raise ConfigError(problem)
    sim = Simulation(model, backend=model.backend, out_dir=out, existing=existing)
    sim.check_choices()  # backend, scheme
    sim.check_forms()  # what the modules state to each other: a term added to a law that reads none
    check_table_values(model.solver)
    model.warn_about_inert_settings()  # once the input passed: a refused one is one line
    found = existing_run(out)
    replaced = ", which --overwrite replaces" if existing == "overwrite" else ""
    if is_root_process():
        print(f"primordia: the input is valid: {model.mesh_data.num_cells} cells, {model.num_steps} steps of "
              f"dt = {model.dt:g} to t = {model.t_final:g} on {model.backend}"
              + (f"; {out} already holds {found}{replaced}" if found else "") + "; nothing was run")
    return 0


def command_plugins(args) -> int:
    from primordia.core.plugins import (CHOOSING_HOOKS, HOOK_BY_KIND, ask_backend_choosers, choosers,
                                        get_plugin_manager, registry)

    pm = get_plugin_manager()
    for kind in HOOK_BY_KIND:
        table = registry(kind, pm)
        print(f"{kind}:")
        for name, (piece, origin) in sorted(table.items()):
            note = ""
            if kind == "backends":
                reason = piece.availability()
                note = "  [available]" if reason is None else f"  [unavailable: {reason}]"
            print(f"  {name:<22} {origin}{note}")
    ask_backend_choosers(pm)  # a chooser that breaks is listed below, not found at the next run
    print("choosers:")
    for hook, asked in choosers(pm).items():
        order = ", then ".join(f"{plugin} [{origin}]" if origin != plugin else plugin for plugin, origin in asked)
        print(f"  {hook:<34} {CHOOSING_HOOKS[hook]}, asking {order or 'nobody'}")
    _print_linear_algebra()
    if pm.load_report.broken:
        print("broken:")
        for plugin, problems in pm.load_report.broken.items():
            origin = pm.load_report.sources.get(plugin, "")
            print(f"  {plugin:<22} {origin + '  ' if origin else ''}[{'; '.join(problems)}]")
    return 0


def _print_linear_algebra() -> None:
    """PETSc's version and the BLAS it runs on (:mod:`primordia.core.blas`)."""
    from primordia.core.blas import reference_blas_warning, system_blas

    print("linear algebra:")
    try:
        from petsc4py import PETSc
    except ImportError as exc:
        print(f"  {'PETSc':<22} [unavailable: {exc}]")
        return
    print(f"  {'PETSc':<22} {'.'.join(str(part) for part in PETSc.Sys.getVersion())}")
    libraries = system_blas()
    for library in libraries:
        print(f"  {'BLAS':<22} {library.describe()}")
    if not libraries:
        print(f"  {'BLAS':<22} [not found among the process's mapped libraries]")
    warning = reference_blas_warning(libraries)
    if warning is not None:
        print(f"  warning: {warning}")
    print(f"  {'compiled loops':<22} {compiled.status().removeprefix('compiled loops: ')}")


def console() -> None:
    """The ``primordia`` console script (and ``python -m primordia``): :func:`main`, and its status as the exit
    status.  An interrupted command leaves the signals it handles ignored until the process ends: everything is
    written, and a late copy (mpirun forwards a SIGTERM a second after the batch system's) changes nothing."""
    sys.exit(main(_until_exit=True))


def main(argv: list[str] | None = None, *, _until_exit: bool = False) -> int:
    """The ``primordia`` command with arguments ``argv`` (default: the process's); returns its exit status.

    Called from Python, it leaves the signal handlers as it found them: an interrupted command ignored Ctrl-C for
    the rest of the session (a notebook could no longer be interrupted)."""
    import signal
    import threading

    before = {signum: signal.getsignal(signum) for signum in HANDLED}
    try:
        return _command(argv)
    finally:
        if not _until_exit and threading.current_thread() is threading.main_thread():
            for signum, handler in before.items():
                if handler is not None:  # None: a handler not installed from Python, which cannot be put back
                    signal.signal(signum, handler)


def _command(argv: list[str] | None) -> int:
    with INTERRUPTS.installed():  # SIGTERM, like Ctrl-C, stops the program with a word, from the very start
        try:
            parser = build_parser()
            args = parser.parse_args(argv)
            restart = getattr(args, "restart", None)  # its start-up begins here, with PETSc's and MPI's (0.5 s)
            restart = Path(restart) if restart is not None else None
            with _start_up_of_a_restart(restart, getattr(args, "dry_run", False)):
                _refuse_an_unwritable_tmpdir()
                _broken_pipes_raise()
                _refuse_ranks_for_a_serial_command(args.command)
                _errors_comm()
                _name_plugins(args.plugins)
            return args.func(args)
        except BrokenPipeError:  # `primordia plugins | head`: the reader has all it wanted
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nothing more to flush at exit
            return EXIT_BROKEN_PIPE
        except KeyboardInterrupt as interrupted:
            return _interrupted(interrupted)
        except (PrimordiaError, ModuleNotFoundError) as exc:
            if INTERRUPTS.received:  # a signal that came back as a failed solve or an unreadable file
                return _interrupted(InterruptedRun(INTERRUPTS.received))
            error = exc if isinstance(exc, PrimordiaError) else missing_system_package(exc)
            if error is None:  # a module primordia's own dependencies should have brought: a bug
                _abort_other_ranks(exc)
                raise
            line = f"primordia: error: {(str(error).splitlines() or [''])[0]}"
            if is_root_process():
                _write_line(line)
            if error is exc or "mpi4py.MPI" in sys.modules:  # without mpi4py the ranks cannot agree: each stops
                _stop_together(line)
            return EXIT_USAGE
        except Exception as exc:
            if INTERRUPTS.received:
                return _interrupted(InterruptedRun(INTERRUPTS.received))
            _abort_other_ranks(exc)
            raise


def _refuse_an_unwritable_tmpdir() -> None:
    """One line when ``TMPDIR`` names a folder that cannot be written, before MPI starts (dolfinx and petsc4py
    start it on import): Open MPI keeps its session files there, and a read-only one (or a file) gave some 50
    lines of its banners and MPI_Init_thread's abort, for any command.  A missing one Open MPI makes, so the
    nearest folder that exists is probed instead (one under a file, or in a read-only tree, gave the same
    banners).  (Under ``mpirun``, mpirun itself says it first.)"""
    folder = os.environ.get("TMPDIR")
    if not folder:
        return
    from primordia.core.atomic_files import nearest_existing, reason_of, refusal_to_write

    existing = str(nearest_existing(folder))  # missing: Open MPI makes it, in the nearest folder that exists

    refusal = refusal_to_write(existing)
    if refusal is not None:
        where = "" if existing == os.path.abspath(folder) else f"{existing}: "
        raise ConfigError(f"TMPDIR {folder} cannot be written ({where}{reason_of(refusal)}): MPI keeps its session "
                          f"files there; set TMPDIR to a writable folder")


def _refuse_ranks_for_a_serial_command(command: str) -> None:
    """Only ``run`` shares its work over MPI ranks: any other command ran whole on every rank of an ``mpirun``
    (its report printed once per rank, interleaved, and its files written by every rank at once)."""
    ranks = mpi_world()[1]
    if command != "run" and ranks > 1:
        raise ConfigError(f"primordia {command} is serial: run it without mpirun (only primordia run uses "
                          f"several ranks; this is one of {ranks})")


def _name_plugins(plugins: list[str]) -> None:
    """Add ``-p`` plugins to ``PRIMORDIA_PLUGINS`` (read when the plugin manager is built; inherited by the
    processes a sweep starts)."""
    if not plugins:
        return
    from primordia.core import plugins as plugins_

    if any(not item.strip() or "," in item for item in plugins):
        raise ConfigError("-p needs one module name or .py file each time (no commas)")
    named = [str(Path(item.strip()).resolve()) if plugins_.names_a_file(item.strip()) else item.strip()
             for item in plugins]  # a file by its absolute path: a sweep's runs start in other directories
    os.environ[plugins_.PLUGINS_VARIABLE] = ",".join(plugins_.named_plugins() + named)
    plugins_.get_plugin_manager(reload=True)


def _broken_pipes_raise() -> None:
    """Python's own SIGPIPE disposition (ignored, so a write to a closed pipe raises BrokenPipeError) again.

    PETSc's initialisation installs its error handler for SIGPIPE, which turned `primordia plugins | head`
    into "PETSC ERROR: Caught signal number 13 Broken Pipe" and an MPI_ABORT. PETSc is initialised
    here, before any output, so that its handler is in place to be replaced.
    """
    import signal

    try:
        from petsc4py import PETSc  # noqa: F401  (initialises PETSc, which installs its signal handlers)
    except ImportError:
        return
    signal.signal(signal.SIGPIPE, signal.SIG_IGN)


def _interrupted(interrupted: KeyboardInterrupt) -> int:
    """One line saying the program was interrupted (and where, for a run), and the exit status 128 + signal."""
    import signal

    signum = getattr(interrupted, "signum", None) or INTERRUPTS.received or signal.SIGINT
    detail = str(interrupted) or f"interrupted ({signal_name(signum)}) during start-up, before the first step"
    if is_root_process():
        print(f"primordia: {detail}", file=sys.stderr)
    for handled in HANDLED:  # everything is written: a late second signal changes nothing
        signal.signal(handled, signal.SIG_IGN)
    return 128 + signum


_ERRORS_COMM = []  # under mpirun: a duplicate of the world on which the ranks agree that they stop (_stop_together)


def _errors_comm():
    """The communicator of :func:`_stop_together`, made at the start on every rank (None in serial)."""
    if not _ERRORS_COMM and mpi_world()[1] > 1:
        from mpi4py import MPI

        _ERRORS_COMM.append(MPI.COMM_WORLD.Dup())
    return _ERRORS_COMM[0] if _ERRORS_COMM else None


def _stop_together(line: str) -> None:
    """Return once every rank stops on an error, as they do on an error decided alike on every rank.

    An error met by one rank alone (a plugin that fails on rank 1 only, where its file or data differ) leaves
    the other ranks waiting for it in a collective call, and this rank then waited for them in MPI_Finalize:
    ``mpirun -n 2`` with kinetics that raised on rank 1 printed nothing and hung until ``timeout 120`` killed it.
    The ranks agree without blocking, on a communicator of their own; after ``ERROR_PATIENCE_S`` this rank
    prints ``line`` (rank 0, which prints, may be one of those waiting) and aborts the job, exit status 2.
    """
    from primordia.core.reductions import every_rank_stops

    comm = _errors_comm()
    if comm is None or every_rank_stops(comm, ERROR_PATIENCE_S):
        return
    if not is_root_process():
        _write_line(line)
    sys.stderr.flush()
    from mpi4py import MPI

    MPI.COMM_WORLD.Abort(EXIT_USAGE)


def _abort_other_ranks(exc: Exception) -> None:
    """A bug raised on one MPI rank: print it and abort the job, so that no other rank waits for it forever."""
    mpi = sys.modules.get("mpi4py.MPI")
    if mpi is None or mpi.COMM_WORLD.size == 1:
        return
    traceback.print_exception(exc)
    sys.stderr.flush()
    mpi.COMM_WORLD.Abort(1)


if __name__ == "__main__":
    sys.exit(main())
