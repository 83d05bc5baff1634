"""The MPI launcher's variables are dropped from a child's environment; the user's own Open MPI settings stay."""

from __future__ import annotations

from primordia.core.launcher import without_launcher

INHERITED = {"OMPI_COMM_WORLD_SIZE": "2", "OMPI_COMM_WORLD_RANK": "1", "OMPI_MCA_ess": "singleton",
             "OMPI_MCA_orte_hnp_uri": "x", "PMIX_SERVER_URI21": "y", "PMI_RANK": "1", "HYDRA_CONTROL_FD": "3"}
USERS = {"OMPI_MCA_btl_vader_single_copy_mechanism": "none", "OMPI_MCA_odls_base_sigkill_timeout": "5",
         "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1", "PATH": "/usr/bin"}


def test_a_child_keeps_the_users_settings_and_not_the_launchers():
    assert without_launcher({**INHERITED, **USERS}) == USERS


def test_a_sweeps_run_is_not_a_rank_but_keeps_the_users_open_mpi_settings(monkeypatch):
    from primordia.sweep import WORKER_STARTING, _run_environment

    for key, value in {**INHERITED, **USERS, WORKER_STARTING: "1"}.items():
        monkeypatch.setenv(key, value)
    environment = _run_environment()
    assert not set(INHERITED) & set(environment) and WORKER_STARTING not in environment
    assert {key: environment[key] for key in USERS} == USERS
