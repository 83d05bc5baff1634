"""A third party's Fourier symbol whose ``add_to`` breaks is one line naming the module (``primordia stability``).

Found writing a physics module from docs/plugins.md alone: an ``add_to`` that raised, or added to a row no model
has or at an order past phi^2, was a traceback; a NaN was refused as "not a real pencil ... without the factor
i k", and an unknown declared without a row printed its dispersion relation, then a matplotlib traceback.
"""

import math

import numpy as np
import pytest

from primordia.analysis.composed import linearise_model
from primordia.core.errors import PrimordiaError
from primordia.core.meshes import rectangle
from primordia.model import Model


class Symbol:
    """q with dq/dt = -2 q + m unless ``breaks`` replaces add_to's entries."""

    def __init__(self, unknowns=("q",), breaks=None):
        self.unknowns, self.breaks = unknowns, breaks

    def add_to(self, system):
        if self.breaks is not None:
            return self.breaks(system)
        system.add(1, "q", "q", 1.0)
        system.add(0, "q", "q", 2.0 + 0.0 * system.K)
        system.add(0, "q", "m", -1.0)


def _linearised(symbol):
    model = Model(physics=["chemotaxis"], parameters={"m0": 0.75, "D_m": 0.03},
                  mesh=rectangle((0.0, 0.0), (1.0, 1.0), (2, 2)), dt=0.1, t_final=0.1)
    stranger = type("Stranger", (), {"name": "stranger", "finite_strain": False,
                                     "fourier_symbol": lambda self, context: symbol})()
    object.__setattr__(model, "physics_objects", model.physics_objects + [stranger])  # Model is read-only
    return linearise_model(model)


def _raise(system):
    raise RuntimeError("boom")


@pytest.mark.parametrize("symbol, message", [
    (Symbol(breaks=_raise), "physics stranger (test_fourier_symbol_checks.Stranger): fourier_symbol's add_to "
                            "failed: RuntimeError: boom (at "),
    (Symbol(breaks=lambda system: system.add(0, "z", "m", 1.0)),
     "physics stranger: its Fourier symbol adds to the row 'z', no unknown of this model (its unknowns: m, e, f, b, "
     "q; the module's own go in its unknowns)"),
    (Symbol(breaks=lambda system: system.add(0, "q", "h", 1.0)),
     "physics stranger: its Fourier symbol adds to the column 'h', no unknown"),
    (Symbol(breaks=lambda system: system.add(3, "q", "q", 1.0)),
     "physics stranger: its Fourier symbol adds a term of order 3 (the power of phi: 0, 1 or 2)"),
    (Symbol(breaks=lambda system: system.add(0, "q", "q", math.nan * system.K)),
     "physics stranger: its Fourier symbol adds a value that is not finite at (q, q), order 0"),
    (Symbol(breaks=lambda system: system.add(0, "m", "m", 0.0)),
     "physics stranger: its Fourier symbol declares the unknown 'q' but adds no term to its row "
     "(system.add(order, 'q', column, value))"),
], ids=["raises", "no-such-row", "no-such-column", "order-3", "nan", "no-row-for-its-unknown"])
def test_a_broken_add_to_is_one_line_naming_the_module(symbol, message):
    with pytest.raises(PrimordiaError) as error:
        _linearised(symbol)
    assert str(error.value).startswith(message) and "\n" not in str(error.value), str(error.value)


def test_a_well_formed_symbol_adds_its_root():
    """dq/dt = -2 q + m, read by nothing: one more root, -2, at every k."""
    rates = _linearised(Symbol()).rates(np.array([0.0, 1.0, 2.5]))
    for at_k in rates:
        assert sum(np.isfinite(root) and abs(root + 2.0) < 1e-10 for root in at_k) == 1
