"""Scalar time series in netCDF (primordia.core.scalar_series)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from primordia.core.errors import PrimordiaError
from primordia.core.scalar_series import ScalarSeries
from file_writers import WriterDied, leftovers


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
