"""Plugins that misbehave cannot break primordia (issue 10), through the real ``primordia`` command.

A hook that raises, answers something that is not a list of named pieces of its
kind, or reuses a name already taken: one warning naming the plugin, its
contribution skipped, the built-ins and the other plugins working, and
``primordia plugins`` listing it as broken.  An output writer that fails is
disabled with one warning and the run goes on.
"""

from __future__ import annotations

import json

import pytest

from cli_checks import listing
from plugin_sources import FROZEN_KINETICS

RAISES = """\
from primordia.core.plugins import hookimpl

@hookimpl
def primordia_physics():
    raise RuntimeError("this hook raises on purpose")
"""

JUNK = {
    "a-string": 'return "chemotaxis"',
    "none-in-a-list": "return [None]",
    "a-class-without-a-name": "return [type('NoName', (), {})]",
    "not-a-kinetics": "return [type('Named', (), {'name': 'named'})]",
}

REUSES = """\
from primordia.core.plugins import hookimpl
from primordia.physics.chemotaxis import Chemotaxis


class Impostor(Chemotaxis):
    name = "chemotaxis"

    def subproblems(self):
        raise RuntimeError("the impostor ran")


@hookimpl
def primordia_physics():
    return [Impostor]
"""

FAILING_OUTPUT = """\
from primordia.core.outputs import Output
from primordia.core.plugins import hookimpl


class Exploding(Output):
    name = "exploding"
    calls = 0

    def record(self, run):
        raise OSError("disk full (injected)")


@hookimpl
def primordia_outputs():
    return [Exploding]
"""

CHOOSER_RAISES = """\
from primordia.core.plugins import hookimpl

@hookimpl
def primordia_select_backend(name, entries, comm):
    raise RuntimeError("this chooser breaks on purpose")
"""


def _install(plugin_distribution, name: str, source: str) -> dict:
    module = name.replace("-", "_")
    plugin_distribution("primordia-frozen-kinetics", "0.3", {"frozen_kinetics": FROZEN_KINETICS},
                        {"frozen": "frozen_kinetics"})
    return plugin_distribution(f"primordia-{name}", "0.1", {module: source}, {name: module})


def _assert_skipped_with_one_warning(primordia_cli, small_config, tmp_path, env, name: str, *fragments: str,
                                     run: bool = True):
    listed = primordia_cli("plugins", env=env)
    assert listed.returncode == 0 and "Traceback" not in listed.stderr, listed.stderr
    warnings = listed.stderr.splitlines()
    assert len(warnings) == 1 and warnings[0].startswith(f"primordia: warning: plugin '{name}'"), listed.stderr
    for fragment in fragments:
        assert fragment in warnings[0], warnings[0]
    table = listing(listed.stdout)
    assert name in table["broken"], listed.stdout
    assert "chemotaxis" in table["physics"] and table["physics"]["chemotaxis"].startswith("primordia (built-in)")
    assert "frozen" in table["kinetics"]  # the other plugin keeps working
    if not run:
        return
    ran = primordia_cli("run", small_config(), "--out", tmp_path / "out", "--no-progress",
                        "--set", "kinetics.name=frozen", env=env)
    assert ran.returncode == 0, ran.stderr
    assert ran.stderr.splitlines() == warnings, ran.stderr
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["status"] == "completed"


def test_a_hook_that_raises(primordia_cli, small_config, plugin_distribution, tmp_path):
    env = _install(plugin_distribution, "raises", RAISES)
    _assert_skipped_with_one_warning(primordia_cli, small_config, tmp_path, env, "raises",
                                     "primordia_physics raised RuntimeError: this hook raises on purpose")


@pytest.mark.parametrize("kind", list(JUNK))
def test_a_hook_that_answers_junk(primordia_cli, small_config, plugin_distribution, tmp_path, kind):
    source = f"from primordia.core.plugins import hookimpl\n\n@hookimpl\ndef primordia_kinetics():\n    {JUNK[kind]}\n"
    env = _install(plugin_distribution, "junk", source)
    _assert_skipped_with_one_warning(primordia_cli, small_config, tmp_path, env, "junk", "primordia_kinetics returned",
                                     run=kind == "a-string")


def test_a_hook_that_reuses_a_built_in_name(primordia_cli, small_config, plugin_distribution, tmp_path):
    env = _install(plugin_distribution, "impostor", REUSES)
    _assert_skipped_with_one_warning(primordia_cli, small_config, tmp_path, env, "impostor",
                                     "reuses the name 'chemotaxis', taken by primordia (built-in)")


def test_a_failing_output_writer_is_disabled_and_the_run_goes_on(primordia_cli, small_config, plugin_distribution,
                                                                 tmp_path):
    env = plugin_distribution("primordia-exploding", "0.1", {"exploding": FAILING_OUTPUT}, {"exploding": "exploding"})
    out = tmp_path / "out"
    ran = primordia_cli("run", small_config(), "--out", out, "--no-progress", "--set", "output.series_every=1", env=env)
    assert ran.returncode == 0, ran.stderr
    warnings = ran.stderr.splitlines()
    assert len(warnings) == 1, ran.stderr
    assert warnings[0] == ("primordia: warning: output 'exploding' failed at t = 0.2 (record): OSError: disk full "
                           "(injected); it is disabled for the rest of the run")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["steps"] == 5


