"""What a physics module is, and what it may ask of the run it joins.

A physics module owns some fields (``fields()``), states its weak forms once in
UFL on the objects a :class:`Discretisation` hands out, and returns them as an
ordered list of :class:`Subproblem` objects that the coupling layer solves.  It
never imports a finite element library: the backend behind the
:class:`Discretisation` does the assembly.

A module that needs a field owned by another module declares it in
``requires`` (e.g. the mechano-chemical coupling requires ``u`` from a
poroelasticity module) and reads it with ``disc.field(name)``; a missing
provider is reported by name before anything is assembled.

What a restart needs is declared too: the run checkpoints every field a module
declares in ``fields()``, with its value at the start of the step and its rate
(e.g. the solid velocity), by itself; a module that carries anything else from
step to step returns it from :meth:`Physics.state` and takes it back in
:meth:`Physics.restore_state`.  A module whose discretisation keeps a field
non-negative says so in :meth:`Physics.nonnegative_fields`: a step that breaks
the promise has failed and is retried with a smaller time step.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
import ufl
from ufl.algorithms import expand_derivatives

from primordia.core.config import Configured, merge_options
from primordia.core.errors import ConfigError, PluginError, is_third_party, third_party_code
from primordia.core.parameters import Parameter

if TYPE_CHECKING:
    from primordia.physics.discretisation import Discretisation

#: Up to this many ranks a constant matrix solved directly is factorised whole by one rank
#: (``solve_on_one_rank``): the chemotaxis species' and linear Biot's defaults.
GATHERED_RANKS = 8


@dataclass(frozen=True)
class FieldSpec:
    """A field a physics module owns: its name, element and meaning."""

    name: str
    degree: int = 1
    #: A vector field (gdim components), else a scalar.
    vector: bool = False
    description: str = ""
    #: Fields with the same group are solved together (one mixed function); None: alone.
    group: str | None = None
    #: The tissue's displacement: outputs draw the fields on the configuration it deforms to.
    displacement: bool = False


@dataclass
class Subproblem:
    """One (non)linear solve: find ``unknown`` with ``residual(unknown) = 0``.

    ``jacobian`` is ``ufl.derivative(residual, unknown)``.  ``linear`` marks a
    residual affine in the unknown (one Newton step is exact, a KSP solve);
    otherwise the solve is Newton's method through PETSc SNES.
    ``constant_jacobian`` marks a Jacobian that does not change between time
    steps (assembled and factorised once).  ``operator`` is an optional
    algebraic term (see :class:`AlgebraicOperator`) added to both.
    ``preconditioner`` is an optional bilinear form added to the Jacobian in
    the preconditioning matrix (e.g. the stabilisation that makes a block a
    sparse Schur complement approximation).  ``fields`` names the fields of a
    mixed ``unknown`` in order (the splits of a fieldsplit preconditioner), and
    ``rigid_body`` the displacement among them whose rigid-body motions are the
    near-nullspace of its block (for AMG).  ``continuation`` = (constant, steps) asks for the
    solve to be done in ``steps`` stages with the UFL ``constant`` set to
    1/steps, 2/steps, ..., 1 (load continuation: each stage starts from the last).
    ``petsc_options`` are defaults for the options prefix ``prefix``.
    ``failure_hint`` is appended to the error when the solve fails (what the
    physics knows about why it may be impossible).
    """

    name: str
    unknown: Any
    residual: ufl.Form
    jacobian: ufl.Form
    bcs: list = field(default_factory=list)
    linear: bool = True
    constant_jacobian: bool = False
    operator: "AlgebraicOperator | None" = None
    preconditioner: ufl.Form | None = None
    fields: tuple[str, ...] = ()
    rigid_body: str | None = None
    continuation: tuple[Any, int] | None = None
    petsc_options: dict[str, Any] = field(default_factory=dict)
    failure_hint: str | None = None

    @property
    def prefix(self) -> str:
        return self.name.replace(".", "_") + "_"


@dataclass(frozen=True)
class Diagnostic:
    """A derived quantity a physics module asks the run to record in its series.

    ``kind`` is ``"integral"`` (``expression`` is then a functional, a UFL form
    with its measure, recorded as ``NAME``), ``"extrema"`` (``expression`` is a
    UFL expression, whose minimum and maximum over the cell vertices are recorded
    as ``NAME_min`` and ``NAME_max``) or ``"value"`` (``expression`` is a callable
    returning a number the module computes itself, the same on every rank).
    """

    name: str
    kind: str
    expression: Any
    description: str = ""


class AlgebraicOperator(ABC):
    """A term assembled from matrices rather than from a UFL integrand.

    Used where a discretisation must act on the assembled operator to keep a
    discrete property (e.g. the exponentially fitted chemotactic flux that
    keeps the cell density non-negative).  ``update`` is called once per time
    step before the solve; the operator's matrix is added to the Jacobian and
    its action (:meth:`apply`) to the residual, so the solver layer needs to
    know nothing of the operator but this interface.
    """

    @abstractmethod
    def update(self) -> None:
        """Recompute the operator from the current state."""

    @abstractmethod
    def matrix(self):
        """The PETSc Mat of the operator (pattern of the P1 stiffness matrix)."""

    def apply(self, x, residual) -> None:
        """residual += A x (PETSc vectors of the unknown and of the residual)."""
        self.matrix().multAdd(x, residual, residual)

    def shifted(self, diagonal):
        """A + diag(``diagonal``) (a PETSc Vec of the owned rows) in the operator's own storage, for a
        solve whose Jacobian is otherwise diagonal (a lumped mass), valid until the next
        :meth:`update`; or ``None`` when the operator cannot, and the solver adds a copy of
        :meth:`matrix` and the diagonal.  :meth:`matrix` and :meth:`apply` keep meaning A alone.
        """
        return None


class Physics(Configured, ABC):
    """A balance law or constitutive piece, contributed through ``primordia_physics``."""

    #: Name used in ``[model] physics = [...]``.
    name: ClassVar[str]
    #: Parameters read by this module (seed names and defaults).
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    #: The options of the module's config table ``[physics.NAME]``, with their defaults; the values
    #: of a run are ``self.settings`` (the table's values over these defaults).
    options: ClassVar[Mapping[str, Any]] = {}
    #: Fields this module reads but another module provides, and quantities another offers (``provides``).
    requires: ClassVar[tuple[str, ...]] = ()
    #: Quantities other than its fields this module offers to others in ``setup`` (``disc.provide``), so that
    #: a model missing what a module ``requires`` is refused when it is composed (``--dry-run``), not at set-up.
    provides: ClassVar[tuple[str, ...]] = ()
    #: Whether the module needs a reaction kinetics plugin.
    needs_kinetics: ClassVar[bool] = False
    #: Whether the module needs a growth-law plugin (``[growth_law]``).
    needs_growth_law: ClassVar[bool] = False
    #: Whether the module states its balance laws at finite strain on a reference configuration.
    finite_strain: ClassVar[bool] = False
    #: Bytes a run of this module needs per cell at least, by dimension, where that is more than the mesh's own
    #: floor (:data:`primordia.core.meshes.MIN_BYTES_PER_CELL`): a run whose mesh needs more memory than the
    #: machine has is refused at its set-up and by ``--dry-run`` (:meth:`primordia.model.Model.check_affordable`),
    #: not killed by the kernel part-way through allocating it.
    min_bytes_per_cell: ClassVar[Mapping[int, int]] = {}

    def __init__(self, params: Mapping[str, float], kinetics=None, growth_law=None, **given):
        self.params = params
        self.kinetics = kinetics
        self.growth_law = growth_law
        self.settings: dict[str, Any] = merge_options(f"physics {self.name}", self.options, given)
        self.validate_options()

    def validate_options(self) -> None:
        """Check ``self.settings``; raise :class:`ConfigError` naming a bad value."""

    def check_composition(self, modules: list["Physics"]) -> None:
        """Refuse, in one line (:class:`ConfigError`), a model this module cannot join."""

    def inert_options(self, modules: list["Physics"], gdim: int, solver: Mapping[str, Any]) -> dict[str, str]:
        """The options of this module that have no effect in this model, each with why (e.g. the coupled solve's
        ``preconditioner`` under ``solve = "split"``): ``modules``, the model's physics; ``gdim``, the mesh's
        dimension; ``solver``, the config's ``[solver.*]`` tables.  The model warns, in one line, about one that
        holds a value other than its default: the user asked for something the run will not do.  A default is
        not told (the resolved config.toml a restart reads holds every default)."""
        return {}

    def inert_solver_tables(self) -> dict[str, str]:
        """The ``[solver.NAME]`` tables of the subproblems this module has under other settings and not under these
        (the species' own under ``solve = "coupled"``), each with why: given, such a table is one warning, as an
        inert option is, where a table naming no subproblem of any choice is refused (a misspelling)."""
        return {}

    def check_scheme(self, scheme, modules: list["Physics"]) -> None:
        """Refuse, in one line (:class:`ConfigError`), a splitting scheme this module's discretisation is
        wrong under (``scheme``: the :class:`~primordia.coupling.splitting.SplittingScheme`, its ``name``
        and its ``settings`` set)."""

    @abstractmethod
    def fields(self) -> list[FieldSpec]:
        """The fields this module owns."""

    @abstractmethod
    def setup(self, disc: Discretisation) -> None:
        """Build forms on ``disc`` (:class:`~primordia.physics.discretisation.Discretisation`)."""

    @abstractmethod
    def initialise(self, disc: Discretisation) -> None:
        """Set the initial values of the owned fields (seed eq. (2.6) etc.)."""

    @abstractmethod
    def subproblems(self) -> list[Subproblem]:
        """The solves of one time step of this module, in order."""

    def initial_subproblems(self) -> list[Subproblem]:
        """Solves that complete the initial state, run once after every module's ``initialise``."""
        return []

    def before_step(self, t: float, dt: float) -> None:
        """Update anything time-dependent before the solves of the step ending at ``t``."""

    def diagnostics(self) -> list[Diagnostic]:
        """Derived quantities to record in the run's series (after ``setup``)."""
        return []

    def fourier_symbol(self, context) -> Any:
        """This module's part of the linear stability analysis (``primordia stability``), or None: a model
        with a module that has none is refused there, since the analysis would not be the model that runs.

        Built-in modules are known to :mod:`primordia.analysis.composed` itself; a third party's answers
        an object with ``add_to(system)``, which adds its linearised terms about the homogeneous steady
        state under plane waves exp(i k.x + phi t) (grad -> i k, d/dt -> phi) by
        ``system.add(order, row, column, value)`` (``order`` 0, 1, 2: the coefficient of phi^order; rows
        and columns named ``u_1``..``u_d``, ``p``, the species and its own unknowns; ``system.k``, the
        wave vectors, ``system.K`` = |k|^2), and ``unknowns``, the names of the fields it adds (its own
        rows, after the species).  ``context`` holds ``steady_state.values`` (the species at rest),
        ``jacobian`` (dR/dc there) and ``params``.  See ``plugins/primordia-morphogen``.
        """
        return None

    def check_inputs(self, mesh_data, times) -> None:
        """Refuse, in one line, inputs only the mesh and the time span show wrong (before any assembly, and again
        at the times of a try that failed mid-run, from ``times[0]`` = t_start: a formula infinite at a step time
        no sample met is named there, not blamed on dt).

        By default the module's boundary conditions (option ``boundary``, a list of
        ``[[physics.NAME.boundary]]`` tables) are built and each formula is evaluated
        on its boundary's vertices at ``times``: a component of x the mesh lacks, a
        division by zero or an overflow is a :class:`ConfigError` naming the condition.
        """
        if "boundary" not in self.options:
            return
        from primordia.physics.boundary_conditions import condition_code, conditions_from_config

        own = [spec.name for spec in self.fields()]
        for condition in conditions_from_config(self.settings["boundary"], mesh_data, mesh_data.gdim):
            if condition.field not in own:
                raise ConfigError(f"boundary condition '{condition.kind}' on '{condition.boundary}' acts on the field "
                                  f"{condition.field}, which physics {self.name} does not solve for "
                                  f"(it has: {', '.join(own)})")
            vertices = mesh_data.points[np.unique(mesh_data.boundaries[condition.boundary])]
            with condition_code(type(condition), condition.boundary, "check"):
                condition.check(vertices, times)

    def nonnegative_fields(self) -> tuple[str, ...]:
        """Fields this module's discretisation keeps >= 0 (read after ``setup``), e.g. a monotone scheme's density.

        A step that leaves one of them negative has failed: it is rejected and retried
        with a smaller time step.
        """
        return ()

    def state(self) -> dict[str, Any]:
        """What the next step needs beyond the fields, for checkpoints (numbers, strings, lists, numpy arrays).

        Fields, their start-of-step values and their rates are saved by the run;
        return here anything else this module carries from one step to the next
        (a random generator's state, a history kept outside the fields).
        """
        return {}

    def restore_state(self, state: dict[str, Any]) -> None:
        """Take back what :meth:`state` returned (on restart, after ``setup``, or when a step is undone)."""



class Coupling(Physics):
    """A module that only couples: it owns no field and solves nothing, it adds terms to others' laws.

    Subclasses implement :meth:`setup`, where they declare their terms with
    ``disc.contribute(field, term, by=self.name)`` (e.g. active stress in the momentum
    balance, the FGF sink in the FGF balance law).
    """

    def fields(self) -> list[FieldSpec]:
        return []

    def initialise(self, disc: Discretisation) -> None:
        """Nothing to set: a coupling owns no field."""

    def subproblems(self) -> list[Subproblem]:
        return []


@contextmanager
def module_code(module: Physics, method: str):
    """Run ``method`` of a physics module: a third party's bug in it (any exception but primordia's own
    one-line errors) is one line naming the module, the method and where in the plugin's files it
    happened (:func:`~primordia.core.errors.third_party_code`), not a traceback.  primordia's own modules
    are left alone: their bugs are primordia's and keep their tracebacks.

    A :class:`ConfigError` the discretisation raises while a third party's module builds its forms names
    the module too: "field 'zz' is required but no physics module of this model provides it" did not say
    which of the model's plugins read it.
    """
    cls = type(module)
    try:
        with third_party_code(f"physics {module.name} ({cls.__module__}.{cls.__qualname__}): {method} failed", cls):
            yield
    except ConfigError as error:
        if (not is_third_party(cls) or method not in _BUILDING_FORMS
                or f"physics {module.name}" in str(error)):
            raise
        raise ConfigError(f"physics {module.name}: {method}: {error}") from error


#: The methods where a module reads the discretisation: a ConfigError there is about what it asked for.
_BUILDING_FORMS = ("setup", "initialise", "subproblems", "initial_subproblems", "before_step", "diagnostics")


def fields_of(module: Physics) -> list[FieldSpec]:
    """``module.fields()``, refused in one line naming the module unless it is a list of :class:`FieldSpec`."""
    with module_code(module, "fields"):
        specs = module.fields()
    if not isinstance(specs, (list, tuple)) or not all(isinstance(spec, FieldSpec) for spec in specs):
        raise PluginError(f"physics {module.name}: fields() must return a list of primordia.physics.base.FieldSpec, "
                          f"got {specs!r}")
    return list(specs)


def subproblems_of(module: Physics, initial: bool = False, disc: "Discretisation | None" = None) -> list[Subproblem]:
    """``module.subproblems()`` (``initial``: ``initial_subproblems()``), refused in one line naming the module
    unless it is a list of :class:`Subproblem` whose residual and Jacobian are UFL forms; given the run's
    ``disc``, also unless each solves for a field the module declares (:func:`_check_owned`)."""
    method = "initial_subproblems" if initial else "subproblems"
    with module_code(module, method):
        subproblems = getattr(module, method)()
    if not isinstance(subproblems, (list, tuple)) or not all(isinstance(sub, Subproblem) for sub in subproblems):
        raise PluginError(f"physics {module.name}: {method}() must return a list of "
                          f"primordia.physics.base.Subproblem, got {subproblems!r}")
    for sub in subproblems:
        for what in ("residual", "jacobian"):
            if not isinstance(getattr(sub, what), ufl.Form):
                raise PluginError(f"physics {module.name}: subproblem {sub.name}'s {what} must be a UFL form "
                                  f"(a sum of integrals; the jacobian ufl.derivative(residual, unknown)), got "
                                  f"{getattr(sub, what)!r}")
        _check_arguments(module, sub)
        if disc is not None:
            _check_owned(module, sub, disc)
        if sub.constant_jacobian and expand_derivatives(sub.jacobian).coefficients():
            # kept from the first solve where no split residual refreshes it (Dirichlet conditions): a cue
            # with a fixed boundary value decaying at a rate k m ended 4e-5 off after 10 steps, without a word
            raise PluginError(f"physics {module.name}: subproblem {sub.name} says constant_jacobian=True, but its "
                              f"jacobian reads fields, so a matrix kept from the first step would go stale; set it "
                              f"with primordia.physics.base.jacobian_is_constant(jacobian, disc)")
    return list(subproblems)


def _check_owned(module: Physics, sub: Subproblem, disc: Discretisation) -> None:
    """``sub`` solves for a field ``module`` declares in ``fields()``, or one line naming the module.

    A module that solved another's field (``disc.unknown("m")`` with ``disc.test("m")``, to add a term to the
    cells' balance) had it solved twice a step, once by each balance law, without a word.  Under ``monolithic``
    every field is one unknown, so this holds there whatever the module solves."""
    if any(sub.unknown is disc.unknown(spec.name) for spec in fields_of(module)):
        return
    solved = [name for name in disc.field_names() if disc.unknown(name) is sub.unknown]
    raise PluginError(f"physics {module.name}: subproblem {sub.name} solves for "
                      f"{'field ' + ', '.join(solved) if solved else 'a function that is no field of the model'}, "
                      f"which is not one of the fields {module.name} declares in fields(); a module solves its "
                      f"own fields, and adds terms to another's balance law with disc.contribute")


def check_affine(module: Physics, sub: Subproblem) -> None:
    """A subproblem marked ``linear`` has a residual affine in its unknown, or one line naming the module.

    Its solve is one Newton step from the start of the step (:class:`~primordia.coupling.solvers.LinearSolver`):
    on a residual that is not affine that is a silently inexact answer.  The split chemotaxis gave one to the
    schnakenberg activator, whose own production u^2 v it read at the unknown, and lost the step's non-negativity.
    Checked by the splitting schemes that solve each module's subproblems as they are (not ``monolithic``,
    whose one Newton solve is nonlinear whatever its parts say)."""
    if sub.linear and sub.unknown in expand_derivatives(ufl.derivative(sub.residual, sub.unknown)).coefficients():
        raise PluginError(f"physics {module.name}: subproblem {sub.name} says linear=True, but its residual is "
                          f"not affine in its unknown (its derivative still reads it), so one linear solve would "
                          f"not solve it; set linear=False (Newton's method) or read the unknown's nonlinear "
                          f"terms at disc.previous(name)")


def _check_arguments(module: Physics, sub: Subproblem) -> None:
    """The residual is linear in one test function and the Jacobian bilinear in a test and a trial function,
    all of the unknown's space, or one line naming the module.

    A residual with no test function (a functional) or with a trial function too was a ValueError traceback
    from the solver layer ("not enough values to unpack"); one tested by another field's test function
    (``disc.test("m")`` in the balance law of ``g``), or a Jacobian differentiated with respect to another
    field, ran to the end on another P1 field's space with a silently wrong answer.  Compared by identity:
    scikit-fem's spaces of two P1 fields are equal as UFL spaces.
    """
    space = sub.unknown.ufl_function_space() if hasattr(sub.unknown, "ufl_function_space") else None
    for what, kinds in (("residual", ("test",)), ("jacobian", ("test", "trial"))):
        arguments = sorted(getattr(sub, what).arguments(), key=lambda argument: argument.number())
        if len(arguments) == len(kinds) and all(argument.ufl_function_space() is space for argument in arguments):
            continue
        if len(arguments) != len(kinds):
            found = f"{len(arguments)} argument(s) ({', '.join(_argument_kind(a) for a in arguments) or 'none'})"
        else:
            found = "an argument of another space than the unknown's (another field's disc.test or disc.trial?)"
        shape = "one test function" if what == "residual" else "a test and a trial function"
        raise PluginError(f"physics {module.name}: subproblem {sub.name}'s {what} must be linear in {shape} of "
                          f"its unknown's space (disc.test(name) of a field it solves for; the jacobian "
                          f"ufl.derivative(residual, unknown)), got {found}")


def _argument_kind(argument) -> str:
    return "a test function" if argument.number() == 0 else "a trial function"


def jacobian_is_constant(jacobian: ufl.Form, disc: Discretisation) -> bool:
    """True when a Jacobian reads no field and not the time: assembled and factorised once."""
    expanded = expand_derivatives(jacobian)  # before expansion, derivative() still lists the unknown
    return not expanded.coefficients() and disc.t not in expanded.constants()
