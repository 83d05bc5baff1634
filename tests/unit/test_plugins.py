"""The plugin registry (primordia.core.plugins, primordia.core.selection, ``primordia plugins``).

Built-ins register through the same hooks as third parties; entry points of the
group ``primordia`` are loaded once; a broken plugin is one warning and is
skipped; the ``firstresult`` choosers can be overridden; unknown names raise
:class:`PluginError` naming what is registered.
"""

from __future__ import annotations

import json
import os
import tomllib

import pytest

from primordia.core.errors import PluginError, PrimordiaError
from primordia.core.meshes import rectangle
from primordia.core.plugins import get_plugin_manager, hookimpl, lookup, registry
from primordia.coupling.orchestrator import Simulation
from primordia.coupling.splitting import Sequential
from primordia.model import Model

from cli_checks import listing
from mms import PhysicsPlugin
from plugin_sources import FROZEN_KINETICS

BUILT_IN = "primordia (built-in)"

BROKEN_PLUGIN = """\
raise RuntimeError("this plugin is broken on purpose")
"""


def small_model(**kwargs) -> Model:
    return Model(physics=["chemotaxis"], parameters={"m0": 0.75, "D_m": 0.03},
                 mesh=rectangle((0, 0), (4, 4), (6, 6)), dt=0.2, t_final=0.6,
                 output={"pictures": False}, **kwargs)


# -- what is registered, and from where ---------------------------------------------------


def test_plugins_lists_every_built_in_piece_and_its_origin(primordia_cli):
    result = primordia_cli("plugins")
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    table = listing(result.stdout)
    expected = {
        "physics": ["chemotaxis"],
        "kinetics": ["painter2018"],
        "backends": ["fenicsx", "skfem"],
        "splitting_schemes": ["sequential"],
        "outputs": ["config", "xdmf", "series", "pictures", "summary"],
    }
    for kind, names in expected.items():
        assert kind in table, f"no '{kind}:' section in\n{result.stdout}"
        for name in names:
            assert name in table[kind], f"{kind} {name} not listed"
            assert table[kind][name].startswith(BUILT_IN), table[kind][name]
    # a backend that cannot be imported is a failure, not a footnote
    for backend in ("fenicsx", "skfem"):
        assert table["backends"][backend].endswith("[available]"), f"{backend}: {table['backends'][backend]}"


def test_registry_reports_built_in_origin_in_process():
    for kind, name in [("physics", "chemotaxis"), ("kinetics", "painter2018"), ("backends", "fenicsx"),
                       ("splitting_schemes", "sequential"), ("outputs", "summary")]:
        piece, origin = registry(kind)[name]
        assert piece.name == name and origin == BUILT_IN


# -- entry points -------------------------------------------------------------------------------


def test_an_entry_point_kinetics_is_listed_with_its_distribution(primordia_cli, plugin_distribution):
    env = plugin_distribution("primordia-frozen-kinetics", "0.3", {"frozen_kinetics": FROZEN_KINETICS},
                              {"frozen": "frozen_kinetics"})
    result = primordia_cli("plugins", env=env)
    assert result.returncode == 0, result.stderr
    kinetics = listing(result.stdout)["kinetics"]
    assert kinetics["frozen"] == "primordia-frozen-kinetics 0.3"
    assert kinetics["painter2018"] == BUILT_IN


def test_an_entry_point_kinetics_can_be_selected_in_a_run(primordia_cli, plugin_distribution, small_config,
                                                          tmp_path):
    env = plugin_distribution("primordia-frozen-kinetics", "0.3", {"frozen_kinetics": FROZEN_KINETICS},
                              {"frozen": "frozen_kinetics"})
    out = tmp_path / "out"
    result = primordia_cli("run", small_config(), "--out", out, "--no-progress",
                           "--set", "kinetics.name=frozen", env=env)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    with open(out / "config.toml", "rb") as stream:
        assert tomllib.load(stream)["kinetics"]["name"] == "frozen"
    final = json.loads((out / "summary.json").read_text())["final"]
    # painter2018 would react; frozen leaves its own rest state untouched
    for species, value in {"e": 0.5, "f": 0.25, "b": 0.125}.items():
        assert final[species]["min"] == pytest.approx(value, abs=1e-12), species
        assert final[species]["max"] == pytest.approx(value, abs=1e-12), species


