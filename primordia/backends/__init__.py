"""Finite element backends, registered by name and imported only when used."""

from primordia.core.plugins import BackendEntry, hookimpl


@hookimpl
def primordia_backends():
    return [
        BackendEntry("fenicsx", "primordia.backends.fenicsx:FenicsxBackend",
                     "dolfinx 0.5 (Debian): MPI-parallel, FFCx-compiled UFL forms"),
        BackendEntry("skfem", "primordia.backends.skfem:SkfemBackend",
                     "scikit-fem: serial, UFL forms evaluated with numpy"),
    ]
