"""The discretised run a physics module sees: mesh, measures, fields, time.

:class:`Discretisation` hands physics modules UFL objects made by the run's
backend (spaces, fields, constants, measures) and keeps, for every field, its
current value and its value at the start of the step (``previous``).  It is
also where couplings meet: a module adds a term to another module's balance
law with :meth:`contribute`, and reads a field another module owns with
:meth:`field` (a missing provider is named).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable

import ufl

from primordia.core.errors import ConfigError


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
        self._spaces: dict[tuple, object] = {}
        self._current: dict[str, object] = {}
        self._previous: dict[str, object] = {}
        self._owner: dict[str, str] = {}
        self._contributions: dict[str, list[Callable]] = defaultdict(list)

    # -- spaces and fields --------------------------------------------------------------
    def space(self, degree: int = 1, vector: bool = False):
        key = (degree, vector)
        if key not in self._spaces:
            element = (ufl.VectorElement("Lagrange", self.cell, degree) if vector
                       else ufl.FiniteElement("Lagrange", self.cell, degree))
            self._spaces[key] = self.backend.function_space(self.mesh, element)
        return self._spaces[key]

    def add_field(self, name: str, space, owner: str):
        if name in self._current:
            raise ConfigError(f"field '{name}' is provided by both {self._owner[name]} and {owner}")
        self._current[name] = self.backend.function(space, name)
        self._previous[name] = self.backend.function(space, f"{name}_previous")
        self._owner[name] = owner
        return self._current[name]

    def field(self, name: str):
        try:
            return self._current[name]
        except KeyError:
            raise ConfigError(f"field '{name}' is required but no physics module of this model provides it "
                              f"(provided: {', '.join(self._current) or 'none'})") from None

    def previous(self, name: str):
        self.field(name)
        return self._previous[name]

    def field_names(self) -> list[str]:
        return list(self._current)

    def owner(self, name: str) -> str:
        return self._owner[name]

    # -- measures -------------------------------------------------------------------------
    def ds(self, boundary: str | None = None):
        return self._ds if boundary is None else self._ds(self.mesh_data.boundary_id(boundary))

    # -- couplings ------------------------------------------------------------------------
    def contribute(self, field_name: str, term: Callable):
        """Add ``term(test)`` (a UFL form) to the residual of ``field_name``'s balance law."""
        self._contributions[field_name].append(term)

    def contributions(self, field_name: str, test) -> list:
        return [term(test) for term in self._contributions[field_name]]

    # -- values ---------------------------------------------------------------------------
    def set_vertex_values(self, name: str, values):
        self.backend.set_vertex_values(self.field(name), values)

    def interpolate(self, name: str, values):
        self.backend.interpolate(self.field(name), values)

    def store_previous(self):
        """previous <- current, for every field (start of a step)."""
        for name, current in self._current.items():
            previous = self._previous[name]
            self.backend.local_array(previous)[:] = self.backend.local_array(current)

    def set_time(self, t: float, dt: float):
        self.time = t
        self.t.value = t
        self.dt.value = dt
