"""One line naming the machine a benchmark ran on; every benchmark prints it first.

Figures from different machines do not compare, and a virtual machine's name can change under
the same project between sessions: on 2026-12-02 the (u, p) LU solve of example 1b at 171 x 171
squares took 45-54 ms a step on one session's machine and 18-21 ms on the next one's (AMD EPYC,
family 25, with AVX-512), which moved every "step against its solves" ratio.

    .venv/bin/python benchmarks/machine.py
"""

from __future__ import annotations

import os
import platform
from pathlib import Path

#: Vector extensions worth naming (the compilers' and BLAS's choice of kernels follows them).
VECTOR_FLAGS = ("avx512f", "avx2", "avx", "sse4_2", "neon", "asimd")


def _cpuinfo() -> dict[str, str]:
    """The first processor's fields of /proc/cpuinfo (empty where there is none)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return {}
    fields = {}
    for line in text.split("\n\n")[0].splitlines():
        key, _, value = line.partition(":")
        fields[key.strip()] = value.strip()
    return fields


def _caches() -> str:
    """The first CPU's cache sizes by level (L2, L3), from sysfs."""
    sizes = {}
    for index in sorted(Path("/sys/devices/system/cpu/cpu0/cache").glob("index*")):
        try:
            level, kind = (index / "level").read_text().strip(), (index / "type").read_text().strip()
            size = (index / "size").read_text().strip()
        except OSError:
            continue
        if kind != "Instruction" and level in ("2", "3"):
            sizes[f"L{level}"] = size
    return ", ".join(f"{level} {size}" for level, size in sorted(sizes.items()))


def describe() -> str:
    """E.g. ``machine: AMD EPYC (family 25 model 17), 2 CPUs, avx512f, L2 1024K, L3 32768K; PETSc 3.18.5``."""
    info = _cpuinfo()
    name = info.get("model name") or platform.processor() or platform.machine()
    if "cpu family" in info:
        name += f" (family {info['cpu family']} model {info.get('model', '?')})"
    flags = set(info.get("flags", info.get("Features", "")).split())
    vector = next((flag for flag in VECTOR_FLAGS if flag in flags), None)
    parts = [part for part in (name, f"{os.cpu_count()} CPUs", vector, _caches()) if part]
    try:
        from petsc4py import PETSc

        petsc = "PETSc " + ".".join(str(n) for n in PETSc.Sys.getVersion())
    except ImportError:
        petsc = "no petsc4py"
    return f"machine: {', '.join(parts)}; {petsc}"


def launch_environment() -> dict[str, str]:
    """The environment of an ``mpirun`` a benchmark starts: this process's, as root may use it, without the
    variables of an MPI launcher or singleton above it (:mod:`primordia.core.launcher`)."""
    from primordia.core.launcher import without_launcher

    return {**without_launcher(os.environ), "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}


#: The seed's examples in examples/ (``ex*.toml``): what the scripts' ``--share`` and ``--full`` may name.
EXAMPLES = sorted(path.stem for path in (Path(__file__).resolve().parent.parent / "examples").glob("ex*.toml"))


def require_at_least(parser, *bounds: tuple[str, int | None, int]) -> None:
    """``parser.error`` (one line, exit 2) for the first (option, value, least) whose value is below its least (a
    value None: the option was not given)."""
    for option, value, least in bounds:
        if value is not None and value < least:
            parser.error(f"{option} must be at least {least}, got {value}")


def last_words(stderr: str) -> str:
    """The last line a failed child wrote, before mpirun's own report (which opens with a line of dashes)."""
    lines = stderr.strip().splitlines()
    lines = lines[:next((k for k, line in enumerate(lines) if set(line) == {"-"}), len(lines))]
    return (lines or ["no output"])[-1]


if __name__ == "__main__":
    print(describe())
