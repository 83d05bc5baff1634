"""A piece a test puts in with ``primordia.testing.registered`` under a name an installed plugin has.

Writing a plugin from docs/plugins.md with an older version of it installed (``reverse_sequential`` here), the
guide's own test ran the installed class instead of the one it registered: a warning on stderr, which pytest
captures, and a passing test of the wrong code.
"""

import pytest

from primordia.core.errors import PluginError
from primordia.core.plugins import get_plugin_manager, hookimpl, registry
from primordia.coupling.splitting import Sequential
from primordia.testing import registered


class Installed(Sequential):
    name = "qa_scheme"


class UnderTest(Sequential):
    name = "qa_scheme"


class Plugin:
    def __init__(self, scheme):
        self.scheme = scheme

    @hookimpl
    def primordia_splitting_schemes(self):
        return [self.scheme]


@pytest.fixture
def installed():
    """``Installed`` in the plugin manager under a plugin name of its own, as an entry point puts it."""
    pm = get_plugin_manager()
    pm.register(Plugin(Installed), name="qa_installed_distribution")
    try:
        yield
    finally:
        pm.unregister(name="qa_installed_distribution")


def test_a_registered_piece_whose_name_is_taken_is_an_error_not_the_installed_piece(installed):
    with registered(Plugin(UnderTest)), pytest.raises(PluginError) as error:
        registry("splitting_schemes")
    assert str(error.value) == ("plugin 'primordia.testing.0' (primordia.testing.0): hook primordia_splitting_schemes "
                                "reuses the name 'qa_scheme', taken by qa_installed_distribution")


def test_without_the_clash_the_registered_piece_is_the_one_found():
    with registered(Plugin(UnderTest)):
        assert registry("splitting_schemes")["qa_scheme"][0] is UnderTest
    assert "qa_scheme" not in registry("splitting_schemes")
