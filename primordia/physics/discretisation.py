"""The discretised run a physics module sees: mesh, measures, fields, time.

This is the API a physics author writes against.  :class:`Discretisation`
hands physics modules UFL objects made by the run's backend (spaces, fields,
constants, measures, Dirichlet conditions) and keeps, for every field, its
current value and its value at the start of the step (``previous``).  It is
also where couplings meet: a module adds a term to another module's balance
law with :meth:`Discretisation.contribute`, and reads a field another module
owns with :meth:`Discretisation.field` (a missing provider is named).  A term
contributed to a field whose balance law no subproblem reads is an error
(:meth:`Discretisation.check_contributions`), not a term silently lost.

Fields are stored in *groups*: the fields of a group are solved together and
live in one backend function (a mixed function when the group has several
fields, e.g. displacement and pore pressure).  ``field``, ``previous``,
``rate`` and ``test`` return UFL expressions either way, so a physics module
reads the same whether its fields are alone, grouped with each other, or all
in one monolithic group (the splitting scheme decides the grouping).

The coupling layer (:mod:`primordia.coupling`) creates the discretisation and
drives it (groups, time, stored values); a physics module only reads from it
and declares to it, and never needs the backend behind it.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import ufl
from ufl.core.expr import Expr

from primordia.core.backend import Backend, BoundaryCondition, PointFunction
from primordia.core.errors import ConfigError, third_party_code
from primordia.core.mesh_data import MeshData
from primordia.physics.kinematics import MOTIONLESS, Kinematics

if TYPE_CHECKING:
    from primordia.physics.base import FieldSpec

#: A term one module adds to another's balance law: the test function in, a UFL form (or None) out.
Term = Callable[[Expr], "ufl.Form | None"]


@dataclass
class _Group:
    name: str
    fields: list[str]
    space: Any
    current: Any
    previous: Any
    rate: Any | None = None
    span: Any | None = None  # a constant: the length of the sub-step that last advanced the group (span())

    def index(self, field: str) -> int | None:
        return None if len(self.fields) == 1 else self.fields.index(field)


class Discretisation:
    """The mesh, measures, fields and time of one run, on one backend (see the module docstring).

    What physics reads: ``mesh_data``, ``gdim``, ``dx``, ``dx_lumped``, ``ds(boundary)``, ``x``,
    ``n``, ``t`` (time at the end of the step, a UFL constant), ``dt``, ``time`` (a float),
    ``field``, ``previous``, ``rate``, ``span``, ``test``, ``trial``, ``unknown``, ``kinematics``.
    What physics declares: ``provide``, ``provide_kinematics``, ``contribute``.
    """

    def __init__(self, backend: Backend, mesh_data: MeshData):
        self.backend = backend  # for the coupling layer; physics goes through the methods below
        self.mesh_data = mesh_data
        self.mesh = backend.create_mesh(mesh_data)
        self.cell = self.mesh.ufl_domain().ufl_cell()
        self.gdim: int = mesh_data.gdim
        self.dx: ufl.Measure = backend.measure("dx", self.mesh)
        self.dx_lumped: ufl.Measure = backend.lumped_dx(self.mesh)
        self._ds = backend.measure("ds", self.mesh)
        self.x = ufl.SpatialCoordinate(self.mesh.ufl_domain())
        self.n = ufl.FacetNormal(self.mesh.ufl_domain())
        self.time = 0.0
        self.t = backend.constant(self.mesh, 0.0)  # time at the end of the current step
        self.dt = backend.constant(self.mesh, 1.0)
        self._groups: dict[str, _Group] = {}
        self._group_of: dict[str, str] = {}
        self._owner: dict[str, str] = {}
        self._specs: dict[str, FieldSpec] = {}
        self._splits: dict[tuple[str, str], tuple] = {}
        self._provided: dict[str, tuple[Any, str]] = {}
        self._contributions: dict[str, list[tuple[Term, str]]] = defaultdict(list)
        self._consumed: set[str] = set()
        self._kinematics: tuple[Kinematics, str] | None = None
        #: (group of the balance, group read): that group's function as it stood when the balance's group last
        #: completed a sub-step (see :meth:`at_balance`)
        self._balances: dict[tuple[str, str], Any] = {}

    # -- spaces and fields --------------------------------------------------------------
    def element(self, spec: FieldSpec) -> ufl.FiniteElementBase:
        if spec.vector:
            return ufl.VectorElement("Lagrange", self.cell, spec.degree)
        return ufl.FiniteElement("Lagrange", self.cell, spec.degree)

    def add_group(self, name: str, specs: Sequence[FieldSpec], owners: dict[str, str]) -> None:
        """Create the function holding the fields ``specs`` (solved together)."""
        for spec in specs:
            if spec.name in self._group_of or spec.name in self._provided:
                raise ConfigError(f"field '{spec.name}' is provided by both {self.owner(spec.name)} "
                                  f"and {owners[spec.name]}")
        elements = [self.element(spec) for spec in specs]
        element = elements[0] if len(elements) == 1 else ufl.MixedElement(elements)
        space = self.backend.function_space(self.mesh, element)
        group = _Group(name, [s.name for s in specs], space,
                       self.backend.function(space, name), self.backend.function(space, f"{name}_previous"))
        self._groups[name] = group
        for spec in specs:
            self._group_of[spec.name] = name
            self._owner[spec.name] = owners[spec.name]
            self._specs[spec.name] = spec

    def _group(self, name: str) -> _Group:
        if name not in self._group_of:
            provided = ", ".join(list(self._group_of) + list(self._provided)) or "none"
            raise ConfigError(f"field '{name}' is required but no physics module of this model provides it "
                              f"(provided: {provided})")
        return self._groups[self._group_of[name]]

    def _component(self, name: str, function, kind: str) -> Expr:
        group = self._group(name)
        index = group.index(name)
        if index is None:
            return function
        key = (group.name, kind)
        if key not in self._splits:
            self._splits[key] = ufl.split(function)
        return self._splits[key][index]

    def field(self, name: str) -> Any:
        """The current value of a field (a UFL expression), or what another module provides under ``name``."""
        if name in self._provided:
            return self._provided[name][0]
        group = self._group(name)
        return self._component(name, group.current, "current")

    def previous(self, name: str) -> Expr:
        """The value of a field at the start of the step."""
        group = self._group(name)
        return self._component(name, group.previous, "previous")

    def at_balance(self, name: str, of: str) -> Expr:
        """Field ``name`` as it stood when field ``of``'s group last completed a sub-step (before any: its value
        when this is first asked, after the initial state is complete).

        What a balance of ``of`` reads of another field at its own previous state. The conservative
        accumulation J c - J_b c^n needs J_b, the volume ratio when c^n was balanced: under ``strang``
        the species' two half steps straddle the mechanics, and J at the start of the mechanics' step
        counted each volume change twice; with ``inner_steps`` each inner step counted it again.  In
        the same group (``monolithic``), or when the schemes solve ``of`` after ``name`` in each
        step (``sequential``, ``fixed_point``), it is ``name``'s value at the start of the step.
        """
        key = (self._group(of).name, self._group(name).name)
        if key[0] == key[1]:
            return self.previous(name)
        if key not in self._balances:
            source = self._groups[key[1]]
            function = self.backend.function(source.space, f"{key[1]}_at_{key[0]}_balance")
            self.backend.local_array(function)[:] = self.backend.local_array(source.current)
            self._balances[key] = function
        return self._component(name, self._balances[key], f"at_{key[0]}_balance")

    def rate(self, name: str) -> Expr:
        """(field at the end - at the start of the last completed step) / dt: e.g. the solid velocity."""
        group = self._group(name)
        if group.rate is None:
            group.rate = self.backend.function(group.space, f"{group.name}_rate")
        return self._component(name, group.rate, "rate")

    def span(self, name: str) -> Expr:
        """The length of the sub-step that last advanced ``name``'s group, a constant.

        (field - previous) / span is that field's rate over its own last sub-step, which is what a
        module reading another module's field wants: under ``strang`` the chemistry's half step when
        the mechanics runs over the whole dt, where (m - m^n) / dt halved dm/dt.  When both are
        solved in one sub-step (``fixed_point``, ``monolithic``, or in turn within one step) it is dt.
        """
        group = self._group(name)
        if group.span is None:
            group.span = self.backend.constant(self.mesh, float(self.dt.value))
        return group.span

    def restore_spans(self, dt: float) -> None:
        """After a restart: every group was last advanced by the checkpointed run's last sub-step, of ``dt``."""
        for group in self._groups.values():
            if group.span is not None:
                group.span.value = dt

    def rate_function(self, name: str) -> ufl.Coefficient:
        """The backend function holding the rate of ``name``'s group (e.g. for an initial-rate solve)."""
        self.rate(name)
        return self._group(name).rate

    def set_rate(self, name: str, values: PointFunction | float) -> None:
        """Set the rate of a field (e.g. an initial solid velocity) to the interpolant of ``values``."""
        self.rate(name)
        self._interpolate_into(self._group(name).rate, name, values)

    def test(self, name: str) -> Expr:
        """The test function of a field's balance law."""
        return self._argument(name, "test", ufl.TestFunction)

    def unknown(self, name: str) -> ufl.Coefficient:
        """The backend function solved for when ``name``'s balance law is solved."""
        return self._group(name).current

    def unknown_fields(self, name: str) -> tuple[str, ...]:
        """The fields solved together with ``name`` (its group), in the order of the unknown's sub-spaces."""
        return tuple(self._group(name).fields)

    def trial(self, name: str) -> Expr:
        """The trial function of a field in its group's space (for bilinear forms such as preconditioners)."""
        return self._argument(name, "trial", ufl.TrialFunction)

    def _argument(self, name: str, kind: str, make) -> Expr:
        """The test or trial function of the group holding ``name``, split into its fields, at ``name``."""
        group = self._group(name)
        key = (group.name, kind)
        if key not in self._splits:
            argument = make(group.space)
            self._splits[key] = (argument,) if len(group.fields) == 1 else ufl.split(argument)
        index = group.index(name)
        return self._splits[key][0 if index is None else index]

    def constant(self, value: float) -> ufl.Constant:
        """A UFL constant on the mesh whose value can be changed between solves (``.value = ...``)."""
        return self.backend.constant(self.mesh, value)

    @property
    def ranks(self) -> int:
        """How many MPI ranks share the mesh (solver defaults may differ in parallel)."""
        return self.backend.comm.size

    def function_of(self, name: str) -> tuple[Any, int | None]:
        """(backend function, component index or None) holding a field, for output."""
        group = self._group(name)
        return group.current, group.index(name)

    def is_alone(self, name: str) -> bool:
        """Whether a field is a whole backend function (nodal arrays can be read directly)."""
        return len(self._group(name).fields) == 1

    def field_names(self) -> list[str]:
        return list(self._group_of)

    def displacement_field(self) -> str | None:
        """The field declared the tissue's displacement (``FieldSpec.displacement``), or None."""
        return next((name for name, spec in self._specs.items() if spec.displacement), None)

    def groups(self) -> list[str]:
        return list(self._groups)

    def group_function(self, group: str) -> ufl.Coefficient:
        return self._groups[group].current

    def group_fields(self, group: str) -> list[str]:
        return list(self._groups[group].fields)

    def group_of_function(self, function) -> str:
        """The name of the group a backend function (``unknown``: its current value or its rate) holds."""
        for name, group in self._groups.items():
            if group.current is function or group.rate is function:
                return name
        raise KeyError("not a field group of this discretisation")

    def owner(self, name: str) -> str:
        if name in self._provided:
            return self._provided[name][1]
        return self._owner[name]

    def provide(self, name: str, expression: Any, owner: str) -> None:
        """Offer a derived quantity (a UFL expression) to other modules under ``name``."""
        if name in self._group_of or name in self._provided:
            raise ConfigError(f"'{name}' is provided by both {self.owner(name)} and {owner}")
        self._provided[name] = (expression, owner)

    # -- kinematics -----------------------------------------------------------------------
    def provide_kinematics(self, kinematics: Kinematics, owner: str) -> None:
        """Declare how the tissue moves (a mechanics module does this in ``setup``)."""
        if self._kinematics is not None:
            raise ConfigError(f"the motion of the tissue is described by both {self._kinematics[1]} and {owner}")
        self._kinematics = (kinematics, owner)

    @property
    def kinematics(self) -> Kinematics:
        """The tissue's motion as provided by the mechanics module; motionless without one.

        Read it when building forms (``subproblems``), after every module's ``setup``.
        """
        return MOTIONLESS if self._kinematics is None else self._kinematics[0]

    # -- measures -------------------------------------------------------------------------
    def ds(self, boundary: str | None = None) -> ufl.Measure:
        return self._ds if boundary is None else self._ds(self.mesh_data.boundary_id(boundary))

    def dx_degree(self, degree: int | None) -> ufl.Measure:
        """``dx`` with a fixed quadrature degree (``None``: the backend's estimate)."""
        return self.dx if degree is None else self.dx(metadata={"quadrature_degree": int(degree)})

    def ds_degree(self, degree: int | None, boundary: str | None = None) -> ufl.Measure:
        """``ds`` (on ``boundary``) with a fixed quadrature degree (``None``: the backend's estimate)."""
        measure = self.ds(boundary)
        return measure if degree is None else measure(metadata={"quadrature_degree": int(degree)})

    # -- Dirichlet conditions -------------------------------------------------------------
    def dirichlet_bc(self, name: str, boundary: str, values: PointFunction | float,
                     component: int | None = None) -> BoundaryCondition:
        """Fix field ``name`` (its ``component``, for a vector field) on ``boundary`` to ``values``.

        ``values`` is a number or a function of the points x (shape (gdim, n)); the condition
        acts on the unknown of ``name``'s group, whatever the grouping.
        """
        group = self._group(name)
        index = group.index(name)
        path = tuple(i for i in (index, component) if i is not None)
        return self.backend.dirichlet_bc(group.space, boundary, values, component=path or None)

    def update_dirichlet_bc(self, bc: BoundaryCondition, values: PointFunction | float) -> None:
        """Give a condition of :meth:`dirichlet_bc` new values (e.g. at a new time)."""
        self.backend.update_dirichlet_bc(bc, values)

    # -- algebraic operators --------------------------------------------------------------
    def assemble_matrix(self, form: ufl.Form, A=None):
        """The PETSc matrix of a bilinear form (into ``A`` when given), for an algebraic operator."""
        return self.backend.assemble_matrix(form, A=A)

    def previous_vector(self, name: str):
        """The PETSc vector of a field's start-of-step value (a field alone in its group)."""
        if not self.is_alone(name):
            raise ConfigError(f"field '{name}' shares its function with {', '.join(self.unknown_fields(name))}: "
                              f"an algebraic operator needs it alone")
        return self.backend.petsc_vector(self._group(name).previous)

    @property
    def comm(self):
        """The MPI communicator of the mesh."""
        return self.backend.comm

    # -- couplings ------------------------------------------------------------------------
    def contribute(self, field_name: str, term: Term, by: str = "a coupling") -> None:
        """Add ``term(test)`` (a UFL form, or None for nothing) to the residual of ``field_name``'s balance law.

        ``by`` names the contributing module in the error raised when no balance law reads the term.
        """
        self._group(field_name)  # a field no module provides is named now
        self._contributions[field_name].append((term, by))

    def contributors(self, field_name: str) -> tuple[str, ...]:
        """The modules that add terms to ``field_name``'s balance law (:meth:`contribute`'s ``by``), in order."""
        return tuple(dict.fromkeys(by for _, by in self._contributions.get(field_name, ())))

    def contributions(self, field_name: str, test: Expr) -> list[ufl.Form]:
        """The terms contributed to ``field_name``'s balance law: what its owner adds to the residual."""
        self._consumed.add(field_name)
        forms = []
        for term, by in self._contributions[field_name]:
            with third_party_code(f"the term {by} adds to the balance law of '{field_name}' failed", term):
                form = term(test)
            if form is not None:
                forms.append(form)
        return forms

    def check_contributions(self) -> None:
        """Refuse (one line) a term contributed to a field whose balance law no subproblem read."""
        for field_name, terms in self._contributions.items():
            if terms and field_name not in self._consumed:
                raise ConfigError(f"{terms[0][1]} adds a term to the balance law of '{field_name}', but "
                                  f"{self.owner(field_name)} does not read contributed terms")

    # -- values ---------------------------------------------------------------------------
    def set_vertex_values(self, name: str, values: np.ndarray) -> None:
        """Set a P1 field from values at every mesh vertex (MeshData order)."""
        group = self._group(name)
        index = group.index(name)
        if index is None:
            self.backend.set_vertex_values(group.current, values)
            return
        spec = self._specs[name]
        if spec.degree != 1:
            raise ConfigError(f"field '{name}' is not P1 and cannot be set from vertex values")
        alone = self.backend.function(self.backend.function_space(self.mesh, self.element(spec)), f"{name}_vertices")
        self.backend.set_vertex_values(alone, values)
        self._interpolate_into(group.current, name, alone)

    def interpolate(self, name: str, values: PointFunction | float) -> None:
        """Set a field to the interpolant of ``values`` (a number or a function of the points x)."""
        self._interpolate_into(self._group(name).current, name, values)

    def _interpolate_into(self, function, name: str, values) -> None:
        """Interpolate ``values`` into ``name``'s part of a group function (current, rate...)."""
        index = self._group(name).index(name)
        if index is None:
            self.backend.interpolate(function, values)
        else:
            self.backend.interpolate_component(function, index, values)

    def store_previous(self, groups: Sequence[str] | None = None) -> None:
        """previous <- current, for every group (start of a step) or the given ones."""
        for name in groups or self._groups:
            group = self._groups[name]
            self.backend.local_array(group.previous)[:] = self.backend.local_array(group.current)
            if group.span is not None:  # this sub-step advances the group over dt
                group.span.value = self.dt.value

    def update_rates(self, dt: float, groups: Sequence[str] | None = None) -> None:
        """rate <- (current - previous) / dt for every group (or the given ones) whose rate is used, at the end
        of their sub-step; and what their balances read of other groups (:meth:`at_balance`) <- current."""
        for name in groups or self._groups:
            group = self._groups[name]
            if group.rate is not None:
                rate = self.backend.local_array(group.rate)  # in place: the same numbers, no temporaries
                np.subtract(self.backend.local_array(group.current), self.backend.local_array(group.previous), out=rate)
                np.divide(rate, dt, out=rate)
        for (balanced, read), function in self._balances.items():
            if groups is None or balanced in groups:
                self.backend.local_array(function)[:] = self.backend.local_array(self._groups[read].current)

    def set_time(self, t: float, dt: float) -> None:
        self.time = t
        self.t.value = t
        self.dt.value = dt

    # -- state: what the next step reads ------------------------------------------------
    def state_functions(self) -> dict[str, Any]:
        """Every backend function the next step reads, by ``GROUP/current``, ``GROUP/previous``, ``GROUP/rate``
        and ``GROUP/at_OTHER_balance`` (:meth:`at_balance`).

        A splitting scheme stores a group's start value when it advances that group,
        so between steps ``previous`` may still hold an older value that another
        module's forms read (e.g. u^{n-1} while the species are solved): all three are state.
        """
        functions = {}
        for name, group in self._groups.items():
            functions[f"{name}/current"] = group.current
            functions[f"{name}/previous"] = group.previous
            if group.rate is not None:
                functions[f"{name}/rate"] = group.rate
        for (balanced, read), function in self._balances.items():
            functions[f"{read}/at_{balanced}_balance"] = function
        return functions

    def copy_state(self, into: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """A copy of this rank's values (owned and ghost) of every state function: see :meth:`restore_state`.

        ``into``: an earlier copy whose arrays are overwritten (a step saves its start every
        time: no new arrays); a new copy when it does not match the state's functions.
        """
        functions = self.state_functions()
        if into is None or into.keys() != functions.keys():
            return {key: self.backend.local_array(function).copy() for key, function in functions.items()}
        for key, function in functions.items():
            values = self.backend.local_array(function)
            if into[key].shape != values.shape:
                into[key] = values.copy()
            else:
                np.copyto(into[key], values)
        return into

    def restore_state(self, saved: dict[str, np.ndarray]) -> None:
        """Put back the values of :meth:`copy_state` (undo a rejected or interrupted step)."""
        for key, function in self.state_functions().items():
            self.backend.local_array(function)[:] = saved[key]
