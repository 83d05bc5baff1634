"""A user's mistakes, through the real ``primordia`` command (primordia.cli).

Each one exits with status 2 and prints exactly one line on stderr,
``primordia: error: ...``, naming the problem, and no traceback.  A run that
fails part-way leaves what it wrote readable, with a summary saying it stopped.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import matplotlib.image
import meshio
import numpy as np
import pytest
import xarray as xr

from cli_checks import assert_one_line_error

BAD_OVERRIDES = [
    pytest.param(["--set", "nonsense.key=1"], ["unknown config section [nonsense]"], id="unknown-section"),
    pytest.param(["--set", "parameters.D_mm=0.1"], ["unknown parameter 'D_mm'", "did you mean D_m"],
                 id="unknown-parameter-with-suggestion"),
    pytest.param(["--set", "time.dtt=0.1"], ["unknown key time.dtt", "dt"], id="unknown-key-in-time"),
    pytest.param(["--set", "output.snapshots=[1.0]"], ["unknown key output.snapshots", "times"],
                 id="unknown-key-in-output"),
    pytest.param(["--set", "parameters.D_m=-1"], ["D_m", "must be > 0", "-1"], id="negative-diffusivity"),
    pytest.param(["--set", "parameters.alpha=-0.5"], ["alpha", "must be >= 0"], id="negative-sensitivity"),
    pytest.param(["--set", "time.dt=0"], ["time.dt must be a number > 0"], id="zero-dt"),
    pytest.param(["--set", "time.dt=-0.2"], ["time.dt must be a number > 0", "-0.2"], id="negative-dt"),
    pytest.param(["--set", "time.t_final=1.05"], ["1.05", "not a multiple of dt = 0.2"], id="t-final-off-grid"),
    pytest.param(["--set", "output.times=[0.5]"], ["output time 0.5", "not a multiple of dt"],
                 id="output-time-off-grid"),
    pytest.param(["--set", "mesh.cells=[0, 8]"], ["mesh cells", "positive integers", "[0, 8]"], id="zero-cells"),
    pytest.param(["--set", "mesh.upper=[0.0, 4.0]"], ["upper corner must exceed the lower corner along x"],
                 id="upper-not-above-lower"),
    pytest.param(["--backend", "deal.ii"], ["unknown backend 'deal.ii'", "fenicsx", "skfem"], id="unknown-backend"),
    pytest.param(["--set", "kinetics.name=painter2019"], ["unknown kinetics 'painter2019'", "painter2018"],
                 id="unknown-kinetics"),
    pytest.param(["--set", "model.physics=[\"chemotaxi\"]"], ["unknown physics 'chemotaxi'", "chemotaxis"],
                 id="unknown-physics"),
    pytest.param(["--set", "coupling.scheme=leapfrog"], ["unknown splitting scheme 'leapfrog'", "sequential"],
                 id="unknown-splitting-scheme"),
    pytest.param(["--set", "physics.chemotaxis.flux_scheme=upwind"], ["flux_scheme", "upwind"],
                 id="unknown-flux-scheme"),
    pytest.param(["--set", "parameters.D_m"], ["--set expects section.key=value", "parameters.D_m"],
                 id="set-without-value"),
    pytest.param(["--set", "D_m=0.1"], ["--set key must name a section and a key", "D_m"], id="set-without-section"),
    pytest.param(["--set", "=0.1"], ["--set expects section.key=value"], id="set-without-key"),
    pytest.param(["--set", "time.dt.value=0.1"], ["time.dt", "not a table"], id="set-into-a-value"),
]


@pytest.mark.parametrize("arguments, fragments", BAD_OVERRIDES)
def test_bad_override_is_one_line_and_status_2(primordia_cli, small_config, tmp_path, arguments, fragments):
    result = primordia_cli("run", small_config(), "--out", tmp_path / "out", "--no-progress", *arguments)
    assert_one_line_error(result, *fragments)


def test_missing_config_file(primordia_cli, tmp_path):
    result = primordia_cli("run", tmp_path / "nowhere.toml", "--no-progress")
    assert_one_line_error(result, "config file not found", "nowhere.toml")


def test_config_file_that_is_not_toml(primordia_cli, small_config):
    result = primordia_cli("run", small_config("[model\nname = 'x'\n"), "--no-progress")
    assert_one_line_error(result, "invalid TOML", "small.toml")


def test_unknown_section_in_the_file(primordia_cli, small_config):
    result = primordia_cli("run", small_config(small_config.text + "\n[boundary]\nleft = 1\n"), "--no-progress")
    assert_one_line_error(result, "unknown config section [boundary]")


def test_missing_mesh_file(primordia_cli, small_config):
    text = small_config.text.replace('type = "rectangle"\nupper = [4.0, 4.0]\ncells = [8, 8]',
                                'type = "file"\npath = "meshes/missing.msh"')
    assert "missing.msh" in text
    result = primordia_cli("run", small_config(text), "--no-progress")
    assert_one_line_error(result, "mesh file", "missing.msh", "does not exist")


@pytest.mark.parametrize("dry_run", [[], ["--dry-run"]], ids=["run", "dry-run"])
def test_a_jit_cache_that_cannot_be_written_is_one_line(primordia_cli, small_config, tmp_path, dry_run):
    """A batch job's home is often read-only on the compute nodes: FFCx's traceback from the first function
    space (OSError: Read-only file system: '.../.cache/fenics') was all it said.  A cache under a file stands in
    for a read-only one here (root may write anywhere else)."""
    (tmp_path / "a_file").write_text("")
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "a_file")}
    result = primordia_cli("run", small_config(), "--out", tmp_path / "out", "--no-progress", *dry_run, env=env)
    assert_one_line_error(result, "dolfinx's JIT cache", "a_file/fenics cannot be written", "XDG_CACHE_HOME")


@pytest.mark.parametrize("tmpdir", ["a_file", "a_file/tmp"], ids=["file", "missing_under_a_file"])
@pytest.mark.parametrize("command", [["plugins"], ["run", "--dry-run"]], ids=["plugins", "run"])
def test_a_tmpdir_that_cannot_be_written_is_one_line(primordia_cli, small_config, tmp_path, command, tmpdir):
    """Open MPI keeps its session files in TMPDIR: a read-only one was some 50 lines of its banners and an abort
    in MPI_Init_thread, for any command.  A file stands in for a read-only folder (root may write anywhere).
    A missing TMPDIR Open MPI makes, unless the folder it would be made in cannot be written: that gave the
    same banners until the folder that exists was probed."""
    (tmp_path / "a_file").write_text("")
    env = {**os.environ, "TMPDIR": str(tmp_path / tmpdir)}
    arguments = [*command, small_config(), "--out", tmp_path / "out"] if command[0] == "run" else command
    result = primordia_cli(*arguments, env=env)
    assert_one_line_error(result, f"TMPDIR {tmp_path / tmpdir} cannot be written", "not a directory",
                          "set TMPDIR to a writable")


def test_a_missing_tmpdir_is_left_to_open_mpi_which_makes_it(primordia_cli, tmp_path):
    env = {**os.environ, "TMPDIR": str(tmp_path / "new" / "tmp")}
    result = primordia_cli("plugins", env=env)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "new" / "tmp").is_dir()


def test_unknown_command_and_missing_argument_are_usage_errors(primordia_cli):
    assert_one_line_error(primordia_cli("simulate"), "invalid choice", "simulate")
    assert_one_line_error(primordia_cli("run"), "config")


# -- failures during a run --------------------------------------------------------------------


def test_a_diverged_solve_stops_the_run_with_one_line(primordia_cli, small_config, tmp_path):
    """A real PETSc failure: one unpreconditioned GMRES iteration cannot reach the m solve's rtol of 1e-12
    (with the default ILU on this small mesh it can, once dt has been halved a few times)."""
    out = tmp_path / "out"
    result = primordia_cli("run", small_config(), "--out", out, "--no-progress",
                           "--set", "solver.chemotaxis_m.ksp_max_it=1", "--set", "solver.chemotaxis_m.pc_type=none")
    assert_one_line_error(result, "chemotaxis.m", "linear solver diverged", "chemotaxis_m_")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"].startswith("stopped at t = 0:") and "diverged" in summary["status"]
    assert summary["steps"] == 0
    with xr.open_dataset(out / "series.nc") as series:
        assert list(series["time"].values) == [0.0]


#: A third-party splitting scheme that fails in its 6th step the way a diverged solve does.
FAILING_SCHEME = """\
from primordia.core.errors import SolverError
from primordia.core.plugins import hookimpl
from primordia.coupling.splitting import Sequential


