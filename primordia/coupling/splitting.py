"""Operator-splitting schemes: how the physics modules of a run share a time step.

Each scheme is one small class with ``advance(sim)``, registered through the
``primordia_splitting_schemes`` hook and chosen by the ``firstresult`` hook
``primordia_select_splitting_scheme`` from ``[coupling] scheme``.

* ``sequential`` (Lie): every module's subproblems once, in model order, each
  seeing the fields already updated in this step.  First order in dt in the
  splitting error; exact when the model has a single module.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

from primordia.core.plugins import hookimpl


class SplittingScheme(ABC):
    name: str

    def __init__(self, physics: list):
        self.physics = physics

    def field_groups(self, physics: list) -> dict[str, list]:
        """Which fields are solved together: by default, as each module groups its own."""
        groups: dict[str, list] = {}
        for module in physics:
            for spec in module.fields():
                groups.setdefault(spec.group or spec.name, []).append(spec)
        return groups

    def build(self, sim) -> None:
        """Create the solvers (default: one per subproblem, in model order)."""
        sim.solvers = [sim.solver_for(sub) for module in self.physics for sub in module.subproblems()]

    @abstractmethod
    def advance(self, sim) -> dict:
        """Advance all fields from ``sim.time`` by ``sim.dt``; return solver statistics."""


class Sequential(SplittingScheme):
    """Lie splitting: one sweep over the modules' subproblems per step."""

    name = "sequential"

    def advance(self, sim) -> dict:
        stats = {}
        for solver in sim.solvers:
            stats[solver.sub.name] = solver.solve()
        return stats


@hookimpl
def primordia_splitting_schemes():
    return [Sequential]
