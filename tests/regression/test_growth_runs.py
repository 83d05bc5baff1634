"""Seed example 2a (section 5.4) and the finite-strain solver, on coarse meshes and both backends.

* Newton (PETSc SNES) contracts quadratically on a real step of example 2a, and every Jacobian is
  the derivative of its residual (central finite differences, both backends).
* Coarse example 2a gives the same fields on both backends, to the Newton tolerance.
* With the conservative accumulation d(J m)/dt, the cells int J m dX are conserved to solver
  tolerance while the tissue grows; with the seed's material form (4.17a) they grow with J
  (cells keep their density as the tissue grows) -- measured, not assumed.
* The series records the growth diagnostics, Newton iterations and SNES reasons; min m stays >= 0
  under the exponentially fitted flux on the moving metric (measured here).
* Every splitting scheme runs example 2a and agrees with the seed's fixed-point iteration to O(dt).
* Example 4 at laptop size (3D, the law (4.13)) runs a few steps and agrees between the backends.
* A box held on every face cannot grow (J_e = 1 asks J = J_g): one clear line, no NaN, no hang.
"""

from __future__ import annotations

import gc
import weakref
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from petsc4py import PETSc

import growth_test_laws
from petsc_garbage import garbage_report, run_communicators
from primordia.core.errors import ConfigError, SolverError
from primordia.core.meshes import rectangle
from primordia.coupling.orchestrator import Simulation
from primordia.coupling import solvers
from primordia.coupling.solvers import NewtonSolver
from primordia.model import Model

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
BACKENDS = ("fenicsx", "skfem")
COARSE = ["mesh.cells=[8,8]", "time.t_final=2.0", "output.times=[2.0]", "output.pictures=false",
          "output.series_every=1"]
EXACT_NEWTON = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps",
                "snes_lag_preconditioner": 1, "snes_rtol": 1e-12, "snes_atol": 1e-13}


def coarse_ex02a(backend, tmp_path, *extra) -> Simulation:
    model = Model.from_file(EXAMPLES / "ex02a.toml", [*COARSE, *extra])
    return Simulation(model, backend=backend, out_dir=tmp_path / backend).setup()


def growth_solver(sim) -> NewtonSolver:
    (solver,) = [s for s in sim.solvers if s.sub.name == "poroelastic_growth"]
    return solver


# -- Newton -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("backend", BACKENDS)
def test_newton_contracts_quadratically_on_a_step_of_example_2a(backend, tmp_path):
    sim = coarse_ex02a(backend, tmp_path, 'coupling.scheme="sequential"',
                       *(f"solver.poroelastic_growth.{k}={v}" for k, v in EXACT_NEWTON.items()))
    for _ in range(3):  # the first step jumps from the initial equilibrium (damped by the line search)
        sim.step()
    residuals = growth_solver(sim).history[0]
    assert len(residuals) >= 4, residuals  # enough iterations to see the rate
    above_noise = residuals[residuals > 1e-11 * residuals[0]]
    ratios = np.log(above_noise[2:] / residuals[0]) / np.log(above_noise[1:-1] / residuals[0])
    # quadratic: log r_{k+1} ~ 2 log r_k, relative to r_0 (linear convergence would give ~1)
    assert ratios.size and ratios.min() > 1.7, (residuals, ratios)


def _finite_difference_check(sim, subproblem, seed=0):
    """max |J v - (F(x + e v) - F(x - e v)) / 2e| relative to |J v|, at a perturbed state."""
    backend = sim.backend
    state = backend.local_array(subproblem.unknown)
    rng = np.random.default_rng(seed)
    state += 1e-3 * rng.standard_normal(state.shape) * max(1.0, np.abs(state).max())
    backend.update_ghosts(subproblem.unknown)
    x0 = state.copy()
    direction = rng.standard_normal(state.shape)
    jacobian = backend.assemble_matrix(subproblem.jacobian)
    Jv = jacobian.createVecLeft()
    v = jacobian.createVecRight()
    v.array[:] = direction[:len(v.array)]
    jacobian.mult(v, Jv)

    def residual(x):
        state[:] = x
        backend.update_ghosts(subproblem.unknown)
        return backend.assemble_vector(subproblem.residual).array.copy()

    epsilon = 1e-6
    difference = (residual(x0 + epsilon * direction) - residual(x0 - epsilon * direction)) / (2 * epsilon)
    state[:] = x0
    backend.update_ghosts(subproblem.unknown)
    return np.abs(difference - Jv.array).max() / np.abs(Jv.array).max()


