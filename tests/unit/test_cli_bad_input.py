"""A user's mistakes, through the real ``primordia`` command (primordia.cli).

Each one exits with status 2 and prints exactly one line on stderr,
``primordia: error: ...``, naming the problem, and no traceback.  A run that
fails part-way leaves what it wrote readable, with a summary saying it stopped.
"""

from __future__ import annotations

import json
import tomllib

import matplotlib.image
import meshio
import numpy as np
import pytest
import xarray as xr


def assert_one_line_error(result, *fragments: str) -> str:
    """Exit status 2, one stderr line ``primordia: error: ...`` containing every fragment."""
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert "Traceback" not in result.stderr and "Traceback" not in result.stdout, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("primordia: error: "), lines[0]
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in {lines[0]!r}"
    return lines[0]


BAD_OVERRIDES = [
    pytest.param(["--set", "nonsense.key=1"], ["unknown config section [nonsense]"], id="unknown-section"),
    pytest.param(["--set", "parameters.D_mm=0.1"], ["unknown parameter 'D_mm'", "did you mean D_m"],
                 id="unknown-parameter-with-suggestion"),
    pytest.param(["--set", "time.dtt=0.1"], ["unknown key time.dtt", "dt"], id="unknown-key-in-time"),
    pytest.param(["--set", "output.snapshots=[1.0]"], ["unknown key output.snapshots", "times"],
                 id="unknown-key-in-output"),
    pytest.param(["--set", "parameters.D_m=-1"], ["D_m", "must be > 0", "-1"], id="negative-diffusivity"),
    pytest.param(["--set", "parameters.alpha=-0.5"], ["alpha", "must be >= 0"], id="negative-sensitivity"),
    pytest.param(["--set", "time.dt=0"], ["time.dt must be > 0"], id="zero-dt"),
    pytest.param(["--set", "time.dt=-0.2"], ["time.dt must be > 0", "-0.2"], id="negative-dt"),
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


def test_unknown_command_and_missing_argument_are_usage_errors(primordia_cli):
    assert_one_line_error(primordia_cli("simulate"), "invalid choice", "simulate")
    assert_one_line_error(primordia_cli("run"), "config")


# -- failures during a run --------------------------------------------------------------------


def test_a_diverged_solve_stops_the_run_with_one_line(primordia_cli, small_config, tmp_path):
    """A real PETSc failure: one GMRES iteration cannot reach the m solve's rtol of 1e-12."""
    out = tmp_path / "out"
    result = primordia_cli("run", small_config(), "--out", out, "--no-progress",
                           "--set", "solver.chemotaxis_m.ksp_max_it=1")
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