def test_an_entry_point_naming_a_class_is_one_warning_saying_so(primordia_cli, plugin_distribution):
    """It was "hook primordia_kinetics raised TypeError: FrozenPlugin.primordia_kinetics() missing 1 required
    positional argument: 'self'", once per hook, for a plugin written as the guide's classes are."""
    source = FROZEN_KINETICS.replace("@hookimpl\ndef primordia_kinetics():",
                                     "class FrozenPlugin:\n    @hookimpl\n    def primordia_kinetics(self):")
    source = source.replace("\n    return [Frozen]", "\n        return [Frozen]")
    env = plugin_distribution("primordia-frozen-class", "0.1", {"frozen_class": source},
                              {"frozen": "frozen_class:FrozenPlugin"})
    listed = primordia_cli("plugins", env=env)
    assert listed.returncode == 0 and len(listed.stderr.splitlines()) == 1, listed.stderr
    assert listed.stderr.startswith("primordia: warning: plugin 'frozen' (primordia-frozen-class 0.1) failed to load "
                                    "and is skipped: PluginError: frozen_class:FrozenPlugin is a class, whose "
                                    "@hookimpl methods need an instance"), listed.stderr


def test_a_broken_entry_point_is_one_warning_and_the_rest_works(primordia_cli, plugin_distribution,
                                                                small_config, tmp_path):
    plugin_distribution("primordia-broken", "1.0", {"broken_plugin": BROKEN_PLUGIN}, {"broken": "broken_plugin"})
    env = plugin_distribution("primordia-frozen-kinetics", "0.3", {"frozen_kinetics": FROZEN_KINETICS},
                              {"frozen": "frozen_kinetics"})

    listed = primordia_cli("plugins", env=env)
    assert listed.returncode == 0
    warnings = listed.stderr.splitlines()
    assert len(warnings) == 1, listed.stderr
    assert warnings[0].startswith("primordia: warning: plugin 'broken' (primordia-broken 1.0)")
    assert "broken on purpose" in warnings[0]
    table = listing(listed.stdout)
    assert "painter2018" in table["kinetics"] and "frozen" in table["kinetics"]

    ran = primordia_cli("run", small_config(), "--out", tmp_path / "out", "--no-progress",
                        "--set", "kinetics.name=frozen", env=env)
    assert ran.returncode == 0, ran.stderr
    assert len(ran.stderr.splitlines()) == 1 and "plugin 'broken'" in ran.stderr
    assert "Traceback" not in ran.stderr
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["status"] == "completed"


# -- plugins not installed: PRIMORDIA_PLUGINS and -p ------------------------------------------------


def test_a_plugin_file_not_installed_is_loaded_by_p_and_used_in_a_run(primordia_cli, small_config, tmp_path):
    """Before, a plugin had to be installed (an entry point) to be found: "-p" was an unknown argument."""
    plugin = tmp_path / "my_frozen.py"
    plugin.write_text(FROZEN_KINETICS)
    listed = primordia_cli("-p", plugin, "plugins")
    assert listed.returncode == 0, listed.stderr
    assert listing(listed.stdout)["kinetics"]["frozen"] == f"{plugin.resolve()} (PRIMORDIA_PLUGINS)"
    out = tmp_path / "out"
    ran = primordia_cli("-p", plugin, "run", small_config(), "--out", out, "--no-progress",
                        "--set", "kinetics.name=frozen")
    assert ran.returncode == 0, ran.stderr
    final = json.loads((out / "summary.json").read_text())["final"]
    assert final["e"]["min"] == pytest.approx(0.5, abs=1e-12) and final["e"]["max"] == pytest.approx(0.5, abs=1e-12)
    relative = primordia_cli("-p", "my_frozen.py", "plugins", cwd=tmp_path)  # a sweep's runs start elsewhere
    assert listing(relative.stdout)["kinetics"]["frozen"] == f"{plugin.resolve()} (PRIMORDIA_PLUGINS)"

    # a restart without -p said "unknown kinetics 'frozen'", not where the run had it from
    longer = primordia_cli("run", "--restart", out, "--no-progress", "--set", "time.t_final=1.4")
    assert longer.returncode == 2 and len(longer.stderr.splitlines()) == 1, longer.stderr
    assert "unknown kinetics 'frozen'" in longer.stderr
    assert f"(the run loaded {plugin.resolve()} with -p: give it again, primordia -p {plugin.resolve()}" in longer.stderr
    again = primordia_cli("-p", plugin, "run", "--restart", out, "--no-progress", "--set", "time.t_final=1.4")
    assert again.returncode == 0, again.stderr


