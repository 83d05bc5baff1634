"""Checkpoint files: everything a run needs to take its next step, in one file written atomically.

A checkpoint is one ``.npz`` file: every numpy array of the state stored exactly
(float64 bit for bit), and one JSON document (``meta``) holding the rest (time,
step, dt, the step controller, solver statistics, the outputs' rows so far, the
configuration).  Python floats go through JSON by their shortest round-tripping
repr, so they come back bit for bit too.  The file is written next to its final
name and renamed over it (:func:`primordia.core.atomic_files.atomic_path`), so a run killed
while writing leaves the previous checkpoint whole.  Nothing is unpickled on
reading: a checkpoint holds data, never code.
"""

from __future__ import annotations

import json
import tokenize
import zipfile
from pathlib import Path

import numpy as np

from primordia.core.atomic_files import atomic_path
from primordia.core.errors import PrimordiaError

#: The checkpoint of a run, in its output directory.
CHECKPOINT_FILE = "checkpoint.npz"
#: Bumped whenever the layout changes: an older checkpoint is refused by name, not misread.
FORMAT = 1


def write(path: str | Path, tree: dict) -> Path:
    """Write ``tree`` (dicts, lists, numbers, strings, None, numpy arrays) to ``path`` atomically."""
    arrays: dict[str, np.ndarray] = {}
    meta = json.dumps({"format": FORMAT, "tree": _flatten(tree, arrays)}, default=_json_scalar)
    with atomic_path(path) as temporary:
        _savez(temporary, {"meta": np.array(meta), **arrays})
    return Path(path)


def _savez(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """``numpy.savez(path, **arrays)``, with the archive closed when a write fails.

    numpy 1.26's savez leaves its ZipFile open when a write raises (a full disk): the archive was closed
    later, by the garbage collector, after its file, and printed "Exception ignored in: ZipFile.__del__ ...
    ValueError: seek of closed file", a traceback, into the run's one-line report of the full disk.
    """
    with zipfile.ZipFile(path, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as archive:
        for key, value in arrays.items():
            with archive.open(f"{key}.npy", "w", force_zip64=True) as member:  # numpy's own layout
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)


def read(path: str | Path) -> dict:
    """The tree written by :func:`write`; a missing, foreign or damaged file is one PrimordiaError."""
    return _load(path, arrays=True)


def read_meta(path: str | Path) -> dict:
    """The tree written by :func:`write` without its arrays (each replaced by None): cheap to read."""
    return _load(path, arrays=False)


def _load(path: str | Path, arrays: bool) -> dict:
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            if meta.get("format") != FORMAT:
                raise PrimordiaError(f"checkpoint {path} has format {meta.get('format')!r}; this primordia "
                                     f"reads format {FORMAT}")
            return _unflatten(meta["tree"], data, arrays)
    except FileNotFoundError:
        raise PrimordiaError(f"no checkpoint at {path}") from None
    # an empty file is EOFError; a damaged .npy header fails numpy's parsing of it with TokenError
    except (OSError, EOFError, ValueError, KeyError, tokenize.TokenError, zipfile.BadZipFile) as error:
        raise PrimordiaError(f"checkpoint {path} cannot be read ({type(error).__name__}: {error})") from None


def _flatten(value, arrays: dict):
    if isinstance(value, np.ndarray):
        key = f"a{len(arrays)}"
        arrays[key] = value
        return {"__array__": key}
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value):
            raise PrimordiaError(f"checkpoint keys must be strings, got {list(value)[:3]!r}")
        return {k: _flatten(v, arrays) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_flatten(v, arrays) for v in value]
    return value


def _unflatten(value, data, arrays: bool = True):
    if isinstance(value, dict):
        if set(value) == {"__array__"}:
            return np.array(data[value["__array__"]]) if arrays else None
        return {k: _unflatten(v, data, arrays) for k, v in value.items()}
    if isinstance(value, list):
        return [_unflatten(v, data, arrays) for v in value]
    return value


def _json_scalar(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise PrimordiaError(f"cannot store a {type(value).__name__} in a checkpoint: {value!r}")
