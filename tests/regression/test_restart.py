"""Checkpoint and restart through the real ``primordia`` command (issue 10).

A coarse seed example runs once uninterrupted; the same run is killed with a
real SIGKILL (its whole process group) at a random moment after a random step,
then continued with ``primordia run --restart OUT_DIR``.  It must end with the
same fields, start-of-step values and rates (velocities) as the uninterrupted
run, bit for bit, and the same series, on both backends and under
``mpirun -n 2``.
"""

from __future__ import annotations

import os
import random
import signal
import time
from pathlib import Path

import meshio
import numpy as np
import pytest
import xarray as xr

import run_control as rc
from primordia.core.signals import copy_window

CASES = [pytest.param(example, backend, ranks, id=f"{example}-{backend}-np{ranks}",
                      marks=[pytest.mark.mpi] if ranks > 1 else [])
         for example in ("ex01a", "ex01b", "ex02a") for backend, ranks in (("fenicsx", 1), ("skfem", 1),
                                                                            ("fenicsx", 2))]


@pytest.mark.parametrize("example, backend, ranks", CASES)
def test_a_run_killed_at_a_random_step_and_restarted_ends_bit_for_bit_as_the_uninterrupted_one(
        example, backend, ranks, tmp_path, plugin_distribution):
    arguments = [rc.EXAMPLES / f"{example}.toml", *rc.COARSE[example], "--backend", backend,
                 "--set", "checkpoint.every_steps=2", "--set", "output.series_every=1", "--set", "output.pictures=false",
                 "--no-progress"]
    steps = {"ex01a": 10, "ex01b": 8, "ex02a": 6}[example]
    chance = random.Random()
    killed_after = 2 * chance.randrange(1, steps // 2 - 1)
    env = plugin_distribution("primordia-hold-still", "0.1", {"hold_still": rc.HOLDING_OUTPUT},
                              {"hold_still": "hold_still"})
    hold = {**env, "PRIMORDIA_TEST_HOLD_AT": str(killed_after + 3)}

    # a serial reference runs on the second core beside the run to be killed; two ranks take both cores
    reference = rc.start("run", *arguments, "--out", tmp_path / "reference", ranks=ranks)
    killed, process = tmp_path / "killed", None
    try:
        if ranks > 1:
            status, stderr = rc.finish(reference, timeout=300)
            assert status == 0, stderr[-3000:]
        process = rc.start("run", *arguments, "--out", killed, ranks=ranks, env=hold)
        rc.wait_for_checkpoint(process, killed, killed_after)
        time.sleep(chance.uniform(0.0, 0.3))  # anywhere in the next steps: a solve, a write, the outputs
        rc.kill_group(process)
        process.communicate(timeout=60)
        rc.wait_until_gone(killed)
        status, stderr = rc.finish(reference, timeout=300)
        assert status == 0, stderr[-3000:]
    finally:  # a failure above leaves no run behind (the held one would sleep for 10 minutes)
        for started in (reference, process):
            if started is not None:
                rc.stop(started)
    assert rc.summary(killed)["status"] == "running"  # what a killed process leaves
    assert rc.checkpointed_step(killed) < steps

    restarted = rc.run("run", "--restart", killed, "--no-progress", ranks=ranks, env=env)
    assert restarted.returncode == 0, (rc.primordia_lines(restarted.stderr), restarted.stderr[-3000:])
    after = rc.summary(killed)
    assert after["status"] == "completed" and after["restarts"] == 1 and after["steps"] == steps

    expected, got = rc.final_state(tmp_path / "reference"), rc.final_state(killed)
    assert sorted(got) == sorted(expected)
    assert any(key.endswith("/rate") for key in got) == (example != "ex01a")  # velocities are state too
    # in serial bit for bit; under MPI the mesh partition (PT-SCOTCH's) differs from run to run, and with it
    # the order of every parallel sum: equal to round-off, 1e-12 of each field's size, or 1e-10 where GMRES
    # applies a growth tangent matrix-free (2a's default), whose differences of residuals scale round-off
    # by 1 / h ~ 1e8 before Newton's tolerance damps it (3.5e-12 of the rate's size measured)
    tolerance = 0.0 if ranks == 1 else (1e-10 if example == "ex02a" else 1e-12)
    for key, values in expected.items():
        difference = np.max(np.abs(got[key] - values), initial=0.0)
        assert difference <= tolerance * max(1.0, np.max(np.abs(values), initial=0.0)), (key, difference)
    with xr.open_dataset(tmp_path / "reference" / "series.nc") as one, xr.open_dataset(killed / "series.nc") as two:
        np.testing.assert_array_equal(two["time"].values, one["time"].values)
        for name in ("m_integral", "m_min", "m_max", "dt"):
            np.testing.assert_allclose(two[name].values, one[name].values, rtol=tolerance, atol=0)


@pytest.mark.mpi
@pytest.mark.parametrize("written_on, continued_on", [(1, 3), (3, 2), (4, 1)], ids=["1-to-3", "3-to-2", "4-to-1"])
def test_a_checkpoint_written_on_some_ranks_is_continued_on_others(written_on, continued_on, tmp_path):
    """A run begun on a laptop goes on on a cluster, and back: the fields are stored by DOF keys whatever the
    ranks.  It was refused ("it was written by 1 MPI ranks, this run has 3"), and a serial checkpoint held the
    backend's DOF order, which no other partition has."""
    arguments = [rc.EXAMPLES / "ex01b.toml", "--set", "mesh.cells=[4,4]", "--set", "output.pictures=false",
                 "--no-progress"]
    whole = rc.run("run", *arguments, "--set", "time.t_final=1.6", "--set", "output.times=[0.8,1.6]",
                   "--out", tmp_path / "whole")
    assert whole.returncode == 0, whole.stderr[-3000:]
    first = rc.run("run", *arguments, "--set", "time.t_final=0.8", "--set", "output.times=[0.8]",
                   "--out", tmp_path / "parts", ranks=written_on)
    assert first.returncode == 0, first.stderr[-3000:]
    second = rc.run("run", "--restart", tmp_path / "parts", "--set", "time.t_final=1.6",
                    "--set", "output.times=[0.8,1.6]", "--no-progress", ranks=continued_on)
    assert second.returncode == 0, (rc.primordia_lines(second.stderr), second.stderr[-3000:])
    summary = rc.summary(tmp_path / "parts")
    assert (summary["status"], summary["restarts"], summary["steps"], summary["mpi_ranks"]) == (
        "completed", 1, 8, continued_on)
    expected, got = rc.final_state(tmp_path / "whole"), rc.final_state(tmp_path / "parts")
    assert sorted(got) == sorted(expected) and any(key.endswith("/rate") for key in got)
    for key, values in expected.items():  # other partitions: the parallel sums' round-off
        assert np.max(np.abs(got[key] - values)) <= 1e-12 * max(1.0, np.max(np.abs(values))), key


def test_sigterm_stops_between_steps_with_a_checkpoint_and_the_run_continues(small_config, tmp_path):
    out = tmp_path / "out"
    arguments = [small_config(), "--set", "time.t_final=400.0", "--set", "mesh.cells=[16,16]", "--no-progress"]
    process = rc.start("run", *arguments, "--out", out)
    rc.wait_for_steps(process, out, 10)
    rc.kill_group(process, signal.SIGTERM)
    status, stderr = rc.finish(process)
    assert status == 128 + signal.SIGTERM, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("primordia: interrupted at t = "), stderr
    assert "(SIGTERM)" in lines[0] and f"--restart {out}" in lines[0]
    stopped = rc.summary(out)
    assert stopped["status"].startswith("interrupted at t = ") and "SIGTERM" in stopped["status"]
    assert rc.checkpointed_step(out) == stopped["steps"] > 0
    with xr.open_dataset(out / "series.nc") as series:
        assert series["time"].values[-1] <= stopped["time"]  # the summary never lags the data

    later = repr(stopped["time"] + 2.0)
    again = rc.run("run", "--restart", out, "--no-progress", "--set", f"time.t_final={later}",
                   "--set", f"output.times=[{later}]")
    assert again.returncode == 0, again.stderr
    assert rc.summary(out)["status"] == "completed" and rc.summary(out)["restarts"] == 1


@pytest.mark.mpi
def test_sigusr1_to_mpirun_stops_every_rank_between_steps_and_the_run_continues(small_config, tmp_path):
    """mpirun forwards SIGUSR1 to the ranks at once and kills nobody (its Ctrl-C and SIGTERM reach the ranks a
    second late and SIGKILL follows a second after): the way to stop a parallel run whose steps are long."""
    out = tmp_path / "out"
    process = rc.start("run", small_config(), "--set", "time.t_final=4000.0", "--set", "mesh.cells=[24,24]",
                       "--no-progress", "--out", out, ranks=2)  # long enough never to end before the signal
    try:
        rc.wait_for_steps(process, out, 10)
        process.send_signal(signal.SIGUSR1)  # to mpirun alone, as a user or a batch system would
        status, stderr = rc.finish(process)
    finally:
        rc.stop(process)
    assert status == 128 + signal.SIGUSR1, stderr[-3000:]
    lines = rc.primordia_lines(stderr)
    assert len(lines) == 1 and lines[0].startswith("primordia: interrupted at t = ") and "(SIGUSR1)" in lines[0], stderr
    stopped = rc.summary(out)
    assert stopped["status"].startswith("interrupted at t = ") and "SIGUSR1" in stopped["status"]
    assert rc.checkpointed_step(out) == stopped["steps"] > 0
    rc.wait_until_gone(out)
    later = repr(stopped["time"] + 2.0)
    again = rc.run("run", "--restart", out, "--no-progress", "--set", f"time.t_final={later}",
                   "--set", f"output.times=[{later}]", ranks=2)
    assert again.returncode == 0, again.stderr[-3000:]
    assert rc.summary(out)["status"] == "completed" and rc.summary(out)["restarts"] == 1


def test_a_second_ctrl_c_stops_at_once_and_the_summary_says_so(small_config, tmp_path):
    out = tmp_path / "out"
    process = rc.start("run", small_config(), "--set", "time.t_final=400.0", "--set", "mesh.cells=[24,24]",
                       "--no-progress", "--out", out)
    rc.wait_for_steps(process, out, 10)
    process.send_signal(signal.SIGINT)
    process.send_signal(signal.SIGINT)
    status, stderr = rc.finish(process)
    assert status == 128 + signal.SIGINT, stderr
    assert len(stderr.splitlines()) == 1 and "interrupted" in stderr and "Traceback" not in stderr
    assert rc.summary(out)["status"].startswith("interrupted at t = ")


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_a_signal_during_start_up_is_an_interruption_not_an_input_error(signum, tmp_path):
    out = tmp_path / "out"
    process = rc.start("run", rc.EXAMPLES / "ex02a.toml", *rc.COARSE["ex02a"], "--no-progress", "--out", out)
    time.sleep(1.0)  # importing, reading, or building forms
    process.send_signal(signum)
    status, stderr = rc.finish(process)
    assert status == 128 + signum, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("primordia: interrupted"), stderr
    assert "error" not in lines[0]


SIGNAL_AT_FINISH = """\
import os
import signal

from primordia.core.outputs import Output
from primordia.core.plugins import hookimpl


class SignalAtFinish(Output):
    name = "signal_at_finish"

    def finish(self, run, status):
        os.kill(os.getpid(), signal.SIGTERM)  # a scheduler's SIGTERM while the run writes its last files


@hookimpl
def primordia_outputs():
    return [SignalAtFinish]
"""


SIGNAL_AT_RESUME = """\
import os
import signal

from primordia.core.outputs import Output
from primordia.core.plugins import hookimpl


class SignalAtResume(Output):
    name = "signal_at_resume"

    def resume(self, run, state):
        os.kill(os.getpid(), signal.SIGTERM)  # a scheduler's SIGTERM while the restart sets up


@hookimpl
def primordia_outputs():
    return [SignalAtResume]
"""


def test_a_restart_stopped_during_its_start_up_says_how_the_run_goes_on(small_config, tmp_path):
    """It said "interrupted (SIGTERM) during start-up, before the first step", as a new run's start-up, of a run
    at t = 0.6 whose summary.json said "interrupted at t = 0.6": nothing said its checkpoint was still there."""
    plugin = tmp_path / "signal_at_resume.py"
    plugin.write_text(SIGNAL_AT_RESUME)
    out = tmp_path / "out"
    assert rc.run("run", small_config(), "--set", "time.t_final=0.6", "--no-progress", "--out", out).returncode == 0
    stopped = rc.run("-p", plugin, "run", "--restart", out, "--set", "time.t_final=1.0", "--no-progress")
    assert stopped.returncode == 128 + signal.SIGTERM, stopped.stderr
    assert stopped.stderr.splitlines() == [
        f"primordia: interrupted (SIGTERM) during the restart's start-up, before its first step; "
        f"primordia run --restart {out} continues it from its checkpoint at t = 0.6"]
    assert rc.summary(out)["status"] == "interrupted at t = 0.6 (SIGTERM)"
    again = rc.run("run", "--restart", out, "--set", "time.t_final=1.0", "--no-progress")
    assert again.returncode == 0, again.stderr
    assert (rc.summary(out)["status"], rc.summary(out)["time"]) == ("completed", 1.0)


def test_a_restart_stopped_before_the_command_itself_starts_says_so_too(small_config, tmp_path, monkeypatch, capsys):
    """A signal in the restart's first half second (PETSc's and MPI's start, before the command reads the
    checkpoint) still said "during start-up, before the first step", as a new run's (the restart QA pass)."""
    import primordia.cli
    from primordia.core.errors import InterruptedRun

    out = tmp_path / "out"
    assert rc.run("run", small_config(), "--set", "time.t_final=0.6", "--no-progress", "--out", out).returncode == 0

    def signalled():
        raise InterruptedRun(signal.SIGTERM)

    monkeypatch.setattr(primordia.cli, "_broken_pipes_raise", signalled)
    assert primordia.cli.main(["run", "--restart", str(out), "--no-progress"]) == 128 + signal.SIGTERM
    assert capsys.readouterr().err.splitlines() == [
        f"primordia: interrupted (SIGTERM) during the restart's start-up, before its first step; "
        f"primordia run --restart {out} continues it from its checkpoint at t = 0.6"]


def test_a_signal_while_a_failed_run_stops_leaves_the_failure_its_line(small_config, tmp_path):
    """The run had failed (dt_min) when the signal came: its line is the failure's, exit status 2.  It was
    "primordia: interrupted (SIGTERM) during start-up, before the first step" and 143 (seen under mpirun -n 4:
    SIGUSR1 while example 1b at 16^2 stopped at dt_min at t = 239.238, after 1196 steps)."""
    plugin = tmp_path / "signal_at_finish.py"
    plugin.write_text(SIGNAL_AT_FINISH)
    out = tmp_path / "out"
    result = rc.run("-p", plugin, "run", small_config(), "--set", "solver.chemotaxis_m.ksp_max_it=1",
                    "--set", "time.dt_min=0.1", "--no-progress", "--out", out)
    lines = result.stderr.splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0].startswith("primordia: error: step 1 (t = 0 -> ") and "time.dt_min = 0.1" in lines[0]
    assert rc.summary(out)["status"].startswith("stopped at t = 0: step 1")


