"""Reductions over the ranks (primordia.core.reductions): their answers on one rank and on two."""

import os
import subprocess
import sys

import numpy as np
import pytest

from primordia.core import reductions


class _OneRank:
    """A communicator of one rank that refuses to be asked: one rank's value is the answer."""

    size = 1

    def allreduce(self, value, op=None):
        raise AssertionError("a reduction over one rank sent a message")

    def Allreduce(self, *args, **kwargs):
        raise AssertionError("a reduction over one rank sent a message")


def test_one_rank_answers_with_its_own_values_without_messages():
    comm = _OneRank()
    assert reductions.largest(comm, 3.5) == 3.5
    assert reductions.smallest(comm, -2) == -2
    assert reductions.on_every_rank(comm, 1) is True and reductions.on_every_rank(comm, 0) is False
    assert reductions.extrema(comm, -1.0, 4.0) == (-1.0, 4.0)
    assert reductions.lowest_rank_where(comm, True) == 0 and reductions.lowest_rank_where(comm, False) is None
    assert reductions.every_rank_stops(comm, 0.0) is True
    values = np.array([1.0, -np.inf, 2.0])
    reductions.largest_in_place(comm, values)
    assert values.tolist() == [1.0, -np.inf, 2.0]


TWO_RANKS = """
import numpy as np
from mpi4py import MPI
from primordia.core import reductions as r
comm = MPI.COMM_WORLD
rank = comm.rank
assert r.largest(comm, float(rank)) == 1.0 and r.smallest(comm, float(rank)) == 0.0
assert r.extrema(comm, 10.0 - rank, 5.0 * rank) == (9.0, 5.0)
assert r.on_every_rank(comm, True) is True and r.on_every_rank(comm, rank == 0) is False
values = np.array([float(rank), -float(rank), np.inf if rank else -np.inf])
r.largest_in_place(comm, values)
assert values.tolist() == [1.0, 0.0, np.inf], values
agreeing = comm.Dup()
assert r.lowest_rank_where(agreeing, rank == 1) == 1 and r.lowest_rank_where(agreeing, False, 30.0) is None
assert r.every_rank_stops(agreeing, 30.0) is True
if rank == 0:  # rank 1 is late: rank 0 gives up, then waits in a collective of the world as after an abort's print
    assert r.every_rank_stops(agreeing, 0.2) is False
else:
    import time
    time.sleep(1.0)
    assert r.every_rank_stops(agreeing, 30.0) is True  # rank 0's abandoned request is still there to meet
comm.Barrier()
ranks = comm.gather(rank, root=0)  # one line from rank 0: two ranks writing at once can interleave
if rank == 0:
    print("agreed on ranks", sorted(ranks))
"""


@pytest.mark.mpi
def test_two_ranks_reduce_to_one_answer(tmp_path):
    script = tmp_path / "reduce.py"
    script.write_text(TWO_RANKS)
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    done = subprocess.run(["mpirun", "-n", "2", sys.executable, str(script)], env=env, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "agreed on ranks [0, 1]" in done.stdout.splitlines()
