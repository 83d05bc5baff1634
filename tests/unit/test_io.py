"""Crash-safe output files (primordia.core.io)."""

from __future__ import annotations

import json
import math
import tomllib

import h5py
import matplotlib.image
import meshio
import numpy as np
import pytest
import xarray as xr

from primordia.core import io
from primordia.core.errors import PrimordiaError
from primordia.core.io import (
    ScalarSeries,
    XdmfSeries,
    atomic_path,
    atomic_write_bytes,
    atomic_write_text,
    plot_field,
    plot_fields_grid,
    write_json,
    write_toml,
)
from primordia.core.meshes import box, rectangle


class WriterDied(RuntimeError):
    """Stands for a run dying in the middle of writing a file."""


def leftovers(directory):
    """Temporary files an interrupted write could have left behind."""
    return sorted(p.name for p in directory.rglob(".*tmp-*"))


def read_series(path):
    """(points, cells, [(t, point_data), ...]) of an XDMF time series, via meshio."""
    with meshio.xdmf.TimeSeriesReader(path) as reader:
        points, cells = reader.read_points_cells()
        steps = [reader.read_data(k)[:2] for k in range(reader.num_steps)]
    return points, cells, steps


@pytest.fixture
def square():
    return rectangle((0, 0), (2, 1), (6, 3))


def bump(mesh, t):
    x, y = mesh.points[:, 0], mesh.points[:, 1]
    return np.exp(-((x - 1 - 0.1 * t) ** 2 + (y - 0.5) ** 2) / 0.1)


# ---------------------------------------------------------------------------
# atomic files
# ---------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------
# XdmfSeries
# ---------------------------------------------------------------------------


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

    monkeypatch.setattr(io, "atomic_write_bytes", die)
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


# ---------------------------------------------------------------------------
# ScalarSeries
# ---------------------------------------------------------------------------


def test_scalar_series_reads_back_with_xarray_and_fills_new_keys_with_nan(tmp_path):
    path = tmp_path / "series.nc"
    series = ScalarSeries(path, attrs={"m_integral": {"units": "dimensionless", "description": "integral of m"}})
    series.append(0.0, {"m_integral": 1.5, "m_min": 0.0})
    series.append(0.5, {"m_integral": 1.75, "m_min": np.float32(0.25), "linear_iterations": np.int64(7)})
    series.append(1.0, {"m_integral": 2.0, "linear_iterations": 9}, attrs={"time": {"units": "dimensionless"}})
    with xr.open_dataset(path, engine="scipy") as data:
        data = data.load()
    np.testing.assert_array_equal(data["time"], [0.0, 0.5, 1.0])
    np.testing.assert_array_equal(data["m_integral"], [1.5, 1.75, 2.0])
    np.testing.assert_array_equal(data["m_min"], [0.0, 0.25, np.nan])
    np.testing.assert_array_equal(data["linear_iterations"], [np.nan, 7.0, 9.0])
    assert data["m_integral"].attrs == {"units": "dimensionless", "description": "integral of m"}
    assert data["time"].attrs["units"] == "dimensionless"
    assert leftovers(tmp_path) == []


def test_scalar_series_write_that_dies_leaves_the_previous_file(tmp_path, monkeypatch):
    path = tmp_path / "series.nc"
    series = ScalarSeries(path)
    series.append(0.0, {"m_max": 3.0})

    def die_after_partial_write(self, target, *args, **kwargs):
        with open(target, "wb") as partial:
            partial.write(b"CDF\x01 half a header")
        raise WriterDied("killed while writing netCDF")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", die_after_partial_write)
    with pytest.raises(WriterDied):
        series.append(1.0, {"m_max": 4.0})
    monkeypatch.undo()
    with xr.open_dataset(path, engine="scipy") as data:
        np.testing.assert_array_equal(data["m_max"], [3.0])
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize(
    "t, row, message",
    [
        (1.0, {"m": "big"}, "value 'm' must be a number"),
        (1.0, {"m": np.ones(2)}, r"value 'm' must be a single number, got shape \(2,\)"),
        (1.0, {"time": 3.0}, "'time' is the series dimension"),
        (0.0, {"m": 1.0}, "time 0 does not follow"),
    ],
)
def test_scalar_series_rejects_bad_rows(tmp_path, t, row, message):
    series = ScalarSeries(tmp_path / "series.nc")
    series.append(0.0, {"m": 1.0})
    with pytest.raises(PrimordiaError, match=message):
        series.append(t, row)


def test_scalar_series_needs_an_existing_directory(tmp_path):
    with pytest.raises(PrimordiaError, match="does not exist"):
        ScalarSeries(tmp_path / "missing" / "series.nc")


# ---------------------------------------------------------------------------
# pictures
# ---------------------------------------------------------------------------


def read_png(path):
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return matplotlib.image.imread(path)[..., :3]


def distinct_colours(image) -> int:
    return len(np.unique((image * 255).astype(np.uint8).reshape(-1, 3), axis=0))


