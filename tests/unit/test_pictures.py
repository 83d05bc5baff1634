"""PNG pictures of vertex fields (primordia.core.pictures)."""

from __future__ import annotations

import matplotlib.image
import numpy as np
import pytest

from primordia.core.errors import PrimordiaError
from primordia.core.meshes import box
from primordia.core.pictures import default_columns, plot_field, plot_fields_grid
from file_writers import bump, leftovers, square  # noqa: F401


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


def test_plot_field_of_a_mesh_with_a_sloped_top_draws_its_upper_surface(tmp_path):
    """A tetrahedral mesh whose top is not flat has no face at z = z_max: every picture of the run failed
    ("ValueError: zero-size array to reduction operation maximum") and the pictures output was disabled."""
    from primordia.core.pictures import _plot_surface

    slab = box((0, 0, 0), (2, 1, 1), (4, 2, 2))
    slab.points[:, 2] *= 1.0 + 0.05 * slab.points[:, 0]  # z = 1 at x = 0, 1.1 at x = 2
    values = slab.points[:, 0] + slab.points[:, 1]
    image = read_png(plot_field(tmp_path / "slope.png", slab, values))
    assert distinct_colours(image) > 100
    view = _plot_surface(slab)
    assert view.label == "top, z = 1 to 1.1"
    assert _view_area(view, slab) == pytest.approx(2.0)  # the whole upper surface, seen from above


def test_plot_fields_grid_puts_panels_side_by_side(tmp_path, square):
    snapshots = {f"t = {t}": bump(square, t / 100) for t in (160, 280, 400, 520)}
    row = read_png(plot_fields_grid(tmp_path / "row.png", square, snapshots, title="m"))
    single = read_png(plot_field(tmp_path / "one.png", square, snapshots["t = 160"]))
    assert row.shape[1] > 3 * single.shape[1]
    grid = read_png(plot_fields_grid(tmp_path / "grid.png", square, snapshots, ncols=2, shared_colour_scale=False))
    assert grid.shape[0] > 1.5 * single.shape[0]


@pytest.mark.parametrize("count, columns", [(1, 1), (4, 4), (5, 3), (7, 4), (8, 4), (9, 3), (13, 4)])
def test_many_fields_wrap_into_rows_of_at_most_four(count, columns):
    assert default_columns(count) == columns


def test_all_fields_of_example_2a_are_drawn_in_two_rows(tmp_path, square):
    """Its seven fields were one row of 3,234 x 462 pixels: each panel too small to read on a page."""
    fields = {f"field {i}": bump(square, i / 10) for i in range(7)}
    row = read_png(plot_fields_grid(tmp_path / "row.png", square, fields, ncols=7, shared_colour_scale=False))
    grid = read_png(plot_fields_grid(tmp_path / "grid.png", square, fields, shared_colour_scale=False))
    assert grid.shape[1] < 0.65 * row.shape[1] and grid.shape[0] > 1.6 * row.shape[0]


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


def _view_area(view, mesh) -> float:
    xy = view.at_points(mesh.points[:, view.axes])
    corners = xy[view.triangles]
    edges = corners[:, 1:] - corners[:, :1]
    return float(0.5 * np.abs(edges[:, 0, 0] * edges[:, 1, 1] - edges[:, 0, 1] * edges[:, 1, 0]).sum())


@pytest.mark.parametrize("shift", [0.0, 0.15], ids=["structured-box", "interior-vertices-moved"])
def test_the_slice_of_a_3d_mesh_is_the_whole_cross_section_with_fields_linear_on_it(shift):
    """A mesh whose faces do not lie in the middle plane (any unstructured one) was drawn as the few faces
    that did: two scattered triangles of the 4 x 1 cross-section, white elsewhere."""
    from primordia.core.mesh_data import MeshData
    from primordia.core.pictures import _slice_surface

    slab = box((0, 0, 0), (4, 4, 1), (4, 4, 2))
    points = slab.points.copy()
    interior = np.all((points > 1e-9) & (points < np.array([4, 4, 1]) - 1e-9), axis=1)
    points[interior, 1] += shift * np.random.default_rng(0).uniform(-1, 1, np.count_nonzero(interior))
    mesh = MeshData(points, slab.cells, slab.boundaries)
    view = _slice_surface(mesh)
    assert view.label == "slice y = 2"
    assert _view_area(view, mesh) == pytest.approx(4.0, rel=1e-12)
    cut = view.at_points(mesh.points)
    np.testing.assert_allclose(cut[:, 1], 2.0, atol=1e-12)  # every drawn point lies in the plane
    linear = mesh.points @ np.array([1.0, 3.0, 2.0])
    np.testing.assert_allclose(view.at_points(linear), cut @ np.array([1.0, 3.0, 2.0]), atol=1e-12)


