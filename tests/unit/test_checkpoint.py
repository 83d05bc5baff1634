"""Checkpoint files (primordia.core.checkpoint): read back bit for bit, or refused in one error."""

from __future__ import annotations

import numpy as np
import pytest

from primordia.core import checkpoint
from primordia.core.errors import PrimordiaError


def test_a_checkpoint_reads_back_bit_for_bit(tmp_path):
    tree = {"time": 0.1 + 0.2, "fields": {"m": np.linspace(0.0, 1.0, 7)}, "rows": [1, None, "a"]}
    path = checkpoint.write(tmp_path / checkpoint.CHECKPOINT_FILE, tree)
    back = checkpoint.read(path)
    assert back["time"] == tree["time"] and back["rows"] == tree["rows"]
    assert back["fields"]["m"].tobytes() == tree["fields"]["m"].tobytes()
    assert checkpoint.read_meta(path)["fields"] == {"m": None}


def _empty(data: bytes) -> bytes:
    return b""


def _damaged_array_header(data: bytes) -> bytes:
    """A bit flipped in an array's .npy header: numpy's parsing of the header raises TokenError."""
    assert data.count(b"'shape': (1000,)") == 1
    return data.replace(b"'shape': (1000,)", b"'shape': (1000,(")


@pytest.mark.parametrize("reader, damage", [
    (checkpoint.read, _empty), (checkpoint.read_meta, _empty), (checkpoint.read, _damaged_array_header),
], ids=["read-empty", "read_meta-empty", "read-damaged-header"])  # read_meta reads no array header
def test_a_damaged_checkpoint_is_one_error(tmp_path, damage, reader):
    """An empty checkpoint.npz (EOFError) and a damaged array header (TokenError) escaped as tracebacks from
    `primordia run --restart`, where a truncated one was one line."""
    path = checkpoint.write(tmp_path / checkpoint.CHECKPOINT_FILE, {"m": np.zeros(1000)})
    path.write_bytes(damage(path.read_bytes()))
    with pytest.raises(PrimordiaError, match=f"checkpoint {path} cannot be read"):
        reader(path)


def test_restarting_from_an_empty_checkpoint_is_one_line_and_keeps_the_files(tmp_path, primordia_cli,
                                                                            small_config):
    out = tmp_path / "run"
    assert primordia_cli("run", small_config(), "--out", out, "--no-progress").returncode == 0
    (out / checkpoint.CHECKPOINT_FILE).write_bytes(b"")
    kept = {path.name: path.read_bytes() for path in out.iterdir() if path.is_file()}
    result = primordia_cli("run", "--restart", out, "--no-progress")
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("primordia: error: checkpoint ") and "cannot be read" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert {path.name: path.read_bytes() for path in out.iterdir() if path.is_file()} == kept
