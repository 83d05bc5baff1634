"""What the tests of primordia's file writers share: a writer that dies, its leftovers, a small mesh."""

import meshio
import numpy as np
import pytest

from primordia.core.meshes import rectangle


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
