"""primordia's own choosers for the ``firstresult`` hooks (run last).

A plugin that implements the same hooks without ``trylast`` is asked first and
can override these choices.
"""

from __future__ import annotations

from primordia.core.errors import PluginError, warn
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
    kept, ignored = _options_for(name, options, schemes)
    scheme = schemes[name](physics, **kept)  # refuses a bad option in one line, before any warning is printed
    for key, other in ignored.items():
        warn(f"coupling.{key} is an option of scheme '{other}' and is ignored by '{name}'")
    return scheme


def _options_for(name: str, options: dict, schemes: dict) -> tuple[dict, dict]:
    """The [coupling] options of scheme ``name``, and those left out: {key: the scheme whose option it is}.

    An option that belongs to another registered scheme (e.g. ``tolerance`` of
    ``fixed_point`` in a config whose scheme was switched with ``--set``) is left
    out, with a warning once the scheme is made; one that no scheme knows reaches
    the scheme, which refuses it in one line.
    """
    own = set(getattr(schemes[name], "options", {}))
    others = {key: other for other, cls in schemes.items() if other != name
              for key in getattr(cls, "options", {}) if key not in own}
    kept = {key: value for key, value in options.items() if key not in others}
    return kept, {key: others[key] for key in options if key in others}
