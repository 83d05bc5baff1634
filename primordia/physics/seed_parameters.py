"""Parameter declarations of every seed module, gathered for the whole model.

Each module declares its own parameters (next to the equations that read them:
the species' rest density, diffusivities and sensitivity with the ``painter2018``
kinetics that declares the species); this file holds the declarations of the
mechanical modules and lists which declarations make up the seed's full
poro-mechano-chemical model, so that the linear stability analysis and the
simulations read the very same names, defaults and checks (seed Table 3.1).
"""

from __future__ import annotations

from primordia.core.parameters import Parameter, ParameterSet

POROELASTICITY = (
    Parameter("E", 3.0e4, "Young modulus of the skeleton"),
    Parameter("nu", 0.4, "Poisson ratio of the skeleton", constraint="poisson"),
    Parameter("C_0", 1.0e-3, "constrained specific storage", constraint="nonnegative"),
    Parameter("kappa", 1.0e-4, "hydraulic conductivity"),
    Parameter("alpha_BW", 0.1, "Biot-Willis coefficient", constraint="nonnegative"),
    Parameter("eta", 0.1, "fluid viscosity"),
    Parameter("rho", 1.0, "solid density", constraint="nonnegative"),
)

ACTIVE_STRESS = (
    Parameter("tau", 60.0, "active stress magnitude (> 0 a tension: the tissue contracts; < 0 dilates)",
              constraint="any"),
    Parameter("zeta", 1.0, "saturation of the active stress tau m / (1 + zeta m^2)",
              constraint="nonnegative"),
)

MECHANOCHEMICAL = (
    Parameter("xi_f", 0.15, "FGF sink per unit volume change (seed eq. (2.3c))", constraint="any"),
)


def lame(params) -> tuple[float, float]:
    """Lame constants (mu, lambda) from Young modulus E and Poisson ratio nu."""
    E, nu = params["E"], params["nu"]
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def seed_parameters(**overrides: float) -> ParameterSet:
    """Table 3.1 of the seed (plus the scaling constants fixed to 1), with overrides."""
    from primordia.physics.kinetics.painter2018 import PARAMETERS as PAINTER2018

    return ParameterSet(
        PAINTER2018 + POROELASTICITY + ACTIVE_STRESS + MECHANOCHEMICAL, overrides
    )
