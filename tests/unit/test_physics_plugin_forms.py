"""A third party's physics module whose weak forms are wrong-shaped is one line naming it, on both backends.

Found writing a physics module from docs/plugins.md alone (a cue g the cells secrete): a residual without a test
function, or with a trial function, was a ValueError traceback from the solver layer; one tested by another
field's test function, or a Jacobian taken with respect to another field, ran to the end with a wrong answer
(both fields P1, so the vectors had the same length).
"""

import dataclasses

import pytest
import ufl

from mms import PhysicsPlugin
from primordia import Model
from primordia.core.errors import PluginError
from primordia.core.meshes import rectangle
from primordia.physics.base import FieldSpec, Physics, Subproblem
from primordia.testing import registered

BACKENDS = ["fenicsx", "skfem"]


class TwoScalars(Physics):
    """s and r, each ds/dt = -s, dr/dt = -r, solved apart; the classes below break s's solve one way each."""

    name = "qa_two_scalars"

    def fields(self):
        return [FieldSpec("s", description="a scalar"), FieldSpec("r", description="another scalar")]

    def setup(self, disc):
        self.disc = disc

    def initialise(self, disc):
        disc.interpolate("s", 1.0)
        disc.interpolate("r", 1.0)

    def solve(self, name, residual=None):
        disc = self.disc
        if residual is None:
            field = disc.field(name)
            residual = ((field - disc.previous(name)) / disc.dt + field) * disc.test(name) * disc.dx
        unknown = disc.unknown(name)
        return Subproblem(name=f"{self.name}.{name}", unknown=unknown, residual=residual,
                          jacobian=ufl.derivative(residual, unknown),
                          petsc_options={"ksp_type": "preonly", "pc_type": "lu"})

    def subproblems(self):
        return [self.solve("s"), self.solve("r")]


def _run(physics, backend, tmp_path):
    with registered(PhysicsPlugin(physics)):
        model = Model(physics=[physics.name], mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1, t_final=0.2,
                      output={"pictures": False})
        return model.run(backend=backend, out=tmp_path / "out")


def _s_solve(make):
    """TwoScalars with s's subproblem replaced by ``make(module, disc, subproblem)``."""
    def subproblems(self):
        return [make(self, self.disc, self.solve("s")), self.solve("r")]
    return type("Broken", (TwoScalars,), {"name": "qa_broken", "subproblems": subproblems})


def _residual(disc, s, test):
    return ((s - disc.previous("s")) / disc.dt + s) * test * disc.dx


BROKEN = {
    "a functional": (lambda module, disc, sub: module.solve("s", _residual(disc, disc.field("s"), 1.0)),
                     "residual must be linear in one test function of its unknown's space", "got 0 argument(s) (none)"),
    "a bilinear residual": (lambda module, disc, sub: module.solve("s", _residual(disc, disc.trial("s"),
                                                                                 disc.test("s"))),
                            "residual must be linear in one test function",
                            "got 2 argument(s) (a test function, a trial function)"),
    "another field's test function": (lambda module, disc, sub: module.solve("s", _residual(disc, disc.field("s"),
                                                                                           disc.test("r"))),
                                      "residual must be linear in one test function", "another space"),
    "the residual as jacobian": (lambda module, disc, sub: dataclasses.replace(sub, jacobian=sub.residual),
                                 "jacobian must be linear in a test and a trial function", "got 1 argument(s)"),
    "a jacobian by another field": (lambda module, disc, sub: dataclasses.replace(
        sub, jacobian=ufl.derivative(sub.residual + disc.field("r") * disc.test("s") * disc.dx, disc.unknown("r"))),
        "jacobian must be linear in a test and a trial function", "another space"),
}


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("broken", BROKEN)
def test_a_wrong_shaped_weak_form_is_one_line_naming_the_module(broken, backend, tmp_path):
    make, shape, found = BROKEN[broken]
    with pytest.raises(PluginError) as error:
        _run(_s_solve(make), backend, tmp_path)
    message = str(error.value)
    assert message.startswith(f"physics qa_broken: subproblem qa_broken.s's {shape.split(' must')[0]}"), message
    assert shape in message and found in message and "\n" not in message, message


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_well_formed_pair_runs_and_decays_as_backward_euler_says(backend, tmp_path):
    """s^{n+1} = s^n / (1 + dt): 1 / 1.1^2 after two steps of 0.1, at every vertex, on both backends."""
    values = _run(TwoScalars, backend, tmp_path).vertex_values()
    for name in ("s", "r"):
        assert abs(values[name] - 1 / 1.1**2).max() < 1e-12


