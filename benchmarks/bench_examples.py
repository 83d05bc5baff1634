"""Benchmarks of seed examples 1a and 1b: framework vs a plain dolfinx script, backends, schemes.

Prints, for 43, 86 and 171 squares per side, the time per step (ms, median of
repeats, setup and output excluded) of

* primordia on the fenicsx backend (and on skfem when it is importable),
* benchmarks/plain_dolfinx_ex01a.py, the same discrete scheme written directly
  against dolfinx,

and the ratios framework/plain and skfem/fenicsx.  ``--ex01b`` adds example 1b
(poroelastic tissue) per backend and per splitting scheme.  With ``--full`` it also runs
the whole example 1a (2,600 steps on the seed's 58,482-triangle mesh) through
the CLI and reports its wall time and peak memory.

    .venv/bin/python benchmarks/bench_examples.py [--steps 40] [--repeats 3] [--sizes 43 86 171] [--ex01b] [--full]
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

from machine import describe, last_words, require_at_least  # benchmarks/machine.py

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))


def framework_ms_per_step(n: int, steps: int, backend: str, example: str = "ex01a", extra=()) -> float:
    from primordia.coupling.orchestrator import Simulation
    from primordia.model import Model

    model = Model.from_file(ROOT / f"examples/{example}.toml",
                            [f"mesh.cells=[{n},{n}]", "output.pictures=false", *extra])
    sim = Simulation(model, backend=backend, out_dir=f"/tmp/primordia-bench-{backend}-{n}")
    sim.setup()
    sim.step()  # first step: JIT / first factorisations
    start = time.perf_counter()
    for _ in range(steps):
        sim.step()
    return 1e3 * (time.perf_counter() - start) / steps


def plain_ms_per_step(n: int, steps: int) -> float:
    import plain_dolfinx_ex01a

    plain_dolfinx_ex01a.main(n, 1)  # JIT
    return plain_dolfinx_ex01a.main(n, steps)[0]


def median_of(repeats: int, fn, *args) -> float:
    return statistics.median(fn(*args) for _ in range(repeats))


def full_run(out: Path = Path("/tmp/primordia-bench-full"), extra: tuple[str, ...] = ()) -> None:
    """The whole example 1a as ``primordia run`` runs it, into ``out`` (replacing an earlier benchmark's run there:
    a second ``--full`` was refused, a CalledProcessError traceback); a failed run is its own last line, exit 1."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "primordia.cli", "run", str(ROOT / "examples/ex01a.toml"),
                           "--out", str(out), "--no-progress", "--overwrite", *extra],
                          stderr=subprocess.PIPE, text=True)
    if done.returncode != 0:
        sys.exit(f"bench_examples: the full example 1a failed: {last_words(done.stderr)}")
    wall = time.perf_counter() - start
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"full example 1a (171x171, 2600 steps, fenicsx, incl. start-up and outputs): "
          f"{wall:.1f} s wall, peak memory {peak_mb:.0f} MB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--sizes", type=int, nargs="+", default=[43, 86, 171])
    parser.add_argument("--full", action="store_true", help="also run the whole example 1a")
    parser.add_argument("--ex01b", action="store_true", help="also time example 1b per backend and scheme")
    args = parser.parse_args()
    require_at_least(parser, ("--steps", args.steps, 1), ("--repeats", args.repeats, 1),
                     ("--sizes", min(args.sizes), 1))
    print(describe(), flush=True)

    from primordia.core.plugins import BackendEntry

    skfem_ok = BackendEntry("skfem", "primordia.backends.skfem:SkfemBackend").availability() is None
    print(f"{'size':>8} {'fenicsx':>10} {'plain':>10} {'fw/plain':>9}" + (f" {'skfem':>10} {'sk/fx':>7}" if skfem_ok else ""))
    for n in args.sizes:
        fenicsx = median_of(args.repeats, framework_ms_per_step, n, args.steps, "fenicsx")
        plain = median_of(args.repeats, plain_ms_per_step, n, args.steps)
        row = f"{n:>5}^2 {fenicsx:>8.2f}ms {plain:>8.2f}ms {fenicsx / plain:>9.3f}"
        if skfem_ok:
            skfem = median_of(args.repeats, framework_ms_per_step, n, args.steps, "skfem")
            row += f" {skfem:>8.2f}ms {skfem / fenicsx:>7.2f}"
        print(row, flush=True)
    if not skfem_ok:
        print("skfem backend not importable: skipped its column")
    if args.ex01b:
        ex01b_table(args, skfem_ok)
    if args.full:
        full_run()


#: Splitting schemes timed on example 1b (monolithic needs the Galerkin cell flux).
SCHEMES = {
    "sequential": ['coupling.scheme="sequential"'],
    "strang": ['coupling.scheme="strang"'],
    "fixed_point": ['coupling.scheme="fixed_point"', "coupling.tolerance=1e-8"],
    "monolithic": ['coupling.scheme="monolithic"', 'physics.chemotaxis.flux_scheme="galerkin"'],
}


def ex01b_table(args, skfem_ok: bool) -> None:
    backends = ["fenicsx"] + (["skfem"] if skfem_ok else [])
    print("\nexample 1b (poroelastic, periodic traction): ms/step")
    print(f"{'size':>8} {'scheme':>12} " + " ".join(f"{b:>10}" for b in backends))
    for n in args.sizes:
        for scheme, extra in SCHEMES.items():
            times = [median_of(args.repeats, framework_ms_per_step, n, args.steps, b, "ex01b", extra)
                     for b in backends]
            print(f"{n:>5}^2 {scheme:>12} " + " ".join(f"{t:>8.2f}ms" for t in times), flush=True)


if __name__ == "__main__":
    main()
