"""Boundary conditions of the poromechanics, each an object that contributes its own terms.

Given per named boundary in a config::

    [[physics.poroelasticity.boundary]]
    boundary = "top"
    type = "traction"
    value = ["0", "s0 * sin(pi * t / t_hat)"]
    constants = { s0 = 1500.0, t_hat = 320.0 }

Kinds (seed eqs. (2.7b)-(2.7c), (4.16a)-(4.16b) and beyond).  The same kinds
serve the small-strain model (on the domain) and the finite-strain growth model
(on the reference configuration Omega_0, normal N_0, first Piola-Kirchhoff
stress P = P_e + P_f):

* ``clamped``              u = 0                                (Dirichlet, seed (2.7b))
* ``displacement``         u = value(x, t)                      (Dirichlet, vector formula)
* ``normal_displacement``  u . n = value(x, t), tangential traction free
                           (axis-aligned boundaries: fixes the normal component;
                           u . N_0 = 0 on Gamma_0 of seed section 5.4)
* ``traction``             sigma n = value(x, t)                (Neumann, seed (2.7c));
                           P N_0 = value (nominal traction) at finite strain
* ``robin``                springs: P N_0 + xi_R J F^-T u = 0 (seed (4.16a)), value = xi_R;
                           sigma n + xi_R u = 0 at small strain
* ``fluid_flux``           (kappa/eta) grad p . n = value(x, t), positive: inflow (Neumann; 0 = no flux, seed (2.7b),
                           (4.16b) on Gamma_0 with J C^-1 Grad p . N_0)
* ``fluid_pressure``       p = value(x, t)                      (Dirichlet, seed (2.7c); p_D of (4.16b))

A condition either adds weak-form terms (:meth:`terms`) or Dirichlet constraints
(:meth:`dirichlet`) and updates its time-dependent values (:meth:`update`); the
physics module sums whatever its conditions contribute, without asking what
kind they are.  Kinds are plugins: each class carries its ``kind`` and is
contributed through the ``primordia_boundary_conditions`` hook (the built-ins
below are, by :func:`primordia_boundary_conditions`), so a new kind needs no edit here.
Terms that depend on the deformation read it from the run's kinematics
(``disc.kinematics``, :mod:`primordia.physics.kinematics`).
"""

from __future__ import annotations

import ast
from typing import ClassVar

import numpy as np
import ufl

from primordia.core.errors import ConfigError, PluginError, third_party_code
from primordia.core.expressions import Formula, VectorFormula
from primordia.core.plugins import hookimpl

ALLOWED_KEYS = {"boundary", "type", "value", "constants"}


class Condition:
    """One condition on one named boundary (subclass it for a new kind, with a unique ``kind``)."""

    #: Name used in ``type = "..."`` of a ``[[physics.NAME.boundary]]`` table.
    kind: ClassVar[str]
    #: The field whose balance law the condition belongs to.
    field: ClassVar[str]
    #: The registry name of the kind (its ``kind``).
    name: ClassVar[str]
    vector_value: ClassVar[bool] = False
    #: Whether the condition prescribes the normal displacement (the boundary cannot move outwards freely).
    holds_normal_displacement: ClassVar[bool] = False
    default_value = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "kind" in cls.__dict__:
            cls.name = cls.kind

    def __init__(self, boundary: str, value=None, constants=None, gdim: int = 2):
        self.boundary = boundary
        where = f"boundary condition '{self.kind}' on '{boundary}'"
        if value is None:
            value = self.default_value(gdim) if callable(self.default_value) else self.default_value
            if value is None:
                raise ConfigError(f"{where} needs a value")
        if self.vector_value:
            self.formula = VectorFormula(value, constants, where)
            if len(self.formula) != gdim:
                raise ConfigError(f"{where}: value needs {gdim} components, got {len(self.formula)}")
        else:
            self.formula = Formula(value, constants, where)
        self._bcs = []

    def check(self, points: np.ndarray, times) -> None:
        """Refuse, in one line, a value that cannot be evaluated (or is out of range) at ``points`` at ``times``."""
        self.formula.check(points, times)

    def terms(self, disc) -> dict[str, list]:
        """Weak-form terms added to residuals: {field name: [form, ...]}."""
        return {}

    def dirichlet(self, disc) -> list:
        """Dirichlet constraints (backend objects) on the field's group."""
        return []

    def homogeneous(self, disc) -> list:
        """The same constraints with zero values (for increments and rates), new objects each call."""
        return []

    def update(self, disc, t: float) -> None:
        """Refresh time-dependent prescribed values (Dirichlet kinds)."""

    def rates(self, disc, t: float, dt: float) -> list:
        """Constraints on the field's rate over [t, t + dt]: the prescribed value's secant, new objects each call."""
        return self.homogeneous(disc)

    def restraint(self, motions: np.ndarray, points: np.ndarray, times) -> np.ndarray:
        """How the condition holds the rigid-body motions of the displacement: one row per constraint it puts on
        ``motions`` (modes x boundary vertices x components, the motions at the boundary's ``points``), a rigid
        motion the rows map to zero being one the condition lets through.  None by default (a traction)."""
        return np.zeros((0, motions.shape[0]))


