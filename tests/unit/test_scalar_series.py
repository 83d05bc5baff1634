"""Scalar time series in netCDF (primordia.core.scalar_series)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import xarray as xr

from primordia.core import scalar_series
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

    def die_after_partial_write(target, variables, global_attrs):
        with open(target, "wb") as partial:
            partial.write(b"CDF\x01 half a header")
        raise WriterDied("killed while writing netCDF")

    monkeypatch.setattr(scalar_series, "_write_netcdf", die_after_partial_write)
    with pytest.raises(WriterDied):
        series.append(1.0, {"m_max": 4.0})
    monkeypatch.undo()
    with xr.open_dataset(path, engine="scipy") as data:
        np.testing.assert_array_equal(data["m_max"], [3.0])
    assert leftovers(tmp_path) == []


def test_the_file_is_what_xarray_writes(tmp_path):
    """The series is written by scipy's NetCDF writer: xarray must read it as what it writes itself, values,
    attributes and encodings (float64 with a NaN fill value, UTF-8 text along string<N>)."""
    series = ScalarSeries(tmp_path / "series.nc", attrs={"m_max": {"units": "dimensionless"},
                                                         "time": {"units": "days"}},
                          global_attrs={"title": "a series", "version": "the file's own, not scipy's"})
    series.append(0.0, {"m_max": 3.0})
    series.append(0.5, {"m_max": 4.0, "linear_iterations": 7})  # NaN in the first row
    series.add_event("rejections", {"t": 0.25, "subproblem": "chemotaxis.m", "reason": "diverged, étape 1"})
    series.add_event("rejections", {"t": 0.375, "dt": 0.125})  # no text: empty strings
    series.add_event("notes", {"text": ""})  # only empty text: string1
    empty = ScalarSeries(tmp_path / "empty.nc")
    empty.restore({"times": [], "columns": {}, "attrs": {}})  # no row yet
    for written in (series, empty):
        by_xarray = tmp_path / f"{written.path.stem}_by_xarray.nc"
        written.dataset().to_netcdf(by_xarray, engine="scipy")
        assert written.path.read_bytes()[:4] == by_xarray.read_bytes()[:4] == b"CDF\x02"  # 64-bit offsets
        with xr.open_dataset(written.path) as ours, xr.open_dataset(by_xarray) as theirs:
            xr.testing.assert_identical(ours.load(), theirs.load())
            for name in theirs.variables:
                np.testing.assert_equal(ours[name].encoding, theirs[name].encoding, err_msg=name)  # NaN == NaN
    with xr.open_dataset(series.path) as ours:
        assert ours["rejections_reason"].values.tolist() == ["diverged, étape 1", ""]
        assert ours["time"].attrs == {"units": "days"}
        assert ours.attrs == {"title": "a series", "version": "the file's own, not scipy's"}


def test_text_attributes_beyond_ascii_are_written_as_xarray_writes_them(tmp_path):
    """A model named "Hühner-Feder" put "ü" in the file's title: scipy's writer encodes text attributes as ASCII,
    so the run's series output failed at its first row and was disabled, and the run left no series.nc."""
    series = ScalarSeries(tmp_path / "series.nc", attrs={"psi_max": {"long_name": "maximum of ψ"}},
                          global_attrs={"title": "scalar series of model 'Hühner-Feder 羽'"})
    series.append(0.0, {"psi_max": 1.0})
    by_xarray = tmp_path / "by_xarray.nc"
    series.dataset().to_netcdf(by_xarray, engine="scipy")
    with xr.open_dataset(series.path) as ours, xr.open_dataset(by_xarray) as theirs:
        xr.testing.assert_identical(ours.load(), theirs.load())
        assert ours.attrs["title"] == "scalar series of model 'Hühner-Feder 羽'"
        assert ours["psi_max"].attrs["long_name"] == "maximum of ψ"


def test_a_row_imports_neither_xarray_nor_dask(tmp_path):
    """xarray's own writing imports xarray, pandas and dask, and dask.distributed in to_netcdf: 1.3 s of
    every run process."""
    script = textwrap.dedent(f"""
        import sys
        from primordia.core.scalar_series import ScalarSeries
        ScalarSeries({str(tmp_path / "series.nc")!r}).append(0.0, {{"m_max": 3.0}})
        print(*(name in sys.modules for name in ("xarray", "pandas", "dask", "distributed")))
    """)
    ran = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert ran.returncode == 0, ran.stderr
    assert ran.stdout.split() == ["False"] * 4, ran.stdout
    with xr.open_dataset(tmp_path / "series.nc") as written:
        assert written["m_max"].values.tolist() == [3.0]


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


def test_an_event_dimension_named_time_is_refused(tmp_path):
    series = ScalarSeries(tmp_path / "series.nc")
    with pytest.raises(PrimordiaError, match="'time' is the dimension of the rows"):
        series.add_event("time", {"t": 0.5})


def test_scalar_series_needs_an_existing_directory(tmp_path):
    with pytest.raises(PrimordiaError, match="does not exist"):
        ScalarSeries(tmp_path / "missing" / "series.nc")


def test_rows_appended_soon_after_a_rewrite_wait_for_the_next_one_or_a_flush(tmp_path, monkeypatch):
    """A run recording a row every few milliseconds rewrites series.nc at most every min_interval seconds;
    the file is whole meanwhile, and a flush (the run's end) writes what waits."""
    import primordia.core.scalar_series as module

    clock = [100.0]
    monkeypatch.setattr(module.time, "monotonic", lambda: clock[0])
    path = tmp_path / "series.nc"
    series = ScalarSeries(path, min_interval=2.0)

    def times():
        with xr.open_dataset(path, engine="scipy") as data:
            return list(data["time"].values)

    series.append(0.0, {"m_max": 1.0})  # the first row is written at once
    clock[0] += 0.5
    series.append(0.2, {"m_max": 2.0})
    assert times() == [0.0]
    clock[0] += 1.6  # 2.1 s after the rewrite
    series.append(0.4, {"m_max": 3.0})
    assert times() == [0.0, 0.2, 0.4]
    clock[0] += 0.1
    series.append(0.6, {"m_max": 4.0})
    assert times() == [0.0, 0.2, 0.4]
    series.flush()
    assert times() == [0.0, 0.2, 0.4, 0.6]
    assert leftovers(tmp_path) == []
    written = path.stat().st_mtime_ns
    series.flush()  # nothing waits: no rewrite
    assert path.stat().st_mtime_ns == written


def test_a_second_signal_inside_a_row_leaves_the_series_whole(tmp_path):
    """A second Ctrl-C raises where the program is (signals' "deferred" mode): one that came between a row's time and
    its columns left columns shorter than the times in the stop's checkpoint, and the restart disabled the series."""
    import os
    import signal

    from primordia.core.errors import InterruptedRun
    from primordia.core.signals import INTERRUPTS

    class SignalledTimes(list):
        def append(self, value):  # the signal arrives just after the time is added
            super().append(value)
            os.kill(os.getpid(), signal.SIGINT)

    series = ScalarSeries(tmp_path / "series.nc")
    series.append(0.0, {"m": 1.0})
    series._times = SignalledTimes(series._times)
    INTERRUPTS.reset()
    with INTERRUPTS.installed(), INTERRUPTS.mode_of("deferred"):
        INTERRUPTS.count = 1  # the run is already stopping: the next signal raises at once
        try:
            series.append(0.2, {"m": 2.0})
        except InterruptedRun:
            pass
    INTERRUPTS.reset()
    state = series.state()
    assert len(state["times"]) == len(state["columns"]["m"]) == 2
