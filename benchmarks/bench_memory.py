"""Does a run hold its memory? Bytes allocated per step, and per rebuild of the solvers.

For each example (coarse meshes), runs a few steps, then measures with glibc's ``mallinfo2`` (the
bytes the process has allocated, C libraries included: PETSc, MUMPS, dolfinx; not the resident size,
which reused pages hide) how much stays allocated

* per time step, over ``--steps`` steps after ``--warmup``;
* per rebuild of the solvers (what a checkpoint or a rejected step does), over ``--rebuilds``;
* how much a rebuild gives back at once, before the new solvers solve ("MB freed at once": the old
  solvers' factorisations and work arrays; about 0 when something still holds them, and the next
  step then holds two factorisations).

A run that holds its memory prints about 0 kB per step. Two leaks found this way killed example 2a at
the seed's 171 x 171 mesh (see the README, "Long runs"): 1.9 MB a step at 43 x 43 from PETSc objects
dropped on COMM_SELF, and 67 MB per rebuild from Newton solvers kept alive by a reference cycle.
The compiled-form cache may add a little per rebuild, up to its bound.

    .venv/bin/python benchmarks/bench_memory.py                        # 1a, 1b, 2a, 2b, 4 (small), fenicsx
    .venv/bin/python benchmarks/bench_memory.py --examples ex02a --backends fenicsx skfem --steps 20
"""

from __future__ import annotations

import argparse
import ctypes
import sys
import tempfile
from pathlib import Path

from machine import describe, require_at_least  # benchmarks/machine.py

ROOT = Path(__file__).resolve().parent.parent

#: example -> coarse mesh cells (every example's own physics, at a size that runs in seconds)
CASES = {"ex01a": "[43,43]", "ex01b": "[43,43]", "ex02a": "[24,24]", "ex02b": "[24,24]", "ex04_small": "[6,6,2]"}


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in
                "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost".split()]


def allocated_mb() -> float:
    """Bytes in use from malloc (small blocks and mmapped ones), in MB."""
    libc = ctypes.CDLL("libc.so.6")
    libc.mallinfo2.restype = _MallInfo2
    info = libc.mallinfo2()
    return (info.uordblks + info.hblkhd) / 2**20


def measure(example: str, backend: str, steps: int, warmup: int, rebuilds: int) -> tuple[float, float]:
    from primordia.coupling.orchestrator import Simulation
    from primordia.model import Model

    model = Model.from_file(ROOT / "examples" / f"{example}.toml",
                            [f"mesh.cells={CASES[example]}", "output.pictures=false", "output.times=[]",
                             "time.t_final=1e6"])
    with tempfile.TemporaryDirectory() as out:
        sim = Simulation(model, backend=backend, out_dir=out, existing="overwrite").setup()
        for _ in range(warmup):
            sim.step()
        start = allocated_mb()
        for _ in range(steps):
            sim.step()
        per_step = (allocated_mb() - start) / steps
        start, freed = allocated_mb(), 0.0
        for _ in range(rebuilds):
            before = allocated_mb()
            sim._create_solvers()
            freed += before - allocated_mb()  # the old solvers' memory, given back before the new ones solve
            sim.step()
        per_rebuild = (allocated_mb() - start) / rebuilds - per_step
    return per_step, per_rebuild, freed / rebuilds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--backends", nargs="+", default=["fenicsx"], choices=["fenicsx", "skfem"])
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--warmup", type=int, default=4)
    parser.add_argument("--rebuilds", type=int, default=3)
    args = parser.parse_args()
    require_at_least(parser, ("--steps", args.steps, 1), ("--warmup", args.warmup, 0),
                     ("--rebuilds", args.rebuilds, 1))
    print(describe(), flush=True)
    if not sys.platform.startswith("linux"):
        sys.exit("bench_memory: needs glibc's mallinfo2 (Linux)")
    print(f"{'example':>11} {'backend':>8} {'mesh':>9} {'kB per step':>12} {'kB per rebuild':>15} {'MB freed at once':>17}")
    for example in args.examples:
        for backend in args.backends:
            per_step, per_rebuild, freed = measure(example, backend, args.steps, args.warmup, args.rebuilds)
            print(f"{example:>11} {backend:>8} {CASES[example]:>9} {1024 * per_step:>12.1f} {1024 * per_rebuild:>15.1f}"
                  f" {freed:>17.1f}", flush=True)


if __name__ == "__main__":
    main()
