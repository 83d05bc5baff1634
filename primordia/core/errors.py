"""Errors that reach the user as one line.

Every mistake a user can make (an unknown parameter, a wrong sign, a missing
file, an impossible mesh, an unknown backend or plugin) raises a subclass of
:class:`PrimordiaError`.  The CLI prints ``primordia: error: <message>`` and
exits with status 2; anything else is a bug and keeps its traceback.
"""


class PrimordiaError(Exception):
    """A problem with the user's input, stated in one line."""


class ConfigError(PrimordiaError):
    """A configuration value, section or parameter is unknown or invalid."""


class MeshError(PrimordiaError):
    """A mesh cannot be built or read."""


class PluginError(PrimordiaError):
    """A named backend, physics, kinetics, scheme or output is not registered."""


class SolverError(PrimordiaError):
    """A solve failed (diverged linear or nonlinear solver, NaN in a field)."""
