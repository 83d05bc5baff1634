"""A plugin that fails on one MPI rank only (``mpirun -n 2``): one line, the right exit status, and no hang.

A hang is the worst outcome on a cluster (the job burns its allocation until the scheduler kills it), so
every run here has a timeout, and a timeout fails the test.  The plugins fail on rank 1 only, as a plugin
reading a file only one rank can see, or a value only one rank holds, would.
"""

from __future__ import annotations

import json

import pytest

import run_control as rc

pytestmark = pytest.mark.mpi

#: An output failing on rank 1 at the moment ``FAIL_AT`` says, from step ``FAIL_FROM`` on.  ``collective`` raises
#: before an allreduce that rank 0 makes: against the hookspec's contract, as a careless plugin does.
FLAKY_OUTPUT = """\
import os

from mpi4py import MPI

import primordia.coupling.orchestrator
from primordia.core.outputs import Output
from primordia.core.plugins import hookimpl

primordia.coupling.orchestrator.OUTPUT_PATIENCE_S = 3.0  # the test's patience, not a user's 300 s
WHERE, FROM = os.environ.get("FAIL_AT", ""), int(os.environ.get("FAIL_FROM", "0"))


def failing(moment, run):
    return WHERE == moment and MPI.COMM_WORLD.rank == 1 and run.step_index >= FROM


class Flaky(Output):
    name = "flaky"

    def start(self, run):
        if failing("start", run):
            raise RuntimeError("flaky start")

    def record(self, run):
        if failing("record", run):
            raise RuntimeError("flaky record")
        if WHERE == "collective" and run.step_index >= FROM:
            if failing("collective", run):
                raise RuntimeError("flaky before its allreduce")
            run.comm.allreduce(1.0)

    def finish(self, run, status):
        if failing("finish", run):
            raise RuntimeError("flaky finish")


@hookimpl
def primordia_outputs():
    return [Flaky]
"""


def _run(tmp_path, small_config, *extra, env=None, timeout=120):
    plugin = tmp_path / "flaky.py"
    plugin.write_text(FLAKY_OUTPUT)
    # a record at every step, so that a failure from step FAIL_FROM on comes at that step
    return rc.run("-p", plugin, "run", small_config(), "--out", tmp_path / "out", "--no-progress",
                  "--set", "output.series_every=1", *extra, ranks=2, env=env, timeout=timeout)


@pytest.mark.parametrize("moment", ["start", "record", "finish"])
def test_an_output_failing_on_one_rank_is_disabled_with_one_warning(moment, tmp_path, small_config):
    result = _run(tmp_path, small_config, env={"FAIL_AT": moment, "FAIL_FROM": "2" if moment == "record" else "0"})
    assert result.returncode == 0, result.stderr[-2000:]
    lines = rc.primordia_lines(result.stderr + result.stdout)
    assert len(lines) == 2, result.stderr[-2000:]
    assert lines[0].startswith("primordia: warning: output 'flaky' failed at t = ") and f"({moment})" in lines[0]
    assert f"flaky {moment} (on rank 1); it is disabled" in lines[0]
    assert lines[1].startswith("primordia: completed: 5 steps")
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["status"] == "completed"


def test_an_output_failing_on_one_rank_before_its_collective_call_ends_the_job(tmp_path, small_config):
    """Rank 1 raised before the allreduce rank 0 was inside, and entered the allgather of the failures: the two
    waited for each other until ``timeout`` killed the job.  Now rank 1 waits 3 s (the patience the plugin
    sets), says so in one line and aborts the job; the checkpoint of the step before continues the run."""
    result = _run(tmp_path, small_config, "--set", "checkpoint.every_steps=1",
                  env={"FAIL_AT": "collective", "FAIL_FROM": "3"}, timeout=60)
    assert result.returncode == 2, result.stderr[-2000:]
    lines = rc.primordia_lines(result.stderr)
    assert len(lines) == 1, result.stderr[-2000:]
    assert lines[0].startswith("primordia: error: stopped at t = 0.6: output 'flaky' failed on rank 1 (record): "
                               "RuntimeError: flaky before its allreduce, and the other ranks were still inside it "
                               "after 3 s"), lines[0]
    assert lines[0].endswith(f"continue it from its last checkpoint with: primordia run --restart {tmp_path / 'out'}")
    out = tmp_path / "out"
    assert json.loads((out / "summary.json").read_text())["status"].startswith("stopped at t = 0.6: output 'flaky'")
    assert rc.checkpointed_step(out) == 2  # step 3 is recorded before it is checkpointed
    plugin = tmp_path / "flaky.py"
    restarted = rc.run("-p", plugin, "run", "--restart", out, "--no-progress", ranks=2, timeout=120)
    assert restarted.returncode == 0, restarted.stderr[-2000:]
    assert rc.summary(out)["status"] == "completed" and rc.summary(out)["steps"] == 5


