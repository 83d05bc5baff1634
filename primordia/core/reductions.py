"""Reductions over the ranks by what they compute: the one place the package names MPI's operations.

mpi4py is imported only when a reduction runs on several ranks (importing it starts MPI, which a
serial command such as ``primordia plugins`` should not pay for), and a communicator of one rank
returns its value untouched, so the serial stand-in of the scikit-fem backend works too.
"""

from __future__ import annotations

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
