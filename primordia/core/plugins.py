"""The plugin manager: built-ins and entry points, loaded once.

:func:`get_plugin_manager` registers the built-in plugins of
:data:`DEFAULT_PLUGINS` and then every entry point of the group ``primordia``.
A plugin that fails to import or register produces one warning naming it and
is skipped; the rest keeps working.  :func:`registry` turns the contribute
hooks into name -> class tables and reports where each piece came from.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import sys
import warnings
from dataclasses import dataclass, field

import pluggy

from primordia.core import hookspecs
from primordia.core.errors import PluginError

hookimpl = pluggy.HookimplMarker("primordia")

#: Built-in plugins, registered through the same hooks a third party uses.
DEFAULT_PLUGINS = (
    "primordia.backends",
    "primordia.physics",
    "primordia.physics.kinetics",
    "primordia.physics.boundary_conditions",
    "primordia.coupling.splitting",
    "primordia.core.outputs",
    "primordia.core.selection",
)

#: The contribute hooks and the name of the kind of piece each yields.
KINDS = {
    "physics": "primordia_physics",
    "kinetics": "primordia_kinetics",
    "growth_laws": "primordia_growth_laws",
    "boundary_conditions": "primordia_boundary_conditions",
    "backends": "primordia_backends",
    "splitting_schemes": "primordia_splitting_schemes",
    "outputs": "primordia_outputs",
}

_manager: pluggy.PluginManager | None = None


@dataclass(frozen=True)
class BackendEntry:
    """A backend known by name, imported only when used ("module:Class")."""

    name: str
    target: str
    description: str = ""

    def load(self):
        module_name, _, class_name = self.target.partition(":")
        module = importlib.import_module(module_name)
        return getattr(module, class_name)

    def availability(self) -> str | None:
        """None when the backend imports, else the reason it does not."""
        try:
            self.load()
        except Exception as exc:  # noqa: BLE001 - any import failure means "unavailable"
            return f"{type(exc).__name__}: {exc}".splitlines()[0]
        return None


@dataclass
class LoadReport:
    """What was registered from where, and what failed to load."""

    sources: dict[str, str] = field(default_factory=dict)  # plugin name -> origin
    failures: list[str] = field(default_factory=list)


def _warn(message: str) -> None:
    print(f"primordia: warning: {message}", file=sys.stderr)


def get_plugin_manager(reload: bool = False) -> pluggy.PluginManager:
    """The process-wide plugin manager (built-ins + entry points)."""
    global _manager
    if _manager is not None and not reload:
        return _manager
    pm = pluggy.PluginManager("primordia")
    pm.add_hookspecs(hookspecs)
    pm.load_report = LoadReport()
    for module_name in DEFAULT_PLUGINS:
        pm.register(importlib.import_module(module_name), name=module_name)
        pm.load_report.sources[module_name] = "primordia (built-in)"
    for entry_point in importlib.metadata.entry_points(group="primordia"):
        origin = _distribution_label(entry_point)
        try:
            plugin = entry_point.load()
            _check_contract(plugin)
            pm.register(plugin, name=entry_point.name)
        except Exception as exc:  # noqa: BLE001 - a broken plugin must not break the rest
            reason = f"{type(exc).__name__}: {exc}".splitlines()[0]
            message = f"plugin '{entry_point.name}' ({origin}) failed to load and is skipped: {reason}"
            pm.load_report.failures.append(message)
            _warn(message)
            continue
        pm.load_report.sources[entry_point.name] = origin
    _manager = pm
    return pm


def _check_contract(plugin) -> None:
    """Refuse a plugin that states it was written for another major version of the hook contract."""
    stated = getattr(plugin, "PRIMORDIA_CONTRACT", None)
    major = hookspecs.CONTRACT_VERSION[0]
    if stated is not None and stated != major:
        raise PluginError(f"it was written for version {stated} of primordia's hook contract, this is {major}")


def _distribution_label(entry_point) -> str:
    dist = getattr(entry_point, "dist", None)
    if dist is None:
        return "entry point"
    return f"{dist.metadata['Name']} {dist.version}"


def registry(kind: str, pm: pluggy.PluginManager | None = None) -> dict[str, tuple[object, str]]:
    """name -> (piece, origin) for one kind of contribution (see :data:`KINDS`)."""
    pm = pm or get_plugin_manager()
    hook_name = KINDS[kind]
    table: dict[str, tuple[object, str]] = {}
    for impl in getattr(pm.hook, hook_name).get_hookimpls():
        origin = pm.load_report.sources.get(impl.plugin_name, impl.plugin_name)
        for piece in impl.function() or ():
            name = piece.name
            if name in table:
                _warn(f"{kind} '{name}' from {origin} replaces the one from {table[name][1]}")
            table[name] = (piece, origin)
    return table


def lookup(kind: str, name: str, pm: pluggy.PluginManager | None = None):
    """The registered piece of ``kind`` called ``name``; an unknown name names the known ones."""
    table = registry(kind, pm)
    try:
        return table[name][0]
    except KeyError:
        known = ", ".join(sorted(table)) or "none"
        label = kind.replace("_", " ") if kind in ("physics", "kinetics") else kind.replace("_", " ")[:-1]
        raise PluginError(f"unknown {label} '{name}' (registered: {known})") from None
