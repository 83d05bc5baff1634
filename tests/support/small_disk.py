"""A command run on a small, soon full disk: a tmpfs of a few kB mounted in a private mount namespace.

The mount exists only for the command (``unshare --mount``): nothing is left mounted when a test fails or
is killed.  What the command left on the disk is copied out to ``copy`` before the namespace goes.
Mounting needs root (CAP_SYS_ADMIN), which ``make test`` has (it runs as root, see README.md).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

#: mount a tmpfs of $1 kB on $2, run the rest with the exit status kept, copy the disk out to $3.
_SCRIPT = 'mount -t tmpfs -o size="$1"k tmpfs "$2" || exit 90; d="$2"; c="$3"; shift 3; "$@"; s=$?; ' \
          'cp -a "$d/." "$c/"; exit $s'


def small_disks_available() -> str | None:
    """Why a tmpfs cannot be mounted for a test here (None: it can)."""
    if shutil.which("unshare") is None:
        return "no unshare command"
    if os.geteuid() != 0:
        return "mounting a tmpfs needs root (make test runs as root)"
    return None


def on_a_small_disk(kilobytes: int, disk: Path, copy: Path, argv: list[str], **kwargs) -> subprocess.CompletedProcess:
    """Run ``argv`` with a ``kilobytes`` kB tmpfs mounted on ``disk``; the disk's files end up in ``copy``."""
    reason = small_disks_available()
    if reason is not None:
        pytest.skip(reason)
    disk.mkdir(parents=True, exist_ok=True)
    copy.mkdir(parents=True, exist_ok=True)
    result = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c", _SCRIPT, "sh",
                             str(kilobytes), str(disk), str(copy), *argv],
                            capture_output=True, text=True, timeout=300, **kwargs)
    if result.returncode == 90:  # root without CAP_SYS_ADMIN (a container): the simulated full disks still run
        pytest.skip(f"cannot mount a tmpfs here: {result.stderr.strip()}")
    return result


def primordia_command() -> list[str]:
    """The ``primordia`` console script installed next to this interpreter (the command a user runs)."""
    return [str(Path(sys.executable).parent / "primordia")]