def test_a_kept_preconditioner_is_rebuilt_when_krylov_needs_more_iterations_and_gives_the_same_run(tmp_path):
    """``rebuild_preconditioner_after`` (the 2D default: a MUMPS factorisation kept while GMRES needs at
    most 10 iterations): a lower bound rebuilds more often, 0 at every Newton step (PETSc's default),
    and the runs agree to the Newton tolerance, since every Newton step solves with the current tangent."""
    def run(after):
        model = Model.from_file(EXAMPLES / "ex02a.toml", [*COARSE, "mesh.cells=[12,12]", "time.t_final=3.0",
                                                          "output.times=[3.0]",
                                                          f"solver.poroelastic_growth.rebuild_preconditioner_after={after}"])
        sim = Simulation(model, backend="fenicsx", out_dir=tmp_path / str(after)).setup()
        while sim.step_index < model.num_steps:
            sim.step()
        solver = growth_solver(sim)
        newton = sum(n for n, _ in sim.newton["poroelastic_growth"])
        return sim.backend.local_array(sim.disc.unknown("u")).copy(), solver.preconditioner_builds, newton, solver

    kept, kept_builds, newton, solver = run(10)
    eager, eager_builds, _, _ = run(1)
    fresh, fresh_builds, _, _ = run(0)
    assert solver._kept is not None and solver.ksp.getType() == "gmres"
    assert 1 <= kept_builds < eager_builds, (kept_builds, eager_builds)
    assert kept_builds < newton  # kept over Newton steps and time steps
    assert fresh_builds == 0  # no kept matrix: PETSc builds the preconditioner at every Newton step
    scale = np.abs(fresh).max()
    assert np.abs(kept - fresh).max() < 1e-5 * scale and np.abs(eager - fresh).max() < 1e-5 * scale


def test_a_relative_bound_rebuilds_the_kept_preconditioner_after_a_solve_k_above_its_fresh_ones(tmp_path):
    """``rebuild_preconditioner_after = "fresh+K"`` on a Newton solve (the Schur fieldsplit's default): the
    kept AMG hierarchies are built again right after, and only after, a Krylov solve that needed more than K
    iterations above the most a Newton step needed with them fresh (from their build to the end of that
    Newton solve); a smaller K builds more often, and the runs agree to the Newton tolerance."""
    def run(after):
        model = Model.from_file(EXAMPLES / "ex02a.toml", [*COARSE, "mesh.cells=[12,12]", "time.t_final=3.0",
                                                          "output.times=[3.0]",
                                                          'physics.poroelastic_growth.preconditioner="schur"',
                                                          f'solver.poroelastic_growth.rebuild_preconditioner_after="{after}"'])
        sim = Simulation(model, backend="fenicsx", out_dir=tmp_path / after).setup()
        solver = growth_solver(sim)
        events = []  # ("solve", Krylov iterations), ("build", None), ("newton", None) at a Newton solve's end
        solver.ksp.setMonitor(lambda ksp, its, rnorm: events.append(("solve", its)) if its == 0
                              else events.__setitem__(-1, ("solve", its)))
        built, newton = type(solver)._built_kept, type(solver)._run_snes
        solver._built_kept = lambda: events.append(("build", None)) or built(solver)
        solver._run_snes = lambda: newton(solver) or events.append(("newton", None))
        while sim.step_index < model.num_steps:
            sim.step()
        return sim.backend.local_array(sim.disc.unknown("u")).copy(), events

    def rebuilds_where_due(events, margin):
        fresh, measuring, due = 0, False, False
        for kind, iterations in events:
            if kind == "build":
                assert due or not fresh, "built again though no solve went over the bound"
                fresh, measuring, due = 0, True, False
            elif kind == "newton":
                measuring = False
            elif measuring:
                fresh = max(fresh, iterations)
            else:
                assert not due, "a solve over the bound was not followed by a build"
                due = iterations > fresh + margin
        return sum(kind == "build" for kind, _ in events)

    tight, tight_events = run("fresh+0")
    loose, loose_events = run("fresh+6")
    tight_builds, loose_builds = rebuilds_where_due(tight_events, 0), rebuilds_where_due(loose_events, 6)
    solves = sum(kind == "solve" for kind, _ in loose_events)
    assert 1 <= loose_builds < tight_builds < solves / 2, (loose_builds, tight_builds, solves)
    assert np.abs(tight - loose).max() < 1e-5 * np.abs(tight).max()


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_matrix_free_tangent_is_assembled_only_for_the_kept_preconditioner_and_gives_the_same_run(
        backend, tmp_path, monkeypatch):
    """The 2D default (``snes_mf_operator`` with the kept factorisation): GMRES applies the tangent by
    differences of the residual, the tangent is assembled only when the factorisation is refreshed, and
    the run agrees with one that assembles it at every Newton step to the Newton tolerance."""
    def run(matrix_free):
        model = Model.from_file(EXAMPLES / "ex02a.toml", [*COARSE, "time.t_final=1.0", "output.times=[1.0]",
                                                          f"solver.poroelastic_growth.snes_mf_operator={matrix_free}"])
        sim = Simulation(model, backend=backend, out_dir=tmp_path / str(matrix_free)).setup()
        solver = growth_solver(sim)
        assembled = []
        tangent = type(solver)._assemble_jacobian
        monkeypatch.setattr(solver, "_assemble_jacobian", lambda: assembled.append(1) or tangent(solver))
        while sim.step_index < model.num_steps:
            sim.step()
        newton = sum(n for n, _ in sim.newton["poroelastic_growth"])
        operator = solver.snes.getKSP().getOperators()[0].getType()
        return sim.backend.local_array(sim.disc.unknown("u")).copy(), len(assembled), solver.preconditioner_builds, \
            newton, operator

    free, free_tangents, free_builds, newton, free_operator = run("true")
    assembled, tangents, _, _, operator = run("false")
    assert free_operator == PETSc.Mat.Type.MFFD and operator != PETSc.Mat.Type.MFFD
    assert tangents >= newton  # every Newton step assembles its tangent
    assert free_tangents == free_builds < newton  # only to build or refresh the kept factorisation
    assert np.abs(free - assembled).max() < 1e-6 * np.abs(assembled).max()


