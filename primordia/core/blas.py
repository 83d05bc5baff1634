"""Which BLAS the process's linear algebra runs on, and a warning when it is the reference one.

PETSc's direct solvers (MUMPS above all) spend their factorisations in BLAS-3 on
dense fronts.  Debian links them to ``libblas.so.3``, which on a fresh system is
the netlib reference implementation: example 2a's growth tangent at 171 x 171
squares factorised in 14.8 s on it and in 5.0 s on OpenBLAS (README, "Backends").
``tools/setup.sh`` installs OpenBLAS; on a machine set up otherwise,
:func:`reference_blas_warning` says so in one line, with what to install.

The libraries are found among the shared objects mapped into this process
(Linux's ``/proc/self/maps``) and told apart by the symbols they export:
OpenBLAS ``openblas_get_config``, BLIS ``bli_info_get_version_str``, MKL
``MKL_Get_Version``, FlexiBLAS ``flexiblas_current_backend``; a library that
exports ``dgemm_`` and none of those is the reference BLAS.  numpy's and
scipy's own copies (in their wheels' ``.libs`` folders) are left out: they are
not what PETSc calls.  Elsewhere (macOS, a system without ``/proc``) nothing is
found and nothing is said.
"""

from __future__ import annotations

import ctypes
import os
import re
from dataclasses import dataclass
from pathlib import Path

#: The file names a BLAS may be mapped under.
_BLAS_NAME = re.compile(r"^lib(blas|openblas\w*|blis\w*|mkl_rt|flexiblas)[.-]")

#: Exported symbol -> implementation, checked in this order.
_SIGNATURES = (("openblas_get_config", "OpenBLAS"), ("bli_info_get_version_str", "BLIS"),
               ("MKL_Get_Version", "MKL"), ("flexiblas_current_backend", "FlexiBLAS"))

#: OpenBLAS's openblas_get_parallel(): how it was built.
_OPENBLAS_THREADING = {0: "serial", 1: "pthreads", 2: "OpenMP"}


@dataclass(frozen=True)
class BlasLibrary:
    path: str         # the mapped file, symbolic links resolved
    kind: str         # "OpenBLAS", "BLIS", "MKL", "FlexiBLAS", "reference" or "unknown"
    detail: str = ""  # e.g. OpenBLAS's version and threading

    def describe(self) -> str:
        return f"{self.kind}{f' ({self.detail})' if self.detail else ''}  {self.path}"


def system_blas(maps: str | Path = "/proc/self/maps") -> list[BlasLibrary]:
    """The BLAS libraries mapped into this process, outside numpy's and scipy's wheels."""
    try:
        lines = Path(maps).read_text().splitlines()
    except OSError:
        return []
    mapped = dict.fromkeys(fields[5] for fields in (line.split(maxsplit=5) for line in lines) if len(fields) == 6)
    return list(dict.fromkeys(classify(os.path.realpath(path)) for path in mapped
                              if _BLAS_NAME.match(os.path.basename(path))
                              and ".libs/" not in path and "site-packages" not in path))


def classify(path: str) -> BlasLibrary:
    """Which implementation the shared library at ``path``, already mapped, is, from the symbols it exports."""
    try:  # RTLD_NOLOAD: a handle on the mapped library, never a library loaded anew
        library = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
    except OSError:
        return BlasLibrary(path, "unknown")
    return BlasLibrary(path, *kind_of(lambda symbol: hasattr(library, symbol), library))


def kind_of(exports, library=None) -> tuple[str, str]:
    """(implementation, detail) of a library whose exported symbols ``exports(name)`` answers for."""
    for symbol, kind in _SIGNATURES:
        if exports(symbol):
            return kind, _openblas_detail(library) if kind == "OpenBLAS" and library is not None else ""
    return ("reference", "") if exports("dgemm_") else ("unknown", "")


def _openblas_detail(library) -> str:
    try:
        library.openblas_get_config.restype = ctypes.c_char_p
        config = library.openblas_get_config().decode(errors="replace").split()
        threading = _OPENBLAS_THREADING.get(library.openblas_get_parallel(), "")
    except (AttributeError, OSError):
        return ""
    version = config[1] if len(config) > 1 and config[0] == "OpenBLAS" else ""
    return ", ".join(part for part in (version, threading) if part)


def reference_blas_warning(libraries: list[BlasLibrary] | None = None) -> str | None:
    """One line when the linear algebra runs on the reference BLAS, else None."""
    libraries = system_blas() if libraries is None else libraries
    slow = [library.path for library in libraries if library.kind == "reference"]
    if not slow:
        return None
    return (f"PETSc's BLAS is the reference implementation ({', '.join(slow)}): direct solves (MUMPS) factorise "
            f"about 3x slower; on Debian install an optimised one: apt-get install libopenblas0-serial")
