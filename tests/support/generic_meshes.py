"""Meshes without the symmetries of structured ones, so backend comparisons test the general case."""

import numpy as np

from primordia.core.mesh_data import MeshData


def perturbed(data: MeshData, amplitude: float, seed: int = 1) -> MeshData:
    """The mesh with its interior vertices moved at random: generic, non-right cells."""
    rng = np.random.default_rng(seed)
    points = data.points.copy()
    low, high = points.min(axis=0), points.max(axis=0)
    interior = np.all((points > low + 1e-9) & (points < high - 1e-9), axis=1)
    points[interior] += amplitude * rng.uniform(-1.0, 1.0, size=(interior.sum(), data.gdim))
    return MeshData(points, data.cells, data.boundaries)