def test_primordia_plugins_names_modules_on_the_path_and_files(primordia_cli, tmp_path):
    (tmp_path / "frozen_module.py").write_text(FROZEN_KINETICS)
    other = tmp_path / "elsewhere" / "frozen_file.py"
    other.parent.mkdir()
    other.write_text(FROZEN_KINETICS.replace('"frozen"', '"frozen_too"'))
    env = {**os.environ, "PYTHONPATH": str(tmp_path), "PRIMORDIA_PLUGINS": f" frozen_module , {other}"}
    listed = primordia_cli("plugins", env=env)
    assert listed.returncode == 0, listed.stderr
    kinetics = listing(listed.stdout)["kinetics"]
    assert kinetics["frozen"] == "module frozen_module (PRIMORDIA_PLUGINS)"
    assert kinetics["frozen_too"] == f"{other} (PRIMORDIA_PLUGINS)"


@pytest.mark.parametrize("make, expected", [
    (lambda tmp: tmp / "absent.py", "plugin '{path}' (PRIMORDIA_PLUGINS): no such file"),
    (lambda tmp: "no_such_plugin_module", "plugin 'no_such_plugin_module' (PRIMORDIA_PLUGINS) failed to load: "
                                          "ModuleNotFoundError: No module named 'no_such_plugin_module'"),
    (lambda tmp: _written(tmp / "broken.py", BROKEN_PLUGIN),
     "plugin '{path}' (PRIMORDIA_PLUGINS) failed to load: RuntimeError: this plugin is broken on purpose "
     "(at {path}:1)"),
    (lambda tmp: _written(tmp / "misspelt.py", "from primordia.core.plugins import hookimpl\n\n"
                                               "@hookimpl\ndef primordia_kinetic():\n    return []\n"),
     "failed to load: its @hookimpl primordia_kinetic is not a hook of primordia (did you mean primordia_kinetics?)"),
    (lambda tmp: _written(tmp / "painter2018.py", FROZEN_KINETICS),  # the name a built-in module is registered by?
     None),
    (lambda tmp: "primordia.physics.kinetics", "the name 'primordia.physics.kinetics' is taken by primordia "
                                               "(built-in)"),
    (lambda tmp: "primordia_logistic", "failed to load: it is registered already, as 'logistic' "
                                       "(primordia-logistic 0.1.0)"),
], ids=["missing file", "missing module", "raises on import", "misspelt hook", "file named like a piece",
        "a built-in again", "an installed plugin again"])
def test_a_named_plugin_that_cannot_be_loaded_is_one_line_and_exit_2(primordia_cli, tmp_path, make, expected):
    """A plugin asked for by name stops the program (an installed one that breaks is a warning and skipped)."""
    item = make(tmp_path)
    result = primordia_cli("-p", item, "plugins")
    if expected is None:  # a file's name is its plugin's name, which may equal a piece's: no clash
        assert result.returncode == 0, result.stderr
        return
    assert result.returncode == 2, result.stdout
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("primordia: error: "), result.stderr
    assert expected.format(path=item) in lines[0]


