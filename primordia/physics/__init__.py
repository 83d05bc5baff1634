"""Physics modules: one balance law or constitutive piece per file (built-in plugin)."""

from primordia.core.plugins import hookimpl


@hookimpl
def primordia_physics():
    from primordia.physics.active_stress import ActiveStress
    from primordia.physics.chemotaxis import Chemotaxis
    from primordia.physics.mechanochemical import MechanoChemical
    from primordia.physics.poroelastic_growth import PoroelasticGrowth
    from primordia.physics.poroelastic_linear import LinearPoroelasticity

    return [Chemotaxis, LinearPoroelasticity, PoroelasticGrowth, ActiveStress, MechanoChemical]


@hookimpl
def primordia_growth_laws():
    from primordia.physics.growth_laws import Seed2D, Seed3D

    return [Seed2D, Seed3D]
