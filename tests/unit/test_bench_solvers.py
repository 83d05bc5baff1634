"""The solver study's growth summary (benchmarks/bench_solvers.py): the cost per doubling of the unknowns."""

import importlib.util
import math
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


@pytest.fixture(scope="module")
def bench():
    sys.path.insert(0, str(BENCHMARKS))  # bench_solvers imports its neighbour machine.py
    try:
        spec = importlib.util.spec_from_file_location("bench_solvers", BENCHMARKS / "bench_solvers.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.path.remove(str(BENCHMARKS))


def test_linear_cost_is_a_factor_of_two_per_doubling_whatever_the_refinement(bench):
    assert bench.per_doubling((1000, 4000), (10.0, 40.0)) == pytest.approx(2.0)
    assert bench.per_doubling((1000, 3770), (10.0, 37.7)) == pytest.approx(2.0)
    # N^1.5 (a banded direct solve): 2 ** 1.5 per doubling
    assert bench.per_doubling((1000, 3000), (1.0, 3.0 ** 1.5)) == pytest.approx(2.0 ** 1.5)


def _row(unknowns, ms, krylov):
    return {"unknowns": unknowns, "ms_per_step": ms, "krylov_per_newton": krylov}


def test_the_summary_takes_medians_and_pairs_each_repeat_with_itself(bench):
    by_size = {
        10: {0: _row(8793, 800.0, 18.1), 1: _row(8793, 700.0, 18.1), 2: _row(8793, 900.0, 18.1)},
        20: {0: _row(33153, 3400.0, 18.3), 1: _row(33153, 3300.0, 18.3), 2: _row(33153, 3500.0, 18.3)},
    }
    krylov, step = bench.growth_lines(by_size)
    assert krylov == "Krylov/Newton 18.1, 18.3 (+1% from 10 to 20)"
    factor = lambda a, b: (b / a) ** (math.log(2.0) / math.log(33153 / 8793))  # noqa: E731
    pairs = (factor(800, 3400), factor(700, 3300), factor(900, 3500))  # repeat k at 10 with repeat k at 20
    low, high = min(pairs), max(pairs)
    assert step == (f"10 -> 20: 800 -> 3400 ms/step, 3.77x the unknowns, {factor(800, 3400):.2f}x per doubling "
                    f"(repeats {low:.2f}-{high:.2f})")


def test_a_repeat_that_failed_at_one_size_is_left_out_of_the_pairs(bench):
    by_size = {43: {0: _row(7744, 1.0, 4.0), 1: _row(7744, 1.2, 4.0)},
               86: {1: _row(30276, 2.4, 4.8)}}
    _, step = bench.growth_lines(by_size)
    assert "repeats" not in step  # one pair left: no range to give
    assert step.startswith("43 -> 86: 1.1 -> 2.4 ms/step")


SCRIPTS = sorted(p.name for p in BENCHMARKS.glob("*.py") if p.name != "machine.py")


@pytest.mark.parametrize("script", SCRIPTS)
def test_every_benchmark_script_says_how_to_run_it(script):
    """``--help`` of every script in benchmarks/ (which the suite does not otherwise run) prints its usage:
    the plain dolfinx script read its arguments by position and took "--help" for a mesh size (a traceback)."""
    import subprocess

    done = subprocess.run([sys.executable, str(BENCHMARKS / script), "--help"], capture_output=True, text=True,
                          cwd=BENCHMARKS, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"usage: {script}"), done.stdout


def test_the_plain_dolfinx_script_refuses_a_mesh_of_no_cells_in_one_line():
    import subprocess

    done = subprocess.run([sys.executable, str(BENCHMARKS / "plain_dolfinx_ex01a.py"), "0", "5"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1] == "plain_dolfinx_ex01a.py: error: cells and steps must be positive"
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("options, error", [
    (["--systems", "cells", "--preconditioners", "foo"], "--preconditioners: cells has no foo (its own: lu, "),
    (["--systems", "growth2d", "cells", "--preconditioners", "lu"], "--preconditioners: growth2d has no lu (its own: "),
    (["--share", "ex01c"], "argument --share: invalid choice: 'ex01c'"),
    (["--share", "ex01a", "--backends", "fenix"], "argument --backends: invalid choice: 'fenix'"),
    (["--steps", "0"], "--steps must be at least 1, got 0"),
    (["--warmup", "-1"], "--warmup must be at least 0, got -1"),
    (["--sizes", "43", "0"], "--sizes must be at least 1, got 0"),
    (["--ranks", "0"], "--ranks must be at least 1, got 0"),
])
def test_a_bad_option_of_the_solver_study_is_one_line_before_any_run(options, error):
    """A preconditioner the system does not have, an example or backend that does not exist, no steps: each ran
    every child to a "failed" row (a KeyError, a division by zero) and exited 0."""
    import subprocess

    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_solvers.py"), *options], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2, done.stdout
    assert done.stderr.strip().splitlines()[-1].startswith(f"bench_solvers.py: error: {error}"), done.stderr
    assert done.stdout == ""


def test_the_share_of_a_3d_example_sizes_its_box_as_growth3d(bench):
    """``--share ex04_small`` set two cells per side of a box mesh: every size failed."""
    assert bench.mesh_cells("ex04_small", 20) == "[20,20,2]"
    assert bench.mesh_cells("ex04", 40) == "[40,40,4]"
    assert bench.mesh_cells("ex01b", 43) == "[43,43]"


MPIRUN_STDERR = """Traceback (most recent call last):
  File "bench_solvers.py", line 267, in main
primordia.core.errors.PrimordiaError: the skfem backend is serial: run it without mpirun
--------------------------------------------------------------------------
Primary job  terminated normally, but 1 process returned
a non-zero exit code. Per user-direction, the job has been aborted.
--------------------------------------------------------------------------
"""


@pytest.mark.parametrize("script", ["bench_solvers.py", "bench_scaling.py"])
def test_a_run_failed_under_mpirun_is_told_by_its_own_last_line_not_mpiruns(script):
    """Under ``--ranks 2`` every failure read "failed (-----...)": the last line of mpirun's banner."""
    sys.path.insert(0, str(BENCHMARKS))
    try:
        spec = importlib.util.spec_from_file_location(script[:-3], BENCHMARKS / script)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCHMARKS))
    assert module.last_words(MPIRUN_STDERR) == ("primordia.core.errors.PrimordiaError: the skfem backend is serial: "
                                                "run it without mpirun")
    assert module.last_words("primordia: error: no such file\n") == "primordia: error: no such file"
    assert module.last_words("") == "no output"


