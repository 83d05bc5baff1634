"""Writing on a full disk: one clear error, never a crash, and every file written before stays whole."""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import sys
import textwrap

import matplotlib.image
import meshio
import numpy as np
import pytest
import xarray as xr

from primordia.core import atomic_files, checkpoint, outputs
from primordia.core.atomic_files import StorageError
from primordia.core.meshes import rectangle
from primordia.model import Model
from cli_checks import assert_one_line_error
from run_control import EXAMPLES, command, environment
from small_config import SMALL_CONFIG
from small_disk import on_a_small_disk, primordia_command

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


#: The real flush of a written file (FillingDisk replaces it).
FSYNC = atomic_files._fsync_file


class FillingDisk:
    """A disk that fills: every atomic write after the first ``room`` fails with ENOSPC (at its fsync, as on NFS);
    ``room = None`` lets every write through, counting them.  ``once``: only the write at ``room`` fails (a large
    file that did not fit; the smaller ones after it do)."""

    def __init__(self, monkeypatch, room: int | None, once: bool = False):
        self.room, self.once, self.written = room, once, 0

        def filling(path):
            self.written += 1
            if self.room is not None and (self.written == self.room + 1 or self.written > self.room and not once):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
            FSYNC(path)

        monkeypatch.setattr(atomic_files, "_fsync_file", filling)


def small_model(t_final: float = 0.6) -> Model:
    """4 x 4 squares, three steps, fields at 0.4 and t_final, a series row at every step, a checkpoint every second."""
    return Model(physics=["chemotaxis"], parameters={"m0": 0.75}, mesh=rectangle((0.0, 0.0), (4.0, 4.0), cells=(4, 4)),
                 dt=0.2, t_final=t_final, output={"pictures": False, "times": [0.4, t_final], "series_every": 1},
                 checkpoint={"every_steps": 2, "every_minutes": 0})


