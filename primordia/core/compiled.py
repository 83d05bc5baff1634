"""A few C loops for what numpy does one element at a time, compiled once per machine.

numpy 1.26 evaluates ``exp`` and ``expm1`` of float64 with a scalar call per element on AVX2
machines (its SIMD float64 ``exp`` needs AVX-512): 8.9 and 15 ns an element on the AMD EPYC
of the session of 2026-12-02, where an addition takes 0.4.  The exponentially fitted flux of
the cell density (:mod:`primordia.physics.edge_flux`) evaluates both at every edge of the mesh
at every step (88k edges at the seed's 171^2), and its sparse products allocate and pass over
the edges again: 3.0-3.6 ms of a 23 ms step of example 1a at 171^2.  glibc's vector math library (libmvec)
evaluates four at a time, within 4 ulps.

The source below is compiled by the system's C compiler (``$CC``, else ``cc``; the FEniCSx
backend's FFCx needs one too) into ``$PRIMORDIA_CACHE_DIR/compiled`` (default
``~/.cache/primordia/compiled``), keyed by a hash of the source and flags, written atomically, and
loaded with ctypes: no build step at install time, no new dependency.  On x86-64 ``target_clones`` makes an AVX2 and a
baseline copy of each loop, chosen when the library is loaded, so a cache shared by machines
with different processors stays valid.  Where libmvec or ``target_clones`` is missing (another
C library, another processor family) the loops are built without them; where no compiler
works, :func:`kernels` gives ``None`` and the callers keep their numpy code.

``PRIMORDIA_COMPILED=off`` keeps numpy everywhere; ``PRIMORDIA_COMPILED=on`` makes a failed
build an error instead of a silent fall-back.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from primordia.core.errors import PrimordiaError
from primordia.core.reductions import on_every_rank

SOURCE = r"""
#include <stddef.h>
#include <string.h>

#ifdef PRIMORDIA_VECTOR_MATH  /* glibc's libmvec: the first declarations carry the simd attribute */
#define SIMD __attribute__((__simd__("notinbranch")))
#else
#define SIMD
#endif
#ifdef PRIMORDIA_CLONES
#define CLONES __attribute__((target_clones("avx2", "default")))
#else
#define CLONES
#endif

extern double exp(double) SIMD;
extern double expm1(double) SIMD;

/* y = exp(x) */
CLONES void primordia_exp(ptrdiff_t n, const double *restrict x, double *restrict y)
{
  #pragma omp simd
  for (ptrdiff_t i = 0; i < n; ++i)
    y[i] = exp(x[i]);
}

/* mid_e = (c[low_e] + c[high_e]) / 2 */
CLONES void primordia_edge_midpoints(ptrdiff_t n, const double *restrict c, const long long *restrict low,
                                     const long long *restrict high, double *restrict mid)
{
  #pragma omp simd
  for (ptrdiff_t e = 0; e < n; ++e)
    mid[e] = 0.5 * c[low[e]] + 0.5 * c[high[e]];
}

/* Pe_e = chi_e (a[high_e] / D - a[low_e] / D), table[e] = B(Pe_e), table[n + e] = B(Pe_e) + Pe_e = B(-Pe_e),
   B(x) = x / expm1(x), B(0) = 1; the operations and their order are those of the numpy code. */
CLONES void primordia_edge_bernoulli(ptrdiff_t n, const double *restrict chi, const double *restrict a,
                                     const long long *restrict low, const long long *restrict high,
                                     double inverse_diffusivity, double *restrict table)
{
  #pragma omp simd
  for (ptrdiff_t e = 0; e < n; ++e) {
    double peclet = chi[e] * (a[high[e]] * inverse_diffusivity + a[low[e]] * -inverse_diffusivity);
    double ratio = peclet / expm1(peclet);
    double b = peclet == 0.0 ? 1.0 : ratio;
    table[e] = b;
    table[n + e] = b + peclet;
  }
}

/* The fitted operator's values from the table, edge by edge: the entry (low, high) of edge e is
   -w B(Pe_e), the entry (high, low) -w B(-Pe_e), and each end's diagonal entry gains w B(-Pe) of its
   own row (w: the entry's weight, w_ij D).  A position of -1 is an entry another process holds.
   The diagonal sums run in the order of the edges, which is that of the entry matrix's columns:
   the same numbers as its product.  A position p >= split is other[p - split]: on several processes the
   values go straight into PETSc's diagonal block (values) and off-diagonal block (other), whose positions
   primordia/core/petsc_library.py's BlockPlaces numbers; every diagonal entry is in the first.  One array:
   split past every position, other unused (NULL). */