def test_a_folder_holding_a_run_is_refused_unless_overwritten_or_restarted(primordia_cli, small_config, tmp_path):
    out = tmp_path / "out"
    assert primordia_cli("run", small_config(), "--out", out, "--no-progress").returncode == 0
    (out / "m_t0001.00.png").write_bytes(b"an old picture")
    (out / "notes.txt").write_text("the user's own file")
    for own in ("figure_1.png", "my_test.png", "m.png"):  # were removed with the run's pictures
        (out / own).write_bytes(b"the user's own picture")
    for written in ("final_fields.png", "m_snapshots.png", "metrics_m.png", "m_t-000.50.png", "u_t10000.0.png"):
        (out / written).write_bytes(b"a picture runs and primordia analyse write")

    again = primordia_cli("run", small_config(), "--out", out, "--no-progress", "--set", "time.t_final=0.6")
    assert again.returncode == 2 and len(again.stderr.splitlines()) == 1, again.stderr
    assert "already holds a run that ended: completed" in again.stderr and "--overwrite" in again.stderr

    replaced = primordia_cli("run", small_config(), "--out", out, "--no-progress", "--overwrite",
                             "--set", "time.t_final=0.6")
    assert replaced.returncode == 0, replaced.stderr
    assert rc.summary(out)["steps"] == 3
    assert not (out / "m_t0001.00.png").exists() and (out / "notes.txt").read_text() == "the user's own file"
    assert sorted(p.name for p in out.glob("*.png")) == ["figure_1.png", "m.png", "my_test.png"]

    longer = primordia_cli("run", "--restart", out, "--no-progress", "--set", "time.t_final=1.0")
    assert longer.returncode == 0, longer.stderr
    assert rc.summary(out)["steps"] == 5 and rc.summary(out)["restarts"] == 1


