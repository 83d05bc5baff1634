"""The orchestrator (primordia.coupling.orchestrator): setup order, step and time bookkeeping, outputs, summary, errors.

Small runs of the chemotaxis system (4 x 4 squares, dt = 0.2) on fenicsx, watched through the
public plugin hooks: a physics module that only records what the run asks of it (listed
*before* chemotaxis, whose field m it reads) and an output that records every moment it is
called at.  The splitting schemes' own bookkeeping is in test_splitting.py; restarts and
signals through the real command in tests/regression/test_restart.py.
"""

from __future__ import annotations

import json
import shutil

import meshio
import numpy as np
import pytest
import xarray as xr

from primordia.core.errors import ConfigError, PluginError, SolverError
from primordia.core.meshes import read_mesh, rectangle
from primordia.core.outputs import Output
from primordia.core.plugins import hookimpl
from primordia.coupling.orchestrator import Simulation
from primordia.model import Model
from primordia.physics.base import Physics
from primordia.testing import registered

DT = 0.2


class Recorder(Physics):
    """Owns no field, reads m, and records each call; fails a step on request (a solve that diverged)."""

    name = "recorder"
    #: read: the field it reads; fail_at: the end time of the step to fail (-1: none); fail_dt: fail it only when taken with this dt (0: any)
    options = {"fail_at": -1.0, "fail_dt": 0.0, "read": "m"}

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.calls: list[tuple] = []

    @property
    def requires(self):
        return (self.settings["read"],)

    def fields(self):
        return []

    def setup(self, disc):
        self.calls.append(("setup", disc.field(self.settings["read"]).ufl_shape))

    def initialise(self, disc):
        self.calls.append(("initialise",))

    def subproblems(self):
        return []

    def before_step(self, t, dt):
        self.calls.append(("before_step", t, dt))
        if abs(t - self.settings["fail_at"]) < 1e-9 and self.settings["fail_dt"] in (0.0, dt):
            raise SolverError(f"recorder: injected failure at t = {t:g}")


class Recording(Output):
    """Every moment an output is called at: (moment, step, time), and the integral of m at the start."""

    name = "recording"

    def __init__(self):
        self.moments: list[tuple] = []

    def start(self, run):
        self.moments.append(("start", run.step_index, run.time))
        self.initial_mass = run.field_statistics()["m"]["integral"]

    def record(self, run):
        self.moments.append(("record", run.step_index, run.time))

    def snapshot(self, run):
        self.moments.append(("snapshot", run.step_index, run.time))

    def rejection(self, run, event):
        self.moments.append(("rejection", run.step_index, event["time"], event["dt"]))

    def finish(self, run, status):
        self.moments.append(("finish", run.step_index, run.time, status))


class WatchingPlugin:
    @hookimpl
    def primordia_physics(self):
        return [Recorder]

    @hookimpl
    def primordia_outputs(self):
        return [Recording]


@pytest.fixture(scope="module")
def watching():
    with registered(WatchingPlugin(), name="tests.unit.test_orchestrator"):
        yield


def model(t_final=1.0, recorder=None, output=None, **changes) -> Model:
    return Model(**{"physics": ["recorder", "chemotaxis"], "parameters": {"m0": 0.75},
                    "mesh": rectangle((0.0, 0.0), (4.0, 4.0), cells=(4, 4)), "dt": DT, "t_final": t_final,
                    "output": {"pictures": False, **(output or {})}, "physics_options": {"recorder": recorder or {}},
                    **changes})


def recording(sim) -> Recording:
    (output,) = [o for o in sim.outputs if o.name == "recording"]
    return output


@pytest.fixture(scope="module")
def completed(watching, tmp_path_factory):
    """Five steps to t = 1, snapshots at 0.2, 0.6 and 1.0, a series point every second step."""
    out = tmp_path_factory.mktemp("completed")
    sim = Simulation(model(output={"times": [0.6, 0.2, 1.0], "series_every": 2}), backend="fenicsx",
                     out_dir=out, existing="refuse")
    sim.setup()
    assert (sim.status, sim.step_index, sim.time) == ("running", 0, 0.0)
    return sim.run()


# -- setup and the time loop --------------------------------------------------------------------
def test_modules_that_own_fields_are_set_up_first_then_every_module_initialised_then_stepped(completed):
    calls = completed.model.physics_objects[0].calls
    assert calls[0] == ("setup", ())  # listed first, set up after chemotaxis made m (a scalar)
    assert calls[1] == ("initialise",)
    steps = calls[2:]
    assert [name for name, *_ in steps] == ["before_step"] * 5
    assert [t for _, t, _ in steps] == pytest.approx([0.2, 0.4, 0.6, 0.8, 1.0], abs=1e-12)
    assert all(dt == DT for _, _, dt in steps)


