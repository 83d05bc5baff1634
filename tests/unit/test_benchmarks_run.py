"""Every script in benchmarks/ runs to its end at its smallest size and prints each figure its docstring names.

The suite times nothing (README, "Benchmarks"): these runs check that the scripts behind the measured figures
still run against the current code, not how fast. A few seconds each; the scripts that launch mpirun do so on 2
ranks.
"""

import re
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"

NUMBER = r"-?\d+(?:\.\d+)?(?:e[+-]\d+)?"  # a finite figure as the scripts print it (no nan, no inf)
MACHINE = r"machine: .+; PETSc \d"

#: script -> (its cheapest options, the lines its output must hold, as regular expressions)
RUNS = {
    "bench_solvers": (
        ["--systems", "cells", "--sizes", "4", "6", "--preconditioners", "bjacobi_ilu", "--steps", "1",
         "--warmup", "0"],
        [MACHINE,
         *(rf"^ +cells +bjacobi_ilu +{size} +1 +{unknowns} +{NUMBER} +- +{NUMBER} +{NUMBER} +{NUMBER} +1\.00$"
           for size, unknowns in ((4, 100), (6, 196))),
         r"^  cells bjacobi_ilu: Krylov/Newton \d+\.\d, \d+\.\d \([+-]\d+% from 4 to 6\)$",
         rf"^    4 -> 6: {NUMBER} -> {NUMBER} ms/step, 1\.96x the unknowns, {NUMBER}x per doubling$"]),
    "bench_solvers_share": (
        ["--share", "ex01a", "--sizes", "4", "--steps", "1", "--warmup", "0", "--ranks", "2"],
        [MACHINE, rf"^ +ex01a +fenicsx +4 +{NUMBER} +{NUMBER} +{NUMBER}$",
         rf"^ +solves on 2 rank\(s\), ms/step: chemotaxis\.b {NUMBER}, chemotaxis\.e {NUMBER}, "
         rf"chemotaxis\.f {NUMBER}, chemotaxis\.m {NUMBER}$"]),
    "bench_scaling": (
        ["--examples", "ex01a", "--set", "mesh.cells=[4,4]", "--steps", "2", "--solves"],
        [MACHINE, rf"^ +ex01a +100( +{NUMBER}){{7}}$",
         *(rf"^ +linear solves on {ranks} rank\(s\), ms/step: chemotaxis\.b {NUMBER}, " for ranks in (1, 2))]),
    "bench_examples": (
        ["--sizes", "4", "--steps", "1", "--repeats", "1"],
        [MACHINE, rf"^ +4\^2 +{NUMBER}ms +{NUMBER}ms +{NUMBER} +{NUMBER}ms +{NUMBER}$"]),
    "bench_growth": (
        ["--sizes", "4", "--steps", "1"],
        [MACHINE, *(rf"^ +4 +{backend} +\d+ +{NUMBER} +{NUMBER} +{NUMBER} +212$" for backend in ("fenicsx", "skfem")),
         rf"^ +ratio +{NUMBER} +\(skfem / fenicsx\)$"]),
    "bench_memory": (
        ["--examples", "ex01a", "--steps", "1", "--warmup", "0", "--rebuilds", "1"],
        [MACHINE, rf"^ +ex01a +fenicsx +\[43,43\] +{NUMBER} +{NUMBER} +{NUMBER}$"]),
    "bench_skfem_mixed": (
        ["--sizes", "2", "--box", "1", "--repeats", "1"],
        [MACHINE, *(rf"^ +{mesh} +{dofs} \|( +{NUMBER}){{3}} \|( +{NUMBER}){{3}} \| +{NUMBER}$"
                    for mesh, dofs in ((r"2\^2", 68), (r"1\^3", 97)))]),
    "mumps_reproducibility": (["--n", "4"], [r"^[0-9a-f]{16}$"]),
    "plain_dolfinx_ex01a": (["4", "1"], [rf"^plain dolfinx: 4x4: {NUMBER} ms/step \(m in \[{NUMBER}, {NUMBER}\]\)$"]),
}


@pytest.mark.parametrize("run", [pytest.param(name, marks=[pytest.mark.mpi] if "--ranks" in options or
                                              name == "bench_scaling" else [])
                                 for name, (options, _) in RUNS.items()])
def test_a_benchmark_runs_to_its_end_at_its_smallest_size(run):
    """From a process that has started MPI, as a pytest worker that ran a backend's tests has (and a notebook that
    imported dolfinx): its children inherit the singleton's OMPI_/PMIX_ variables, and the mpirun of bench_scaling
    and bench_solvers --ranks 2 handed them exited 1 without a word (the fresh suite's failures of 2026-12-05)."""
    from mpi4py import MPI  # noqa: F401 - starts MPI in this process, whose environment the script inherits

    options, expected = RUNS[run]
    script = run.removesuffix("_share") + ".py"
    done = subprocess.run([sys.executable, str(BENCHMARKS / script), *options], capture_output=True, text=True,
                          cwd=BENCHMARKS, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr and "failed" not in done.stdout, done.stdout + done.stderr
    for pattern in expected:
        assert re.search(pattern, done.stdout, re.MULTILINE), f"{pattern!r} not in:\n{done.stdout}"