@pytest.mark.parametrize("source, expected", [
    (FROZEN_KINETICS.replace('"frozen"', '"painter2018"'),
     "hook primordia_kinetics reuses the name 'painter2018', taken by primordia (built-in)"),
    (FROZEN_KINETICS.replace("return [Frozen]", "raise RuntimeError('broken on purpose')"),
     "hook primordia_kinetics raised RuntimeError: broken on purpose"),
    (FROZEN_KINETICS.replace("return [Frozen]", "return Frozen"), "hook primordia_kinetics returned <class "),
    # "which is not a Output class"
    (FROZEN_KINETICS.replace("def primordia_kinetics():", "def primordia_outputs():"),
     "hook primordia_outputs returned <class 'primordia_plugin_mine.Frozen'>, which is not an Output class"),
], ids=["a name taken", "a hook that raises", "not a list", "not an output"])
def test_a_named_plugin_whose_hook_is_broken_stops_in_one_line(primordia_cli, small_config, tmp_path, source,
                                                               expected):
    """Before, it was one warning, its kinetics skipped, and the run went on: with the built-in painter2018 when
    the file's kinetics reused that name, which the author asked for by ``-p`` and did not get."""
    plugin = _written(tmp_path / "mine.py", source)
    for args in (["plugins"], ["run", small_config(), "--out", tmp_path / "out", "--dry-run"]):
        result = primordia_cli("-p", plugin, *args)
        assert result.returncode == 2, result.stderr
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"primordia: error: plugin 'mine' ({plugin} "), result.stderr
        assert expected in lines[0]


def test_p_with_a_comma_or_nothing_is_refused(primordia_cli):
    for item in ["a.py,b.py", " "]:
        result = primordia_cli("-p", item, "plugins")
        assert result.returncode == 2
        assert result.stderr.strip() == "primordia: error: -p needs one module name or .py file each time (no commas)"


def _written(path, text: str):
    path.write_text(text)
    return path


# -- the firstresult choosers ---------------------------------------------------------------------


@pytest.fixture
def registered():
    """``registered(plugin)`` registers a plugin object for the test, unregistering it afterwards."""
    pm = get_plugin_manager()
    names = []

    def register(plugin):
        names.append(pm.register(plugin))
        return plugin

    yield register
    for name in names:
        pm.unregister(name=name)


def test_a_plugin_backend_chooser_overrides_the_built_in_one(registered, tmp_path):
    from primordia.backends.fenicsx import FenicsxBackend

    class InstrumentedBackend(FenicsxBackend):
        name = "fenicsx-instrumented"

    class PreferInstrumented:
        asked = []

        @hookimpl
        def primordia_select_backend(self, name, entries, comm):
            self.asked.append(name)
            return InstrumentedBackend(comm) if name == "fenicsx" else None

    chooser = registered(PreferInstrumented())
    sim = small_model().run(backend="fenicsx", out=tmp_path / "run")
    assert chooser.asked == ["fenicsx"]
    assert type(sim.backend) is InstrumentedBackend
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["backend"] == "fenicsx-instrumented"


def test_a_chooser_returning_none_defers_to_the_built_in_one(registered, tmp_path):
    class Abstains:
        @hookimpl
        def primordia_select_backend(self, name, entries, comm):
            return None

    registered(Abstains())
    sim = Simulation(small_model(), backend="fenicsx", out_dir=tmp_path / "run").setup()
    assert sim.backend.name == "fenicsx"


def test_a_plugin_splitting_chooser_overrides_the_built_in_one(registered, tmp_path):
    class CountingSequential(Sequential):
        name = "counting"
        steps = 0

        def advance(self, sim, *args, **kwargs):
            CountingSequential.steps += 1
            return super().advance(sim, *args, **kwargs)

    class PreferCounting:
        @hookimpl
        def primordia_select_splitting_scheme(self, name, options, schemes, physics):
            return CountingSequential(physics, **options) if name == "sequential" else None

    registered(PreferCounting())
    model = small_model()
    sim = model.run(out=tmp_path / "run")
    assert isinstance(sim.scheme, CountingSequential)
    assert CountingSequential.steps == model.num_steps == 3


# -- unknown names -------------------------------------------------------------------------------