void primordia_edge_entries(ptrdiff_t n, ptrdiff_t n_rows, const double *restrict table,
                            const double *restrict weights, const long long *restrict forward,
                            const long long *restrict backward, const long long *restrict low_diagonal,
                            const long long *restrict high_diagonal, const long long *restrict diagonals,
                            ptrdiff_t split, double *restrict values, double *restrict other)
{
  for (ptrdiff_t r = 0; r < n_rows; ++r)
    values[diagonals[r]] = 0.0;
  for (ptrdiff_t e = 0; e < n; ++e) {
    const double toward = table[e], away = table[n + e];
    const long long f = forward[e], b = backward[e];
    if (f >= 0) {
      *(f < split ? values + f : other + (f - split)) = -(weights[f] * toward);
      values[low_diagonal[e]] += weights[f] * away;
    }
    if (b >= 0) {
      *(b < split ? values + b : other + (b - split)) = -(weights[b] * away);
      values[high_diagonal[e]] += weights[b] * toward;
    }
  }
}

/* The P1 advection load of terms sharing one velocity r: for each term t,
   b_i += s_t |K| / ((d + 1)(d + 2)) grad c_K . (sum_j r_j + r_i) over the cells K at vertex i, the exact
   integral of s (r . grad c) w_i for P1 r, c and w on affine simplices (primordia/coupling/p1_advection.py).
   Triangles (gdim 2) or tetrahedra (gdim 3), nv = gdim + 1 vertices; gradients (cells, nv, gdim) of the
   hat functions; r_dofs (cells, nv, gdim): the vertices' positions in r[d]; out[t], c_dofs[t] (cells, nv):
   the positions in b and in c[t].  The velocity is read once a cell for every term; per term the operations
   are those of one term alone.  One loop per dimension D (nv = D + 1): with constant bounds the compiler
   unrolls the vertex and coordinate loops and keeps the cell's values in registers: 1.2 against 4.7 ms for
   example 1b's three species at 171^2 with the bounds as arguments. */
#define P1_ADVECTION(D)                                                                                    \
static void p1_advection_##D(ptrdiff_t n, ptrdiff_t terms, const double *restrict scales,                 \
                             const double *restrict gradients, const double *restrict weights,              \
                             const int *const *restrict out, const int *const *restrict c_dofs,             \
                             const int *restrict r_dofs, const double *const *restrict c,                   \
                             const double *const *restrict r, double *restrict b)                           \
{                                                                                                           \
  enum { NV = D + 1 };                                                                                      \
  for (ptrdiff_t e = 0; e < n; ++e) {                                                                       \
    double sum[D] = {0.0}, at[NV][D];                                                                       \
    const double *restrict grad = gradients + e * NV * D;                                                   \
    const int *restrict rd = r_dofs + e * NV * D;                                                           \
    for (int j = 0; j < NV; ++j)                                                                            \
      for (int d = 0; d < D; ++d) {                                                                         \
        at[j][d] = r[d][rd[j * D + d]];                                                                     \
        sum[d] += at[j][d];                                                                                 \
      }                                                                                                     \
    for (ptrdiff_t t = 0; t < terms; ++t) {                                                                 \
      const int *restrict cd = c_dofs[t] + e * NV, *restrict o = out[t] + e * NV;                           \
      const double *restrict ct = c[t];                                                                     \
      double g[D] = {0.0};                                                                                  \
      for (int j = 0; j < NV; ++j) {                                                                        \
        const double cj = ct[cd[j]];                                                                        \
        for (int d = 0; d < D; ++d)                                                                         \
          g[d] += cj * grad[j * D + d];                                                                     \
      }                                                                                                     \
      const double w = scales[t] * weights[e];                                                              \
      for (int i = 0; i < NV; ++i) {                                                                        \
        double dot = 0.0;                                                                                   \
        for (int d = 0; d < D; ++d)                                                                         \
          dot += g[d] * (sum[d] + at[i][d]);                                                                \
        b[o[i]] += w * dot;                                                                                 \
      }                                                                                                     \
    }                                                                                                       \
  }                                                                                                         \
}
P1_ADVECTION(2)
P1_ADVECTION(3)

