"""The contract of a reaction-kinetics plugin: its species, how they move, how they react.

A kinetics declares its **species** (:class:`Species`): names, which parameter is
each one's diffusivity, which species climbs the gradient of which (with the
sensitivity :meth:`Kinetics.sensitivity`), which the moving solid carries or
consumes, and which starts perturbed.  The transport physics
(:mod:`primordia.physics.chemotaxis`) and the mechano-chemical couplings read
these declarations, so a plugin can bring a fifth species or a different system
altogether; the seed's m, e, f, b are the declaration of ``painter2018``.

For every species the kinetics gives its reaction rate split as
``R_s = production_s - loss_s * c_s`` with ``production_s >= 0`` and
``loss_s >= 0`` wherever the concentrations are non-negative.  The split is what
the IMEX scheme needs: production is taken explicitly and loss implicitly (a
Patankar-type linearisation), so a non-negative state stays non-negative for any
time step.  A species that does not react returns the plain numbers ``(0, 0)``:
it is conserved (the linear stability analysis then holds it at its initial value).

Kinetics are written once against an ``ops`` namespace providing ``exp``,
``tanh``, ``sqrt``, ``ln`` and ``x`` (spatial coordinates as a tuple): the same
code then builds UFL expressions for the weak forms (``ops = primordia.core.ops.UFL``),
numpy values for initial data (``ops = primordia.core.ops.NUMPY``), and first
derivatives for the linear stability analysis (dual numbers,
:mod:`primordia.analysis.autodiff`), so the analysis linearises the very code
the simulation runs.  Use only arithmetic and ``ops`` functions in
:meth:`~Kinetics.split_rates` and :meth:`~Kinetics.sensitivity`.

Kinetics register through the ``primordia_kinetics`` hook, built-in and
third-party alike; see ``primordia/core/hookspecs.py``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from primordia.core.config import Configured, merge_options
from primordia.core.errors import PluginError, PrimordiaError, plugin_code, third_party_code
from primordia.core.parameters import Parameter
from primordia.core.validation import field_name


@dataclass(frozen=True)
class Species:
    """A species of a kinetics, and how the transport physics moves it.

    ``diffusivity``  name of the parameter holding its diffusion coefficient
                     (dimensionless); None: immobile (reacts in place, no transport).
    ``attractant``   the species whose gradient it climbs: the flux is
                     ``D grad c - chi(c) c grad a``, chi from :meth:`Kinetics.sensitivity`
                     (seed eq. (2.3a)); it must be mobile.
    ``advected``     carried by the solid velocity, ``+ u_t . grad c`` (seed (2.3a), (2.3c), (2.3d)).
    ``volume_sink``  consumed by volume change, ``+ xi_f div u`` (seed (2.3c)), when the
                     mechano-chemical couplings are in the model.
    ``perturbed``    its initial state carries the run's perturbation
                     (``physics.chemotaxis.perturbation``: seeded noise or a cosine mode).
    """

    name: str
    description: str
    diffusivity: str | None = None
    attractant: str | None = None
    advected: bool = False
    volume_sink: bool = False
    perturbed: bool = False

    @property
    def mobile(self) -> bool:
        return self.diffusivity is not None


class Kinetics(Configured, ABC):
    """The species of a model and their reactions."""

    #: Name under which the kinetics is selected in a config (``[kinetics] name``).
    name: ClassVar[str]
    #: The species, in solve order (the transport physics solves them one after another).
    species: ClassVar[tuple[Species, ...]] = ()
    #: Parameters the kinetics reads (reactions, diffusivities, sensitivities, initial data), with defaults.
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    #: Non-numeric options accepted in the ``[kinetics]`` table, with defaults; the values of a run
    #: are ``self.settings`` (the table's values over these defaults).
    options: ClassVar[Mapping[str, Any]] = {}

    def __init__(self, params: Mapping[str, float], **given):
        self.params = params
        self.settings: dict[str, Any] = merge_options(f"kinetics {self.name}", self.options, given)
        check_species(self)

    @property
    def species_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.species)

    def species_named(self, name: str) -> Species:
        for species in self.species:
            if species.name == name:
                return species
        raise KeyError(name)

    @abstractmethod
    def split_rates(self, c: Mapping[str, Any], t, ops) -> dict[str, tuple[Any, Any]]:
        """``{species: (production, loss_rate)}`` at concentrations ``c``, time ``t``.

        The reaction is ``R_s = production - loss_rate * c[s]``; a species with
        no reaction returns ``(0, 0)``.
        """

    def rates(self, c: Mapping[str, Any], t, ops) -> dict[str, Any]:
        """The full reaction rates ``R_s`` (used by the Galerkin residual and the analysis)."""
        return {s: prod - loss * c[s] for s, (prod, loss) in self.split_rates(c, t, ops).items()}

    @abstractmethod
    def initial_state(self, t0, ops) -> dict[str, Any]:
        """Every species at ``t0`` before the run's perturbation (at rest: seed eq. (2.6) for painter2018)."""

    def sensitivity(self, species: str, density, ops):
        """chi(c) of a species that climbs an attractant's gradient, at its own density ``c``.

        The chemotactic flux is ``chi(c) c grad a``.  Only species declared with an
        ``attractant`` are asked.
        """
        raise PluginError(f"kinetics {self.name}: species {species} climbs a gradient but the kinetics "
                          f"defines no sensitivity(species, density, ops)")

    def homogeneous(self) -> "Kinetics":
        """The kinetics the linear stability analysis linearises: spatially homogeneous and autonomous.

        The default is the kinetics itself (reactions that read neither ``ops.x`` nor
        ``t``); a kinetics with a space- or time-dependent forcing returns the state it
        settles to (``painter2018``: the priming wave saturated, seed section 3).
        """
        return self