@pytest.mark.parametrize("options, error", [
    (["--repeats", "0"], "--repeats must be at least 1, got 0"),
    (["--steps", "0"], "--steps must be at least 1, got 0"),
    (["--ranks", "1"], "--ranks must be at least 2, got 1"),
    (["--as-shipped", "--steps", "20"], "--as-shipped runs each example as its TOML states it: it takes neither"),
])
def test_a_bad_option_of_the_scaling_study_is_one_line_before_any_run(options, error):
    """--repeats 0 ran both rank counts and ended in an IndexError; --steps 0 silently ran the default 200 steps
    (``steps or default``), and so did --steps under --as-shipped, which runs the whole example."""
    import subprocess

    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_scaling.py"), "--examples", "ex01a",
                           "--set", "mesh.cells=[8,8]", *options], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stdout
    assert done.stderr.strip().splitlines()[-1].startswith(f"bench_scaling.py: error: {error}"), done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("script, options, error", [
    ("bench_examples.py", ["--sizes", "8", "--steps", "0"], "--steps must be at least 1, got 0"),
    ("bench_examples.py", ["--sizes", "8", "--repeats", "0"], "--repeats must be at least 1, got 0"),
    ("bench_growth.py", ["--sizes", "0"], "--sizes must be at least 1, got 0"),
    ("bench_growth.py", ["--no-ex02a", "--full", "ex2a"], "argument --full: invalid choice: 'ex2a'"),
    ("bench_growth.py", ["--backends", "fenix"], "argument --backends: invalid choice: 'fenix'"),
    ("bench_memory.py", ["--examples", "ex01a", "--rebuilds", "0"], "--rebuilds must be at least 1, got 0"),
    ("bench_skfem_mixed.py", ["--sizes", "4", "--box", "--repeats", "0"], "--repeats must be at least 1, got 0"),
    ("mumps_reproducibility.py", ["--n", "0"], "--n must be at least 1, got 0"),
    ("mumps_reproducibility.py", ["--n", "4", "--package", "mumsp"], "--package mumsp: this PETSc cannot factorise"),
])
def test_a_bad_option_of_a_benchmark_is_one_line_and_exit_2(script, options, error):
    """No steps or repeats ended in a ZeroDivisionError or an empty median, --steps -1 printed negative times,
    an example or backend that does not exist a traceback from the run, --n 0 the digest of nothing, an unknown
    factor package PETSc's error stack."""
    import subprocess

    done = subprocess.run([sys.executable, str(BENCHMARKS / script), *options], capture_output=True, text=True,
                          cwd=BENCHMARKS, timeout=120)
    assert done.returncode == 2, done.stdout
    assert done.stderr.strip().splitlines()[-1].startswith(f"{script}: error: {error}"), done.stderr
    assert "Traceback" not in done.stderr


def test_a_study_whose_run_failed_says_so_at_its_end_and_exits_1():
    """A failed run was a line among the rows and the study exited 0: a script driving it saw success."""
    options = ["--systems", "cells", "--sizes", "4", "--preconditioners", "bjacobi_ilu", "--steps", "1",
               "--warmup", "0", "--set", "mesh.cells=[0,4]"]
    done = subprocess.run([sys.executable, str(BENCHMARKS / "bench_solvers.py"), *options], capture_output=True,
                          text=True, cwd=BENCHMARKS, timeout=120)
    assert done.returncode == 1, done.stdout + done.stderr
    assert "cells bjacobi_ilu 4: failed (" in done.stdout
    assert done.stderr.strip().splitlines()[-1] == "bench_solvers: 1 run(s) failed: cells bjacobi_ilu 4"


def test_the_full_example_run_of_the_benchmark_replaces_its_last_one_and_a_failure_is_one_line(tmp_path, capsys):
    """``bench_examples.py --full`` a second time was refused by the first one's run (a CalledProcessError
    traceback), as was any failed run."""
    sys.path.insert(0, str(BENCHMARKS))
    try:
        spec = importlib.util.spec_from_file_location("bench_examples", BENCHMARKS / "bench_examples.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCHMARKS))
    coarse = ("--set", "mesh.cells=[4,4]", "--set", "time.t_final=0.4", "--set", "output.times=[0.4]",
              "--set", "output.pictures=false")
    for _ in range(2):
        module.full_run(tmp_path / "full", coarse)
        assert "full example 1a (171x171, 2600 steps" in capsys.readouterr().out
    with pytest.raises(SystemExit) as failed:
        module.full_run(tmp_path / "full", (*coarse, "--set", "mesh.cells=[0,4]"))
    assert str(failed.value).startswith("bench_examples: the full example 1a failed: primordia: error: ")
