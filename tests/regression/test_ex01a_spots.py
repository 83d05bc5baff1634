"""Example 1a lays down rows of spots behind the priming wave (seed Figure 5.1), with m >= 0.

Behind the wave, a stripe of cells forms and then breaks into spots along it.  A
discretisation that smears the chemotactic sensitivity at stripe edges can keep
the stripes straight (an earlier edge average of chi did exactly that), so this
checks the pattern itself: along the row through the first stripe, m must vary
strongly in x (spots), and stay non-negative everywhere.
"""

import meshio
import numpy as np
import xarray as xr

from primordia.model import Model

RESOLUTION = ["mesh.cells=[86,86]", "time.t_final=300", "output.times=[300]", "output.pictures=false"]


def test_rows_of_spots_form_behind_the_wave(tmp_path):
    Model.from_file("examples/ex01a.toml", RESOLUTION).run(out=tmp_path)
    reader = meshio.xdmf.TimeSeriesReader(tmp_path / "fields.xdmf")
    points, _ = reader.read_points_cells()
    _, fields, _ = reader.read_data(reader.num_steps - 1)
    m = fields["m"]
    lower = (points[:, 1] > 1.0) & (points[:, 1] < 5.0)  # first row of buds near y = 3.6 (not the boundary layer)
    row_y = points[lower][np.argmax(m[lower]), 1]
    row = np.isclose(points[:, 1], row_y)
    along_x = m[row]
    print(f"row y = {row_y:.2f}: m mean {along_x.mean():.3f}, std {along_x.std():.3f}, "
          f"min {along_x.min():.3f}, max {along_x.max():.3f}")
    assert along_x.max() > 2.0 * 0.75  # cells have gathered well above m0
    assert along_x.std() > 0.3 * along_x.mean()  # spots, not a uniform stripe
    assert along_x.min() < 0.5 * along_x.max()  # gaps between the spots
    series = xr.open_dataset(tmp_path / "series.nc")
    assert float(series["m_min"].min()) >= 0.0
