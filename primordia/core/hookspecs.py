"""Every hook of primordia, in one file: the plugin author's manual.

A plugin is a module (or object) with functions decorated ``@hookimpl`` and
named like the stubs below; it is registered either as a built-in
(``primordia.core.plugins.DEFAULT_PLUGINS``) or by a distribution's entry point
in the group ``primordia``::

    [project.entry-points.primordia]
    my_kinetics = "my_package.plugin"

Two kinds of hooks:

* hooks that *contribute* (all answers are collected): physics modules,
  kinetics, growth laws, boundary-condition kinds, backends, splitting schemes,
  outputs.  Each returns a
  list of classes (or :class:`~primordia.core.plugins.BackendEntry` for
  backends) carrying a unique ``name``.
* hooks that *choose* (``firstresult``: the first non-None answer wins):
  which backend and which splitting scheme a run uses.  primordia's own
  choosers run last (``trylast``), so a plugin can override a choice.

Built-in pieces register through these very same hooks.

The contract is versioned (:data:`CONTRACT_VERSION`, major.minor): a new hook, a new
optional argument or a new optional method raises the minor version; removing or
renaming a hook, changing what it returns or adding a required method raises the
major one.  A plugin module may state the major version it was written for
(``PRIMORDIA_CONTRACT = 1``); one written for another major version is refused with
one warning.  The plugin author's guide is docs/plugins.md.
"""

from __future__ import annotations

import pluggy

hookspec = pluggy.HookspecMarker("primordia")

#: (major, minor) of this hook contract.  1.1: growth laws and boundary-condition kinds.  1.2: self.settings
#: (self.opts still reads them), GrowthLaw.directions_at, Output.options, the Coupling base, Discretisation
#: in primordia.physics.discretisation.  1.3: the optional Backend.shares_dofs / owned_dof_coordinates,
#: OutputOption.names_fields.
#: 1.4: the optional AlgebraicOperator.shifted (the lumped mass added to an operator in place).
#: 1.5: the optional Backend.p1_cell_dofs / p1_cell_coordinates (the closed-form P1 advection).
#: 1.6: the optional Physics.check_scheme (refuse a splitting scheme), Output.finishes_last, Discretisation.span.
#: 1.7: the optional Physics.fourier_symbol and Physics.provides, Discretisation.at_balance,
#: Kinematics.volume_ratio_of.
#: 1.8: the optional Physics.inert_options / inert_solver_tables (settings a model leaves without effect) and
#: Output.flush (what waits in memory, written when a run ends without finish).
CONTRACT_VERSION = (1, 8)


@hookspec
def primordia_physics() -> list[type]:
    """Physics modules (subclasses of ``primordia.physics.base.Physics``).

    Returns a list of classes; each has a unique ``name`` used in a config's
    ``[model] physics = [...]`` list.  A module owning fields implements ``fields``,
    ``setup(disc)``, ``initialise(disc)`` and ``subproblems()``: each ``Subproblem``'s
    residual is linear in one test function of its unknown's space (``disc.test``
    of a field it solves for) and its Jacobian is ``ufl.derivative(residual,
    unknown)``.  A module that only couples subclasses ``Coupling`` and adds terms
    to other modules' balance laws with ``disc.contribute``.  What either reads
    from another module goes in ``requires``; ``fourier_symbol`` gives its part of
    ``primordia stability``.  A third party's exception or wrong-shaped answer is
    refused in one line naming the module.
    """


@hookspec
def primordia_kinetics() -> list[type]:
    """Reaction kinetics (subclasses of ``primordia.physics.kinetics.base.Kinetics``).

    Returns a list of classes; each has a unique ``name`` selected by
    ``[kinetics] name = "..."``.
    """


@hookspec
def primordia_growth_laws() -> list[type]:
    """Growth laws of the finite-strain growth model (seed section 4, eqs. (4.13)-(4.15)).

    Returns a list of classes (subclasses of ``primordia.physics.growth_laws.GrowthLaw``);
    each has a unique ``name`` selected by ``[growth_law] name = "..."``.  A law
    gives the growth factors gamma_i(fields, t, X) as UFL expressions; the growth
    tensor F_g and the fluid source ell = ell_0 sum_i d gamma_i/dt are built from
    them.  Built-in: ``seed2d`` (4.14), ``seed3d`` (4.13).
    """


