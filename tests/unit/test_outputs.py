"""What a run writes (primordia.core.outputs): the options outputs declare, series, atomic files."""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr

from file_writers import WriterDied, leftovers
from primordia.core.errors import ConfigError, PluginError
from primordia.core.meshes import rectangle
from primordia.core.outputs import (
    FieldsXdmf,
    Output,
    OutputOption,
    Pictures,
    ScalarSeriesNetcdf,
    Summary,
    declared_options,
    field_names,
)
from primordia.core.plugins import hookimpl
from primordia.core.validation import flag, number
from primordia.model import Model
from primordia.physics.base import FieldSpec
from primordia.testing import registered

MESH = rectangle((0, 0), (4, 4), (4, 4))


def small_model(**output) -> Model:
    return Model(physics=["chemotaxis"], parameters={"m0": 0.75, "D_m": 0.03}, mesh=MESH, dt=0.2, t_final=0.6,
                 output={"times": [0.6], "pictures": False, **output})


# ---------------------------------------------------------------------------
# options an output declares
# ---------------------------------------------------------------------------


class CellCount(Output):
    """A third party's output with an option of its own: how often it counts the cells."""

    name = "cell_count"
    options = {"count_every": OutputOption(2, partial(number, integer=True, at_least=1), "steps between counts")}

    def start(self, run):
        self.every = run.model.output["count_every"]
        self.counted = []

    def record(self, run):
        if run.step_index % self.every == 0:
            self.counted.append(run.step_index)
        if run.is_root:
            (Path(run.out_dir) / "counted.json").write_text(json.dumps(self.counted))


class CellCountPlugin:
    @hookimpl
    def primordia_outputs(self):
        return [CellCount]


@pytest.fixture
def cell_count():
    with registered(CellCountPlugin()):
        yield


def test_a_plugin_output_option_is_accepted_with_its_default(cell_count):
    assert small_model().output["count_every"] == 2
    assert small_model(count_every=3).output["count_every"] == 3


def test_a_plugin_output_option_is_checked_by_its_declaration(cell_count):
    with pytest.raises(ConfigError) as caught:
        small_model(count_every=0)
    assert str(caught.value) == "output.count_every must be an integer >= 1, got 0"


def test_an_unknown_output_key_is_one_error_listing_the_declared_ones(cell_count):
    with pytest.raises(ConfigError) as caught:
        small_model(count_evry=3)
    message = str(caught.value)
    assert message.startswith("unknown key output.count_evry (known: ") and "\n" not in message
    assert all(key in message for key in ("times", "series_every", "pictures", "displacement_scale", "count_every"))


def test_without_its_plugin_the_option_is_unknown():
    with pytest.raises(ConfigError, match="unknown key output.count_every"):
        small_model(count_every=3)


def test_a_run_hands_the_option_to_its_output(cell_count, tmp_path):
    small_model(count_every=3, series_every=1).run(backend="skfem", out=tmp_path)  # steps 1, 2, 3
    assert json.loads((tmp_path / "counted.json").read_text()) == [3]  # by the default, 2: [2]


def test_a_key_two_outputs_declare_is_refused():
    class Thumbnails(Output):
        name = "thumbnails"
        options = {"pictures": OutputOption(False, flag)}

    with pytest.raises(ConfigError, match="'pictures' is declared by two outputs, 'pictures' and 'thumbnails'"):
        declared_options([Pictures, Thumbnails])


