"""The shared petsc4py solver layer."""

import numpy as np
import pytest
import ufl

from primordia.backends.fenicsx import FenicsxBackend
from primordia.core.meshes import rectangle
from primordia.coupling.solvers import KeptPreconditioner, SubproblemSolver
from primordia.physics.base import Subproblem


def _stokes(backend):
    """Taylor-Hood Stokes: a zero pressure block, which unpivoted LU cannot factorise."""
    mesh = backend.create_mesh(rectangle((0, 0), (1, 1), (4, 4)))
    cell = mesh.ufl_cell()
    space = backend.function_space(mesh, ufl.MixedElement([ufl.VectorElement("Lagrange", cell, 2),
                                                            ufl.FiniteElement("Lagrange", cell, 1)]))
    state = backend.function(space, "w")
    u, p = ufl.split(state)
    v, q = ufl.TestFunctions(space)
    dx = backend.measure("dx", mesh)
    residual = (ufl.inner(ufl.grad(u), ufl.grad(v)) - p * ufl.div(v) - q * ufl.div(u)
                - ufl.inner(ufl.as_vector([1.0, 0.0]), v)) * dx
    bc = backend.dirichlet_bc(space, "left", [0.0, 0.0], component=0)
    return state, Subproblem("stokes_test", state, residual, ufl.derivative(residual, state), bcs=[bc],
                             petsc_options={"ksp_type": "preonly", "pc_type": "lu"})


def test_a_zero_pivot_in_unpivoted_lu_falls_back_to_mumps(capsys):
    """Said in primordia's one line (a Python warning was two, once per rank, and FFCx's logging made them
    ``WARNING:py.warnings:`` lines)."""
    backend = FenicsxBackend()
    state, problem = _stokes(backend)
    solver = SubproblemSolver(backend, problem)
    assert solver.ksp.getPC().getFactorSolverType() == "petsc"
    solver.solve()
    assert capsys.readouterr().err == ("primordia: warning: stokes_test: PETSc's unpivoted LU met a zero pivot, "
                                       "switching to MUMPS\n")
    assert solver.ksp.getPC().getFactorSolverType() == "mumps"
    assert solver.ksp.getConvergedReason() > 0
    assert np.isfinite(backend.local_array(state)).all() and np.abs(backend.local_array(state)).max() > 0


def test_the_fallback_to_mumps_drops_a_default_ordering_for_its_own():
    """Handed PETSc's nested dissection, MUMPS factorises in that order (ICNTL(7) = 1) with many times the fill
    of its own analysis; the PC keeps the ordering it read, so the fallback sets MUMPS's own again."""
    backend = FenicsxBackend()
    state, problem = _stokes(backend)
    problem.petsc_options["pc_factor_mat_ordering_type"] = "nd"
    solver = SubproblemSolver(backend, problem)
    solver.solve()
    factor = solver.ksp.getPC().getFactorMatrix()
    assert factor.getType() == "mumps" and factor.getMumpsIcntl(7) != 1
    assert solver.ksp.getConvergedReason() > 0


def _reaction_diffusion(name, petsc_options):
    """A symmetric positive definite linear subproblem on a 4 x 4 mesh, and its backend."""
    backend = FenicsxBackend()
    mesh = backend.create_mesh(rectangle((0, 0), (1, 1), (4, 4)))
    space = backend.function_space(mesh, ufl.FiniteElement("Lagrange", mesh.ufl_cell(), 1))
    u, v = backend.function(space, "u"), ufl.TestFunction(space)
    residual = (ufl.inner(ufl.grad(u), ufl.grad(v)) + u * v - v) * backend.measure("dx", mesh)
    return backend, Subproblem(name, u, residual, ufl.derivative(residual, u), petsc_options=petsc_options)


def test_a_petsc_error_in_an_iterative_solve_is_one_solver_error_not_swallowed():
    from primordia.core.errors import SolverError

    # A preconditioner PETSc cannot set up (composite without sub-preconditioners) raises inside KSPSolve.
    # Not ksp_error_if_not_converged: after any earlier PETSc error inside a KSPSolve (another test's), PETSc
    # 3.18's static nesting level of KSPSolve stays raised and DIVERGED_ITS no longer raises.
    backend, problem = _reaction_diffusion("raising_test", {"ksp_type": "gmres", "pc_type": "composite"})
    with pytest.raises(SolverError, match=r"^raising_test: the linear solve failed \(PETSc error 73: No composite"):
        SubproblemSolver(backend, problem).solve()