def test_steps_and_time_are_counted_on_the_grid_of_dt(completed):
    assert (completed.status, completed.step_index) == ("completed", 5)
    assert completed.time == 5 * DT  # computed from the step count: no drift of a sum of dt
    assert completed.step_sizes() == {"dt": DT, "rejections": 0.0}
    counts = completed.iteration_counts()
    assert {"chemotaxis_m_linear_iterations", "chemotaxis_f_linear_iterations"} <= set(counts)
    assert all(len(its) == 5 for its in completed.iterations.values())  # one record per step and subproblem
    described = completed.series_descriptions()  # what series.nc's long_name and units read
    assert set(counts) | set(completed.step_sizes()) | set(completed.memory_use()) == set(described)
    assert described["chemotaxis_m_linear_iterations"] == (
        "linear (Krylov) iterations in the last step of chemotaxis_m", "1")


def test_output_times_and_t_final_are_reached_as_given_where_k_dt_is_off_by_round_off(watching, tmp_path):
    """dt = 0.1: 3 x 0.1 = 0.30000000000000004 and 7 x 0.1 = 0.7000000000000001.  The run reached and wrote
    those, so series.nc's ``sel(time=0.3)`` did not find the output time asked for."""
    import meshio

    sim = Simulation(model(t_final=0.7, dt=0.1, output={"times": [0.3, 0.7], "series_every": 1}),
                     backend="fenicsx", out_dir=tmp_path).setup().run()
    assert sim.time == 0.7 and json.loads((tmp_path / "summary.json").read_text())["time"] == 0.7
    with xr.open_dataset(tmp_path / "series.nc") as series:
        assert float(series.sel(time=0.3)["step"]) == 3 and float(series.sel(time=0.7)["step"]) == 7
        assert series["time"].values[1] == 0.1  # the other steps stay on the grid t_start + k dt
    with meshio.xdmf.TimeSeriesReader(tmp_path / "fields.xdmf") as reader:
        reader.read_points_cells()
        assert [reader.read_data(k)[0] for k in range(reader.num_steps)] == [0.3, 0.7]


def test_outputs_are_called_at_start_at_series_steps_at_snapshot_times_and_at_the_end(completed):
    moments = recording(completed).moments
    assert moments[0] == ("start", 0, 0.0)
    assert moments[-1] == ("finish", 5, 5 * DT, "completed")
    assert [(step, t) for moment, step, t in moments[1:-1] if moment == "snapshot"] == \
        [(1, 0.2), (3, 0.6), (5, 1.0)]  # output.times, sorted, hit exactly: as given, not 3 * DT
    # every series_every = 2 steps and at every snapshot
    assert [step for moment, step, _ in moments[1:-1] if moment == "record"] == [1, 2, 3, 4, 5]
    assert not [m for m in moments if m[0] == "rejection"]


def test_the_summary_states_the_run(completed):
    summary = json.loads((completed.out_dir / "summary.json").read_text())
    # the times too, asked after the run ended (a notebook's next cell): they counted the time since as the run's
    assert summary == completed.summary("completed") | {"peak_memory_mb": summary["peak_memory_mb"]}
    assert summary["wall_time_s"] == completed.wall_time
    assert (summary["status"], summary["backend"], summary["mpi_ranks"]) == ("completed", "fenicsx", 1)
    assert (summary["steps"], summary["time"], summary["dt"]) == (5, 5 * DT, DT)
    assert summary["cells"] == 32
    assert summary["dofs"] == {"m": 25, "e": 25, "f": 25, "b": 25} and summary["dofs_total"] == 100
    assert (summary["rejected_steps"], summary["restarts"], summary["checkpoint_step"]) == (0, 0, 5)
    assert summary["splitting_scheme"] == "sequential"
    assert set(summary["mean_linear_iterations"]) == {"chemotaxis.m", "chemotaxis.e", "chemotaxis.f", "chemotaxis.b"}
    solves = summary["linear_solve_ms_per_step"]  # what each step's linear algebra costs, by subproblem
    assert set(solves) == set(summary["mean_linear_iterations"]) and min(solves.values()) >= 0.0
    assert 0.0 < sum(solves.values()) < summary["ms_per_step"]
    assert summary["wall_time_s"] > 0 and summary["ms_per_step"] == pytest.approx(1e3 * summary["wall_time_s"] / 5)
    # the 4 steps after the first (which loads the forms and sets the solvers up) took part of the wall time
    assert 0.0 < 4 * summary["ms_per_step_after_first"] < 1e3 * summary["wall_time_s"]
    # this process's peak resident memory: more than the interpreter alone, less than the machine
    assert 50.0 < summary["peak_memory_mb"] < 1e6
    with xr.open_dataset(completed.out_dir / "series.nc") as series:  # and the memory at every record
        assert np.all(series["memory_mb"].values > 50.0)
        assert np.all(series["memory_mb"].values <= series["peak_memory_mb"].values)
    final = summary["final"]
    assert set(final) == {"m", "e", "f", "b"}
    # zero-flux boundaries and no reaction in the cell equation: the cells are conserved (seed (2.3a), (2.7a))
    assert final["m"]["integral"] == pytest.approx(recording(completed).initial_mass, rel=1e-9)
    assert final["m"]["integral"] == pytest.approx(0.75 * 16, rel=1e-2)
    values = completed.vertex_values()
    for name, stats in final.items():
        assert (stats["min"], stats["max"]) == (float(values[name].min()), float(values[name].max()))


