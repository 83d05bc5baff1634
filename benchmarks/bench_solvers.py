"""Solver study: how the cost of each system grows with the mesh, per preconditioner (issue 9).

For each system and size it prints, per preconditioner (a named set of config overrides):

* mean Krylov iterations per Newton step of the system studied (for linear systems: per solve),
* Newton iterations per time step (nonlinear systems),
* ms per time step (mean over the timed steps, after warm-up steps: JIT, first factorisations), in
  CPU time of the process by default (``--clock cpu``: on a machine others are using, wall time
  measures them too; the largest over the ranks under MPI) or in wall time (``--clock wall``),
* peak memory of the run (its own process) and bytes per unknown (peak / all unknowns of the run),
* the ratio of ms/step to the direct solver's at the same size (the first preconditioner listed).

With more than one size it ends with, per system and preconditioner, the Krylov iterations per Newton
step at each size and their change from the first size to the last, and the cost per doubling of the
unknowns between consecutive sizes, (ms_2 / ms_1) ** (log 2 / log(N_2 / N_1)) (issue 9's bar: 2.3).
One run of a size can be 10-20% off on a shared machine (example 4 at 10 boxes a side: 727 to 904
ms/step within an hour), which moves a factor per doubling by about as much: ``--repeats N`` runs each
size N times, a repeat running the sizes one after another, and the summary gives the medians' factor
and the range over the repeats.  With ``--share``, ``--repeats N`` ends with each case's median
step/solves ratio and its range.

Systems (``--systems``):

* ``growth2d``: the (u, psi, p) Newton system of example 2a (``examples/ex02a.toml``, fixed-point coupling);
* ``growth3d``: the same system in example 4 (``examples/ex04_small.toml`` stretched to larger boxes);
* ``biot``: the (u, p) system of example 1b (linear Biot, ``examples/ex01b.toml``);
* ``cells``: the cell-density solve of example 1a (``examples/ex01a.toml``, exponentially fitted);
* ``chemotaxis``: the four species of example 1a solved as one Newton system (``solve = "coupled"``).

Each (system, preconditioner, size) runs in a child process (``--one``), so its peak memory is its own;
``--ranks 2`` runs the children under ``mpirun -n 2``.

``--share ex01a ex01b`` prints instead, per example (any of the seed's in ``examples/``; a size is
squares per side, or boxes per side of a 3D example, sized as ``growth3d``), backend and size, the cost
of a step against the time its linear solves take in the same run (Krylov iterations, preconditioner set-ups,
factorisations, diagonal divisions: ``linear_solve_seconds`` of each solver, on the clock the step is
timed with, ``--clock``), and their ratio, then each subproblem's share; with ``--ranks 2`` under
``mpirun`` (fenicsx), the largest over the ranks.

    .venv/bin/python benchmarks/bench_solvers.py --systems growth2d --sizes 43 86 171 --steps 3
    .venv/bin/python benchmarks/bench_solvers.py --systems growth3d --sizes 10 20 40 --steps 2
    .venv/bin/python benchmarks/bench_solvers.py --systems growth3d --sizes 10 20 30 --preconditioners schur --steps 8 --repeats 2
    .venv/bin/python benchmarks/bench_solvers.py --systems biot cells --sizes 43 86 171 342
    .venv/bin/python benchmarks/bench_solvers.py --share ex01a ex01b --sizes 171 --backends fenicsx skfem --steps 100 --clock wall --repeats 3
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import statistics
import subprocess
import sys
from pathlib import Path

from machine import EXAMPLES, describe, last_words, launch_environment, require_at_least  # benchmarks/machine.py

ROOT = Path(__file__).resolve().parent.parent

#: The cell density by BoomerAMG with HMIS coarsening and extended+i interpolation (hypre's advice for 2D and 3D).
HMIS = ["solver.chemotaxis_m.pc_type=\"hypre\"", "solver.chemotaxis_m.pc_hypre_boomeramg_coarsen_type=\"HMIS\"",
        "solver.chemotaxis_m.pc_hypre_boomeramg_interp_type=\"ext+i\""]

#: What each system runs: the example, how a size maps to mesh cells, the subproblem studied, preconditioners.
SYSTEMS = {
    "growth2d": {
        "example": "ex02a", "cells": lambda n: f"[{n},{n}]", "subproblem": "poroelastic_growth",
        "preconditioners": {
            "lu_fresh": ['physics.poroelastic_growth.preconditioner="lu"',
                         "solver.poroelastic_growth.rebuild_preconditioner_after=0"],
            # PETSc's own lag: a factorisation every 10 Newton steps, kept across steps (the default before
            # rebuild_preconditioner_after)
            "lu_lagged": ['physics.poroelastic_growth.preconditioner="lu"',
                          "solver.poroelastic_growth.rebuild_preconditioner_after=0",
                          "solver.poroelastic_growth.snes_lag_preconditioner=10",
                          "solver.poroelastic_growth.snes_lag_preconditioner_persists=true"],
            "lu_reused": ['physics.poroelastic_growth.preconditioner="lu"'],
            "schur": ['physics.poroelastic_growth.preconditioner="schur"'],
        },
    },
    "growth3d": {
        "example": "ex04_small", "cells": lambda n: f"[{n},{n},{max(2, n // 10)}]",
        "subproblem": "poroelastic_growth",
        "preconditioners": {
            "lu_reused": ['physics.poroelastic_growth.preconditioner="lu"'],
            "schur": ['physics.poroelastic_growth.preconditioner="schur"'],
        },
    },
    "biot": {
        "example": "ex01b", "cells": lambda n: f"[{n},{n}]", "subproblem": "poroelasticity",
        "preconditioners": {
            "lu": ['physics.poroelasticity.preconditioner="lu"'],
            "fixed_stress": ['physics.poroelasticity.preconditioner="fixed_stress"'],
        },
    },
    "cells": {
        "example": "ex01a", "cells": lambda n: f"[{n},{n}]", "subproblem": "chemotaxis.m",
        "preconditioners": {
            "lu": ["solver.chemotaxis_m.ksp_type=\"preonly\"", "solver.chemotaxis_m.pc_type=\"lu\""],
            "bjacobi_ilu": ["solver.chemotaxis_m.pc_type=\"bjacobi\""],
            "gamg": ["solver.chemotaxis_m.pc_type=\"gamg\""],
            "hypre": ["solver.chemotaxis_m.pc_type=\"hypre\""],
            "hypre_hmis": HMIS,
            # the same built afresh at every solve (the others keep theirs while it works: "fresh+1")
            "hypre_hmis_fresh": [*HMIS, "solver.chemotaxis_m.rebuild_preconditioner_after=0"],
        },
    },
    "chemotaxis": {
        "example": "ex01a", "cells": lambda n: f"[{n},{n}]", "subproblem": "chemotaxis",
        "preconditioners": {
            "lu": ['physics.chemotaxis.solve="coupled"', 'physics.chemotaxis.flux_scheme="galerkin"',
                   'physics.chemotaxis.preconditioner="lu"'],
            "block_jacobi": ['physics.chemotaxis.solve="coupled"', 'physics.chemotaxis.flux_scheme="galerkin"',
                             'physics.chemotaxis.preconditioner="block_jacobi"'],
        },
    },
}


def one(system: str, preconditioner: str, size: int, steps: int, warmup: int, extra: list[str],
        clock: str = "cpu") -> dict:
    """Time one run in this process (rank 0 returns the figures)."""
    from primordia.coupling.orchestrator import Simulation
    from primordia.core.clocks import CLOCKS
    from primordia.model import Model

    spec = SYSTEMS[system]
    overrides = [f"mesh.cells={spec['cells'](size)}", "output.pictures=false", "output.series_every=100000",
                 "time.t_final=1e6", *spec["preconditioners"][preconditioner], *extra]
    model = Model.from_file(ROOT / f"examples/{spec['example']}.toml", overrides)
    sim = Simulation(model, backend="fenicsx", out_dir=f"/tmp/primordia-bench-solvers/{system}-{preconditioner}-{size}")
    sim.setup()
    for _ in range(warmup):
        sim.step()
    name = spec["subproblem"]
    linear_before = sum(sim.iterations.get(name, []))
    newton_before = sum(n for n, _ in sim.newton.get(name, []))
    read = CLOCKS[clock]  # the solvers' clocks: steps and solves timed alike
    start = read()
    for _ in range(steps):
        sim.step()
    elapsed = read() - start
    linear = sum(sim.iterations.get(name, [])) - linear_before
    newton = sum(n for n, _ in sim.newton.get(name, [])) - newton_before
    nonlinear = name in sim.newton
    solves = newton if nonlinear else len(sim.iterations.get(name, [])[-steps:])
    unknowns = sum(sim.backend.num_dofs(sim.disc.group_function(g).ufl_function_space()) for g in sim.disc.groups())
    peak = sim.comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
    return {"system": system, "preconditioner": preconditioner, "size": size, "ranks": sim.comm.size,
            "ms_per_step": 1e3 * sim.comm.allreduce(elapsed, op=_max()) / steps,
            "krylov_per_newton": linear / max(solves, 1), "newton_per_step": newton / steps if nonlinear else None,
            "unknowns": unknowns, "peak_bytes": peak, "bytes_per_unknown": peak / unknowns}


def share(example: str, backend: str, size: int, steps: int, warmup: int, extra: list[str], clock: str) -> dict:
    """ms/step and ms of linear solves per step of one example in this process (under MPI: the largest
    over the ranks, for the step and for each subproblem's solves)."""
    from primordia.coupling.orchestrator import Simulation
    from primordia.core.clocks import CLOCKS
    from primordia.model import Model

    overrides = [f"mesh.cells={mesh_cells(example, size)}", "output.pictures=false", "output.series_every=100000",
                 "time.t_final=1e6", *extra]
    model = Model.from_file(ROOT / f"examples/{example}.toml", overrides)
    sim = Simulation(model, backend=backend, out_dir=f"/tmp/primordia-bench-share/{example}-{backend}-{size}")
    sim.setup()
    for _ in range(warmup):
        sim.step()
    before = sim.linear_solve_seconds(clock)  # the solves on the clock the step is timed with
    sim.comm.Barrier()
    read = CLOCKS[clock]  # the solvers' clocks: steps and solves timed alike
    start = read()
    for _ in range(steps):
        sim.step()
    elapsed = read() - start
    solves = {name: seconds - before.get(name, 0.0) for name, seconds in sim.linear_solve_seconds(clock).items()}
    if sim.comm.size > 1:
        elapsed = sim.comm.allreduce(elapsed, op=_max())
    solving = sum(solves.values())
    return {"example": example, "backend": backend, "size": size, "ranks": sim.comm.size,
            "ms_per_step": 1e3 * elapsed / steps, "solve_ms_per_step": 1e3 * solving / steps, "ratio": elapsed / solving,
            "solves_ms_per_step": {name: 1e3 * value / steps for name, value in solves.items()}}


def mesh_cells(example: str, size: int) -> str:
    """``mesh.cells`` of ``example`` at ``size``: squares per side on a rectangle, boxes per side on a box (as
    ``growth3d``: a tenth of them, at least 2, across the thickness)."""
    import tomllib

    kind = tomllib.loads((ROOT / f"examples/{example}.toml").read_text()).get("mesh", {}).get("type")
    return SYSTEMS["growth3d"]["cells"](size) if kind == "box" else f"[{size},{size}]"


def _max():
    from mpi4py import MPI

    return MPI.MAX


#: The runs that failed (their labels): the study says how many at its end and exits 1.
FAILED: list[str] = []


def child(system, preconditioner, size, args) -> dict | None:
    """One ``--one`` run in a child process, or None if it failed."""
    return _run_child(["--one", system, preconditioner, str(size)], f"{system} {preconditioner} {size}", args)


def _run_child(what: list[str], label: str, args) -> dict | None:
    """Run this script with ``what`` (``--one ...`` or ``--share-one ...``) and the shared options in a child
    process, under ``mpirun`` with ``--ranks``; its last JSON line, or None (and a line saying why)."""
    command = [sys.executable, __file__, *what, "--steps", str(args.steps), "--warmup", str(args.warmup),
               "--clock", args.clock, *sum((["--set", s] for s in args.set), [])]
    if args.ranks > 1:
        command = ["mpirun", "-n", str(args.ranks), *command]
    env = launch_environment()
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        reason = last_words(done.stderr)
        print(f"  {label}: failed ({reason[:160]})", flush=True)
        FAILED.append(label)
        return None
    return json.loads(lines[-1])


def share_table(args) -> None:
    print(f"{'example':>8} {'backend':>8} {'size':>5} {'ms/step':>9} {'solves ms':>10} {'step/solves':>11}", flush=True)
    ratios: dict = {}  # (example, backend, size) -> [step/solves of each repeat]
    for _ in range(args.repeats):  # outermost: a repeat runs every case once, so the repeats alternate
        for example in args.share:
            for size in args.sizes:
                for backend in args.backends:
                    row = share_child(example, backend, size, args)
                    if row is None:
                        continue
                    ratios.setdefault((example, backend, size), []).append(row["ratio"])
                    print(f"{example:>8} {backend:>8} {size:>5} {row['ms_per_step']:>9.1f} {row['solve_ms_per_step']:>10.1f} "
                          f"{row['ratio']:>11.2f}", flush=True)
                    shares = ", ".join(f"{name} {ms:.1f}" for name, ms in row["solves_ms_per_step"].items())
                    print(f"{'':>8} solves on {row['ranks']} rank(s), ms/step: {shares}", flush=True)
                    if args.json:
                        with open(args.json, "a") as stream:
                            stream.write(json.dumps(row) + "\n")
    if args.repeats > 1:
        print(f"step/solves, median of {args.repeats} runs (range):", flush=True)
        for (example, backend, size), values in ratios.items():
            print(f"  {example} {backend} {size}: {statistics.median(values):.2f} ({min(values):.2f}-{max(values):.2f})",
                  flush=True)


def share_child(example: str, backend: str, size: int, args) -> dict | None:
    """One ``--share-one`` run in a child process, or None if it failed."""
    return _run_child(["--share-one", example, backend, str(size)], f"{example} {backend} {size}", args)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--systems", nargs="+", default=["growth2d"], choices=sorted(SYSTEMS))
    parser.add_argument("--sizes", type=int, nargs="+", default=[43, 86, 171])
    parser.add_argument("--preconditioners", nargs="+", default=None, help="default: every one of the system")
    parser.add_argument("--steps", type=int, default=3)
    parser.add_argument("--warmup", type=int, default=2)
    parser.add_argument("--ranks", type=int, default=1)
    parser.add_argument("--clock", choices=("cpu", "wall"), default="cpu")
    parser.add_argument("--set", action="append", default=[], help="an extra config override for every run")
    parser.add_argument("--one", nargs=3, metavar=("SYSTEM", "PRECONDITIONER", "SIZE"), help=argparse.SUPPRESS)
    parser.add_argument("--repeats", type=int, default=1,
                        help="run every size N times (each repeat runs the sizes in turn) and summarise medians")
    parser.add_argument("--json", help="also append every row to this file (JSON lines)")
    parser.add_argument("--share", nargs="+", metavar="EXAMPLE", choices=EXAMPLES,
                        help="step cost against linear solves instead")
    parser.add_argument("--backends", nargs="+", default=["fenicsx"], choices=["fenicsx", "skfem"],
                        help="backends of --share")
    parser.add_argument("--share-one", nargs=3, metavar=("EXAMPLE", "BACKEND", "SIZE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    require_at_least(parser, ("--repeats", args.repeats, 1), ("--steps", args.steps, 1), ("--warmup", args.warmup, 0),
                     ("--ranks", args.ranks, 1), ("--sizes", min(args.sizes), 1))
    for system in args.systems if args.preconditioners and not args.share else []:
        unknown = [name for name in args.preconditioners if name not in SYSTEMS[system]["preconditioners"]]
        if unknown:
            parser.error(f"--preconditioners: {system} has no {', '.join(unknown)} "
                         f"(its own: {', '.join(SYSTEMS[system]['preconditioners'])})")
    if args.share_one:
        example, backend, size = args.share_one
        row = share(example, backend, int(size), args.steps, args.warmup, args.set, args.clock)
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print(json.dumps(row), flush=True)
        return
    if args.one:
        row = one(args.one[0], args.one[1], int(args.one[2]), args.steps, args.warmup, args.set, args.clock)
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print(json.dumps(row), flush=True)
        return
    print(describe(), flush=True)
    if args.share:
        share_table(args)
    else:
        study_table(args)
    if FAILED:
        sys.exit(f"bench_solvers: {len(FAILED)} run(s) failed: {', '.join(FAILED)}")


def study_table(args) -> None:
    """The solver study: per system, size and preconditioner, one row of Krylov iterations, cost and memory."""
    header = (f"{'system':>10} {'preconditioner':>14} {'size':>5} {'ranks':>5} {'unknowns':>9} {'Krylov/Newton':>13} "
              f"{'Newton/step':>11} {'ms/step':>9} {'peak MB':>8} {'B/unknown':>9} {'/direct':>7}")
    print(header, flush=True)
    runs: dict = {}  # (system, preconditioner, size) -> {repeat: row}
    for repeat in range(args.repeats):  # outermost: the sizes of one repeat run one after another
        for system in args.systems:
            names = args.preconditioners or list(SYSTEMS[system]["preconditioners"])
            for size in args.sizes:
                direct = None
                for name in names:
                    row = child(system, name, size, args)
                    if row is None:
                        continue
                    runs.setdefault((system, name, size), {})[repeat] = row
                    direct = direct or row["ms_per_step"]
                    newton = f"{row['newton_per_step']:.1f}" if row["newton_per_step"] is not None else "-"
                    print(f"{system:>10} {name:>14} {size:>5} {row['ranks']:>5} {row['unknowns']:>9} "
                          f"{row['krylov_per_newton']:>13.1f} {newton:>11} {row['ms_per_step']:>9.0f} "
                          f"{row['peak_bytes'] / 2**20:>8.0f} {row['bytes_per_unknown']:>9.0f} "
                          f"{row['ms_per_step'] / direct:>7.2f}", flush=True)
                    if args.json:
                        with open(args.json, "a") as stream:
                            stream.write(json.dumps({**row, "ratio_to_direct": row["ms_per_step"] / direct}) + "\n")
    if len(args.sizes) > 1:
        print_growth(runs, args)


def per_doubling(unknowns: tuple[float, float], ms: tuple[float, float]) -> float:
    """The factor by which the cost per step grows for each doubling of the unknowns between two sizes:
    (ms_2 / ms_1) ** (log 2 / log(N_2 / N_1)); 2 is linear cost, and issue 9's bar is 2.3."""
    return (ms[1] / ms[0]) ** (math.log(2.0) / math.log(unknowns[1] / unknowns[0]))


def growth_lines(by_size: dict[int, dict[int, dict]]) -> list[str]:
    """What one preconditioner's runs say about growth over the sizes: Krylov iterations per Newton step
    (median, and the change from the first size to the last), and the cost per doubling of the unknowns
    between consecutive sizes, from the median ms/step and over the repeats (each repeat ran its sizes one
    after the other, so a pair of one repeat saw the same machine)."""
    sizes = sorted(by_size)
    median = {size: statistics.median(row["ms_per_step"] for row in by_size[size].values()) for size in sizes}
    krylov = {size: statistics.median(row["krylov_per_newton"] for row in by_size[size].values()) for size in sizes}
    unknowns = {size: next(iter(by_size[size].values()))["unknowns"] for size in sizes}
    first, last = krylov[sizes[0]], krylov[sizes[-1]]
    change = f"{100.0 * (last / first - 1.0):+.0f}%" if first > 0 else "-"
    lines = [f"Krylov/Newton {', '.join(f'{krylov[size]:.1f}' for size in sizes)} ({change} from {sizes[0]} to {sizes[-1]})"]
    for small, large in zip(sizes, sizes[1:]):
        factor = per_doubling((unknowns[small], unknowns[large]), (median[small], median[large]))
        pairs = [per_doubling((unknowns[small], unknowns[large]),
                              (by_size[small][k]["ms_per_step"], by_size[large][k]["ms_per_step"]))
                 for k in sorted(set(by_size[small]) & set(by_size[large]))]
        spread = f" (repeats {min(pairs):.2f}-{max(pairs):.2f})" if len(pairs) > 1 else ""
        lines.append(f"{small} -> {large}: {_ms(median[small])} -> {_ms(median[large])} ms/step, "
                     f"{unknowns[large] / unknowns[small]:.2f}x the unknowns, {factor:.2f}x per doubling{spread}")
    return lines


def _ms(value: float) -> str:
    return f"{value:.0f}" if value >= 100 else f"{value:.3g}"


def print_growth(runs: dict, args) -> None:
    """Per system and preconditioner, the growth over the sizes (medians when ``--repeats`` > 1)."""
    print(f"growth over the sizes (medians of {args.repeats} run(s) each):", flush=True)
    grouped: dict = {}
    for (system, name, size), rows in runs.items():
        grouped.setdefault((system, name), {})[size] = rows
    for (system, name), by_size in grouped.items():
        if len(by_size) < 2:
            continue
        lines = growth_lines(by_size)
        print(f"  {system} {name}: {lines[0]}", flush=True)
        for line in lines[1:]:
            print(f"    {line}", flush=True)

if __name__ == "__main__":
    main()