def test_a_petsc_error_in_a_factorisation_is_its_own_not_a_zero_pivot(capsys):
    """Any error PETSc raised under an unpivoted LU was taken for a zero pivot: a warning said so, MUMPS was tried,
    and the run then stopped on the option that caused it as one PETSc "did not use" (here a factor viewer
    named "true", which PETSc cannot open)."""
    from primordia.core.errors import SolverError

    backend, problem = _reaction_diffusion("factor_view_test", {"ksp_type": "preonly", "pc_type": "lu"})
    solver = SubproblemSolver(backend, problem, {"mat_factor_view": "true"})
    with pytest.raises(SolverError, match=r"^factor_view_test: the linear solve failed \(PETSc error 56: "
                                          r"Unsupported viewer true \(in mat_factor_view = 'true'\)\)"):
        solver.solve()
    assert "zero pivot" not in capsys.readouterr().err
    assert solver.ksp.getPC().getFactorSolverType() == "petsc"


def _fake_solver(name, reads=(), gathered=True, ranks=2):
    """What independent_batches reads of a solver: whether it is gathered, its unknown, what its residual reads."""
    from types import SimpleNamespace

    unknown = SimpleNamespace(name=name)
    residual = SimpleNamespace(coefficients=lambda: [unknown, *reads])
    return SimpleNamespace(gathered=gathered, owner=0, backend=SimpleNamespace(comm=SimpleNamespace(size=ranks)),
                           sub=SimpleNamespace(name=name, unknown=unknown, residual=residual))


def test_independent_systems_solved_on_one_rank_are_batched_each_to_its_own_rank():
    """Example 1a in parallel: m (a Krylov solve) and e (a division) alone, f and b (neither reads the
    other) at once on ranks 0 and 1; a system that reads an earlier one's unknown waits for it."""
    from primordia.coupling.solvers import independent_batches

    m = _fake_solver("m", gathered=False)
    e = _fake_solver("e", reads=[m.sub.unknown], gathered=False)
    f = _fake_solver("f", reads=[e.sub.unknown])
    b = _fake_solver("b", reads=[m.sub.unknown])
    batches = independent_batches([m, e, f, b])
    assert [[s.sub.name for s in batch] for batch in batches] == [["m"], ["e"], ["f", "b"]]
    assert (f.owner, b.owner) == (0, 1)

    reader = _fake_solver("g", reads=[f.sub.unknown])  # reads f's new value: after f, not beside it
    assert [[s.sub.name for s in batch] for batch in independent_batches([f, reader, b])] == [["f"], ["g", "b"]]
    assert (f.owner, reader.owner, b.owner) == (0, 0, 1)
    # no more systems at once than ranks: a third goes to the next batch, on rank 0 again
    third = _fake_solver("h")
    assert [len(batch) for batch in independent_batches([f, b, third])] == [2, 1]
    assert third.owner == 0


def _builds(rule: KeptPreconditioner, iterations: list[int]) -> list[bool]:
    """Which of the solves with these iteration counts build the preconditioner under ``rule``."""
    builds = []
    for count in iterations:
        keep = rule.keeps()
        if not keep:
            rule.built()
        builds.append(not keep)
        rule.solved(count)
    return builds


def test_a_kept_preconditioner_is_built_again_after_a_solve_over_its_bound():
    # absolute: after a solve with more than 8 iterations
    assert _builds(KeptPreconditioner(8), [7, 8, 9, 7, 9, 9]) == [True, False, False, True, False, True]
    # relative: more than one above the first solve after the build (7, then 5)
    assert _builds(KeptPreconditioner("fresh+1"), [7, 8, 9, 5, 6, 7, 7]) == [True, False, False, True, False, False, True]
    rule = KeptPreconditioner("fresh+1")
    _builds(rule, [7])
    rule.discard()  # dt changed, or a solve failed with the kept one
    assert not rule.keeps()


def test_a_relative_bound_measures_a_fresh_preconditioner_until_a_solve_settles_the_count():
    """A Newton solve's steps report unsettled counts (the first needs far fewer than the later ones); the bound
    is K above the most of them, and the rule keeps the preconditioner while it is still measuring."""
    rule = KeptPreconditioner("fresh+2")
    rule.built()
    for count in (5, 30):
        rule.solved(count, settles=False)
        assert rule.keeps()  # still fresh
    rule.solved(28)  # the Newton solve's last step settles the count at 30
    rule.solved(32, settles=False)
    assert rule.keeps()
    rule.solved(33, settles=False)
    assert not rule.keeps()
