"""Mesh generators, the meshio reader and the [mesh] config table (primordia.core.meshes)."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest

from primordia.core.errors import ConfigError, MeshError
from primordia.core.mesh_data import MeshData
from primordia.core.meshes import (
    box,
    exterior_facets,
    mesh_from_config,
    read_mesh,
    rectangle,
    signed_volumes,
)

# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def facet_measures(mesh: MeshData, name: str) -> np.ndarray:
    """Lengths (2D) or areas (3D) of the facets of boundary ``name``."""
    x = mesh.points[mesh.boundaries[name]]
    if mesh.gdim == 2:
        return np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
    return 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)


def assert_conforming(mesh: MeshData) -> None:
    """Every facet is shared by at most two cells, and the exterior ones are exactly the named boundaries."""
    cells = mesh.cells
    facets = np.vstack([np.delete(cells, i, axis=1) for i in range(cells.shape[1])])
    _, counts = np.unique(np.sort(facets, axis=1), axis=0, return_counts=True)
    assert counts.max() == 2
    named = np.vstack(list(mesh.boundaries.values()))
    exterior = exterior_facets(cells)
    assert len(named) == len(exterior)
    assert {tuple(f) for f in np.sort(named, axis=1)} == {tuple(f) for f in np.sort(exterior, axis=1)}


def gmsh_mesh_from(mesh: MeshData, volume_tag: int = 100) -> meshio.Mesh:
    """A meshio.Mesh with Gmsh physical tags and names for each boundary of ``mesh``."""
    facet_type = "line" if mesh.gdim == 2 else "triangle"
    facets = np.vstack(list(mesh.boundaries.values()))
    tags = np.concatenate([np.full(len(f), mesh.boundary_id(n)) for n, f in mesh.boundaries.items()])
    points = np.column_stack([mesh.points, np.zeros(mesh.num_vertices)]) if mesh.gdim == 2 else mesh.points
    field_data = {name: np.array([tag, mesh.gdim - 1]) for name, tag in mesh.boundary_ids.items()}
    field_data["tissue"] = np.array([volume_tag, mesh.gdim])
    return meshio.Mesh(
        points,
        [(facet_type, facets), (mesh.cell_type, mesh.cells)],
        cell_data={
            "gmsh:physical": [tags, np.full(mesh.num_cells, volume_tag)],
            "gmsh:geometrical": [tags, np.ones(mesh.num_cells, dtype=int)],
        },
        field_data=field_data,
    )


#: A unit square of two triangles in Gmsh 4.1 ASCII, written by hand (not by meshio),
#: with physical curves "left" (x = 0) and "right" (x = 1) and a physical surface.
GMSH41_SQUARE = """$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
3
1 1 "left"
1 2 "right"
2 3 "tissue"
$EndPhysicalNames
$Entities
0 2 1 0
1 0 0 0 0 1 0 1 1 0
2 1 0 0 1 1 0 1 2 0
1 0 0 0 1 1 0 1 3 0
$EndEntities
$Nodes
1 4 1 4
2 1 0 4
1
2
3
4
0 0 0
1 0 0
1 1 0
0 1 0
$EndNodes
$Elements
3 4 1 4
1 1 1 1
1 1 4
1 2 1 1
2 2 3
2 1 2 2
3 1 2 3
4 1 3 4
$EndElements
"""

#: The same square in Gmsh 2.2 ASCII plus a fifth node no element uses, with the
#: second triangle listed clockwise and the "bottom" boundary given no name.
GMSH22_SQUARE = """$MeshFormat
2.2 0 8
$EndMeshFormat
$PhysicalNames
2
1 1 "left"
2 3 "tissue"
$EndPhysicalNames
$Nodes
5
1 0 0 0
2 1 0 0
3 1 1 0
4 0 1 0
5 7 7 0
$EndNodes
$Elements
4
1 1 2 1 1 1 4
2 1 2 7 2 1 2
3 2 2 3 1 1 2 3
4 2 2 3 1 1 4 3
$EndElements
"""

#: The unit square as Gmsh 2.2 writes it with ``Mesh.SaveAll = 1``: the elements of curves in no physical
#: group carry physical tag 0, here the bottom edge and the diagonal, a curve embedded in the surface.
GMSH22_SAVE_ALL = """$MeshFormat
2.2 0 8
$EndMeshFormat
$PhysicalNames
2
1 1 "left"
2 3 "tissue"
$EndPhysicalNames
$Nodes
4
1 0 0 0
2 1 0 0
3 1 1 0
4 0 1 0
$EndNodes
$Elements
5
1 1 2 1 4 4 1
2 1 2 0 1 1 2
3 1 2 0 5 1 3
4 2 2 3 1 1 2 3
5 2 2 3 1 1 3 4
$EndElements
"""

#: A Gmsh 2.2 file with one node and no elements.
GMSH22_NO_ELEMENTS = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 0\n$EndNodes\n$Elements\n0\n$EndElements\n"


# ---------------------------------------------------------------------------
# rectangle
# ---------------------------------------------------------------------------


def test_seed_rectangle_has_the_papers_58482_triangles():
    mesh = rectangle((0, 0), (20, 20), (171, 171), diagonal="right")
    assert mesh.num_cells == 58_482
    assert mesh.num_vertices == 172 * 172
    assert mesh.cell_volumes().sum() == pytest.approx(400.0, rel=1e-12)
    assert signed_volumes(mesh.points, mesh.cells).min() > 0
    for name in ("left", "right", "bottom", "top"):
        assert facet_measures(mesh, name).sum() == pytest.approx(20.0, rel=1e-12)


@pytest.mark.parametrize(
    "diagonal, triangles_per_square, extra_vertices",
    [("right", 2, 0), ("left", 2, 0), ("crossed", 4, 1)],
)
def test_rectangle_counts_area_orientation_and_boundaries(diagonal, triangles_per_square, extra_vertices):
    lower, upper, (nx, ny) = (-1.0, 2.0), (3.0, 3.5), (5, 3)
    mesh = rectangle(lower, upper, (nx, ny), diagonal=diagonal)
    assert mesh.gdim == 2
    assert mesh.num_cells == triangles_per_square * nx * ny
    assert mesh.num_vertices == (nx + 1) * (ny + 1) + extra_vertices * nx * ny
    assert mesh.cell_volumes().sum() == pytest.approx(4.0 * 1.5)
    assert signed_volumes(mesh.points, mesh.cells).min() > 0, "every triangle counter-clockwise"
    assert list(mesh.boundaries) == ["left", "right", "bottom", "top"]
    assert mesh.boundary_ids == {"left": 1, "right": 2, "bottom": 3, "top": 4}
    expected = {"left": (0, -1.0, 1.5), "right": (0, 3.0, 1.5), "bottom": (1, 2.0, 4.0), "top": (1, 3.5, 4.0)}
    for name, (axis, plane, length) in expected.items():
        assert np.all(mesh.points[mesh.boundaries[name], axis] == plane)
        assert facet_measures(mesh, name).sum() == pytest.approx(length)
    assert len(mesh.boundaries["left"]) == ny and len(mesh.boundaries["bottom"]) == nx
    assert_conforming(mesh)


@pytest.mark.parametrize("diagonal, cut", [("right", {(0, 0), (1, 1)}), ("left", {(1, 0), (0, 1)})])
def test_rectangle_diagonal_direction_follows_dolfinx(diagonal, cut):
    mesh = rectangle((0, 0), (1, 1), (1, 1), diagonal=diagonal)
    shared = set(map(int, mesh.cells[0])) & set(map(int, mesh.cells[1]))
    assert {tuple(mesh.points[v]) for v in shared} == cut


def test_rectangle_vertices_run_x_fastest():
    mesh = rectangle((0, 0), (2, 1), (2, 1))
    np.testing.assert_array_equal(mesh.points, [[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1]])


# ---------------------------------------------------------------------------
# box
# ---------------------------------------------------------------------------


def test_box_volume_counts_orientation_and_boundaries():
    lower, upper, (nx, ny, nz) = (0.0, -1.0, 1.0), (2.0, 2.0, 1.5), (4, 3, 2)
    mesh = box(lower, upper, (nx, ny, nz))
    assert mesh.gdim == 3 and mesh.cell_type == "tetra"
    assert mesh.num_cells == 6 * nx * ny * nz
    assert mesh.num_vertices == (nx + 1) * (ny + 1) * (nz + 1)
    assert mesh.cell_volumes().sum() == pytest.approx(2.0 * 3.0 * 0.5)
    assert signed_volumes(mesh.points, mesh.cells).min() > 0
    assert list(mesh.boundaries) == ["left", "right", "bottom", "top", "front", "back"]
    expected = {
        "left": (0, 0.0, 3.0 * 0.5),
        "right": (0, 2.0, 3.0 * 0.5),
        "bottom": (1, -1.0, 2.0 * 0.5),
        "top": (1, 2.0, 2.0 * 0.5),
        "front": (2, 1.0, 2.0 * 3.0),
        "back": (2, 1.5, 2.0 * 3.0),
    }
    for name, (axis, plane, area) in expected.items():
        assert np.all(mesh.points[mesh.boundaries[name], axis] == plane), name
        assert facet_measures(mesh, name).sum() == pytest.approx(area), name
    assert len(mesh.boundaries["front"]) == 2 * nx * ny
    assert_conforming(mesh)


# ---------------------------------------------------------------------------
# generator input errors
# ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"cells": (0, 3)}, "positive integers"),
        ({"cells": (2.5, 3)}, "positive integers"),
        ({"cells": (2, 3, 4)}, "list of 2 positive integers"),
        ({"lower": (0, 0), "upper": (1, 0)}, "upper corner must exceed the lower corner along y"),
        ({"lower": (0,), "upper": (1, 1)}, "lower corner must be a list of 2 numbers"),
        ({"upper": (1, float("nan"))}, "must be finite"),
        ({"diagonal": "diagonal"}, "unknown rectangle diagonal 'diagonal'"),
    ],
)
def test_rectangle_rejects_bad_input_in_one_line(kwargs, message):
    with pytest.raises(MeshError, match=message) as error:
        rectangle(**kwargs)
    assert "\n" not in str(error.value)


def test_box_rejects_upper_below_lower():
    with pytest.raises(MeshError, match="along z"):
        box((0, 0, 1), (1, 1, 0), (1, 1, 1))


@pytest.mark.parametrize("make", [lambda: box((0, 0, 0), (4, 4, 1e-12), (4, 4, 2)),
                                  lambda: rectangle((0, 0), (4, 1e-14), (4, 4))], ids=["box", "rectangle"])
def test_a_generated_mesh_too_thin_for_its_width_is_refused_as_a_file_is(make):
    # a 1e-12 thick slab passed, and its run failed at the first step after retrying down to dt_min
    with pytest.raises(MeshError, match="degenerate") as error:
        make()
    assert "\n" not in str(error.value)
    assert box((0, 0, 0), (4, 4, 1e-6), (4, 4, 2)).num_cells == 192  # thin, but a mesh


# ---------------------------------------------------------------------------
# read_mesh
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("binary", [False, True])
def test_read_gmsh22_written_by_meshio_keeps_names_and_drops_z(tmp_path, binary):
    original = rectangle((0, 0), (2, 1), (4, 2))
    path = tmp_path / "square.msh"
    meshio.write(path, gmsh_mesh_from(original), file_format="gmsh22", binary=binary)
    mesh = read_mesh(path)
    assert mesh.gdim == 2
    np.testing.assert_array_equal(mesh.points, original.points)
    np.testing.assert_array_equal(mesh.cells, original.cells)
    assert mesh.boundary_ids == original.boundary_ids
    for name, facets in original.boundaries.items():
        np.testing.assert_array_equal(mesh.boundaries[name], facets)
    assert "tissue" not in mesh.boundaries


def test_read_hand_written_gmsh41(tmp_path):
    path = tmp_path / "square41.msh"
    path.write_text(GMSH41_SQUARE)
    mesh = read_mesh(path)
    assert (mesh.gdim, mesh.num_cells, mesh.num_vertices) == (2, 2, 4)
    assert mesh.cell_volumes().sum() == pytest.approx(1.0)
    assert mesh.boundary_ids == {"left": 1, "right": 2}
    assert facet_measures(mesh, "left").sum() == pytest.approx(1.0)
    assert np.all(mesh.points[mesh.boundaries["left"], 0] == 0.0)
    assert np.all(mesh.points[mesh.boundaries["right"], 0] == 1.0)


def test_a_gmsh41_file_naming_an_entity_it_lacks_is_refused_saying_so(tmp_path):
    """meshio's reader fails with KeyError(9): the reason given was the bare key, "(as gmsh: 9; ...)"."""
    path = tmp_path / "entity.msh"
    path.write_text(GMSH41_SQUARE.replace("$Elements\n3 4 1 4\n1 1 1 1\n", "$Elements\n3 4 1 4\n1 9 1 1\n"))
    with pytest.raises(MeshError, match=r"as gmsh: it refers to 9, which it does not define \(KeyError\)") as error:
        read_mesh(path)
    assert "\n" not in str(error.value)


