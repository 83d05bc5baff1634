"""PETSc options of a subproblem: nested tables, who overrides whom, one-line errors.

A config's ``[solver.NAME]`` table holds PETSc options of the subproblem whose
options prefix is ``NAME_`` (``chemotaxis_m``, ``poroelastic_growth``, ``monolithic``),
written without the prefix, and, as Firedrake's ``solver_parameters``, nested
tables stand for option prefixes::

    [solver.poroelastic_growth]
    ksp_type = "gmres"
    pc_type = "fieldsplit"
    splits = [["u"], ["psi", "p"]]                       # not a PETSc option: see below
    fieldsplit_u = { ksp_type = "preonly", pc_type = "gamg" }
    fieldsplit_psi_p = { ksp_type = "preonly", pc_type = "hypre" }

is ``-poroelastic_growth_fieldsplit_u_pc_type gamg`` and so on.  A monitor or view set to ``true``
(``ksp_monitor = true``) is the option given bare, ``false`` leaves it out (:func:`reads_a_viewer`).  ``splits`` says
which fields (by name, as the physics module declares them) form each split of a
``fieldsplit`` preconditioner; a split is named by its fields joined with ``_``
(``psi_p``), which is the prefix of its options.  Without ``splits`` every field
is a split of its own.  ``rebuild_preconditioner_after = N``, another key that is
not PETSc's, keeps a preconditioner built for an earlier matrix until a Krylov solve
needs more than N iterations: a Newton solve's over Newton steps and time steps (see
:class:`~primordia.coupling.solvers.NewtonSolver`), a linear subproblem's over time
steps when its matrix changes at every step (see
:class:`~primordia.coupling.solvers.LinearSolver`).  ``"fresh+K"`` says instead: more
than K iterations above what the preconditioner needed fresh (a linear subproblem: its
first solve after the build; a Newton solve: the most any Newton step needed, from the
build to the end of that Newton solve).

Who wins, from weakest to strongest: the solver layer's defaults, the physics
module's (``Subproblem.petsc_options``), the config's table, options given
outside (``PETSC_OPTIONS``, the command line of petsc4py).  A user table that
changes ``pc_type`` (at any level: ``fieldsplit_u = { pc_type = "hypre" }``)
drops the defaults that only made sense for the preconditioner it replaces: the
defaults' options of that level other than ``ksp_*`` and ``snes_*`` (the factor
package, the splits and their sub-solvers, AMG settings, a ``rebuild_preconditioner_after``
count), and, at the top level, a ``ksp_type = "preonly"`` that only made sense with a
direct solve (kept for another one: ``lu`` to ``cholesky``), and so does ``solve_on_one_rank``: the
serial factorisation of the whole system on one rank beat MUMPS's distributed solves for a direct solve,
not for an iterative one (kept from ``lu`` to ``cholesky`` too).  A relative
``rebuild_preconditioner_after = "fresh+K"`` stays: it measures the kept preconditioner
against a fresh one of whatever kind (the cell density's default; ``pc_type = "hypre"``
there keeps BoomerAMG over steps instead of building it at each).
A factor package the defaults give beside a preconditioner that factorises nothing (the growth's
Schur split: its saddle point needs MUMPS's pivoting) stays when ``pc_type`` becomes a factorisation:
``pc_type = "lu"`` there met a zero pivot in PETSc's own LU first, and went to MUMPS with a warning.
A factor package changed to MUMPS drops the defaults' fill-reducing ordering, which MUMPS
would use in place of its own (see :func:`mumps_orders_itself`).

Mistakes are one line (:class:`~primordia.core.errors.ConfigError`, exit status
2): an unknown KSP, PC, SNES or factor-package type or matrix ordering, a value this
PETSc answers by aborting the process (:data:`ABORTING`), or a tolerance or iteration
count out of its range (``ksp_rtol = -1``, which PETSc would take for its default;
``ksp_max_it = 0``), when the solver is made; a value PETSc cannot read (``"abc"``
for a number), with PETSc's reason; an option PETSc never read (misspelt, or
meaningless for the chosen solver) after the first solve; a table naming no
subproblem of the run, when the run is set up.
"""

