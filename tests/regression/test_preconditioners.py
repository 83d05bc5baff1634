"""Each of the seed's preconditioners (section 5.2) converges on a small case to the direct solver's answer.

Every system is run twice on a coarse example, once with a direct solve and once with the
preconditioner under test, on both backends where the system runs on both; the fields must agree
to the solvers' tolerances and the preconditioned run must really iterate (its Krylov counts are
read back).  Also: the splits are named by the physics' fields, and a wrong one is one line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from primordia.core.errors import ConfigError
from primordia.coupling.orchestrator import Simulation
from primordia.coupling.solver_options import unused
from primordia.model import Model

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
BACKENDS = ("fenicsx", "skfem")
QUIET = ["output.pictures=false", "output.series_every=1"]


def run(example: str, backend: str, tmp_path, steps: int, *overrides) -> Simulation:
    model = Model.from_file(EXAMPLES / f"{example}.toml", [*QUIET, *overrides])
    out = tmp_path / f"{example}-{backend}-{abs(hash(overrides))}"
    sim = Simulation(model, backend=backend, out_dir=out).setup()
    for _ in range(steps):
        sim.step()
    return sim


def assert_same_fields(direct: Simulation, iterative: Simulation, tolerance: float) -> None:
    reference, values = direct.vertex_values(), iterative.vertex_values()
    for name, expected in reference.items():
        scale = np.abs(expected).max()
        assert scale > 0, name
        difference = np.abs(values[name] - expected).max() / scale
        assert difference < tolerance, f"{name}: {difference:.1e} from the direct solve"


def krylov_iterations(sim: Simulation, subproblem: str) -> list[int]:
    return sim.iterations[subproblem]


# -- finite-strain growth: GMRES + lower Schur factorisation, AMG blocks, the seed's inexact Newton ----------
GROWTH = ["mesh.cells=[8,8]", "time.t_final=0.6", "output.times=[0.6]", 'coupling.scheme="sequential"',
          "solver.poroelastic_growth.snes_rtol=1e-10", "solver.poroelastic_growth.snes_atol=1e-12"]


@pytest.mark.parametrize("backend", BACKENDS)
def test_growth_schur_fieldsplit_reaches_the_direct_solution(backend, tmp_path):
    direct = run("ex02a", backend, tmp_path, 2, *GROWTH, 'physics.poroelastic_growth.preconditioner="lu"')
    schur = run("ex02a", backend, tmp_path, 2, *GROWTH, 'physics.poroelastic_growth.preconditioner="schur"')
    assert_same_fields(direct, schur, 1e-6)
    newton = sum(iterations for iterations, _ in schur.newton["poroelastic_growth"])
    assert sum(krylov_iterations(schur, "poroelastic_growth")) > 3 * newton  # it iterates: not a direct solve
    pc = schur.solvers[-1].ksp.getPC()
    assert pc.getType() == "fieldsplit"
    assert [ksp.getOptionsPrefix() for ksp in pc.getFieldSplitSubKSP()] == [
        "poroelastic_growth_fieldsplit_u_", "poroelastic_growth_fieldsplit_psi_p_"]
    u_block = pc.getFieldSplitSubKSP()[0]
    assert u_block.getPC().getType() == "gamg"
    assert u_block.getOperators()[1].getNearNullSpace().getVecs(), "the rigid-body modes reached AMG"


def test_growth_schur_fieldsplit_in_3d(tmp_path):
    three_d = ["mesh.cells=[4,4,2]", "time.t_final=1.0", "output.times=[1.0]", 'coupling.scheme="sequential"',
               "solver.poroelastic_growth.snes_rtol=1e-10", "solver.poroelastic_growth.snes_atol=1e-12"]
    direct = run("ex04_small", "fenicsx", tmp_path, 2, *three_d, 'physics.poroelastic_growth.preconditioner="lu"')
    schur = run("ex04_small", "fenicsx", tmp_path, 2, *three_d, 'physics.poroelastic_growth.preconditioner="schur"')
    assert_same_fields(direct, schur, 1e-6)


# -- linear Biot: the fixed-stress Schur fieldsplit instead of LU --------------------------------------------
BIOT = ["mesh.cells=[8,8]", "time.t_final=0.6", "output.times=[0.6]"]


@pytest.mark.parametrize("backend", BACKENDS)
def test_biot_fixed_stress_reaches_the_direct_solution(backend, tmp_path):
    direct = run("ex01b", backend, tmp_path, 3, *BIOT)
    fixed_stress = run("ex01b", backend, tmp_path, 3, *BIOT, 'physics.poroelasticity.preconditioner="fixed_stress"')
    assert_same_fields(direct, fixed_stress, 1e-7)
    assert min(krylov_iterations(fixed_stress, "poroelasticity")) > 2


# -- chemotaxis as one Newton system: the seed's block Jacobi (AMG on m, f, b; Jacobi on e) --------------------
COUPLED = ["mesh.cells=[8,8]", "time.t_final=0.6", "output.times=[0.6]", 'physics.chemotaxis.flux_scheme="galerkin"',
           'physics.chemotaxis.solve="coupled"']


@pytest.mark.parametrize("backend", BACKENDS)
def test_chemotaxis_block_jacobi_reaches_the_direct_solution(backend, tmp_path):
    direct = run("ex01a", backend, tmp_path, 3, *COUPLED, 'physics.chemotaxis.preconditioner="lu"')
    block_jacobi = run("ex01a", backend, tmp_path, 3, *COUPLED, 'physics.chemotaxis.preconditioner="block_jacobi"')
    assert_same_fields(direct, block_jacobi, 1e-8)
    pc = block_jacobi.solvers[0].ksp.getPC()
    assert [sub.getPC().getType() for sub in pc.getFieldSplitSubKSP()] == ["hypre", "jacobi", "hypre", "hypre"]


# -- the monolithic scheme: a configurable default, not MUMPS; a fieldsplit of the same system -----------------
def test_monolithic_takes_its_solver_from_defaults_and_the_config(tmp_path):
    mono = ["mesh.cells=[8,8]", "time.t_final=0.6", "output.times=[0.6]", 'physics.chemotaxis.flux_scheme="galerkin"',
            'coupling.scheme="monolithic"', "solver.monolithic.snes_rtol=1e-10", "solver.monolithic.snes_atol=1e-12"]
    direct = run("ex01b", "fenicsx", tmp_path, 2, *mono)
    assert direct.solvers[0].ksp.getPC().getFactorSolverType() == "petsc"  # PETSc's LU in serial, not MUMPS
    split = run("ex01b", "fenicsx", tmp_path, 2, *mono, 'solver.monolithic.ksp_type="gmres"',
                'solver.monolithic.pc_type="fieldsplit"', 'solver.monolithic.pc_fieldsplit_type="multiplicative"',
                'solver.monolithic.splits=[["m", "e", "f", "b"], ["u", "p"]]', "solver.monolithic.ksp_rtol=1e-10",
                'solver.monolithic.fieldsplit_m_e_f_b.pc_type="lu"', 'solver.monolithic.fieldsplit_u_p.pc_type="lu"')
    assert_same_fields(direct, split, 1e-8)


def test_splits_name_fields_of_the_subproblem(tmp_path):
    with pytest.raises(ConfigError, match=r"solver.poroelastic_growth.splits: 'q' is not a field of "
                                          r"poroelastic_growth \(fields: u, psi, p\)"):
        run("ex02a", "fenicsx", tmp_path, 0, *GROWTH, 'physics.poroelastic_growth.preconditioner="schur"',
            'solver.poroelastic_growth.splits=[["u"], ["q", "p"]]')


# -- the cell density's solve with BoomerAMG (HMIS coarsening, ext+i interpolation) -------------------------
HMIS = ['solver.chemotaxis_m.pc_type="hypre"', 'solver.chemotaxis_m.pc_hypre_boomeramg_coarsen_type="HMIS"',
        'solver.chemotaxis_m.pc_hypre_boomeramg_interp_type="ext+i"']


@pytest.mark.parametrize("backend", BACKENDS)
def test_cell_density_boomeramg_hmis_reaches_the_direct_solution(backend, tmp_path):
    """The configuration whose iterations stay flat over refinements (README, solver study)."""
    coarse = ["mesh.cells=[24,24]", "time.t_final=2.0", "output.times=[2.0]"]
    direct = run("ex01a", backend, tmp_path, 5, *coarse, 'solver.chemotaxis_m.ksp_type="preonly"',
                 'solver.chemotaxis_m.pc_type="lu"')
    amg = run("ex01a", backend, tmp_path, 5, *coarse, *HMIS)
    assert_same_fields(direct, amg, 1e-9)
    assert amg.solvers[0].ksp.getPC().getHYPREType() == "boomeramg"
    assert all(iterations >= 2 for iterations in krylov_iterations(amg, "chemotaxis.m"))  # it iterates
    # the default's "fresh+1" outlives the new pc_type: BoomerAMG is kept over steps, not built at each
    (solver,) = [s for s in amg.solvers if s.sub.name == "chemotaxis.m"]
    assert 1 <= solver.preconditioner_builds < 5, solver.preconditioner_builds


# -- f and b on a growing tissue: CG on an incomplete Cholesky factor, kept while it works -----------------------
@pytest.mark.parametrize("backend", BACKENDS)
def test_morphogens_on_a_growing_tissue_keep_an_incomplete_cholesky_and_reach_the_direct_solution(backend, tmp_path):
    """Their matrices follow the tissue's metric, so they change at every solve: the default keeps each
    rank's incomplete Cholesky factor over those solves while CG needs no more iterations than after its
    build, and the fields are the direct solve's."""
    steps, fixed_point = 3, [o for o in GROWTH if not o.startswith("coupling.")]  # ex02a's own: several solves a step
    lu = [f'solver.chemotaxis_{name}.{key}="{value}"' for name in "fb"
          for key, value in (("ksp_type", "preonly"), ("pc_type", "lu"))]
    direct = run("ex02a", backend, tmp_path, steps, *fixed_point, *lu)
    kept = run("ex02a", backend, tmp_path, steps, *fixed_point)
    assert_same_fields(direct, kept, 1e-9)
    solves_per_step = kept.coupling_iterations["fixed_point"]  # one solve of each species per outer iteration
    for name in "fb":
        (solver,) = [s for s in kept.solvers if s.sub.name == f"chemotaxis.{name}"]
        assert (solver.options["ksp_type"], solver.options["pc_type"], solver.options["sub_pc_type"]) == (
            "cg", "bjacobi", "icc")
        assert not unused(f"chemotaxis_{name}_", ["sub_pc_type"])  # PETSc read it
        # it iterates: at least two CG iterations a solve (a direct solve counts one)
        assert all(its >= 2 * solves for its, solves in zip(krylov_iterations(kept, f"chemotaxis.{name}"),
                                                             solves_per_step))
        assert 1 <= solver.preconditioner_builds < sum(solves_per_step) / 2, solver.preconditioner_builds