@pytest.mark.parametrize("options, message", [
    ({"times": OutputOption(3, flag)}, "output thumbnails declares output.times, a key of the output schedule "
                                       "(series_every, times): it must rename its option"),
    ({"size": 5}, "output thumbnails: its options must be a table of primordia.core.outputs.OutputOption, "
                  "got {'size': 5}"),
    # until 2026-12-05 the output was handed the default its own check refuses
    ({"size": OutputOption(-1.0, partial(number, at_least=0))},
     "output thumbnails declares output.size with the default -1.0, not a valid value of it: output.size must be "
     "a number >= 0, got -1.0"),
    ({"thumbnail_fields": OutputOption("m", field_names, names_fields=True)},
     "output thumbnails declares output.thumbnail_fields with the default 'm', not a valid value of it: "
     "output.thumbnail_fields must be a list of field names, got 'm'"),
])
def test_an_output_declaring_options_wrongly_is_one_line_naming_it(options, message):
    """Before, a key of the schedule was checked by the output's check ("output.times must be true or false,
    got [0.6]", the user blamed), and a plain value was an AttributeError traceback at the model's set-up."""
    thumbnails = type("Thumbnails", (Output,), {"name": "thumbnails", "options": options})
    plugin = SimpleNamespace(primordia_outputs=hookimpl(lambda: [thumbnails]))
    with registered(plugin), pytest.raises(PluginError) as caught:
        small_model()
    assert str(caught.value) == message


def test_an_output_that_fails_mid_run_warns_on_a_line_of_its_own(capsys, tmp_path):
    """The warning continued the progress bar's line: "  0%|   | step 0/3  [00:00<?]primordia: warning: ..."."""
    class Failing(Output):
        name = "failing"

        def snapshot(self, run):
            raise OSError("disk full")

    plugin = SimpleNamespace(primordia_outputs=hookimpl(lambda: [Failing]))
    with registered(plugin):
        small_model().run(backend="skfem", out=tmp_path, progress=True)
    err = capsys.readouterr().err
    before = err[:err.index("primordia: warning: output 'failing' failed")]
    assert before.endswith(("\r", "\n")), repr(before[-80:])


@pytest.mark.parametrize("output, message", [
    ({"pictures": "false"}, "output.pictures must be true or false, got 'false'"),
    ({"displacement_scale": -1}, "output.displacement_scale must be a number >= 0, got -1"),
    ({"series_every": 0}, "output.series_every must be an integer >= 1 (steps), got 0"),
    ({"times": [0.6, "end"]}, "output.times[1] must be a number, got 'end'"),
])
def test_built_in_options_are_checked_in_one_line(output, message):
    with pytest.raises(ConfigError) as caught:
        small_model(**output)
    assert str(caught.value) == message


def test_the_resolved_output_table_holds_every_declared_default():
    output = small_model().output
    assert output["pictures"] is False and output["displacement_scale"] == 1.0 and output["series_every"] == 10


# ---------------------------------------------------------------------------
# series, through a stand-in for a run
# ---------------------------------------------------------------------------


class StandInRun:
    """What outputs read of a run, without a finite element solve: m = t everywhere."""

    class OneRank:
        size, rank = 1, 0

    def __init__(self, out_dir: Path):
        self.out_dir, self.mesh_data, self.is_root, self.comm = out_dir, MESH, True, self.OneRank()
        self.time, self.step_index = 0.0, 0
        self.outputs: list = []  # the outputs the run calls, in order (the summary looks for the series)
        self.diagnostics: list = []  # the physics' Diagnostics (their descriptions name series variables)
        self.model, self.backend = SimpleNamespace(name="stand-in"), SimpleNamespace(name="none")
        self.scheme = SimpleNamespace(name="sequential")

    def advance(self, dt: float = 0.2) -> None:
        self.time, self.step_index = round(self.time + dt, 12), self.step_index + 1

    def vertex_values(self):
        return {"m": np.full(MESH.num_vertices, self.time)}

    def field_specs(self):
        return {"m": FieldSpec("m")}

    def field_statistics(self):
        return {"m": {"integral": 16 * self.time, "min": self.time, "max": self.time}}

    def diagnostic_values(self):
        return {}

    def iteration_counts(self):
        return {"newton_iterations": 2}

    def step_sizes(self):
        return {"dt": 0.2}

    def memory_use(self):
        return {"memory_mb": 100.0 + self.step_index, "peak_memory_mb": 150.0}

    def series_descriptions(self):
        return {"newton_iterations": ("Newton iterations in the last step", "1"),
                "dt": ("the last sub-step's length", "1"),
                "memory_mb": ("resident memory, summed over the ranks (MiB)", "1048576 byte"),
                "peak_memory_mb": ("peak resident memory so far, summed over the ranks (MiB)", "1048576 byte")}

    def summary(self, status):
        return {"status": status, "steps": self.step_index, "time": self.time}