def test_rebuild_preconditioner_after_is_refused_where_it_cannot_work(tmp_path):
    for table, fragment in [
            (["solver.poroelastic_growth.ksp_type=\"preonly\"", "solver.poroelastic_growth.rebuild_preconditioner_after=5"],
             "needs a Krylov method"),
            (["solver.chemotaxis_e.rebuild_preconditioner_after=5"], "needs a Krylov method")]:
        with pytest.raises(ConfigError, match=fragment):
            coarse_ex02a("fenicsx", tmp_path, *table)


@pytest.mark.parametrize("backend", BACKENDS)
def test_every_jacobian_is_the_derivative_of_its_residual(backend, tmp_path):
    sim = coarse_ex02a(backend, tmp_path, 'physics.chemotaxis.flux_scheme="galerkin"')
    sim.step()
    subproblems = [solver.sub for solver in sim.solvers]
    subproblems += sim.model.physics_objects[1].initial_subproblems()
    assert {"poroelastic_growth", "poroelastic_growth.initial", "chemotaxis.m"} <= {s.name for s in subproblems}
    for subproblem in subproblems:
        error = _finite_difference_check(sim, subproblem)
        assert error < 1e-6, f"{subproblem.name}: finite-difference mismatch {error:.1e}"


# -- example 2a, coarse ----------------------------------------------------------------------------------
def _run(backend, tmp_path, *extra):
    model = Model.from_file(EXAMPLES / "ex02a.toml", [*COARSE, *extra])
    return model.run(backend=backend, out=tmp_path / backend)


def test_coarse_example_2a_agrees_between_the_backends(tmp_path):
    tight = ["coupling.tolerance=1e-10", "solver.poroelastic_growth.snes_rtol=1e-10",
             "solver.poroelastic_growth.snes_atol=1e-12"]
    sims = {backend: _run(backend, tmp_path, *tight) for backend in BACKENDS}
    values = {backend: sim.vertex_values() for backend, sim in sims.items()}
    for name, reference in values["fenicsx"].items():
        assert np.ptp(reference) > 0, f"{name} is uniform: nothing is compared"
        difference = np.abs(values["skfem"][name] - reference).max() / np.abs(reference).max()
        assert difference < 1e-8, f"{name}: the backends differ by {difference:.1e}"
    series = {backend: xr.open_dataset(tmp_path / backend / "series.nc") for backend in BACKENDS}
    for key in ("cell_amount", "current_volume", "J_min", "J_max", "J_e_minus_1_max"):
        np.testing.assert_allclose(series["skfem"][key], series["fenicsx"][key], rtol=1e-8, atol=1e-10)


