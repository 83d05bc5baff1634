"""Mistakes in a growth configuration (seed section 4), through the real ``primordia`` command: one line, exit 2."""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_checks import assert_one_line_error

EX02A = Path(__file__).resolve().parents[2] / "examples" / "ex02a.toml"
COARSE = ["--set", "mesh.cells=[4,4]", "--set", "time.t_final=0.4", "--set", "output.times=[0.4]",
          "--set", "output.pictures=false", "--no-progress"]


@pytest.mark.parametrize("overrides, fragments", [
    (["--set", "growth_law.name=seed4d"], ["unknown growth law 'seed4d'", "seed2d", "seed3d"]),
    (["--set", "growth_law.name=seed3d"], ["seed3d is written for 3D, the mesh is 2D"]),
    (["--set", 'model.physics=["chemotaxis", "poroelastic_growth", "mechanochemical", "active_stress"]'],
     ["active_stress", "cannot join poroelastic_growth"]),
    (["--set", "parameters.delta_2=-0.1"], ["parameter delta_2 must be >= 0"]),
    # u_x = 0 on the left alone lets the tissue slide along y: the static initial equilibrium is singular, and the
    # backends "completed" with mean u_y -0.57 (fenicsx) against 7.07 (skfem)
    (["--set", 'physics.poroelastic_growth.boundary=[{boundary="left", type="normal_displacement"}]'],
     ["the boundary conditions leave 1 rigid-body motion(s) of u free and the initial equilibrium is static"]),
    (["--set", "parameters.delta_1=0.1"],  # example 2a's law is seed2d: delta_1 is seed3d's (4.13)
     ["parameter 'delta_1' belongs to growth law seed3d, which this model does not use", "growth law seed2d"]),
    (["--set", "physics.poroelastic_growth.shear_modulus=0"], ["shear_modulus must be a number > 0"]),
    (["--set", "physics.poroelastic_growth.boundary=[{boundary='left', type='springs'}]"],
     ["unknown boundary condition type 'springs'", "robin"]),
    (["--set", "physics.chemotaxis.accumulation=lagrangian"], ["accumulation must be one of material, conservative"]),
    (["--set", "growth_law.directions=[[1.0, 1.0], [0.0, 1.0]]"], ["growth_law.directions must be orthonormal"]),
    # no vectors to read a dimension from: example 2a (seed2d, 2D) was told "3 vectors of 3 numbers (in 3D)"
    (["--set", "growth_law.directions=[]"], ["growth_law.directions must be 2 vectors of 2 numbers", "in 2D"]),
    (["--set", "physics.poroelastic_growth.stabilisation=[-1.0, 0.1]"],
     ["physics.poroelastic_growth.stabilisation[0] (beta_s) must be a number > 0, got -1.0"]),
    (["--set", "physics.poroelastic_growth.stabilisation=[1.0, -0.1]"], ["stabilisation[1] (beta_f) must be a number >= 0"]),
    (["--set", 'solver.poroelastic_growth.splits=[["u"], ["psi", "p"]]'],
     ["solver.poroelastic_growth.splits names the splits of pc_type = \"fieldsplit\"", "pc_type is 'lu'"]),
    # p + c, psi - alpha_BW c solves (4.12a)-(4.12c) as p, psi do: the tangent was singular at every dt, and the
    # run stopped at dt_min on "Newton did not converge: DIVERGED_LINE_SEARCH"
    (["--set", "parameters.C_0=0"], ["parameter C_0 = 0 with no fluid_pressure condition",
                                     "fixed only up to a constant", "give C_0 > 0 or hold p on a boundary"]),
    # one point per cell: the backends failed differently (fenicsx's initial velocity DIVERGED_BREAKDOWN; skfem took an
    # initial state 340% off and blamed chemotaxis.f at step 1), the cross-backend QA pass
    (["--set", "physics.poroelastic_growth.quadrature_degree=1"],
     ["physics.poroelastic_growth.quadrature_degree = 1 integrates at one point per cell", "at least 2"]),
], ids=["unknown-law", "law-of-the-wrong-dimension", "active-stress-with-growth", "negative-growth-rate",
        "a-sliding-tissue", "another-law-s-parameter",
        "zero-shear-modulus", "unknown-condition-kind", "unknown-accumulation", "skewed-directions", "no-directions",
        "negative-psi-stabilisation", "negative-p-stabilisation", "splits-without-fieldsplit", "no-storage",
        "one-point-quadrature"])
