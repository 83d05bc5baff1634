"""The compiled loops (primordia.core.compiled): built on this machine, right, and optional.

On Debian x86-64 (CI and the README's machine) the vector variant must build: a numpy
fall-back there would be a silent slow-down, so it is a failure, not a skip.
"""

from __future__ import annotations

import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest

from primordia.core import compiled
from primordia.core.errors import PrimordiaError


@pytest.fixture
def fresh(monkeypatch, tmp_path):
    """The module as if no library had been loaded in this process, with a cache of its own."""
    monkeypatch.setattr(compiled, "_loaded", {})
    monkeypatch.setenv("PRIMORDIA_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("PRIMORDIA_COMPILED", raising=False)
    return tmp_path


def test_the_loops_build_here_with_vector_math():
    library = compiled.kernels()
    assert library is not None, compiled.status()
    assert compiled.status().startswith("compiled loops: /")
    if platform.machine() == "x86_64" and os.path.exists("/usr/include/x86_64-linux-gnu/bits/math-vector.h"):
        assert compiled._loaded["variant"] == 0, "glibc x86-64 without libmvec's exp: the slow variant was built"


def test_vector_exp_is_numpys_to_four_ulps_everywhere():
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(-745, 709, 20000), rng.uniform(-1e-3, 1e-3, 2000), [0.0, -0.0, 1e-310]])
    expected = np.exp(x)
    got = compiled.vector_exp(x)
    ulps = np.abs(got - expected) / np.spacing(expected)
    assert ulps.max() <= 4, ulps.max()
    with np.errstate(over="ignore"):
        special = compiled.vector_exp(np.array([800.0, -800.0, np.inf, -np.inf, np.nan]))
    assert special[0] == np.inf and special[1] == 0.0 and special[2] == np.inf and special[3] == 0.0
    assert np.isnan(special[4])
    assert compiled.vector_exp(2.0) == np.exp(2.0)  # a scalar goes to numpy
    strided = x[::3]
    np.testing.assert_array_equal(compiled.vector_exp(strided), compiled.vector_exp(strided.copy()))


def test_a_new_cache_is_built_once_and_then_loaded(fresh):
    assert compiled.kernels() is not None
    built = list((fresh / "cache" / "compiled").glob("kernels-*.so"))
    assert len(built) == 1
    inode = built[0].stat().st_ino
    compiled._loaded.clear()
    assert compiled.kernels() is not None
    assert built[0].stat().st_ino == inode  # loaded, not built again (a build renames a new file over it)
    assert not [p for p in built[0].parent.iterdir() if p.name.startswith(".")]  # no temporary file left
    # readable by the others who share a cache (PRIMORDIA_CACHE_DIR on a cluster): the compiler wrote into the
    # private temporary file, whose 0600 it kept (0711 with the execute bits), and they built their own
    assert built[0].stat().st_mode & 0o777 == 0o755, oct(built[0].stat().st_mode)


def test_the_cache_keeps_the_builds_used_last_and_drops_older_ones_and_stale_temporaries(fresh):
    """Builds of other versions (other sources or flags) pile up in a shared cache: all but the
    KEPT_BUILDS most recently used go when a library is loaded, and so do temporary files that a
    killed build left behind for more than an hour; a fresh temporary file (a build under way) stays."""
    cache = fresh / "cache" / "compiled"
    cache.mkdir(parents=True)
    now = time.time()
    others = [cache / f"kernels-{index:016x}.so" for index in range(6)]
    for age, path in enumerate(others, start=1):  # 1 to 6 days unused
        path.write_bytes(b"an older build")
        os.utime(path, (now - age * 86400, now - age * 86400))
    stale, under_way = cache / ".kernels-0000000000000001.abc.so", cache / ".kernels-0000000000000002.def.so"
    for path, age in ((stale, 2 * 3600), (under_way, 60)):
        path.write_bytes(b"")
        os.utime(path, (now - age, now - age))
    assert compiled.kernels() is not None
    current = compiled._loaded["path"]
    left = sorted(path.name for path in cache.iterdir())
    assert left == sorted([current.name, under_way.name, *(path.name for path in others[: compiled.KEPT_BUILDS - 1])])
    os.utime(others[2], (now - 3600, now - 3600))  # another checkout used this build an hour ago
    os.utime(current, (now - 7 * 86400, now - 7 * 86400))
    compiled._loaded.clear()
    assert compiled.kernels() is not None  # loading marks the build in use as the most recent
    assert current.stat().st_mtime > now - 60  # so that another process's pruning keeps it
    assert current.exists() and others[2].exists() and others[0].exists() and others[1].exists()