def _written_times(out) -> list[float]:
    with meshio.xdmf.TimeSeriesReader(out / "fields.xdmf") as reader:
        reader.read_points_cells()
        return [reader.read_data(k)[0] for k in range(reader.num_steps)]


def test_a_restart_that_moves_t_final_writes_the_fields_there_when_output_times_were_the_default(
        primordia_cli, small_config, tmp_path):
    # config.toml froze the default output.times = [t_final]: a longer restart wrote no fields at its own end
    out, given = tmp_path / "default", tmp_path / "given"
    assert primordia_cli("run", small_config(), "--out", out, "--no-progress", "--set", "time.t_final=0.6"
                         ).returncode == 0
    longer = primordia_cli("run", "--restart", out, "--no-progress", "--set", "time.t_final=1.0")
    assert longer.returncode == 0, longer.stderr
    assert _written_times(out) == pytest.approx([0.6, 1.0])

    # times the user gave stay as given; --set output.times on the restart is the user's again
    assert primordia_cli("run", small_config(), "--out", given, "--no-progress", "--set", "time.t_final=0.6",
                         "--set", "output.times=[0.4, 0.6]").returncode == 0
    assert primordia_cli("run", "--restart", given, "--no-progress", "--set", "time.t_final=1.0").returncode == 0
    assert _written_times(given) == pytest.approx([0.4, 0.6])
    assert primordia_cli("run", "--restart", given, "--no-progress", "--set", "time.t_final=1.4",
                         "--set", "output.times=[0.4, 0.6, 1.2]").returncode == 0
    assert _written_times(given) == pytest.approx([0.4, 0.6, 1.2])
    assert primordia_cli("run", "--restart", out, "--no-progress", "--set", "time.t_final=1.4",
                         "--set", "output.times=[1.2]").returncode == 0
    assert _written_times(out) == pytest.approx([0.6, 1.0, 1.2])