def test_a_bad_growth_config_is_one_line(primordia_cli, tmp_path, overrides, fragments):
    result = primordia_cli("run", EX02A, *COARSE, *overrides, "--out", tmp_path / "out")
    assert_one_line_error(result, *fragments)


@pytest.mark.parametrize("backend", ["fenicsx", "skfem"])
def test_no_storage_runs_when_a_boundary_holds_the_fluid_pressure(primordia_cli, tmp_path, backend):
    """C_0 = 0 (the edge of its constraint, C_0 >= 0) is well posed once p is held somewhere."""
    held = '[{boundary="left", type="normal_displacement"}, {boundary="left", type="fluid_pressure", value=0.0}, ' \
           + ", ".join(f'{{boundary="{side}", type="robin", value=1e-4}}' for side in ("right", "bottom", "top")) + "]"
    result = primordia_cli("run", EX02A, *COARSE, "--set", "parameters.C_0=0", "--set", f"physics.poroelastic_growth."
                           f"boundary={held}", "--backend", backend, "--out", tmp_path / "out")
    assert result.returncode == 0, result.stderr
    assert "2 steps on" in result.stdout and "rejected" not in result.stdout, result.stdout


EX04_SMALL = Path(__file__).resolve().parents[2] / "examples" / "ex04_small.toml"


@pytest.mark.parametrize("directions", ["[[1.0, 0.0], [0.0, 1.0]]", "[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]"],
                         ids=["2d-frame", "two-3d-vectors"])
def test_a_dry_run_refuses_directions_of_the_wrong_dimension_on_a_3d_slab(capsys, directions):
    """2D directions on example 4's box: --dry-run called the input valid, the run's set-up refused them;
    two 3D vectors were told they needed "2 vectors of 2 numbers (in 2D)"."""
    from primordia.cli import main

    status = main(["run", str(EX04_SMALL), "--set", "mesh.cells=[2,2,1]",
                   "--set", f"growth_law.directions={directions}", "--dry-run"])
    lines = capsys.readouterr().err.splitlines()
    assert status == 2 and len(lines) == 1, lines
    assert "growth_law.directions must be 3 vectors of 3 numbers" in lines[0] and "in 3D" in lines[0], lines[0]


def test_whether_the_conditions_enclose_the_tissue_is_found_once_a_set_up(tmp_path, monkeypatch):
    """The growth's failure hint looked at the mesh's boundary at every making of the subproblems (each checkpoint
    and rejected step, and the dry run twice): 1.1 s each on example 4 at 129,600 tetrahedra."""
    from primordia.coupling.orchestrator import Simulation
    from primordia.model import Model
    from primordia.physics import poroelastic_growth
    from primordia.physics.base import subproblems_of

    calls = []
    original = poroelastic_growth.encloses
    monkeypatch.setattr(poroelastic_growth, "encloses", lambda *args: calls.append(1) or original(*args))
    model = Model.from_file(EX02A, overrides=["mesh.cells=[3,3]", "time.t_final=0.2", "output.times=[0.2]"])
    sim = Simulation(model, backend="fenicsx", out_dir=tmp_path / "run")
    sim.check_forms()
    growth = next(p for p in model.physics_objects if p.name == "poroelastic_growth")
    sim._choose_backend(), sim._choose_splitting(), sim._discretise(), sim._create_fields(), sim._setup_physics()
    for _ in range(3):
        subproblems_of(growth), subproblems_of(growth, initial=True)
    assert len(calls) == 2  # once per set-up (the dry run's, then this one)


def test_a_slab_thin_for_its_cells_that_stops_the_schur_split_says_so(primordia_cli, tmp_path):
    """Example 4 on (0, 10)^2 x (0, 0.01) with 4 x 4 x 2 boxes stopped at its initial velocity with GMRES's
    DIVERGED_BREAKDOWN and "try other options" alone; the direct solve runs it."""
    thin = ["--set", "mesh.cells=[4,4,2]", "--set", "mesh.upper=[10.0,10.0,0.01]", "--set", "time.t_final=0.5",
            "--set", "output.times=[0.5]", "--set", "output.pictures=false", "--no-progress"]
    result = primordia_cli("run", EX04_SMALL, *thin, "--out", tmp_path / "out")
    assert_one_line_error(result, "poroelastic_growth", "the cells' edges differ up to 707-fold in length",
                          'physics.poroelastic_growth.preconditioner = "lu" solves directly')