def test_series_records_the_growth_and_the_solver(tmp_path):
    sim = _run("fenicsx", tmp_path)
    series = xr.open_dataset(tmp_path / "fenicsx" / "series.nc")
    for key in ("cell_amount", "current_volume", "J_min", "J_max", "J_e_minus_1_min", "J_e_minus_1_max",
                "poroelastic_growth_newton_iterations", "poroelastic_growth_snes_reason", "fixed_point_iterations"):
        assert key in series, key
    newton = series["poroelastic_growth_newton_iterations"].values[1:]
    assert np.all(newton >= 1) and np.all(series["poroelastic_growth_snes_reason"].values[1:] > 0)
    # the tissue grows: area from 400 (times the initial growth) upwards, J > 1 everywhere
    area = series["current_volume"].values
    assert area[0] > 400.0 and np.all(np.diff(area) > 0)
    assert series["J_min"].values[-1] > 1.0
    # the exponentially fitted flux on the moving metric: the metric's shear makes some edge weights
    # negative (no M-matrix guarantee), m stays >= 0 here (measured, see README)
    assert np.all(series["m_most_negative_edge_weight"].values <= 0.0)
    assert series["m_negative_edge_weights"].values.max() > 0
    assert series["m_min"].values.min() >= 0.0
    assert sim.summary("completed")["mean_newton_iterations"]["poroelastic_growth"] >= 1


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_step_of_a_growing_tissue_leaves_no_petsc_objects_behind(backend, tmp_path, capfd):
    """petsc4py (3.18) frees a dropped object only at ``garbage_cleanup`` of its communicator, the
    serial COMM_SELF included. The fitted flux's serial entry matrix, rebuilt at every update on a
    moving mesh, piled up there: example 2a at the seed's 171^2 grew 18 MB a step until the kernel
    killed it at 13 GB. After a step (which collects the run's garbage) nothing may be left."""
    sim = coarse_ex02a(backend, tmp_path)
    for _ in range(2):
        sim.step()
    comms = run_communicators(sim)
    empty, report = garbage_report(comms, capfd)
    assert empty == len(comms), report


def test_solvers_made_anew_free_the_old_ones_without_waiting_for_a_full_collection(tmp_path):
    """At every checkpoint and rejected step the solvers are made anew. A Newton solver whose SNES held
    it through its callbacks lived on in a reference cycle until Python's next full collection, with
    its factorisation: example 2a at 171^2 grew by over 1 GB at each checkpoint."""
    sim = coarse_ex02a("fenicsx", tmp_path)
    sim.step()
    old = [weakref.ref(solver) for solver in sim.solvers]
    gc.disable()
    try:
        sim._create_solvers()
        alive = [ref().sub.name for ref in old if ref() is not None]
    finally:
        gc.enable()
    assert alive == []


@pytest.mark.parametrize("example", ["ex02a", "ex02b"])
def test_solvers_made_anew_are_destroyed_before_the_new_ones_factorise(example, tmp_path, capfd):
    """At a checkpoint the old solvers' PETSc objects go at once, before the next step factorises anew:
    a loop variable that kept the last old solver (the Newton solver), and the old diagnostics that kept
    the fitted operators, left them to the next step's collection, after the new factorisation.
    Example 2b at 171^2 then held two MUMPS factorisations: 1.74 -> 3.06 GB after its first checkpoint."""
    sim = Simulation(Model.from_file(EXAMPLES / f"{example}.toml", COARSE), backend="fenicsx",
                     out_dir=tmp_path).setup()
    sim.step()
    comms = run_communicators(sim)
    sim._create_solvers()  # as at a checkpoint, no step after it
    empty, report = garbage_report(comms, capfd)
    assert empty == len(comms), report


def test_a_snes_kept_past_its_solver_says_the_solver_is_gone(tmp_path):
    """The SNES holds its solver only weakly (see above): used after the solver was dropped, its
    callbacks say so, instead of calling None."""
    sim = coarse_ex02a("fenicsx", tmp_path)
    solver = growth_solver(sim)
    snes, x, f = solver.snes, solver._F.duplicate(), solver._F.duplicate()
    x.set(0.0)
    del solver
    sim._create_solvers()
    gc.collect()
    with pytest.raises(SolverError, match="the solver that made this SNES is gone"):
        snes.computeFunction(x, f)


