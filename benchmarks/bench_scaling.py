"""Strong scaling from 1 to N ranks, and whether the parallel run gives the serial answer.

For each example (with its size and number of steps), runs ``primordia run`` on 1 rank and under
``mpirun -n RANKS`` and prints the wall time per step of each (``summary.json``: outputs included,
set-up excluded; the first step, which compiles the forms, is amortised over the steps), the
speedup, and the largest relative difference between the two runs' final integrals, minima and
maxima of every field (the solvers' tolerance bounds it, not round-off: iterative solvers on
other partitions take other paths to their tolerance).  With ``--solves`` it also prints, for
each run, the CPU ms per step of every subproblem's linear algebra (``summary.json``'s
``linear_solve_ms_per_step``, the largest over the ranks).  On a shared or virtual machine one
pair of runs can be off by 10-20% (2a at 86 x 86 squares gave speedups 1.29 to 1.52 within an hour):
``--repeats N`` runs each rank count N times, alternating, and prints the median runs and the range.

    .venv/bin/python benchmarks/bench_scaling.py                         # examples 1a, 2a, 4 (small)
    .venv/bin/python benchmarks/bench_scaling.py --examples ex04_small --set 'mesh.cells=[40,40,4]' --steps 3
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: example -> (mesh cells, dt, steps): the seed's mesh for 1a, a quarter of it for 2a, 4 at laptop size.
CASES = {
    "ex01a": ("[171,171]", 0.2, 200),
    "ex02a": ("[86,86]", 0.2, 10),
    "ex04_small": ("[20,20,2]", 0.5, 6),
}


def run(example: str, ranks: int, steps: int | None, extra: list[str], out: Path) -> dict:
    cells, dt, default_steps = CASES[example]
    steps = steps or default_steps
    command = [sys.executable, "-m", "primordia.cli", "run", str(ROOT / f"examples/{example}.toml"), "--out", str(out),
               "--set", f"mesh.cells={cells}", "--set", f"time.t_final={steps * dt}",
               "--set", f"output.times=[{steps * dt}]", "--set", "output.pictures=false", "--no-progress", "--overwrite", *extra]
    if ranks > 1:
        command = ["mpirun", "-n", str(ranks), *command]
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    done = subprocess.run(command, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        reason = (done.stderr.strip().splitlines() or ["no output"])[-1]
        sys.exit(f"bench_scaling: {example} on {ranks} rank(s) failed: {reason}")
    return json.loads((out / "summary.json").read_text())


def largest_difference(serial: dict, parallel: dict) -> float:
    worst = 0.0
    for name, stats in serial["final"].items():
        for key, value in stats.items():
            scale = max(abs(value), 1e-12)
            worst = max(worst, abs(parallel["final"][name][key] - value) / scale)
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--examples", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--set", action="append", default=[], help="an extra config override (both runs)")
    parser.add_argument("--solves", action="store_true", help="also print each subproblem's linear-solve ms/step")
    parser.add_argument("--repeats", type=int, default=1,
                        help="run each rank count this many times, alternating; print the medians and the range")
    args = parser.parse_args()
    extra = [a for s in args.set for a in ("--set", s)]
    print(f"{'example':>11} {'dofs':>9} {'1 rank ms/step':>15} {f'{args.ranks} ranks ms/step':>16} {'speedup':>8} "
          f"{'max rel. difference':>20}", flush=True)
    for example in args.examples:
        out = Path(f"/tmp/primordia-bench-scaling/{example}")
        serials, parallels = [], []
        for _ in range(args.repeats):  # alternating, so that a slow spell of the machine touches both
            serials.append(run(example, 1, args.steps, extra, out / "np1"))
            parallels.append(run(example, args.ranks, args.steps, extra, out / f"np{args.ranks}"))
        serial, parallel = _median_run(serials), _median_run(parallels)
        print(f"{example:>11} {serial['dofs_total']:>9} {serial['ms_per_step']:>15.1f} {parallel['ms_per_step']:>16.1f} "
              f"{serial['ms_per_step'] / parallel['ms_per_step']:>8.2f} {largest_difference(serial, parallel):>20.1e}",
              flush=True)
        if args.repeats > 1:
            speedups = sorted(s["ms_per_step"] / p["ms_per_step"] for s in serials for p in parallels)
            print(f"{'':>11} {args.repeats} runs each: 1 rank {_span(serials)}, {args.ranks} ranks {_span(parallels)} "
                  f"ms/step; speedups of any pair {speedups[0]:.2f} to {speedups[-1]:.2f}", flush=True)
        if args.solves:
            for ranks, summary in ((1, serial), (args.ranks, parallel)):
                shares = ", ".join(f"{name} {ms:.1f}" for name, ms in summary["linear_solve_ms_per_step"].items())
                print(f"{'':>11} linear solves on {ranks} rank(s), ms/step: {shares}", flush=True)


def _median_run(summaries: list[dict]) -> dict:
    """The run with the median ms/step (the lower middle one of an even number)."""
    ordered = sorted(summaries, key=lambda summary: summary["ms_per_step"])
    return ordered[(len(ordered) - 1) // 2]


def _span(summaries: list[dict]) -> str:
    times = sorted(summary["ms_per_step"] for summary in summaries)
    return f"{times[0]:.1f}-{times[-1]:.1f}"


if __name__ == "__main__":
    main()
