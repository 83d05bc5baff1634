"""Reaction kinetics plugins shipped with primordia (registered like third-party ones)."""

from primordia.core.plugins import hookimpl


@hookimpl
def primordia_kinetics():
    from primordia.physics.kinetics.painter2018 import Painter2018

    return [Painter2018]
