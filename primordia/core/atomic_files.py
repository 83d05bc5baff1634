"""Files written whole or not at all: a temporary file next to the target, renamed over it.

A run may die at any moment (killed job, full disk, diverged solver), and the
results it has already written must survive it whole.  So no output file is
ever written in place: every writer of primordia (fields, series, pictures,
JSON, TOML, checkpoints, analysis figures and metrics) writes a temporary file
in the same directory and ``os.replace``\\ s it over the final name, which POSIX
makes atomic.  A reader therefore sees either the previous complete file or
the new complete file, never a half-written one; a writer that fails removes
its temporary file and leaves the previous file untouched.

* :func:`atomic_path` -- a temporary path for any library that writes by file name;
* :func:`atomic_write_text`, :func:`atomic_write_bytes` -- text and bytes;
* :func:`writable_target`, :func:`make_directory` -- one clear error for a path that
  cannot be written;
* :class:`StorageError` -- a write its file system refused (full, over quota, read-only, failing):
  ``cannot write PATH: no space left on device``.  No later write there can succeed, so a run
  stops on it (:mod:`primordia.coupling.orchestrator`) where it disables an output that fails otherwise.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
from collections.abc import Iterator
from pathlib import Path

from primordia.core.errors import PrimordiaError

#: What a file system answers a write with when it takes no more: full, over quota, read-only, failing.
STORAGE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EIO})


class StorageError(PrimordiaError):
    """A file could not be written because its file system takes no more (:data:`STORAGE_ERRNOS`)."""


def storage_error(path: str | Path, error: BaseException, doing: str = "write") -> StorageError | None:
    """``cannot write PATH: no space left on device`` when ``error`` (or what it was raised from, as libraries
    re-raise) is a write its file system refused; None for any other error.  ``doing``: what could not be done."""
    seen = set()
    while error is not None and id(error) not in seen:
        seen.add(id(error))
        if isinstance(error, StorageError):
            return error
        if isinstance(error, OSError) and error.errno in STORAGE_ERRNOS:
            return StorageError(f"cannot {doing} {path}: {reason_of(error)}")
        error = error.__cause__ or error.__context__
    return None


def reason_of(error: OSError) -> str:
    """Why the system refused, as primordia's lines say it: ``no space left on device`` (its strerror, which
    starts with a capital: "cannot create the directory out: No space left on device" stood beside the writes'
    "no space left on device")."""
    text = os.strerror(error.errno) if error.errno else str(error)
    return text[:1].lower() + text[1:]


def nearest_existing(path: str | Path) -> Path:
    """``path`` made absolute, or its nearest ancestor that exists: where a folder still to be made would be made."""
    path = Path(os.path.abspath(path))
    return next(p for p in [path, *path.parents] if p.exists())


def refusal_to_write(folder: str | Path) -> OSError | None:
    """Why nothing can be made in the existing ``folder`` (the system's refusal), or None: by making and removing a
    folder there, since os.access says yes to root everywhere (/proc, a read-only mount)."""
    import tempfile

    try:
        os.rmdir(tempfile.mkdtemp(prefix=".primordia-probe-", dir=folder))
    except OSError as error:
        return error
    return None


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it replaces ``path``.

    The temporary name keeps the suffix of ``path`` (libraries that choose a
    format by extension still work) and starts with a dot.  If the block
    raises, the temporary file is removed, ``path`` is left as it was and the
    exception propagates; a write the file system refused (a full disk) as one :class:`StorageError`
    naming ``path``, whatever library raised it.  The parent directory must exist.
    """
    path = writable_target(path)
    temporary = path.with_name(f".{path.stem}.tmp-{secrets.token_hex(4)}{path.suffix}")
    try:
        yield temporary
        if not temporary.is_file():
            raise PrimordiaError(f"cannot write {path}: nothing was written to its temporary file")
        _fsync_file(temporary)
        os.replace(temporary, path)
    except BaseException as error:
        with contextlib.suppress(OSError):  # gone, or a file system turned read-only
            temporary.unlink()
        storage = storage_error(path, error) if isinstance(error, Exception) else None
        if storage is not None and storage is not error:
            raise storage from None
        raise
    _fsync_directory(path.parent)


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return ``path``."""
    with atomic_path(path) as temporary:
        temporary.write_bytes(data)
    return Path(path)


def atomic_write_text(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically; return ``path``."""
    return atomic_write_bytes(path, text.encode(encoding))


def writable_target(path: str | Path) -> Path:
    """``path`` as a Path whose directory exists and which is not itself a directory."""
    if not isinstance(path, (str, os.PathLike)) or not str(path):
        raise PrimordiaError(f"cannot write to {path!r}: not a file path")
    path = Path(path)
    if path.is_dir():
        raise PrimordiaError(f"cannot write {path}: it is a directory")
    if not path.parent.is_dir():
        raise PrimordiaError(f"cannot write {path}: directory {path.parent} does not exist")
    if not os.access(path.parent, os.W_OK | os.X_OK):  # a run's folder remounted read-only mid-run, or chmod-ed
        read_only = bool(os.statvfs(path.parent).f_flag & os.ST_RDONLY)
        raise StorageError(f"cannot write {path}: " + ("read-only file system" if read_only
                                                        else f"directory {path.parent} is not writable"))
    return path


def _fsync_file(path: Path) -> None:
    """Flush ``path`` to disk so the rename never exposes an empty file after a power cut."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_directory(directory: Path) -> None:
    """Make a rename in ``directory`` durable (a no-op where directories cannot be opened)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def make_directory(directory: str | Path) -> Path:
    """``directory``, created (with parents) if missing; PrimordiaError if impossible."""
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise PrimordiaError(f"cannot use {directory} as an output directory: it is a file") from None
    except OSError as error:
        storage = storage_error(directory, error, doing="create the directory")
        if storage is not None:
            raise storage from None
        raise PrimordiaError(f"cannot create the directory {directory}: {reason_of(error)}") from None
    return directory