def test_read_gmsh22_drops_unused_nodes_reorients_and_names_unnamed_tags(tmp_path):
    path = tmp_path / "square22.msh"
    path.write_text(GMSH22_SQUARE)
    mesh = read_mesh(path)
    assert mesh.num_vertices == 4, "the node no element uses is dropped"
    assert signed_volumes(mesh.points, mesh.cells).min() > 0, "the clockwise triangle is flipped"
    assert mesh.boundary_ids == {"left": 1, "boundary_7": 2}
    np.testing.assert_array_equal(mesh.points[mesh.boundaries["boundary_7"]], [[[0, 0], [1, 0]]])


def test_read_gmsh22_saved_with_all_elements_names_only_physical_groups(tmp_path):
    """Physical tag 0 is Gmsh's "in no physical group": it was read as a group 'boundary_0', and the mesh refused
    for that group's facets inside the domain (the embedded diagonal), a group the file never defined."""
    path = tmp_path / "save_all.msh"
    path.write_text(GMSH22_SAVE_ALL)
    mesh = read_mesh(path)
    assert (mesh.num_cells, mesh.num_vertices) == (2, 4)
    assert mesh.boundary_ids == {"left": 1}
    np.testing.assert_array_equal(mesh.points[mesh.boundaries["left"]], [[[0, 1], [0, 0]]])


