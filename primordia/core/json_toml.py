"""Run metadata and resolved configurations: :func:`write_json`, :func:`write_toml`, written atomically."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterator, Mapping
from datetime import date, datetime
from pathlib import Path

import numpy as np

from primordia.core.atomic_files import atomic_write_text
from primordia.core.errors import PrimordiaError


def write_json(path: str | Path, obj) -> Path:
    """Write ``obj`` as indented JSON with sorted keys, atomically.

    numpy scalars and arrays become numbers and lists, paths strings.
    Non-finite floats are written as ``NaN`` / ``Infinity`` (what Python's
    ``json`` reads back), since a diverged run's metrics must still be saved.
    """
    text = json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n"
    return atomic_write_text(path, text)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise PrimordiaError(f"cannot write {type(value).__name__} value {value!r} to JSON")


def write_toml(path: str | Path, mapping: Mapping) -> Path:
    """Write ``mapping`` as TOML, atomically.

    Values may be str, int, float (incl. inf / nan), bool, dates, lists of
    these, nested mappings (written as ``[tables]``) and lists of mappings
    (``[[arrays of tables]]``); numpy scalars and arrays are converted.
    """
    if not isinstance(mapping, Mapping):
        raise PrimordiaError(f"cannot write {path} as TOML: expected a mapping, got {type(mapping).__name__}")
    return atomic_write_text(path, "".join(_toml_table(mapping, ())))


def _toml_table(table: Mapping, prefix: tuple[str, ...]) -> Iterator[str]:
    """Lines of a TOML table: its plain keys first, then its sub-tables."""
    plain = {k: v for k, v in table.items() if not _is_table(v) and not _is_table_array(v)}
    for key, value in plain.items():
        yield f"{_toml_key(key)} = {_toml_value(value, prefix + (key,))}\n"
    for key, value in table.items():
        if _is_table(value):
            name = ".".join(map(_toml_key, prefix + (key,)))
            yield f"\n[{name}]\n"
            yield from _toml_table(value, prefix + (key,))
        elif _is_table_array(value):
            name = ".".join(map(_toml_key, prefix + (key,)))
            for item in value:
                yield f"\n[[{name}]]\n"
                yield from _toml_table(item, prefix + (key,))


def _is_table(value) -> bool:
    return isinstance(value, Mapping)


def _is_table_array(value) -> bool:
    return isinstance(value, (list, tuple)) and len(value) > 0 and all(isinstance(v, Mapping) for v in value)


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _toml_key(key) -> str:
    if not isinstance(key, str):
        raise PrimordiaError(f"TOML keys must be strings, got {key!r}")
    return key if _BARE_KEY.match(key) else _toml_string(key)


def _toml_string(text: str) -> str:
    """A TOML basic string with the escapes TOML requires."""
    escaped = []
    for char in text:
        if char in '"\\':
            escaped.append("\\" + char)
        elif char in "\b\t\n\f\r":
            escaped.append({"\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}[char])
        elif ord(char) < 0x20 or ord(char) == 0x7F:
            escaped.append(f"\\u{ord(char):04x}")
        else:
            escaped.append(char)
    return '"' + "".join(escaped) + '"'


def _toml_value(value, where: tuple[str, ...]) -> str:
    """One TOML value (inline), or a PrimordiaError naming the dotted key."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return _toml_float(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, Path):
        return _toml_string(str(value))
    if isinstance(value, (datetime, date)):
        return value.isoformat()
    if isinstance(value, (list, tuple)):
        if any(isinstance(item, Mapping) for item in value):
            return "[" + ", ".join(_inline_table(item, where) for item in value) + "]"
        return "[" + ", ".join(_toml_value(item, where) for item in value) + "]"
    raise PrimordiaError(f"cannot write {'.'.join(where)} = {value!r} to TOML ({type(value).__name__})")


def toml_text(value) -> str:
    """``value`` as a TOML file writes it inline (``"lu"``, ``[1.0, 0.5]``, ``false``), for messages quoting one."""
    return _inline_table(value, ())


def _inline_table(value, where: tuple[str, ...]) -> str:
    if not isinstance(value, Mapping):
        return _toml_value(value, where)
    items = ", ".join(f"{_toml_key(k)} = {_inline_table(v, where + (k,))}" for k, v in value.items())
    return "{" + items + "}"


def _toml_float(value: float) -> str:
    if math.isnan(value):
        return "nan"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    text = repr(value)
    return text if any(c in text for c in ".en") else text + ".0"