def test_solvers_made_anew_leave_no_petsc_objects_behind(tmp_path, capfd):
    """dolfinx makes PETSc objects on duplicates of the communicator (one per function space's index map),
    and PETSc keeps each one's garbage apart: the old solvers' matrices and vectors (a factorisation's
    worth, 4.7 MB at 43^2 for linear Biot) stayed on communicators the run never cleaned."""
    sim = Simulation(Model.from_file(EXAMPLES / "ex01b.toml", ["mesh.cells=[8,8]", "output.pictures=false",
                                                                "output.times=[]"]),
                     backend="fenicsx", out_dir=tmp_path).setup()
    sim.step()
    objects = [obj for solver in sim.solvers for obj in vars(solver).values() if isinstance(obj, PETSc.Object)]
    comms = {comm.tompi4py().py2f(): comm for comm in (obj.getComm() for obj in objects)}
    del objects
    sim._create_solvers()
    sim.step()  # which collects the garbage
    empty, report = garbage_report(comms.values(), capfd)
    assert empty == len(comms) >= 2, report


def test_the_constraint_residual_at_the_vertices_shrinks_with_the_mesh(tmp_path):
    """J_e = 1 (4.12c) holds weakly (P1 multiplier): at the vertices J_e - 1 is a discretisation error.

    Measured (t = 2, max |J_e - 1| over cell vertices): 0.032 on 8 x 8, 0.014 on 16 x 16, 0.0046 on 32 x 32
    squares of (0, 20)^2 (README "Findings"); the second step, to t = 0.4, is the worst (0.071, 0.030, 0.010).
    """
    largest = []
    for cells in (8, 16):
        _run("fenicsx", tmp_path / str(cells), f"mesh.cells=[{cells},{cells}]")
        series = xr.open_dataset(tmp_path / str(cells) / "fenicsx" / "series.nc")
        largest.append(max(abs(series["J_e_minus_1_min"].values[-1]), abs(series["J_e_minus_1_max"].values[-1])))
    assert largest[1] < 0.7 * largest[0] and largest[1] < 0.05, largest


@pytest.mark.parametrize("backend", BACKENDS)
def test_cells_are_conserved_by_the_conservative_accumulation(backend, tmp_path):
    five_steps = "time.dt=0.4"  # to t = 2 as the other coarse runs, in half their steps
    sim = _run(backend, tmp_path, 'physics.chemotaxis.accumulation="conservative"', "coupling.tolerance=1e-11",
               five_steps)
    series = xr.open_dataset(tmp_path / backend / "series.nc")
    amount, area = series["cell_amount"].values, series["current_volume"].values
    assert len(amount) == 6
    assert area[-1] > 1.5 * area[0]  # the tissue grew by half, at least
    assert np.abs(amount - amount[0]).max() < 1e-9 * amount[0], amount
    # and the seed's material form (4.17a) does not conserve them: cells are carried with the growth
    material = _run(backend, tmp_path / "material", five_steps).out_dir / "series.nc"
    material = xr.open_dataset(material)["cell_amount"].values
    assert material[-1] > 1.3 * material[0]
    assert sim.status == "completed"


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_monolithic_scheme_conserves_the_cells_to_its_newton_tolerance(backend, tmp_path):
    """The README said monolithic, like fixed_point, kept the drift below 1e-9 at coupling.tolerance = 1e-11, an
    option monolithic ignores; no test ran it.  Its tolerance is the Newton solve's: 1.0e-7 at the default
    snes_rtol (drift 1.04e-7 on both backends), 4e-15 at 1e-12."""
    monolithic = ['coupling.scheme="monolithic"', 'physics.chemotaxis.flux_scheme="galerkin"',
                  'physics.chemotaxis.accumulation="conservative"', "time.dt=0.4"]
    for label, tolerance in (("default", []), ("tight", ["solver.monolithic.snes_rtol=1e-12",
                                                         "solver.monolithic.snes_atol=1e-14"])):
        sim = _run(backend, tmp_path / label, *monolithic, *tolerance)
        amount = xr.open_dataset(sim.out_dir / "series.nc")["cell_amount"].values
        drift = np.abs(amount / amount[0] - 1.0).max()
        assert sim.status == "completed" and len(amount) == 6
        assert drift < (1e-12 if tolerance else 1e-6), (label, amount)