def test_a_scalar_field_s_integral_is_its_values_against_its_basis_integrals(completed):
    """The series' integrals of the species (whole P1 functions) are dot products with the integrals of the
    basis functions, and equal the assembled integrals."""
    for name in ("m", "e", "f", "b"):
        assert completed._integral_weights[name] is not None
        field = completed.disc.field(name)
        assembled = completed.backend.assemble_scalar(field * completed.disc.dx)
        assert completed._integral(name) == pytest.approx(assembled, rel=1e-13)
    weights = completed._integral_weights["m"]
    assert weights.sum() == pytest.approx(16.0, rel=1e-13)  # the basis functions sum to 1: the area of (0, 4)^2
    assert completed.field_statistics()["m"]["integral"] == completed._integral("m")


def test_field_statistics_are_computed_once_per_state(watching, tmp_path, monkeypatch):
    """A row of the series and the summary written with it ask for them in turn: the second is served, and
    the next accepted step computes them again, from its own fields."""
    sim = Simulation(model(t_final=0.4), backend="fenicsx", out_dir=tmp_path).setup()
    asked = []
    extrema = sim.backend.vertex_extrema
    monkeypatch.setattr(sim.backend, "vertex_extrema", lambda *args: asked.append(args) or extrema(*args))
    first = sim.field_statistics()  # the series' first row computed them at set-up
    assert sim.field_statistics() == first and asked == []
    sim.step()
    later = sim.field_statistics()
    assert sim.field_statistics() == later and len(asked) == len(first)
    for name, stats in later.items():
        assert (stats["min"], stats["max"]) == extrema(*sim.disc.function_of(name))
        assert stats["integral"] == sim._integral(name)
    assert later != first


def test_a_completed_run_leaves_a_checkpoint_and_its_outputs(completed):
    written = {path.name for path in completed.out_dir.iterdir()}
    assert {"summary.json", "config.toml", "checkpoint.npz"} <= written


# -- error paths ---------------------------------------------------------------------------------
def one_line(caught) -> str:
    message = str(caught.value)
    assert "\n" not in message, message
    return message


def test_a_directory_holding_a_run_is_refused_unless_told(watching, completed):
    with pytest.raises(ConfigError) as caught:
        Simulation(model(), out_dir=completed.out_dir, existing="refuse").setup()
    assert "already holds" in one_line(caught)
    assert "use --overwrite to replace it, or --restart" in str(caught.value)
    assert "from Python: Model.run(..., overwrite=True) or restart=True" in str(caught.value)


def test_a_simulation_is_set_up_and_stepped_once_and_only_to_t_final(watching, tmp_path):
    """setup() again on a finished Simulation claimed its folder again, as overwrite: it cleared the run's fields
    and checkpoint; step() after the end went past t_final without a word; step() or run() before setup() was
    an AttributeError from inside."""
    sim = model(t_final=0.4).run(out=tmp_path / "run", overwrite=True)
    written = sorted(path.name for path in sim.out_dir.iterdir())
    with pytest.raises(ConfigError) as caught:
        sim.setup()
    assert one_line(caught).startswith("this Simulation is set up already (completed, t = 0.4): a Simulation runs once")
    assert sorted(path.name for path in sim.out_dir.iterdir()) == written and "fields.xdmf" in written
    with pytest.raises(ConfigError) as caught:
        sim.step()
    assert one_line(caught).startswith("the run has reached t_final = 0.4; to go further, continue it")
    assert (sim.time, sim.step_index) == (0.4, 2)
    fresh = Simulation(model(), out_dir=tmp_path / "fresh")
    for method in (fresh.step, fresh.run):
        with pytest.raises(ConfigError, match=r"^Simulation\.(step|run)\(\) needs setup\(\) first"):
            method()