from __future__ import annotations

import ctypes
import difflib
import re
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from petsc4py import PETSc

from primordia.core.errors import ConfigError
from primordia.core.petsc_library import matrix_ordering_registered, petsc_library
from primordia.core.validation import number

#: Not a PETSc option: the fields of each split of a fieldsplit preconditioner (lists of field names).
SPLITS = "splits"
#: Not a PETSc option: a solve keeps its preconditioner (a factorisation, an AMG hierarchy) until a Krylov
#: solve takes more than this many iterations, then builds it anew from the current matrix (0: whenever the
#: matrix changed, PETSc's default).  A Newton solve keeps it over Newton steps and time steps (see
#: NewtonSolver), a linear subproblem whose matrix changes at every step over time steps (see LinearSolver).
#: The value may also be "fresh+K": K iterations more than the preconditioner needed fresh.
REBUILD = "rebuild_preconditioner_after"
#: How the relative form of REBUILD starts: "fresh+K", the iterations of a fresh preconditioner plus K.
FRESH = "fresh"
#: Not a PETSc option: a linear subproblem's whole system is gathered to one rank and solved there by that
#: rank's serial KSP (the other options of the table configure it); independent subproblems of a step so
#: marked are solved at once, each on its own rank (see :func:`~primordia.coupling.solvers.solve_in_turn`).
GATHER = "solve_on_one_rank"
#: The options of this table that primordia reads itself, not PETSc.
OWN_OPTIONS = (SPLITS, REBUILD, GATHER)

#: Option families that describe the Krylov method or Newton, not the preconditioner: kept when pc_type changes.
_KEPT_ACROSS_PC = ("ksp_", "snes_")

#: Direct solves: ``ksp_type = "preonly"`` made sense only with one of these.
DIRECT = ("lu", "cholesky")


def flatten(table: Mapping, where: str, prefix: str = "", spelled: dict[str, str] | None = None) -> dict[str, Any]:
    """Flat options from a (nested) table: ``{"fieldsplit_u": {"pc_type": "gamg"}}`` -> ``fieldsplit_u_pc_type``.

    Names are lower-cased: PETSc's options database ignores case (``KSP_RTOL`` is ``ksp_rtol``), and the
    checks and the defaults it overrides are keyed by the lower-case name.  One option written twice
    (``sub = { pc_type = "lu" }`` and ``sub_pc_type = "icc"``) is one line naming both spellings: which
    one won depended on their order in the table.  ``spelled`` maps each option found so far to how it
    was written.
    """
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where} must be a table of PETSc options, got {table!r}")
    spelled = {} if spelled is None else spelled
    path = spelled.get(prefix, "")
    flat: dict[str, Any] = {}
    for key, value in table.items():
        name = prefix + str(key).lstrip("-").lower()
        written = f"{path}.{key}" if path else str(key)
        if isinstance(value, Mapping):
            level = name + ("" if name.endswith("_") else "_")
            spelled[level] = written
            flat.update(flatten(value, where, level, spelled))
            continue
        if name in spelled:
            raise ConfigError(f"{where}: option {name} is given twice, as {spelled[name]} and as {written}")
        spelled[name] = written
        if name == SPLITS:
            flat[name] = _splits(value, f"{where}.{name}")
        elif name == REBUILD:
            flat[name] = _rebuild_after(value, f"{where}.{name}")
        elif name == GATHER:
            if not isinstance(value, bool):
                raise ConfigError(f"{where}.{name} must be true or false, got {value!r}")
            flat[name] = value
        elif isinstance(value, (list, tuple, dict)):
            raise ConfigError(f"{where}.{name} must be a number, a string or true/false, got {value!r}")
        elif isinstance(value, bool) and reads_a_viewer(name):
            if value:
                flat[name] = ""  # the bare flag: PETSc's default viewer (its own "true" is no viewer)
        else:
            flat[name] = value
    return flat


