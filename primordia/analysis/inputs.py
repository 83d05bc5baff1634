"""What the stability analysis reads from a TOML file and ``--set`` overrides.

A run configuration (one with a ``[model]`` table) is composed into the
:class:`~primordia.model.Model` that ``primordia run`` would run
(:func:`read_model`), overrides applied the same way.  A file without ``[model]``
is a parameter set of the seed's model: its ``[parameters]`` table holds
overrides by seed name (Table 3.1 names), ``--set parameters.NAME=VALUE``
overrides on top (:func:`read_parameters`).  Every mistake is a one-line
:class:`~primordia.core.errors.ConfigError`.
"""

from __future__ import annotations

from collections.abc import Iterable

from primordia.core.config import apply_overrides, load_config, parse_assignment
from primordia.core.errors import ConfigError
from primordia.core.parameters import ParameterSet
from primordia.core.validation import number
from primordia.physics.seed_parameters import seed_parameters


def parameters_table(path) -> dict:
    """The ``[parameters]`` table of a TOML file (empty if it has none)."""
    table = load_config(path).get("parameters", {})
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: [parameters] must be a table")
    return dict(table)


def parse_parameter_assignment(text: str) -> tuple[str, float]:
    """``"parameters.NAME=VALUE"`` -> (NAME, VALUE as float)."""
    keys, value = parse_assignment(str(text))
    if keys[0] != "parameters" or len(keys) != 2:
        raise ConfigError(f"--set expects parameters.NAME=VALUE, got {text!r}")
    return keys[1], float(number(value, f"--set {'.'.join(keys)}: the value"))


def read_parameters(config=None, assignments: Iterable[str] = ()) -> ParameterSet:
    """Table 3.1 defaults, overridden by ``config``'s ``[parameters]``, then by ``--set`` assignments.

    Unknown names and values of the wrong sign are reported by the parameter
    declarations (one line, naming the parameter).
    """
    overrides = parameters_table(config) if config is not None else {}
    for text in assignments or ():
        name, value = parse_parameter_assignment(text)
        overrides[name] = value
    return seed_parameters(**overrides)


def read_model(config, assignments: Iterable[str] = ()):
    """The :class:`~primordia.model.Model` a run configuration composes (as ``primordia run`` does), or None.

    None for a file without a ``[model]`` table (a parameter set of the seed's model).
    ``assignments`` are ``section.key=value`` overrides, as for ``primordia run --set``.
    """
    table = load_config(config)
    if "model" not in table:
        return None
    from primordia.model import Model

    return Model.from_config(apply_overrides(table, list(assignments or ())))
