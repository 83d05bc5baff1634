"""Splitting schemes (primordia.coupling.splitting): what each does with a step, and what it costs.

The orders of the splitting errors are measured in tests/regression/test_splitting_order.py; here,
the schemes' bookkeeping on small runs of example 1b (chemistry + linear poroelasticity) on skfem.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from petsc4py import PETSc

from petsc_garbage import garbage_report
from primordia.core.errors import ConfigError
from primordia.coupling.orchestrator import Simulation
from primordia.model import Model

EX01B = Path(__file__).resolve().parents[2] / "examples" / "ex01b.toml"
SMALL = ["mesh.cells=[4,4]", "time.t_final=0.6", "output.times=[0.6]", "output.pictures=false"]


def simulation(tmp_path, *extra, backend="skfem") -> Simulation:
    return Simulation(Model.from_file(EX01B, [*SMALL, *extra]), backend=backend, out_dir=tmp_path).setup()


def test_the_fixed_point_iteration_records_its_iterations_and_reaches_its_tolerance(tmp_path):
    sim = simulation(tmp_path, 'coupling.scheme="fixed_point"', "coupling.tolerance=1e-10")
    sim.step()
    (count,) = sim.coupling_iterations["fixed_point"]
    assert 2 <= count <= 50
    assert sim.iteration_counts()["fixed_point_iterations"] == count
    assert sim.summary("running")["mean_coupling_iterations"] == {"fixed_point": count}  # no scheme named there


def test_a_fixed_point_step_leaves_no_petsc_garbage(tmp_path, monkeypatch, capfd):
    """petsc4py frees objects of a parallel communicator only when its garbage is collected: a scheme
    that dropped vectors in its iterations grew without bound (15 GB for example 2a at 86^2).  With the
    run's collection switched off, a step must leave nothing behind."""
    sim = simulation(tmp_path, 'coupling.scheme="fixed_point"', "coupling.tolerance=1e-10", backend="fenicsx")
    sim.step()  # the first step makes the scheme's work vectors
    comms = [keeper.getComm() for keeper in sim.backend._petsc_comms.values()]
    for comm in comms:
        PETSc.garbage_cleanup(comm)
    monkeypatch.setattr(sim.backend, "collect_garbage", lambda: None)
    sim.step()
    empty, report = garbage_report(comms, capfd)
    assert empty == len(comms), report


@pytest.mark.parametrize("value, message", [(0.0, "coupling.tolerance must be a number > 0"), (-1.0, "must be a number > 0")])
def test_a_bad_fixed_point_tolerance_is_one_line(tmp_path, value, message):
    with pytest.raises(ConfigError, match=message):
        Model.from_file(EX01B, [*SMALL, 'coupling.scheme="fixed_point"', f"coupling.tolerance={value}"]).run(
            backend="skfem", out=tmp_path)


def test_strang_splits_the_first_module_in_halves(tmp_path):
    sim = simulation(tmp_path, 'coupling.scheme="strang"')
    solves = []
    original = sim.advance
    sim.advance = lambda solvers, t0, duration, inner=1: solves.append((solvers[0].sub.name, duration)) or original(
        solvers, t0, duration, inner)
    sim.scheme.advance(sim, 0.0, 0.2)
    assert [name for name, _ in solves] == ["chemotaxis.m", "poroelasticity", "chemotaxis.m"]
    assert [duration for _, duration in solves] == pytest.approx([0.1, 0.2, 0.1])


EX02A = EX01B.with_name("ex02a.toml")


@pytest.mark.parametrize("scheme", ["strang", "sequential", "fixed_point"])
def test_every_scheme_takes_the_conservative_accumulation_on_a_growing_tissue(tmp_path, scheme):
    """strang was refused: its two half steps counted each volume change twice, until the species read J where
    they were last balanced (Discretisation.at_balance; the cells' conservation: test_growth_runs.py)."""
    model = Model.from_file(EX02A, ["mesh.cells=[4,4]", "time.t_final=0.4", "output.times=[0.4]",
                                    "output.pictures=false", 'physics.chemotaxis.accumulation="conservative"',
                                    f'coupling.scheme="{scheme}"'])
    _choices_checked(Simulation(model, backend="skfem", out_dir=tmp_path), False)


EX01A = EX01B.with_name("ex01a.toml")


@pytest.mark.parametrize("flux_scheme, refused", [("exponential_fitting", True), ("galerkin", False)])
def test_the_monolithic_scheme_refuses_the_exponentially_fitted_flux_before_the_run(tmp_path, flux_scheme, refused):
    """The fitted flux acts on the species as separate fields; the set-up refused it in one field, but
    ``primordia run --dry-run``, which asks for the splitting scheme only, called such a config valid."""
    model = Model.from_file(EX01A, ["mesh.cells=[4,4]", 'coupling.scheme="monolithic"',
                                    f'physics.chemotaxis.flux_scheme="{flux_scheme}"'])
    _choices_checked(Simulation(model, backend="skfem", out_dir=tmp_path),
                     refused and r'flux_scheme = "exponential_fitting" needs the species as separate fields; with '
                                 r'the monolithic scheme use')


def _choices_checked(sim, refusal):
    """``sim.check_choices()`` refuses with a message matching ``refusal``, or (refusal False) accepts."""
    if refusal:
        with pytest.raises(ConfigError, match=refusal):
            sim.check_choices()
    else:
        sim.check_choices()