def test_python_s_restart_and_overwrite_together_are_refused(completed):
    """Both true silently restarted; the command line refuses --restart with --overwrite."""
    with pytest.raises(ConfigError, match="restart=True continues the run in out, overwrite=True replaces it"):
        model().run(out=completed.out_dir, restart=True, overwrite=True)


def test_a_restart_needs_a_checkpoint(watching, tmp_path):
    with pytest.raises(ConfigError) as caught:
        Simulation(model(), out_dir=tmp_path / "empty", existing="restart").setup()
    assert "holds no checkpoint to restart from" in one_line(caught)


def test_an_output_directory_that_is_a_file(watching, tmp_path):
    (tmp_path / "file").write_text("")
    with pytest.raises(ConfigError) as caught:
        Simulation(model(), out_dir=tmp_path / "file").setup()
    assert one_line(caught) == f"the output directory {tmp_path / 'file'} is a file, not a directory"


def test_a_run_from_python_is_in_progress_while_its_process_runs(watching, tmp_path):
    """A run's process was told from a recycled pid by its command line naming primordia, which a script's or a
    Jupyter kernel's does not: its run was called "killed without a word" while it ran, and another process's
    overwrite (or restart) was let into its folder."""
    import socket
    import subprocess
    import sys
    import time

    from primordia.core.outputs import existing_run

    out = tmp_path / "live"
    script = ("from primordia import Model\nfrom primordia.core.meshes import rectangle\n"
              "Model(physics=['chemotaxis'], parameters={'m0': 0.75}, mesh=rectangle((0, 0), (4, 4), cells=(4, 4)), "
              f"dt=0.2, t_final=1e5, output={{'pictures': False}}).run(out={str(out)!r})\n")
    (tmp_path / "notebook.py").write_text(script)  # a command line without the word primordia
    process = subprocess.Popen([sys.executable, "notebook.py"], cwd=tmp_path, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        while not (out / "summary.json").is_file():  # written whole (atomically), saying "running"
            assert process.poll() is None and time.monotonic() < deadline, process.stderr.read().decode()
            time.sleep(0.1)
        assert existing_run(out) == f"a run in progress (process {process.pid} on {socket.gethostname()})"
        with pytest.raises(ConfigError) as caught:
            Simulation(model(), out_dir=out, existing="overwrite").setup()
        assert one_line(caught).endswith("; stop it first")
        summary = json.loads((out / "summary.json").read_text())
        summary["process"]["started"] += 1  # the same pid, another process: the run's was recycled
        (out / "summary.json").write_text(json.dumps(summary))
        assert existing_run(out).startswith("a run that was killed without a word")
    finally:
        process.kill()
        process.wait()


def test_a_killed_run_is_said_as_far_as_its_checkpoint_got(watching, tmp_path):
    """The summary is rewritten at series times only: a run killed after its checkpoint of step 5 was said
    "killed without a word at 0 steps, t = 0.0" (found by the cluster QA pass)."""
    from primordia.core.outputs import existing_run

    out = tmp_path / "killed"
    model(t_final=1.0).run(out=out)
    summary = json.loads((out / "summary.json").read_text())
    summary.update(status="running", steps=0, time=0.0, process={"pid": 2**22 + 7, "host": "nowhere"})
    (out / "summary.json").write_text(json.dumps(summary))  # as written at the start, then SIGKILL
    assert existing_run(out) == "a run that was killed without a word after 5 steps, t = 1 (its process 4194311 " \
                                "is gone)"
    (out / "checkpoint.npz").unlink()
    assert existing_run(out).startswith("a run that was killed without a word after 0 steps, t = 0.0 ")


@pytest.mark.parametrize("changes, fragment", [
    ({"backend": "fenics"}, "fenics"),
    ({"coupling": "leapfrog"}, "leapfrog"),
])
def test_an_unknown_backend_or_scheme_is_refused_before_any_assembly(watching, tmp_path, changes, fragment):
    with pytest.raises(PluginError) as caught:
        model(**changes).run(out=tmp_path)
    assert fragment in one_line(caught)


def test_a_field_no_module_provides_is_named_when_the_model_is_composed(watching, tmp_path):
    """Before, at set-up: ``--dry-run`` said the input was valid (active_stress without poroelasticity)."""
    with pytest.raises(ConfigError) as caught:
        model(recorder={"read": "u"})
    assert one_line(caught) == ("physics recorder requires 'u', which no physics module of this model provides "
                                "(fields: m, e, f, b)")
    with pytest.raises(ConfigError) as caught:
        model(recorder={"read": "lame_constants"})
    assert one_line(caught).endswith("(fields: m, e, f, b); physics poroelasticity provides it")


def test_a_restart_of_another_model_names_what_differs(watching, completed, tmp_path):
    shutil.copytree(completed.out_dir, tmp_path / "run")
    other = model(parameters={"m0": 0.75, "D_m": 0.05})
    with pytest.raises(ConfigError) as caught:
        Simulation(other, out_dir=tmp_path / "run", existing="restart").setup()
    assert "parameters.D_m differs from the checkpointed run's" in one_line(caught)


def test_a_restart_writes_an_output_time_it_is_at_and_refuses_one_it_has_passed(watching, tmp_path):
    """A run that ended at t = 0.6 with fields at 0.4, restarted with output.times = [0.4, 0.6], "completed"
    and fields.xdmf held 0.4 only; with [0.2, 0.4] it did not say that 0.2 was behind it, never to be written."""
    def xdmf_times():
        with meshio.xdmf.TimeSeriesReader(tmp_path / "fields.xdmf") as reader:
            reader.read_points_cells()
            return [reader.read_data(k)[0] for k in range(reader.num_steps)]

    Simulation(model(t_final=0.6, output={"times": [0.4]}), out_dir=tmp_path).setup().run()
    with pytest.raises(ConfigError) as caught:
        Simulation(model(t_final=0.6, output={"times": [0.2, 0.4]}), out_dir=tmp_path, existing="restart").setup()
    assert one_line(caught) == (f"cannot restart from {tmp_path / 'checkpoint.npz'}: output time 0.2 is before "
                                f"its t = 0.6, and the run did not write the fields there (a restart writes "
                                f"later times, and the time it is at)")
    for _ in range(2):  # written once, at the restart; the next restart finds it written
        Simulation(model(t_final=0.6, output={"times": [0.4, 0.6]}), out_dir=tmp_path, existing="restart").setup().run()
        assert xdmf_times() == [0.4, 0.6]


def test_restarts_with_no_step_left_are_counted(watching, tmp_path):
    """A restart of a completed run with the same t_final wrote no checkpoint, so the next one counted from the
    same number: summary.json said 1 restart after two."""
    Simulation(model(t_final=0.4), out_dir=tmp_path).setup().run()
    for count in (1, 2):
        Simulation(model(t_final=0.4), out_dir=tmp_path, existing="restart").setup().run()
        assert json.loads((tmp_path / "summary.json").read_text())["restarts"] == count


def test_a_restart_on_a_mesh_file_changed_since_the_checkpoint_is_refused(watching, tmp_path):
    """The resolved config names a mesh file by its path only: a file rewritten between the run and its restart
    (here one interior vertex moved, the same topology) loaded the checkpoint's fields onto the other mesh, and
    fields.xdmf went on describing the first one."""
    square = rectangle((0.0, 0.0), (4.0, 4.0), cells=(4, 4))
    path = tmp_path / "tissue.vtu"
    flat = np.column_stack([square.points, np.zeros(square.num_vertices)])  # z = 0, as most files hold it
    meshio.write(path, meshio.Mesh(flat, [("triangle", square.cells)]))
    Simulation(model(t_final=0.4, mesh=read_mesh(path)), out_dir=tmp_path / "run", existing="refuse").setup().run()
    moved = flat.copy()
    moved[6, :2] += 0.1  # an interior vertex of the 5 x 5 grid
    meshio.write(path, meshio.Mesh(moved, [("triangle", square.cells)]))
    with pytest.raises(ConfigError) as caught:
        Simulation(model(t_final=0.6, mesh=read_mesh(path)), out_dir=tmp_path / "run", existing="restart").setup()
    assert one_line(caught).endswith(f"the mesh read from {path.resolve()} differs from the checkpointed run's "
                                     f"(a restart continues the same model)")


def test_a_failed_step_is_retried_in_halves_and_the_grid_of_dt_is_kept(watching, tmp_path):
    sim = Simulation(model(t_final=0.6, recorder={"fail_at": 0.4, "fail_dt": DT}), out_dir=tmp_path).setup().run()
    assert (sim.status, sim.step_index, sim.time) == ("completed", 3, 0.6)  # t_final as given, not 3 * DT
    assert len(sim.rejections) == 1
    (rejection,) = sim.rejections
    assert (rejection["time"], rejection["dt"]) == (pytest.approx(0.2), DT)
    assert "injected failure at t = 0.4" in rejection["reason"]
    steps = [(t, dt) for name, *rest in sim.model.physics_objects[0].calls[2:] if name == "before_step"
             for t, dt in [rest]]
    # step 2 failed whole, then went in two halves; step 3 grew back to dt (a step that follows two halves)
    assert [dt for _, dt in steps] == pytest.approx([0.2, 0.2, 0.1, 0.1, 0.2])
    assert [t for t, _ in steps] == pytest.approx([0.2, 0.4, 0.3, 0.4, 0.6])
    assert ("rejection", 1, pytest.approx(0.2), DT) in recording(sim).moments
    assert json.loads((tmp_path / "summary.json").read_text())["rejected_steps"] == 1


def test_a_run_stopped_inside_a_step_restarts_on_the_grid_of_that_step(watching, tmp_path):
    """Step 2 fails whole, its first half goes through and its second half cannot be halved (dt_min): the run
    stops at t = 0.3, inside step 2, and its checkpoint holds that state.  The restart (with the fault mended:
    a changed ``[solver]`` table is the user's way) takes the second half, t = 0.3 -> 0.4 with dt = 0.1.  It
    took halves of what was left of the step (0.3 -> 0.35) with halves of dt (0.1): the physics were at
    t = 0.45 when the run's clock reached the end of step 2, t = 0.4."""
    failing = model(t_final=0.6, recorder={"fail_at": 0.4}, dt_min=0.1)
    with pytest.raises(SolverError):
        Simulation(failing, out_dir=tmp_path).setup().run()
    sim = Simulation(model(t_final=0.6, recorder={"fail_at": 0.4}, dt_min=0.1), out_dir=tmp_path,
                     existing="restart").setup()
    assert (sim.step_index, sim.time) == (1, pytest.approx(0.3))
    recorder = sim.model.physics_objects[0]
    recorder.settings["fail_at"] = -1.0
    sim.run()
    assert (sim.status, sim.step_index, sim.time) == ("completed", 3, 0.6)
    # each sub-step's end time and dt, as the physics see them: the second half of step 2, then step 3 whole
    steps = [(t, dt) for name, *rest in recorder.calls if name == "before_step" for t, dt in [rest]]
    assert steps == [(pytest.approx(0.4), 0.1), (pytest.approx(0.6), 0.2)]


def test_a_restart_inside_a_step_past_t_final_is_refused(watching, tmp_path):
    """A run stopped at t = 0.3, inside step 2, restarted with t_final = 0.2: step 1 was not past its one step,
    so the run "completed" at t = 0.3, past its t_final, with the fields of 0.3 as its last."""
    with pytest.raises(SolverError):
        Simulation(model(t_final=0.6, recorder={"fail_at": 0.4}, dt_min=0.1), out_dir=tmp_path).setup().run()
    with pytest.raises(ConfigError) as caught:
        Simulation(model(t_final=0.2, recorder={"fail_at": 0.4}, dt_min=0.1, output={"times": []}), out_dir=tmp_path,
                   existing="restart").setup()
    assert one_line(caught) == (f"cannot restart from {tmp_path / 'checkpoint.npz'}: it is at t = 0.3, "
                                f"past time.t_final = 0.2")


def test_without_adaptive_steps_a_failed_step_stops_the_run_naming_it(watching, tmp_path):
    sim = Simulation(model(t_final=0.6, recorder={"fail_at": 0.4}, adaptive=False), out_dir=tmp_path).setup()
    with pytest.raises(SolverError) as caught:
        sim.run()
    # with how the run goes on (the restart QA pass: the README said --restart continues it, the line
    # did not): from the checkpoint of the steps before, with what a restart may change
    assert one_line(caught) == ("step 2 (t = 0.2 -> 0.4): recorder: injected failure at t = 0.4; primordia run "
                                f"--restart {tmp_path} continues it from its checkpoint at t = 0.2 (a restart may "
                                "change [solver], time.adaptive and time.dt_min)")
    assert (sim.step_index, sim.time) == (1, DT)  # the failed step was undone
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"].startswith("stopped at t = 0.2: step 2 (t = 0.2 -> 0.4)")
    assert summary["checkpoint_step"] == 1  # the whole steps are kept for a restart


def test_a_run_on_a_mesh_made_in_python_says_how_python_continues_it(watching, tmp_path):
    """It said "primordia run --restart OUT", which cannot rebuild a mesh config.toml holds no table of (it refuses
    such a run in one line): Python's words instead (the restart QA pass)."""
    from primordia.core.mesh_data import MeshData

    generated = rectangle((0.0, 0.0), (4.0, 4.0), cells=(4, 4))
    by_hand = MeshData(generated.points.copy(), generated.cells.copy(), dict(generated.boundaries))
    sim = Simulation(model(t_final=0.6, recorder={"fail_at": 0.4}, adaptive=False, mesh=by_hand), out_dir=tmp_path)
    with pytest.raises(SolverError) as caught:
        sim.setup().run()
    assert one_line(caught).endswith(f"; Simulation(model, out_dir={str(tmp_path)!r}, existing=\"restart\") "
                                     "continues it from its checkpoint at t = 0.2 (a restart may change [solver], "
                                     "time.adaptive and time.dt_min)"), one_line(caught)
    assert not Simulation(model(), out_dir=tmp_path / "other").restart_hint.startswith("Simulation(")


def test_memory_the_process_freed_is_given_back_to_the_system():
    """glibc keeps freed heap memory for later: without a trim the resident size stays at its peak
    (example 2b at 171^2: 2.77 GB kept, 1.83 GB after a trim)."""
    import ctypes

    from primordia.coupling.orchestrator import release_free_memory, resident_memory_mb

    libc = ctypes.CDLL("libc.so.6")
    libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    blocks = [libc.malloc(4096) for _ in range(40_000)]  # 160 MB of small blocks, on the heap
    for block in blocks:
        ctypes.memset(block, 1, 4096)  # touched: resident
    for block in blocks[:-1]:
        libc.free(block)  # the last one pins the top of the heap: only a trim can give the rest back
    before = resident_memory_mb()[0]
    assert release_free_memory()
    after = resident_memory_mb()[0]
    libc.free(blocks[-1])
    assert before - after > 100, (before, after)


def test_a_finished_runs_petsc_objects_are_freed_when_the_next_run_begins(watching, tmp_path, capfd, monkeypatch):
    """A run's PETSc objects dropped after its last step, with its Simulation, waited in the garbage of dolfinx's
    communicators, which nothing cleaned again: a loop of runs in one process kept every earlier run's matrices
    and vectors (3.5 MB a run at 86^2 squares, 13 MB at 172^2). The next fenicsx backend cleans them up and lets
    those communicators go."""
    import gc

    import primordia.backends.fenicsx as fenicsx
    from petsc_garbage import garbage_report

    first = model(t_final=0.4).run(out=tmp_path / "first")
    keepers = list(first.backend._petsc_comms.values())
    comms = {keeper.getComm().tompi4py().py2f(): keeper.getComm() for keeper in keepers}
    del first
    gc.collect()
    empty, report = garbage_report(comms.values(), capfd)
    assert empty < len(comms), report  # the run's objects wait in its communicators' garbage
    cleaned, cleanup = [], fenicsx.PETSc.garbage_cleanup
    monkeypatch.setattr(fenicsx.PETSc, "garbage_cleanup", lambda comm: cleaned.append(comm.tompi4py().py2f())
                        or cleanup(comm))
    fenicsx.FenicsxBackend()  # the next run's
    monkeypatch.undo()
    assert set(comms) <= set(cleaned) and not any(keepers)  # cleaned, then the communicators let go


def test_a_finished_skfem_run_is_not_kept_alive_by_the_next(watching, tmp_path):
    """The integrands analysed for evaluation were cached process-wide (the last 256), and each held its run's
    spaces and mesh: a loop of runs in one process kept the last 20 or so alive (9.5 MB a run at 86^2 squares)."""
    import gc
    import weakref

    from primordia.backends.skfem import SkfemBackend

    first = model(t_final=0.4).run(backend="skfem", out=tmp_path / "first")
    mesh = weakref.ref(first.disc.mesh)
    del first
    SkfemBackend()  # the next run's
    gc.collect()
    assert mesh() is None


def test_solvers_made_anew_give_the_old_ones_memory_back(watching, tmp_path, monkeypatch):
    import primordia.coupling.orchestrator as orchestrator

    released = []
    sim = Simulation(model(), out_dir=tmp_path / "run").setup()
    monkeypatch.setattr(orchestrator, "release_free_memory", lambda: released.append(sim.solvers) or True)
    old = sim.solvers
    sim._create_solvers()  # as at a checkpoint
    assert len(released) == 1 and released[0] is not old  # after the old solvers went, the new made


def test_the_time_of_the_solves_counts_on_when_solvers_are_made_anew(watching, tmp_path):
    sim = Simulation(model(), out_dir=tmp_path / "run").setup()
    for _ in range(3):
        sim.step()
    before = sim.linear_solve_ms()
    clocks = {clock: sim.linear_solve_seconds(clock) for clock in ("cpu", "wall")}
    sim._create_solvers()  # as at a checkpoint: the new solvers start from zero
    assert sim.linear_solve_ms() == before and sum(before.values()) > 0.0
    assert {clock: sim.linear_solve_seconds(clock) for clock in ("cpu", "wall")} == clocks
    # each clock its own: the wall time of the solves is there, and is not the CPU time
    assert sum(clocks["wall"].values()) > 0.0 and clocks["wall"] != clocks["cpu"]


def test_the_series_ends_with_the_last_state_whatever_series_every_says(watching, tmp_path):
    """t_final neither an output time nor a multiple of series_every: the series stopped at the last multiple."""
    Simulation(model(t_final=1.0, dt=0.2, output={"times": [0.4], "series_every": 3}), backend="skfem",
               out_dir=tmp_path).setup().run()
    with xr.open_dataset(tmp_path / "series.nc") as series:
        assert [int(step) for step in series["step"].values] == [0, 2, 3, 5]


def test_a_checkpoint_is_written_whole_whatever_signals_arrive_meanwhile(completed, monkeypatch):
    """A second signal while a stopping run wrote its checkpoint aborted the write (found through a sweep that
    stops its runs: "Exception ignored in ZipFile.__del__"): the run said it stopped at t, its checkpoint
    was older. The signals are counted and the checkpoint is written whole."""
    import signal

    from primordia.core import checkpoint
    from primordia.core.signals import INTERRUPTS

    real = checkpoint.write

    def write(path, tree):
        INTERRUPTS._handle(signal.SIGTERM, None)
        INTERRUPTS._handle(signal.SIGTERM, None)  # a second signal: "at once" outside the write
        return real(path, tree)

    monkeypatch.setattr(checkpoint, "write", write)
    try:
        with INTERRUPTS.mode_of("deferred"):
            completed.write_checkpoint()
        assert INTERRUPTS.count == 2 and INTERRUPTS.urgent  # noted for the run to stop at once afterwards
    finally:
        INTERRUPTS.reset()
    meta = checkpoint.read_meta(completed.out_dir / checkpoint.CHECKPOINT_FILE)
    assert meta["run"]["step"] == completed.step_index


@pytest.mark.parametrize("when", ["in a step", "while the run ends"])
def test_a_signal_one_run_received_does_not_stop_the_next_run_in_the_process(watching, tmp_path, monkeypatch, when):
    """A Ctrl-C that stopped a run from Python (a notebook's interrupt), or one that came while a run wrote its
    last outputs (counted, not raised), stayed noted: every later run in the process stopped after its first
    step, "interrupted at t = 0.2 (Ctrl-C)"."""
    import signal

    from primordia.core.errors import InterruptedRun
    from primordia.core.signals import INTERRUPTS

    def signal_in_a_step(self, t, dt):
        if abs(t - 2 * DT) < 1e-9:
            INTERRUPTS._handle(signal.SIGINT, None)

    def signal_while_ending(self, run, status):
        INTERRUPTS._handle(signal.SIGINT, None)

    try:
        if when == "in a step":
            monkeypatch.setattr(Recorder, "before_step", signal_in_a_step)
            with pytest.raises(InterruptedRun, match=r"^interrupted at t = 0\.4 \(Ctrl-C\)") as stopped:
                model(t_final=1.0).run(out=tmp_path / "first")
            # in Python's words: it said "continue it with: primordia run --restart OUT" to a notebook
            assert str(stopped.value).endswith(f"continue it with: Model.run(out={str(tmp_path / 'first')!r}, "
                                               f"restart=True)"), str(stopped.value)
        else:
            monkeypatch.setattr(Recording, "finish", signal_while_ending)
            assert model(t_final=0.4).run(out=tmp_path / "first").status == "completed"
        monkeypatch.undo()
        second = model(t_final=0.6).run(out=tmp_path / "second")
    except InterruptedRun as stopped:  # a KeyboardInterrupt would end the test session
        pytest.fail(f"the second run stopped: {stopped}")
    finally:
        INTERRUPTS.reset()
    assert (second.status, second.step_index) == ("completed", 3)
