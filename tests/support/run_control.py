"""Running ``primordia run`` the way a scheduler or a user does: in the background, signalled, killed, restarted.

Shared by the restart, signal and adaptive-step tests.  Every run is a real
process of the real command; a kill is a real SIGKILL of the run's whole process
group (under ``mpirun``: the launcher and every rank, as a batch system does).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
PYTHON = sys.executable
MPI_ENV = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMPI_MCA_rmaps_base_oversubscribe": "1"}

#: Coarse versions of the seed's examples 1a, 1b and 2a: a few seconds each, every step checkpointed.
COARSE = {
    "ex01a": ["--set", "mesh.cells=[8,8]", "--set", "time.t_final=2.0", "--set", "output.times=[1.0,2.0]"],
    "ex01b": ["--set", "mesh.cells=[4,4]", "--set", "time.t_final=1.6", "--set", "output.times=[0.8,1.6]"],
    "ex02a": ["--set", "mesh.cells=[4,4]", "--set", "time.t_final=1.2", "--set", "output.times=[0.6,1.2]"],
}

#: A throwaway output plugin that holds a run still from step ``PRIMORDIA_TEST_HOLD_AT`` on, so that the test's
#: SIGKILL (sent at a random moment after a random step) always lands before the run could finish.
HOLDING_OUTPUT = """\
import os
import time

from primordia.core.outputs import Output
from primordia.core.plugins import hookimpl


class HoldStill(Output):
    name = "hold_still"

    def record(self, run):
        if run.step_index >= int(os.environ.get("PRIMORDIA_TEST_HOLD_AT", "1000000000")):
            time.sleep(600)


@hookimpl
def primordia_outputs():
    return [HoldStill]
"""


def default_sigint():
    """A job started in the background inherits SIGINT ignored: give the run Python's default back."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def command(*args, ranks: int = 1) -> list[str]:
    run = [PYTHON, "-m", "primordia.cli", *map(str, args)]
    return ["mpirun", "-n", str(ranks), *run] if ranks > 1 else run


def environment(extra: dict | None = None, base: dict | None = None) -> dict:
    return {**(base or os.environ), **MPI_ENV, **(extra or {})}


def run(*args, ranks: int = 1, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run ``primordia ARGS`` to the end (a timeout is a hang, and fails the caller)."""
    return subprocess.run(command(*args, ranks=ranks), capture_output=True, text=True, env=environment(env),
                          timeout=timeout, preexec_fn=default_sigint)


def start(*args, ranks: int = 1, env: dict | None = None) -> subprocess.Popen:
    """Start ``primordia ARGS`` in its own process group (so that it can be killed whole)."""
    return subprocess.Popen(command(*args, ranks=ranks), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=environment(env), start_new_session=True, preexec_fn=default_sigint)


def checkpointed_step(out: Path) -> int:
    """The step of the checkpoint in ``out`` (-1: none yet)."""
    from primordia.core import checkpoint

    try:
        return int(checkpoint.read_meta(out / checkpoint.CHECKPOINT_FILE)["run"]["step"])
    except Exception:  # noqa: BLE001 - not written yet, or being replaced
        return -1


def wait_for_checkpoint(process: subprocess.Popen, out: Path, step: int, timeout: float = 240) -> None:
    """Wait until the run has checkpointed ``step`` (fails if it ends or stalls first)."""
    deadline = time.monotonic() + timeout
    while checkpointed_step(out) < step:
        if process.poll() is not None:
            raise AssertionError(f"the run ended before step {step}: {process.stderr.read()[-2000:]}")
        if time.monotonic() > deadline:
            raise AssertionError(f"no checkpoint of step {step} after {timeout} s")
        time.sleep(0.01)


def wait_for_steps(process: subprocess.Popen, out: Path, steps: int, timeout: float = 240) -> None:
    """Wait until the run's summary reports ``steps`` steps (rewritten at a series time at most every
    SUMMARY_INTERVAL seconds, or with series.nc)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            if summary(out)["steps"] >= steps:
                return
        except (OSError, ValueError, KeyError):
            pass
        if process.poll() is not None:
            raise AssertionError(f"the run ended before step {steps}: {process.stderr.read()[-2000:]}")
        if time.monotonic() > deadline:
            raise AssertionError(f"no step {steps} after {timeout} s")
        time.sleep(0.02)


def kill_group(process: subprocess.Popen, signum: int = signal.SIGKILL) -> None:
    """Send ``signum`` to the run's whole process group (mpirun and its ranks too)."""
    os.killpg(process.pid, signum)


def wait_until_gone(out: Path, timeout: float = 30) -> None:
    """Wait until the process that wrote ``out``'s summary has died: killed MPI ranks outlive mpirun for a moment,
    and a restart refuses a folder whose run still looks alive."""
    from primordia.core.outputs import run_is_alive

    deadline = time.monotonic() + timeout
    while run_is_alive(summary(out).get("process") or {}):
        assert time.monotonic() < deadline, "the killed run's process is still alive"
        time.sleep(0.1)


def finish(process: subprocess.Popen, timeout: float = 120) -> tuple[int, str]:
    """The exit status and stderr of a started run (a timeout is a hang)."""
    try:
        _, stderr = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        kill_group(process)
        process.communicate()
        raise AssertionError(f"the run did not end within {timeout} s (a hang)") from None
    return process.returncode, stderr


def stop(process: subprocess.Popen) -> None:
    """Kill a started run's process group if it is still running (nothing once it ended)."""
    if process.poll() is None:
        kill_group(process)
        process.communicate()


def summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def final_state(out: Path) -> dict[str, np.ndarray]:
    """Every field, start-of-step value and rate in the run's last checkpoint (written at its end)."""
    from primordia.core import checkpoint

    return checkpoint.read(out / checkpoint.CHECKPOINT_FILE)["fields"]


def primordia_lines(stderr: str) -> list[str]:
    """What primordia itself printed (under mpirun, mpirun's own banner is left out)."""
    return [line for line in stderr.splitlines() if line.startswith("primordia:") or "Traceback" in line
            or line.endswith("Error") or "Error:" in line]
