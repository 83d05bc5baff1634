"""primordia's own choosers for the ``firstresult`` hooks (run last).

A plugin that implements the same hooks without ``trylast`` is asked first and
can override these choices.
"""

from __future__ import annotations

from primordia.core.errors import PluginError
from primordia.core.plugins import hookimpl


@hookimpl(trylast=True)
def primordia_select_backend(name, entries, comm):
    if name not in entries:
        known = ", ".join(sorted(entries)) or "none"
        raise PluginError(f"unknown backend '{name}' (registered: {known})")
    entry = entries[name]
    reason = entry.availability()
    if reason is not None:
        raise PluginError(f"backend '{name}' is registered but cannot be imported ({reason})")
    return entry.load()(comm)


@hookimpl(trylast=True)
def primordia_select_splitting_scheme(name, options, schemes, physics):
    if name not in schemes:
        known = ", ".join(sorted(schemes)) or "none"
        raise PluginError(f"unknown splitting scheme '{name}' (registered: {known})")
    return schemes[name](physics, **options)
