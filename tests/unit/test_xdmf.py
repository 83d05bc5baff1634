"""XDMF time series of vertex fields (primordia.core.xdmf)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from primordia.core import xdmf
from primordia.core.errors import PrimordiaError
from primordia.core.meshes import box, rectangle
from primordia.core.xdmf import XdmfSeries
from file_writers import WriterDied, bump, leftovers, read_series, square  # noqa: F401


def test_xdmf_series_reads_back_with_meshio_after_every_write(tmp_path, square):
    series = XdmfSeries(tmp_path / "out", square)
    velocity = np.column_stack([square.points[:, 1], -square.points[:, 0]])
    times = [0.0, 0.25, 1.0 / 3.0]
    for k, t in enumerate(times):
        series.write(t, {"m": bump(square, t), "u": (1 + t) * velocity})
        points, cells, steps = read_series(tmp_path / "out" / "fields.xdmf")
        assert [s[0] for s in steps] == times[: k + 1], "the file on disk holds every time so far"
    np.testing.assert_array_equal(points, square.points)
    assert cells[0].type == "triangle"
    np.testing.assert_array_equal(cells[0].data, square.cells)
    for t, point_data in steps:
        np.testing.assert_array_equal(point_data["m"], bump(square, t))
        assert point_data["u"].shape == (square.num_vertices, 3), "2D vectors are padded to 3 components"
        np.testing.assert_array_equal(point_data["u"][:, :2], (1 + t) * velocity)
        assert np.all(point_data["u"][:, 2] == 0.0)
    assert series.times == times


def test_xdmf_series_of_a_box_with_a_tensor(tmp_path):
    mesh = box((0, 0, 0), (1, 1, 1), (2, 2, 2))
    stress = np.tile(np.arange(9.0).reshape(3, 3), (mesh.num_vertices, 1, 1))
    XdmfSeries(tmp_path, mesh, name="solid").write(2.0, {"sigma": stress, "p": mesh.points[:, 2]})
    points, cells, [(t, data)] = read_series(tmp_path / "solid.xdmf")
    assert t == 2.0 and cells[0].type == "tetra"
    np.testing.assert_array_equal(points, mesh.points)
    np.testing.assert_array_equal(data["sigma"], stress.reshape(-1, 9))
    np.testing.assert_array_equal(data["p"], mesh.points[:, 2])


def test_xdmf_index_is_dolfinx_style_xml(tmp_path, square):
    XdmfSeries(tmp_path, square).write(0.0, {"m": bump(square, 0.0)})
    text = (tmp_path / "fields.xdmf").read_text()
    assert 'xmlns:xi="http://www.w3.org/2001/XInclude"' in text
    assert 'CollectionType="Temporal"' in text and 'AttributeType="Scalar" Center="Node"' in text
    assert "fields_h5/t000000.h5:/m" in text and "fields_h5/mesh.h5:/topology" in text


def test_xdmf_write_that_dies_mid_way_leaves_the_previous_series_whole(tmp_path, square, monkeypatch):
    series = XdmfSeries(tmp_path, square)
    series.write(0.0, {"m": bump(square, 0.0)})
    series.write(1.0, {"m": bump(square, 1.0)})

    def die_after_partial_write(self, name, data=None, **kwargs):
        h5py.Group.create_dataset.__wrapped__(self, name, data=np.asarray(data)[:3])
        raise WriterDied("killed while writing heavy data")

    die_after_partial_write.__wrapped__ = h5py.Group.create_dataset
    with monkeypatch.context() as patch:
        patch.setattr(h5py.Group, "create_dataset", die_after_partial_write)
        with pytest.raises(WriterDied):
            series.write(2.0, {"m": bump(square, 2.0)})
    _, _, steps = read_series(tmp_path / "fields.xdmf")
    assert [t for t, _ in steps] == [0.0, 1.0]
    np.testing.assert_array_equal(steps[1][1]["m"], bump(square, 1.0))
    assert leftovers(tmp_path) == []
    series.write(2.0, {"m": bump(square, 2.0)})
    assert [t for t, _ in read_series(tmp_path / "fields.xdmf")[2]] == [0.0, 1.0, 2.0]


def test_xdmf_index_write_that_dies_leaves_the_previous_index(tmp_path, square, monkeypatch):
    series = XdmfSeries(tmp_path, square)
    series.write(0.0, {"m": bump(square, 0.0)})
    before = (tmp_path / "fields.xdmf").read_bytes()

    def die(*args, **kwargs):
        raise WriterDied("killed while writing the index")

    monkeypatch.setattr(xdmf, "atomic_write_bytes", die)
    with pytest.raises(WriterDied):
        series.write(1.0, {"m": bump(square, 1.0)})
    assert (tmp_path / "fields.xdmf").read_bytes() == before
    assert [t for t, _ in read_series(tmp_path / "fields.xdmf")[2]] == [0.0]


def test_a_new_xdmf_series_replaces_an_old_one_of_the_same_name(tmp_path, square):
    old = XdmfSeries(tmp_path, square)
    for t in (0.0, 1.0, 2.0):
        old.write(t, {"m": bump(square, t)})
    other = rectangle((0, 0), (1, 1), (2, 2))
    XdmfSeries(tmp_path, other).write(5.0, {"c": np.ones(other.num_vertices)})
    points, _, steps = read_series(tmp_path / "fields.xdmf")
    assert len(points) == other.num_vertices
    assert [t for t, _ in steps] == [5.0]


@pytest.mark.parametrize(
    "t, fields, message",
    [
        (1.0, {"m": np.zeros(5)}, r"field 'm' has shape \(5,\)"),
        (1.0, {"u": np.zeros((28, 3))}, r"expected vertex values of shape \(28,\), \(28, 2\)"),
        (1.0, {}, "no fields given"),
        (1.0, {"a/b": np.zeros(28)}, "field name must be"),
        (0.5, {"m": np.zeros(28)}, "time 0.5 does not follow the last written time 0.5"),
        (float("nan"), {"m": np.zeros(28)}, "time must be a finite number"),
    ],
)
def test_xdmf_series_rejects_bad_writes(tmp_path, square, t, fields, message):
    series = XdmfSeries(tmp_path, square)
    series.write(0.5, {"m": np.zeros(square.num_vertices)})
    with pytest.raises(PrimordiaError, match=message):
        series.write(t, fields)
    assert [s for s, _ in read_series(tmp_path / "fields.xdmf")[2]] == [0.5]


def test_xdmf_series_directory_errors(tmp_path, square):
    (tmp_path / "file").write_text("x")
    with pytest.raises(PrimordiaError, match="is a file"):
        XdmfSeries(tmp_path / "file", square)
    with pytest.raises(PrimordiaError, match="series name must be"):
        XdmfSeries(tmp_path, square, name="a:b")


def _truncate(path):
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])


@pytest.mark.parametrize("damage, message", [
    (_truncate, "t000001.h5 cannot be read (Unable to open file (truncated file"),
    (lambda path: path.unlink(), "t000001.h5 is missing"),
    (lambda path: xdmf._write_h5(path, {"other": np.zeros(3)}), "t000001.h5 lacks m"),
], ids=["truncated", "missing", "another-file"])
def test_a_series_whose_heavy_data_is_damaged_is_not_continued(tmp_path, square, damage, message):
    """A restart listed every checkpointed time again without looking at its HDF5 file: with one truncated or
    gone, it completed without a word and left an index meshio and ParaView cannot open."""
    series = XdmfSeries(tmp_path, square)
    for t in (0.5, 1.0):
        series.write(t, {"m": bump(square, t)})
    state = series.state()
    damage(tmp_path / "fields_h5" / "t000001.h5")
    index = (tmp_path / "fields.xdmf").read_bytes()
    with pytest.raises(PrimordiaError, match=f"cannot continue, .*{message}".replace("(", r"\(")):
        XdmfSeries(tmp_path, square).restore(state)
    assert (tmp_path / "fields.xdmf").read_bytes() == index