def test_a_field_no_module_provides_names_the_module_that_read_it(tmp_path):
    """A module reading a field it did not declare in ``requires``: the line named the field only, not which
    of the model's plugins asked for it."""
    from primordia.core.errors import ConfigError

    reader = _s_solve(lambda module, disc, sub: module.solve("s", _residual(disc, disc.field("s") + disc.field("zz"),
                                                                              disc.test("s"))))
    with pytest.raises(ConfigError) as error:
        _run(reader, "skfem", tmp_path)
    assert str(error.value).startswith("physics qa_broken: subproblems: field 'zz' is required but no physics "
                                       "module of this model provides it"), str(error.value)


def test_a_constant_jacobian_that_reads_a_field_is_refused(tmp_path):
    """constant_jacobian=True on a Jacobian that reads r: kept from the first step where no split residual
    refreshed it (Dirichlet conditions), it went stale without a word (4e-5 off after 10 steps)."""
    def claims_constant(module, disc, sub):
        s = disc.field("s")
        residual = ((s - disc.previous("s")) / disc.dt + disc.field("r") * s) * disc.test("s") * disc.dx
        return dataclasses.replace(module.solve("s", residual), constant_jacobian=True)

    with pytest.raises(PluginError) as error:
        _run(_s_solve(claims_constant), "skfem", tmp_path)
    assert str(error.value).startswith("physics qa_broken: subproblem qa_broken.s says constant_jacobian=True, but "
                                       "its jacobian reads fields"), str(error.value)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_linear_subproblem_whose_residual_is_not_affine_is_refused(backend, tmp_path):
    """linear=True (the default) on ds/dt = -s^2: one Newton step from s^n was taken for the solve without a word
    (how the split chemotaxis stepped Schnakenberg's u^2 v); with linear=False the same residual is solved."""
    def quadratic(module, disc, sub):
        s = disc.field("s")
        return module.solve("s", ((s - disc.previous("s")) / disc.dt + s**2) * disc.test("s") * disc.dx)

    with pytest.raises(PluginError) as error:
        _run(_s_solve(quadratic), backend, tmp_path)
    assert str(error.value).startswith("physics qa_broken: subproblem qa_broken.s says linear=True, but its residual "
                                       "is not affine in its unknown"), str(error.value)
    newton = _s_solve(lambda module, disc, sub: dataclasses.replace(quadratic(module, disc, sub), linear=False))
    s = _run(newton, backend, tmp_path / "newton").vertex_values()["s"]
    expected = 1.0
    for _ in range(2):  # s + dt s^2 = s^n, the positive root
        expected = (-1 + (1 + 4 * 0.1 * expected) ** 0.5) / (2 * 0.1)
    assert abs(s - expected).max() < 1e-7  # to the Newton solve's tolerance


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_subproblem_solving_another_module_s_field_is_refused(backend, tmp_path):
    """A second module solving s again (ds/dt = -2 s, say, to add a term to its balance): s was solved twice a
    step, once by each balance law, without a word."""
    class Meddler(Physics):
        name = "qa_meddler"
        requires = ("s",)

        def fields(self):
            return []

        def setup(self, disc):
            self.disc = disc

        def initialise(self, disc):
            pass

        def subproblems(self):
            disc, s = self.disc, self.disc.field("s")
            residual = ((s - disc.previous("s")) / disc.dt + 2 * s) * disc.test("s") * disc.dx
            return [Subproblem(name="qa_meddler.s", unknown=disc.unknown("s"), residual=residual,
                               jacobian=ufl.derivative(residual, disc.unknown("s")))]

    with registered(PhysicsPlugin(TwoScalars), PhysicsPlugin(Meddler)):
        model = Model(physics=[TwoScalars.name, Meddler.name], mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1,
                      t_final=0.2, output={"pictures": False})
        with pytest.raises(PluginError) as error:
            model.run(backend=backend, out=tmp_path / "out")
    assert str(error.value).startswith("physics qa_meddler: subproblem qa_meddler.s solves for field s, which is "
                                       "not one of the fields qa_meddler declares in fields()"), str(error.value)