#: Options PETSc reads as a viewer (``ksp_monitor``, ``snes_converged_reason``, ``ksp_view_pre``, at any level),
#: whose value says where to print (``"stdout"``, ``"ascii:FILE"``): PETSc takes "true" and "false" there for
#: viewer names and stops at the first solve.  Their ``_cancel`` and ``pause_final`` options are true/false.
#: Any word ``monitor`` or ``view`` of the name, not only after ``ksp_``, ``snes_``, ...: the viewers
#: ``snes_test_jacobian_view``, ``mat_factor_view`` (read as a factorisation is made), ``snes_fas_monitor`` and
#: ``ksp_lsqr_monitor`` stopped the run at "true".  The true/false options so named (``pc_gasm_view_subdomains``,
#: ``snes_vi_monitor``) are false unless given, so the bare flag and its absence mean what true and false do;
#: and where PETSc asks only whether the option is given (``ksp_gmres_krylov_monitor``), "false" turned it on.
_VIEWER = re.compile(r"(?:^|_)(?:monitor|view|converged_reason|converged_rate)(?:_[a-z0-9_]+)?$")


def reads_a_viewer(name: str) -> bool:
    """Whether PETSc reads option ``name`` as a viewer: ``true`` there is the option given bare (printed to
    standard output), ``false`` the option left out, as PETSc itself has no "false" viewer."""
    return bool(_VIEWER.search(name)) and not name.endswith(("_cancel", "_pause_final"))


def _rebuild_after(value, where: str) -> int | str:
    """A number of Krylov iterations (0 or more), or ``"fresh+K"``: K more than the first solve after a build.

    Not ``"+K"``: TOML reads ``+2`` as the number 2, so ``--set ...=+2`` would silently mean the other rule.
    """
    relative = re.fullmatch(r"\s*fresh\s*\+\s*(\d+)\s*", value) if isinstance(value, str) else None
    if relative:
        return f"{FRESH}+{int(relative.group(1))}"
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ConfigError(f"{where} must be a number of Krylov iterations (0 or more), or \"fresh+K\" for K more "
                          f"than the first solve after the preconditioner was built, got {value!r}")
    return value


def _splits(value, where: str) -> tuple[tuple[str, ...], ...]:
    if (not isinstance(value, (list, tuple)) or not value
            or not all(isinstance(s, (list, tuple)) and s and all(isinstance(f, str) for f in s) for s in value)):
        raise ConfigError(f"{where} must be a list of lists of field names, e.g. [[\"u\"], [\"psi\", \"p\"]], "
                          f"got {value!r}")
    return tuple(tuple(split) for split in value)


def combine(defaults: Mapping[str, Any], user: Mapping[str, Any]) -> dict[str, Any]:
    """``defaults`` overridden by ``user``; a changed ``pc_type`` drops the defaults of the old preconditioner."""
    kept = dict(defaults)
    for key, value in user.items():
        if not key.endswith("pc_type") or str(defaults.get(key, value)) == str(value):
            continue
        level = key[: -len("pc_type")]
        direct_to_direct = level == "" and str(defaults.get("pc_type")) in DIRECT and str(value) in DIRECT
        # a factor package beside a preconditioner that factorises nothing names the one the system needs
        system_package = str(defaults.get(key)) not in DIRECT and str(value) in DIRECT
        for name in list(kept):
            rest = name[len(level):]
            if (name.startswith(level) and name != key and not rest.startswith(_KEPT_ACROSS_PC)
                    and not _relative_rebuild(rest, kept[name]) and not (direct_to_direct and name == GATHER)
                    and not (system_package and rest == PACKAGE)):
                del kept[name]
        if (level == "" and str(defaults.get("pc_type")) in DIRECT and str(value) not in DIRECT
                and "ksp_type" not in user and kept.get("ksp_type") == "preonly"):
            del kept["ksp_type"]
    return mumps_orders_itself({**kept, **user}, user)


