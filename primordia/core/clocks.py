"""The clocks solve and step times are kept in: this process's CPU time, and wall time.

Standard library only, so that a benchmark's driver can time on the solvers' clocks without
importing PETSc (:mod:`primordia.coupling.solvers` keeps its solve times here).
"""

from __future__ import annotations

import time

#: Clock name -> reader: this process's CPU time (its threads; other programs' load left out), and wall time.
CLOCKS = {"cpu": time.process_time, "wall": time.perf_counter}


def no_time() -> dict[str, float]:
    """Zero seconds on every clock of :data:`CLOCKS`: a total to add times to."""
    return dict.fromkeys(CLOCKS, 0.0)


def now() -> dict[str, float]:
    """Now, on every clock of :data:`CLOCKS`."""
    return {name: read() for name, read in CLOCKS.items()}


def add_since(totals: dict[str, float], start: dict[str, float], minus: dict[str, float] | None = None) -> None:
    """totals += the time since ``start`` (less ``minus``), on each clock."""
    end = now()
    for clock, begun in start.items():
        totals[clock] += end[clock] - begun - (minus[clock] if minus else 0.0)