def test_read_3d_gmsh_box_with_facet_names(tmp_path):
    original = box((0, 0, 0), (1, 2, 3), (2, 2, 2))
    path = tmp_path / "box.msh"
    meshio.write(path, gmsh_mesh_from(original), file_format="gmsh22", binary=False)
    mesh = read_mesh(path)
    assert mesh.gdim == 3 and mesh.num_cells == original.num_cells
    assert mesh.cell_volumes().sum() == pytest.approx(6.0)
    assert list(mesh.boundaries) == list(original.boundaries)
    assert facet_measures(mesh, "front").sum() == pytest.approx(2.0)
    assert facet_measures(mesh, "left").sum() == pytest.approx(6.0)


@pytest.mark.parametrize("suffix", [".xdmf", ".vtu"])
def test_read_other_formats_without_boundary_names(tmp_path, suffix):
    original = rectangle((0, 0), (1, 1), (3, 3))
    path = tmp_path / f"plain{suffix}"
    meshio.write(path, meshio.Mesh(original.points, [("triangle", original.cells)]))
    mesh = read_mesh(path)
    assert mesh.boundaries == {}
    np.testing.assert_allclose(mesh.points, original.points)
    np.testing.assert_array_equal(mesh.cells, original.cells)


def test_read_a_flat_mesh_whose_z_carries_round_off(tmp_path):
    """A plane mesh rotated or moved by another tool keeps z = 0 only to round-off: z of 1e-17 refused it as a
    surface mesh, "not in a z = constant plane"."""
    original = rectangle((0, 0), (4, 4), (3, 3))
    z = 1e-17 * np.random.default_rng(1).uniform(-1.0, 1.0, original.num_vertices)
    path = tmp_path / "flat.vtu"
    meshio.write(path, meshio.Mesh(np.column_stack([original.points, z]), [("triangle", original.cells)]))
    mesh = read_mesh(path)
    assert mesh.gdim == 2
    np.testing.assert_array_equal(mesh.points, original.points)


