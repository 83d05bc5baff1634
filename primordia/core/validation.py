"""The one check of a number, a flag or a list of numbers read from a configuration.

Every option of the configuration that is a number goes through :func:`number`, so
the message a user reads is the same everywhere: one line naming the option, what
it must be, and what was given::

    number(options["shear_modulus"], "physics.poroelastic_growth.shear_modulus", above=0)
    -> ConfigError: physics.poroelastic_growth.shear_modulus must be a number > 0, got -1

Booleans are not numbers here (TOML's ``true`` is not 1), and neither are NaN or
infinities.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from primordia.core.errors import ConfigError, PluginError

__all__ = ["number", "flag", "numbers", "is_number", "is_integer", "field_name"]


def is_number(value: Any) -> bool:
    """A finite int or float (numpy's too), not a bool."""
    return isinstance(value, (int, float, np.number)) and not isinstance(value, bool) and math.isfinite(value)


def is_integer(value: Any) -> bool:
    """An int (numpy's too), not a bool."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def field_name(name: Any, owner: str, what: str = "a field") -> None:
    """A field's name (a species' too) is an identifier: it becomes a NetCDF variable, a file name, a TOML key
    and a name in expressions.  Else one :class:`~primordia.core.errors.PluginError` naming ``owner``, the
    plugin that declared it."""
    if not isinstance(name, str) or not name.isidentifier():
        raise PluginError(f"{owner}: {what} is named {name!r}, not a name (letters, digits and _, "
                          f"as a Python identifier)")


def number(value: Any, where: str, *, above: float | None = None, at_least: float | None = None,
           below: float | None = None, at_most: float | None = None, integer: bool = False,
           hint: str = "") -> float | int:
    """``value`` if it is a finite number within the bounds given, else one ConfigError naming ``where``.

    ``above``/``below`` are strict bounds, ``at_least``/``at_most`` inclusive ones; ``integer``
    asks for an int (a float such as 2.0 is refused: a count is written as a count).  ``hint``
    is appended to the message in parentheses (e.g. the unit, or what 0 means).
    """
    valid = is_integer(value) if integer else is_number(value)
    valid = valid and (above is None or value > above) and (at_least is None or value >= at_least) \
        and (below is None or value < below) and (at_most is None or value <= at_most)
    if not valid:
        raise ConfigError(f"{where} must be {describe(above, at_least, below, at_most, integer)}"
                          f"{f' ({hint})' if hint else ''}, got {value!r}")
    return value


def is_flag(value: Any) -> bool:
    """True or false (numpy's too), not the string "false", not 0."""
    return isinstance(value, (bool, np.bool_))


def flag(value: Any, where: str) -> bool:
    """``value`` as a bool if it is true or false (numpy's too; not the string "false", not 0), else one
    ConfigError."""
    if not is_flag(value):
        raise ConfigError(f"{where} must be true or false, got {value!r}")
    return bool(value)


def numbers(value: Any, where: str, *, length: int | tuple[int, ...] | None = None, **bounds) -> list:
    """A list of numbers (each checked as by :func:`number` with ``bounds``), of ``length`` entries if given."""
    lengths = (length,) if isinstance(length, int) else length
    what = "a list of numbers" if lengths is None else f"a list of {' or '.join(map(str, lengths))} numbers"
    if isinstance(value, np.ndarray) and value.ndim == 1:  # np.linspace(...) in Python: was refused
        value = value.tolist()
    if not isinstance(value, (list, tuple)) or (lengths is not None and len(value) not in lengths):
        raise ConfigError(f"{where} must be {what}, got {value!r}")
    return [number(entry, f"{where}[{index}]", **bounds) for index, entry in enumerate(value)]


def describe(above=None, at_least=None, below=None, at_most=None, integer=False) -> str:
    """'a number > 0', 'an integer >= 1', 'a number in [0, 1)', ... for the bounds given."""
    kind = "an integer" if integer else "a number"
    low = (f"({above:g}", f"> {above:g}") if above is not None else \
        (f"[{at_least:g}", f">= {at_least:g}") if at_least is not None else None
    high = (f"{below:g})", f"< {below:g}") if below is not None else \
        (f"{at_most:g}]", f"<= {at_most:g}") if at_most is not None else None
    if low and high:
        return f"{kind} in {low[0]}, {high[0]}"
    if low or high:
        return f"{kind} {(low or high)[1]}"
    return kind
