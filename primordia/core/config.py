"""Run configurations: TOML files, ``--set`` overrides, and their validation.

A configuration is a nested mapping with these tables (all optional but
``[mesh]`` and ``[time]``)::

    [model]        physics = ["chemotaxis"], backend = "fenicsx", name, description
    [kinetics]     name = "painter2018", plus the kinetics' own options
    [growth_law]   name = "seed2d" | "seed3d", plus the law's own options (directions)
    [physics.NAME] options of one physics module
    [parameters]   model constants by their seed names (Table 3.1)
    [mesh]         type = "rectangle" | "box" | "file", ...
    [time]         dt, t_final, t_start, adaptive, dt_min
    [output]       times, series_every, and the options the outputs declare (snapshot_fields: pictures)
                   (built in: pictures, displacement_scale)
    [checkpoint]   every_steps, every_minutes
    [coupling]     scheme = "sequential" | "strang" | "fixed_point" | "monolithic", and its options
    [solver.PREFIX] PETSc options of one subproblem (e.g. [solver.chemotaxis_m])

Every unknown table or key is reported by its dotted name; values are checked
where they are used (parameters by their declarations, mesh by the mesh
builder, options by their module).
"""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from primordia.core.atomic_files import reason_of
from primordia.core.errors import ConfigError, warn
from primordia.core.validation import is_flag, is_integer, is_number

SECTIONS = {
    "model": {"physics", "backend", "name", "description"},
    "kinetics": None,  # open: the kinetics validates its own options
    "growth_law": None,  # open: the growth law validates its own options
    "physics": None,  # open: one sub-table per physics module
    "parameters": None,  # open: validated against the declared parameters
    "mesh": None,  # open: validated by primordia.core.meshes.mesh_from_config
    "time": {"dt", "t_final", "t_start", "adaptive", "dt_min"},
    "output": None,  # open: the schedule plus the options the registered outputs declare (primordia.model)
    "checkpoint": {"every_steps", "every_minutes"},
    "coupling": None,  # open: scheme plus the scheme's own options
    "solver": None,  # open: PETSc options by prefix
}
#: The key :func:`load_config` adds: the folder of the file, which relative paths (a mesh file) start from.
BASE_DIR = "_base_dir"
#: Sections whose entries are themselves tables (one per physics module, one per solver prefix).
TABLES_OF_TABLES = {"physics": "[physics.NAME]", "solver": "[solver.PREFIX]"}
#: A configuration is a few kilobytes; anything far larger is not one (and is not read into memory).
MAX_CONFIG_BYTES = 1 << 20


