"""Parameter declarations of every seed module, gathered for the whole model.

Each module declares its own parameters (next to the equations that read them);
this file only lists which declarations make up the seed's full
poro-mechano-chemical model, so that the linear stability analysis and the
simulations read the very same names, defaults and checks (seed Table 3.1).
"""

from __future__ import annotations

from primordia.core.parameters import Parameter, ParameterSet

CHEMOTAXIS = (
    Parameter("m0", 2.0, "rest density of mesenchymal cells (seed eq. (2.5))"),
    Parameter("D_m", 0.01, "cell diffusivity"),
    Parameter("D_f", 0.1, "FGF diffusivity"),
    Parameter("D_b", 1.0, "BMP diffusivity (1 in the seed's scaling)", source="seed section 2 scaling"),
    Parameter("alpha", 4.0, "chemotactic sensitivity to FGF", constraint="nonnegative"),
    Parameter("gamma", 1.0, "saturation of the chemotactic flux alpha m exp(-gamma m)",
              constraint="nonnegative", source="seed section 2 scaling"),
)

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
    Parameter("tau", 60.0, "active stress magnitude (> 0 dilates, < 0 contracts)", constraint="any"),
    Parameter("zeta", 1.0, "saturation of the active stress tau m / (1 + zeta m^2)",
              constraint="nonnegative"),
)

MECHANOCHEMICAL = (
    Parameter("xi_f", 0.15, "FGF sink per unit volume change (seed eq. (2.2c))", constraint="any"),
)


def lame(params) -> tuple[float, float]:
    """Lame constants (mu, lambda) from Young modulus E and Poisson ratio nu."""
    E, nu = params["E"], params["nu"]
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def seed_parameters(**overrides: float) -> ParameterSet:
    """Table 3.1 of the seed (plus the scaling constants fixed to 1), with overrides."""
    from primordia.physics.kinetics.painter2018 import PARAMETERS as PAINTER2018

    return ParameterSet(
        CHEMOTAXIS + PAINTER2018 + POROELASTICITY + ACTIVE_STRESS + MECHANOCHEMICAL, overrides
    )
