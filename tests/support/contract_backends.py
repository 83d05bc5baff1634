"""Backends as a plugin written for an older hook contract would provide them."""

from primordia.backends.skfem import SkfemBackend
from primordia.core.backend import Backend
from primordia.core.plugins import BackendEntry, hookimpl


class Contract12Skfem(SkfemBackend):
    """scikit-fem without the DOF-layout methods contract 1.3 added (the base class's defaults)."""

    name = "skfem_contract_1_2"
    shares_dofs = Backend.shares_dofs
    owned_dof_coordinates = Backend.owned_dof_coordinates


class Contract12Plugin:
    @hookimpl
    def primordia_backends(self):
        return [BackendEntry(Contract12Skfem.name, f"{__name__}:Contract12Skfem", "scikit-fem as of contract 1.2")]