class _Dirichlet(Condition):
    """Prescribes (part of) a field; value formulas are evaluated at the DOF points."""

    def _values(self, t: float):
        return lambda x: self.formula.numpy(x, t)

    def _component(self, disc) -> int | None:
        """The component of the field the condition fixes (None: all of it)."""
        return None

    def dirichlet(self, disc):
        # One constraint per discretisation, shared by every subproblem that asks for it (the growth
        # module's initial equilibrium and its time step; the solvers made again after a failed step), so that
        # :meth:`update` moves the values every solve reads.  Making a new one on each call left the
        # earlier ones, those of the time step's solver, at their first values.
        if getattr(self, "_bcs_of", None) is not disc:
            self._bcs = [disc.dirichlet_bc(self.field, self.boundary, self._values(disc.time), self._component(disc))]
            self._bcs_of = disc
        return list(self._bcs)

    def homogeneous(self, disc):
        return [disc.dirichlet_bc(self.field, self.boundary, 0.0, self._component(disc))]

    def update(self, disc, t):
        if self.formula.depends_on_time():
            for bc in self._bcs:
                disc.update_dirichlet_bc(bc, self._values(t))

    def restraint(self, motions, points, times):
        """The prescribed components of u at every vertex of the boundary (none for another field)."""
        if self.field != "u":
            return super().restraint(motions, points, times)
        axis = self._axis(points)
        held = motions if axis is None else motions[:, :, axis:axis + 1]
        return held.reshape(motions.shape[0], -1).T

    def _axis(self, points: np.ndarray) -> int | None:
        """The component of u the condition fixes on the boundary through ``points`` (None: all of them)."""
        return None

    def rates(self, disc, t, dt):
        if not self.formula.depends_on_time():
            return self.homogeneous(disc)
        secant = lambda x: (self.formula.numpy(x, t + dt) - self.formula.numpy(x, t)) / dt  # noqa: E731
        return [disc.dirichlet_bc(self.field, self.boundary, secant, self._component(disc))]


class Clamped(_Dirichlet):
    kind, field, vector_value, holds_normal_displacement = "clamped", "u", True, True

    @staticmethod
    def default_value(gdim):
        return ["0"] * gdim

    def __init__(self, boundary, value=None, constants=None, gdim=2):
        refused = ConfigError(f"boundary condition 'clamped' on '{boundary}' is u = 0 and takes no value, "
                              f"got {value!r} (type = \"displacement\" prescribes u)")
        if value is not None and not isinstance(value, (list, tuple)):  # not "a list of formulas" for a lone value
            raise refused
        super().__init__(boundary, value, constants, gdim)
        if value is not None and not all(_is_zero(component) for component in self.formula.components):
            raise refused


class Displacement(_Dirichlet):
    kind, field, vector_value, holds_normal_displacement = "displacement", "u", True, True


class NormalDisplacement(_Dirichlet):
    """u . n prescribed on a boundary whose normal is a coordinate axis."""

    kind, field, default_value, holds_normal_displacement = "normal_displacement", "u", "0", True

    def _component(self, disc):
        return _normal_axis(disc.mesh_data, self.boundary)

    def _axis(self, points):
        return _flat_axis(np.asarray(points, dtype=float), self.boundary)

    def check(self, points, times):
        """Also refuse a boundary that is not flat and normal to an axis (``primordia run --dry-run`` included)."""
        super().check(points, times)
        _flat_axis(np.asarray(points, dtype=float), self.boundary)