def test_a_mesh_file_too_large_for_the_memory_is_refused_as_a_generated_mesh_is(tmp_path, monkeypatch):
    """The generators refused a mesh that needs more memory than is available; a file of it was read and run
    until the machine ran out of memory."""
    import primordia.core.meshes as meshes

    path = write_vtu(tmp_path / "big.vtu", UNIT_SQUARE, [("triangle", [[0, 1, 2], [0, 2, 3]])])
    monkeypatch.setattr(meshes, "available_memory", lambda: 3_000)  # bytes: one triangle's worth
    with pytest.raises(MeshError, match="a mesh of 2 cells needs at least") as error:
        read_mesh(path)
    assert "\n" not in str(error.value)


def test_a_model_needing_more_memory_per_cell_than_the_mesh_is_refused_before_its_run(tmp_path, monkeypatch):
    """3D growth needs 125-128 kB per tetrahedron; 80 x 80 x 8 boxes passed the mesh's 4 kB floor and --dry-run
    on a machine with 23 GB, where the run would need about 38 GB.  Checked where a run starts (and by a dry
    run), over the machines Open MPI says the ranks span; not by a linear analysis of the model."""
    import primordia.core.meshes as meshes
    from primordia.coupling.orchestrator import Simulation
    from primordia.model import Model

    model = Model.from_file(Path(__file__).resolve().parents[2] / "examples" / "ex04_small.toml", ["mesh.cells=[4,4,2]"])  # 192 tetrahedra
    monkeypatch.setattr(meshes, "available_memory", lambda: 10_000_000)  # 10 MB: 52 kB a tetrahedron
    message = ("a mesh of 192 cells needs at least 18.3 MB of memory for physics poroelastic_growth (100 kB per "
               "cell), more than the 9.54 MB available: use fewer cells or more nodes")
    with pytest.raises(MeshError) as error:
        Simulation(model, out_dir=tmp_path / "out").check_choices()
    assert str(error.value) == message
    with pytest.raises(MeshError):
        Simulation(model, out_dir=tmp_path / "out").setup()
    assert not (tmp_path / "out").exists()  # nothing written
    monkeypatch.setattr("primordia.core.errors.mpi_world", lambda: (0, 4))
    model.check_affordable()  # 4 ranks, and no word on how many share a machine: not checked
    monkeypatch.setenv("OMPI_COMM_WORLD_LOCAL_SIZE", "2")
    monkeypatch.setattr(meshes, "available_memory", lambda: 9_000_000)  # 2 machines of 9 MB each: 18 MB
    with pytest.raises(MeshError, match="more than the 17.2 MB available on its 2 nodes"):
        model.check_affordable()
    monkeypatch.setattr(meshes, "available_memory", lambda: 10_000_000)
    model.check_affordable()  # 2 machines of 10 MB each