#: Kinetics whose set-up fails on rank 1 only, as ``KIN_MODE`` says: its rates raise, or miss a species.
FLAKY_KINETICS = """\
import os
import sys

from mpi4py import MPI

from primordia.core.plugins import hookimpl
from primordia.physics.kinetics.painter2018 import Painter2018

sys.modules["__main__"].ERROR_PATIENCE_S = 3.0  # the test's patience (python -m primordia.cli), not a user's 60 s
MODE = os.environ["KIN_MODE"]


class Flaky(Painter2018):
    name = "flaky_kinetics"

    def split_rates(self, c, t, ops):
        rates = super().split_rates(c, t, ops)
        if MPI.COMM_WORLD.rank == 1:
            if MODE == "raise":
                raise RuntimeError("flaky kinetics")
            if MODE == "nan":  # a value only rank 1 holds: the forms differ, and so did their collective calls
                production, loss = rates["m"]
                rates["m"] = (production * float("nan"), loss)
                return rates
            rates.pop("b")
        return rates


@hookimpl
def primordia_kinetics():
    return [Flaky]
"""


#: The line of FLAKY_KINETICS that raises: the error names it.
RAISE_LINE = next(n for n, line in enumerate(FLAKY_KINETICS.splitlines(), start=1) if "raise RuntimeError" in line)


@pytest.mark.parametrize("mode, message", [
    ("raise", "kinetics flaky_kinetics (primordia_plugin_flaky_kinetics.Flaky): split_rates failed: RuntimeError: "
              "flaky kinetics (at PLUGIN:LINE)"),
    ("shape", "kinetics flaky_kinetics: split_rates must return {species: (production, loss_rate)} for its species "
              "m, e, f, b, got m, e, f"),
    ("nan", "chemotaxis.m: its equations differ between MPI ranks (rank 0 and rank 1): a plugin answers otherwise "
            "on some rank (a NaN there, or a value read from a file only one rank sees)")])
@pytest.mark.parametrize("dry_run", [[], ["--dry-run"]], ids=["run", "dry-run"])
def test_kinetics_failing_on_one_rank_is_one_line(mode, message, dry_run, tmp_path, small_config):
    """The error was rank 1's alone: rank 1 printed nothing (only rank 0 prints errors) and waited in MPI_Finalize
    while rank 0 waited in a collective call of the set-up, until ``timeout`` killed the job.  ``--dry-run``, which
    did not build the forms, said "the input is valid"."""
    plugin = tmp_path / "flaky_kinetics.py"
    plugin.write_text(FLAKY_KINETICS)
    result = rc.run("-p", plugin, "run", small_config(), "--set", "kinetics.name=flaky_kinetics", "--out",
                    tmp_path / "out", "--no-progress", *dry_run, ranks=2, env={"KIN_MODE": mode}, timeout=60)
    assert result.returncode == 2, result.stderr[-2000:]
    message = message.replace("PLUGIN", str(plugin)).replace("LINE", str(RAISE_LINE))
    assert rc.primordia_lines(result.stderr) == [f"primordia: error: {message}"], result.stderr[-2000:]