@pytest.mark.parametrize("kind, label, known", [
    ("physics", "physics", "chemotaxis"), ("kinetics", "kinetics", "painter2018"),
    ("backends", "backend", "fenicsx"), ("splitting_schemes", "splitting scheme", "sequential"),
    ("outputs", "output", "summary"),
])
def test_lookup_of_an_unknown_name_names_the_registered_ones(kind, label, known):
    with pytest.raises(PluginError, match=rf"^unknown {label} 'no_such_thing' \(registered: .*{known}"):
        lookup(kind, "no_such_thing")


def test_unknown_physics_raises_plugin_error():
    with pytest.raises(PluginError, match=r"unknown physics 'elasticity_typo' \(registered: .*chemotaxis"):
        Model(physics=["elasticity_typo"], mesh=rectangle(cells=(2, 2)), dt=1.0, t_final=1.0)


def test_unknown_kinetics_raises_plugin_error():
    with pytest.raises(PluginError, match=r"unknown kinetics 'painter2019' \(registered: .*painter2018"):
        small_model(kinetics="painter2019")


def test_unknown_backend_raises_plugin_error(tmp_path):
    with pytest.raises(PluginError, match=r"unknown backend 'deal\.ii' \(registered: .*fenicsx.*skfem"):
        Simulation(small_model(), backend="deal.ii", out_dir=tmp_path / "run").setup()


def test_unknown_splitting_scheme_raises_plugin_error(tmp_path):
    with pytest.raises(PluginError, match=r"unknown splitting scheme 'leapfrog' \(registered: .*sequential"):
        Simulation(small_model(coupling="leapfrog"), out_dir=tmp_path / "run").setup()


def test_plugin_errors_are_user_errors():
    """The CLI prints any PrimordiaError as one line; PluginError must be one."""
    assert issubclass(PluginError, PrimordiaError)


def test_a_plugin_registered_after_another_was_unregistered_is_the_one_looked_up():
    """The registry's cache is keyed by the hook functions' ids: an unregistered plugin's function
    must not be freed and its id reused by the next one (which would then get the old contributions)."""
    from primordia.physics.chemotaxis import Chemotaxis

    pm = get_plugin_manager()
    for generation in range(40):  # a concrete physics: an abstract class is no piece (it is skipped as broken)
        physics = type("Probe", (Chemotaxis,), {"name": "registry_probe", "generation": generation})
        pm.register(PhysicsPlugin(physics), name="tests.registry_probe")
        try:
            assert registry("physics", pm)["registry_probe"][0].generation == generation
        finally:
            pm.unregister(name="tests.registry_probe")


def test_a_run_records_its_software_and_a_restart_without_its_installed_plugin_names_it(
        primordia_cli, small_config, plugin_distribution, tmp_path):
    """summary.json said nothing of the versions or plugins a result was computed with, and a restart where the
    plugin's distribution was gone said only "unknown kinetics 'frozen'" (the packaging QA pass)."""
    env = plugin_distribution("primordia-frozen-kinetics", "0.3", {"frozen_kinetics": FROZEN_KINETICS},
                              {"frozen": "frozen_kinetics"})
    out = tmp_path / "out"
    ran = primordia_cli("run", small_config(), "--out", out, "--no-progress", "--set", "kinetics.name=frozen", env=env)
    assert ran.returncode == 0, ran.stderr
    software = json.loads((out / "summary.json").read_text())["software"]
    import dolfinx
    import primordia

    assert software["primordia"] == primordia.__version__ and software["dolfinx"] == dolfinx.__version__
    assert software["petsc"].startswith("3.") and software["plugins"]["frozen"] == "primordia-frozen-kinetics 0.3"
    longer = primordia_cli("run", "--restart", out, "--no-progress", "--set", "time.t_final=1.4")  # not installed
    assert longer.returncode == 2 and len(longer.stderr.splitlines()) == 1, longer.stderr
    assert longer.stderr.startswith("primordia: error: unknown kinetics 'frozen'")
    assert "(the run was made with the plugin frozen from primordia-frozen-kinetics 0.3, not installed here)" \
        in longer.stderr