# -- the cell density keeps its preconditioner over time steps (rebuild_preconditioner_after = "fresh+1") --------
def _cell_density_run(backend: str, tmp_path, steps: int, *overrides) -> tuple[Simulation, int]:
    """Example 1a on a coarse mesh, and how many ILU factorisations its cell-density solves made (the
    factor matrix's PETSc state moves at each numeric factorisation).  ILU itself stands for the default
    block Jacobi/ILU, whose one block's factor petsc4py 3.18 cannot reach."""
    coarse = ["mesh.cells=[24,24]", "time.t_final=100.0", "output.times=[100.0]", 'solver.chemotaxis_m.pc_type="ilu"',
              'solver.chemotaxis_m.rebuild_preconditioner_after="fresh+1"']
    model = Model.from_file(EXAMPLES / "ex01a.toml", [*QUIET, *coarse, *overrides])
    sim = Simulation(model, backend=backend, out_dir=tmp_path / f"m-{backend}-{abs(hash(overrides))}").setup()
    (solver,) = [s for s in sim.solvers if s.sub.name == "chemotaxis.m"]
    states = set()
    for _ in range(steps):
        sim.step()
        pc = solver.ksp.getPC()
        if pc.getType() == "ilu":
            states.add(pc.getFactorMatrix().stateGet())
    return sim, len(states)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_cell_density_keeps_its_preconditioner_until_krylov_needs_more_and_reaches_the_same_fields(
        backend, tmp_path):
    """With the default bound (``"fresh+1"``) the ILU of an earlier step's matrix is kept until a solve needs
    one iteration more than the first after its build; every solve still reaches its tolerance with the current matrix, so the fields
    are those of a fresh preconditioner at every step and of a direct solve."""
    steps = 60
    kept, kept_factorisations = _cell_density_run(backend, tmp_path, steps)
    fresh, fresh_factorisations = _cell_density_run(backend, tmp_path, steps,
                                                    "solver.chemotaxis_m.rebuild_preconditioner_after=0")
    never, never_factorisations = _cell_density_run(backend, tmp_path, steps,
                                                    "solver.chemotaxis_m.rebuild_preconditioner_after=1000")
    direct, _ = _cell_density_run(backend, tmp_path, steps, 'solver.chemotaxis_m.ksp_type="preonly"',
                                  'solver.chemotaxis_m.pc_type="lu"', "solver.chemotaxis_m.rebuild_preconditioner_after=0")
    (solver,) = [s for s in kept.solvers if s.sub.name == "chemotaxis.m"]
    assert fresh_factorisations == steps  # PETSc's default: a changed matrix is factorised again
    assert never_factorisations == 1
    assert 1 < kept_factorisations < steps / 2, kept_factorisations
    assert solver.preconditioner_builds == kept_factorisations
    its = krylov_iterations(kept, "chemotaxis.m")
    assert max(its) > min(its)  # the kept ILU costs iterations as the matrix moves away from it
    assert_same_fields(fresh, kept, 1e-10)
    assert_same_fields(direct, kept, 1e-10)
    assert_same_fields(direct, never, 1e-10)


