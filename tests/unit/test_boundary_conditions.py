"""Boundary-condition kinds (primordia.physics.boundary_conditions): what each one contributes.

On the scikit-fem backend (serial, no JIT); the kinds are cross-validated on both backends in
tests/regression/test_crossval.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import ufl

from primordia.backends.skfem import SkfemBackend
from primordia.core.errors import ConfigError
from primordia.core.mesh_data import MeshData
from primordia.core.meshes import rectangle
from primordia.physics.discretisation import Discretisation
from primordia.physics.base import FieldSpec
from primordia.physics.boundary_conditions import conditions_from_config, encloses, free_rigid_motions
from primordia.physics.kinematics import Kinematics

MESH = rectangle((0, 0), (2, 1), (4, 2))


@pytest.fixture
def disc():
    disc = Discretisation(SkfemBackend(), MESH)
    disc.add_group("mech", [FieldSpec("u", vector=True, group="mech"), FieldSpec("p", group="mech")],
                   {"u": "mechanics", "p": "mechanics"})
    return disc


def conditions(*tables):
    return conditions_from_config(list(tables), MESH, 2)


def total(disc, forms) -> np.ndarray:
    return sum(disc.backend.assemble_vector(form).array for form in forms)


def test_dirichlet_kinds_fix_what_they_say_at_the_boundary_nodes(disc):
    clamp, normal, pressure = conditions({"boundary": "left", "type": "clamped"},
                                         {"boundary": "bottom", "type": "normal_displacement", "value": "0.5 * t"},
                                         {"boundary": "top", "type": "fluid_pressure", "value": "x[0]"})
    space = disc.unknown("u").function_space
    (left,) = clamp.dirichlet(disc)
    assert set(space.dof_component[left.handle.dofs]) == {0, 1}       # both components of u
    assert np.all(space.dof_coordinates[0, left.handle.dofs] == 0.0)
    (bottom,) = normal.dirichlet(disc)
    assert set(space.dof_component[bottom.handle.dofs]) == {1}        # only u_y: the normal of y = 0
    (top,) = pressure.dirichlet(disc)
    assert set(space.dof_component[top.handle.dofs]) == {2}
    np.testing.assert_allclose(top.handle.values, space.dof_coordinates[0, top.handle.dofs])
    normal.update(disc, 2.0)                                         # time-dependent: refreshed
    np.testing.assert_allclose(bottom.handle.values, 1.0)


def test_neumann_kinds_add_their_loads(disc):
    traction, flux = conditions({"boundary": "top", "type": "traction", "value": ["0", "-3"]},
                                {"boundary": "right", "type": "fluid_flux", "value": "2"})
    (load,) = traction.terms(disc)["u"]
    (inflow,) = flux.terms(disc)["p"]
    space = disc.unknown("u").function_space
    residual = total(disc, [load, inflow])
    y = space.dof_component == 1
    assert residual[y].sum() == pytest.approx(3.0 * 2.0)              # -(-3) over |top| = 2
    assert residual[space.dof_component == 2].sum() == pytest.approx(-2.0 * 1.0)  # -(2) over |right| = 1


def test_robin_springs_are_xi_u_at_small_strain_and_xi_J_F_inverse_transpose_u_at_finite_strain(disc):
    (springs,) = conditions({"boundary": "right", "type": "robin", "value": "0.5"})
    disc.interpolate("u", lambda x: np.stack([0.1 * x[0], 0.2 * x[1]]))
    (small,) = springs.terms(disc)["u"]
    space = disc.unknown("u").function_space
    residual = total(disc, [small])
    # int over x = 2, y in (0, 1): 0.5 * u_x = 0.5 * 0.2 = 0.1 and 0.5 * u_y = 0.1 y -> 0.05
    assert residual[space.dof_component == 0].sum() == pytest.approx(0.1)
    assert residual[space.dof_component == 1].sum() == pytest.approx(0.05)
    F = ufl.Identity(2) + ufl.grad(disc.field("u"))
    disc.provide_kinematics(Kinematics(volume_ratio=ufl.det(F), deformation_gradient=F), "mechanics")
    (finite,) = springs.terms(disc)["u"]
    residual = total(disc, [finite])
    # F = diag(1.1, 1.2), J = 1.32: J F^-T u = (1.32 / 1.1 * 0.2, 1.32 / 1.2 * 0.2 y)
    assert residual[space.dof_component == 0].sum() == pytest.approx(0.5 * 1.2 * 0.2)
    assert residual[space.dof_component == 1].sum() == pytest.approx(0.5 * 1.1 * 0.1)


@pytest.mark.parametrize("table, message", [
    ({"boundary": "left", "type": "clamp"}, "unknown boundary condition type 'clamp'"),
    ({"boundary": "north", "type": "clamped"}, "names boundary 'north', which the mesh lacks"),
    ({"boundary": "top", "type": "traction", "value": ["1"]}, "value needs 2 components, got 1"),
    ({"boundary": "top", "type": "robin"}, "boundary condition 'robin' on 'top' needs a value"),
    ({"boundary": "top", "type": "fluid_flux", "value": "y + 1"}, "unknown name 'y'"),
    ({"boundary": "top", "type": "fluid_flux", "valu": "1"}, "unknown key 'valu'"),
])
def test_a_bad_condition_is_one_line_naming_it(table, message):
    with pytest.raises(ConfigError) as failure:
        conditions(table)
    assert message in str(failure.value) and "\n" not in str(failure.value)


def test_a_condition_on_a_boundary_without_facets_is_refused():
    """A MeshData built by hand with an empty 'top': a traction on it acted on nothing and the run completed."""
    mesh = MeshData(MESH.points, MESH.cells, {**MESH.boundaries, "top": np.zeros((0, 2), dtype=int)})
    with pytest.raises(ConfigError) as failure:
        conditions_from_config([{"boundary": "top", "type": "traction", "value": ["0", "1"]}], mesh, 2)
    assert str(failure.value) == ("boundary condition 'traction' names boundary 'top', which has no facets "
                                  "(the condition would act on nothing)")


def test_normal_displacement_needs_an_axis_aligned_boundary(disc):
    slanted = MeshData(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), np.array([[0, 1, 2]]),
                       {"hypotenuse": np.array([[1, 2]])})
    (condition,) = conditions_from_config([{"boundary": "hypotenuse", "type": "normal_displacement"}], slanted, 2)
    other = Discretisation(SkfemBackend(), slanted)
    other.add_group("u", [FieldSpec("u", vector=True)], {"u": "mechanics"})
    with pytest.raises(ConfigError, match="needs a flat boundary normal to a coordinate axis"):
        condition.dirichlet(other)


def test_a_tissue_held_normally_on_every_side_is_enclosed():
    held = [{"boundary": side, "type": "normal_displacement"} for side in ("left", "right", "bottom", "top")]
    assert encloses(conditions(*held), MESH)
    assert not encloses(conditions(*held[:3], {"boundary": "top", "type": "robin", "value": "1"}), MESH)


@pytest.mark.parametrize("tables, free", [
    ([], 3),
    ([{"boundary": "top", "type": "traction", "value": ["0", "1"]},
      {"boundary": "top", "type": "fluid_pressure", "value": "0"}], 3),         # p holds no motion of u
    ([{"boundary": "bottom", "type": "normal_displacement"}], 1),                # slides along x
    ([{"boundary": "bottom", "type": "normal_displacement"},
      {"boundary": "top", "type": "normal_displacement"}], 1),                   # parallel rollers: still slides
    ([{"boundary": "bottom", "type": "normal_displacement"},
      {"boundary": "left", "type": "normal_displacement"}], 0),
    ([{"boundary": "left", "type": "clamped"}], 0),
    ([{"boundary": "right", "type": "displacement", "value": ["t", "0"]}], 0),
    ([{"boundary": "right", "type": "robin", "value": "x[1]"}], 0),             # stiff except at one vertex
    ([{"boundary": "right", "type": "robin", "value": "0"}], 3),
])
def test_the_rigid_motions_the_conditions_leave_free_are_counted(tables, free):
    assert free_rigid_motions(conditions(*tables), MESH, [0.0, 1.0]) == free


@pytest.mark.parametrize("rho, refused", [(0.0, True), (1.0, False)])
def test_a_tissue_without_inertia_and_free_to_move_rigidly_is_refused(rho, refused):
    # With rho = 0 and traction on every side, (2.1c) fixes u up to a rigid motion: the singular system was
    # solved anyway, the two backends returning different rigid motions (top u_y -1.6e-3 and -3.2e-3 in a
    # 6 x 6 example 1b with tau = 1e-3 at t = 2).
    from primordia.model import Model

    free = [{"boundary": side, "type": "traction", "value": ["0", "0"]} for side in ("left", "right", "bottom")]
    model = lambda: Model(physics=["poroelasticity"], parameters={"rho": rho}, mesh=MESH, dt=0.1,  # noqa: E731
                          t_final=0.2, physics_options={"poroelasticity": {"boundary": free}})
    if not refused:
        model()
        return
    with pytest.raises(ConfigError) as failure:
        model()
    assert "the boundary conditions leave 3 rigid-body motion(s) of u free and rho = 0" in str(failure.value)
    assert "\n" not in str(failure.value)


def test_a_dirichlet_condition_asked_twice_gives_the_constraints_its_update_moves(disc):
    # The growth module asks for its constraints for the initial equilibrium and again for the time step
    # (and the solvers are made again after a rejected step): each call made new ones and update() moved
    # only the last, so the time step's solver kept a time-dependent displacement at its first value.
    (normal,) = conditions({"boundary": "left", "type": "normal_displacement", "value": "-0.5 * t"})
    (first,) = normal.dirichlet(disc)
    (again,) = normal.dirichlet(disc)
    assert again is first
    normal.update(disc, 0.4)
    np.testing.assert_allclose(first.handle.values, -0.2)


def test_a_time_dependent_displacement_moves_the_growing_tissue(tmp_path):
    from primordia.core import config as config_
    from primordia.model import Model

    config = config_.load_config(Path(__file__).resolve().parents[2] / "examples" / "ex02a.toml")
    config["mesh"]["cells"], config["time"]["t_final"], config["output"] = [4, 4], 0.4, {"times": [0.4], "pictures": False}
    config["physics"]["poroelastic_growth"]["boundary"][0]["value"] = "-0.5 * t"  # the left edge, u_x = -t/2
    sim = Model.from_config(config).run(backend="skfem", out=tmp_path / "run")
    left = sim.model.mesh_data.points[:, 0] == 0.0
    np.testing.assert_allclose(sim.vertex_values()["u"][left, 0], -0.2, atol=1e-12)


@pytest.mark.parametrize("tables, message", [
    ([{"boundary": "left", "type": "clamped"}, {"boundary": "left", "type": "displacement", "value": ["1", "0"]}],
     "boundary 'left' is given two Dirichlet conditions on u ('clamped' and 'displacement'): give one"),
    ([{"boundary": "left", "type": "clamped"}, {"boundary": "left", "type": "normal_displacement"}],
     "two Dirichlet conditions on u ('clamped' and 'normal_displacement')"),
    ([{"boundary": "top", "type": "fluid_pressure", "value": "1"}, {"boundary": "top", "type": "fluid_pressure", "value": "2"}],
     "boundary 'top' is given two Dirichlet conditions on p"),
    ([{"boundary": "top", "type": "clamped", "value": ["1", "0"]}],
     "boundary condition 'clamped' on 'top' is u = 0 and takes no value"),
    ([{"boundary": "top", "type": "clamped", "value": 1}],  # was: "must be a list of formulas, one per component"
     "boundary condition 'clamped' on 'top' is u = 0 and takes no value, got 1"),
])
def test_conflicting_or_contradictory_dirichlet_conditions_are_one_line(tables, message):
    with pytest.raises(ConfigError) as failure:
        conditions(*tables)
    assert message in str(failure.value) and "\n" not in str(failure.value)


def test_conditions_of_different_fields_or_boundaries_may_meet():
    clamp, pressure, spring, zero = conditions({"boundary": "left", "type": "clamped"},
                                               {"boundary": "left", "type": "fluid_pressure", "value": "0"},
                                               {"boundary": "right", "type": "robin", "value": "x[1]"},
                                               {"boundary": "bottom", "type": "clamped", "value": ["0", "0.0"]})
    spring.check(MESH.points[np.unique(MESH.boundaries["right"])], [0.0, 1.0])


def test_a_negative_spring_stiffness_is_one_line():
    (spring,) = conditions({"boundary": "right", "type": "robin", "value": "1 - t"})
    points = MESH.points[np.unique(MESH.boundaries["right"])]
    spring.check(points, [0.0, 1.0])
    with pytest.raises(ConfigError) as failure:
        spring.check(points, [0.0, 2.0])
    assert "'robin' on 'right': the stiffness '1 - t' must be >= 0, got -1 at x = (2, 0), t = 2" in str(failure.value)


def test_a_slanted_normal_displacement_is_refused_before_the_run():
    # It was found only when the constraint was made: `primordia run --dry-run` called the input valid.
    from primordia.model import Model

    slanted = MeshData(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), np.array([[0, 1, 2]]),
                       {"hypotenuse": np.array([[1, 2]]), "legs": np.array([[0, 1], [0, 2]])})
    held = [{"boundary": "legs", "type": "clamped"}, {"boundary": "hypotenuse", "type": "normal_displacement"}]
    with pytest.raises(ConfigError, match="normal_displacement on 'hypotenuse' needs a flat boundary"):
        Model(physics=["poroelasticity"], parameters={"E": 100.0, "nu": 0.3}, mesh=slanted, dt=0.1, t_final=0.2,
              physics_options={"poroelasticity": {"boundary": held}})


@pytest.mark.parametrize("backend", ["fenicsx", "skfem"])
def test_the_growing_tissue_starts_with_its_moving_boundary_s_own_rate(backend, tmp_path):
    """The initial velocity solve (the equilibrium following the growth over the first step) took
    the rate 0 on every Dirichlet boundary: a boundary prescribed to move at u_x = -t/2 started at rest."""
    from primordia.core import config as config_
    from primordia.coupling.orchestrator import Simulation
    from primordia.model import Model

    config = config_.load_config(Path(__file__).resolve().parents[2] / "examples" / "ex02a.toml")
    config["mesh"]["cells"], config["time"]["t_final"], config["output"] = [4, 4], 0.4, {"times": [0.4], "pictures": False}
    config["physics"]["poroelastic_growth"]["boundary"][0]["value"] = "-0.5 * t"  # the left edge, u_x = -t/2
    sim = Simulation(Model.from_config(config), backend=backend, out_dir=tmp_path / "run").setup()
    rates = sim.disc.rate_function("u")  # the (u, psi, p) group's rates; u is its first component
    rate = sim.backend.vertex_values(rates, sim.disc.function_of("u")[1])
    left = sim.model.mesh_data.points[:, 0] == 0.0
    np.testing.assert_allclose(rate[left, 0], -0.5, rtol=1e-12)
