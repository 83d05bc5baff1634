"""A plugin that breaks the contract of its kind is one line naming it, never a traceback.

A kinetics or growth law without a required method, with a parameter whose default is no
value of it or that another piece declares with another default, with species named like
another module's field, or whose methods answer something of the wrong shape: each is
refused when the model is composed (so ``--dry-run`` and ``stability`` refuse it too), or,
for a growth law's factors, at set-up, with a :class:`PrimordiaError` naming the piece.
A hook named like no hook is a broken plugin, not a silently unused one.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from primordia.analysis.composed import linearise_model
from primordia.core.errors import ConfigError, PluginError
from primordia.core.meshes import rectangle
from primordia.core.parameters import Parameter, ParameterSet
from primordia.core.plugins import hookimpl, lookup
from primordia.model import Model
from primordia.physics.base import FieldSpec, Physics
from primordia.physics.growth_laws import GrowthLaw
from primordia.physics.kinetics.base import Kinetics, Species
from primordia.testing import registered

from plugin_sources import FROZEN_KINETICS


class Decay(Kinetics):
    """dq/dt = k - q + D_q lap q: a well-behaved kinetics the broken ones below vary."""

    name = "qa_decay"
    species = (Species("q", "a substance", diffusivity="D_q", perturbed=True),)
    parameters = (Parameter("D_q", 1.0, "diffusivity of q"), Parameter("k", 1.0, "production of q"))

    def split_rates(self, c, t, ops):
        return {"q": (self.params["k"], 1.0)}

    def initial_state(self, t0, ops):
        return {"q": self.params["k"]}


def _kinetics(name, **attributes):
    return type(f"Kinetics_{name}", (Decay,), {"name": name, "__module__": __name__, **attributes})


class Plugin:
    def __init__(self, kinetics=(), growth_laws=()):
        self.kinetics, self.growth_laws = list(kinetics), list(growth_laws)

    @hookimpl
    def primordia_kinetics(self):
        return self.kinetics

    @hookimpl
    def primordia_growth_laws(self):
        return self.growth_laws


def _model(kinetics, physics=("chemotaxis",), **options):
    return Model(physics=list(physics), kinetics=kinetics, mesh=rectangle((0, 0), (4, 4), (4, 4)), dt=0.2,
                 t_final=0.4, output={"pictures": False}, **options)


def test_the_well_behaved_kinetics_composes():
    with registered(Plugin([Decay])):
        assert _model("qa_decay").kinetics_object.species_names == ("q",)


def test_a_kinetics_without_its_rates_is_skipped_with_the_reason():
    class NoRates(Kinetics):
        name = "qa_no_rates"
        species = Decay.species
        parameters = Decay.parameters

        def initial_state(self, t0, ops):
            return {"q": 1.0}

    with registered(Plugin([NoRates])), pytest.raises(PluginError) as error:
        lookup("kinetics", "qa_no_rates")
    assert "kinetics 'qa_no_rates' was skipped" in str(error.value)
    assert "does not define the required split_rates" in str(error.value)


@pytest.mark.parametrize("default, fragment", [(None, "with the default None"), ("abc", "with the default 'abc'"),
                                               (-1.0, "must be > 0")])
def test_a_parameter_default_that_is_no_value_of_it_names_the_kinetics(default, fragment):
    broken = _kinetics("qa_bad_default", parameters=(Parameter("D_q", 1.0, "d"), Parameter("k", default, "k")))
    with registered(Plugin([broken])), pytest.raises(PluginError) as error:
        _model("qa_bad_default")
    assert str(error.value).startswith("kinetics qa_bad_default declares parameter k") and fragment in str(error.value)


def test_a_parameter_declared_with_another_default_names_both_pieces():
    clash = _kinetics("qa_clash", parameters=Decay.parameters + (Parameter("E", 7.0, "not Young's modulus"),))
    with registered(Plugin([clash])), pytest.raises(PluginError) as error:
        _model("qa_clash", physics=["chemotaxis", "poroelasticity"],
               physics_options={"poroelasticity": {"boundary": [{"boundary": "bottom", "type": "clamped"}]}})
    assert str(error.value).startswith("parameter E is declared by physics poroelasticity (default 30000) "
                                       "and by kinetics qa_clash (default 7)")


def test_a_species_named_like_another_modules_field_names_both():
    displaced = _kinetics("qa_species_u", species=(Species("u", "clashes", diffusivity="D_q", perturbed=True),),
                          split_rates=lambda self, c, t, ops: {"u": (1.0, 1.0)},
                          initial_state=lambda self, t0, ops: {"u": 1.0})
    with registered(Plugin([displaced])), pytest.raises(ConfigError) as error:
        _model("qa_species_u", physics=["chemotaxis", "poroelasticity"],
               physics_options={"poroelasticity": {"boundary": [{"boundary": "bottom", "type": "clamped"}]}})
    assert str(error.value) == ("field 'u' is provided by both physics chemotaxis (a species of kinetics "
                                "qa_species_u) and physics poroelasticity")


@pytest.mark.parametrize("attributes, message", [
    ({"species": ("q",)}, "its species must be a tuple of primordia.physics.kinetics.base.Species"),
    ({"initial_state": lambda self, t0, ops: {}}, "initial_state must return a value for every species"),
    ({"split_rates": lambda self, c, t, ops: {"z": (1.0, 1.0)}}, "split_rates must return {species: "
                                                                   "(production, loss_rate)} for its species q, got z"),
    ({"split_rates": lambda self, c, t, ops: None}, "split_rates must return"),
    ({"split_rates": lambda self, c, t, ops: {"q": 1.0}}, "split_rates must give species q a pair"),
    ({"split_rates": lambda self, c, t, ops: {"q": ("1.0", 1.0)}}, "give species q a real production, got '1.0'"),
    ({"split_rates": lambda self, c, t, ops: {"q": (1.0, None)}}, "give species q a real loss_rate, got None"),
    ({"initial_state": lambda self, t0, ops: {"q": "1"}}, "initial_state must give species q a real number"),
    ({"split_rates": lambda self, c, t, ops: {"q": (c["h"], 1.0)}}, "split_rates failed: KeyError: 'h'"),
    # these two ran without a word: the extra species dropped, the negative loss rate taken implicitly
    ({"initial_state": lambda self, t0, ops: {"q": 1.0, "z": 2.0}},
     "initial_state gives z, which is not one of its species (q)"),
    ({"split_rates": lambda self, c, t, ops: {"q": (1.0, -0.5)}},
     "split_rates gives species q a negative loss_rate (-0.5) at the initial state"),
    ({"__init__": lambda self, params, **given: 1 / 0}, "could not be set up: ZeroDivisionError"),
])
def test_a_kinetics_breaking_its_contract_is_one_line_naming_it(attributes, message):
    broken = _kinetics("qa_broken_kinetics", **attributes)
    with registered(Plugin([broken])), pytest.raises(PluginError) as error:
        _model("qa_broken_kinetics")
    assert "qa_broken_kinetics" in str(error.value) and message in str(error.value)
    assert "\n" not in str(error.value)


def _raising_rates(self, c, t, ops):
    raise RuntimeError("the rates' table is not loaded")


def test_a_kinetics_bug_at_the_input_check_names_its_class_and_place():
    """A RuntimeError in split_rates at the input check said "kinetics NAME: split_rates failed: ..." without the
    class or where, as the same bug in the weak forms (kinetics_code) says (the plugin QA pass)."""
    with registered(Plugin([_kinetics("qa_raising", split_rates=_raising_rates)])), pytest.raises(PluginError) as error:
        _model("qa_raising")
    assert str(error.value).startswith(f"kinetics qa_raising ({__name__}.Kinetics_qa_raising): split_rates failed: "
                                       f"RuntimeError: the rates' table is not loaded (at {__file__}:"), str(error.value)


ATTRACTED = (Species("q", "climbs r", diffusivity="D_q", attractant="r", perturbed=True),
             Species("r", "the attractant", diffusivity="D_q"))


@pytest.mark.parametrize("attributes, message", [
    ({"split_rates": lambda self, c, t, ops: {"q": (np.exp(-c["q"]), 1.0)}},
     "split_rates failed: TypeError: loop of ufunc does not support argument 0 of type "),
    ({"split_rates": lambda self, c, t, ops: {"q": (1.0 if c["q"] > 0 else 0.0, 1.0)}},
     "split_rates failed: UFLException: UFL conditions cannot be evaluated as bool in a Python context."),
    ({"initial_state": lambda self, t0, ops: {"q": np.ones(3)}},
     "initial_state must give species q a real number or one per vertex (25,), got an array of shape (3,)"),
    ({"species": ATTRACTED, "split_rates": lambda self, c, t, ops: {"q": (0, 0), "r": (0, 0)},
      "initial_state": lambda self, t0, ops: {"q": 1.0, "r": 1.0},
      "sensitivity": lambda self, species, density, ops: "chi"}, "sensitivity must give species q a real chi"),
])
def test_a_kinetics_numbers_take_and_the_weak_forms_do_not_is_one_line_naming_it(attributes, message, tmp_path):
    """Each was a traceback at set-up (np.exp or an `if` on a UFL field, a chi the fitted flux cannot make a float
    of) or at the first field set (an array of the wrong length): numpy's checks at the vertices passed them."""
    with registered(Plugin([_kinetics("qa_numbers_only", **attributes)])), pytest.raises(PluginError) as error:
        _model("qa_numbers_only").run(backend="skfem", out=tmp_path)
    assert str(error.value).startswith("kinetics qa_numbers_only") and message in str(error.value), str(error.value)
    assert "\n" not in str(error.value)