def test_the_scalar_series_has_a_row_per_record_and_continues_from_a_state(tmp_path):
    run, series = StandInRun(tmp_path), ScalarSeriesNetcdf()
    series.start(run)
    run.advance()
    series.record(run)
    state = series.state()
    run.advance()
    series.record(run)  # written after the checkpoint: gone when the run continues from it
    series.finish(run, "completed")  # rows recorded soon after a rewrite wait for the next one, or the end
    with xr.open_dataset(tmp_path / "series.nc", engine="scipy") as data:
        np.testing.assert_allclose(data["time"], [0.0, 0.2, 0.4])
        assert data.attrs["title"] == f"primordia scalar series of model 'stand-in' ({tmp_path.name})"
        assert data.attrs["source"].endswith("backend none, 1 MPI rank(s), splitting scheme sequential")
        # CF-1.8, whose units are UDUNITS-2's: "dimensionless" (the time's until 2026-12-05) is not one
        assert data.attrs["Conventions"] == "CF-1.8" and data["time"].attrs["units"] == "1"
        np.testing.assert_allclose(data["m_integral"], [0.0, 3.2, 6.4])
        np.testing.assert_allclose(data["memory_mb"], [100.0, 101.0, 102.0])
    resumed = ScalarSeriesNetcdf()
    resumed.resume(run, state)
    with xr.open_dataset(tmp_path / "series.nc", engine="scipy") as data:
        np.testing.assert_allclose(data["time"], [0.0, 0.2])
        assert data.attrs["title"].startswith("primordia scalar series")  # a continued run's file keeps them
    assert leftovers(tmp_path) == []


def test_the_summary_is_rewritten_with_the_series_not_at_every_row(tmp_path, monkeypatch):
    """At a series time summary.json is rewritten when series.nc just was (at most every SERIES_INTERVAL
    seconds) or SUMMARY_INTERVAL after its own last rewrite; so it never describes fewer steps than
    series.nc, and a fast run does not pay two fsyncs and the run's statistics at every row."""
    import primordia.core.outputs as outputs
    import primordia.core.scalar_series as scalar_series

    clock = [100.0]
    for module in (outputs, scalar_series):
        monkeypatch.setattr(module.time, "monotonic", lambda: clock[0])
    run, series, summary = StandInRun(tmp_path), ScalarSeriesNetcdf(), Summary()
    run.outputs = [series, summary]

    def steps():
        with xr.open_dataset(tmp_path / "series.nc", engine="scipy") as data:
            written = int(data["step"].values[-1])
        return written, json.loads((tmp_path / "summary.json").read_text())["steps"]

    for output in run.outputs:
        output.start(run)
    assert steps() == (0, 0)
    def record():
        run.advance()
        for output in run.outputs:
            output.record(run)

    apart = outputs.SUMMARY_INTERVAL / 4
    for _ in range(3):  # rows closer than SUMMARY_INTERVAL: the series waits, and so does the summary
        clock[0] += apart
        record()
        assert steps() == (0, 0)
    clock[0] += apart  # SUMMARY_INTERVAL after its start: the summary alone
    record()
    assert steps() == (0, 4)
    while clock[0] + apart < 100.0 + outputs.SERIES_INTERVAL:  # the series waits; the summary every interval
        clock[0] += apart
        record()
        written, described = steps()
        assert written == 0 and run.step_index - 3 <= described <= run.step_index
    clock[0] += apart
    record()
    assert steps() == (run.step_index, run.step_index)  # the series is rewritten: the summary with it


