"""The contract of a reaction-kinetics plugin.

A kinetics object gives, for every species of the chemotaxis model, its
reaction rate split as ``R_s = production_s - loss_s * c_s`` with
``production_s >= 0`` and ``loss_s >= 0`` wherever the concentrations are
non-negative.  The split is what the IMEX scheme needs: production is taken
explicitly and loss implicitly (a Patankar-type linearisation), so a
non-negative state stays non-negative for any time step.

Kinetics are written once against an ``ops`` namespace providing ``exp``,
``tanh`` and ``x`` (spatial coordinates as a tuple): the same code then builds
UFL expressions for the weak forms (``ops = primordia.core.ops.UFL``) or numpy
values for initial data and the stability analysis (``ops = primordia.core.ops.NUMPY``).

Kinetics register through the ``primordia_kinetics`` hook, built-in and
third-party alike; see ``primordia/core/hookspecs.py``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any, ClassVar

from primordia.core.config import merge_options
from primordia.core.parameters import Parameter


class Kinetics(ABC):
    """Reaction terms of the species ``m, e, f, b`` (or a plugin's own list)."""

    #: Name under which the kinetics is selected in a config (``[kinetics] name``).
    name: ClassVar[str]
    #: Species the kinetics reacts; must match the transport model's species.
    species: ClassVar[tuple[str, ...]] = ("m", "e", "f", "b")
    #: Parameters the kinetics reads, with seed defaults.
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    #: Non-numeric options accepted in the ``[kinetics]`` table, with defaults.
    options: ClassVar[Mapping[str, Any]] = {}

    def __init__(self, params: Mapping[str, float], **options):
        self.params = params
        self.opts = merge_options(f"kinetics {self.name}", self.options, options)

    @abstractmethod
    def split_rates(self, c: Mapping[str, Any], t, ops) -> dict[str, tuple[Any, Any]]:
        """``{species: (production, loss_rate)}`` at concentrations ``c``, time ``t``.

        The reaction is ``R_s = production - loss_rate * c[s]``; a species with
        no reaction returns ``(0, 0)``.
        """

    def rates(self, c: Mapping[str, Any], t, ops) -> dict[str, Any]:
        """The full reaction rates ``R_s`` (used by the Galerkin residual and analysis)."""
        return {s: prod - loss * c[s] for s, (prod, loss) in self.split_rates(c, t, ops).items()}

    @abstractmethod
    def initial_state(self, m0: float, t0, ops) -> dict[str, Any]:
        """The species other than ``m`` at rest with ``m = m0`` (seed eq. (2.5))."""