def every_row_written(monkeypatch):
    """series.nc and summary.json rewritten at every row: the same writes in every run, however fast it goes."""
    monkeypatch.setattr(outputs, "SERIES_INTERVAL", 0.0)
    monkeypatch.setattr(outputs, "SUMMARY_INTERVAL", 0.0)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The run no disk stops: its series, and how many files it writes (atomically) in all."""
    out = tmp_path_factory.mktemp("uninterrupted")
    monkeypatch = pytest.MonkeyPatch()
    every_row_written(monkeypatch)
    disk = FillingDisk(monkeypatch, None)
    try:
        small_model().run(out=out)
    finally:
        monkeypatch.undo()
    with xr.open_dataset(out / "series.nc") as series:
        return series.load(), disk.written


def assert_whole(out):
    """Every file the run left reads: what was written before the disk filled stays whole."""
    assert not list(out.rglob(".*tmp-*")), "a failed write left its temporary file"
    if (out / "series.nc").exists():
        with xr.open_dataset(out / "series.nc") as series:
            assert np.all(np.diff(series.time.values) > 0)
    if (out / "summary.json").exists():
        json.loads((out / "summary.json").read_text())
    if (out / "fields.xdmf").exists():
        with meshio.xdmf.TimeSeriesReader(out / "fields.xdmf") as reader:
            reader.read_points_cells()
            for k in range(reader.num_steps):
                reader.read_data(k)
    if (out / "checkpoint.npz").exists():
        checkpoint.read(out / "checkpoint.npz")
    for picture in out.glob("*.png"):
        matplotlib.image.imread(picture)


@pytest.mark.parametrize("once", [False, True], ids=["full", "one-file-too-large"])
def test_a_run_whose_disk_fills_stops_in_one_line_and_continues_once_there_is_room(tmp_path, monkeypatch,
                                                                                   uninterrupted, once):
    """Whichever write the disk refuses first, the run stops there with one StorageError naming the file; until
    2026-12-05 the output was disabled with a warning (the checkpoint skipped) and the run computed on, writing
    nothing, to end "completed" with exit status 0 (example 1a at 20 x 20 into a 40 kB tmpfs: series.nc of one
    row, no checkpoint).  Its files stay whole, and a restart once there is room ends as the run that no disk
    stopped (the checkpoints at the same steps: bit for bit)."""
    reference, writes = uninterrupted
    every_row_written(monkeypatch)
    assert writes >= 15, writes  # config, mesh, 2 field times (4 files), 4 series rows and summaries, 2 checkpoints
    restarted = []
    for room in range(0, writes, 3 if once else 1):  # a third of them: what a full disk adds is the summary's word
        out = tmp_path / f"room{room}"
        disk = FillingDisk(monkeypatch, room, once)
        if once and room == writes - 1:  # the summary saying "completed": written into the room the run held for it
            small_model().run(out=out)
            assert json.loads((out / "summary.json").read_text())["status"] == "completed"
            assert_whole(out)
            continue
        with pytest.raises(StorageError, match=f"cannot write {out}/.*: no space left on device") as stopped:
            small_model().run(out=out)
        assert "\n" not in str(stopped.value)
        assert_whole(out)
        if not (out / "checkpoint.npz").exists():
            assert "it wrote no checkpoint to continue from" in str(stopped.value) or "stopped at" not in str(
                stopped.value), stopped.value
            continue
        summary = json.loads((out / "summary.json").read_text())
        if once:  # a full disk takes no summary either: it says "running", and a restart goes on all the same
            assert summary["status"] == f"stopped at t = {summary['time']:g}: {str(stopped.value).split(';')[0]}"
            continue  # the restart is the full disk's
        assert (f"Model.run(out={str(out)!r}, restart=True) continues it from its checkpoint at t = "
                in str(stopped.value)), stopped.value  # from Python, in Python's words
        disk.room = None  # space freed
        small_model().run(out=out, restart=True)
        restarted.append(room)
        with xr.open_dataset(out / "series.nc") as series:
            np.testing.assert_array_equal(series.time.values, reference.time.values)
            for name in ("m_integral", "m_min", "m_max", "f_integral"):
                np.testing.assert_array_equal(series[name].values, reference[name].values, err_msg=name)
        assert json.loads((out / "summary.json").read_text())["status"] == "completed"
    assert once or len(restarted) >= 3, restarted  # the rooms that stop after a checkpoint, and continue


#: A small run that writes every kind of file: 8 x 8 squares, five steps, pictures at 0.4 and 1, checkpoints.
PICTURED = SMALL_CONFIG.replace("pictures = false\n", "times = [0.4, 1.0]\nseries_every = 1\n") + """
[checkpoint]
every_steps = 2
"""


#: kB of disk -> the file that no longer fits (measured 2026-12-05: 4 series.nc at the start, 48 the first picture,
#: 200 the second checkpoint, 260 the pictures' grid at the end): any of them is one line and whole files
@pytest.mark.parametrize("ranks, kilobytes", [(1, 4), (1, 48), (1, 260), (2, 200)])
def test_primordia_run_on_a_full_disk_says_so_in_one_line_and_exits_with_status_2(tmp_path, ranks, kilobytes):
    config = tmp_path / "small.toml"
    config.write_text(PICTURED)
    disk, copy = tmp_path / "disk", tmp_path / "copy"
    result = on_a_small_disk(kilobytes, disk, copy, command("run", config, "--out", disk / "run", "--no-progress",
                                                            ranks=ranks), env=environment())
    assert result.returncode != 0, result.stderr
    ours = [line for line in result.stderr.splitlines() if line.startswith("primordia")]
    assert len(ours) == 1 and ours[0].startswith(f"primordia: error: cannot write {disk / 'run'}/"), result.stderr
    assert ours[0].split(": ")[3].startswith("no space left on device"), ours[0]
    assert "Traceback" not in result.stderr and "Exception ignored" not in result.stderr, result.stderr
    if ranks == 1:
        assert result.returncode == 2 and result.stderr.splitlines() == ours, result.stderr
    assert_whole(copy / "run")


@pytest.mark.parametrize("code, reason", [(errno.ENOSPC, "no space left on device"),
                                          (errno.EDQUOT, "disk quota exceeded"),
                                          (errno.EROFS, "read-only file system")])
def test_a_write_the_file_system_refuses_is_one_storage_error_naming_the_file(tmp_path, code, reason):
    """Whatever library wrote (and however it re-raised the OSError), and the previous file stays."""
    path = tmp_path / "series.nc"
    path.write_text("the previous, whole file")
    with pytest.raises(StorageError) as refused:
        with atomic_files.atomic_path(path) as temporary:
            temporary.write_text("half a")
            try:
                raise OSError(code, os.strerror(code))
            except OSError as error:
                raise RuntimeError("a library's own words") from error
    assert str(refused.value) == f"cannot write {path}: {reason}"
    assert path.read_text() == "the previous, whole file" and list(tmp_path.iterdir()) == [path]


def test_a_folder_turned_read_only_is_a_storage_error(tmp_path, monkeypatch):
    """A run's folder remounted read-only mid-run (as a failing disk is): os.access says no, even to root, and the
    output was disabled with "directory ... is not writable" while the run went on to end "completed"."""
    monkeypatch.setattr(atomic_files.os, "access", lambda path, mode: False)
    monkeypatch.setattr(atomic_files.os, "statvfs", lambda path: os.statvfs_result((0,) * 8 + (os.ST_RDONLY, 255)))
    with pytest.raises(StorageError, match=f"cannot write {tmp_path / 'summary.json'}: read-only file system$"):
        atomic_files.atomic_write_text(tmp_path / "summary.json", "{}")


def test_an_output_that_fails_otherwise_is_still_disabled_and_the_run_goes_on(tmp_path, monkeypatch):
    """Only a file system that takes no more stops a run: a picture that cannot be drawn does not."""
    def broken(*args, **kwargs):
        raise ValueError("a drawing bug")

    monkeypatch.setattr(outputs, "plot_field", broken)
    model = Model(physics=["chemotaxis"], parameters={"m0": 0.75}, mesh=rectangle((0.0, 0.0), (4.0, 4.0), cells=(4, 4)),
                  dt=0.2, t_final=0.4, output={"times": [0.4]})
    sim = model.run(out=tmp_path / "run")
    assert sim.status == "completed" and "pictures" not in [output.name for output in sim.outputs]


def test_primordia_stability_on_a_full_disk_says_so_in_one_line(tmp_path):
    """Until 2026-12-05 a traceback ending in "OSError: [Errno 28] No space left on device", exit status 1."""
    disk, copy = tmp_path / "disk", tmp_path / "copy"
    result = on_a_small_disk(60, disk, copy, [*primordia_command(), "stability", str(EXAMPLES / "ex01a.toml"),
                                              "--out", str(disk / "stability")])
    assert_one_line_error(result, f"cannot write {disk / 'stability'}/dispersion.png: no space left on device")
    with xr.open_dataset(copy / "stability" / "dispersion.nc") as written_before:  # whole
        assert written_before.sizes


def test_primordia_analyse_on_a_full_disk_says_so_in_one_line(tmp_path, small_config):
    """Until 2026-12-05 a traceback ending in "OSError: [Errno 28] No space left on device", exit status 1."""
    config = small_config(PICTURED.replace("times = [0.4, 1.0]", "times = [1.0]"))
    ran = subprocess.run([*primordia_command(), "run", str(config), "--out", str(tmp_path / "run"), "--no-progress",
                          "--set", "output.pictures=false"], capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stderr
    (tmp_path / "run" / "checkpoint.npz").unlink()  # analyse reads the fields: a smaller disk fills sooner
    disk, copy = tmp_path / "disk", tmp_path / "copy"
    copied = f'cp -a "{tmp_path / "run"}" "{disk}/run" && exec "$@"'  # the run's files: 40 of the 72 kB
    result = on_a_small_disk(72, disk, copy, ["sh", "-c", copied, "sh", *primordia_command(), "analyse",
                                              str(disk / "run"), "--species", "m"])
    assert_one_line_error(result, f"cannot write {disk / 'run'}/metrics_m.png: no space left on device")
    assert not list((copy / "run").glob(".*tmp-*"))
    with xr.open_dataset(copy / "run" / "metrics.nc") as written_before:  # whole
        assert written_before.sizes


def test_a_restart_whose_missed_snapshot_fills_the_disk_says_why_it_stopped(tmp_path, monkeypatch):
    """A restart at an output time the run did not write (here one it adds, 0.4) writes those fields in setup();
    a full disk there raised out of setup() with summary.json still saying "running", and the next run into the
    folder called the run "killed without a word".  Whichever write of the restart's set-up the disk refuses,
    the summary says why the run stopped, and a restart once there is room writes the fields at 0.4."""
    from primordia.coupling.orchestrator import Simulation

    def model(t_final, times):
        return Model(physics=["chemotaxis"], parameters={"m0": 0.75},
                     mesh=rectangle((0.0, 0.0), (4.0, 4.0), cells=(4, 4)), dt=0.2, t_final=t_final,
                     output={"pictures": False, "times": times}, checkpoint={"every_steps": 2, "every_minutes": 0})

    every_row_written(monkeypatch)
    first = tmp_path / "first"
    model(0.4, [0.2]).run(out=first)
    disk = FillingDisk(monkeypatch, None)
    counted = Simulation(model(0.8, [0.4, 0.8]), out_dir=tmp_path / "counted", existing="restart")
    shutil.copytree(first, tmp_path / "counted")
    counted.setup()
    setup_writes = disk.written
    assert 0.4 in counted.snapshot_times and setup_writes >= 5, setup_writes  # the missed snapshot's writes counted
    stopped_in_snapshot = 0
    for room in range(setup_writes):
        out = tmp_path / f"room{room}"
        shutil.copytree(first, out)
        disk = FillingDisk(monkeypatch, room, once=True)
        sim = Simulation(model(0.8, [0.4, 0.8]), out_dir=out, existing="restart")
        with pytest.raises(StorageError, match=f"cannot write {out}/.*: no space left on device") as stopped:
            sim.setup()
        assert_whole(out)
        status = json.loads((out / "summary.json").read_text())["status"]
        assert status.startswith("stopped at t = 0.4: cannot write "), (room, status)
        assert "killed" not in outputs.existing_run(out)
        assert "continues it from its checkpoint at t = 0.4" in str(stopped.value), stopped.value
        stopped_in_snapshot += "fields" in str(stopped.value)
        disk.room = None  # space freed
        model(0.8, [0.4, 0.8]).run(out=out, restart=True)
        with meshio.xdmf.TimeSeriesReader(out / "fields.xdmf") as reader:
            reader.read_points_cells()
            assert [reader.read_data(k)[0] for k in range(reader.num_steps)] == pytest.approx([0.2, 0.4, 0.8])
    assert stopped_in_snapshot >= 2, stopped_in_snapshot  # fields.h5 and fields.xdmf at 0.4


def test_an_output_directory_a_full_disk_refuses_is_one_line_in_the_words_of_the_writes(tmp_path, small_config):
    """A tmpfs without a free inode (nr_inodes=1: its root): creating the run's folder said "(No space left on
    device)", with a capital, where a refused write says "no space left on device"."""
    from small_disk import small_disks_available

    if small_disks_available() is not None:
        pytest.skip(small_disks_available())
    disk = tmp_path / "disk"
    disk.mkdir()
    script = 'mount -t tmpfs -o size=64k,nr_inodes=1 tmpfs "$1" || exit 90; shift; exec "$@"'
    result = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c", script, "sh", str(disk),
                             *primordia_command(), "run", str(small_config()), "--out", str(disk / "run"),
                             "--no-progress"], capture_output=True, text=True, timeout=300)
    if result.returncode == 90:
        pytest.skip(f"cannot mount a tmpfs here: {result.stderr.strip()}")
    assert_one_line_error(result, f"the output directory {disk / 'run'} cannot be created in {disk} "
                                  f"(no space left on device)")