def load_config(path: str | Path) -> dict:
    """Read a TOML configuration; a missing, unreadable or malformed file is one clear error.

    Only a regular file is opened (a folder, a FIFO or a device such as /dev/zero
    would fail, block or never end), and it must be UTF-8 text.
    """
    path = Path(path)
    if not path.exists():
        raise ConfigError(f"config file not found: {path}")
    if path.is_dir():
        raise ConfigError(f"config file {path} is a folder, not a TOML file")
    if not path.is_file():
        raise ConfigError(f"config file {path} is not a regular file (a device, a pipe or a socket)")
    try:
        with path.open("rb") as stream:
            data = stream.read(MAX_CONFIG_BYTES + 1)
    except OSError as error:
        raise ConfigError(f"cannot read config file {path}: {reason_of(error)}") from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(f"config file {path} is larger than {MAX_CONFIG_BYTES >> 20} MB: not a configuration")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ConfigError(f"config file {path} is not UTF-8 text (byte {error.start}: "
                          f"{data[error.start:error.start + 1]!r}); is it a binary file?") from None
    try:
        config = tomllib.loads(text.removeprefix("\ufeff"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML ({exc})") from None
    for section in config:  # _base_dir is primordia's own key: a file's would move its relative paths
        if section.startswith("_"):
            raise ConfigError(f"unknown config section [{section}] in {path} (known: {', '.join(SECTIONS)})")
    config[BASE_DIR] = str(path.resolve().parent)
    return config


def parse_assignment(text: str) -> tuple[list[str], Any]:
    """``"section.key=value"`` -> (["section", "key"], value), value parsed as TOML.

    The key is a TOML dotted key, so a part may be quoted (``solver."my.prefix".ksp_rtol=1e-3``);
    a key TOML does not read (a non-ASCII bare word) is split at its dots.
    """
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"--set expects section.key=value, got {text!r}")
    keys = _dotted_key(key)
    if len(keys) < 2 or not all(keys):
        raise ConfigError(f"--set key must name a section and a key (e.g. parameters.D_m), got {key!r}")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()  # a bare word: take it as a string (e.g. --set model.backend=skfem)
    return keys, value


def _dotted_key(key: str) -> list[str]:
    """The parts of a ``--set`` key, read as TOML reads a dotted key (quotes and all)."""
    split = [part.strip() for part in key.strip().split(".")]
    if "\n" in key or "\r" in key:
        return split
    try:
        table = tomllib.loads(f"{key.strip()} = 0")
    except tomllib.TOMLDecodeError:
        return split
    keys = []
    while isinstance(table, dict) and len(table) == 1:
        ((name, table),) = table.items()
        keys.append(name)
    return keys if table == 0 else split


def apply_overrides(config: dict, assignments: list[str]) -> dict:
    """A copy of ``config`` with every ``section.key=value`` assignment applied (a lone string is one)."""
    config = copy.deepcopy(config)
    if isinstance(assignments, str):
        assignments = [assignments]
    for text in assignments or ():
        if not isinstance(text, str):
            raise ConfigError(f"an override is a string section.key=value, got {text!r}")
        keys, value = parse_assignment(text)
        if keys[0].startswith("_"):  # primordia's own keys (_base_dir), not the user's
            raise ConfigError(f"--set {text}: unknown config section [{keys[0]}] (known: {', '.join(SECTIONS)})")
        table = config
        for key in keys[:-1]:
            table = table.setdefault(key, {})
            if not isinstance(table, dict):
                raise ConfigError(f"--set {text}: {key} is not a table")
        _merge(table, {keys[-1]: value})  # an inline table adds to the table it names
    return config


def _merge(table: dict, given: dict) -> None:
    """``given``'s keys into ``table``, tables into tables: the keys ``given`` does not name stay.

    ``--set 'physics.poroelasticity={displacement_degree=1}'`` replaced the whole table (TOML's meaning
    of an inline table) and so dropped ex01b's four boundary conditions without a word; it now means
    the same as ``--set physics.poroelasticity.displacement_degree=1``.  A list is replaced whole.
    """
    for key, value in given.items():
        if isinstance(value, dict) and isinstance(table.get(key), dict):
            _merge(table[key], value)
        else:
            table[key] = value


def check_structure(config: dict) -> None:
    """Reject unknown tables and keys, naming them."""
    for section, value in config.items():
        if section == BASE_DIR:
            continue
        if section not in SECTIONS:
            raise ConfigError(f"unknown config section [{section}] (known: {', '.join(SECTIONS)})")
        if not isinstance(value, dict):
            raise ConfigError(f"config section [{section}] must be a table")
        if section in TABLES_OF_TABLES:
            for name, entry in value.items():
                if not isinstance(entry, dict):
                    raise ConfigError(f"{section}.{name} must be a table ({TABLES_OF_TABLES[section]}), "
                                      f"got {entry!r}")
        allowed = SECTIONS[section]
        if allowed is None:
            continue
        for key in value:
            if key not in allowed:
                raise ConfigError(f"unknown key {section}.{key} (known: {', '.join(sorted(allowed))})")


class Configured:
    """A configured plugin object: ``self.settings`` holds its run's option values.

    Contract 1.1 called them ``self.opts``; that name still reads the settings (with one
    warning per class), so plugins written against 1.1 keep working under 1.2.
    """

    settings: dict

    def __repr__(self) -> str:
        """Which piece and its settings (a notebook's model.physics_objects showed ``<... object at 0x...>``)."""
        name = getattr(self, "name", None)
        return f"{type(self).__name__}(name={name!r}, settings={getattr(self, 'settings', None)!r})"

    @property
    def opts(self) -> dict:
        cls = type(self)
        if cls not in _WARNED_OPTS:
            _WARNED_OPTS.add(cls)
            warn(f"{cls.__module__}.{cls.__name__} reads self.opts, renamed self.settings in contract 1.2")
        return self.settings


_WARNED_OPTS: set[type] = set()


def merge_options(where: str, defaults, given) -> dict:
    """``defaults`` updated with ``given``; an unknown option, or one of the wrong type, is one error naming it.

    The type an option takes is that of its default: true/false for a boolean, an
    integer for an integer, a number for a float, a string, a list or a table
    (a default of None takes anything: the module checks it).
    """
    if not isinstance(given, dict):
        raise ConfigError(f"{where}: options must be a table of name = value, got {given!r}")
    unknown = set(given) - set(defaults)
    if unknown:
        raise ConfigError(f"{where}: unknown option '{sorted(unknown)[0]}' "
                          f"(known: {', '.join(defaults) or 'none'})")
    for key, value in given.items():
        expected = _expected_kind(defaults[key])
        if expected is not None and not _is_kind(value, expected):
            raise ConfigError(f"{where}: option '{key}' must be {expected}, got {value!r}")
    return {**defaults, **{key: as_toml_reads_it(value) for key, value in given.items()}}


def as_toml_reads_it(value):
    """``value`` as a config.toml holding it reads back: TOML has no null, so unset options (None) inside a table are
    left out, and it has no tuple or numpy scalar, so those are lists and Python's numbers.  An option given as
    np.int64(3) was "must be an integer, got 3", and a tuple inside an option (a boundary condition's value) made
    a restart of the same model from Python refused as another model."""
    if isinstance(value, dict):
        return {k: as_toml_reads_it(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [as_toml_reads_it(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def _expected_kind(default) -> str | None:
    """What an option with this default must be, in words (None: anything)."""
    if isinstance(default, bool):
        return "true or false"
    if isinstance(default, int):
        return "an integer"
    if isinstance(default, float):
        return "a number"
    if isinstance(default, str):
        return "a string"
    if isinstance(default, (list, tuple)):
        return "a list"
    if isinstance(default, dict):
        return "a table"
    return None


def _is_kind(value, kind: str) -> bool:
    checks = {
        "true or false": is_flag,
        "an integer": is_integer,
        "a number": is_number,
        "a string": lambda v: isinstance(v, str),
        "a list": lambda v: isinstance(v, (list, tuple)),
        "a table": lambda v: isinstance(v, dict),
    }
    return checks[kind](value)