#: A mesh and its facet tags as dolfinx's XDMFFile writes them (write_mesh, then write_meshtags): two grids,
#: the tags' sharing the mesh's geometry.
DOLFINX_XDMF = """<?xml version="1.0"?>
<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>
<Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude">
  <Domain>
    <Grid Name="mesh" GridType="Uniform">
      <Topology TopologyType="{cell}" NumberOfElements="{cells}" NodesPerElement="{corners}">
        <DataItem Dimensions="{cells} {corners}" NumberType="Int" Format="HDF">tissue.h5:/Mesh/mesh/topology</DataItem>
      </Topology>
      <Geometry GeometryType="{geometry}">
        <DataItem Dimensions="{points} {gdim}" Format="HDF">tissue.h5:/Mesh/mesh/geometry</DataItem>
      </Geometry>
    </Grid>
    <Grid Name="facet_tags" GridType="Uniform">
      <xi:include xpointer="xpointer(/Xdmf/Domain/Grid/Geometry)" />
      <Topology TopologyType="{facet}" NumberOfElements="{facets}" NodesPerElement="{gdim}">
        <DataItem Dimensions="{facets} {gdim}" NumberType="Int" Format="HDF"
          >tissue.h5:/MeshTags/facet_tags/topology</DataItem>
      </Topology>
      <Attribute Name="facet_tags" AttributeType="Scalar" Center="Cell">
        <DataItem Dimensions="{facets} 1" Format="HDF">tissue.h5:/MeshTags/facet_tags/Values</DataItem>
      </Attribute>
    </Grid>
  </Domain>
</Xdmf>
"""


def write_dolfinx_xdmf(directory, original: MeshData):
    """``original`` and its boundaries' facet tags (10 x its boundary ids) in directory/tissue.xdmf and .h5."""
    import h5py

    facets = np.vstack(list(original.boundaries.values()))
    tags = np.concatenate([np.full(len(f), 10 * original.boundary_id(n)) for n, f in original.boundaries.items()])
    with h5py.File(directory / "tissue.h5", "w") as h5:
        h5["Mesh/mesh/topology"], h5["Mesh/mesh/geometry"] = original.cells, original.points
        h5["MeshTags/facet_tags/topology"], h5["MeshTags/facet_tags/Values"] = facets, tags
    gdim = original.gdim
    (directory / "tissue.xdmf").write_text(DOLFINX_XDMF.format(
        cell=["Triangle", "Tetrahedron"][gdim - 2], facet=["PolyLine", "Triangle"][gdim - 2], gdim=gdim,
        geometry=["XY", "XYZ"][gdim - 2], cells=original.num_cells, corners=gdim + 1, points=original.num_vertices,
        facets=len(facets)))
    return directory / "tissue.xdmf"


@pytest.mark.parametrize("make", [lambda: rectangle((0, 0), (2, 1), (4, 2)),
                                  lambda: box((0, 0, 0), (1, 2, 3), (2, 2, 2))], ids=["triangles", "tetrahedra"])
def test_read_an_xdmf_mesh_with_facet_tags_as_dolfinx_writes_it(tmp_path, make):
    """meshio reads one grid per XDMF file: the mesh and facet tags of dolfinx's XDMFFile (the FEniCSx way to give
    a mesh its boundary markers) were refused whole, "XDMF reader: Only supports one grid right now"."""
    original = make()
    mesh = read_mesh(write_dolfinx_xdmf(tmp_path, original))
    np.testing.assert_array_equal(mesh.points, original.points)
    np.testing.assert_array_equal(mesh.cells, original.cells)
    assert list(mesh.boundaries) == [f"boundary_{10 * i}" for i in original.boundary_ids.values()]
    for name, facets in original.boundaries.items():
        np.testing.assert_array_equal(mesh.boundaries[f"boundary_{10 * original.boundary_id(name)}"], facets)


def test_an_xdmf_mesh_with_facet_tags_whose_hdf5_file_is_gone_is_refused_naming_it(tmp_path):
    path = write_dolfinx_xdmf(tmp_path, rectangle((0, 0), (2, 1), (4, 2)))
    (tmp_path / "tissue.h5").unlink()
    with pytest.raises(MeshError, match=r"as xdmf: .*Unable to open file.*tissue\.h5") as error:
        read_mesh(path)
    assert "\n" not in str(error.value)


def test_read_the_mesh_of_a_runs_fields_xdmf(tmp_path):
    """A run's fields.xdmf (a mesh grid and a temporal collection) gives its mesh, as ParaView reads it."""
    from primordia.core.xdmf import XdmfSeries

    original = rectangle((0, 0), (2, 1), (4, 2))
    XdmfSeries(tmp_path, original).write(1.0, {"m": original.points[:, 0]})
    mesh = read_mesh(tmp_path / "fields.xdmf")
    np.testing.assert_array_equal(mesh.points, original.points)
    np.testing.assert_array_equal(mesh.cells, original.cells)
    assert mesh.boundaries == {}