def check_species(kinetics: Kinetics) -> None:
    """The declaration is consistent: unique names, known attractants and diffusivity parameters."""
    where = f"kinetics {kinetics.name}"
    if not isinstance(kinetics.species, (list, tuple)) or not all(isinstance(s, Species) for s in kinetics.species):
        raise PluginError(f"{where}: its species must be a tuple of primordia.physics.kinetics.base.Species, "
                          f"got {kinetics.species!r}")
    for species in kinetics.species:  # a species is a field
        field_name(species.name, where, "a species")
    names = [s.name for s in kinetics.species]
    if not names:
        raise PluginError(f"{where} declares no species")
    if len(set(names)) != len(names):
        raise PluginError(f"{where} declares a species twice: {', '.join(names)}")
    declared = {p.name for p in kinetics.parameters}
    for species in kinetics.species:
        if species.diffusivity is not None and species.diffusivity not in declared:
            raise PluginError(f"{where}: the diffusivity {species.diffusivity} of species {species.name} "
                              f"is not among its parameters")
        if species.attractant is not None:
            if species.attractant not in names or species.attractant == species.name:
                raise PluginError(f"{where}: species {species.name} climbs '{species.attractant}', "
                                  f"which is not another of its species ({', '.join(names)})")
            if not species.mobile:
                raise PluginError(f"{where}: species {species.name} climbs a gradient but has no diffusivity")


