"""Remainders of several linear subproblems assembled as one form (primordia.coupling.batched)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from primordia import Model
from primordia.core.config import apply_overrides, load_config
from primordia.coupling import batched, orchestrator
from primordia.coupling.batched import batch_remainders
from primordia.coupling.p1_advection import P1Advection

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.parametrize("backend", ["fenicsx", "skfem"])
def test_the_species_explicit_terms_assembled_together_equal_each_assembled_alone(backend, tmp_path):
    """Example 1b: the advection of m, f and b by the solid velocity (and f's FGF sink) is one form; each
    species' part of it is its own remainder's vector."""
    config = apply_overrides(load_config(EXAMPLES / "ex01b.toml"),
                             ["mesh.cells=[12,12]", "time.t_final=0.4", "output.times=[0.4]", "output.pictures=false"])
    sim = Model.from_config(config).run(backend=backend, out=tmp_path / "out")
    members = {solver.sub.name: solver._affine for solver in sim.solvers
               if getattr(solver, "_affine", None) is not None and solver._affine.batch is not None}
    assert set(members) == {"chemotaxis.m", "chemotaxis.f", "chemotaxis.b"}  # e has no assembled remainder
    for name, affine in sorted(members.items(), key=lambda item: item[1].batch[1]):
        batch, index = affine.batch
        alone = sim.backend.assemble_vector(affine.assembled_remainder)
        together = batch.vector(index, alone.duplicate())
        scale = np.abs(alone.getArray()).max()
        assert scale > 0, name
        np.testing.assert_allclose(together.getArray(), alone.getArray(), rtol=0, atol=1e-13 * scale, err_msg=name)


@pytest.mark.parametrize("backend", ["fenicsx", "skfem"])
def test_a_remainder_left_out_of_a_batch_gets_the_closed_form_a_batch_would(backend, tmp_path, monkeypatch):
    """The closed form is chosen in one place (affine.closed_form): example 1b with nothing batched evaluates
    each species' advection by the solid velocity from its closed form, alone, and ends where the batched
    run does."""
    config = apply_overrides(load_config(EXAMPLES / "ex01b.toml"),
                             ["mesh.cells=[12,12]", "time.t_final=0.4", "output.times=[0.4]", "output.pictures=false"])
    batched_run = Model.from_config(config).run(backend=backend, out=tmp_path / "batched")
    monkeypatch.setattr(orchestrator, "batch_remainders", lambda backend, solvers: [])
    alone = Model.from_config(config).run(backend=backend, out=tmp_path / "alone")
    closed = {solver.sub.name: type(solver._affine._closed_remainder) for solver in alone.solvers
              if solver.sub.name.startswith("chemotaxis.") and solver._affine.assembled_remainder is not None}
    assert closed == dict.fromkeys(["chemotaxis.m", "chemotaxis.f", "chemotaxis.b"], P1Advection)  # e has none
    together, apart = batched_run.vertex_values(), alone.vertex_values()
    for name, values in together.items():
        scale = np.abs(values).max()
        assert scale > 0, name
        np.testing.assert_allclose(apart[name], values, rtol=0, atol=1e-11 * scale, err_msg=name)


def _fake(name, reads=()):
    """A solver as batch_remainders reads it: its unknown, and an affine split whose assembled remainder reads ``reads``."""
    unknown = SimpleNamespace(name=name)
    space = object()
    remainder = SimpleNamespace(coefficients=lambda: list(reads),
                                arguments=lambda: [SimpleNamespace(ufl_function_space=lambda: space)])
    affine = SimpleNamespace(available=True, batch=None, assembled_remainder=remainder)
    return SimpleNamespace(sub=SimpleNamespace(name=name, unknown=unknown), _affine=affine)


def test_a_remainder_that_reads_a_field_solved_before_it_is_not_batched(monkeypatch):
    """The batch is assembled at the first member's solve: a member whose remainder reads the unknown of a
    solve that runs between the first member's and its own would read it stale."""
    monkeypatch.setattr(batched, "_is_p1_scalar", lambda space: True)
    built = []
    monkeypatch.setattr(batched.RemainderBatch, "build",
                        classmethod(lambda cls, backend, remainders: built.append(remainders) or object()))
    backend = SimpleNamespace(shares_dofs=lambda a, b: True, comm=SimpleNamespace(allgather=lambda value: [value]))
    m, e = _fake("m"), _fake("e")
    f = _fake("f", reads=[e.sub.unknown])  # reads e, which is solved after m: left out
    b = _fake("b", reads=[SimpleNamespace(name="b_previous")])  # a start-of-step value only: in
    solvers = [m, e, f, b]
    assert len(batch_remainders(backend, solvers)) == 1
    assert [s._affine.batch[1] if s._affine.batch else None for s in solvers] == [0, 1, None, 2]
    assert len(built) == 1 and len(built[0]) == 3
    assert batch_remainders(backend, solvers) == []  # members of a batch are not batched again