def test_a_run_rebuilt_from_its_config_toml_keeps_default_output_times_following_t_final(
        primordia_cli, small_config, tmp_path):
    """The README's way to extend a run from Python, Model.from_file(its config.toml, ["time.t_final=..."]), and
    `primordia run OUT/config.toml --restart OUT`: config.toml froze the default output.times as [the old
    t_final], so the longer run wrote no fields at its end, where `--restart OUT --set time.t_final=...` did."""
    from primordia import Model

    out = tmp_path / "default"
    assert primordia_cli("run", small_config(), "--out", out, "--no-progress", "--set", "time.t_final=0.6"
                         ).returncode == 0
    longer = Model.from_file(out / "config.toml", ["time.t_final=1.0"])
    assert longer.output["times"] == [1.0]
    longer.run(out=out, restart=True)
    assert _written_times(out) == pytest.approx([0.6, 1.0])
    again = primordia_cli("run", out / "config.toml", "--restart", out, "--no-progress", "--set", "time.t_final=1.4")
    assert again.returncode == 0, again.stderr
    assert _written_times(out) == pytest.approx([0.6, 1.0, 1.4])
    # times that were given stay in config.toml as given
    given = tmp_path / "given"
    assert primordia_cli("run", small_config(), "--out", given, "--no-progress", "--set", "time.t_final=0.6",
                         "--set", "output.times=[0.6]").returncode == 0
    assert Model.from_file(given / "config.toml", ["time.t_final=1.0"]).output["times"] == [0.6]