def test_a_ufl_error_in_a_kinetics_is_not_printed_besides_its_one_line(primordia_cli, small_config, tmp_path):
    """UFL logs each error to stdout before raising it: "UFL conditions cannot be evaluated as bool in a Python
    context." stood on a line of its own above primordia's."""
    plugin = tmp_path / "branching.py"
    plugin.write_text(FROZEN_KINETICS.replace("(0.0, 0.0) for", "(1.0 if c['m'] > 0 else 0.0, 0.0) for"))
    result = primordia_cli("-p", plugin, "run", small_config(), "--out", tmp_path / "out", "--no-progress",
                           "--set", "kinetics.name=frozen")
    assert result.returncode == 2 and "UFL conditions" not in result.stdout, result.stdout
    assert len(result.stderr.splitlines()) == 1 and "split_rates failed: UFLException" in result.stderr


@pytest.mark.parametrize("split_rates, message", [
    (lambda self, c, t, ops: {"q": (np.exp(-c["q"]) + 1.0, 1.0)},
     "split_rates on dual numbers failed: TypeError: operand 'Dual' does not support ufuncs"),
    (lambda self, c, t, ops: {"q": (1.0 if c["q"] > 0 else 0.0, 1.0)},
     "split_rates on dual numbers failed: TypeError: '>' not supported between instances of 'Dual' and 'int'"),
])
def test_a_kinetics_dual_numbers_do_not_take_is_one_line_in_the_stability_analysis(split_rates, message):
    """Each was a traceback of primordia.analysis.composed under `primordia stability`."""
    with registered(Plugin([_kinetics("qa_not_dual", split_rates=split_rates)])), pytest.raises(PluginError) as error:
        linearise_model(_model("qa_not_dual"))
    assert str(error.value).startswith("kinetics qa_not_dual") and message in str(error.value), str(error.value)


