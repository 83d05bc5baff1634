"""What petsc4py still holds as garbage on communicators (objects dropped but not yet destroyed).

petsc4py (3.18) destroys a dropped object only at ``garbage_cleanup`` of its communicator,
and keeps each communicator's garbage apart; ``garbage_view`` prints it.  Shared by the
tests that a step, a scheme's iterations or solvers made anew leave nothing behind.
"""

from __future__ import annotations

from petsc4py import PETSc


def garbage_report(comms, capfd) -> tuple[int, str]:
    """(how many of ``comms`` hold no garbage, what ``garbage_view`` printed for them)."""
    capfd.readouterr()  # what the test printed before is not part of the report
    for comm in comms:
        PETSc.garbage_view(comm)
    report = capfd.readouterr().out
    return report.count("Total entries: 0"), report


def run_communicators(sim) -> list:
    """The communicators a run's PETSc objects live on: COMM_SELF, COMM_WORLD and the backend's
    duplicates (dolfinx makes one per index map; the backend keeps a handle on each)."""
    keepers = getattr(sim.backend, "_petsc_comms", {}).values()
    return [PETSc.COMM_SELF, PETSc.COMM_WORLD, *(keeper.getComm() for keeper in keepers)]