class Traction(Condition):
    kind, field, vector_value = "traction", "u", True

    def terms(self, disc):
        traction = self.formula.ufl(disc.x, disc.t)
        return {"u": [-ufl.inner(traction, disc.test("u")) * disc.ds(self.boundary)]}  # (2.7c)


class Robin(Condition):
    """Springs on the boundary: seed (4.16a), (P_e + P_f) N_0 + xi_R J F^-T u = 0; value = xi_R.

    Weak form: + xi_R J F^-T u . w on the boundary.  At small strain (no deformation
    gradient in the kinematics) J F^-T = I: sigma n + xi_R u = 0.
    """

    kind, field = "robin", "u"

    def terms(self, disc):
        stiffness = self.formula.ufl(disc.x, disc.t)
        u, w, motion = disc.field("u"), disc.test("u"), disc.kinematics
        spring = u
        if motion.deformation_gradient is not None:
            spring = motion.volume_ratio * ufl.dot(ufl.inv(motion.deformation_gradient).T, u)
        measure = disc.ds_degree(motion.quadrature_degree, self.boundary)
        return {"u": [stiffness * ufl.inner(spring, w) * measure]}  # (4.16a)

    def restraint(self, motions, points, times):
        """Every component of u at the vertices where the springs are stiff (xi_R > 0) at all ``times``."""
        stiff = np.all([self.formula.numpy(np.asarray(points, dtype=float).T, float(t)) > 0 for t in times], axis=0)
        stiff = np.broadcast_to(stiff, (len(points),))
        return motions[:, stiff, :].reshape(motions.shape[0], -1).T

    def check(self, points, times):
        """The springs' stiffness xi_R must be >= 0 (a negative one pushes the boundary away, unbounded)."""
        super().check(points, times)
        for t in times:
            stiffness = self.formula.numpy(np.asarray(points, dtype=float).T, float(t))
            if np.any(stiffness < 0):
                where = np.asarray(points)[np.flatnonzero(stiffness < 0)[0]]
                raise ConfigError(f"boundary condition 'robin' on '{self.boundary}': the stiffness "
                                  f"{self.formula.text!r} must be >= 0, got {float(stiffness.min()):g} at "
                                  f"x = ({', '.join(f'{c:g}' for c in where)}), t = {float(t):g}")


class FluidFlux(Condition):
    kind, field, default_value = "fluid_flux", "p", "0"

    def terms(self, disc):
        flux = self.formula.ufl(disc.x, disc.t)
        return {"p": [-flux * disc.test("p") * disc.ds(self.boundary)]}  # (2.7b), (4.16b) with flux 0


class FluidPressure(_Dirichlet):
    kind, field = "fluid_pressure", "p"


#: The built-in kinds, contributed through the ``primordia_boundary_conditions`` hook.
BUILT_IN = (Clamped, Displacement, NormalDisplacement, Traction, Robin, FluidFlux, FluidPressure)


@hookimpl
def primordia_boundary_conditions():
    return list(BUILT_IN)


def condition_kinds() -> dict[str, type]:
    """Every registered kind (built-in and plugins) by name."""
    from primordia.core.plugins import registry

    return {name: cls for name, (cls, _) in registry("boundary_conditions").items()}


def _refuse_a_skipped_kind(kind: str) -> None:
    """A kind a plugin gives but that was skipped (two plugins give it, or its contribution was junk): why, in one
    line, as a kinetics or a growth law so skipped says (:func:`primordia.core.plugins.lookup`), not "unknown"."""
    from primordia.core.plugins import why_skipped

    why = why_skipped("boundary_conditions", kind)
    if why is not None:
        raise PluginError(f"boundary condition type {kind!r} was skipped: {why}")