def _law(name, factors, requires=()):
    return type(f"Law_{name}", (GrowthLaw,), {"name": name, "requires": requires, "dimensions": (2,),
                                              "factors": lambda self, fields, t, X, dimension: factors(fields, t)})


@pytest.mark.parametrize("factors, requires, message", [
    (lambda fields, t: [0.1 * t], (), "factors must return 2 growth factors in 2D (one per direction k_i), got 1"),
    (lambda fields, t: [t, t, t], (), "got 3"),
    (lambda fields, t: None, (), "got None"),
    (lambda fields, t: ["0.1 * t", 0.0], (), "gamma_1 is '0.1 * t'"),
    (lambda fields, t: [fields["m"], t], (), "factors read the field 'm', which is not in its requires (none)"),
])
def test_a_growth_law_breaking_its_contract_is_one_line_naming_it(factors, requires, message):
    law = _law("qa_broken_law", factors, requires)(ParameterSet(()))
    with pytest.raises(PluginError) as error:
        law.growth_tensor({name: 0.5 for name in requires}, 1.0, None, 2)
    assert str(error.value).startswith("growth law qa_broken_law: ") and message in str(error.value)


def test_a_growth_law_reading_an_undeclared_parameter_is_one_line_naming_it():
    """It was "unknown parameter 'rate'", naming no law (a kinetics' split_rates is named)."""
    law = _law("qa_undeclared", lambda fields, t: [t, t])
    law.factors = lambda self, fields, t, X, dimension: [t, self.params["rate"] * t]
    with pytest.raises(PluginError) as error:
        law(ParameterSet(())).growth_tensor({}, 1.0, None, 2)
    assert str(error.value).startswith("growth law qa_undeclared: factors failed: ConfigError: unknown parameter "
                                       "'rate'"), str(error.value)


