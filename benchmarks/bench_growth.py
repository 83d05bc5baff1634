"""Benchmarks of the finite-strain growth examples (seed section 4): cost per step and how it grows.

Prints, for example 2a (``examples/ex02a.toml``: chemotaxis on the reference configuration,
poroelasticity with growth, the seed's fixed-point coupling) at 43, 86 and 171 squares per side
(171: the seed's 58,482 triangles), per backend:

* ms per step (median over the timed steps, after two warm-up steps: JIT, first factorisations),
* Newton iterations and Krylov (GMRES) iterations of the mechanics per step, fixed-point iterations,
* the DOFs of the (u, psi, p) system,

and the skfem / fenicsx ratio.  ``--ex04`` adds the laptop-size 3D example
(``examples/ex04_small.toml``).  ``--full ex02a ex02b`` runs whole examples through the CLI and
reports wall time and peak memory (of the child process).

    .venv/bin/python benchmarks/bench_growth.py [--steps 10] [--sizes 43 86 171] [--backends fenicsx skfem]
    .venv/bin/python benchmarks/bench_growth.py --sizes 43 --ex04
    .venv/bin/python benchmarks/bench_growth.py --full ex02a ex02b
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_growth.py --clock cpu   # on a busy machine
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

from primordia.core.clocks import CLOCKS  # the clocks the solvers time themselves on (no PETSc import)

from machine import EXAMPLES, describe, require_at_least  # benchmarks/machine.py

ROOT = Path(__file__).resolve().parent.parent

clock = time.perf_counter


def per_step(example: str, backend: str, steps: int, overrides: list[str]) -> dict:
    from primordia.coupling.orchestrator import Simulation
    from primordia.model import Model

    model = Model.from_file(ROOT / f"examples/{example}.toml", ["output.pictures=false", *overrides])
    sim = Simulation(model, backend=backend, out_dir=f"/tmp/primordia-bench-growth-{backend}").setup()
    for _ in range(2):
        sim.step()
    times, newton, krylov, outer = [], [], [], []
    for _ in range(steps):
        start = clock()
        sim.step()
        times.append(clock() - start)
        counts = sim.iteration_counts()
        newton.append(counts["poroelastic_growth_newton_iterations"])
        krylov.append(counts["poroelastic_growth_linear_iterations"])
        outer.append(counts.get("fixed_point_iterations", 1))
    group = sim.disc.group_function(sim.disc.groups()[-1])
    dofs = {name: sim.backend.num_dofs(sim.disc.group_function(name).ufl_function_space())
            for name in sim.disc.groups()}
    return {"ms": 1e3 * statistics.median(times), "newton": statistics.mean(newton),
            "krylov": statistics.mean(krylov), "outer": statistics.mean(outer),
            "mechanics_dofs": dofs.get("poroelastic_growth", group), "steps": steps}


def table(example: str, sizes: list[int], backends: list[str], steps: int, mesh_key) -> None:
    print(f"\n{example}: per step (median of {steps} steps after 2 warm-up steps, {clock.__name__})")
    print(f"{'size':>10} {'backend':>8} {'ms/step':>9} {'Newton':>7} {'GMRES':>7} {'outer':>6} {'(u,psi,p) dofs':>15}")
    for n in sizes:
        rows = {}
        for backend in backends:
            row = rows[backend] = per_step(example, backend, steps, [mesh_key(n)])
            print(f"{n:>10} {backend:>8} {row['ms']:>9.0f} {row['newton']:>7.1f} {row['krylov']:>7.1f} "
                  f"{row['outer']:>6.1f} {row['mechanics_dofs']:>15}", flush=True)
        if len(rows) == 2:
            print(f"{'':>10} {'ratio':>8} {rows['skfem']['ms'] / rows['fenicsx']['ms']:>9.2f}  (skfem / fenicsx)")


def full(example: str) -> None:
    out = Path(f"/tmp/primordia-bench-full-{example}")
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "primordia.cli", "run", str(ROOT / f"examples/{example}.toml"),
                    "--out", str(out), "--no-progress"], check=True)
    wall = time.perf_counter() - start
    peak = max(before, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024
    summary = json.loads((out / "summary.json").read_text())
    print(f"full {example} ({summary['cells']} cells, {summary['dofs_total']} dofs, {summary['steps']} steps, "
          f"{summary['backend']}): {wall:.0f} s wall, peak memory {peak:.0f} MB, status {summary['status']}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--sizes", type=int, nargs="+", default=[43, 86, 171])
    parser.add_argument("--backends", nargs="+", default=["fenicsx", "skfem"], choices=["fenicsx", "skfem"])
    parser.add_argument("--ex04", action="store_true", help="also time examples/ex04_small.toml (3D)")
    parser.add_argument("--no-ex02a", action="store_true", help="skip the example 2a table")
    parser.add_argument("--full", nargs="*", default=[], choices=EXAMPLES,
                        help="run these examples whole (e.g. ex02a ex02b)")
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall",
                        help="cpu: this process's CPU time, fair on a machine others are using (run with "
                             "OPENBLAS_NUM_THREADS=1)")
    args = parser.parse_args()
    require_at_least(parser, ("--steps", args.steps, 1), ("--sizes", min(args.sizes), 1))
    print(describe(), flush=True)
    global clock
    clock = CLOCKS[args.clock]
    if not args.no_ex02a:
        table("ex02a", args.sizes, args.backends, args.steps, lambda n: f"mesh.cells=[{n},{n}]")
    if args.ex04:
        table("ex04_small", [20], args.backends, args.steps, lambda n: f"mesh.cells=[{n},{n},2]")
    for example in args.full:
        full(example)


if __name__ == "__main__":
    main()