def test_a_series_finished_before_it_started_writes_nothing_and_does_not_fail(tmp_path):
    """A Ctrl-C during start-up finishes the outputs, some of which never started."""
    run = StandInRun(tmp_path)
    ScalarSeriesNetcdf().finish(run, "interrupted")
    assert not (tmp_path / "series.nc").exists()


def test_the_fields_series_lists_every_snapshot(tmp_path):
    import meshio

    run, fields = StandInRun(tmp_path), FieldsXdmf()
    fields.start(run)
    for _ in range(2):
        run.advance()
        fields.snapshot(run)
    with meshio.xdmf.TimeSeriesReader(tmp_path / "fields.xdmf") as reader:
        reader.read_points_cells()
        times = [reader.read_data(k)[0] for k in range(reader.num_steps)]
    assert times == [0.2, 0.4]


# ---------------------------------------------------------------------------
# atomic files: a write that dies leaves the previous file
# ---------------------------------------------------------------------------


def test_an_interrupted_summary_write_leaves_the_previous_summary(tmp_path, monkeypatch):
    run, summary = StandInRun(tmp_path), Summary()
    summary.start(run)
    before = (tmp_path / "summary.json").read_bytes()
    assert json.loads(before)["status"] == "running"

    def die_half_way(self, data):
        with open(self, "wb") as partial_file:
            partial_file.write(data[: len(data) // 2])
        raise WriterDied("killed while writing summary.json")

    monkeypatch.setattr(Path, "write_bytes", die_half_way)
    run.advance()
    with pytest.raises(WriterDied):
        summary.finish(run, "completed")
    monkeypatch.undo()
    assert (tmp_path / "summary.json").read_bytes() == before
    assert leftovers(tmp_path) == []
    summary.finish(run, "completed")
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "completed"


# ---------------------------------------------------------------------------
# pictures shared out over the ranks
# ---------------------------------------------------------------------------
class _TwoRanks:
    """rank 0 of a two-rank communicator whose scatter keeps what each rank was given."""

    size, rank = 2, 0

    def __init__(self):
        self.shares = None

    def scatter(self, shares, root=0):
        self.shares = shares
        return shares[0]


class _Root:
    def __init__(self, comm, mesh_data=None):
        self.comm, self.is_root, self.mesh_data = comm, True, mesh_data


def test_the_pictures_of_one_moment_are_shared_out_largest_first():
    from primordia.core.outputs import _draw_shared

    drawn = []
    draw = lambda path, mesh, **arguments: drawn.append(path)  # noqa: E731
    comm = _TwoRanks()
    # example 1a's end: m's grid of four snapshots and the four fields; then one with three small ones
    _draw_shared(_Root(comm), lambda: [(4, draw, "m_snapshots.png", {}), (4, draw, "final_fields.png", {})])
    assert [[path for _, _, path, _ in share] for share in comm.shares] == [["m_snapshots.png"], ["final_fields.png"]]
    assert drawn == ["m_snapshots.png"]  # rank 0 draws its own share only
    _draw_shared(_Root(comm), lambda: [(1, draw, "a", {}), (3, draw, "b", {}), (1, draw, "c", {}), (1, draw, "d", {})])
    assert [[path for _, _, path, _ in share] for share in comm.shares] == [["b"], ["a", "c", "d"]]


def test_a_failure_listing_the_pictures_still_hands_the_other_ranks_their_share():
    """Rank 0 failing before the scatter would leave rank 1 waiting in it forever."""
    from primordia.core.outputs import _draw_shared

    def pictures():
        raise KeyError("m")

    comm = _TwoRanks()
    with pytest.raises(KeyError):
        _draw_shared(_Root(comm), pictures)
    assert comm.shares == [[], []]


def stop_with_ctrl_c(sim, monkeypatch, before_step: int) -> None:
    """Run ``sim`` to a Ctrl-C at the start of step ``before_step`` (0-based: after that many steps)."""
    from primordia.coupling.orchestrator import Simulation

    step = Simulation.step

    def interrupted(self):
        if self.step_index == before_step:
            raise KeyboardInterrupt
        step(self)

    monkeypatch.setattr(Simulation, "step", interrupted)
    with pytest.raises(KeyboardInterrupt):
        sim.run()


def test_a_run_stopped_early_draws_the_grid_of_the_snapshots_it_reached(tmp_path, monkeypatch):
    """The grid of the snapshot times is drawn when the run ends, and a run that stops (here a Ctrl-C
    after its third step) ends too: its grid holds the snapshots before the stop."""
    from primordia.coupling.orchestrator import Simulation

    model = Model(physics=["chemotaxis"], parameters={"m0": 0.75, "D_m": 0.03}, mesh=MESH, dt=0.2, t_final=1.0,
                  output={"times": [0.2, 0.4, 0.8], "pictures": True})
    sim = Simulation(model, backend="skfem", out_dir=tmp_path).setup()
    stop_with_ctrl_c(sim, monkeypatch, before_step=3)
    assert sim.status.startswith("interrupted at t = 0.6")
    pictures = {path.name for path in tmp_path.glob("*.png")}
    assert pictures == {"m_t0000.20.png", "m_t0000.40.png", "m_snapshots.png", "final_fields.png"}
    (output,) = [o for o in sim.outputs if o.name == "pictures"]
    assert list(output.snapshots["m"]) == ["m, t = 0.2", "m, t = 0.4"]



def test_a_run_stopped_between_output_times_titles_its_last_fields_by_the_time_of_its_step(tmp_path, monkeypatch):
    """A run stopped after three steps of 0.1 is at 0.1 + 0.1 + 0.1 = 0.30000000000000004: final_fields.png
    said "all fields at t = 0.30000000000000004 (interrupted at t = 0.3 (Ctrl-C))" (example 1a stopped by
    SIGTERM after 629 steps: "t = 125.80000000000001")."""
    from primordia.core import outputs
    from primordia.coupling.orchestrator import Simulation

    titles = []
    monkeypatch.setattr(outputs, "plot_fields_grid", lambda path, mesh, **drawn: titles.append(drawn["title"]))
    model = Model(physics=["chemotaxis"], parameters={"m0": 0.75, "D_m": 0.03}, mesh=MESH, dt=0.1, t_final=1.0,
                  output={"times": [1.0], "pictures": True})
    sim = Simulation(model, backend="skfem", out_dir=tmp_path).setup()
    stop_with_ctrl_c(sim, monkeypatch, before_step=3)
    assert sim.time == 0.1 + 0.1 + 0.1 != 0.3
    assert titles == ["all fields at t = 0.3 (interrupted at t = 0.3 (Ctrl-C))"]


def test_a_vector_snapshot_is_titled_by_the_magnitude_it_shows(tmp_path):
    """u's pictures show |u|: its snapshots were titled "u, t = 0.1" beside final_fields.png's "|u|"."""
    model = Model(physics=["poroelasticity"], parameters={"E": 100.0, "nu": 0.3}, mesh=MESH, dt=0.1, t_final=0.2,
                  physics_options={"poroelasticity": {"boundary": [{"boundary": "bottom", "type": "clamped"}]}},
                  output={"times": [0.1, 0.2], "pictures": True, "snapshot_fields": ["u", "p"]})
    sim = model.run(backend="skfem", out=tmp_path)
    (output,) = [o for o in sim.outputs if o.name == "pictures"]
    assert list(output.snapshots["u"]) == ["|u|, t = 0.1", "|u|, t = 0.2"]
    assert list(output.snapshots["p"]) == ["p, t = 0.1", "p, t = 0.2"]
    assert {path.name for path in tmp_path.glob("u_*.png")} == {"u_t0000.10.png", "u_t0000.20.png", "u_snapshots.png"}

def test_the_summary_says_why_the_run_stopped_before_the_last_pictures_are_drawn(tmp_path, monkeypatch):
    """mpirun gives its ranks one second between the SIGTERM it forwards from a Ctrl-C and SIGKILL: the final
    grids, drawn first, took most of it, and a small run on two ranks stopped that way kept "running"."""
    from primordia.coupling.orchestrator import Simulation

    statuses = []

    def draw_the_final_grids(self, run, status):
        statuses.append(json.loads((Path(run.out_dir) / "summary.json").read_text())["status"])

    monkeypatch.setattr(Pictures, "finish", draw_the_final_grids)
    sim = Simulation(small_model(pictures=True), backend="skfem", out_dir=tmp_path).setup()
    stop_with_ctrl_c(sim, monkeypatch, before_step=2)
    assert statuses == ["interrupted at t = 0.4 (Ctrl-C)"]
    built_in = [output.name for output in sim.outputs if output.name in ("pictures", "summary")]  # not a plugin's
    assert built_in == ["pictures", "summary"], "the other moments keep their order"


def test_output_times_that_agree_to_two_decimals_get_pictures_of_their_own(tmp_path):
    """With dt = 0.001 the three output times were all written to m_t0000.00.png, each over the last."""
    model = Model(physics=["chemotaxis"], parameters={"m0": 0.75, "D_m": 0.03}, mesh=MESH, dt=0.001, t_final=0.003,
                  output={"times": [0.001, 0.002, 0.003], "pictures": True})
    sim = model.run(backend="skfem", out=tmp_path)
    pictures = {path.name for path in tmp_path.glob("m_t*.png")}
    assert pictures == {"m_t0000.001.png", "m_t0000.002.png", "m_t0000.003.png"}
    (output,) = [o for o in sim.outputs if o.name == "pictures"]
    assert list(output.snapshots["m"]) == ["m, t = 0.001", "m, t = 0.002", "m, t = 0.003"]


@pytest.mark.parametrize("t, times, stamp", [
    (160.0, [160.0, 280.0], "0160.00"),  # the names of every run so far
    (0.4, [0.4, 1.0], "0000.40"),
    (0.001, [0.001, 0.002], "0000.001"),
    (1.000001, [1.000001, 1.000002], "0001.000001"),
    (-0.5, [-0.5, 1.0], "-0000.50"),  # was -000.50: the sign took a digit
    (-1.0, [-1.0, -0.5], "-0001.00"),
    (-1000.0, [-1000.0, 5.0], "-1000.00"),
    (5000.0, [5000.0, 20000.0], "05000.00"),  # was 5000.00, sorted after 20000.00
    (20000.0, [5000.0, 20000.0], "20000.00"),
    (0.5, [0.5, 123456.25], "000000.50"),
])
def test_a_picture_s_time_has_the_digits_its_output_times_need(t, times, stamp):
    from primordia.core.outputs import picture_time, step_time_label, time_label

    assert picture_time(t, times) == stamp
    assert time_label(1.0) == "1" and time_label(1.0000001) == "1.0000001"  # %g would print 1
    assert step_time_label(629 * 0.2) == "125.8" and step_time_label(1.0000001) == "1.0000001"


def test_a_vector_field_s_series_names_the_extrema_it_holds(tmp_path):
    """u_min and u_max are the extrema of u's components (example 1b's u_min is negative), but their long_name
    said "minimum of |u|", a magnitude that cannot be negative; u_integral is that of |u|."""
    model = Model.from_file("examples/ex01b.toml", ["mesh.cells=[4,4]", "time.t_final=0.4", "output.times=[0.4]",
                                                    "output.pictures=false"])
    model.run(backend="skfem", out=tmp_path, progress=False)
    with xr.open_dataset(tmp_path / "series.nc") as series:
        assert float(series["u_min"][-1]) < 0 < float(series["u_max"][-1])
        assert series["u_min"].attrs["long_name"] == "minimum of the components of u at the vertices"
        assert series["u_max"].attrs["long_name"] == "maximum of the components of u at the vertices"
        assert series["u_integral"].attrs["long_name"] == "integral of |u| over the reference domain"
        assert series["p_min"].attrs["long_name"] == "minimum of p at the vertices"