def _cell_amounts(tmp_path, *extra):
    """int J m dX at every step of coarse example 2a with the conservative accumulation (5 steps to t = 2)."""
    sim = _run("fenicsx", tmp_path, 'physics.chemotaxis.accumulation="conservative"', "time.dt=0.4", *extra)
    return sim, xr.open_dataset(sim.out_dir / "series.nc")["cell_amount"].values


@pytest.mark.parametrize("inner_steps", [1, 2])
def test_strang_conserves_the_cells_whose_half_steps_straddle_the_growth(inner_steps, tmp_path):
    """The species read J where they were last balanced (Discretisation.at_balance), not at the start of the
    mechanics' step: strang then counts each volume change once. Before, int J m dX fell to 0.55 of its start
    whatever dt (each change counted twice), and strang was refused with this accumulation."""
    _, amount = _cell_amounts(tmp_path, 'coupling.scheme="strang"', f"coupling.inner_steps={inner_steps}")
    assert np.abs(amount / amount[0] - 1.0).max() < 1e-12, amount


def test_sequential_inner_steps_count_each_volume_change_once(tmp_path):
    """Lie splitting with the species first lags the mechanics by one step (int J m dX at the output reads the
    J the species have not balanced yet: 7.5% here at t = 2, converging with dt); inner steps of the species
    counted the last change again (6.0% against 3.5% at dt = 0.2 on 6 x 6) and now leave the lag as it is."""
    _, one = _cell_amounts(tmp_path / "1", 'coupling.scheme="sequential"')
    _, two = _cell_amounts(tmp_path / "2", 'coupling.scheme="sequential"', "coupling.inner_steps=2")
    assert np.abs(two / one - 1.0).max() < 1e-4, (one, two)


def test_a_restart_keeps_where_the_species_were_last_balanced(tmp_path):
    """Under sequential the species were last balanced on the displacement before the last growth step, not
    on the current one: the checkpoint holds it, so a restart ends as the uninterrupted run does."""
    whole, _ = _cell_amounts(tmp_path / "whole", 'coupling.scheme="sequential"')
    first, _ = _cell_amounts(tmp_path / "parts", 'coupling.scheme="sequential"', "time.t_final=1.2",
                             "output.times=[1.2]")
    config = first.out_dir / "config.toml"
    resumed = Model.from_file(config, ["time.t_final=2.0", "output.times=[2.0]"]).run(
        backend="fenicsx", out=first.out_dir, restart=True)
    expected, values = whole.vertex_values(), resumed.vertex_values()
    for name in ("m", "u", "psi", "p"):
        # the reused factorisation is made anew at the restart: equal to the solver tolerances (5e-8 here);
        # a restart reading the balance at the current displacement differed by 12% in m
        assert np.abs(values[name] - expected[name]).max() <= 1e-6 * np.abs(expected[name]).max(), name


@pytest.mark.parametrize("scheme", ["sequential", "strang", "monolithic"])
def test_every_splitting_scheme_runs_example_2a(scheme, tmp_path):
    extra = ['physics.chemotaxis.flux_scheme="galerkin"'] if scheme == "monolithic" else []
    reference = _run("fenicsx", tmp_path / "fixed_point", *extra).vertex_values()
    values = _run("fenicsx", tmp_path / scheme, f'coupling.scheme="{scheme}"', *extra).vertex_values()
    for name in ("m", "u", "psi", "p"):
        difference = np.abs(values[name] - reference[name]).max() / np.abs(reference[name]).max()
        assert difference < 0.05, f"{scheme}: {name} differs from the fixed-point run by {difference:.1e}"


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_monolithic_scheme_runs_growth_with_the_seed_s_schur_preconditioner(backend, tmp_path):
    """The Schur split u | (psi, p), the default in 3D, named the growth's fields alone; under the monolithic
    scheme its initial solve is grouped with m, e, f, b, and the run stopped before its first step with
    "solver.poroelastic_growth_initial.splits must hold every field ..." for a table nobody wrote."""
    overrides = ["mesh.cells=[3,3]", "time.t_final=0.2", "output.times=[0.2]", "output.pictures=false",
                 'coupling.scheme="monolithic"', 'physics.chemotaxis.flux_scheme="galerkin"']
    values = {}
    for preconditioner in ("schur", "lu"):
        model = Model.from_file(EXAMPLES / "ex02a.toml",
                                [*overrides, f'physics.poroelastic_growth.preconditioner="{preconditioner}"'])
        sim = model.run(backend=backend, out=tmp_path / preconditioner)
        assert sim.status == "completed"
        values[preconditioner] = sim.vertex_values()
    for name in ("u", "psi", "p", "m"):
        reference = values["lu"][name]
        assert np.abs(values["schur"][name] - reference).max() < 1e-6 * np.abs(reference).max(), name