def test_plot_field_draws_a_coloured_field(tmp_path, square):
    path = plot_field(tmp_path / "m.png", square, bump(square, 0.0), title="m at t = 0")
    image = read_png(path)
    assert path.stat().st_size > 10_000
    assert distinct_colours(image) > 200, "a gouraud-shaded field has many colours"
    viridis_yellow = np.array([0.993, 0.906, 0.144])
    assert np.any(np.all(np.abs(image - viridis_yellow) < 0.05, axis=-1)), "the maximum is drawn in yellow"
    assert leftovers(tmp_path) == []


def test_plot_field_on_the_deformed_configuration_is_another_picture(tmp_path, square):
    values = bump(square, 0.0)
    plain = read_png(plot_field(tmp_path / "plain.png", square, values))
    shear = np.column_stack([0.3 * square.points[:, 1], np.zeros(square.num_vertices)])
    deformed = read_png(
        plot_field(tmp_path / "deformed.png", square, values, displacement=shear, displacement_scale=2.0)
    )
    assert plain.shape == deformed.shape and not np.array_equal(plain, deformed)


def test_plot_field_of_a_box_draws_its_top_face(tmp_path):
    mesh = box((0, 0, 0), (2, 1, 1), (4, 2, 2))
    image = read_png(plot_field(tmp_path / "box.png", mesh, mesh.points[:, 0] + mesh.points[:, 2]))
    assert distinct_colours(image) > 100


def test_plot_fields_grid_puts_panels_side_by_side(tmp_path, square):
    snapshots = {f"t = {t}": bump(square, t / 100) for t in (160, 280, 400, 520)}
    row = read_png(plot_fields_grid(tmp_path / "row.png", square, snapshots, title="m"))
    single = read_png(plot_field(tmp_path / "one.png", square, snapshots["t = 160"]))
    assert row.shape[1] > 3 * single.shape[1]
    grid = read_png(plot_fields_grid(tmp_path / "grid.png", square, snapshots, ncols=2, shared_colour_scale=False))
    assert grid.shape[0] > 1.5 * single.shape[0]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"values": np.zeros(3)}, "expected 28 vertex values, got shape \\(3,\\)"),
        ({"displacement": np.zeros((28, 3))}, "displacement must have shape \\(28, 2\\)"),
        ({"path": "no/such/dir/m.png"}, "does not exist"),
    ],
)
def test_plot_field_errors(tmp_path, square, kwargs, message):
    arguments = {"path": tmp_path / "m.png", "mesh": square, "values": np.zeros(28)} | kwargs
    if kwargs.get("path"):
        arguments["path"] = tmp_path / kwargs["path"]
    with pytest.raises(PrimordiaError, match=message):
        plot_field(**arguments)


# ---------------------------------------------------------------------------
# JSON and TOML
# ---------------------------------------------------------------------------


def test_write_json_sorts_keys_and_converts_numpy(tmp_path):
    path = write_json(
        tmp_path / "run.json",
        {
            "zeta": np.float64(0.5),
            "alpha": {"n": np.int64(3), "ok": np.bool_(True), "v": np.arange(3)},
            "nan": math.nan,
        },
    )
    text = path.read_text()
    assert text.index('"alpha"') < text.index('"nan"') < text.index('"zeta"')
    data = json.loads(text)
    assert data["alpha"] == {"n": 3, "ok": True, "v": [0, 1, 2]} and data["zeta"] == 0.5
    assert math.isnan(data["nan"])


def test_write_json_rejects_unknown_objects(tmp_path):
    with pytest.raises(PrimordiaError, match="cannot write object value"):
        write_json(tmp_path / "x.json", {"a": object()})
    assert not (tmp_path / "x.json").exists()


def test_write_toml_round_trips_through_tomllib(tmp_path):
    config = {
        "title": 'seed "run" 1\n',
        "steps": np.int64(400),
        "dt": 0.5,
        "big": 1e20,
        "flags": [True, False],
        "limits": [-math.inf, math.inf],
        "mesh": {"type": "rectangle", "cells": np.array([171, 171]), "upper": [20.0, 20.0]},
        "parameters": {"D_m": 0.01, "nested": {"odd key": 1}},
        "outputs": [{"kind": "xdmf", "every": 10}, {"kind": "png", "fields": ["m", "u"]}],
    }
    with open(write_toml(tmp_path / "resolved.toml", config), "rb") as handle:
        back = tomllib.load(handle)
    expected = dict(config, steps=400, mesh={"type": "rectangle", "cells": [171, 171], "upper": [20.0, 20.0]})
    assert back == expected


def test_write_toml_rejects_values_toml_cannot_hold(tmp_path):
    with pytest.raises(PrimordiaError, match="cannot write mesh.shape = None to TOML"):
        write_toml(tmp_path / "x.toml", {"mesh": {"shape": None}})
    assert not (tmp_path / "x.toml").exists()