def test_a_run_given_another_backend_from_python_names_it_and_is_continued_on_it(
        primordia_cli, small_config, tmp_path):
    """Model.run(backend="skfem") on a model of the default backend wrote model.backend = "fenicsx" into config.toml
    and the checkpoint: `primordia run --restart OUT` said "it was written on backend skfem, this run is on
    fenicsx", and with --backend skfem "model.backend differs from the checkpointed run's"."""
    import tomllib

    from primordia import Model

    out = tmp_path / "skfem"
    Model.from_file(small_config(), ["time.t_final=0.6"]).run(backend="skfem", out=out)
    with open(out / "config.toml", "rb") as stream:
        assert tomllib.load(stream)["model"]["backend"] == "skfem"
    longer = primordia_cli("run", "--restart", out, "--no-progress", "--set", "time.t_final=0.8")
    assert longer.returncode == 0, longer.stderr
    assert "on skfem" in longer.stdout
    # the model as it was built, run again on the backend it was given, continues too
    sim = Model.from_file(small_config(), ["time.t_final=1.0"]).run(backend="skfem", out=out, restart=True)
    assert (sim.status, sim.restarts, sim.time) == ("completed", 2, 1.0)
    refused = primordia_cli("run", "--restart", out, "--no-progress", "--backend", "fenicsx")
    assert refused.returncode == 2
    assert refused.stderr.strip().endswith("it was written on backend skfem, this run is on fenicsx")


