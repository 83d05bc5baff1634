"""The discretised run a physics module sees: mesh, measures, fields, time.

:class:`Discretisation` hands physics modules UFL objects made by the run's
backend (spaces, fields, constants, measures) and keeps, for every field, its
current value and its value at the start of the step (``previous``).  It is
also where couplings meet: a module adds a term to another module's balance
law with :meth:`contribute`, and reads a field another module owns with
:meth:`field` (a missing provider is named).

Fields are stored in *groups*: the fields of a group are solved together and
live in one backend function (a mixed function when the group has several
fields, e.g. displacement and pore pressure).  ``field``, ``previous``,
``rate`` and ``test`` return UFL expressions either way, so a physics module
reads the same whether its fields are alone, grouped with each other, or all
in one monolithic group (the splitting scheme decides the grouping).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass

import ufl

from primordia.core.errors import ConfigError
from primordia.physics.kinematics import MOTIONLESS, Kinematics


@dataclass
class _Group:
    name: str
    fields: list[str]
    space: object
    current: object
    previous: object
    rate: object | None = None

    def index(self, field: str) -> int | None:
        return None if len(self.fields) == 1 else self.fields.index(field)


class Discretisation:
    def __init__(self, backend, mesh_data):
        self.backend = backend
        self.mesh_data = mesh_data
        self.mesh = backend.create_mesh(mesh_data)
        self.cell = self.mesh.ufl_domain().ufl_cell()
        self.gdim = mesh_data.gdim
        self.dx = backend.measure("dx", self.mesh)
        self.dx_lumped = backend.lumped_dx(self.mesh)
        self._ds = backend.measure("ds", self.mesh)
        self.x = ufl.SpatialCoordinate(self.mesh.ufl_domain())
        self.n = ufl.FacetNormal(self.mesh.ufl_domain())
        self.time = 0.0
        self.t = backend.constant(self.mesh, 0.0)  # time at the end of the current step
        self.dt = backend.constant(self.mesh, 1.0)
        self._groups: dict[str, _Group] = {}
        self._group_of: dict[str, str] = {}
        self._owner: dict[str, str] = {}
        self._specs: dict[str, object] = {}
        self._splits: dict[tuple[str, str], tuple] = {}
        self._provided: dict[str, tuple[object, str]] = {}
        self._contributions: dict[str, list[Callable]] = defaultdict(list)
        self._kinematics: tuple[Kinematics, str] | None = None

    # -- spaces and fields --------------------------------------------------------------
    def element(self, spec) -> ufl.FiniteElementBase:
        if spec.vector:
            return ufl.VectorElement("Lagrange", self.cell, spec.degree)
        return ufl.FiniteElement("Lagrange", self.cell, spec.degree)

    def add_group(self, name: str, specs: list, owners: dict[str, str]) -> None:
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

    def _component(self, name: str, function, kind: str):
        group = self._group(name)
        index = group.index(name)
        if index is None:
            return function
        key = (group.name, kind)
        if key not in self._splits:
            self._splits[key] = ufl.split(function)
        return self._splits[key][index]

    def field(self, name: str):
        """The current value of a field (or a quantity another module provides)."""
        if name in self._provided:
            return self._provided[name][0]
        group = self._group(name)
        return self._component(name, group.current, "current")

    def previous(self, name: str):
        """The value of a field at the start of the step."""
        group = self._group(name)
        return self._component(name, group.previous, "previous")

    def rate(self, name: str):
        """(field at the end - at the start of the last completed step) / dt: e.g. the solid velocity."""
        group = self._group(name)
        if group.rate is None:
            group.rate = self.backend.function(group.space, f"{group.name}_rate")
        return self._component(name, group.rate, "rate")

    def rate_function(self, name: str):
        """The backend function holding the rate of ``name``'s group (e.g. for an initial-rate solve)."""
        self.rate(name)
        return self._group(name).rate

    def set_rate(self, name: str, values) -> None:
        """Set the rate of a field (e.g. an initial solid velocity) to the interpolant of ``values``."""
        self.rate(name)
        self._interpolate_into(self._group(name).rate, name, values)

    def test(self, name: str):
        """The test function of a field's balance law."""
        return self._argument(name, "test", ufl.TestFunction)

    def unknown(self, name: str):
        """The backend function solved for when ``name``'s balance law is solved."""
        return self._group(name).current

    def unknown_fields(self, name: str) -> tuple[str, ...]:
        """The fields solved together with ``name`` (its group), in the order of the unknown's sub-spaces."""
        return tuple(self._group(name).fields)

    def trial(self, name: str):
        """The trial function of a field in its group's space (for bilinear forms such as preconditioners)."""
        return self._argument(name, "trial", ufl.TrialFunction)

    def _argument(self, name: str, kind: str, make):
        """The test or trial function of the group holding ``name``, split into its fields, at ``name``."""
        group = self._group(name)
        key = (group.name, kind)
        if key not in self._splits:
            argument = make(group.space)
            self._splits[key] = (argument,) if len(group.fields) == 1 else ufl.split(argument)
        index = group.index(name)
        return self._splits[key][0 if index is None else index]

    def function_of(self, name: str) -> tuple[object, int | None]:
        """(backend function, component index or None) holding a field, for output."""
        group = self._group(name)
        return group.current, group.index(name)

    def is_alone(self, name: str) -> bool:
        """Whether a field is a whole backend function (nodal arrays can be read directly)."""
        return len(self._group(name).fields) == 1

    def field_names(self) -> list[str]:
        return list(self._group_of)

    def groups(self) -> list[str]:
        return list(self._groups)

    def group_function(self, group: str):
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

    def provide(self, name: str, expression, owner: str) -> None:
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
    def ds(self, boundary: str | None = None):
        return self._ds if boundary is None else self._ds(self.mesh_data.boundary_id(boundary))

    def dx_degree(self, degree: int | None):
        """``dx`` with a fixed quadrature degree (``None``: the backend's estimate)."""
        return self.dx if degree is None else self.dx(metadata={"quadrature_degree": int(degree)})

    def ds_degree(self, degree: int | None, boundary: str | None = None):
        """``ds`` (on ``boundary``) with a fixed quadrature degree (``None``: the backend's estimate)."""
        measure = self.ds(boundary)
        return measure if degree is None else measure(metadata={"quadrature_degree": int(degree)})

    # -- couplings ------------------------------------------------------------------------
    def contribute(self, field_name: str, term: Callable):
        """Add ``term(test)`` (a UFL form, or None for nothing) to the residual of ``field_name``'s balance law."""
        self._contributions[field_name].append(term)

    def contributions(self, field_name: str, test) -> list:
        return [form for form in (term(test) for term in self._contributions[field_name]) if form is not None]

    # -- values ---------------------------------------------------------------------------
    def set_vertex_values(self, name: str, values):
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

    def interpolate(self, name: str, values):
        self._interpolate_into(self._group(name).current, name, values)

    def _interpolate_into(self, function, name: str, values):
        """Interpolate ``values`` into ``name``'s part of a group function (current, rate...)."""
        index = self._group(name).index(name)
        if index is None:
            self.backend.interpolate(function, values)
        else:
            self.backend.interpolate_component(function, index, values)

    def store_previous(self, groups: list[str] | None = None):
        """previous <- current, for every group (start of a step) or the given ones."""
        for name in groups or self._groups:
            group = self._groups[name]
            self.backend.local_array(group.previous)[:] = self.backend.local_array(group.current)

    def update_rates(self, dt: float, groups: list[str] | None = None):
        """rate <- (current - previous) / dt for every group (or the given ones) whose rate is used."""
        for name in groups or self._groups:
            group = self._groups[name]
            if group.rate is not None:
                rate = self.backend.local_array(group.rate)
                rate[:] = (self.backend.local_array(group.current) - self.backend.local_array(group.previous)) / dt

    def set_time(self, t: float, dt: float):
        self.time = t
        self.t.value = t
        self.dt.value = dt

    # -- state: what the next step reads ------------------------------------------------
    def state_functions(self) -> dict[str, object]:
        """Every backend function the next step reads, by ``GROUP/current``, ``GROUP/previous``, ``GROUP/rate``.

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
        return functions

    def copy_state(self) -> dict[str, object]:
        """A copy of this rank's values (owned and ghost) of every state function: see :meth:`restore_state`."""
        return {key: self.backend.local_array(function).copy() for key, function in self.state_functions().items()}

    def restore_state(self, saved: dict[str, object]) -> None:
        """Put back the values of :meth:`copy_state` (undo a rejected or interrupted step)."""
        for key, function in self.state_functions().items():
            self.backend.local_array(function)[:] = saved[key]