def test_strang_s_fluid_source_reads_the_chemistry_s_rate_over_its_own_half_step(tmp_path):
    """The growth's fluid source (4.15) reads dm/dt.  Under strang the chemistry has moved m over dt / 2 when
    the mechanics runs over dt, and (m - m^n) / dt halved it: p moved away from the fixed-point solution as dt
    shrank (relative distances 7.8e-6, 1.18e-5, 1.39e-5 at dt = 0.05, 0.025, 0.0125).  Over the chemistry's own
    half step it converges at first order (9.49e-6, 4.65e-6, 2.30e-6, orders 1.03, 1.01; skfem the same).
    Until 2026-12-05 this took two dt and asked only for a ratio below 0.7 (an order above 0.5), and its
    docstring and the README gave distances (2.68e-4, 1.33e-4) that this configuration does not give."""
    base = ["mesh.cells=[6,6]", "mesh.upper=[4.0,4.0]", "time.t_final=0.4", "output.times=[0.4]",
            "output.pictures=false", "parameters.ell_0=0.05", "kinetics.priming_wave=false",
            "physics.chemotaxis.perturbation=0.3"]
    steps, distances = (0.05, 0.025, 0.0125), []
    for dt in steps:
        p = {}
        for scheme in ("fixed_point", "strang"):
            extra = ["coupling.tolerance=1e-10"] if scheme == "fixed_point" else []
            model = Model.from_file(EXAMPLES / "ex02a.toml", [*base, f"time.dt={dt}", f'coupling.scheme="{scheme}"',
                                                              *extra])
            p[scheme] = model.run(backend="fenicsx", out=tmp_path / f"{scheme}_{dt}").vertex_values()["p"]
        distances.append(np.linalg.norm(p["strang"] - p["fixed_point"]) / np.linalg.norm(p["fixed_point"]))
    orders = np.diff(np.log(distances)) / np.diff(np.log(steps))
    assert np.all(np.abs(orders - 1.0) < 0.2), (distances, orders)
    assert 5e-6 < distances[0] < 2e-5, distances  # the size measured: the distance is the splitting's, not noise