def test_an_unwritable_cache_builds_for_this_process(fresh, monkeypatch, private_tmp):
    blocker = fresh / "not-a-directory"
    blocker.write_text("")
    monkeypatch.setenv("PRIMORDIA_CACHE_DIR", str(blocker))
    assert compiled.kernels() is not None
    assert "built for this process" in compiled.status()
    np.testing.assert_array_equal(compiled.vector_exp(np.zeros(4)), np.ones(4))  # still mapped, though unlinked
    assert not list(private_tmp.iterdir())  # its temporary directory is gone


@pytest.fixture
def private_tmp(monkeypatch, tmp_path):
    """tempfile's directory for this test alone, to see what a process-only build leaves there."""
    directory = tmp_path / "tmp"
    directory.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(directory))
    return directory


def test_a_read_only_cache_builds_for_this_process(fresh, monkeypatch, private_tmp):
    if os.geteuid() == 0:  # root writes into a read-only directory: make it a file's child instead
        monkeypatch.setattr(compiled.tempfile, "NamedTemporaryFile", _refusing_in(fresh / "cache"))
    else:
        (fresh / "cache" / "compiled").mkdir(parents=True)
        (fresh / "cache" / "compiled").chmod(0o500)
    assert compiled.kernels() is not None
    assert "built for this process" in compiled.status()
    assert not list(private_tmp.iterdir())


def _refusing_in(directory):
    """tempfile.NamedTemporaryFile, refusing (as a read-only directory would) to create files under ``directory``."""
    original = tempfile.NamedTemporaryFile

    def named_temporary_file(*args, dir=None, **kwargs):
        if dir is not None and str(dir).startswith(str(directory)):
            raise PermissionError(13, "Permission denied", str(dir))
        return original(*args, dir=dir, **kwargs)

    return named_temporary_file


def test_off_keeps_numpy(fresh, monkeypatch):
    monkeypatch.setenv("PRIMORDIA_COMPILED", "off")
    assert compiled.kernels() is None
    assert "off" in compiled.status()
    x = np.linspace(-3, 3, 11)
    np.testing.assert_array_equal(compiled.vector_exp(x), np.exp(x))


def test_without_a_compiler_auto_falls_back_and_on_is_one_clear_error(fresh, monkeypatch):
    monkeypatch.setenv("CC", "/nonexistent/cc")
    assert compiled.kernels() is None
    assert "no C compiler" in compiled.status() and "/nonexistent/cc" in compiled.status()
    compiled._loaded.clear()
    monkeypatch.setenv("PRIMORDIA_COMPILED", "on")
    with pytest.raises(PrimordiaError, match="PRIMORDIA_COMPILED=on but the compiled loops could not be built"):
        compiled.kernels()


def test_a_compiler_that_fails_falls_back_to_numpy(fresh, monkeypatch, tmp_path):
    failing = tmp_path / "failing-cc"
    failing.write_text("#!/bin/sh\necho 'cc: error: this compiler builds nothing' >&2\nexit 1\n")
    failing.chmod(0o755)
    monkeypatch.setenv("CC", str(failing))
    assert compiled.kernels() is None
    assert "this compiler builds nothing" in compiled.status()
    assert not list((fresh / "cache" / "compiled").glob("*"))  # nothing half-written left


def test_a_wrong_mode_is_one_line_naming_it(fresh, monkeypatch):
    monkeypatch.setenv("PRIMORDIA_COMPILED", "fast")
    with pytest.raises(PrimordiaError, match="PRIMORDIA_COMPILED must be auto, on or off, got 'fast'"):
        compiled.kernels()