def test_a_killed_run_is_named_killed_and_a_restart_refuses_another_model(primordia_cli, small_config, tmp_path):
    out = tmp_path / "out"
    process = rc.start("run", small_config(), "--set", "time.t_final=400.0", "--set", "mesh.cells=[16,16]",
                       "--set", "checkpoint.every_steps=5", "--no-progress", "--out", out)
    rc.wait_for_checkpoint(process, out, 5)
    rc.kill_group(process)
    process.communicate(timeout=60)

    again = primordia_cli("run", small_config(), "--out", out, "--no-progress")
    assert again.returncode == 2 and "was killed without a word" in again.stderr, again.stderr
    other = primordia_cli("run", "--restart", out, "--no-progress", "--set", "parameters.D_m=0.05")
    assert other.returncode == 2 and len(other.stderr.splitlines()) == 1, other.stderr
    assert "parameters.D_m differs from the checkpointed run" in other.stderr
    empty = primordia_cli("run", "--restart", tmp_path / "nothing", "--no-progress")
    assert empty.returncode == 2 and "holds no checkpoint" in empty.stderr, empty.stderr


def _series_times(out) -> list[float]:
    with xr.open_dataset(out / "series.nc") as series:
        return [float(t) for t in series["time"].values]


@pytest.mark.parametrize("stop", ["sigterm", "solver-error", "full-disk"])
def test_every_row_recorded_before_a_stop_is_in_the_series(stop, tmp_path, monkeypatch):
    """series.nc is rewritten at most every SERIES_INTERVAL seconds (2 s): the rows of a fast run wait in memory.
    A run that stops (a signal, a failed step, a full disk) must still leave every row it recorded; here the
    interval is an hour, so that every row after the first waits for the stop's flush."""
    import errno
    import os

    from primordia.core import outputs
    from primordia.core.atomic_files import StorageError
    from primordia.core.errors import InterruptedRun, SolverError
    from primordia.core.meshes import rectangle
    from primordia.core.signals import INTERRUPTS
    from primordia.coupling import orchestrator
    from primordia.model import Model

    monkeypatch.setattr(outputs, "SERIES_INTERVAL", 3600.0)
    inadmissible, write_checkpoint = orchestrator.Simulation._inadmissible, orchestrator.checkpoint_file.write

    def failing(sim, t):  # the step to t = 1.0 (the fifth) meets its stop
        if t > 0.9 and stop == "sigterm" and sim.step_index == 4 and sim.step_done == 0.0:
            os.kill(os.getpid(), signal.SIGTERM)  # deferred: the step ends, then the run stops
        if t > 0.9 and stop == "solver-error":  # no rejection event, which would rewrite the file
            raise SolverError("chemotaxis.m: a failure no smaller step mends", depends_on_step=False)
        return inadmissible(sim, t)

    def full(path, tree):
        if stop == "full-disk":
            raise StorageError(f"cannot write {path}: {os.strerror(errno.ENOSPC).lower()}")
        write_checkpoint(path, tree)

    monkeypatch.setattr(orchestrator.Simulation, "_inadmissible", failing)
    monkeypatch.setattr(orchestrator.checkpoint_file, "write", full)
    model = Model(physics=["chemotaxis"], parameters={"m0": 0.75}, mesh=rectangle((0.0, 0.0), (4.0, 4.0), cells=(4, 4)),
                  dt=0.2, t_final=2.0, adaptive=False, output={"pictures": False, "series_every": 1},
                  checkpoint={"every_steps": 5, "every_minutes": 0})
    stopped_by = {"sigterm": InterruptedRun, "solver-error": SolverError, "full-disk": StorageError}[stop]
    try:
        with pytest.raises(stopped_by):
            model.run(out=tmp_path / "out")
    finally:
        INTERRUPTS.reset()  # the signal is this run's: the next test's must not stop on it
    reached = {"sigterm": 1.0, "solver-error": 0.8, "full-disk": 1.0}[stop]
    assert _series_times(tmp_path / "out") == pytest.approx([0.2 * k for k in range(round(reached / 0.2) + 1)])
    assert rc.summary(tmp_path / "out")["time"] == pytest.approx(reached)