MISSPELT = """\
from primordia.core.plugins import hookimpl

@hookimpl
def primordia_kinetic():
    return []
"""

WRONG_ARGUMENTS = """\
from primordia.core.plugins import hookimpl

@hookimpl
def primordia_kinetics(config):
    return []
"""

NO_RATES = """\
from primordia.core.plugins import hookimpl
from primordia.core.parameters import Parameter
from primordia.physics.kinetics.base import Kinetics, Species


class NoRates(Kinetics):
    name = "norates"
    species = (Species("q", "q", diffusivity="D_q"),)
    parameters = (Parameter("D_q", 1.0, "d"),)

    def initial_state(self, t0, ops):
        return {"q": 1.0}


@hookimpl
def primordia_kinetics():
    return [NoRates]
"""


def test_a_misspelt_hook_and_a_hook_with_unknown_arguments_are_listed_as_broken(primordia_cli, plugin_distribution):
    plugin_distribution("primordia-misspelt", "0.1", {"misspelt": MISSPELT}, {"misspelt": "misspelt"})
    env = plugin_distribution("primordia-arguments", "0.1", {"arguments": WRONG_ARGUMENTS}, {"arguments": "arguments"})
    listed = primordia_cli("plugins", env=env)
    assert listed.returncode == 0 and "Traceback" not in listed.stderr, listed.stderr
    warnings = listed.stderr.splitlines()
    assert len(warnings) == 2, listed.stderr
    assert any("plugin 'misspelt'" in line and "its @hookimpl primordia_kinetic is not a hook of primordia "
               "(did you mean primordia_kinetics?)" in line for line in warnings), warnings
    assert any("plugin 'arguments'" in line and "Argument(s) {'config'} are declared in the hookimpl" in line
               for line in warnings), warnings


def test_a_run_naming_a_skipped_kinetics_is_one_line_saying_why(primordia_cli, plugin_distribution, small_config,
                                                                 tmp_path):
    env = plugin_distribution("primordia-norates", "0.1", {"norates_plugin": NO_RATES}, {"norates": "norates_plugin"})
    config = small_config(small_config.text.replace("m0 = 0.75\nD_m = 0.03\n", ""))
    ran = primordia_cli("run", config, "--out", tmp_path / "out", "--dry-run", "--set", "kinetics.name=norates", env=env)
    assert ran.returncode == 2 and "Traceback" not in ran.stderr, ran.stderr
    assert ran.stderr.splitlines()[-1] == (
        "primordia: error: kinetics 'norates' was skipped: plugin 'norates' (primordia-norates 0.1): hook "
        "primordia_kinetics returned 'norates' (NoRates), which does not define the required split_rates; "
        "its kinetics are skipped")


