"""Errors that reach the user as one line.

Every mistake a user can make (an unknown parameter, a wrong sign, a missing
file, an impossible mesh, an unknown backend or plugin) raises a subclass of
:class:`PrimordiaError`.  The CLI prints ``primordia: error: <message>`` and
exits with status 2; anything else is a bug and keeps its traceback.  A run
stopped by a signal raises :class:`InterruptedRun` (a ``KeyboardInterrupt``):
it is reported as interrupted, never as a mistake in the input.
"""

import contextlib
import logging
import os
import sys
import traceback


class PrimordiaError(Exception):
    """A problem with the user's input, stated in one line."""


class ConfigError(PrimordiaError):
    """A configuration value, section or parameter is unknown or invalid."""


class MeshError(PrimordiaError):
    """A mesh cannot be built or read."""


class PluginError(PrimordiaError):
    """A named backend, physics, kinetics, scheme or output is not registered."""


def one_line(error: BaseException, named: bool = True) -> str:
    """An exception in one line: its type (unless ``named`` is false) and message, a message of several lines
    (pluggy's) joined; the type alone when there is no message."""
    text = f"{type(error).__name__}: {error}" if named else str(error)
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return "; ".join(lines) or type(error).__name__


@contextlib.contextmanager
def plugin_code(what: str, passes: tuple[type[BaseException], ...] = (PrimordiaError,), source: type | None = None):
    """Run a plugin's code: an exception other than ``passes`` (a bug of the plugin) becomes one line,
    ``PluginError("<what>: <the exception in one line>")``, its traceback kept as the cause.

    ``source``: the plugin's class; the line then ends with the last place in the plugin's own
    files the exception passed through (``(at FILE:LINE)``), which the one line would otherwise hide.
    UFL, which logs each error it raises to stdout before raising it, is kept from printing a second line.
    """
    ufl_log = logging.getLogger("UFL")
    outermost = _below_error not in ufl_log.filters  # plugin code may run plugin code: the outermost removes it
    ufl_log.addFilter(_below_error)
    try:
        yield
    except passes:
        raise
    except Exception as error:  # noqa: BLE001 - the plugin's own bug, stated in one line
        raise PluginError(f"{what}: {one_line(error)}{place_in(error, source)}") from error
    finally:
        if outermost:
            ufl_log.removeFilter(_below_error)


def _below_error(record: logging.LogRecord) -> bool:
    return record.levelno < logging.ERROR


def is_third_party(source) -> bool:
    """Whether ``source`` (a class, a function) is a plugin's, not defined in ``primordia.``."""
    return not getattr(source, "__module__", "").startswith("primordia.")


def third_party_code(what: str, source, passes: tuple[type[BaseException], ...] = (PrimordiaError,)):
    """:func:`plugin_code` for code that may be primordia's own or a plugin's (a physics module's method, a term
    it contributes): a plugin's bug is one line; primordia's own (:func:`is_third_party` false) keeps its
    traceback, since it is primordia's bug."""
    if not is_third_party(source):
        return contextlib.nullcontext()
    return plugin_code(what, passes, source=source)


def place_in(error: BaseException, source: type | None) -> str:
    """`` (at FILE:LINE)``: the innermost frame of ``error``'s traceback in the files of ``source``'s top-level
    package (or module), or "" when it passed through none of them."""
    top = sys.modules.get(getattr(source, "__module__", "").partition(".")[0])
    file = getattr(top, "__file__", None)
    if not file:
        return ""
    root = os.path.dirname(file) if os.path.basename(file) == "__init__.py" else file
    places = [(frame.f_code.co_filename, line) for frame, line in traceback.walk_tb(error.__traceback__)
              if frame.f_code.co_filename == root or frame.f_code.co_filename.startswith(root + os.sep)]
    return f" (at {places[-1][0]}:{places[-1][1]})" if places else ""


#: What primordia imports that pip does not install (``pyproject.toml`` declares none of them): built against the
#: system's PETSc, MPI and HDF5, the ones dolfinx links (Debian's python3-dolfinx and python3-h5py-mpi, in a venv
#: made with ``--system-site-packages``; README, "Backends").  pip's h5py wheel carries an HDF5 of its own, which
#: fails beside dolfinx's in one process ("Not a datatype"), so h5py is not declared either.
SYSTEM_PACKAGES = ("dolfinx", "basix", "petsc4py", "mpi4py", "h5py")


def missing_system_package(error: BaseException) -> PrimordiaError | None:
    """The one line for a :data:`SYSTEM_PACKAGES` package that cannot be imported (``error`` a
    ``ModuleNotFoundError``), or ``None`` for any other error: an installation to complete, not a bug."""
    name = (getattr(error, "name", None) or "").partition(".")[0]
    if not isinstance(error, ModuleNotFoundError) or name not in SYSTEM_PACKAGES:
        return None
    return PrimordiaError(f"{name} is not installed: primordia needs petsc4py, mpi4py and h5py built against the "
                          f"system's PETSc, MPI and HDF5, which pip does not install (Debian: apt-get install "
                          f"python3-dolfinx python3-h5py-mpi, and a venv made with --system-site-packages; "
                          f"README, \"Backends\")")


class SolverError(PrimordiaError):
    """A solve failed (diverged linear or nonlinear solver, NaN in a field).

    ``depends_on_step``: whether a smaller time step may succeed where this one failed.  False for
    a solver that cannot work at any step (PETSc refused its options at set-up: a usage error); an
    adaptive run then stops at once instead of halving dt down to ``time.dt_min`` first.
    """

    def __init__(self, message: str, *, depends_on_step: bool = True):
        super().__init__(message)
        self.depends_on_step = depends_on_step


class InterruptedRun(KeyboardInterrupt):
    """The run was asked to stop (Ctrl-C, SIGTERM): not an error of the input; ``signum`` says which signal."""

    def __init__(self, signum: int, message: str = ""):
        super().__init__(message)
        self.signum = signum


def mpi_world() -> tuple[int, int]:
    """(this process's MPI rank, the number of ranks) of the job.

    Read from mpi4py when it is imported, else from the launcher's environment (OpenMPI's or
    a PMI launcher's), so that asking never initialises MPI.
    """
    import os
    import sys

    if "mpi4py.MPI" in sys.modules:
        world = sys.modules["mpi4py.MPI"].COMM_WORLD
        return world.rank, world.size
    rank = os.environ.get("OMPI_COMM_WORLD_RANK") or os.environ.get("PMI_RANK") or "0"
    size = os.environ.get("OMPI_COMM_WORLD_SIZE") or os.environ.get("PMI_SIZE") or "1"
    return int(rank), int(size)


def is_root_process() -> bool:
    """Whether this is MPI rank 0 (messages are printed once, not once per rank)."""
    return mpi_world()[0] == 0


def warn(message: str) -> None:
    """One line ``primordia: warning: ...`` on stderr, from rank 0 only; a run's progress bar is cleared first and
    drawn again after it, or the warning would continue the bar's line."""
    import sys

    if not is_root_process():
        return
    bars = sys.modules.get("tqdm")  # imported by the progress bars: a bar may be on the screen
    with bars.tqdm.external_write_mode(file=sys.stderr) if bars else contextlib.nullcontext():
        print(f"primordia: warning: {message}", file=sys.stderr, flush=True)