def test_a_wrong_mode_stops_a_run_with_one_line(tmp_path):
    primordia = shutil.which("primordia", path=os.path.dirname(sys.executable))
    config = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "ex01a.toml")
    result = subprocess.run([primordia, "run", config, "--set", "mesh.cells=[4,4]", "--set", "time.t_final=0.05",
                             "--out", str(tmp_path / "out"), "--no-progress"],
                            capture_output=True, text=True, env={**os.environ, "PRIMORDIA_COMPILED": "fast"},
                            timeout=300)
    assert result.returncode != 0
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert lines and "PRIMORDIA_COMPILED must be auto, on or off" in lines[-1]
    assert "Traceback" not in result.stderr


def test_addresses_are_checked():
    with pytest.raises(ValueError, match="contiguous float64"):
        compiled.address(np.zeros(4, dtype=np.float32))
    with pytest.raises(ValueError, match="contiguous int64"):
        compiled.address(np.zeros(4, dtype=np.int32), np.int64)
    with pytest.raises(ValueError, match="contiguous float64"):
        compiled.address(np.zeros(8)[::2])


def test_the_places_of_a_parallel_matrix_s_values_in_its_blocks():
    """Each local entry's place in a parallel matrix's blocks (``petsc_library.BlockPlaces``): its count among its
    block's entries before it, the off-diagonal block's after ``split``."""
    from primordia.core.petsc_library import BlockPlaces

    n = 6
    tridiagonal = [[c for c in (i - 1, i, i + 1) if 0 <= c < n] for i in range(n)]
    in_diagonal = np.array([c % 2 == 0 for c in np.concatenate(tridiagonal)])  # any mask: the places are counts
    places = BlockPlaces(_one_rank_mpiaij(tridiagonal), in_diagonal)
    assert places.split == int(in_diagonal.sum())
    assert places.place[in_diagonal].tolist() == list(range(places.split))
    assert places.place[~in_diagonal].tolist() == list(range(places.split, len(in_diagonal)))


def _one_rank_mpiaij(rows_columns: list[list[int]]):
    """A parallel AIJ matrix on one process (its off-diagonal block empty) with these entries, each 1."""
    from petsc4py import PETSc

    matrix = PETSc.Mat().create(comm=PETSc.COMM_SELF)
    matrix.setSizes((len(rows_columns), len(rows_columns)))
    matrix.setType("mpiaij")
    matrix.setPreallocationNNZ(([len(columns) for columns in rows_columns], 0))
    for row, columns in enumerate(rows_columns):
        matrix.setValues(row, columns, np.ones(len(columns)))
    matrix.assemble()
    return matrix


def test_block_places_never_write_past_a_block_smaller_than_the_columns_given(monkeypatch):
    """``BlockPlaces.of`` writes into PETSc's own arrays before it reads the matrix back: given the columns of a
    tridiagonal matrix and a diagonal one, it wrote 16 entries into a block of 6 (on a larger matrix, a heap
    corrupted and an abort at exit).  A matrix whose blocks hold other counts than the columns is not written."""
    from primordia.core.petsc_library import BlockPlaces

    n = 6
    tridiagonal = [[c for c in (i - 1, i, i + 1) if 0 <= c < n] for i in range(n)]
    columns = np.concatenate(tridiagonal).astype(np.int64)
    written = []
    write = BlockPlaces.write
    monkeypatch.setattr(BlockPlaces, "write", lambda self, values: written.append(len(values)))
    assert BlockPlaces.of(_one_rank_mpiaij([[i] for i in range(n)]), columns) is None
    assert written == []
    monkeypatch.setattr(BlockPlaces, "write", write)
    matrix = _one_rank_mpiaij(tridiagonal)
    places = BlockPlaces.of(matrix, columns)
    assert places is not None
    places.write(np.arange(1.0, len(columns) + 1.0))
    matrix.assemble()
    assert matrix.getValuesCSR()[2].tolist() == list(range(1, len(columns) + 1))
    with pytest.raises(ValueError, match="contiguous array of 16 PETSc scalars"):
        places.write(np.zeros(len(columns) - 1))