def test_the_snapshots_of_a_growing_tissue_are_drawn_to_one_scale_inside_the_picture(tmp_path, square,
                                                                                    monkeypatch):
    """Each snapshot was fitted to its own deformed extent: the earlier, smaller tissue was drawn larger than
    the later one, and the constrained layout put that panel's x label below the picture's edge (example 2a at
    t = 1 and 2)."""
    from matplotlib.figure import Figure

    drawn = []
    save = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda figure, *args, **kwargs: (drawn.append(figure),
                                                                             save(figure, *args, **kwargs))[1])
    x, y = square.points.T
    growths = {"m, t = 1": (0.5, 0.1), "m, t = 2": (0.8, 0.3)}  # stretch along x, a bend that grows with it
    displacements = {key: np.column_stack([s * x * (1 + y), b * np.sin(np.pi * x) * (1 - y)])
                     for key, (s, b) in growths.items()}
    plot_fields_grid(tmp_path / "m_snapshots.png", square, {key: bump(square, 0.0) for key in growths},
                     title="m at the snapshot times", displacements=displacements)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    (figure,) = drawn
    renderer = FigureCanvasAgg(figure).get_renderer()
    figure.draw(renderer)  # the constrained layout, as when it was saved
    panels = [ax for ax in figure.axes if ax.get_label() != "<colorbar>"]
    assert len(panels) == 2
    assert panels[0].get_xlim() == panels[1].get_xlim() and panels[0].get_ylim() == panels[1].get_ylim()
    for ax in panels:
        drawn_box = ax.get_tightbbox(renderer)  # with its title and axis labels
        assert drawn_box.y0 >= 0 and drawn_box.x0 >= 0 and drawn_box.y1 <= figure.bbox.y1, ax.get_title()


def test_a_long_title_is_wrapped_inside_the_picture(tmp_path, square, monkeypatch):
    """final_fields.png of a run that failed is titled by its error: one line of 250 characters ran off both
    sides of the picture (example 2a's Newton failure: "t = 0 (stopped at t = 0: step 1 ... options under
    -poroelast" was what showed of it)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    drawn = []
    save = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda figure, *args, **kwargs: (drawn.append(figure),
                                                                             save(figure, *args, **kwargs))[1])
    status = ("stopped at t = 0: step 1 (t = 0 -> 40): poroelastic_growth (fields u, psi, p): Newton did not "
              "converge: DIVERGED_MAX_IT after 2 iterations, residual 6.409e+02 from 9.312e+02; options under "
              "-poroelastic_growth_")
    for count in (1, 4):
        fields = {f"field {i}": bump(square, i / 10) for i in range(count)}
        plot_fields_grid(tmp_path / f"final_fields_{count}.png", square, fields, shared_colour_scale=False,
                         title=f"all fields at t = 0 ({status})")
    for figure in drawn:
        renderer = FigureCanvasAgg(figure).get_renderer()
        figure.draw(renderer)
        title = figure._suptitle
        assert title.get_text().replace("\n", " ") == f"all fields at t = 0 ({status})"
        drawn_box = title.get_window_extent(renderer)
        assert drawn_box.x0 >= 0 and drawn_box.x1 <= figure.bbox.x1 and drawn_box.y1 <= figure.bbox.y1
        for ax in figure.axes:  # the panels make room for it
            assert ax.get_tightbbox(renderer).y1 <= drawn_box.y0 + 1
