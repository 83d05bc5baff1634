"""Strong scaling from 1 to N ranks, and whether the parallel run gives the serial answer.

For each example (with its size and number of steps), runs ``primordia run`` on 1 rank and under
``mpirun -n RANKS`` and prints the wall time per step of each (``summary.json``: outputs included,
set-up excluded) and the speedup, twice: over the whole run (``ms_per_step``: the first step,
which also loads the compiled forms and makes the first factorisations, amortised over the few
steps of a benchmark) and over the steps after the first (``ms_per_step_after_first``: what a run
of thousands of steps settles to).  Then the largest relative difference between the two runs'
final integrals, minima and maxima of every field (the solvers' tolerance bounds it, not
round-off: iterative solvers on other partitions take other paths to their tolerance).  With
``--solves`` it also prints, for each run, the CPU ms per step of every subproblem's linear
algebra (``summary.json``'s ``linear_solve_ms_per_step``, the largest over the ranks).  On a
shared or virtual machine one pair of runs can be off by 10-20% (2a at 86 x 86 squares gave
speedups 1.29 to 1.52 within an hour): ``--repeats N`` runs each rank count N times, alternating,
and prints the median runs and the range.

``--ceiling`` also runs RANKS serial copies at once and prints what that does to each copy's
ms/step after the first step: the cores share caches and memory bandwidth, so even a run that
split its work perfectly would reach at most RANKS x (alone / at once), the "ceiling" column.  A
speedup near the ceiling means the parallel algorithm loses little; the gap to RANKS is the
machine's, not the code's.

``--as-shipped`` runs each example as its TOML file states it (its mesh, its time span, its outputs and
pictures: what ``primordia run examples/EX.toml`` does) and prints instead the wall time of the whole
command, from start to exit, and its speedup: set-up, imports, every output and picture included.

    .venv/bin/python benchmarks/bench_scaling.py                         # examples 1a, 2a, 4 (small)
    .venv/bin/python benchmarks/bench_scaling.py --examples ex04_small --set 'mesh.cells=[40,40,4]' --steps 3
    .venv/bin/python benchmarks/bench_scaling.py --examples ex01a --as-shipped --repeats 3   # the full 2,600 steps
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from machine import describe, last_words, launch_environment, require_at_least  # benchmarks/machine.py

ROOT = Path(__file__).resolve().parent.parent

#: example -> (mesh cells, dt, steps): the seed's mesh for 1a, a quarter of it for 2a, 4 at laptop size.
CASES = {
    "ex01a": ("[171,171]", 0.2, 200),
    "ex02a": ("[86,86]", 0.2, 10),
    "ex04_small": ("[20,20,2]", 0.5, 6),
}

#: summary.json's ms per step of the whole run, and of the steps after the first.
WHOLE, LATER = "ms_per_step", "ms_per_step_after_first"


#: summary key of --as-shipped: the command's wall time in seconds
COMMAND = "command_s"


def run(example: str, ranks: int, steps: int | None, extra: list[str], out: Path, shipped: bool = False) -> dict:
    began = time.perf_counter()
    summary = finish(example, ranks, start(example, ranks, steps, extra, out, shipped), out)
    summary[COMMAND] = time.perf_counter() - began
    return summary


def start(example: str, ranks: int, steps: int | None, extra: list[str], out: Path,
          shipped: bool = False) -> subprocess.Popen:
    cells, dt, default_steps = CASES[example]
    steps = steps or default_steps
    command = [sys.executable, "-m", "primordia.cli", "run", str(ROOT / f"examples/{example}.toml"), "--out", str(out)]
    if not shipped:
        command += ["--set", f"mesh.cells={cells}", "--set", f"time.t_final={steps * dt}",
                    "--set", f"output.times=[{steps * dt}]", "--set", "output.pictures=false"]
    command += ["--no-progress", "--overwrite", *extra]
    if ranks > 1:
        command = ["mpirun", "-n", str(ranks), *command]
    env = launch_environment()
    return subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def finish(example: str, ranks: int, process: subprocess.Popen, out: Path) -> dict:
    _, stderr = process.communicate()
    if process.returncode != 0:
        sys.exit(f"bench_scaling: {example} on {ranks} rank(s) failed: {last_words(stderr)}")
    return json.loads((out / "summary.json").read_text())


def at_once(example: str, copies: int, steps: int | None, extra: list[str], out: Path) -> dict:
    """The mean ms/step (whole runs, and after the first step) of ``copies`` serial runs started together."""
    outs = [out / f"copy{k}" for k in range(copies)]
    processes = [start(example, 1, steps, extra, where) for where in outs]
    summaries = [finish(example, 1, process, where) for process, where in zip(processes, outs)]
    return {key: sum(summary[key] for summary in summaries) / copies for key in (WHOLE, LATER)}


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
    parser.add_argument("--ceiling", action="store_true",
                        help="also run RANKS serial copies at once and print the speedup the machine allows")
    parser.add_argument("--as-shipped", action="store_true",
                        help="run each example as its TOML states it and time the whole command")
    args = parser.parse_args()
    require_at_least(parser, ("--ranks", args.ranks, 2), ("--steps", args.steps, 1), ("--repeats", args.repeats, 1))
    if args.as_shipped and (args.steps is not None or args.ceiling):
        parser.error("--as-shipped runs each example as its TOML states it: it takes neither --steps nor --ceiling")
    print(describe(), flush=True)
    extra = [a for s in args.set for a in ("--set", s)]
    n = args.ranks
    if args.as_shipped:
        return as_shipped(args, extra)
    print(f"{'':>21} {'--- the whole run (first step amortised) ---':>46}   {'--- the steps after the first ---':>46}")
    print(f"{'example':>11} {'dofs':>9} {'1 rank ms/step':>15} {f'{n} ranks ms/step':>16} {'speedup':>8}   "
          f"{'1 rank ms/step':>15} {f'{n} ranks ms/step':>16} {'speedup':>8} {'max rel. difference':>20}"
          + (f" {f'{n} serial at once':>18} {'ceiling':>8}" if args.ceiling else ""), flush=True)
    for example in args.examples:
        out = Path(f"/tmp/primordia-bench-scaling/{example}")
        serials, parallels, crowded = [], [], []
        for _ in range(args.repeats):  # alternating, so that a slow spell of the machine touches all
            serials.append(run(example, 1, args.steps, extra, out / "np1"))
            parallels.append(run(example, n, args.steps, extra, out / f"np{n}"))
            if args.ceiling:
                crowded.append(at_once(example, n, args.steps, extra, out))
        line = f"{example:>11} {serials[0]['dofs_total']:>9}"
        for key, gap in ((WHOLE, "   "), (LATER, "")):
            serial, parallel = _median(serials, key), _median(parallels, key)
            line += f" {serial:>15.1f} {parallel:>16.1f} {serial / parallel:>8.2f}{gap}"
        line += f" {largest_difference(_median_run(serials), _median_run(parallels)):>20.1e}"
        if args.ceiling:
            together = _median(crowded, LATER)
            line += f" {together:>18.1f} {n * _median(serials, LATER) / together:>8.2f}"
        print(line, flush=True)
        if args.repeats > 1:
            for key, what in ((WHOLE, "whole runs"), (LATER, "after the first step")):
                speedups = sorted(s[key] / p[key] for s in serials for p in parallels)
                print(f"{'':>11} {args.repeats} runs each, {what}: 1 rank {_span(serials, key)}, {n} ranks "
                      f"{_span(parallels, key)} ms/step; speedups of any pair {speedups[0]:.2f} to {speedups[-1]:.2f}",
                      flush=True)
        if args.solves:
            for ranks, summary in ((1, _median_run(serials)), (n, _median_run(parallels))):
                shares = ", ".join(f"{name} {ms:.1f}" for name, ms in summary["linear_solve_ms_per_step"].items())
                print(f"{'':>11} linear solves on {ranks} rank(s), ms/step: {shares}", flush=True)


def as_shipped(args, extra: list[str]) -> None:
    """Each example as shipped: the command's wall time on 1 and on RANKS ranks, and the speedup."""
    n = args.ranks
    print(f"{'example':>11} {'dofs':>9} {'steps':>6} {'1 rank s':>9} {f'{n} ranks s':>10} {'speedup':>8}   "
          f"{'ms/step after the first':>24} {'max rel. difference':>20}", flush=True)
    for example in args.examples:
        out = Path(f"/tmp/primordia-bench-scaling/{example}-shipped")
        serials, parallels = [], []
        for _ in range(args.repeats):  # alternating, so that a slow spell of the machine touches all
            serials.append(run(example, 1, None, extra, out / "np1", shipped=True))
            parallels.append(run(example, n, None, extra, out / f"np{n}", shipped=True))
        serial, parallel = _median(serials, COMMAND), _median(parallels, COMMAND)
        later = f"{_median(serials, LATER):.1f} / {_median(parallels, LATER):.1f}"
        print(f"{example:>11} {serials[0]['dofs_total']:>9} {serials[0]['steps']:>6} {serial:>9.1f} {parallel:>10.1f} "
              f"{serial / parallel:>8.2f}   {later:>24} "
              f"{largest_difference(_median_run(serials), _median_run(parallels)):>20.1e}", flush=True)
        if args.repeats > 1:
            speedups = [s[COMMAND] / p[COMMAND] for s, p in zip(serials, parallels)]
            print(f"{'':>11} {args.repeats} runs each: 1 rank {_span(serials, COMMAND)} s, {n} ranks "
                  f"{_span(parallels, COMMAND)} s; speedups of the alternating pairs "
                  f"{', '.join(f'{x:.2f}' for x in speedups)}", flush=True)


def _median(summaries: list[dict], key: str) -> float:
    """The median of ``key`` (the lower middle one of an even number)."""
    values = sorted(summary[key] for summary in summaries)
    return values[(len(values) - 1) // 2]


def _median_run(summaries: list[dict]) -> dict:
    """The run with the median ms/step (the lower middle one of an even number)."""
    ordered = sorted(summaries, key=lambda summary: summary[WHOLE])
    return ordered[(len(ordered) - 1) // 2]


def _span(summaries: list[dict], key: str) -> str:
    times = sorted(summary[key] for summary in summaries)
    return f"{times[0]:.1f}-{times[-1]:.1f}"


if __name__ == "__main__":
    main()