def test_a_solve_that_fails_with_a_kept_preconditioner_is_solved_again_with_a_fresh_one(tmp_path):
    """Never rebuilt, the ILU of the first step needs 5 GMRES iterations by step 20 of this run, a fresh
    one 3 or 4: with at most 4 allowed, those solves fail, are solved again with a fresh ILU, and the
    run goes on without a rejected step."""
    sim, factorisations = _cell_density_run("fenicsx", tmp_path, 60, "solver.chemotaxis_m.rebuild_preconditioner_after=1000",
                                            "solver.chemotaxis_m.ksp_max_it=4")
    (solver,) = [s for s in sim.solvers if s.sub.name == "chemotaxis.m"]
    assert sim.rejections == [] and len(krylov_iterations(sim, "chemotaxis.m")) == 60
    assert factorisations == solver.preconditioner_builds >= 2
    assert max(krylov_iterations(sim, "chemotaxis.m")) <= 4


def test_the_cell_density_keeps_its_preconditioner_by_default(tmp_path):
    """...and its ILU(1) works on an RCM ordering (fewer GMRES iterations than ILU(0), or the backends' DOF orders)."""
    sim = run("ex01a", "fenicsx", tmp_path, 1, "mesh.cells=[6,6]", "time.t_final=0.4", "output.times=[0.4]")
    (solver,) = [s for s in sim.solvers if s.sub.name == "chemotaxis.m"]
    assert solver.options["pc_type"] == "bjacobi" and solver._rebuild_after == "fresh+1"
    assert solver.options["sub_pc_factor_mat_ordering_type"] == "rcm" and solver.options["sub_pc_factor_levels"] == 1
    assert not unused("chemotaxis_m_", ["sub_pc_factor_mat_ordering_type", "sub_pc_factor_levels"])  # PETSc read them
    assert solver.preconditioner_builds == 1 and solver._rebuild_rule.keeps()  # built at the first solve, then kept
    sim.step()
    assert solver.preconditioner_builds == 1


def test_a_malformed_rebuild_bound_and_one_where_nothing_is_kept_are_refused(tmp_path):
    for overrides, fragment in [
            (['solver.poroelastic_growth.rebuild_preconditioner_after="fresh+"'], "must be a number of Krylov"),
            (['solver.chemotaxis_m.rebuild_preconditioner_after="2"'], "must be a number of Krylov iterations"),
            (['solver.chemotaxis_m.ksp_type="preonly"', 'solver.chemotaxis_m.pc_type="lu"',
              'solver.chemotaxis_m.rebuild_preconditioner_after="fresh+1"'], "needs a Krylov method")]:
        example = "ex02a" if "growth" in overrides[0] else "ex01a"
        with pytest.raises(ConfigError, match=fragment):
            run(example, "fenicsx", tmp_path, 1, "mesh.cells=[6,6]", "time.t_final=0.2", "output.times=[0.2]",
                *overrides)
