"""What an MPI launcher leaves in a process's environment, and an environment for a child without it.

A process whose parent had started MPI (a rank of an ``mpirun``, a pytest worker or a notebook that imported
dolfinx, a sweep's worker) inherits the launcher's variables (``OMPI_COMM_WORLD_SIZE``, ``OMPI_MCA_ess``,
``PMIX_SERVER_URI``...).  A child handed them believes it is a rank of that job: a sweep's serial run, or the
``mpirun`` of a benchmark, which exited 1 without a word after its run had completed.  A user's own Open MPI
settings (``OMPI_MCA_odls_base_sigkill_timeout``, a container's ``OMPI_MCA_btl_vader_single_copy_mechanism``) are
not the launcher's and stay.
"""

from __future__ import annotations

from collections.abc import Mapping

#: The prefixes of what a launcher or an MPI singleton sets (other ``OMPI_`` variables, except the ``OMPI_MCA_``
#: settings and root's permission, are its too: :func:`is_launchers`).
LAUNCHER_SET = ("PMIX_", "PMI_", "HYDRA_", "OMPI_MCA_ess", "OMPI_MCA_orte_", "OMPI_MCA_pmix", "OMPI_MCA_initial_wdir",
                "OMPI_MCA_shmem_RUNTIME_QUERY_hint")


def is_launchers(key: str) -> bool:
    """Whether the environment variable ``key`` is one a launcher set, not the user."""
    return key.startswith(LAUNCHER_SET) or (key.startswith("OMPI_") and not key.startswith("OMPI_MCA_")
                                            and not key.startswith("OMPI_ALLOW_RUN_AS_ROOT"))


def without_launcher(environment: Mapping[str, str]) -> dict[str, str]:
    """``environment`` without the variables of the MPI launcher or singleton above this process."""
    return {key: value for key, value in environment.items() if not is_launchers(key)}