class FailsInStep6(Sequential):
    name = "fails_in_step_6"

    def advance(self, sim, *args, **kwargs):
        if sim.step_index == 5:
            raise SolverError("chemotaxis.m: the linear solver diverged (injected in step 6)")
        return super().advance(sim, *args, **kwargs)


@hookimpl
def primordia_splitting_schemes():
    return [FailsInStep6]
"""


def test_a_run_failing_midway_leaves_readable_outputs(primordia_cli, small_config, plugin_distribution, tmp_path):
    env = plugin_distribution("primordia-failing-scheme", "0.1", {"failing_scheme": FAILING_SCHEME},
                              {"failing_scheme": "failing_scheme"})
    out = tmp_path / "out"
    result = primordia_cli(
        "run", small_config(), "--out", out, "--no-progress",
        "--set", "coupling.scheme=fails_in_step_6", "--set", "time.t_final=2.0",
        "--set", "output.times=[0.4, 0.8, 2.0]", "--set", "output.series_every=1", "--set", "output.pictures=true",
        env=env,
    )
    assert_one_line_error(result, "injected in step 6")

    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"].startswith("stopped at t = 1:"), summary["status"]
    assert "injected in step 6" in summary["status"]
    assert summary["steps"] == 5 and summary["time"] == pytest.approx(1.0)
    assert np.isfinite(summary["final"]["m"]["integral"])

    with xr.open_dataset(out / "series.nc") as series:
        np.testing.assert_allclose(series["time"].values, [0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
        assert np.all(np.isfinite(series["m_integral"].values))

    with meshio.xdmf.TimeSeriesReader(out / "fields.xdmf") as reader:
        reader.read_points_cells()
        frames = [reader.read_data(k) for k in range(reader.num_steps)]
    assert [t for t, _, _ in frames] == pytest.approx([0.4, 0.8])
    assert all(np.all(np.isfinite(data["m"])) for _, data, _ in frames)

    with open(out / "config.toml", "rb") as stream:
        assert tomllib.load(stream)["coupling"]["scheme"] == "fails_in_step_6"
    for picture in ("m_t0000.40.png", "m_t0000.80.png", "final_fields.png"):
        assert matplotlib.image.imread(out / picture).ndim == 3, picture


# -- issue 10: every class of bad input, one line and exit 2 ------------------------------------------
# One real process per class (below); the variants of each class run through the same command's
# entry point in this process (``primordia.cli.main``), which is what the console script calls.

EX01B = Path(__file__).resolve().parents[2] / "examples" / "ex01b.toml"
EX01B_COARSE = ["--set", "mesh.cells=[4,4]", "--set", "time.t_final=0.4", "--set", "output.times=[0.4]",
                "--set", "output.pictures=false"]
BOUNDARY = "physics.poroelasticity.boundary"


def in_process(capsys, *arguments) -> tuple[int, str]:
    """``primordia ARGUMENTS`` through the command's entry point: (exit status, stderr)."""
    from primordia.cli import main

    status = main([str(a) for a in arguments])
    return status, capsys.readouterr().err


