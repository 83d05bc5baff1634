"""Reading what the real ``primordia`` command answered: a one-line error, the ``primordia plugins`` listing."""

from __future__ import annotations

import re


def assert_one_line_error(result, *fragments: str) -> str:
    """Exit status 2, one stderr line ``primordia: error: ...`` containing every fragment."""
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert "Traceback" not in result.stderr and "Traceback" not in result.stdout, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("primordia: error: "), lines[0]
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in {lines[0]!r}"
    return lines[0]


def listing(stdout: str) -> dict[str, dict[str, str]]:
    """``primordia plugins`` output as {kind: {name: rest of the line}}."""
    table: dict[str, dict[str, str]] = {}
    kind = None
    for line in stdout.splitlines():
        if re.fullmatch(r"[a-z_]+:", line):
            kind = line[:-1]
            table[kind] = {}
        elif line.startswith("  ") and kind is not None:
            name, _, rest = line.strip().partition(" ")
            table[kind][name] = rest.strip()
    return table
