"""Reductions over the ranks by what they compute: the one place the package names MPI's operations.

mpi4py is imported only when a reduction runs on several ranks (importing it starts MPI, which a
serial command such as ``primordia plugins`` should not pay for), and a communicator of one rank
returns its value untouched, so the serial stand-in of the scikit-fem backend works too.
"""

from __future__ import annotations

import time

import numpy as np


def _mpi():
    from mpi4py import MPI

    return MPI


def largest(comm, value):
    """The largest ``value`` over the ranks of ``comm``."""
    return value if comm.size == 1 else comm.allreduce(value, op=_mpi().MAX)


def smallest(comm, value):
    """The smallest ``value`` over the ranks of ``comm``."""
    return value if comm.size == 1 else comm.allreduce(value, op=_mpi().MIN)


def on_every_rank(comm, flag: bool) -> bool:
    """Whether ``flag`` holds on every rank of ``comm``."""
    return bool(flag) if comm.size == 1 else bool(comm.allreduce(bool(flag), op=_mpi().LAND))


def extrema(comm, low: float, high: float) -> tuple[float, float]:
    """(smallest ``low``, largest ``high``) over the ranks: a field's range from each rank's own part."""
    return smallest(comm, low), largest(comm, high)


def largest_in_place(comm, values: np.ndarray) -> None:
    """Each entry of ``values`` replaced by its largest over the ranks (one message for the whole array)."""
    if comm.size > 1:
        MPI = _mpi()
        comm.Allreduce(MPI.IN_PLACE, values, op=MPI.MAX)


class RanksMissing(Exception):
    """The other ranks did not join a reduction within the time a rank was given to wait for them."""


def lowest_rank_where(comm, flag: bool, patience: float | None = None) -> int | None:
    """The lowest rank of ``comm`` where ``flag`` holds (None: on none), waiting for the other ranks at most
    ``patience`` seconds (None: as long as they take) and then raising :class:`RanksMissing`.

    Non-blocking underneath (MPI_Iallreduce, polled), so a rank that gives up is not stuck inside MPI: a rank
    whose other ranks sit in a collective call it will never make can still say so and end the job.  ``comm``
    should be one that no other code calls collectives on meanwhile (a duplicate), or the calls could match.
    """
    if comm.size == 1:
        return 0 if flag else None
    MPI = _mpi()
    mine = np.array([comm.rank if flag else comm.size], dtype=np.int64)
    lowest = np.empty_like(mine)
    request = comm.Iallreduce(mine, lowest, op=MPI.MIN)
    if patience is None:
        request.Wait()
    else:
        deadline, pause = time.monotonic() + patience, 1e-4
        while not request.Test():
            if time.monotonic() > deadline:
                raise RanksMissing(f"the other ranks did not come within {patience:g} s")
            time.sleep(pause)
            pause = min(2 * pause, 0.1)  # a prompt answer costs no 0.1 s, a long wait no busy core
    return int(lowest[0]) if lowest[0] < comm.size else None


def every_rank_stops(comm, patience: float) -> bool:
    """Whether every rank of ``comm`` came to this call within ``patience`` seconds, each rank calling it as it
    stops on an error: False when the others are still elsewhere (in a collective call this rank never makes,
    after an error met by this rank alone), which only ending the job resolves.  ``comm`` as for
    :func:`lowest_rank_where`: a duplicate no other code calls collectives on."""
    try:
        lowest_rank_where(comm, True, patience)
    except RanksMissing:
        return False
    return True
