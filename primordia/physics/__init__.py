"""Physics modules: one balance law or constitutive piece per file (built-in plugin)."""

from primordia.core.plugins import hookimpl


@hookimpl
def primordia_physics():
    from primordia.physics.chemotaxis import Chemotaxis

    return [Chemotaxis]