#: An output that stops a 2-rank run at step 3 (t = 0.6) as ``STOP`` says, every row of series.nc after the first
#: waiting in memory for an hour (the test's interval, not a user's 2 s): "rank 0 alone" raises on rank 0 before an
#: allreduce rank 1 is inside (rank 0 waits 3 s for it, then aborts); "two signals" holds every rank still for the
#: test's two SIGUSR1s, of which the second stops the run at once.
STOP_AT_STEP_3 = """\
import os
import time

import primordia.core.outputs
import primordia.coupling.orchestrator
from primordia.core.outputs import Output
from primordia.core.plugins import hookimpl

primordia.core.outputs.SERIES_INTERVAL = 3600.0
primordia.coupling.orchestrator.OUTPUT_PATIENCE_S = 3.0  # the test's patience, not a user's 300 s


class StopAtThree(Output):
    name = "stop_at_three"

    def record(self, run):
        if run.step_index != 3:
            return
        if os.environ["STOP"] == "rank 0 alone":
            if run.comm.rank == 0:
                raise RuntimeError("rank 0's record")
            run.comm.allreduce(1.0)
        else:
            if run.is_root:
                (run.out_dir / "holding").touch()
            time.sleep(float(os.environ.get("HOLD", 60)))


@hookimpl
def primordia_outputs():
    return [StopAtThree]
"""