def write_vtu(path, points, cells):
    meshio.write(path, meshio.Mesh(np.asarray(points, dtype=float), cells))
    return path


UNIT_SQUARE = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]


def test_a_gmsh_group_that_shares_its_facets_with_another_is_named_in_a_warning(tmp_path, capsys):
    """Gmsh 4.1 puts an entity in several physical groups; meshio keeps the first, and a facet carries one
    name here: "walls" (both curves, also "left" and "right") went missing without a word."""
    path = tmp_path / "walls.msh"
    path.write_text(GMSH41_SQUARE.replace("$PhysicalNames\n3\n", '$PhysicalNames\n4\n1 4 "walls"\n').replace(
        "1 0 0 0 0 1 0 1 1 0\n2 1 0 0 1 1 0 1 2 0\n", "1 0 0 0 0 1 0 2 1 4 0\n2 1 0 0 1 1 0 2 2 4 0\n"))
    mesh = read_mesh(path)
    assert sorted(mesh.boundaries) == ["left", "right"]
    warning = capsys.readouterr().err
    assert warning.count("\n") == 1 and "physical group 'walls' shares 2 of its 2 facets" in warning, warning
    assert "'walls' is left out" in warning
    path.write_text(GMSH41_SQUARE)
    read_mesh(path)
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize(
    "make_file, message",
    [
        (lambda d: d / "missing.msh", "does not exist"),
        (lambda d: d, "is not a file"),
        (lambda d: (d / "junk.msh").write_text("not a mesh") and d / "junk.msh", "cannot read mesh file"),
        (lambda d: (d / "mesh.txt").write_text("1 2 3") and d / "mesh.txt", "no mesh format with extension '.txt'"),
        (lambda d: write_vtu(d / "q.vtu", UNIT_SQUARE, [("quad", [[0, 1, 2, 3]])]), "no triangle or tetra cells"),
        (
            lambda d: write_vtu(
                d / "mixed.vtu", UNIT_SQUARE + [[2, 0, 0]], [("triangle", [[1, 4, 2]]), ("quad", [[0, 1, 2, 3]])]
            ),
            "unsupported cell types quad",
        ),
        (
            lambda d: write_vtu(
                d / "flat.vtu", [[0, 0], [1, 0], [2, 0], [0, 1]], [("triangle", [[0, 1, 2], [0, 1, 3]])]
            ),
            "1 degenerate",
        ),
        (lambda d: (d / "empty.msh").write_text(GMSH22_NO_ELEMENTS) and d / "empty.msh", "is empty"),
        # meshio's reason was "need at least one array to concatenate" ("Inconsistent data!" in some layouts)
        (lambda d: write_vtu(d / "empty.vtu", UNIT_SQUARE, [("triangle", np.zeros((0, 3), int))]), "is empty"),
        (
            lambda d: write_vtu(d / "surface.vtu", [[0, 0, 0], [1, 0, 0], [0, 1, 1]], [("triangle", [[0, 1, 2]])]),
            "not in a z = constant plane",
        ),
        # the second triangle's own copies of the diagonal's ends: the square cut in two along it, m and the
        # morphogens blind to each other across the cut, accepted without a word
        (
            lambda d: write_vtu(
                d / "cut.vtu", UNIT_SQUARE + [[0, 0, 0], [1, 1, 0]], [("triangle", [[0, 1, 2], [4, 5, 3]])]
            ),
            r"2 vertices at the coordinates of another \(duplicated nodes, e.g. vertex 4 at \(0, 0\), as vertex 0\)",
        ),
    ],
    ids=["missing", "directory", "unreadable", "unknown-format", "quads", "mixed", "degenerate", "empty", "empty-vtu", "surface",
         "duplicated-nodes"],
)
def test_read_mesh_errors_are_one_line(tmp_path, make_file, message):
    path = make_file(tmp_path)
    with pytest.raises(MeshError, match=message) as error:
        read_mesh(path)
    assert "\n" not in str(error.value)


def _with_boundaries(mesh: MeshData, boundaries: dict) -> MeshData:
    return MeshData(mesh.points, mesh.cells, boundaries)