def condition_code(kind: type, boundary: str, method: str):
    """Run ``method`` of a boundary-condition kind: a third party's bug in it is one line naming the kind, its
    class, the boundary and where in the plugin's files it happened, not a traceback.  The built-in modules
    that hold the conditions (poroelasticity, growth) are primordia's, so their own wrapping leaves a third
    party's kind alone; primordia's own kinds keep their tracebacks."""
    return third_party_code(f"{_named(kind, boundary)}: {method} failed", kind)


def _named(kind: type, boundary: str) -> str:
    """A condition in a plugin's error line: its type, its boundary and its class."""
    return f"boundary condition '{kind.kind}' on '{boundary}' ({kind.__module__}.{kind.__qualname__})"


class Conditions(list):
    """The conditions of one physics module: what they contribute together, each contributing its own."""

    def terms(self, disc, field: str | None = None):
        """The sum of every condition's weak-form terms (0 when none adds any); only those of ``field``'s balance
        law when it is given."""
        return sum((term for condition in self for name, terms in self._terms_of(condition, disc).items()
                    if field in (None, name) for term in terms), 0)

    @staticmethod
    def _terms_of(condition: Condition, disc) -> dict:
        """``condition.terms(disc)``, refused in one line unless it is ``{field name: [form, ...]}``."""
        with condition_code(type(condition), condition.boundary, "terms"):
            terms = condition.terms(disc)
        if not isinstance(terms, dict) or not all(isinstance(name, str) and isinstance(forms, (list, tuple))
                                                   for name, forms in terms.items()):
            raise PluginError(f"{_named(type(condition), condition.boundary)}: terms must return "
                              f"{{field name: [form, ...]}}, got {terms!r}")
        return terms

    def dirichlet(self, disc) -> list:
        """Every condition's Dirichlet constraints."""
        return self._each("dirichlet", disc)

    def homogeneous(self, disc) -> list:
        """The same constraints with zero values (for increments and rates)."""
        return self._each("homogeneous", disc)

    def update(self, disc, t: float) -> None:
        """Refresh every time-dependent prescribed value for time ``t``."""
        for condition in self:
            with condition_code(type(condition), condition.boundary, "update"):
                condition.update(disc, t)

    def rates(self, disc, t: float, dt: float) -> list:
        """Every condition's constraints on the rate over [t, t + dt] (the secant of a time-dependent value)."""
        return self._each("rates", disc, t, dt)

    def _each(self, method: str, *args) -> list:
        """Every condition's constraints of ``method``, each called as third-party code."""
        constraints = []
        for condition in self:
            with condition_code(type(condition), condition.boundary, method):
                constraints.extend(getattr(condition, method)(*args))
        return constraints


def conditions_from_config(tables, mesh_data, gdim: int) -> Conditions:
    """Build the conditions of a ``boundary`` list of tables, validating each."""
    if tables is None:
        return Conditions()
    if not isinstance(tables, list):
        raise ConfigError("boundary conditions must be a list of tables ([[physics.NAME.boundary]])")
    conditions = Conditions()
    for table in tables:
        if not isinstance(table, dict):
            raise ConfigError("each boundary condition must be a table with boundary and type")
        unknown = set(table) - ALLOWED_KEYS
        if unknown:
            raise ConfigError(f"unknown key '{sorted(unknown)[0]}' in a boundary condition "
                              f"(known: {', '.join(sorted(ALLOWED_KEYS))})")
        kind = table.get("type")
        kinds = condition_kinds()
        if kind not in kinds:
            _refuse_a_skipped_kind(kind)
            raise ConfigError(f"unknown boundary condition type {kind!r} (known: {', '.join(kinds)})")
        boundary = table.get("boundary")
        if boundary not in mesh_data.boundaries:
            raise ConfigError(f"boundary condition '{kind}' names boundary {boundary!r}, which the mesh lacks "
                              f"(it has: {', '.join(mesh_data.boundaries) or 'none'})")
        if not len(mesh_data.boundaries[boundary]):  # a MeshData built by hand; files and generators name no empty one
            raise ConfigError(f"boundary condition '{kind}' names boundary {boundary!r}, which has no facets "
                              f"(the condition would act on nothing)")
        with condition_code(kinds[kind], boundary, "__init__"):
            condition = kinds[kind](boundary, table.get("value"), table.get("constants"), gdim)
        if _is_dirichlet(condition):
            other = next((c for c in conditions if _is_dirichlet(c) and c.boundary == boundary
                          and c.field == condition.field), None)
            if other is not None:
                raise ConfigError(f"boundary {boundary!r} is given two Dirichlet conditions on {condition.field} "
                                  f"('{other.kind}' and '{condition.kind}'): give one")
        conditions.append(condition)
    return conditions


