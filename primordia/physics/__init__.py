"""Physics modules: one balance law or constitutive piece per file (built-in plugin)."""

from primordia.core.plugins import hookimpl


@hookimpl
def primordia_physics():
    from primordia.physics.active_stress import ActiveStress
    from primordia.physics.chemotaxis import Chemotaxis
    from primordia.physics.mechanochemical import MechanoChemical
    from primordia.physics.poroelastic_linear import LinearPoroelasticity

    return [Chemotaxis, LinearPoroelasticity, ActiveStress, MechanoChemical]