def assert_one_line(status: int, stderr: str, *fragments: str) -> None:
    assert status == 2, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("primordia: error: "), stderr
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in {lines[0]!r}"


WRONG_TYPES = [
    (["output.pictures=\"false\""], ["output.pictures must be true or false", "'false'"]),
    (["output.pictures=1"], ["output.pictures must be true or false"]),
    (["kinetics.priming_wave=\"false\""], ["kinetics painter2018: option 'priming_wave' must be true or false"]),
    (["physics.chemotaxis=3"], ["physics.chemotaxis must be a table"]),
    (["physics.chemotaxis.perturbation=\"0.1\""], ["option 'perturbation' must be a number"]),
    (["physics.chemotaxis.wavenumber=3"], ["option 'wavenumber' must be a list"]),
    (["model.physics=3"], ["model.physics must be a non-empty list of names"]),
    (["model.name=3"], ["model.name must be a string"]),
    (["output.snapshot_fields=3"], ["output.snapshot_fields must be a list of field names"]),
    (["output.times=[true]"], ["output.times[0] must be a number", "True"]),
    (["coupling.inner_steps=1.5"], ["option 'inner_steps' must be an integer"]),
    # with an option of another scheme beside it: its warning came first, two lines (the config fuzzing found it)
    (["coupling.inner_steps=\"\"", "coupling.tolerance=1e-6"], ["option 'inner_steps' must be an integer"]),
    (["coupling.scheme=3"], ["coupling.scheme must be the name of a splitting scheme"]),
    (["solver.chemotaxis_m=3"], ["solver.chemotaxis_m must be a table"]),
    (["kinetics.name=3"], ["kinetics.name must be the name of a kinetics"]),
    (["time.adaptive=\"yes\""], ["time.adaptive must be true or false"]),
    (["checkpoint.every_steps=-1"], ["checkpoint.every_steps must be an integer >= 0"]),
]