def checked_evaluation(kinetics: Kinetics, t0, ops) -> tuple[dict[str, Any], dict[str, tuple[Any, Any]]]:
    """``(initial_state(t0, ops), split_rates(state, t0, ops))``, checked against the contract.

    Each must be a table with a value for every declared species (the rates: a pair production, loss rate,
    and no other species; the sensitivity of each species that climbs a gradient), each value a real number or
    an array of them, one per vertex.  A kinetics that breaks the contract,
    or whose code fails on numbers (``ops = NUMPY``) in another way than arithmetic, is one line naming it
    (:class:`PluginError`);
    arithmetic that fails (an overflow, a math domain error) propagates, for the caller to blame the parameters.
    """
    where = f"kinetics {kinetics.name}"
    names = kinetics.species_names
    state = _call(kinetics, "initial_state", t0, ops)
    if not isinstance(state, Mapping) or set(names) - set(state):
        missing = sorted(set(names) - set(state)) if isinstance(state, Mapping) else names
        raise PluginError(f"{where}: initial_state must return a value for every species, got {state!r} "
                          f"(missing: {', '.join(missing)})")
    extra = [str(name) for name in state if name not in names]
    if extra:  # was dropped without a word
        raise PluginError(f"{where}: initial_state gives {', '.join(extra)}, which is not one of its species "
                          f"({', '.join(names)})")
    state = {name: state[name] for name in names}
    vertices = np.shape(ops.x[0]) if ops.x is not None else ()
    for name in names:
        _check_real(state[name], f"{where}: initial_state must give species {name} a real number", vertices)
    rates = _call(kinetics, "split_rates", state, t0, ops)
    nonnegative = all(float(np.min(state[name])) >= 0 for name in names)  # where the split promises signs
    if not isinstance(rates, Mapping) or set(rates) != set(names):
        got = ", ".join(map(str, rates)) if isinstance(rates, Mapping) else repr(rates)
        raise PluginError(f"{where}: split_rates must return {{species: (production, loss_rate)}} for its species "
                          f"{', '.join(names)}, got {got}")
    for name in names:
        pair = rates[name]
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            raise PluginError(f"{where}: split_rates must give species {name} a pair (production, loss_rate), "
                              f"got {pair!r}")
        for part, value in zip(("production", "loss_rate"), pair):
            _check_real(value, f"{where}: split_rates must give species {name} a real {part}", vertices)
            low = float(np.min(value))
            if low < 0 and nonnegative:  # the split's promise (module docstring): a negative loss rate ran, unsaid
                raise PluginError(f"{where}: split_rates gives species {name} a negative {part} ({low:g}) at the "
                                  f"initial state; production and loss rate must be >= 0 where the "
                                  f"concentrations are (R = production - loss_rate c)")
    for species in kinetics.species:
        if species.attractant is not None:
            chi = _call(kinetics, "sensitivity", species.name, state[species.name], ops)
            _check_real(chi, f"{where}: sensitivity must give species {species.name} a real chi", vertices)
    return state, dict(rates)


def _check_real(value, refusal: str, vertices: tuple[int, ...]) -> None:
    """One line (``refusal``, then the value) unless ``value`` is a real number or an array of them, one per vertex
    (``vertices``: the shape of a coordinate): a string or None would otherwise fail as a traceback deep in the weak
    forms, an array of another length as one where the fields are set."""
    if not isinstance(value, (int, float, np.ndarray, np.number)) or np.asarray(value).dtype.kind not in "biuf":
        raise PluginError(f"{refusal}, got {value!r}")
    if np.ndim(value) and np.shape(value) != vertices:
        raise PluginError(f"{refusal} or one per vertex {vertices}, got an array of shape {np.shape(value)}")


def kinetics_code(kinetics: Kinetics, method: str, passes: tuple[type[BaseException], ...] = (PrimordiaError,)):
    """Run ``method`` of a kinetics where the weak forms are built or assembled (``ops`` UFL, or numbers at the
    edges) or the stability analysis differentiates it (dual numbers): a third party's bug there (``np.exp`` or
    ``if`` on a species, which numbers take and UFL and dual numbers do not) is one line naming the kinetics and
    where in its files it happened, not a traceback; primordia's own keep theirs.  ``passes``: what the caller
    handles itself."""
    return third_party_code(_failed(kinetics, method), type(kinetics), passes)


def _failed(kinetics: Kinetics, method: str) -> str:
    """How a failure of ``method`` of ``kinetics`` begins: its name, its class and the method."""
    cls = type(kinetics)
    return f"kinetics {kinetics.name} ({cls.__module__}.{cls.__qualname__}): {method} failed"


def _call(kinetics: Kinetics, method: str, *args):
    # arithmetic that fails (ValueError: a math domain error) is blamed on the parameters, by the caller; anything
    # else is named as kinetics_code names it: the class and where in its files (a RuntimeError said neither)
    with plugin_code(_failed(kinetics, method), passes=(PluginError, ArithmeticError, ValueError),
                     source=type(kinetics)):
        return getattr(kinetics, method)(*args)
