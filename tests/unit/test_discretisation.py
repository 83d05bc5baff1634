"""The discretisation physics modules see: field groups, previous values and rates, couplings, kinematics.

Run on the scikit-fem backend (serial, no JIT): the discretisation is backend-neutral, and the
backends themselves are cross-validated elsewhere (tests/regression/test_crossval.py).
"""

from __future__ import annotations

import numpy as np
import pytest
import ufl

from primordia.backends.skfem import SkfemBackend
from primordia.core.errors import ConfigError
from primordia.core.meshes import rectangle
from primordia.physics.base import FieldSpec
from primordia.physics.discretisation import Discretisation
from primordia.physics.kinematics import MOTIONLESS, Kinematics


@pytest.fixture
def disc():
    return Discretisation(SkfemBackend(), rectangle((0, 0), (2, 1), (4, 2)))


def integral(disc, expression) -> float:
    return disc.backend.assemble_scalar(expression * disc.dx)


def test_fields_alone_and_grouped_read_the_same(disc):
    owners = {"c": "a", "u": "b", "p": "b"}
    disc.add_group("c", [FieldSpec("c")], owners)
    disc.add_group("mech", [FieldSpec("u", degree=2, vector=True, group="mech"), FieldSpec("p", group="mech")], owners)
    assert disc.is_alone("c") and not disc.is_alone("u")
    disc.interpolate("c", lambda x: x[0])
    disc.interpolate("p", lambda x: 1.0 + x[1])
    disc.interpolate("u", lambda x: np.stack([x[0] * x[1], -x[0]]))
    assert integral(disc, disc.field("c")) == pytest.approx(2.0)               # int_0^2 int_0^1 x
    assert integral(disc, disc.field("p")) == pytest.approx(3.0)               # int (1 + y)
    assert integral(disc, ufl.div(disc.field("u"))) == pytest.approx(1.0)      # div u = y
    assert disc.owner("u") == "b" and disc.group_fields("mech") == ["u", "p"]


def test_previous_values_and_rates_follow_the_steps(disc):
    disc.add_group("c", [FieldSpec("c")], {"c": "a"})
    disc.rate("c")  # a module asks for the rate: it is then kept
    disc.interpolate("c", 1.0)
    disc.store_previous()
    disc.interpolate("c", 3.0)
    disc.update_rates(0.5)
    assert integral(disc, disc.previous("c")) == pytest.approx(2.0)
    assert integral(disc, disc.rate("c")) == pytest.approx(8.0)                # (3 - 1)/0.5 over area 2


def test_a_missing_or_doubly_provided_field_is_named(disc):
    disc.add_group("c", [FieldSpec("c")], {"c": "chemistry"})
    with pytest.raises(ConfigError, match="field 'u' is required but no physics module of this model provides it"):
        disc.field("u")
    with pytest.raises(ConfigError, match="field 'c' is provided by both chemistry and other"):
        disc.add_group("c2", [FieldSpec("c")], {"c": "other"})


def test_contributions_are_built_when_asked_and_none_adds_nothing(disc):
    disc.add_group("c", [FieldSpec("c")], {"c": "a"})
    disc.contribute("c", lambda test: 2.0 * test * disc.dx)
    disc.contribute("c", lambda test: None)   # a coupling with nothing to add in this model
    forms = disc.contributions("c", disc.test("c"))
    assert len(forms) == 1
    assert disc.backend.assemble_vector(forms[0]).sum() == pytest.approx(4.0)
    disc.check_contributions()  # the owner of c read them


def test_a_contribution_no_balance_law_reads_is_refused(disc):
    disc.add_group("c", [FieldSpec("c")], {"c": "chemistry"})
    with pytest.raises(ConfigError, match="field 'q' is required but no physics module"):
        disc.contribute("q", lambda test: test * disc.dx, by="bead")
    disc.contribute("c", lambda test: test * disc.dx, by="bead")
    with pytest.raises(ConfigError, match="bead adds a term to the balance law of 'c', but chemistry does not read"):
        disc.check_contributions()


def test_dirichlet_conditions_fix_a_field_in_its_group(disc):
    disc.add_group("mech", [FieldSpec("u", vector=True, group="mech", displacement=True), FieldSpec("p", group="mech")],
                   {"u": "mechanics", "p": "mechanics"})
    assert disc.displacement_field() == "u"
    pressure = disc.dirichlet_bc("p", "left", 2.0)
    normal = disc.dirichlet_bc("u", "left", lambda x: 0.5 * np.ones(x.shape[1]), component=0)
    vector = disc.backend.petsc_vector(disc.unknown("p"))
    disc.backend.set_dirichlet(vector, [pressure, normal])
    values = disc.backend.local_array(disc.unknown("p"))
    assert sorted(set(np.round(values, 12))) == [0.0, 0.5, 2.0]  # p = 2 and u_x = 0.5 on the left, 0 elsewhere


def test_kinematics_default_to_a_motionless_tissue_and_have_one_provider(disc):
    assert disc.kinematics is MOTIONLESS and not disc.kinematics.moves and not disc.kinematics.finite_strain
    disc.add_group("u", [FieldSpec("u", vector=True)], {"u": "mechanics"})
    moving = Kinematics(volume_change=ufl.div(disc.field("u")), velocity=disc.rate("u"))
    disc.provide_kinematics(moving, "mechanics")
    assert disc.kinematics is moving and moving.moves and not moving.finite_strain
    with pytest.raises(ConfigError, match="described by both mechanics and other"):
        disc.provide_kinematics(MOTIONLESS, "other")


def test_measures_with_a_fixed_quadrature_degree(disc):
    assert disc.dx_degree(None) is disc.dx
    measure = disc.dx_degree(3)
    assert measure.metadata()["quadrature_degree"] == 3
    boundary = disc.ds_degree(2, "left")
    assert boundary.metadata()["quadrature_degree"] == 2
    assert disc.backend.assemble_scalar(ufl.as_ufl(1.0) * boundary) == pytest.approx(1.0)  # |left| = 1