@pytest.mark.parametrize("assignments, fragments", WRONG_TYPES, ids=[a[0] for a, _ in WRONG_TYPES])
def test_a_value_of_the_wrong_type_anywhere(capsys, small_config, tmp_path, assignments, fragments):
    arguments = [a for assignment in assignments for a in ("--set", assignment)]
    assert_one_line(*in_process(capsys, "run", small_config(), "--out", tmp_path / "out", *arguments), *fragments)


@pytest.mark.parametrize("section", ["physics", "coupling", "checkpoint", "time"])
def test_a_number_where_a_table_is_expected(capsys, small_config, section):
    text = "\n".join(line for line in small_config.text.splitlines() if line != f"[{section}]")
    body = text.split("\n[time]")[0] if section == "time" else text
    config = small_config(f"{section} = 3\n" + body + ("\n" if section == "time" else ""), name=f"{section}.toml")
    assert_one_line(*in_process(capsys, "run", config), section)


FORMULAS = [
    ('["0", "1/0"]', "", ["boundary condition 'traction' on 'top'", "division by zero"]),
    ('["0", "x[2]"]', "", ["boundary condition 'traction' on 'top'", "x[2]", "does not exist in 2D"]),
    ('["0", "exp(1000)"]', "", ["'traction' on 'top'", "overflow"]),
    ('["0", "exp(10 * t)"]', "", ["'traction' on 'top'", "t = 71.875", "overflow"]),
    ('["0", "s0"]', ', constants={s0="abc"}', ["constant 's0' must be a number"]),
    ('["0", "t"]', ", constants={t=1.0}", ["constant 't' would shadow t, the time"]),
    ('["0", "x[0]"]', ", constants={x=1.0}", ["constant 'x' would shadow x"]),
    ('["0", "1"]', ", constants=3", ["constants must be a table"]),
    ('["0", "1/(x[1] - 20)"]', "", ["'traction' on 'top'", "x = (0, 20)", "division by zero"]),
]


@pytest.mark.parametrize("value, extra, fragments", FORMULAS, ids=[f[0] + f[1] for f in FORMULAS])
def test_a_boundary_formula_that_cannot_be_evaluated_is_refused_when_read(capsys, tmp_path, value, extra,
                                                                           fragments):
    condition = f'[{{boundary="top", type="traction", value={value}{extra}}}]'
    status, stderr = in_process(capsys, "run", EX01B, *EX01B_COARSE, "--set", f"{BOUNDARY}={condition}",
                                "--set", "time.t_final=100.0", "--set", "time.dt=0.5",
                                "--set", "output.times=[100.0]", "--dry-run")
    assert_one_line(status, stderr, *fragments)


BAD_CONDITIONS = [
    ('[{boundary="bottom", type="clamped"}, {boundary="bottom", type="displacement", value=["0.1", "0"]}]',
     ["boundary 'bottom' is given two Dirichlet conditions on u ('clamped' and 'displacement')"]),
    ('[{boundary="top", type="fluid_pressure", value="1"}, {boundary="top", type="fluid_pressure", value="2"}]',
     ["boundary 'top' is given two Dirichlet conditions on p"]),
    ('[{boundary="top", type="clamped", value=["1", "0"]}]', ["'clamped' on 'top' is u = 0 and takes no value"]),
    ('[{boundary="bottom", type="clamped"}, {boundary="top", type="robin", value="0.1 - t"}]',
     ["'robin' on 'top'", "must be >= 0", "t = 0.1"]),
]


@pytest.mark.parametrize("conditions, fragments", BAD_CONDITIONS, ids=["clamped-and-displacement", "two-pressures",
                                                                      "clamped-with-a-value", "negative-springs"])
def test_contradictory_conditions_are_refused_when_read(capsys, conditions, fragments):
    status, stderr = in_process(capsys, "run", EX01B, *EX01B_COARSE, "--set", f"{BOUNDARY}={conditions}", "--dry-run")
    assert_one_line(status, stderr, *fragments)