def test_a_hook_marked_optional_is_not_taken_for_a_misspelt_one():
    """pluggy's ``optionalhook=True`` says on purpose that the hook may not exist (a newer primordia's)."""
    from primordia.core.plugins import _check_hook_names, get_plugin_manager

    class Ahead:
        @hookimpl(optionalhook=True)
        def primordia_a_later_hook(self):
            return []

    class Misspelt:
        @hookimpl
        def primordia_growth_law(self):
            return []

    pm = get_plugin_manager()
    ahead, misspelt = Ahead(), Misspelt()
    pm.register(ahead, name="tests.ahead")
    pm.register(misspelt, name="tests.misspelt")
    try:
        _check_hook_names(pm, ahead, "tests.ahead")
        with pytest.raises(PluginError, match="primordia_growth_law is not a hook of primordia "
                                              r"\(did you mean primordia_growth_laws\?\)"):
            _check_hook_names(pm, misspelt, "tests.misspelt")
        assert pm.get_plugin("tests.misspelt") is None  # refused: unregistered again
    finally:
        for name in ("tests.ahead", "tests.misspelt"):
            if pm.get_plugin(name) is not None:
                pm.unregister(name=name)


def test_a_growth_law_reading_a_field_no_module_provides_is_refused_naming_it():
    """Refused when the model is composed (so by --dry-run too); at set-up the line did not name the law."""
    with pytest.raises(ConfigError, match=r"growth law seed2d reads m, which no physics module of this model "
                                          r"provides \(fields: p, psi, u\)"):
        Model(physics=["poroelastic_growth"], growth_law="seed2d", mesh=rectangle((0, 0), (1, 1), (2, 2)),
              dt=0.1, t_final=0.2, output={"pictures": False})


class _Named(Physics):
    """Owns one field, named by a subclass: nothing else."""

    name = "qa_named"
    field_name = "q"

    def fields(self):
        return [FieldSpec(self.field_name)]

    def setup(self, disc):
        pass

    def initialise(self, disc):
        pass

    def subproblems(self):
        return []


class PhysicsPlugin:
    def __init__(self, *physics):
        self.physics = list(physics)

    @hookimpl
    def primordia_physics(self):
        return self.physics


@pytest.mark.parametrize("name", ["cell density", "m.1", ""])
def test_a_field_named_what_no_file_or_key_can_hold_names_the_module(name):
    """A field is a NetCDF variable, a picture's file name and a TOML key: 'cell density' was accepted."""
    spaced = type("Spaced", (_Named,), {"name": "qa_spaced", "field_name": name})
    with registered(PhysicsPlugin(spaced)), pytest.raises(PluginError) as error:
        Model(physics=["qa_spaced"], mesh=rectangle((0, 0), (4, 4), (4, 4)), dt=0.2, t_final=0.4)
    assert str(error.value).startswith(f"physics qa_spaced: a field is named {name!r}, not a name")


class _Scalar(Physics):
    """A passive scalar s: ds/dt = lap s, zero flux; the physics modules below break it one way each."""

    name = "qa_scalar"

    def fields(self):
        return [FieldSpec("s")]

    def setup(self, disc):
        self.disc = disc

    def initialise(self, disc):
        disc.interpolate("s", 1.0)

    def subproblems(self):
        import ufl

        from primordia.physics.base import Subproblem

        disc = self.disc
        s, v = disc.field("s"), disc.test("s")
        residual = (s - disc.previous("s")) / disc.dt * v * disc.dx + ufl.inner(ufl.grad(s), ufl.grad(v)) * disc.dx
        return [Subproblem(name="qa_scalar.s", unknown=disc.unknown("s"), residual=residual,
                           jacobian=ufl.derivative(residual, disc.unknown("s")))]