@pytest.mark.parametrize(
    "change, message",
    [
        # an edge between two triangles, tagged "top": fenicsx and skfem both dropped it from the
        # traction's integral without a word
        (lambda m: {**m.boundaries, "top": m.cells[:1, 1:]}, "boundary 'top' has 1 facet inside the domain"),
        # the diagonal of the whole square: fenicsx dropped it silently, skfem refused it
        (lambda m: {**m.boundaries, "top": np.array([[0, m.num_vertices - 1]])},
         "boundary 'top' has 1 facet that no cell has as a side"),
        # the top edge in "left" too: fenicsx gave it one name and skfem the other (two results)
        (lambda m: {**m.boundaries, "left": np.vstack([m.boundaries["left"], m.boundaries["top"]])},
         "3 facets in both boundary 'left' and boundary 'top'"),
    ],
    ids=["interior", "no-side-of-a-cell", "in-two-boundaries"],
)
def test_read_mesh_refuses_named_facets_that_are_not_one_boundarys_exterior_facets(tmp_path, change, message):
    square = rectangle((0, 0), (1, 1), (3, 3))
    path = tmp_path / "tags.msh"
    meshio.write(path, gmsh_mesh_from(_with_boundaries(square, change(square))), file_format="gmsh22")
    with pytest.raises(MeshError, match=message) as error:
        read_mesh(path)
    assert "\n" not in str(error.value)


def test_read_mesh_refuses_named_facets_on_vertices_no_cell_uses(tmp_path):
    """An exporter that gave the top curve nodes of its own (at the coordinates of the cells' nodes): the facets
    were dropped with the unused vertices, 'top' came back empty, and a traction on it was lost without a word."""
    square = rectangle((0, 0), (1, 1), (3, 3))
    top = square.boundaries["top"]
    points = np.vstack([square.points, square.points[np.unique(top)]])
    copies = dict(zip(np.unique(top), square.num_vertices + np.arange(len(np.unique(top)))))
    stray = {**square.boundaries, "top": np.vectorize(copies.get)(top)}
    mesh = gmsh_mesh_from(MeshData(points, square.cells, stray))
    meshio.write(tmp_path / "stray.msh", mesh, file_format="gmsh22")
    with pytest.raises(MeshError, match="boundary 'top' has 3 facets that no cell has as a side") as error:
        read_mesh(tmp_path / "stray.msh")
    assert "\n" not in str(error.value)


def test_read_mesh_keeps_a_boundary_listed_twice_or_reversed(tmp_path):
    square = rectangle((0, 0), (1, 1), (3, 3))
    top = square.boundaries["top"]
    path = tmp_path / "tags.msh"
    twice = {**square.boundaries, "top": np.vstack([top, top[:, ::-1]])}
    meshio.write(path, gmsh_mesh_from(_with_boundaries(square, twice)), file_format="gmsh22")
    mesh = read_mesh(path)
    assert list(mesh.boundaries) == list(square.boundaries)
    assert facet_measures(mesh, "top").sum() == pytest.approx(2.0)  # as given; both backends tag each facet once


# ---------------------------------------------------------------------------
# mesh_from_config
# ---------------------------------------------------------------------------


def test_config_rectangle_is_the_seed_mesh():
    mesh = mesh_from_config(
        {"type": "rectangle", "lower": [0, 0], "upper": [20, 20], "cells": [171, 171], "diagonal": "right"}, "."
    )
    assert mesh.num_cells == 58_482
    assert mesh.cell_volumes().sum() == pytest.approx(400.0)


def test_config_box_defaults_lower_to_origin():
    mesh = mesh_from_config({"type": "box", "upper": [1, 2, 3], "cells": [1, 2, 3]})
    assert mesh.points.min(axis=0).tolist() == [0, 0, 0]
    assert mesh.cell_volumes().sum() == pytest.approx(6.0)


def test_config_file_path_is_relative_to_base_dir(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "square.msh").write_text(GMSH41_SQUARE)
    mesh = mesh_from_config({"type": "file", "path": "meshes/square.msh"}, base_dir=tmp_path)
    assert mesh.boundary_ids == {"left": 1, "right": 2}
    # the table that reads this mesh again from anywhere (a run's config.toml, for a mesh read in Python)
    assert mesh.source() == {"type": "file", "path": str((tmp_path / "meshes" / "square.msh").resolve())}


@pytest.mark.parametrize(
    "table, error, message",
    [
        ({"type": "disc", "cells": [1, 1]}, ConfigError, "type must be one of 'rectangle', 'box', 'file', got 'disc'"),
        ({"upper": [1, 1], "cells": [1, 1]}, ConfigError, "got None"),
        ({"type": "rectangle", "upper": [1, 1], "cells": [1, 1], "nx": 3}, ConfigError, "unknown key 'nx'"),
        (
            {"type": "box", "upper": [1, 1, 1], "cells": [1, 1, 1], "diagonal": "left"},
            ConfigError,
            "unknown key 'diagonal'",
        ),
        ({"type": "rectangle", "upper": [1, 1]}, ConfigError, "needs 'cells'"),
        ({"type": "rectangle", "upper": [1, 1], "cells": [4]}, ConfigError, "cells must be a list of 2"),
        ({"type": "box", "upper": [1, 1], "cells": [1, 1, 1]}, ConfigError, "upper must be a list of 3"),
        ({"type": "rectangle", "upper": [1, 1], "cells": [0, 4]}, MeshError, "positive integers"),
        ({"type": "rectangle", "upper": [1, 1], "cells": [-2, 4]}, MeshError, "positive integers"),
        ({"type": "rectangle", "lower": [1, 0], "upper": [1, 1], "cells": [2, 2]}, MeshError, "along x"),
        ({"type": "rectangle", "upper": ["a", 1], "cells": [2, 2]}, MeshError, "upper corner must be a list of 2"),
        ({"type": "file"}, ConfigError, "needs 'path'"),
        ({"type": "file", "path": "nowhere.msh"}, MeshError, "nowhere.msh does not exist"),
        ({"type": "file", "path": 3}, ConfigError, "path must be a file name"),
    ],
)
def test_config_errors_name_the_problem(tmp_path, table, error, message):
    with pytest.raises(error, match=message) as raised:
        mesh_from_config(table, tmp_path)
    assert "\n" not in str(raised.value)


