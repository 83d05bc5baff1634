"""Boundary-condition kinds are plugins (hook ``primordia_boundary_conditions``): a third-party kind
is listed, chosen by ``type = "..."`` and contributes its own term, with no edit of primordia."""

from __future__ import annotations

import numpy as np
import pytest
import ufl

from primordia.core.errors import ConfigError, PluginError
from primordia.core.meshes import rectangle
from primordia.core.plugins import get_plugin_manager, hookimpl, registry
from primordia.model import Model
from primordia.physics.boundary_conditions import Condition, conditions_from_config


class NormalPressure(Condition):
    """A follower-free pressure load on a boundary: sigma n = -value n (a third party's kind)."""

    kind, field = "normal_pressure", "u"

    def terms(self, disc):
        pressure = self.formula.ufl(disc.x, disc.t)
        return {"u": [pressure * ufl.inner(disc.n, disc.test("u")) * disc.ds(self.boundary)]}


class SolidPressureLoad(Condition):
    """A third party's kind on the solid pressure psi, a field of poroelastic_growth only."""

    kind, field = "solid_pressure_load", "psi"

    def terms(self, disc):
        return {"psi": [self.formula.ufl(disc.x, disc.t) * disc.test("psi") * disc.ds(self.boundary)]}


class BuggyLoad(Condition):
    """A third party's kind with a bug in its terms."""

    kind, field = "buggy_load", "u"

    def terms(self, disc):
        return {"u": [disc.no_such_method()]}


class ListedLoad(Condition):
    """A third party's kind whose terms are a list, not {field: [form, ...]}."""

    kind, field = "listed_load", "u"

    def terms(self, disc):
        return [self.formula.ufl(disc.x, disc.t) * disc.test("u")[0] * disc.ds(self.boundary)]


class UnbuildableLoad(Condition):
    """A third party's kind whose constructor fails."""

    kind, field = "unbuildable_load", "u"

    def __init__(self, boundary, value=None, constants=None, gdim=2):
        raise TypeError("unbuildable on purpose")


class _Plugin:
    @hookimpl
    def primordia_boundary_conditions(self):
        return [NormalPressure, SolidPressureLoad, BuggyLoad, ListedLoad, UnbuildableLoad]


@pytest.fixture
def third_party_kind():
    pm = get_plugin_manager()
    plugin = pm.register(_Plugin(), name="tests.third_party_condition")
    yield
    pm.unregister(name=plugin)


def squeezed(load: str | None, kind: str = "normal_pressure"):
    boundary = [{"boundary": "bottom", "type": "clamped"}]
    if load is not None:
        boundary.append({"boundary": "top", "type": kind, "value": load})
    model = Model(physics=["poroelasticity"], parameters={"E": 100.0, "nu": 0.3},
                  mesh=rectangle((0, 0), (1, 1), (4, 4)), dt=0.1, t_final=0.2,
                  physics_options={"poroelasticity": {"boundary": boundary}}, output={"pictures": False})
    return model


def test_a_plugin_kind_is_registered_and_contributes_its_term(third_party_kind, tmp_path):
    assert registry("boundary_conditions")["normal_pressure"][0] is NormalPressure
    pressed = squeezed("2.0").run(backend="fenicsx", out=tmp_path / "pressed").vertex_values()["u"]
    free = squeezed(None).run(backend="fenicsx", out=tmp_path / "free").vertex_values()["u"]
    assert np.abs(free).max() < 1e-12  # nothing loads the free block
    assert pressed[:, 1].min() < -1e-3  # the pressure on top pushes it down


def test_an_unknown_kind_names_the_registered_ones(third_party_kind):
    with pytest.raises(ConfigError) as failure:
        conditions_from_config([{"boundary": "top", "type": "pressure"}], rectangle((0, 0), (1, 1), (2, 2)), 2)
    assert "unknown boundary condition type 'pressure'" in str(failure.value)
    assert "normal_pressure" in str(failure.value) and "robin" in str(failure.value)


def test_a_kind_on_a_field_the_physics_lacks_is_one_line_before_the_run(third_party_kind):
    boundary = [{"boundary": "bottom", "type": "clamped"}, {"boundary": "top", "type": "solid_pressure_load", "value": "1"}]
    with pytest.raises(ConfigError) as failure:
        Model(physics=["poroelasticity"], parameters={"E": 100.0, "nu": 0.3}, mesh=rectangle((0, 0), (1, 1), (4, 4)),
              dt=0.1, t_final=0.2, physics_options={"poroelasticity": {"boundary": boundary}})
    assert str(failure.value) == ("boundary condition 'solid_pressure_load' on 'top' acts on the field psi, "
                                  "which physics poroelasticity does not solve for (it has: u, p)")


@pytest.mark.parametrize("kind, told", [
    ("buggy_load", "terms failed: AttributeError: 'Discretisation' object has no attribute 'no_such_method' (at "),
    ("listed_load", "terms must return {field name: [form, ...]}, got ["),
    ("unbuildable_load", "__init__ failed: TypeError: unbuildable on purpose (at "),
])
def test_a_bug_in_a_third_party_kind_is_one_line_naming_it(third_party_kind, tmp_path, kind, told):
    """A kind's bug was a traceback and exit status 1: its methods are called by poroelasticity or growth,
    primordia's own modules, whose own bugs keep their tracebacks, so nothing named the kind."""
    with pytest.raises(PluginError) as failure:
        squeezed("2.0", kind).run(backend="skfem", out=tmp_path / "out")
    message = str(failure.value)
    assert message.startswith(f"boundary condition '{kind}' on 'top' ({__name__}.")
    assert told in message and "\n" not in message


def test_a_kind_skipped_at_loading_says_why_not_unknown(monkeypatch):
    """A kind two installed plugins give is used from neither; a config naming it said "unknown boundary condition
    type", where a kinetics or a growth law so skipped says why (the plugin QA pass)."""
    why = "plugin 'b' reuses the name 'gm_pressure' of plugin 'a'; ... uninstall one of them"
    monkeypatch.setitem(get_plugin_manager().load_report.skipped, ("boundary_conditions", "gm_pressure"), why)
    with pytest.raises(PluginError, match="^boundary condition type 'gm_pressure' was skipped: plugin 'b' reuses"):
        conditions_from_config([{"boundary": "top", "type": "gm_pressure"}], rectangle((0, 0), (1, 1), (2, 2)), 2)
    with pytest.raises(ConfigError, match="^unknown boundary condition type 'gm_pressures'"):
        conditions_from_config([{"boundary": "top", "type": "gm_pressures"}], rectangle((0, 0), (1, 1), (2, 2)), 2)