def test_a_chooser_that_raises_is_skipped(primordia_cli, small_config, plugin_distribution, tmp_path):
    env = plugin_distribution("primordia-chooser", "0.1", {"chooser": CHOOSER_RAISES}, {"chooser": "chooser"})
    ran = primordia_cli("run", small_config(), "--out", tmp_path / "out", "--no-progress", env=env)
    assert ran.returncode == 0, ran.stderr
    warnings = ran.stderr.splitlines()
    assert len(warnings) == 1 and "plugin 'chooser'" in warnings[0] and "breaks on purpose" in warnings[0]
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["backend"] == "fenicsx"


def test_plugins_asks_the_backend_choosers_and_lists_a_broken_one(primordia_cli, plugin_distribution):
    """``primordia plugins`` names who chooses, in the order asked, and finds a chooser that breaks
    without a run: one warning, and the plugin listed as broken."""
    env = plugin_distribution("primordia-chooser", "0.1", {"chooser": CHOOSER_RAISES}, {"chooser": "chooser"})
    listed = primordia_cli("plugins", env=env)
    assert listed.returncode == 0 and "Traceback" not in listed.stderr, listed.stderr
    warnings = listed.stderr.splitlines()
    assert len(warnings) == 1 and "plugin 'chooser'" in warnings[0] and "breaks on purpose" in warnings[0], warnings
    table = listing(listed.stdout)
    assert "breaks on purpose" in table["broken"]["chooser"]
    assert table["choosers"]["primordia_select_backend"] == (
        "the backend, asking chooser [primordia-chooser 0.1], then primordia.core.selection [primordia (built-in)]")
    assert table["choosers"]["primordia_select_splitting_scheme"] == (
        "the splitting scheme, asking primordia.core.selection [primordia (built-in)]")


BUGGY_PHYSICS = """\
from primordia.core.plugins import hookimpl
from primordia.physics.base import Coupling


class Buggy(Coupling):
    name = "buggy"

    def setup(self, disc):
        disc.contribute("m", lambda v: disc.no_such_method() * v * disc.dx, by=self.name)


@hookimpl
def primordia_physics():
    return [Buggy]
"""


def test_a_bug_in_a_contributed_term_is_one_line_naming_it_and_exit_status_2(primordia_cli, small_config,
                                                                               plugin_distribution, tmp_path):
    """A third party's bug in a term it adds to a built-in's balance law was a 20-line traceback and exit status 1
    (the term is called by chemotaxis, primordia's own module, when it builds its forms)."""
    env = plugin_distribution("primordia-buggy", "0.1", {"buggy": BUGGY_PHYSICS}, {"buggy": "buggy"})
    ran = primordia_cli("run", small_config(), "--out", tmp_path / "out", "--no-progress",
                        "--set", 'model.physics=["chemotaxis", "buggy"]', env=env)
    assert ran.returncode == 2 and "Traceback" not in ran.stderr, ran.stderr
    assert ran.stderr.splitlines() == [
        f"primordia: error: the term buggy adds to the balance law of 'm' failed: AttributeError: 'Discretisation' "
        f"object has no attribute 'no_such_method' (at {tmp_path / 'site-packages' / 'buggy.py'}:9)"], ran.stderr


def test_a_name_two_installed_plugins_give_is_used_from_neither(primordia_cli, small_config, plugin_distribution,
                                                                 tmp_path):
    """Two installed plugins giving one kinetics: the one whose distribution the path listed first ran, with a
    warning and exit status 0, so the same config ran one plugin's kinetics on one machine and the other's on
    another.  A config naming it is now one line naming both, exit status 2; the rest keeps working."""
    env = _install(plugin_distribution, "frozen-copy", FROZEN_KINETICS)
    listed = primordia_cli("plugins", env=env)
    assert listed.returncode == 0 and "Traceback" not in listed.stderr, listed.stderr
    warning = listed.stderr.splitlines()
    assert len(warning) == 1 and "reuses the name 'frozen'" in warning[0], listed.stderr
    assert "frozen" not in listing(listed.stdout)["kinetics"], listed.stdout
    ran = primordia_cli("run", small_config(), "--out", tmp_path / "out", "--no-progress",
                        "--set", "kinetics.name=frozen", env=env)
    assert ran.returncode == 2 and "Traceback" not in ran.stderr, ran.stderr
    lines = ran.stderr.splitlines()
    assert lines[0] == warning[0] and len(lines) == 2, ran.stderr
    assert lines[1].startswith("primordia: error: kinetics 'frozen' was skipped: ") and "uninstall one" in lines[1]
    assert "primordia-frozen-kinetics 0.3" in lines[1] and "primordia-frozen-copy 0.1" in lines[1]
    ran = primordia_cli("run", small_config(), "--out", tmp_path / "built-in", "--no-progress", env=env)
    assert ran.returncode == 0 and ran.stderr.splitlines() == warning, ran.stderr