def test_a_boundary_formula_through_the_real_command(primordia_cli, tmp_path):
    condition = '[{boundary="bottom", type="displacement", value=["0", "1/x[1]"]}]'
    result = primordia_cli("run", EX01B, *EX01B_COARSE, "--set", f"{BOUNDARY}={condition}", "--out",
                           tmp_path / "out")
    assert_one_line_error(result, "boundary condition 'displacement' on 'bottom'", "division by zero")
    assert not (tmp_path / "out").exists()  # refused when read: nothing was set up


def _binary(path):
    path.write_bytes(bytes(range(256)) * 4)
    return path


def _latin1(path):
    path.write_bytes("[model]\nname = 'sm\xe4ll'\n".encode("latin-1"))
    return path


def _folder(path):
    path.mkdir()
    return path


def _fifo(path):
    os.mkfifo(path)
    return path


@pytest.mark.parametrize("make, fragments", [
    (_binary, ["is not UTF-8 text", "binary"]), (_latin1, ["is not UTF-8 text"]),
    (_folder, ["is a folder"]), (_fifo, ["is not a regular file"]),
    (lambda path: Path("/dev/zero"), ["/dev/zero", "not a regular file"]),
    (lambda path: Path("/proc/1/mem"), ["cannot read config file /proc/1/mem: permission denied"]),
], ids=["binary", "latin-1", "folder", "fifo", "dev-zero", "unreadable"])
def test_a_config_that_is_no_text_file(capsys, tmp_path, make, fragments):
    assert_one_line(*in_process(capsys, "run", make(tmp_path / "config.toml")), *fragments)


def test_a_binary_config_through_the_real_command(primordia_cli, tmp_path):
    assert_one_line_error(primordia_cli("run", _binary(tmp_path / "x.toml")), "is not UTF-8 text")


@pytest.mark.parametrize("out, fragments", [
    ("FILE", ["is a file, not a directory"]), ("/dev/null", ["/dev/null is a file"]),
    ("FILE/sub", ["lies inside", "which is a file"]), ("/proc/primordia-out", ["cannot"]), ("", ["--out needs"]),
], ids=["a-file", "dev-null", "under-a-file", "not-writable", "empty"])
def test_an_output_directory_that_cannot_be_one(capsys, small_config, tmp_path, out, fragments):
    (tmp_path / "file").write_text("a file")
    out = out.replace("FILE", str(tmp_path / "file"))
    assert_one_line(*in_process(capsys, "run", small_config(), "--out", out), *fragments)


@pytest.mark.parametrize("out", ["/proc/primordia-out", "/sys/primordia-out"])
def test_a_dry_run_refuses_an_output_directory_that_cannot_be_made_even_as_root(capsys, small_config, out):
    """As root os.access says /proc is writable: --dry-run said "the input is valid" and the run then refused."""
    assert_one_line(*in_process(capsys, "run", small_config(), "--dry-run", "--out", out), "cannot be")


def test_an_output_file_through_the_real_command(primordia_cli, small_config, tmp_path):
    (tmp_path / "file").write_text("a file")
    assert_one_line_error(primordia_cli("run", small_config(), "--out", tmp_path / "file"), "is a file")


@pytest.mark.parametrize("assignments, fragments", [
    (["mesh.cells=[100000,100000]"], ["20,000,000,000 cells needs at least", "available: use fewer cells"]),
    (["mesh.cells=[4611686018427387904,2]"], ["cells needs at least"]),
    (['mesh.type="box"', "mesh.upper=[1.0,1.0,1.0]", "mesh.cells=[3000,3000,3000]"], ["memory"]),
    (["time.dt=1e-9"], ["time.dt = 1e-09 gives", "steps", "dimensionless"]),
    (["time.t_final=1e300", "time.dt=1e290"], ["steps"]),
], ids=["mesh-1e10", "mesh-2^63", "box-3000^3", "dt-1e-9", "t-final-1e300"])
def test_sizes_that_cannot_run_are_refused_before_allocating(capsys, small_config, assignments, fragments):
    arguments = [a for assignment in assignments for a in ("--set", assignment)]
    assert_one_line(*in_process(capsys, "run", small_config(), "--dry-run", *arguments), *fragments)