def mumps_orders_itself(options: dict[str, Any], user: Iterable[str]) -> dict[str, Any]:
    """``options`` without a default fill-reducing ordering at a level whose factor package is MUMPS.

    Handed an ordering of PETSc's, serial MUMPS factorises in that order instead of its own analysis
    (``ICNTL(7) = 1``): PETSc's nested dissection of a 150 x 150 five-point Laplacian filled its factors
    with 16.3M entries against 0.92M with MUMPS's own, and example 2a's monolithic step at 43 x 43 took
    4.4 s against 1.0.  On more than one rank MUMPS ignores it.  An ordering the user wrote (a key of
    ``user``) stays.
    """
    for key, value in list(options.items()):
        level = key[: -len(PACKAGE)]
        if (key.endswith(PACKAGE) and str(value) == "mumps" and level + ORDERING in options
                and level + ORDERING not in user):
            del options[level + ORDERING]
    return options


def _relative_rebuild(name: str, value) -> bool:
    """Whether ``name = value`` is the relative rebuild rule ("fresh+K"), which holds for any preconditioner:
    it compares a kept one with what a fresh one of the same kind needs.  A number of iterations was chosen
    for the preconditioner it came with, and goes with it."""
    return name == REBUILD and isinstance(value, str) and value.startswith(FRESH)


def parallel_safe(options: Mapping[str, Any], parallel: bool) -> dict[str, Any]:
    """A direct solve without a factor package gets PETSc's own (serial) or MUMPS (more than one rank).

    Block-Jacobi and additive-Schwarz sub-solves (``sub_``) and the whole-system solve of a
    ``redundant`` preconditioner (``redundant_``) are serial on every rank: PETSc's own, and so is
    the solve of a system gathered to one rank (``solve_on_one_rank``).
    """
    safe = dict(options)
    parallel = parallel and not options.get(GATHER)
    for key, value in options.items():
        level = key[: -len("pc_type")]
        if key.endswith("pc_type") and str(value) in DIRECT and level + PACKAGE not in options:
            serial = not parallel or "sub_" in level or "redundant_" in level
            safe[level + PACKAGE] = "petsc" if serial else "mumps"
    return safe


