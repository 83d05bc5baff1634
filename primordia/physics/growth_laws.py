r"""Growth laws of the finite-strain growth model (seed section 4): plugins that give F_g.

A growth law gives the growth factors gamma_i(m, t, X), one per direction k_i of
a local orthonormal frame of the reference configuration, and the growth
deformation gradient is built from them as printed after seed eq. (4.12):

    F_g = I + sqrt(gamma_1) k_1 (x) k_1 + sqrt(gamma_2) k_2 (x) k_2 [+ gamma_3 k_3 (x) k_3]

(in 2D only gamma_1, gamma_2 on k_1, k_2).  As printed, the in-plane factors enter
through their square roots and gamma_3 does not (one of the seed's printed
inconsistencies, kept: a law that wants otherwise overrides :meth:`GrowthLaw.stretches`).

Built-ins (registered through ``primordia_growth_laws``, chosen by ``[growth_law] name``):

* ``seed3d``, seed eq. (4.13): gamma_1 = gamma_2 = delta_1 t, gamma_3 = delta_2 t + delta_3 m/(1 + m^2);
* ``seed2d``, seed eq. (4.14): gamma_1 = gamma_2 = delta_2 t + delta_3 m/(1 + m^2).

The fluid source of (4.12b) is derived from the law, not typed in per law:

    ell = ell_0 sum_i d gamma_i / dt,   d gamma_i/dt = d gamma_i/d t + sum_f d gamma_i/d f  df/dt

by UFL differentiation through the time and the fields the law reads
(:func:`fluid_source`).  For ``seed3d`` this is (4.15) with its printed factor
delta_3 dropped once: ell_0 (2 delta_1 + delta_2 + d_m(gamma_3) d_t m), since
d_m(gamma_3) = delta_3 (1 - m^2)/(1 + m^2)^2 already carries delta_3.  For
``seed2d`` it gives ell = 2 ell_0 (delta_2 + delta_3 (1 - m^2)/(1 + m^2)^2 d_t m):
both in-plane factors grow, so the 2D source is twice the rate of one factor.

Square roots of non-positive factors
------------------------------------
sqrt(gamma) has no real value for gamma < 0 (a law driven by a density that
an oscillating scheme took below zero) and an infinite derivative at 0 (the
3D law at t = 0).  Every root is taken of the smooth positive part,

    sqrt+(gamma) = sqrt( (gamma + sqrt(gamma^2 + eps^2)) / 2 ),   eps = 1e-12,

which equals sqrt(gamma) to round-off for gamma >> eps, is sqrt(eps/2) = 7.1e-7 at
gamma = 0 (the 3D law's F_g(0) is I + 7.1e-7 (k_1 (x) k_1 + k_2 (x) k_2)), falls to 0
(no growth) for gamma < 0, is never NaN, and has finite derivatives everywhere, so Newton
tangents (also with respect to m, in a monolithic solve) stay finite.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np
import ufl

from primordia.core.config import Configured, merge_options
from primordia.core.errors import ConfigError, PluginError, plugin_code
from primordia.core.parameters import Parameter

#: Regularisation of the square roots of growth factors (see the module docstring).
SQRT_EPSILON = 1e-12


def positive_sqrt(gamma, ops=ufl):
    """sqrt+(gamma) = sqrt((gamma + sqrt(gamma^2 + eps^2)) / 2): sqrt(gamma) for gamma > 0, -> 0 below, never NaN."""
    return ops.sqrt(0.5 * (gamma + ops.sqrt(gamma * gamma + SQRT_EPSILON**2)))


class GrowthLaw(Configured, ABC):
    """Growth factors gamma_i(fields, t, X) on orthonormal directions k_i (seed section 4)."""

    #: Name under which the law is selected in a config (``[growth_law] name``).
    name: ClassVar[str]
    #: Parameters the law reads, with defaults and where they come from.
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    #: Fields the law reads (e.g. ``("m",)``), provided by other physics modules.
    requires: ClassVar[tuple[str, ...]] = ()
    #: Spatial dimensions the law is written for.
    dimensions: ClassVar[tuple[int, ...]] = (2, 3)
    #: Options of the ``[growth_law]`` table, with defaults; the values of a run are ``self.settings``
    #: (the table's values over these defaults).
    options: ClassVar[Mapping[str, Any]] = {"directions": None}

    def __init__(self, params: Mapping[str, float], **given):
        self.params = params
        self.settings: dict[str, Any] = merge_options(f"growth law {self.name}", self.options, given)
        directions = self.settings["directions"]
        dimension = _dimension_meant(directions, self.dimensions)
        if directions is not None and dimension is not None:  # validate now, one line; else frame(the mesh's)
            self.frame(dimension)

    @abstractmethod
    def factors(self, fields: Mapping[str, Any], t, X, dimension: int) -> list:
        """gamma_1, ..., gamma_d (UFL expressions or numbers, dimensionless) at ``fields``, time ``t``, point ``X``."""

    def check_dimension(self, dimension: int) -> None:
        refuse_another_dimension(type(self), dimension)

    def frame(self, dimension: int) -> np.ndarray:
        """The directions k_1, ..., k_d as rows (default: the coordinate axes), checked orthonormal."""
        given = self.settings["directions"]
        if given is None:
            return np.eye(dimension)
        try:
            frame = np.array(given, dtype=float)
        except (TypeError, ValueError):
            frame = None
        if frame is None or frame.shape != (dimension, dimension) or not np.all(np.isfinite(frame)):
            raise ConfigError(f"growth_law.directions must be {dimension} vectors of {dimension} numbers "
                              f"(one per direction k_i, in {dimension}D), got {given!r}")
        if not np.allclose(frame @ frame.T, np.eye(dimension), atol=1e-10):
            raise ConfigError(f"growth_law.directions must be orthonormal, got {given!r}")
        return frame

    def stretches(self, gammas: Sequence) -> list:
        """The coefficients of k_i (x) k_i in F_g - I, as printed after (4.12): roots in-plane, gamma_3 as is."""
        return [positive_sqrt(g) if i < 2 else g for i, g in enumerate(gammas)]  # after (4.12c), as printed

    def directions_at(self, X, dimension: int) -> list:
        """k_1, ..., k_d at the reference point ``X`` as UFL vectors: the constant :meth:`frame` here.

        A law whose frame varies in space (a fibre field k_1(X)) overrides this; its k_i must
        stay orthonormal at every X.
        """
        return [ufl.as_vector([float(c) for c in k]) for k in self.frame(dimension)]

    def growth_tensor(self, fields: Mapping[str, Any], t, X, dimension: int):
        """F_g = I + sum_i s_i k_i (x) k_i (the unnumbered equation after seed (4.12)), a UFL tensor."""
        tensor = ufl.Identity(dimension)
        stretches = _checked_terms(self, "stretches", (), dimension, checked_factors(self, fields, t, X, dimension))
        for stretch, k in zip(stretches, _checked_terms(self, "directions_at", (dimension,), dimension, X, dimension)):
            tensor = tensor + stretch * ufl.outer(k, k)  # F_g, after (4.12c)
        return tensor


def refuse_another_dimension(law: type[GrowthLaw], dimension: int) -> None:
    """One line when the class ``law`` is not written for meshes of ``dimension`` (its ``dimensions``)."""
    if dimension not in law.dimensions:
        raise ConfigError(f"growth law {law.name} is written for {' or '.join(map(str, law.dimensions))}D, "
                          f"the mesh is {dimension}D")


def _dimension_meant(directions, dimensions: Sequence[int]) -> int | None:
    """The dimension a ``directions`` list is for: the law's, if it is written for one only, else d when the
    list holds d vectors of d numbers.  None otherwise: the mesh's dimension decides, when the model is
    composed or set up (a 2D run was told "3 vectors of 3 numbers (in 3D)" for directions = [])."""
    if len(dimensions) == 1:
        return dimensions[0]
    if isinstance(directions, (list, tuple)) and len(directions) in (2, 3) and all(
            isinstance(k, (list, tuple)) and len(k) == len(directions) for k in directions):
        return len(directions)
    return None


def _checked_terms(law: GrowthLaw, method: str, shape: tuple[int, ...], dimension: int, *args) -> list:
    """``law.<method>(*args)`` (``stretches``, ``directions_at``: a law may override both), checked: ``dimension``
    UFL expressions or numbers of ``shape``.  A law's bug there, or an answer of another shape, is one line naming
    it (:class:`PluginError`), as in :func:`checked_factors`: zip() silently dropped a missing direction."""
    where = f"growth law {law.name}"
    with plugin_code(f"{where}: {method} failed", passes=(PluginError,), source=type(law)):
        terms = getattr(law, method)(*args)
    what = "scalars" if not shape else f"vectors of {shape[0]} components"
    if not isinstance(terms, (list, tuple)) or len(terms) != dimension:
        raise PluginError(f"{where}: {method} must return {dimension} {what} in {dimension}D (one per direction "
                          f"k_i), got {terms!r}")
    for i, term in enumerate(terms, start=1):
        try:
            expression = ufl.as_ufl(term) if not shape else ufl.as_vector(term)
        except Exception:  # noqa: BLE001 - anything UFL cannot take is refused below
            expression = None
        if expression is None or expression.ufl_shape != shape:
            raise PluginError(f"{where}: {method} must return {what}, got {term!r} for k_{i}")
    return list(terms)


def checked_factors(law: GrowthLaw, fields: Mapping[str, Any], t, X, dimension: int) -> list:
    """``law.factors(...)``, checked: one scalar (a number or a UFL expression) per direction, ``dimension`` of
    them.  A law that breaks this, or whose code fails, is one line naming it (:class:`PluginError`)."""
    where = f"growth law {law.name}"
    with plugin_code(f"{where}: factors failed", passes=(PluginError,), source=type(law)):  # ConfigError: name it
        try:
            gammas = law.factors(fields, t, X, dimension)
        except KeyError as error:
            raise PluginError(f"{where}: factors read the field {error}, which is not in its requires "
                              f"({', '.join(law.requires) or 'none'})") from error
    if not isinstance(gammas, (list, tuple)) or len(gammas) != dimension:
        raise PluginError(f"{where}: factors must return {dimension} growth factors in {dimension}D "
                          f"(one per direction k_i), got "
                          f"{len(gammas) if isinstance(gammas, (list, tuple)) else repr(gammas)}")
    checked = []
    for i, gamma in enumerate(gammas, start=1):
        try:
            expression = ufl.as_ufl(gamma)
        except Exception:  # noqa: BLE001 - anything UFL cannot take is not a factor
            expression = None
        if expression is None or expression.ufl_shape != ():
            raise PluginError(f"{where}: factors must return scalars (numbers or UFL expressions), "
                              f"gamma_{i} is {gamma!r}")
        checked.append(gamma)
    return checked


def saturating(m):
    """m / (1 + m^2): the cell-driven growth of (4.13), (4.14) (the saturation of the active stress (2.5))."""
    return m / (1.0 + m * m)


class Seed3D(GrowthLaw):
    """Seed eq. (4.13): transversely isotropic growth at a constant rate in-plane, driven by m along k_3."""

    name = "seed3d"
    dimensions = (3,)
    requires = ("m",)
    parameters = (
        Parameter("delta_1", 1.0 / 52.0, "in-plane growth rate (seed eq. (4.13))", constraint="nonnegative",
                  source="seed section 5.5"),  # gamma_1 = delta_1 t is a stretch's square: < 0 has no root
        Parameter("delta_2", 0.0, "growth rate along k_3 (seed eq. (4.13))", constraint="nonnegative",
                  source="seed section 5.5"),
        Parameter("delta_3", 1.0 / 104.0, "cell-driven growth along k_3 (seed eq. (4.13))",
                  constraint="nonnegative", source="seed section 5.5"),
    )

    def factors(self, fields, t, X, dimension):
        p = self.params
        in_plane = p["delta_1"] * t
        return [in_plane, in_plane, p["delta_2"] * t + p["delta_3"] * saturating(fields["m"])]  # (4.13)


class Seed2D(GrowthLaw):
    """Seed eq. (4.14): isotropic in-plane growth at a constant rate plus a cell-driven part."""

    name = "seed2d"
    dimensions = (2,)
    requires = ("m",)
    parameters = (
        Parameter("delta_2", 0.15, "growth rate (seed eq. (4.14))", constraint="nonnegative",
                  source="seed section 5.4"),
        Parameter("delta_3", 0.045, "cell-driven growth (seed eq. (4.14))", constraint="nonnegative",
                  source="seed section 5.4"),
    )

    def factors(self, fields, t, X, dimension):
        p = self.params
        gamma = p["delta_2"] * t + p["delta_3"] * saturating(fields["m"])
        return [gamma, gamma]  # (4.14)


def fluid_source(law: GrowthLaw, ell_0: float, fields: Mapping[str, Any], rates: Mapping[str, Any], t, X,
                 dimension: int):
    """ell = ell_0 sum_i d gamma_i/dt (seed eq. (4.15), general form), differentiated through t and the fields.

    ``rates`` holds d f/dt for every field f the law reads (e.g. (m - m^n)/dt).
    """
    time = ufl.variable(t)
    variables = {name: ufl.variable(value) for name, value in fields.items()}
    total = 0
    for gamma in checked_factors(law, variables, time, X, dimension):
        gamma = ufl.as_ufl(gamma)
        total = total + ufl.diff(gamma, time)
        for name, variable in variables.items():
            total = total + ufl.diff(gamma, variable) * rates[name]
    return ell_0 * total  # (4.15), general form
