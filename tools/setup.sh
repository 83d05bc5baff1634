#!/usr/bin/env bash
# Idempotent set-up for a fresh Debian bookworm machine (run as root or with sudo):
#   1. Debian packages: dolfinx 0.5.2 + PETSc 3.18 (MUMPS, hypre) + OpenMPI, venv, MPI-enabled h5py,
#      and OpenBLAS (single-threaded) as the system BLAS/LAPACK: without it PETSc, MUMPS and hypre run
#      on Debian's reference BLAS, and MUMPS factorises example 2a's tangent at 171 x 171 in 14.8 s
#      instead of 5.0 (README, "Backends"). Debian's reference BLAS (libblas3, which dolfinx's PETSc
#      depends on) stays installed beside it, unselected: tests/unit/test_blas.py runs on it once to
#      check the warning `primordia run` prints there; gcc and libc6-dev (FFCx compiles with them, and so
#      do primordia's few C loops, primordia/core/compiled.py, with glibc's vector math library);
#   2. .venv made from /usr/bin/python3 with --system-site-packages (sees Debian's dolfinx/petsc4py);
#   3. primordia (editable) and the example plugins, with numpy pinned below 2
#      (Debian's petsc4py/dolfinx are built against numpy 1.x).
# Every step is skipped when already done.
set -euo pipefail
cd "$(dirname "$0")/.."

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

missing=()
for pkg in python3-dolfinx python3-venv python3-h5py-mpi libopenblas0-serial libblas3 gcc libc6-dev; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$pkg")
  fi
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv (system site packages)"
  /usr/bin/python3 -m venv --system-site-packages .venv
fi

stamp=.venv/.primordia-installed
digest=$(cat pyproject.toml constraints.txt plugins/*/pyproject.toml | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$digest" ]; then
  echo "setup: installing primordia and the example plugins into .venv"
  plugin_args=()
  for plugin in plugins/*/; do plugin_args+=(-e "$plugin"); done
  .venv/bin/pip install -q --disable-pip-version-check -c constraints.txt -e ".[test]" "${plugin_args[@]}"
  echo "$digest" > "$stamp"
fi

# Both backends must import here; a missing one is an error, not a skip.
.venv/bin/python - <<'PY'
import importlib, sys
for name in ("primordia.backends.fenicsx", "primordia.backends.skfem"):
    try:
        importlib.import_module(name)
    except Exception as exc:
        sys.exit(f"setup: backend module {name} does not import: {exc}")
PY