def _is_dirichlet(condition: Condition) -> bool:
    """Whether a condition prescribes (part of) its field (it makes Dirichlet constraints)."""
    return type(condition).dirichlet is not Condition.dirichlet


def _is_zero(formula: Formula) -> bool:
    """Whether a formula is the constant 0 (reads neither x nor t, and is 0)."""
    if any(isinstance(node, ast.Name) and node.id in ("x", "t") for node in ast.walk(formula.tree)):
        return False
    return bool(np.all(formula.numpy(np.zeros((1, 1)), 0.0) == 0.0))


def encloses(conditions: list[Condition], mesh_data) -> bool:
    """Whether conditions holding the normal displacement cover every exterior facet of the mesh."""
    from primordia.core.meshes import exterior_facets

    held = {c.boundary for c in conditions if c.holds_normal_displacement}
    if not held:
        return False
    facets = {tuple(sorted(f)) for name in held for f in mesh_data.boundaries[name]}
    return len(facets) >= len(exterior_facets(mesh_data.cells))


def free_rigid_motions(conditions: list[Condition], mesh_data, times) -> int:
    """How many independent rigid-body motions of the mesh (d translations, d(d-1)/2 rotations) no condition holds.

    Each condition contributes its own rows (:meth:`Condition.restraint`); without inertia the momentum balance
    determines u only up to the motions left free.
    """
    from primordia.physics.kinematics import rigid_motions

    points = np.asarray(mesh_data.points, dtype=float)
    # about the centre, on a unit scale: the rank of the rows below does not depend on where the mesh lies
    motions = rigid_motions((points - points.mean(axis=0)) / max(float(np.ptp(points, axis=0).max()), 1e-300))
    rows = [np.zeros((0, len(motions)))]
    for condition in conditions:
        vertices = np.unique(mesh_data.boundaries[condition.boundary])
        with condition_code(type(condition), condition.boundary, "restraint"):
            rows.append(condition.restraint(motions[:, vertices, :], points[vertices], times))
    held = np.vstack(rows)
    return len(motions) - (np.linalg.matrix_rank(held) if len(held) else 0)


def refuse_free_rigid_motions(where: str, boundary: list, mesh_data, times, static: list[str], balance: str,
                              remedy: str = "") -> None:
    """One line when the conditions of table ``boundary`` leave a rigid-body motion of u free while the balance
    is static for the reasons ``static`` (``"rho = 0"``, ...): the momentum balance ``balance`` (a seed
    equation) then fixes u only up to that motion, a singular matrix.  ``remedy`` adds a way out other than
    holding u on a boundary."""
    if not static:
        return
    free = free_rigid_motions(conditions_from_config(boundary, mesh_data, mesh_data.gdim), mesh_data, times)
    if free:
        raise ConfigError(f"{where}: the boundary conditions leave {free} rigid-body motion(s) of u free and "
                          f"{' and '.join(static)}, so the {balance} has no unique solution; hold u on a boundary "
                          f"(clamped, displacement, robin springs, or normal_displacement on enough boundaries)"
                          f"{remedy}")


def _normal_axis(mesh_data, boundary: str) -> int:
    """The coordinate axis normal to a flat, axis-aligned boundary (else a one-line error)."""
    return _flat_axis(mesh_data.points[np.unique(mesh_data.boundaries[boundary])], boundary)


def _flat_axis(points: np.ndarray, boundary: str) -> int:
    """The coordinate axis normal to the flat, axis-aligned boundary through ``points`` (else a one-line error)."""
    spread = points.max(axis=0) - points.min(axis=0)
    flat = np.flatnonzero(spread <= 1e-10 * max(1.0, float(np.abs(points).max())))
    if len(flat) != 1:
        raise ConfigError(f"normal_displacement on '{boundary}' needs a flat boundary normal to a coordinate axis")
    return int(flat[0])
