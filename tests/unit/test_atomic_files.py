"""Files written whole or not at all (primordia.core.atomic_files)."""

from __future__ import annotations

import pytest

from primordia.core.atomic_files import (atomic_path, atomic_write_bytes, atomic_write_text, nearest_existing,
                                         refusal_to_write)
from primordia.core.errors import PrimordiaError
from file_writers import WriterDied, leftovers


def test_atomic_write_text_and_bytes_replace_whole_files(tmp_path):
    path = tmp_path / "notes.txt"
    atomic_write_text(path, "first\n")
    atomic_write_text(path, "second ü\n")
    assert path.read_text(encoding="utf-8") == "second ü\n"
    atomic_write_bytes(tmp_path / "blob.bin", b"\x00\x01")
    assert (tmp_path / "blob.bin").read_bytes() == b"\x00\x01"
    assert leftovers(tmp_path) == []


def test_atomic_path_keeps_the_suffix_and_replaces_on_success(tmp_path):
    path = tmp_path / "image.png"
    with atomic_path(path) as temporary:
        assert temporary.parent == tmp_path and temporary.suffix == ".png" and temporary != path
        temporary.write_bytes(b"new")
        assert not path.exists(), "the final name appears only when the block ends"
    assert path.read_bytes() == b"new"


def test_atomic_path_failure_keeps_the_previous_file_and_removes_the_temporary(tmp_path):
    path = tmp_path / "result.txt"
    path.write_text("complete old result")
    with pytest.raises(WriterDied):
        with atomic_path(path) as temporary:
            temporary.write_text("half a new res")
            raise WriterDied
    assert path.read_text() == "complete old result"
    assert leftovers(tmp_path) == []


def test_atomic_path_that_writes_nothing_is_an_error(tmp_path):
    with pytest.raises(PrimordiaError, match="nothing was written"):
        with atomic_path(tmp_path / "empty.txt"):
            pass
    assert not (tmp_path / "empty.txt").exists()


@pytest.mark.parametrize(
    "target, message",
    [
        (lambda d: d / "no" / "such" / "dir" / "x.txt", "directory .*dir does not exist"),
        (lambda d: d, "it is a directory"),
        (lambda d: "", "not a file path"),
    ],
)
def test_bad_paths_are_one_line_errors(tmp_path, target, message):
    with pytest.raises(PrimordiaError, match=message) as error:
        atomic_write_text(target(tmp_path), "x")
    assert "\n" not in str(error.value)


def test_a_folder_still_to_be_made_is_probed_where_it_would_be_made(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "a").mkdir()
    assert nearest_existing("a/b/c") == tmp_path / "a"
    assert nearest_existing(tmp_path / "a") == tmp_path / "a"
    (tmp_path / "f").write_text("")
    assert nearest_existing(tmp_path / "f" / "g") == tmp_path / "f"
    assert refusal_to_write(tmp_path / "f") is not None  # a file holds no folder
    assert refusal_to_write(tmp_path / "a") is None