def _set_up(physics_class, tmp_path):
    from primordia.coupling.orchestrator import Simulation

    with registered(PhysicsPlugin(physics_class)):
        model = Model(physics=[physics_class.name], mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1, t_final=0.2,
                      output={"pictures": False})
        return Simulation(model, backend="skfem", out_dir=tmp_path / "out").setup()


@pytest.mark.parametrize("fields", ["s", ["s"], None])
def test_a_physics_module_whose_fields_are_no_list_of_field_specs_is_one_line_when_composed(fields):
    """Composed (so by --dry-run too): it was an AttributeError traceback ('str' object has no attribute 'name')."""
    broken = type("Broken", (_Scalar,), {"name": "qa_fields", "fields": lambda self: fields})
    with registered(PhysicsPlugin(broken)), pytest.raises(PluginError) as error:
        Model(physics=["qa_fields"], mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1, t_final=0.2)
    assert str(error.value) == (f"physics qa_fields: fields() must return a list of primordia.physics.base.FieldSpec, "
                                f"got {fields!r}")


def test_a_physics_module_whose_setup_raises_is_one_line_naming_it_and_where(tmp_path):
    """A plugin's bug in setup (initialise, subproblems...) was a bare traceback and exit status 1."""
    def setup(self, disc):
        disc.no_such_method()

    broken = type("Broken", (_Scalar,), {"name": "qa_setup", "setup": setup, "__module__": __name__})
    with pytest.raises(PluginError) as error:
        _set_up(broken, tmp_path)
    message = str(error.value)
    assert message.startswith(f"physics qa_setup ({__name__}.Broken): setup failed: AttributeError: "
                              f"'Discretisation' object has no attribute 'no_such_method' (at {__file__}:"), message
    assert "\n" not in message and isinstance(error.value.__cause__, AttributeError)  # the traceback stays the cause


@pytest.mark.parametrize("subproblems, fragment", [
    (lambda self: _Scalar.subproblems(self)[0], "subproblems() must return a list of "
                                                 "primordia.physics.base.Subproblem, got Subproblem("),
    (lambda self: [dataclasses.replace(_Scalar.subproblems(self)[0], residual=1.0)],
     "subproblem qa_scalar.s's residual must be a UFL form"),
    (lambda self: [dataclasses.replace(_Scalar.subproblems(self)[0], jacobian=None)],
     "subproblem qa_scalar.s's jacobian must be a UFL form"),
])
def test_a_physics_module_whose_subproblems_are_malformed_is_one_line_naming_it(subproblems, fragment, tmp_path):
    """Was a TypeError or AttributeError traceback from deep in the solver layer."""
    broken = type("Broken", (_Scalar,), {"name": "qa_subproblems", "subproblems": subproblems})
    with pytest.raises(PluginError) as error:
        _set_up(broken, tmp_path)
    assert str(error.value).startswith("physics qa_subproblems: ") and fragment in str(error.value), str(error.value)


def test_the_well_behaved_scalar_sets_up(tmp_path):
    assert _set_up(_Scalar, tmp_path).disc.field_names() == ["s"]


@pytest.mark.parametrize("description", ["", "   "])
def test_a_parameter_without_a_description_names_the_piece(description):
    """Every message about a parameter quotes its description: "parameter D_h must be > 0 (), got -1"."""
    undescribed = type("Undescribed", (_Scalar,), {"name": "qa_undescribed",
                                                   "parameters": (Parameter("D_s", 1.0, description),)})
    with registered(PhysicsPlugin(undescribed)), pytest.raises(PluginError) as error:
        Model(physics=["qa_undescribed"], mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1, t_final=0.2)
    assert str(error.value).startswith("physics qa_undescribed declares parameter D_s without a description")