@pytest.mark.parametrize("code, reason", [(errno.ENOSPC, "no space left on device"),
                                          (errno.EACCES, "permission denied")])
def test_a_folder_that_cannot_be_created_is_said_alike_wherever_it_is_created(tmp_path, monkeypatch, code, reason):
    """The run's claim of its folder said "cannot create the output directory ...: No space left on device",
    make_directory "cannot create the directory ...: no space left on device", or "cannot create output
    directory ...: Permission denied": one wording now, the writes' ("no space left on device")."""
    from primordia.core.errors import PrimordiaError

    real = type(tmp_path).mkdir

    def refused(path, *args, **kwargs):
        if path.name == "refused":
            raise OSError(code, os.strerror(code), str(path))
        return real(path, *args, **kwargs)

    monkeypatch.setattr(type(tmp_path), "mkdir", refused)
    with pytest.raises(PrimordiaError) as made:
        atomic_files.make_directory(tmp_path / "refused")
    assert str(made.value) == f"cannot create the directory {tmp_path / 'refused'}: {reason}"
    with pytest.raises(PrimordiaError) as claimed:  # the folder test creates (and removes) a probe beside it
        small_model().run(out=tmp_path / "refused")
    assert str(claimed.value) == str(made.value)


#: kB of disk for a restart of a run at t = 0.4 (92 kB of files) that adds the output time 0.4 and goes on to 0.8
#: (measured 2026-12-05: 100 refuses the fields at 0.4, 108 fields.xdmf at 0.4, 112 the fields at 0.8, 116
#: fields.xdmf at 0.8): whichever write is refused, no room was left for the summary saying so after it
@pytest.mark.parametrize("kilobytes", [100, 104, 108, 112, 116])
def test_a_restart_on_a_disk_that_fills_leaves_a_summary_saying_why(tmp_path, small_config, kilobytes):
    """summary.json is rewritten atomically, which needs room beside the old one: the write the disk refused
    left none, and summary.json kept saying "running" (at 100 and 108 kB: the next run called the run "killed
    without a word").  The run holds room for that last rewrite (SUMMARY_RESERVE), and gives it back."""
    first = tmp_path / "first"
    ran = subprocess.run([*primordia_command(), "run", str(small_config()), "--out", str(first), "--no-progress",
                          "--set", "time.t_final=0.4", "--set", "output.times=[0.2]"],
                         capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stderr
    disk, copy = tmp_path / "disk", tmp_path / "copy"
    copied = f'cp -a "{first}" "{disk}/run" && exec "$@"'
    result = on_a_small_disk(kilobytes, disk, copy, ["sh", "-c", copied, "sh", *primordia_command(), "run",
                                                     "--restart", str(disk / "run"), "--no-progress",
                                                     "--set", "time.t_final=0.8", "--set", "output.times=[0.4,0.8]"])
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith(f"primordia: error: cannot write {disk / 'run'}/"), result.stderr
    status = json.loads((copy / "run" / "summary.json").read_text())["status"]
    assert status.startswith("stopped at t = ") and "no space left on device" in status, status
    assert not [path.name for path in (copy / "run").iterdir() if path.name.startswith(".")]  # nor the reserve
    assert_whole(copy / "run")