@pytest.mark.parametrize("assignments, fragments", [
    (['physics.chemotaxis.perturbation_shape="cosine"', "physics.chemotaxis.wavenumber=[1.0, 2.0, 3.0]"],
     ["physics.chemotaxis.wavenumber has 3 components", "the mesh is 2D"]),
    (['mesh.type="box"', "mesh.upper=[4.0, 4.0, 1e-12]", "mesh.cells=[4, 4, 2]"],
     ["mesh box [0, 4] x [0, 4] x [0, 1e-12]", "192 degenerate (zero-volume) cells"]),
], ids=["3d-wavenumber-on-a-2d-mesh", "slab-1e-12-thick"])
def test_a_dry_run_refuses_what_the_mesh_s_dimension_or_shape_makes_meaningless(capsys, small_config, assignments,
                                                                                fragments):
    """Both were called valid: k_3 was dropped without a word, and the slab's run failed at its first step
    (the linear solver's set-up, after halving dt down to dt_min)."""
    arguments = [a for assignment in assignments for a in ("--set", assignment)]
    assert_one_line(*in_process(capsys, "run", small_config(), "--dry-run", *arguments), *fragments)


def test_a_mesh_too_big_through_the_real_command(primordia_cli, small_config):
    result = primordia_cli("run", small_config(), "--set", "mesh.cells=[100000,100000]", timeout=60)
    assert_one_line_error(result, "needs at least", "memory")


@pytest.mark.parametrize("arguments, fragments", [
    (["--backend", ""], ["--backend needs a name"]),
    (["--backend", " "], ["--backend needs a name"]),
    (["--set", 'model.backend=""'], ["model.backend must name a backend"]),
    (["--set", 'model.physics=["chemotaxis", "chemotaxis"]'], ["model.physics lists 'chemotaxis' twice"]),
    (["--set", 'model.physics=[""]'], ["model.physics must be a non-empty list of names"]),
], ids=["empty-backend", "blank-backend", "empty-backend-in-config", "duplicated-physics", "empty-physics"])
def test_names_that_name_nothing(capsys, small_config, arguments, fragments):
    assert_one_line(*in_process(capsys, "run", small_config(), "--dry-run", *arguments), *fragments)


def test_an_empty_backend_name_through_the_real_command(primordia_cli, small_config):
    assert_one_line_error(primordia_cli("run", small_config(), "--backend", ""), "--backend needs a name")


@pytest.mark.parametrize("assignments, fragments", [
    (["mesh.upper=[1e300,1e300]"], ["mesh corners", "1e+300", "rescale the domain"]),
    (["mesh.lower=[-1e308,0.0]", "mesh.upper=[1e308,4.0]"], ["mesh corners", "rescale"]),
    (["mesh.upper=[1e-300,1e-300]"], ["mesh corners", "spans only"]),
    (["mesh.upper=[1e200,1e-200]"], ["mesh corners", "coordinates reach"]),
], ids=["1e300", "1e308-span", "1e-300", "1e200-by-1e-200"])
def test_absurd_mesh_coordinates_are_named_as_the_mesh_s_fault(capsys, small_config, assignments, fragments):
    arguments = [a for assignment in assignments for a in ("--set", assignment)]
    assert_one_line(*in_process(capsys, "run", small_config(), "--dry-run", *arguments), *fragments)


def _mesh_file(tmp_path, points, triangles) -> Path:
    path = tmp_path / "mesh.msh"
    meshio.write(path, meshio.Mesh(np.asarray(points, float), [("triangle", np.asarray(triangles))]),
                 file_format="gmsh22", binary=False)
    return path


SQUARE = [[0, 0], [1, 0], [0, 1], [1, 1]]


@pytest.mark.parametrize("points, triangles, fragments", [
    ([[0, 0], [1, 0], [0, np.nan], [1, 1]], [[0, 1, 3], [0, 3, 2]], ["not finite"]),
    (SQUARE, [[0, 1, 3], [0, 3, 2], [0, 1, 3]], ["overlapping cells", "duplicated or folded"]),
    (SQUARE + [[0.25, 0.25]], [[0, 1, 3], [0, 3, 2], [0, 1, 4]], ["overlapping cells"]),
    ([[x * 1e300 for x in p] for p in SQUARE], [[0, 1, 3], [0, 3, 2]], ["coordinates reach 1e+300"]),
], ids=["nan-coordinates", "duplicated-cell", "folded-cell", "coordinates-1e300"])
def test_a_mesh_file_at_fault_is_named(capsys, small_config, tmp_path, points, triangles, fragments):
    path = _mesh_file(tmp_path, points, triangles)
    capsys.readouterr()  # meshio's own chatter while writing the file
    text = small_config.text.replace('type = "rectangle"\nupper = [4.0, 4.0]\ncells = [8, 8]',
                                     f'type = "file"\npath = "{path}"')
    assert_one_line(*in_process(capsys, "run", small_config(text), "--dry-run"), "mesh file", *fragments)


