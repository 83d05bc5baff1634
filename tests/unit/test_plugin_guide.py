"""Every worked example of the plugin author's guide (docs/plugins.md) runs and passes its own tests.

Each ```python block of the guide is executed as a module of its own (so ``f"{__name__}:Class"``
names an importable target, as in a package), then every ``test_*`` function it defines is called,
with a fresh ``tmp_path`` when it asks for one, from the repository root (the examples read
``examples/*.toml``).
"""

from __future__ import annotations

import inspect
import re
import sys
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "plugins.md"
BLOCKS = re.findall(r"```python\n(.*?)```", GUIDE.read_text(), flags=re.S)
RUNNABLE = [(index, code) for index, code in enumerate(BLOCKS) if "def test_" in code]


def test_the_guide_covers_every_contributing_hook():
    text = GUIDE.read_text()
    from primordia.core.plugins import HOOK_BY_KIND

    for hook in HOOK_BY_KIND.values():
        assert f"`{hook}`" in text, f"docs/plugins.md has no section on {hook}"
    assert len(RUNNABLE) >= len(HOOK_BY_KIND), "each hook's section needs a worked, tested example"


@pytest.mark.parametrize("index, code", RUNNABLE, ids=[f"block{index}" for index, _ in RUNNABLE])
def test_a_worked_example_of_the_guide(index, code, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    name = f"plugin_guide_block{index}"
    module = types.ModuleType(name)
    sys.modules[name] = module
    try:
        exec(compile(code, f"{GUIDE}:block{index}", "exec"), module.__dict__)
        tests = [(key, fn) for key, fn in module.__dict__.items() if key.startswith("test_") and callable(fn)]
        assert tests, "the block defines no test"
        for key, fn in tests:
            arguments = {"tmp_path": tmp_path / key} if "tmp_path" in inspect.signature(fn).parameters else {}
            fn(**arguments)
    finally:
        del sys.modules[name]


FUTURE_PLUGIN = '''
import pluggy

PRIMORDIA_CONTRACT = 2
hookimpl = pluggy.HookimplMarker("primordia")


@hookimpl
def primordia_kinetics():
    return []
'''


def test_a_plugin_written_for_another_contract_version_is_one_warning(primordia_cli, plugin_distribution):
    from primordia.core.hookspecs import CONTRACT_VERSION

    env = plugin_distribution("primordia-future", "9.0", {"future_plugin": FUTURE_PLUGIN}, {"future": "future_plugin"})
    listed = primordia_cli("plugins", env=env)
    assert listed.returncode == 0
    (warning,) = listed.stderr.splitlines()
    assert warning.startswith("primordia: warning: plugin 'future' (primordia-future 9.0)")
    assert f"version 2 of primordia's hook contract, this is {CONTRACT_VERSION[0]}" in warning
    assert "painter2018" in listed.stdout  # the rest keeps working


def test_the_guides_kinetics_options_table_is_what_painter2018_takes():
    """The guide's ``[kinetics]`` example names a real option with a value of its type (the plugin QA pass found
    the options undocumented)."""
    import tomllib

    from primordia.core.config import merge_options
    from primordia.physics.kinetics.painter2018 import Painter2018

    tables = [tomllib.loads(block) for block in re.findall(r"```toml\n(.*?)```", GUIDE.read_text(), flags=re.S)]
    (kinetics,) = [table["kinetics"] for table in tables if "kinetics" in table]
    name = kinetics.pop("name")
    assert name == Painter2018.name and kinetics
    assert merge_options(f"kinetics {name}", Painter2018.options, kinetics) == {**Painter2018.options, **kinetics}