@hookspec
def primordia_boundary_conditions() -> list[type]:
    """Boundary-condition kinds (subclasses of ``primordia.physics.boundary_conditions.Condition``).

    Returns a list of classes; each has a unique ``kind`` used as ``type = "..."``
    in a ``[[physics.NAME.boundary]]`` table, and contributes its own weak-form
    terms or Dirichlet constraints.  Built-in: clamped, displacement,
    normal_displacement, traction, robin (4.16a), fluid_flux, fluid_pressure.
    """


@hookspec
def primordia_backends() -> list:
    """Finite element backends, as ``BackendEntry(name, "module:Class")``.

    Entries are imported only when chosen or listed, so a backend whose
    library is missing does not break the others.
    """


@hookspec
def primordia_splitting_schemes() -> list[type]:
    """Operator-splitting schemes (subclasses of ``primordia.coupling.splitting.SplittingScheme``).

    Returns a list of classes; each has a unique ``name`` selected by ``[coupling]
    scheme = "..."``, and ``options`` (keys of ``[coupling]``, with defaults;
    ``self.settings`` holds a run's).  ``advance(sim, t0, dt)`` advances every field
    from ``t0`` to ``t0 + dt`` through ``sim.advance(flow, t0, duration,
    inner_steps)`` on the sub-flows ``self.flows`` (one per module, in model order,
    set by ``build``) and returns the solve statistics by subproblem, summed with
    ``primordia.coupling.solvers.accumulate`` where a flow runs more than once.
    """


@hookspec
def primordia_outputs() -> list[type]:
    """Output writers (subclasses of ``primordia.core.outputs.Output``).

    Every registered output is attached to every run; each decides from the
    run's ``[output]`` table what, if anything, it writes.  An output with options
    declares them in its class attribute ``options`` (key ->
    ``primordia.core.outputs.OutputOption(default, check, help)``): the model then
    accepts those keys of ``[output]``, checks them and fills in their defaults
    before the run; any other key is refused.  A key belongs to one output.

    Under MPI every rank calls every moment of every output.  An output that fails
    (raises) on any rank is disabled on all, with one warning naming the rank, and
    the run goes on.  The ranks agree on that after each call, so an output's
    collective calls (``run.comm``'s, or those of ``run.field_statistics()``,
    ``run.vertex_values()``) must be reached by every rank whatever happens on one:
    catch what may fail on one rank only (a file one rank writes), take part in the
    collective calls, and raise after them (as the pictures' ``_draw_shared`` does).
    A rank that raised before a collective call the other ranks are inside cannot be
    told from a slow one: it waits for them (at least 300 s, ``OUTPUT_PATIENCE_S`` of
    ``primordia.coupling.orchestrator``),
    then ends the job with one line and MPI_Abort, exit status 2.  Before that abort (and when a second
    signal stops a parallel run at once) each output's optional ``flush(run)`` writes, on its own rank and
    without collective calls, what it holds in memory (series.nc's waiting rows).
    """


@hookspec(firstresult=True)
def primordia_select_backend(name: str, entries: dict, comm):
    """Choose and instantiate the backend for a run.

    ``name`` is the requested backend (from ``--backend`` or the config),
    ``entries`` maps registered names to ``BackendEntry``; return a ``Backend``
    instance, or None to let the next implementation decide.
    """


@hookspec(firstresult=True)
def primordia_select_splitting_scheme(name: str, options: dict, schemes: dict, physics: list):
    """Choose the operator-splitting scheme for a run.

    ``name`` is the requested scheme (``[coupling] scheme``), ``options`` the
    rest of the ``[coupling]`` table, ``schemes`` maps registered names to
    classes, ``physics`` lists the run's physics objects; return a scheme
    instance, or None to defer.
    """