@pytest.mark.mpi
@pytest.mark.parametrize("stop", ["rank 0 alone", "two signals"])
def test_a_parallel_run_stopped_at_once_keeps_the_rows_its_series_held(stop, small_config, tmp_path):
    """A failure on rank 0 alone ends the job with MPI_Abort, and a second SIGUSR1 stops a parallel run at once
    (the ranks may be anywhere: rank 0 only patches summary.json): the rows of series.nc waiting in memory were
    lost, and the series held t = 0 alone."""
    plugin = tmp_path / "stop_at_three.py"
    plugin.write_text(STOP_AT_STEP_3)
    out = tmp_path / "out"
    process = rc.start("-p", plugin, "run", small_config(), "--set", "output.series_every=1", "--no-progress",
                       "--out", out, ranks=2, env={"STOP": stop})
    try:
        if stop == "two signals":
            _wait_until_holding(process, out)
            process.send_signal(signal.SIGUSR1)  # noted: the run would stop after this step
            time.sleep(copy_window() + 0.5)  # sooner, the same signal is the first one's copy (test_signals.py)
            process.send_signal(signal.SIGUSR1)  # at once, in the held output
        status, stderr = rc.finish(process, timeout=60)
    finally:
        rc.stop(process)
    assert status == (2 if stop == "rank 0 alone" else 128 + signal.SIGUSR1), stderr[-3000:]
    if stop == "two signals":  # it said "primordia: running; continue it with: primordia run --restart OUT"
        assert rc.primordia_lines(stderr) == ["primordia: interrupted at t = 0.6 (SIGUSR1); it wrote no checkpoint "
                                              "to continue from"], stderr[-3000:]
    assert rc.summary(out)["status"] == ("interrupted at t = 0.6 (SIGUSR1)" if stop == "two signals" else
                                         "stopped at t = 0.6: output 'stop_at_three' failed on rank 0 (record): "
                                         "RuntimeError: rank 0's record, and the other ranks were still inside it "
                                         "after 3 s (a collective call this rank never reached)")
    assert _series_times(out) == pytest.approx([0.0, 0.2, 0.4, 0.6])


def _wait_until_holding(process, out: Path) -> None:
    """Until STOP_AT_STEP_3 holds the run in its step 3 (fails if the run ends first)."""
    deadline = time.monotonic() + 120
    while not (out / "holding").exists():
        assert process.poll() is None and time.monotonic() < deadline, process.stderr.read()[-2000:]
        time.sleep(0.05)


@pytest.mark.mpi
def test_a_sigterm_to_the_whole_job_stops_a_parallel_run_after_its_step_with_a_checkpoint(small_config, tmp_path):
    """A batch system's SIGTERM to the whole job reaches every rank and mpirun, which forwards its own to the ranks
    odls_base_sigkill_timeout seconds later: that copy counted as a second signal and stopped the run at once,
    with no checkpoint (the line said "it wrote no checkpoint to continue from").  Here the timeout is 3 s, as
    README advises batch scripts to raise it: the copy comes 3 s after the signal, inside the step held 4.5 s,
    and SIGKILL at 6 s, after the checkpoint."""
    plugin = tmp_path / "stop_at_three.py"
    plugin.write_text(STOP_AT_STEP_3)
    out = tmp_path / "out"
    process = rc.start("-p", plugin, "run", small_config(), "--set", "output.series_every=1", "--no-progress",
                       "--out", out, ranks=2, env={"STOP": "held", "HOLD": "4.5",
                                                              "OMPI_MCA_odls_base_sigkill_timeout": "3"})
    try:
        _wait_until_holding(process, out)
        ranks = [int(pid) for pid in Path(f"/proc/{process.pid}/task/{process.pid}/children").read_text().split()]
        for pid in [process.pid, *ranks]:  # mpirun and both ranks, each in its own process group
            os.kill(pid, signal.SIGTERM)
        status, stderr = rc.finish(process, timeout=60)
    finally:
        rc.stop(process)
    stopped = rc.summary(out)
    assert stopped["status"] == "interrupted at t = 0.6 (SIGTERM)", stderr[-3000:]
    assert rc.checkpointed_step(out) == stopped["steps"] == 3, stderr[-3000:]
    assert "wrote no checkpoint" not in stderr, stderr[-3000:]
