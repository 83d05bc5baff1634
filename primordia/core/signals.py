"""Ctrl-C, SIGTERM and SIGUSR1: a run stops between two steps, says why, and can be continued.

A user presses Ctrl-C; a batch scheduler sends SIGTERM before it kills a job.  Under
``mpirun`` a Ctrl-C or SIGTERM reaches the ranks a second late and is followed by SIGKILL a
second after that (Open MPI 4.1), while SIGUSR1 sent to ``mpirun`` is forwarded to every rank
at once and nothing follows it: the way to stop a parallel run whose steps take longer.
All three mean "stop", and :data:`INTERRUPTS` handles them alike, in one of three modes:

* ``immediate`` (start-up: reading the input, building forms, initial solves): the
  signal raises :class:`~primordia.core.errors.InterruptedRun` where the program is;
* ``deferred`` (the time loop): the signal is noted, the run finishes its step,
  writes a checkpoint and its outputs, and stops; a second signal stops it at once
  (the step in progress is undone);
* ``shielded`` (writing the last outputs): signals are counted, never raised, so
  ``summary.json`` is never left half-updated or saying "running".

A signal that arrives inside a PETSc callback may come back as a PETSc error:
whoever reports an error asks :attr:`Interrupts.received` first, so an interrupted
start-up is reported as interrupted, never as a mistake in the input.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time

from primordia.core.errors import InterruptedRun

HANDLED = (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1)


def copy_window() -> float:
    """Under mpirun, the same signal again within this many seconds of the first is a copy, not a second request
    (:attr:`Interrupts.copy_window`).  A batch system that signals the whole job reaches every rank and mpirun,
    which forwards its SIGTERM to the ranks ``odls_base_sigkill_timeout`` seconds later (1 by default, Open MPI
    4.1) and SIGKILL as long after that.  Counted as a second signal, that copy stopped every run so signalled
    at once, without the checkpoint the first one asked for."""
    try:
        delay = float(os.environ.get("OMPI_MCA_odls_base_sigkill_timeout", 1.0))
    except ValueError:
        delay = 1.0
    return max(delay, 0.0) + 1.5


def signal_name(signum: int | None) -> str:
    """How a signal is named to the user."""
    return {signal.SIGINT: "Ctrl-C", signal.SIGTERM: "SIGTERM", signal.SIGUSR1: "SIGUSR1"}.get(signum,
                                                                                             f"signal {signum}")


class Interrupts:
    """The process's handler of SIGINT, SIGTERM and SIGUSR1 (see the module docstring)."""

    def __init__(self):
        self.mode = "immediate"
        self.received: int | None = None
        self.count = 0
        #: seconds within which the first signal repeated is its copy (a run on several MPI ranks: copy_window())
        self.copy_window = 0.0
        self._first_at = 0.0
        self._installed = 0
        self._previous: dict[int, object] = {}

    @contextlib.contextmanager
    def installed(self):
        """Handle the signals of :data:`HANDLED` within the block (nested blocks share one installation)."""
        if threading.current_thread() is not threading.main_thread():
            yield self  # only the main thread may install handlers: Python's defaults stay
            return
        if self._installed == 0:
            # a job started in the background (``cmd &``) inherits SIGINT ignored: it stays so, as Python leaves it
            self._previous = {signum: signal.signal(signum, self._handle) for signum in HANDLED
                              if signal.getsignal(signum) is not signal.SIG_IGN}
        self._installed += 1
        try:
            yield self
        finally:
            self._installed -= 1
            if self._installed == 0:
                for signum, handler in self._previous.items():
                    if signal.getsignal(signum) == self._handle:  # unless someone chose another handler since
                        signal.signal(signum, handler)

    @contextlib.contextmanager
    def mode_of(self, mode: str):
        """Handle signals in ``mode`` within the block."""
        previous, self.mode = self.mode, mode
        try:
            yield self
        finally:
            self.mode = previous

    def reset(self) -> None:
        """Forget earlier signals (a new run in the same process)."""
        self.received, self.count = None, 0

    @property
    def urgent(self) -> bool:
        """Whether the run must stop now, not at the end of its step (a second signal, or one at start-up)."""
        return self.received is not None and (self.count > 1 or self.mode == "immediate")

    def _handle(self, signum, frame):
        now = time.monotonic()
        if signum == self.received and now - self._first_at < self.copy_window:
            return  # the same request, by another way (copy_window)
        self.count += 1
        if self.received is None:
            self.received, self._first_at = signum, now
        if self.mode == "shielded":
            return
        if self.mode == "immediate" or self.count > 1:
            raise InterruptedRun(signum)


#: The one handler of the process.
INTERRUPTS = Interrupts()