def test_a_blow_up_names_the_time(primordia_cli, small_config, tmp_path):
    """The first step still converges (the cell density's ILU on an RCM ordering); a later one does not (the
    second with ILU(0), the third with ILU(1)), and the line names it with its times."""
    import re

    result = primordia_cli("run", small_config(), "--out", tmp_path / "out", "--no-progress",
                           "--set", "physics.chemotaxis.flux_scheme=galerkin", "--set", "parameters.alpha=1e8",
                           "--set", "time.adaptive=false")
    line = assert_one_line_error(result, "chemotaxis.m")
    step, begin, end = re.search(r"step (\d+) \(t = ([\d.]+) -> ([\d.]+)\)", line).groups()
    assert int(step) >= 2 and (float(begin), float(end)) == pytest.approx((0.2 * (int(step) - 1), 0.2 * int(step)))


@pytest.mark.parametrize("arguments, fragments", [
    (["--backend", "deal.ii"], ["unknown backend 'deal.ii'", "fenicsx", "skfem"]),
    (["--set", 'model.backend="deal.ii"'], ["unknown backend 'deal.ii'"]),
    (["--set", "coupling.scheme=leapfrog"], ["unknown splitting scheme 'leapfrog'", "sequential"]),
    (["--set", "coupling.scheme=fixed_point", "--set", "coupling.tolerance=-1"], ["coupling.tolerance", "-1"]),
    (["--set", "physics.chemotaxis.seed=-1"], ["physics.chemotaxis.seed must be an integer >= 0", "-1"]),
    (["--set", "parameters.P_2=2000"], ["kinetics painter2018: the initial state cannot be evaluated", "overflows"]),
    (["--set", "parameters.m0=1e300"], ["kinetics painter2018: the initial state cannot be evaluated"]),
    (["--set", 'solver.chemotaxis_m.ksp_type="gmress"'], ["solver.chemotaxis_m: unknown KSP type 'gmress'", "gmres"]),
    (["--set", "solver.chemotaxis_m.sub.pc_type=ilu", "--set", "solver.chemotaxis_m.ksp_rtol=-1"],
     ["solver.chemotaxis_m.ksp_rtol must be a number in [0, 1), got -1"]),
], ids=["unknown-backend", "unknown-backend-in-config", "unknown-scheme", "scheme-option", "negative-seed",
        "steep-hill-switch", "absurd-density", "unknown-ksp", "negative-tolerance"])
def test_a_dry_run_refuses_what_the_run_would_refuse(capsys, small_config, tmp_path, arguments, fragments):
    """``--dry-run`` said "the input is valid ... on deal.ii" where the run stops at once, and took a
    negative seed that numpy refuses with a traceback in the run."""
    assert_one_line(*in_process(capsys, "run", small_config(), "--dry-run", "--out", tmp_path / "out", *arguments),
                    *fragments)
    assert not (tmp_path / "out").exists()



@pytest.mark.parametrize("arguments, fragments", [
    (["--set", "parameters.D_m=0.05"], ["parameters.D_m differs from the checkpointed run's"]),
    (["--set", "mesh.cells=[4,4]"], ["mesh.cells differs from the checkpointed run's"]),
    (["--set", "output.times=[0.4]"], ["output time 0.4 is before its t = 1", "did not write the fields there"]),
    (["--backend", "skfem"], ["it was written on backend fenicsx, this run is on skfem"]),
], ids=["parameter", "mesh", "output-time-passed", "backend"])
def test_a_dry_run_of_a_restart_refuses_what_the_restart_would_refuse(capsys, small_config, tmp_path, arguments,
                                                                       fragments):
    """``--restart OUT --dry-run`` said "the input is valid" where the restart refuses at once: the checkpoint
    decides what a restart may change."""
    out = tmp_path / "out"
    assert in_process(capsys, "run", small_config(), "--out", out, "--no-progress", "--backend", "fenicsx")[0] == 0
    assert_one_line(*in_process(capsys, "run", "--restart", out, "--dry-run", *arguments), *fragments)
    status, stderr = in_process(capsys, "run", "--restart", out, "--dry-run", "--set", "time.t_final=1.4")
    assert status == 0 and not stderr


