"""Writing on a full disk: one clear error, never a crash, and every file written before stays whole."""

from __future__ import annotations

import sys
import textwrap

import meshio
import numpy as np
import pytest

from small_disk import on_a_small_disk

#: Writes 40 x 40 squares' fields (1,681 vertices, 13 kB a time) at t = 0, 1, 2, ... until a write fails.
XDMF_UNTIL_FULL = textwrap.dedent("""
    import sys
    import numpy as np
    from primordia.core.meshes import rectangle
    from primordia.core.xdmf import XdmfSeries
    mesh = rectangle((0, 0), (1, 1), (40, 40))
    series = XdmfSeries(sys.argv[1], mesh)
    t = 0
    try:
        while True:
            series.write(t, {"m": np.full(mesh.num_vertices, float(t))})
            t += 1
    except Exception as error:
        print(f"stopped at t = {t}: {error}")
        sys.exit(3)
""")


@pytest.mark.parametrize("kilobytes", [150, 300])
def test_a_fields_series_on_a_full_disk_fails_with_an_error_and_keeps_its_times(tmp_path, kilobytes):
    """HDF5 writing to a full disk itself left its file half-closed; h5py's clean-up then crashed the process
    at exit (a segmentation fault, exit status 139 at 150-300 kB here; an MPI_ABORT under mpirun) after
    'Exception ignored' tracebacks."""
    disk, copy = tmp_path / "disk", tmp_path / "copy"
    result = on_a_small_disk(kilobytes, disk, copy, [sys.executable, "-c", XDMF_UNTIL_FULL, str(disk / "run")])
    assert result.returncode == 3, (result.returncode, result.stdout, result.stderr[-2000:])
    assert "o space left on device" in result.stdout, result.stdout
    assert "Exception ignored" not in result.stderr and "Traceback" not in result.stderr, result.stderr[-2000:]
    with meshio.xdmf.TimeSeriesReader(copy / "run" / "fields.xdmf") as reader:
        reader.read_points_cells()
        times = [reader.read_data(k)[0] for k in range(reader.num_steps)]
        values = [reader.read_data(k)[1]["m"] for k in range(reader.num_steps)]
    written = int(result.stdout.split("stopped at t = ")[1].split(":")[0])
    assert 1 <= written == len(times), (written, times)  # every time written before the disk filled, whole
    for t, m in zip(times, values):
        np.testing.assert_array_equal(m, t)
    assert not list((copy / "run").rglob(".*tmp-*")), "a failed write left its temporary file"


#: A checkpoint that fits, then one that does not: the first must stay, and the failure be the only word.
CHECKPOINT_UNTIL_FULL = textwrap.dedent("""
    import sys
    import numpy as np
    from primordia.core import checkpoint
    path = sys.argv[1] + "/checkpoint.npz"
    checkpoint.write(path, {"time": 1.5, "fields": {"m": np.arange(1000.0)}})
    try:
        checkpoint.write(path, {"time": 2.0, "fields": {"m": np.arange(100_000.0)}})
    except Exception as error:
        print(f"second checkpoint: {error}")
        sys.exit(3)
""")


def test_a_checkpoint_that_fills_the_disk_keeps_the_previous_one_and_prints_nothing_else(tmp_path):
    """numpy's savez left its archive open when a write failed; the garbage collector closed it after its
    file and printed 'Exception ignored in: ZipFile.__del__' and a traceback beside the run's warning."""
    from primordia.core import checkpoint

    disk, copy = tmp_path / "disk", tmp_path / "copy"
    result = on_a_small_disk(200, disk, copy, [sys.executable, "-c", CHECKPOINT_UNTIL_FULL, str(disk)])
    assert result.returncode == 3, (result.returncode, result.stdout, result.stderr[-2000:])
    assert "o space left on device" in result.stdout, result.stdout
    assert result.stderr == "", result.stderr
    tree = checkpoint.read(copy / "checkpoint.npz")
    assert tree["time"] == 1.5
    np.testing.assert_array_equal(tree["fields"]["m"], np.arange(1000.0))
    assert [path.name for path in copy.iterdir()] == ["checkpoint.npz"]
