"""Bad input under ``mpirun -n 2`` (issue 10): one line from primordia, exit status 2, and no rank left waiting.

Each class is decided on rank 0 and shared, or decided alike on every rank, so
both ranks leave together; a hang is a timeout and fails the test.  mpirun's own
banner about a non-zero exit status is not primordia's output and is left out.
"""

from __future__ import annotations

import pytest

import run_control as rc

pytestmark = pytest.mark.mpi


def _assert_one_line_on_every_rank(result, *fragments):
    assert result.returncode == 2, result.stderr[-2000:]
    lines = rc.primordia_lines(result.stderr)
    assert len(lines) == 1 and lines[0].startswith("primordia: error: "), result.stderr[-2000:]
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


@pytest.mark.parametrize("case", ["out-is-a-file", "boundary-formula", "binary-config", "failed-solve",
                                  "unused-option-on-one-rank", "usage-error-on-one-rank", "unreadable-on-one-rank"])
def test_bad_input_under_two_ranks(case, small_config, tmp_path):
    (tmp_path / "a_file").write_text("not a directory")
    (tmp_path / "binary.toml").write_bytes(bytes(range(256)))
    arguments, fragments = {
        "out-is-a-file": ([small_config(), "--out", tmp_path / "a_file"], ["is a file"]),
        "boundary-formula": ([rc.EXAMPLES / "ex01b.toml", "--set", "mesh.cells=[4,4]", "--set",
                              'physics.poroelasticity.boundary=[{boundary="top", type="traction", value=["0", "x[2]"]}]'],
                             ["'traction' on 'top'", "x[2]"]),
        "binary-config": ([tmp_path / "binary.toml"], ["not UTF-8"]),
        "failed-solve": ([small_config(), "--set", "solver.chemotaxis_m.ksp_max_it=1", "--set", "time.dt_min=0.1"],
                         ["chemotaxis.m", "linear solver diverged", "time.dt_min = 0.1"]),
        # b's system is solved whole by rank 1 (f's by rank 0): only that rank's solver reads the options, and
        # its verdict is every rank's
        "unused-option-on-one-rank": ([small_config(), "--set", "solver.chemotaxis_b.pc_factor_levels=2"],
                                      ["solver.chemotaxis_b", "PETSc did not use option 'pc_factor_levels'",
                                       "(here ksp_type preonly, pc_type lu)"]),
        # f's owner (rank 0) alone meets PETSc's usage error; every rank stops at the first try, not after the
        # dt halvings (which would say "retried down to")
        "usage-error-on-one-rank": ([small_config(), "--set", 'solver.chemotaxis_f.pc_factor_mat_solver_type="mumps"',
                                     "--set", "solver.chemotaxis_f.mat_mumps_icntl_7=99"],
                                    ["step 1 (t = 0 -> 0.2): chemotaxis.f: the linear solve on rank 0 failed",
                                     "PETSc error 63", "Valid values are"]),
        # read by the owner's sub-solver set-up, past read_options: the failure names the option PETSc's reason quotes
        "unreadable-on-one-rank": ([small_config(), "--set", "solver.chemotaxis_b.solve_on_one_rank=true",
                                    "--set", 'solver.chemotaxis_b.pc_type="bjacobi"',
                                    "--set", 'solver.chemotaxis_b.ksp_type="cg"',
                                    "--set", 'solver.chemotaxis_b.sub_pc_factor_fill="zz"'],
                                   ["chemotaxis.b: the linear solve on rank 1 failed",
                                    "zz has no numeric value (in sub_pc_factor_fill = 'zz')"]),
    }[case]
    if "--out" not in arguments:
        arguments += ["--out", tmp_path / "out"]
    result = rc.run("run", *arguments, "--no-progress", ranks=2, timeout=180)
    _assert_one_line_on_every_rank(result, *fragments)
    if case == "usage-error-on-one-rank":
        assert "retried" not in rc.primordia_lines(result.stderr)[0]


@pytest.mark.parametrize("dry_run", [[], ["--dry-run"]], ids=["run", "dry-run"])
@pytest.mark.parametrize("example", ["ex01a", "ex01b"])
def test_more_ranks_than_the_mesh_has_cells_for_is_one_line(example, dry_run, tmp_path):
    """A mesh of 2 triangles on 3 ranks leaves a rank without a cell, on which dolfinx 0.5.2 cannot work (its
    collapse of a vector field's component crashes there, an empty dofmap broke the vertex maps): it was a
    traceback of every rank and an MPI_ABORT.  ``--dry-run``, which did not partition the mesh, said "the input
    is valid"."""
    result = rc.run("run", rc.EXAMPLES / f"{example}.toml", "--set", "mesh.cells=[1,1]", "--set", "time.t_final=0.4",
                    "--set", "output.times=[0.4]", "--no-progress", "--out", tmp_path / "out", *dry_run, ranks=3,
                    timeout=180)
    _assert_one_line_on_every_rank(result, "2 cells", "3 ranks", "own none", "fewer ranks")


@pytest.mark.parametrize("command", ["stability", "analyse", "plugins"])
def test_a_serial_command_under_mpirun_is_one_line(command, tmp_path):
    """Only ``primordia run`` shares its work over ranks.  The others ran whole on every rank: under
    ``mpirun -n 3`` the stability report came three times, interleaved, and three processes wrote the same
    dispersion.nc, analyse's metrics.nc and pictures likewise."""
    arguments = {"stability": [rc.EXAMPLES / "ex01a.toml", "--out", tmp_path / "out"],
                 "analyse": [tmp_path / "out"], "plugins": []}[command]
    result = rc.run(command, *arguments, ranks=3, timeout=180)
    _assert_one_line_on_every_rank(result, f"primordia {command} is serial", "without mpirun")
    assert not result.stdout and not (tmp_path / "out").exists()