void primordia_p1_advection(ptrdiff_t n, ptrdiff_t gdim, ptrdiff_t terms, const double *restrict scales,
                            const double *restrict gradients, const double *restrict weights,
                            const int *const *restrict out, const int *const *restrict c_dofs,
                            const int *restrict r_dofs, const double *const *restrict c,
                            const double *const *restrict r, double *restrict b)
{
  if (gdim == 2) p1_advection_2(n, terms, scales, gradients, weights, out, c_dofs, r_dofs, c, r, b);
  else p1_advection_3(n, terms, scales, gradients, weights, out, c_dofs, r_dofs, c, r, b);
}
"""

#: Both variants compile the same loops; the first vectorises exp and expm1 (glibc, x86-64).
_VARIANTS = (
    (["-DPRIMORDIA_VECTOR_MATH", "-DPRIMORDIA_CLONES"], ["-lmvec", "-lm"]),
    ([], ["-lm"]),
)
# -fno-trapping-math lets the select of B(0) = 1 be vectorised (0/0 raises no trap here);
# -ffp-contract=off keeps a * b + c two roundings, as numpy computes it, on every clone.
_FLAGS = ["-O3", "-fPIC", "-shared", "-fopenmp-simd", "-fno-math-errno", "-fno-trapping-math",
          "-ffp-contract=off"]

# every array goes by its address (a Python int): checked once by :func:`address`, then passed as is
_SIGNATURES = {
    "primordia_exp": [ctypes.c_ssize_t, ctypes.c_void_p, ctypes.c_void_p],
    "primordia_edge_midpoints": [ctypes.c_ssize_t, *[ctypes.c_void_p] * 4],
    "primordia_edge_bernoulli": [ctypes.c_ssize_t, *[ctypes.c_void_p] * 4, ctypes.c_double, ctypes.c_void_p],
    "primordia_edge_entries": [ctypes.c_ssize_t, ctypes.c_ssize_t, *[ctypes.c_void_p] * 7, ctypes.c_ssize_t,
                               ctypes.c_void_p, ctypes.c_void_p],
    "primordia_p1_advection": [ctypes.c_ssize_t, ctypes.c_ssize_t, ctypes.c_ssize_t, *[ctypes.c_void_p] * 9],
}

_loaded: dict = {}  # "library" -> the CDLL or None, once decided in this process


def mode() -> str:
    """``auto`` (the default), ``on`` or ``off``, from ``PRIMORDIA_COMPILED``."""
    value = os.environ.get("PRIMORDIA_COMPILED", "auto").strip().lower() or "auto"
    if value not in ("auto", "on", "off"):
        raise PrimordiaError(f"PRIMORDIA_COMPILED must be auto, on or off, got {value!r}")
    return value


def cache_directory() -> Path:
    root = os.environ.get("PRIMORDIA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "primordia")
    return Path(root) / "compiled"


def kernels(comm=None):
    """The compiled loops (a ctypes library with the functions of :data:`SOURCE`), or ``None``.

    Collective over ``comm`` when one is given: every rank gets the library only if every rank
    has it, so that all ranks compute with the same code (a rank that had it then drops it for
    every later caller, :func:`vector_exp` too).  Ranks that build at once write
    their own temporary files; the last rename wins, with the same bytes.
    """
    if "library" not in _loaded:
        _loaded["library"] = None if mode() == "off" else _build_or_load()
    library = _loaded["library"]
    if comm is not None and comm.size > 1 and not on_every_rank(comm, library is not None):
        if library is not None:  # this process keeps numpy's too, in every caller
            _loaded["library"], _loaded["reason"] = None, "another process could not build them"
        return None
    return library


def _build_or_load():
    compiler = os.environ.get("CC") or "cc"
    if shutil.which(compiler.split()[0]) is None:
        return _failed(f"no C compiler ({compiler!r} is not on PATH)")
    last_error = "no variant built"
    for variant, (defines, libraries) in enumerate(_VARIANTS):
        command = [*compiler.split(), *_FLAGS, *defines]
        key = hashlib.sha256("\0".join([SOURCE, *command, *libraries, platform.machine()]).encode()).hexdigest()[:16]
        target = cache_directory() / f"kernels-{key}.so"
        try:
            built = target if target.is_file() else _compile(command, libraries, target)
            library = _load(built)
            if built == target:
                _keep_recent(target)
            else:  # built for this process alone: mapped now, so nothing needs to stay on disk
                _loaded["path"] = f"{built.name}, built for this process (the cache {target.parent} cannot be written)"
                shutil.rmtree(built.parent, ignore_errors=True)
            _loaded["variant"] = variant
            return library
        except (OSError, AttributeError, subprocess.SubprocessError) as error:  # AttributeError: a function missing
            last_error = str(error).strip().splitlines()[-1] if str(error).strip() else type(error).__name__
    return _failed(last_error)


#: Builds kept in the cache: the one in use and the most recently used others (another checkout or
#: version sharing the cache, a cluster's older runs); older ones, and temporary files that a build
#: killed halfway left behind for an hour, are removed whenever a library is loaded from the cache.
KEPT_BUILDS = 4
_STALE_SECONDS = 3600


def _keep_recent(target: Path) -> None:
    """Mark ``target`` as just used and remove all but the :data:`KEPT_BUILDS` most recently used builds.

    Best effort: a file another process removes or still writes is left alone.  A process that has
    already loaded a removed library keeps it mapped; one about to load it builds it again.
    """
    now = time.time()
    try:
        os.utime(target)
        builds = sorted(target.parent.glob("kernels-*.so"), key=lambda path: path.stat().st_mtime, reverse=True)
        stale = [path for path in target.parent.glob(".kernels-*.so") if now - path.stat().st_mtime > _STALE_SECONDS]
    except OSError:
        return
    for path in [path for path in builds if path != target][KEPT_BUILDS - 1:] + stale:
        try:
            path.unlink()
        except OSError:
            pass


def _compile(command: list[str], libraries: list[str], target: Path) -> Path:
    """Compile :data:`SOURCE` into ``target``, atomically (a temporary file renamed over it); the path
    written (in a temporary directory of its own if the cache cannot be written: the caller removes it
    once the library is loaded)."""
    def temporary_next_to(path: Path):
        return tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.stem}.", suffix=".so", delete=False)

    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        output = temporary_next_to(target)
    except OSError:  # a cache that cannot be written (a read-only home): build for this process only
        target = Path(tempfile.mkdtemp(prefix="primordia-compiled-")) / target.name
        output = temporary_next_to(target)
    output.close()
    with tempfile.TemporaryDirectory(prefix="primordia-build-") as build:
        source = Path(build) / "kernels.c"
        source.write_text(SOURCE)
        try:
            result = subprocess.run([*command, str(source), "-o", output.name, *libraries],
                                    capture_output=True, text=True, timeout=120)
            if result.returncode != 0:
                raise subprocess.SubprocessError(result.stderr or f"the compiler exited with {result.returncode}")
            os.chmod(output.name, 0o755)  # a library's mode: the temporary file was the owner's alone (0600)
            os.replace(output.name, target)
        finally:
            if os.path.exists(output.name):
                os.unlink(output.name)
    return target


def _load(target: Path):
    library = ctypes.CDLL(str(target))
    for name, arguments in _SIGNATURES.items():
        function = getattr(library, name)
        function.argtypes, function.restype = arguments, None
    _loaded["path"] = target
    return library


def _failed(reason: str):
    _loaded["reason"] = reason
    if mode() == "on":
        raise PrimordiaError(f"PRIMORDIA_COMPILED=on but the compiled loops could not be built: {reason}")
    return None


def status() -> str:
    """One line saying what the compiled loops are and where they come from (for ``primordia plugins``)."""
    library = kernels()
    if library is not None:
        return f"compiled loops: {_loaded['path']}"
    if mode() == "off":
        return "compiled loops: off (PRIMORDIA_COMPILED=off), numpy everywhere"
    return f"compiled loops: unavailable ({_loaded.get('reason', 'unknown')}), numpy everywhere"


def address(array: np.ndarray, dtype=np.float64) -> int:
    """The address of a contiguous array of ``dtype`` (float64, or int64 / int32 for indices), checked; the
    caller keeps the array alive while the address is used."""
    if array.dtype != dtype or not array.flags.c_contiguous:
        raise ValueError(f"compiled loops need contiguous {np.dtype(dtype).name} arrays, got {array.dtype}")
    return array.ctypes.data


def vector_exp(x):
    """exp(x) for a float64 array with the compiled loop when there is one (within 4 ulps of numpy's,
    3 against 9 ns an element here); numpy's otherwise, and for anything but a float64 array."""
    library = kernels()
    array = np.asarray(x)
    if library is None or array.dtype != np.float64 or array.ndim == 0:
        return np.exp(x)
    array = np.ascontiguousarray(array)
    result = np.empty_like(array)
    library.primordia_exp(array.size, address(array), address(result))
    return result


def numpy_ops():
    """:data:`primordia.core.ops.NUMPY` with the compiled exp (:func:`vector_exp`): for formulas evaluated
    at every step on large arrays (the chemotactic sensitivity at the edges)."""
    from dataclasses import replace

    from primordia.core.ops import NUMPY

    return replace(NUMPY, exp=vector_exp)
