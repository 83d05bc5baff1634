"""Which BLAS PETSc runs on (primordia.core.blas), and the one-line warning for the reference one."""

import os
import subprocess
import sys
from pathlib import Path

from primordia.core.blas import BlasLibrary, kind_of, reference_blas_warning, system_blas

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_implementations_are_told_apart_by_their_exported_symbols():
    def exporting(*symbols):
        return lambda name: name in symbols

    assert kind_of(exporting("dgemm_", "openblas_get_config"))[0] == "OpenBLAS"
    assert kind_of(exporting("dgemm_", "bli_info_get_version_str"))[0] == "BLIS"
    assert kind_of(exporting("dgemm_", "MKL_Get_Version"))[0] == "MKL"
    assert kind_of(exporting("dgemm_", "flexiblas_current_backend"))[0] == "FlexiBLAS"
    assert kind_of(exporting("dgemm_")) == ("reference", "")  # dgemm and nothing of the others'
    assert kind_of(exporting("cblas_sdot")) == ("unknown", "")


def test_the_mapped_libraries_are_read_from_the_process_maps(tmp_path):
    from petsc4py import PETSc  # noqa: F401  (maps PETSc's BLAS into this process)

    found = system_blas()
    # tools/setup.sh makes OpenBLAS the system BLAS: PETSc's is found, and numpy's own copy is left out
    assert found and all(library.kind == "OpenBLAS" for library in found), found
    assert not any("site-packages" in library.path or ".libs/" in library.path for library in found)
    assert reference_blas_warning(found) is None
    maps = tmp_path / "maps"  # the format of /proc/self/maps: address perms offset dev inode path
    maps.write_text("7f0000000000-7f0000001000 r-xp 00000000 08:01 42 /nonexistent/libblas.so.3\n"
                    "7f0000002000-7f0000003000 r-xp 00000000 08:01 43 /nonexistent/libm.so.6\n"
                    "7f0000004000-7f0000005000 rw-p 00000000 00:00 0 \n")
    assert system_blas(maps) == [BlasLibrary("/nonexistent/libblas.so.3", "unknown")]  # not mapped: not opened
    assert system_blas(tmp_path / "no-such-file") == []  # no /proc: nothing found, nothing said


def test_the_reference_blas_gets_one_line_naming_it_and_what_to_install():
    warning = reference_blas_warning([BlasLibrary("/usr/lib/x86_64-linux-gnu/blas/libblas.so.3", "reference"),
                                      BlasLibrary("/usr/lib/libopenblas.so.0", "OpenBLAS")])
    assert warning is not None and "\n" not in warning
    assert "/usr/lib/x86_64-linux-gnu/blas/libblas.so.3" in warning and "libopenblas.so.0" not in warning
    assert "apt-get install libopenblas0-serial" in warning


def test_primordia_plugins_names_the_blas_and_a_run_warns_on_the_reference_one(tmp_path):
    """End to end: Debian's reference BLAS (libblas3, which python3-dolfinx pulls in) put first on the
    loader's path makes a run say so in one line; the OpenBLAS of tools/setup.sh does not."""
    listing = subprocess.run([sys.executable, "-m", "primordia.cli", "plugins"], capture_output=True, text=True)
    assert listing.returncode == 0, listing.stderr
    blas_lines = listing.stdout.split("linear algebra:\n", 1)[1].splitlines()
    assert any(line.split()[:2] == ["BLAS", "OpenBLAS"] for line in blas_lines), listing.stdout

    reference = Path("/usr/lib/x86_64-linux-gnu/blas/libblas.so.3")
    assert reference.exists(), "Debian's libblas3 (the reference BLAS) is expected beside OpenBLAS"
    run = [sys.executable, "-m", "primordia.cli", "run", str(EXAMPLES / "ex01a.toml"), "--set", "mesh.cells=[4,4]",
           "--set", "time.t_final=0.2", "--set", "output.pictures=false", "--set", "output.times=[0.2]",
           "--no-progress"]
    slow = {**os.environ, "LD_LIBRARY_PATH": f"{reference.parent}:{reference.parent.parent / 'lapack'}"}
    for env, out in ((slow, "slow"), (dict(os.environ), "fast")):
        done = subprocess.run([*run, "--out", str(tmp_path / out)], env=env, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        warnings = [line for line in done.stderr.splitlines() if line.startswith("primordia: warning:")]
        if out == "slow":
            assert len(warnings) == 1 and "reference implementation" in warnings[0], done.stderr
            assert str(reference.parent) in warnings[0] and "libopenblas0-serial" in warnings[0]
        else:
            assert warnings == [], done.stderr