#: The chemotaxis, renamed, with an initial solve of e whose value is NaN on rank 1 only.
FLAKY_INITIAL_SOLVE = """\
import ufl
from mpi4py import MPI

from primordia.core.plugins import hookimpl
from primordia.physics.base import Subproblem
from primordia.physics.chemotaxis import Chemotaxis


class Flaky(Chemotaxis):
    name = "flaky_initial"

    def initial_subproblems(self):
        disc, value = self.disc, float("nan") if MPI.COMM_WORLD.rank == 1 else 0.5
        residual = (disc.field("e") - value) * disc.test("e") * disc.dx
        return [Subproblem(name="flaky_initial.e0", unknown=disc.unknown("e"), residual=residual,
                           jacobian=ufl.derivative(residual, disc.unknown("e")))]


@hookimpl
def primordia_physics():
    return [Flaky]
"""


@pytest.mark.parametrize("dry_run", [[], ["--dry-run"]], ids=["run", "dry-run"])
def test_an_initial_solve_differing_across_ranks_is_one_line(dry_run, tmp_path, small_config):
    """--dry-run compared the ranks' forms of the steps' subproblems only: it said "the input is valid" to an
    initial solve whose equations differed, which the run refuses."""
    plugin = tmp_path / "flaky_initial.py"
    plugin.write_text(FLAKY_INITIAL_SOLVE)
    config = small_config(small_config.text.replace('physics = ["chemotaxis"]', 'physics = ["flaky_initial"]'))
    result = rc.run("-p", plugin, "run", config, "--out", tmp_path / "out", "--no-progress", *dry_run, ranks=2,
                    timeout=60)
    assert result.returncode == 2, result.stderr[-2000:]
    assert rc.primordia_lines(result.stderr) == [
        "primordia: error: flaky_initial.e0: its equations differ between MPI ranks (rank 0 and rank 1): a plugin "
        "answers otherwise on some rank (a NaN there, or a value read from a file only one rank sees)"], \
        result.stderr[-2000:]


#: A physics module (the chemotaxis, renamed) whose ``before_step`` fails on rank 1 only, from the step to t = 0.4.
FLAKY_PHYSICS = """\
from mpi4py import MPI

import primordia.coupling.orchestrator
from primordia.core.plugins import hookimpl
from primordia.physics.chemotaxis import Chemotaxis

primordia.coupling.orchestrator.OUTPUT_PATIENCE_S = 3.0  # the test's patience, not a user's 300 s


class Flaky(Chemotaxis):
    name = "flaky_chemotaxis"

    def before_step(self, t, dt):
        super().before_step(t, dt)
        if MPI.COMM_WORLD.rank == 1 and t > 0.3:
            raise RuntimeError("flaky before_step")


@hookimpl
def primordia_physics():
    return [Flaky]
"""


def test_a_step_failing_on_one_rank_ends_the_job_in_one_line(tmp_path, small_config):
    """Rank 1 raised in its step and went into the stop's checkpoint gather while rank 0 sat in the step's
    collective calls: the job hung without a word until ``timeout``."""
    plugin = tmp_path / "flaky_physics.py"
    plugin.write_text(FLAKY_PHYSICS)
    config = small_config(small_config.text.replace('physics = ["chemotaxis"]', 'physics = ["flaky_chemotaxis"]'))
    out = tmp_path / "out"
    result = rc.run("-p", plugin, "run", config, "--set", "checkpoint.every_steps=1", "--out", out, "--no-progress",
                    ranks=2, timeout=60)
    assert result.returncode == 2, result.stderr[-2000:]
    lines = rc.primordia_lines(result.stderr)
    assert len(lines) == 1, result.stderr[-2000:]
    assert lines[0].startswith("primordia: error: stopped at t = 0.2: physics flaky_chemotaxis"), lines[0]
    assert "before_step failed: RuntimeError: flaky before_step" in lines[0]
    assert "(on rank 1 alone: the other ranks were still in the step after 3 s)" in lines[0]
    assert rc.summary(out)["status"].startswith("stopped at t = 0.2: physics flaky_chemotaxis")
    assert rc.checkpointed_step(out) == 1  # the step 0.2 -> 0.4 failed (before_step is given its end)