def option_text(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


# -- validation -------------------------------------------------------------------------------
def _known_types(kind) -> list[str]:
    names = [getattr(kind.Type, name) for name in dir(kind.Type) if name.isupper()]
    return sorted({name for name in names if isinstance(name, str)})


def _try_type(kind, value: str) -> bool:
    obj = kind().create(PETSc.COMM_SELF)
    try:
        obj.setType(value)
        return True
    except PETSc.Error:
        return False
    finally:
        obj.destroy()


#: Factor packages (``pc_factor_mat_solver_type``) and the external package PETSc must be built with for each.
FACTOR_PACKAGES = {"petsc": None, "mumps": "mumps", "superlu": "superlu", "superlu_dist": "superlu_dist",
                   "umfpack": "suitesparse", "cholmod": "suitesparse", "klu": "suitesparse", "spqr": "suitesparse",
                   "mkl_pardiso": "mkl_pardiso", "mkl_cpardiso": "mkl_cpardiso", "pastix": "pastix",
                   "strumpack": "strumpack", "cusparse": "cuda", "essl": "essl", "lusol": "lusol"}


def _factor_package_available(package: str) -> bool:
    """Whether PETSc was built with ``package`` (asked without trying a factorisation: a PETSc error raised
    and caught inside KSPSetUp leaves the library in a state where a later ``ksp_error_if_not_converged``
    no longer raises)."""
    if package not in FACTOR_PACKAGES:
        return False
    external = FACTOR_PACKAGES[package]
    return external is None or bool(PETSc.Sys.hasExternalPackage(external))


_KINDS = {"ksp_type": ("KSP", PETSc.KSP), "pc_type": ("PC", PETSc.PC), "snes_type": ("SNES", PETSc.SNES)}
_checked: dict[tuple[str, str], bool] = {}


def _exists(kind: str, value: str, probe) -> bool:
    """``probe(value)``, asked once per (kind, value) in a process: a type, package or ordering PETSc has."""
    if (kind, value) not in _checked:
        _checked[kind, value] = probe(value)
    return _checked[kind, value]


def check_types(options: Mapping[str, Any], where: str) -> None:
    """Every KSP, PC, SNES type, factor package and matrix ordering in ``options`` exists here, or one line
    naming it."""
    for key, value in options.items():
        value = option_text(value)
        for suffix, (label, kind) in _KINDS.items():
            if key.endswith(suffix) and _ends_level(key, suffix):
                if not _exists(suffix, value, lambda name: _try_type(kind, name)):
                    known = _known_types(kind)
                    if value in known:  # petsc4py names it, this PETSc was built without it
                        raise ConfigError(f"{where}: {label} type '{value}' in {key} is not available in this PETSc "
                                          f"(built without it)")
                    raise ConfigError(f"{where}: unknown {label} type '{value}' in {key}{_suggestion(value, known)}")
        if key.endswith(PACKAGE):
            if not _exists("package", value, _factor_package_available):
                raise ConfigError(f"{where}: factor package '{value}' in {key} is not available in this PETSc "
                                  f"(e.g. mumps, petsc, superlu, umfpack)")
        for suffix, refused in ABORTING.items():
            read = value if suffix == ORDERING else value.lower()  # PETSc looks orderings up case by case
            if key.endswith(suffix) and _ends_level(key, suffix) and read in refused:
                raise ConfigError(f"{where}: {key} = '{value}' {MC64} {refused[read]}")
        if key.endswith(ORDERING) and _ends_level(key, ORDERING):
            if not _exists("ordering", value, matrix_ordering_registered):
                known = [o for o in _known_orderings() if o not in ABORTING[ORDERING]]
                raise ConfigError(f"{where}: matrix ordering '{value}' in {key} is not one this PETSc has"
                                  f"{_suggestion(value, known) or ' (it has ' + ', '.join(known) + ')'}")


#: The option naming a factorisation's fill-reducing ordering (at any level, e.g. ``sub_`` of block Jacobi).
ORDERING = "pc_factor_mat_ordering_type"
#: The option naming a factorisation's package (PETSc's own, MUMPS, ...).
PACKAGE = "pc_factor_mat_solver_type"
MC64 = ("calls SuperLU_DIST's MC64, HSL code left out of Debian's build, whose stand-in aborts the whole "
        "process (no summary, no checkpoint):")
#: Option values PETSc accepts and this PETSc answers by aborting the process, with what to use instead.
ABORTING = {
    ORDERING: {"wbm": "wbm is a weighted matching for pivoting, not a fill-reducing ordering: try nd, amd or qmd"},
    "mat_superlu_dist_rowperm": {"largediag_mc64": "try LargeDiag_AWPM or NOROWPERM"},
}


def _known_orderings() -> list[str]:
    names = [getattr(PETSc.Mat.OrderingType, n) for n in dir(PETSc.Mat.OrderingType) if n.isupper()]
    return sorted(n for n in names if isinstance(n, str) and _exists("ordering", n, matrix_ordering_registered))


#: Numeric options checked before PETSc reads them, by the option's name without its level: the bounds of
#: :func:`~primordia.core.validation.number`.  PETSc takes a negative tolerance for "the default" and a zero
#: iteration count for a solve that fails at once, and stops with a traceback on a value it cannot parse.
_FRACTION, _NONNEGATIVE, _POSITIVE = dict(at_least=0, below=1), dict(at_least=0), dict(above=0)
_COUNT, _LEVELS = dict(at_least=1, integer=True), dict(at_least=0, integer=True)
NUMERIC_OPTIONS = {
    "ksp_rtol": _FRACTION, "snes_rtol": _FRACTION,
    "ksp_atol": _NONNEGATIVE, "snes_atol": _NONNEGATIVE, "snes_stol": _NONNEGATIVE,
    "ksp_divtol": _POSITIVE,
    "ksp_max_it": _COUNT, "snes_max_it": _COUNT, "snes_max_funcs": _COUNT, "ksp_gmres_restart": _COUNT,
    "pc_mg_levels": _COUNT,
    "pc_factor_levels": _LEVELS, "pc_asm_overlap": _LEVELS, "pc_gasm_overlap": _LEVELS,
    "pc_gamg_agg_nsmooths": _LEVELS,
}
#: Words PETSc reads in place of a number (its defaults and infinities): left to PETSc, but for a level count
#: (fill levels, overlap layers, smoothing steps), where PETSc reads its default as -2 and stops at set-up
#: without naming the option ("Negative overlap value requested" for ``pc_gasm_overlap = "default"``).
_PETSC_WORDS = {"default", "petsc_default", "decide", "petsc_decide", "determine", "petsc_determine",
                "infinity", "-infinity", "petsc_infinity", "petsc_ninfinity"}


def check_values(options: Mapping[str, Any], where: str) -> None:
    """Every tolerance and iteration count in ``options`` (:data:`NUMERIC_OPTIONS`, at any level) is one PETSc
    reads as meant, or one line naming it.  A string (as PETSc's options hold them) is read as the number it
    writes; what is no number is refused as it stands."""
    for key, value in options.items():
        for name, bounds in NUMERIC_OPTIONS.items():
            if key.endswith(name) and _ends_level(key, name):
                if isinstance(value, str):
                    if value.strip().lower() in _PETSC_WORDS and bounds is not _LEVELS:
                        continue
                    try:
                        value = int(value) if bounds.get("integer") else float(value)
                    except ValueError:
                        pass
                number(value, f"{where}.{key}", **bounds)


def read_options(petsc_object, where: str, options: Mapping[str, Any] | None = None) -> None:
    """``petsc_object.setFromOptions()``, with a value PETSc refuses one line naming the solver table, PETSc's
    own reason (not its traceback) and the option of ``options`` whose value the reason quotes, if one does.

    ``options`` are the user's: with the defaults among them, a value the user gave that a default shares
    ("true" with ``snes_mf_operator``, 1 with ``sub_pc_factor_levels``) quoted two options, and so none."""
    try:
        petsc_object.setFromOptions()
    except PETSc.Error as error:
        reason = petsc_reason(error)
        raise ConfigError(f"{where}: PETSc refused the options: {reason}{quoted_option(reason, options)}") from None


def quoted_option(reason: str, options: Mapping[str, Any] | None) -> str:
    """`` (in KEY = 'VALUE')`` for the one option of ``options`` whose value PETSc's ``reason`` quotes (a value
    it could not read: "Input string abc has no numeric value"), else nothing."""
    quoted = [f"{key} = {option_text(value)!r}" for key, value in (options or {}).items()
              if option_text(value) and re.search(rf"(?<!\S){re.escape(option_text(value))}(?!\S)", reason)]
    return f" (in {quoted[0]})" if len(quoted) == 1 else ""


#: PETSc's error classes that say a solver was set up wrongly, not that it met numbers it could not solve
#: (petscerror.h): no support (56, 57), argument errors (60-64, 68-70, 73, 75, 80, 85, 86, 89), a file it
#: cannot open, read or write (65-67, 79: a monitor's ``"ascii:FILE"`` in a missing directory), a missing
#: factor package (92), an option overwritten (93), the wrong number of ranks (94), bad user input (95).  A
#: smaller time step cannot mend them.  A zero pivot (71, 81), a floating-point error (72), a failed
#: convergence (82, 91), memory (55) and an external library's failure (76, 77) may depend on the step.
USAGE_ERRORS = frozenset({56, 57, 60, 61, 62, 63, 64, 65, 66, 67, 68, 69, 70, 73, 75, 79, 80, 85, 86, 89, 92, 93, 94,
                          95})


def depends_on_step(error_code: int) -> bool:
    """Whether a PETSc error (its code) may go away with a smaller time step: not for a usage error."""
    return int(error_code) not in USAGE_ERRORS


def petsc_reason(error: PETSc.Error) -> str:
    """PETSc's own last word on ``error`` (the message under its traceback, e.g. "Unknown or unregistered type:
    metisnd"), or its error code when it left none."""
    lines = [line.partition("] ")[2] or line for line in str(error).splitlines()[1:]]
    lines = [line.strip() for line in lines if line.strip()]
    return lines[-1] if lines else str(error)


def _ends_level(key: str, suffix: str) -> bool:
    """``key`` is ``LEVEL + suffix`` with LEVEL empty or ending in ``_`` (not e.g. ``pc_hypre_type``)."""
    level = key[: -len(suffix)]
    return level == "" or level.endswith("_")


def _suggestion(value: str, known: Iterable[str]) -> str:
    """`` (did you mean ...?)`` with the closest of ``known``, compared in any case: PETSc's type names are
    case-sensitive, and "GASM" was far from "gasm" by its letters' case alone."""
    by_lower = {name.lower(): name for name in known}
    close = [by_lower[name] for name in difflib.get_close_matches(value.lower(), list(by_lower), n=3)]
    return f" (did you mean {', '.join(close)}?)" if close else ""


def unused(prefix: str, keys: Iterable[str]) -> list[str]:
    """Those of the options ``prefix + key`` that PETSc never read."""
    library, names = petsc_library(), []
    for key in keys:
        flag = ctypes.c_int(0)
        library.PetscOptionsUsed(None, (prefix + key).encode(), ctypes.byref(flag))
        if not flag.value:
            names.append(key)
    return names


def check_used(prefix: str, keys: Iterable[str], where: str, comm=None, root: int = 0,
               in_use: Callable[[str], str] | None = None) -> None:
    """After a first solve: an option the user gave that PETSc did not read is one line naming it, and the
    solver in use (``in_use(option)``, of the option with its prefix: "here ksp_type gmres, pc_type bjacobi"):
    a table written for another preconditioner (``pc_gasm_overlap``, for the cell density's default on several
    ranks, run in serial where the default is block Jacobi) was refused without saying which one read the options.

    With ``comm``, only rank ``root`` read the options (a system solved on one rank): its verdict
    is every rank's."""
    keys = [key for key in keys if key not in OWN_OPTIONS]
    missing = unused(prefix, keys) if comm is None or comm.rank == root else None
    solver = in_use(prefix + missing[0]) if missing and in_use is not None else ""
    if comm is not None:
        missing, solver = comm.bcast((missing, solver), root=root)
    if missing:
        raise ConfigError(f"{where}: PETSc did not use option '{missing[0]}' (-{prefix}{missing[0]}): unknown, "
                          f"or not read by the chosen solver" + (f" ({solver})" if solver else ""))


def check_table_values(tables: Mapping[str, Any]) -> None:
    """What can be told of the ``[solver.*]`` tables before the model is discretised (``--dry-run``): each is a
    table of options whose KSP, PC and factor types exist here and whose tolerances and counts are in range.
    Not whether a table names a subproblem of the run (:func:`check_tables`, once the subproblems exist), nor
    whether PETSc reads each option (:func:`check_used`, after the first solve)."""
    for name, table in tables.items():
        where = f"solver.{name}"
        options = flatten(table, where)
        check_types(options, where)
        check_values(options, where)


def check_tables(tables: Mapping[str, Any], prefixes: Iterable[str]) -> None:
    """Every ``[solver.NAME]`` table names a subproblem of the run, or one line naming it and the known ones."""
    known = sorted({prefix.rstrip("_") for prefix in prefixes})
    for name in tables:
        if name not in known:
            raise ConfigError(f"unknown solver table [solver.{name}]: no subproblem of this run has options "
                              f"prefix {name}_{_suggestion(name, known)} (known: {', '.join(known)})")