def test_example_4_at_laptop_size_runs_and_agrees_between_the_backends(tmp_path):
    overrides = ["mesh.cells=[4,4,1]", "time.t_final=1.0", "output.times=[1.0]", "output.pictures=false",
                 "coupling.tolerance=1e-10", "solver.poroelastic_growth.snes_rtol=1e-10",
                 "solver.poroelastic_growth.snes_atol=1e-13", 'physics.poroelastic_growth.preconditioner="lu"']
    values = {}
    for backend in BACKENDS:
        sim = Model.from_file(EXAMPLES / "ex04_small.toml", overrides).run(backend=backend, out=tmp_path / backend)
        assert sim.status == "completed" and sim.disc.gdim == 3
        values[backend] = sim.vertex_values()
    for name, reference in values["fenicsx"].items():
        difference = np.abs(values["skfem"][name] - reference).max() / max(np.abs(reference).max(), 1e-300)
        assert difference < 1e-7, (name, difference)
    # k_3 growth is driven by m: the slab thickens
    assert values["fenicsx"]["u"][:, 2].max() > 0.0


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_box_held_on_every_face_cannot_grow(backend, tmp_path):
    faces = ["left", "right", "bottom", "top"]
    with growth_test_laws.registered():
        model = Model(physics=["poroelastic_growth"], growth_law="test_linear", parameters={"r": 0.1},
                      mesh=rectangle((0, 0), (1, 1), (4, 4)), dt=0.5, t_final=2.0,
                      dt_min=0.1,  # two halvings, then the failure (ten would fail the same way, in 17 s on skfem)
                      physics_options={"poroelastic_growth": {
                          "boundary": [{"boundary": b, "type": "normal_displacement"} for b in faces]}},
                      output={"pictures": False})
        with pytest.raises(SolverError) as failure:
            model.run(backend=backend, out=tmp_path / backend)
    message = str(failure.value)
    assert "\n" not in message and "Newton did not converge" in message
    assert "growth cannot be accommodated" in message and "(t = 0 -> 0.125)" in message  # halved down to dt_min


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_tissue_moved_on_every_face_is_told_why_it_has_no_unique_solution(backend, tmp_path):
    """u = (A - I) X on every face with det A = g^2, the growth's J_g: the data agree with J_e = 1 (seed (4.12c)),
    but psi is then fixed only up to a constant and the solve fails.  The hint said that "the volume of Omega_0
    cannot change", which the data change by 41%, and that the growth could not be accommodated, which it is."""
    A = np.array([[1.3, 0.2], [0.1, 1.1]])
    value = [f"{A[i, 0] - (i == 0)!r} * x[0] + {A[i, 1] - (i == 1)!r} * x[1]" for i in range(2)]
    with growth_test_laws.registered():
        model = Model(physics=["poroelastic_growth"], growth_law="test_uniform",
                      parameters={"g": float(np.sqrt(np.linalg.det(A)))}, mesh=rectangle((0, 0), (1, 1), (2, 2)),
                      dt=0.5, t_final=0.5, physics_options={"poroelastic_growth": {"boundary": [
                          {"boundary": b, "type": "displacement", "value": value}
                          for b in ("left", "right", "bottom", "top")]}}, output={"pictures": False})
        with pytest.raises(SolverError) as failure:
            model.run(backend=backend, out=tmp_path / backend)
    message = str(failure.value)
    assert "\n" not in message and "initial state" in message
    assert "volume of Omega_0 cannot change" not in message
    assert "the boundary values fix the current volume" in message and "psi only up to a constant" in message


def test_faster_growth_starts_without_rejected_steps(tmp_path):
    """delta_2 = 0.5 (3.3 times the seed's): the tissue starts moving with its growth, so Newton is within
    its radius from the first step; from rest (u_t(0) = 0) it failed at every dt down to dt/1024."""
    sim = _run("fenicsx", tmp_path, "parameters.delta_2=0.5")
    series = xr.open_dataset(tmp_path / "fenicsx" / "series.nc")
    assert sim.status == "completed" and series["rejections"].values.max() == 0
    assert series["poroelastic_growth_newton_iterations"].values[1:].max() <= 8


def test_a_later_fixed_point_pass_need_not_go_below_the_step_s_round_off(tmp_path, monkeypatch):
    """Within a step, a later fixed-point pass starts nearly converged, and snes_atol may lie below what round-off
    leaves of the step's residual (which carries rho / dt^2): example 2a at 6 x 6 with delta_2 = 5 stalled at
    1.9e-6 above snes_atol = 1e-7 and stopped at dt_min.  Within ``repeated_within_a_step`` a solve that starts
    below ROUND_OFF_FLOOR times the step's first initial residual takes no Newton step; alone it does.  The floor
    is raised here so that a nudge far above round-off lies below it."""
    monkeypatch.setattr(solvers, "ROUND_OFF_FLOOR", 1e-7)
    config = ["mesh.cells=[4,4]", "time.dt=1e-3", "time.t_final=2e-3", "output.times=[2e-3]", "output.pictures=false"]
    sim = Simulation(Model.from_file(EXAMPLES / "ex02a.toml", config), backend="fenicsx", out_dir=tmp_path).setup()
    solver = next(solver for solver in sim.solvers if isinstance(solver, NewtonSolver))
    with sim.substep(sim.disc.groups(), 1e-3, 1e-3):
        state = sim.backend.petsc_vector(solver.sub.unknown)

        def nudged():  # a change far below the step's first residual, far above snes_atol
            state.array[:] += 1e-11 * np.abs(state.array).max()
            sim.backend.update_ghosts(solver.sub.unknown)

        with solver.repeated_within_a_step():
            assert solver.solve().newton_iterations >= 2
            reference = solver.history[0][0]
            nudged()
            later = solver.solve()
            assert later.newton_iterations == 0 and 1e-7 < solver.history[0][0] < 1e-7 * reference
        nudged()
        assert solver.solve().newton_iterations >= 1  # alone, snes_atol = 1e-7 decides
        assert solver.snes.getTolerances()[1] == 1e-7  # and the pass's tolerance is not left behind
