"""The process's signal handler (primordia.core.signals): a repeated signal, a copy or a second request."""

from __future__ import annotations

import signal

import pytest

from primordia.core.errors import InterruptedRun
from primordia.core.signals import HANDLED, Interrupts, copy_window


def test_a_signal_repeated_at_once_under_mpirun_is_its_copy_not_a_second_request(monkeypatch):
    """A batch system signalling the whole job reaches every rank and mpirun, which forwards its SIGTERM to the
    ranks a second later: counted as a second signal, it stopped the run at once without its checkpoint."""
    clock = [100.0]
    monkeypatch.setattr("primordia.core.signals.time.monotonic", lambda: clock[0])
    monkeypatch.delenv("OMPI_MCA_odls_base_sigkill_timeout", raising=False)
    interrupts = Interrupts()
    interrupts.copy_window = copy_window()  # mpirun's default: its copy comes 1 s after it was signalled
    with interrupts.mode_of("deferred"):
        interrupts._handle(signal.SIGTERM, None)
        clock[0] += 1.2  # mpirun's forwarded copy
        interrupts._handle(signal.SIGTERM, None)
        assert (interrupts.received, interrupts.count, interrupts.urgent) == (signal.SIGTERM, 1, False)
        with pytest.raises(InterruptedRun):  # another signal is a second request
            interrupts._handle(signal.SIGINT, None)
    interrupts.reset()
    with interrupts.mode_of("deferred"):
        interrupts._handle(signal.SIGTERM, None)
        clock[0] += interrupts.copy_window + 0.1  # the same signal later is a second request too
        with pytest.raises(InterruptedRun):
            interrupts._handle(signal.SIGTERM, None)


def test_in_serial_the_same_signal_twice_is_a_second_request():
    interrupts = Interrupts()  # copy_window 0: a run on one rank has no mpirun to forward copies
    with interrupts.mode_of("deferred"):
        interrupts._handle(signal.SIGINT, None)
        with pytest.raises(InterruptedRun):
            interrupts._handle(signal.SIGINT, None)
    assert interrupts.count == 2


def test_the_copy_window_follows_mpirun_s_delay(monkeypatch):
    """A batch script that gives the ranks longer to stop (README) delays mpirun's copy as long."""
    monkeypatch.setenv("OMPI_MCA_odls_base_sigkill_timeout", "60")
    assert copy_window() == 61.5
    monkeypatch.setenv("OMPI_MCA_odls_base_sigkill_timeout", "soon")
    assert copy_window() == 2.5


def _interrupt_at_start(monkeypatch):
    import primordia.cli

    def interrupted():
        raise InterruptedRun(signal.SIGINT)

    monkeypatch.setattr(primordia.cli, "_refuse_an_unwritable_tmpdir", interrupted)


def test_an_interrupted_command_called_from_python_leaves_ctrl_c_as_it_was(monkeypatch, capsys):
    """After an interrupted ``cli.main`` a notebook (or a test session) ignored Ctrl-C for good."""
    from primordia.cli import main

    _interrupt_at_start(monkeypatch)
    before = {signum: signal.getsignal(signum) for signum in HANDLED}
    assert main(["plugins"]) == 128 + signal.SIGINT
    assert "interrupted (Ctrl-C) during start-up" in capsys.readouterr().err
    assert {signum: signal.getsignal(signum) for signum in HANDLED} == before


def test_the_console_script_ignores_late_signals_until_it_exits(monkeypatch, capsys):
    """The console script's process ends with the command: a late copy of the signal must not print a traceback."""
    from primordia.cli import console

    _interrupt_at_start(monkeypatch)
    before = {signum: signal.getsignal(signum) for signum in HANDLED}
    monkeypatch.setattr("sys.argv", ["primordia", "plugins"])
    try:
        with pytest.raises(SystemExit) as exit:
            console()
        assert exit.value.code == 128 + signal.SIGINT
        assert all(signal.getsignal(signum) is signal.SIG_IGN for signum in HANDLED)
    finally:
        for signum, handler in before.items():
            signal.signal(signum, handler)