def test_a_dry_run_of_a_restart_without_a_checkpoint_says_so_as_the_restart_does(capsys, small_config, tmp_path):
    assert_one_line(*in_process(capsys, "run", small_config(), "--restart", tmp_path, "--dry-run"),
                    f"{tmp_path} holds no checkpoint to restart from; checkpoints are written every")

def test_a_negative_seed_through_the_real_command(primordia_cli, small_config, tmp_path):
    result = primordia_cli("run", small_config(), "--out", tmp_path / "out", "--no-progress",
                           "--set", "physics.chemotaxis.seed=-1")
    assert_one_line_error(result, "physics.chemotaxis.seed must be an integer >= 0")


@pytest.mark.parametrize("args", [("plugins",), ("stability", "--domain", "20,20")])
def test_a_reader_that_stops_reading_ends_the_command_quietly(args, tmp_path):
    """`primordia plugins | head` died in PETSc's SIGPIPE handler: "PETSC ERROR: Caught signal number 13
    Broken Pipe" and an MPI_ABORT with exit 59. The read end is closed before the command writes."""
    from conftest import PRIMORDIA

    process = subprocess.Popen([str(PRIMORDIA), *args, *(("--out", str(tmp_path)) if args[0] == "stability" else ())],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    process.stdout.close()
    error = process.stderr.read()
    assert process.wait(timeout=120) == 141 and error == ""


def test_python_dash_m_primordia_is_the_command():
    result = subprocess.run([sys.executable, "-m", "primordia", "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and result.stdout.startswith("usage: primordia") and "``" not in result.stdout


@pytest.mark.parametrize("missing, command", [
    ("petsc4py", ["plugins"]),
    ("mpi4py", ["run", "CONFIG", "--backend", "skfem"]),
    ("h5py", ["analyse", "RUN"]),
], ids=["petsc4py-plugins", "mpi4py-run", "h5py-analyse"])
def test_a_missing_system_package_is_one_line(primordia_cli, small_config, tmp_path, missing, command):
    """petsc4py, mpi4py and h5py are the system's, not pip's (README, "Backends"): ``pip install primordia`` into
    an environment without them gave every command a traceback ending in ModuleNotFoundError (from the plugin
    manager's built-in modules for ``plugins``, ``run`` and ``stability``)."""
    run = tmp_path / "run"
    if "RUN" in command:
        assert primordia_cli("run", small_config(), "--out", run, "--no-progress").returncode == 0
    shadow = tmp_path / "shadow" / missing
    shadow.mkdir(parents=True)
    (shadow / "__init__.py").write_text(f"raise ModuleNotFoundError({f'No module named {missing!r}'!r}, "
                                        f"name={missing!r})\n")
    path = os.pathsep.join(filter(None, [str(shadow.parent), os.environ.get("PYTHONPATH")]))
    env = {**os.environ, "PYTHONPATH": path}
    arguments = [run if item == "RUN" else small_config() if item == "CONFIG" else item for item in command]
    result = primordia_cli(*arguments, *(["--out", tmp_path / "out"] if command[0] == "run" else []), env=env)
    assert_one_line_error(result, f"{missing} is not installed", "pip does not install", "python3-h5py-mpi")


def test_an_error_line_reaches_stderr_in_one_write(monkeypatch, tmp_path):
    """Under mpirun a rank's output is forwarded in the pieces it was written in: ``print`` wrote the line and its
    newline apart, and the abort's banner, forwarded between them, ended the error line (an intermittent failure
    of ``test_kinetics_failing_on_one_rank_is_one_line``)."""
    from primordia.cli import main

    writes = []

    class Recorder:
        def write(self, text):
            writes.append(text)
            return len(text)

        def flush(self):
            pass

    monkeypatch.setattr(sys, "stderr", Recorder())
    assert main(["run", str(tmp_path / "missing.toml")]) == 2
    lines = [text for text in writes if text.startswith("primordia: error:")]
    assert len(lines) == 1 and lines[0].endswith("\n") and lines[0].count("\n") == 1, writes