def _two_triangles(**changes):
    """The unit square as two triangles, boundary 'left' its left edge; ``changes`` replace any part."""
    parts = {"points": np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
             "cells": np.array([[0, 1, 2], [0, 2, 3]]), "boundaries": {"left": np.array([[3, 0]])}}
    parts.update(changes)
    return MeshData(parts["points"], parts["cells"], parts["boundaries"])


@pytest.mark.parametrize("changes, message", [
    ({"boundaries": {"left": np.array([[0, 2]])}}, "boundary 'left' has 1 facet inside the domain"),
    ({"boundaries": {"left": np.array([[3, 0]]), "west": np.array([[0, 3]])}},
     "1 facet in both boundary 'left' and boundary 'west'"),
    ({"points": np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.0, 1.0]])}, "has 1 degenerate (zero-area) cells"),
    ({"cells": np.array([[0, 1, 2], [0, 1, 2]])}, "has overlapping cells"),
    ({"points": np.array([[0.0, 0.0], [1.0, 0.0], [1.0, np.nan], [0.0, 1.0]])}, "some coordinates are not finite"),
    ({"points": np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]]),
      "cells": np.array([[0, 1, 2], [4, 2, 3]]), "boundaries": {"left": np.array([[3, 4]])}},
     "1 vertex at the coordinates of another (duplicated nodes"),
    # ran, the stray vertex drawn at 0: pictures of m = 0.73-0.80 coloured from 0, out to the vertex
    ({"points": np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [10.0, 10.0]])},
     "has 1 vertex that no cell uses (vertex 4 at (10, 10)): leave them out of the points, and renumber"),
])
def test_a_mesh_built_by_hand_is_checked_as_a_file_is(changes, message):
    """A MeshData given to Model was used unchecked: an interior 'left' gave the backends different answers."""
    from primordia.model import Model

    with pytest.raises(MeshError) as error:
        Model(physics=["chemotaxis"], mesh=_two_triangles(**changes), dt=0.1, t_final=0.2)
    assert str(error.value).startswith("the model's MeshData") and message in str(error.value)
    Model(physics=["chemotaxis"], mesh=_two_triangles(), dt=0.1, t_final=0.2)  # the square itself is fine


@pytest.mark.parametrize("changes, message", [
    ({"cells": np.array([[0.0, 1.0, 2.7], [0.0, 2.0, 3.0]])}, "mesh cells must be integer vertex indices, got float64 "
                                                              "values such as 2.7"),
    ({"boundaries": {"left": np.array([[3.0, 0.5]])}}, "boundary 'left' must be integer vertex indices"),
    ({"boundaries": {"left": np.array([[3, 0, 1, 2]])}}, "boundary 'left' must be an (n, 2) array"),
    ({"boundaries": [np.array([[3, 0]])]}, "mesh boundaries must be a mapping of boundary name -> facets, got list"),
    ({"boundaries": {1: np.array([[3, 0]])}}, "mesh boundary names must be non-empty strings"),
    ({"points": np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]) + 1j}, "mesh points must be real numbers"),
    ({"points": [["0", "0"], ["1", "0"], ["1", "1"], ["0", "1"]]}, "mesh points must be real numbers"),
])
def test_a_mesh_built_by_hand_of_the_wrong_kinds_of_values_is_refused_in_one_line(changes, message):
    """A fractional vertex index was truncated to another vertex, an (n, 4) boundary in 2D read as 2n facets and
    complex coordinates lost their imaginary parts, without a word; a list of boundaries or string coordinates
    were a numpy or AttributeError traceback."""
    with pytest.raises(MeshError) as error:
        _two_triangles(**changes)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_a_mesh_built_by_hand_may_give_its_indices_as_whole_floats():
    mesh = _two_triangles(cells=np.array([[0.0, 1.0, 2.0], [0.0, 2.0, 3.0]]), boundaries={"left": [[3.0, 0.0]]})
    assert mesh.cells.dtype == np.int64 and mesh.cells.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert mesh.boundaries["left"].tolist() == [[3, 0]]
