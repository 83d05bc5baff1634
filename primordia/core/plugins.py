"""The plugin manager: built-ins and entry points, loaded once.

:func:`get_plugin_manager` registers the built-in plugins of
:data:`DEFAULT_PLUGINS`, every entry point of the group ``primordia``, and then
the plugins the environment variable ``PRIMORDIA_PLUGINS`` names, installed or not
(as pytest's ``PYTEST_PLUGINS``: module names or paths of ``.py`` files, separated
by commas; ``primordia -p`` adds to it).  An installed plugin that fails to import or
register produces one warning naming it and is skipped; the rest keeps working.  A
plugin named in the variable was asked for: one that fails, to load or in a contribute
hook, stops the program in one line.  :func:`registry` turns the contribute hooks into
name -> class tables and reports where each piece came from.

A plugin is trusted with nothing: a contribute hook that raises, returns
something other than a list of named pieces of the right kind, or reuses a name
already taken (a built-in's, or another plugin's) is named in one warning and
its contribution skipped (a PluginError if the plugin was asked for); a name two
installed plugins give is used from neither, since which of them is found first
depends on the machine, so a config naming it is one line naming both; a choosing
hook (:func:`choose`) that raises or returns something of the wrong kind is skipped
the same way.  Every such plugin is listed as broken by ``primordia plugins``
(:attr:`LoadReport.broken`), which asks the backend choosers itself
(:func:`ask_backend_choosers`); a splitting-scheme chooser
needs a model's physics, so only a run finds it broken.
"""

from __future__ import annotations

import difflib
import importlib
import importlib.metadata
import importlib.util
import inspect
import os
import sys
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import pluggy

from primordia.core import hookspecs
from primordia.core.errors import PluginError, one_line

hookimpl = pluggy.HookimplMarker("primordia")

#: Built-in plugins, registered through the same hooks a third party uses.
DEFAULT_PLUGINS = (
    "primordia.backends",
    "primordia.physics",
    "primordia.physics.kinetics",
    "primordia.physics.boundary_conditions",
    "primordia.coupling.splitting",
    "primordia.core.outputs",
    "primordia.core.selection",
)

#: What a piece of each kind must be ("module:Class": a subclass of it; backends: an instance).
PIECE_TYPES = {
    "physics": "primordia.physics.base:Physics",
    "kinetics": "primordia.physics.kinetics.base:Kinetics",
    "growth_laws": "primordia.physics.growth_laws:GrowthLaw",
    "boundary_conditions": "primordia.physics.boundary_conditions:Condition",
    "backends": "primordia.core.plugins:BackendEntry",
    "splitting_schemes": "primordia.coupling.splitting:SplittingScheme",
    "outputs": "primordia.core.outputs:Output",
}

#: The hook that contributes each kind of piece: kind name -> hook name.
HOOK_BY_KIND = {
    "physics": "primordia_physics",
    "kinetics": "primordia_kinetics",
    "growth_laws": "primordia_growth_laws",
    "boundary_conditions": "primordia_boundary_conditions",
    "backends": "primordia_backends",
    "splitting_schemes": "primordia_splitting_schemes",
    "outputs": "primordia_outputs",
}

_manager: pluggy.PluginManager | None = None

#: The origin of the built-in plugins.
BUILT_IN = "primordia (built-in)"


@dataclass(frozen=True)
class BackendEntry:
    """A backend known by name, imported only when used ("module:Class")."""

    name: str
    target: str
    description: str = ""

    def load(self):
        module_name, _, class_name = self.target.partition(":")
        module = importlib.import_module(module_name)
        return getattr(module, class_name)

    def availability(self) -> str | None:
        """None when the backend imports, else the reason it does not."""
        try:
            self.load()
        except Exception as exc:  # noqa: BLE001 - any import failure means "unavailable"
            return f"{type(exc).__name__}: {exc}".splitlines()[0]
        return None


@dataclass
class LoadReport:
    """What was registered from where, and which plugins are broken (each warned about once)."""

    sources: dict[str, str] = field(default_factory=dict)  # plugin name -> origin
    failures: list[str] = field(default_factory=list)  # one message per broken plugin and hook
    broken: dict[str, list[str]] = field(default_factory=dict)  # plugin name -> what is wrong with it
    skipped: dict[tuple[str, str], str] = field(default_factory=dict)  # (kind, piece name) -> why it was skipped
    #: (kind, piece name) -> why: a name two installed plugins give, used by neither (see :func:`registry`)
    contested: dict[tuple[str, str], str] = field(default_factory=dict)
    asked: set[str] = field(default_factory=set)  # plugins named in PRIMORDIA_PLUGINS: their failures stop the program
    #: plugins a test put in for a block (primordia.testing.registered): a name of theirs already taken stops the
    #: program, since the test would otherwise run the piece that holds it (an installed older version) unawares
    placed: set[str] = field(default_factory=set)

    def report(self, plugin: str, message: str) -> None:
        """Record (and warn, the first time) that ``plugin`` is broken."""
        if message in self.failures:
            return
        self.failures.append(message)
        self.broken.setdefault(plugin, []).append(message)
        _warn(message)


def _warn(message: str) -> None:
    from primordia.core.errors import warn

    warn(message)


def get_plugin_manager(reload: bool = False) -> pluggy.PluginManager:
    """The process-wide plugin manager (built-ins + entry points)."""
    global _manager
    if _manager is not None and not reload:
        return _manager
    pm = pluggy.PluginManager("primordia")
    pm.add_hookspecs(hookspecs)
    pm.load_report = LoadReport()
    for module_name in DEFAULT_PLUGINS:
        pm.register(importlib.import_module(module_name), name=module_name)
        pm.load_report.sources[module_name] = BUILT_IN
    for entry_point in importlib.metadata.entry_points(group="primordia"):
        origin = _distribution_label(entry_point)
        try:
            plugin = entry_point.load()
            _check_not_a_class(plugin, entry_point.value)
            _check_contract(plugin)
            pm.register(plugin, name=entry_point.name)
            _check_hook_names(pm, plugin, entry_point.name)
        except Exception as exc:  # noqa: BLE001 - a broken plugin must not break the rest
            message = f"plugin '{entry_point.name}' ({origin}) failed to load and is skipped: {one_line(exc)}"
            pm.load_report.report(entry_point.name, message)
            continue
        pm.load_report.sources[entry_point.name] = origin
    for item in named_plugins():
        _register_named(pm, item)
    _manager = pm
    return pm


#: The environment variable naming plugins to load without installing them.
PLUGINS_VARIABLE = "PRIMORDIA_PLUGINS"


def named_plugins() -> list[str]:
    """The module names and ``.py`` paths of ``PRIMORDIA_PLUGINS``, in order."""
    return [item.strip() for item in os.environ.get(PLUGINS_VARIABLE, "").split(",") if item.strip()]


def names_a_file(item: str) -> bool:
    """Whether an item of ``PRIMORDIA_PLUGINS`` is a file's path (else a module's name)."""
    return item.endswith(".py") or os.sep in item


def _register_named(pm: pluggy.PluginManager, item: str) -> None:
    """Load and register a plugin ``PRIMORDIA_PLUGINS`` names; any failure is a PluginError naming it."""
    is_file = names_a_file(item)
    name = Path(item).stem if is_file else item
    asked = f"plugin {item!r} ({PLUGINS_VARIABLE})"
    if pm.has_plugin(name):
        raise PluginError(f"{asked}: the name '{name}' is taken by {_origin(pm, name)}")
    if is_file and not Path(item).is_file():
        raise PluginError(f"{asked}: no such file")
    try:
        plugin = _load_file(item, name) if is_file else importlib.import_module(item)
        if pm.get_name(plugin) is not None:  # an installed plugin's module, or a built-in one
            raise PluginError(f"it is registered already, as '{pm.get_name(plugin)}' "
                              f"({_origin(pm, pm.get_name(plugin))})")
        _check_contract(plugin)
        pm.register(plugin, name=name)
        _check_hook_names(pm, plugin, name)
    except Exception as exc:  # noqa: BLE001 - the plugin's own import may raise anything
        lines = [line for frame, line in traceback.walk_tb(exc.__traceback__) if frame.f_code.co_filename == item]
        place = f" (at {item}:{lines[-1]})" if lines else ""
        raise PluginError(f"{asked} failed to load: {one_line(exc, named=not isinstance(exc, PluginError))}"
                          f"{place}") from exc
    where = str(Path(item).resolve()) if is_file else f"module {item}"
    pm.load_report.sources[name] = f"{where} ({PLUGINS_VARIABLE})"
    pm.load_report.asked.add(name)


def _load_file(path: str, name: str):
    """The module of the Python file ``path``, under a name of its own (so pickle and dataclasses find it)."""
    module_name = f"primordia_plugin_{name}"
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"{path} is not a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[module_name]
        raise
    return module


def _check_not_a_class(plugin, target: str) -> None:
    """Refuse an entry point naming a class: pluggy would call its ``@hookimpl`` methods without an instance, and
    every hook would fail with "missing 1 required positional argument: 'self'"."""
    if inspect.isclass(plugin):
        raise PluginError(f"{target} is a class, whose @hookimpl methods need an instance: name a module with "
                          f"@hookimpl functions, or an instance (PLUGIN = {plugin.__name__}() in the module)")


def _check_contract(plugin) -> None:
    """Refuse a plugin that states it was written for another major version of the hook contract."""
    stated = getattr(plugin, "PRIMORDIA_CONTRACT", None)
    major = hookspecs.CONTRACT_VERSION[0]
    if stated is not None and stated != major:
        raise PluginError(f"it was written for version {stated} of primordia's hook contract, this is {major}")


def _check_hook_names(pm, plugin, name: str) -> None:
    """Refuse (unregistered again) a plugin with an ``@hookimpl`` named like no hook: a misspelt hook would
    otherwise be silently never called."""
    unknown = sorted(caller.name for caller in pm.get_hookcallers(plugin) or ()
                     if not caller.has_spec() and not any(impl.optionalhook for impl in caller.get_hookimpls()
                                                          if impl.plugin is plugin))  # optionalhook: said on purpose
    if unknown:
        pm.unregister(plugin, name=name)
        hooks = [hook for hook in dir(hookspecs) if hook.startswith("primordia_")]
        close = difflib.get_close_matches(unknown[0], hooks, n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise PluginError(f"its @hookimpl {unknown[0]} is not a hook of primordia{hint}")


def _distribution_label(entry_point) -> str:
    dist = getattr(entry_point, "dist", None)
    if dist is None:
        return "entry point"
    return f"{dist.metadata['Name']} {dist.version}"


def _origin(pm, plugin_name: str) -> str:
    return pm.load_report.sources.get(plugin_name, plugin_name)


def registry(kind: str, pm: pluggy.PluginManager | None = None) -> dict[str, tuple[object, str]]:
    """name -> (piece, origin) for one kind of contribution (see :data:`HOOK_BY_KIND`).

    Built-ins are registered first, so their names are taken first; a broken
    contribution is reported (:meth:`LoadReport.report`) and skipped.  The table
    is computed once per set of registered plugins.
    """
    pm = pm or get_plugin_manager()
    impls = getattr(pm.hook, HOOK_BY_KIND[kind]).get_hookimpls()
    key = (kind, tuple((impl.plugin_name, id(impl.function)) for impl in impls))
    cache = pm.__dict__.setdefault("_primordia_registries", {})
    if key not in cache:
        table: dict[str, tuple[object, str]] = {}
        for stale in [entry for entry in pm.load_report.contested if entry[0] == kind]:  # found again below if so
            del pm.load_report.contested[stale]
        for impl in impls:
            for name, piece in _contribution(pm, kind, impl, table).items():
                table[name] = (piece, _origin(pm, impl.plugin_name))
        for contested_kind, name in pm.load_report.contested:
            if contested_kind == kind:  # which plugin held it depended on the order the packages were found in
                table.pop(name, None)
        # the entry keeps the hook functions of its key alive: an unregistered plugin's function could
        # otherwise be freed and its id taken by a newly registered one, which would get the old table
        cache[key] = (tuple(impl.function for impl in impls), table)
    return dict(cache[key][1])


def _contribution(pm, kind: str, impl, taken: dict) -> dict[str, object]:
    """The named pieces one plugin's hook contributes; all of them or, if anything is wrong, none (or, for a
    plugin asked for in ``PRIMORDIA_PLUGINS``, a PluginError: it was asked for, so it stops the program)."""
    plugin, origin = impl.plugin_name, _origin(pm, impl.plugin_name)
    where = f"plugin '{plugin}' ({origin}): hook {HOOK_BY_KIND[kind]}"
    try:
        pieces = impl.function()
    except Exception as exc:  # noqa: BLE001 - a broken plugin must not break the rest
        if plugin in pm.load_report.asked:
            raise PluginError(f"{where} raised {one_line(exc)}") from exc
        pm.load_report.report(plugin, f"{where} raised {one_line(exc)}; its {kind.replace('_', ' ')} are skipped")
        return {}
    if pieces is None:
        return {}
    problem = _junk(kind, pieces, taken)
    reused = problem is not None and problem.startswith("reuses the name")
    if problem and (plugin in pm.load_report.asked or (reused and plugin in pm.load_report.placed)):
        raise PluginError(f"{where} {problem}")
    if problem:
        message = f"{where} {problem}; its {kind.replace('_', ' ')} are skipped"
        contested = _contested(kind, pieces, taken) if reused else []
        if contested:
            message += (f", and neither plugin's {', '.join(repr(name) for name in contested)} is used (which one ran "
                        f"depended on the order their packages are found in): uninstall one of them")
            for name in contested:
                pm.load_report.contested[kind, name] = message
        pm.load_report.report(plugin, message)
        for piece in pieces if isinstance(pieces, (list, tuple)) else ():
            name = getattr(piece, "name", None)
            if isinstance(name, str) and name:  # a config naming it is told why it is missing
                pm.load_report.skipped.setdefault((kind, name), message)
        return {}
    return {piece.name: piece for piece in pieces}


def _junk(kind: str, pieces, taken: dict) -> str | None:
    """What is wrong with a hook's answer (None: a list of named pieces of the right kind, with new names)."""
    if not isinstance(pieces, (list, tuple)):
        return f"returned {pieces!r}, not a list of {kind.replace('_', ' ')}"
    required = _piece_type(kind)
    names = []
    for piece in pieces:
        fits = isinstance(piece, required) if kind == "backends" else (
            isinstance(piece, type) and issubclass(piece, required))
        if not fits:
            article = "an" if required.__name__[0] in "AEIOU" else "a"
            return (f"returned {piece!r}, which is not {article} {required.__name__}"
                    f"{'' if kind == 'backends' else ' class'}")
        name = getattr(piece, "name", None)
        if not isinstance(name, str) or not name:
            return f"returned {piece!r}, which has no name"
        if inspect.isabstract(piece):
            missing = ", ".join(sorted(piece.__abstractmethods__))
            return f"returned {name!r} ({piece.__name__}), which does not define the required {missing}"
        if name in taken or name in names:
            owner = taken[name][1] if name in taken else "the same hook"
            return f"reuses the name '{name}', taken by {owner}"
        twice = _parameter_declared_twice(piece)
        if twice is not None:
            return f"returned {name!r}, which {twice}"
        names.append(name)
    return None


def _contested(kind: str, pieces, taken: dict) -> list[str]:
    """The names among ``pieces`` another installed plugin already gives (a built-in's name stays the built-in's).

    Entry points come in the order their distributions are found on the path (a directory listing's), so
    which of two plugins giving one name was registered first, and ran, depended on the machine; neither does.
    """
    return [piece.name for piece in pieces if getattr(piece, "name", None) in taken
            and taken[piece.name][1] != BUILT_IN]


def _parameter_declared_twice(piece) -> str | None:
    """What is wrong when one piece declares one parameter name twice (None: it does not).

    Told as "declared by physics X (default 1) and by physics X (default 2)" only once a model composed it
    (``primordia.model._declarations`` compares owners, not declarations), and not at all when both defaults
    agreed: the model then held the name twice, with two descriptions.  Refused here, with the other checks of
    a hook's answer, the piece is listed as broken by ``primordia plugins`` and named by any config using it.
    """
    declared = getattr(piece, "parameters", ())
    if not isinstance(declared, (list, tuple)):
        return None  # not a tuple of Parameter: the model's composition names that
    seen: dict[str, object] = {}
    for parameter in declared:
        name = getattr(parameter, "name", None)
        if not isinstance(name, str):
            continue
        if name in seen:
            defaults = [getattr(p, "default", None) for p in (seen[name], parameter)]
            told = (f"default {defaults[0]!r}" if defaults[0] == defaults[1]
                    else f"defaults {defaults[0]!r} and {defaults[1]!r}")
            return f"declares parameter {name} twice ({told}): one name is one parameter, so rename or drop one"
        seen[name] = parameter
    return None


def _piece_type(kind: str) -> type:
    module_name, _, class_name = PIECE_TYPES[kind].partition(":")
    return getattr(importlib.import_module(module_name), class_name)


def choose(hook_name: str, validate, pm: pluggy.PluginManager | None = None, **kwargs):
    """The first acceptable answer of a ``firstresult`` hook, asking the plugins in pluggy's order.

    ``validate(answer)`` says whether an answer is of the right kind.  A
    third-party implementation that raises anything but a user error
    (:class:`~primordia.core.errors.PrimordiaError`), or answers junk, is reported
    and skipped; primordia's own choosers raise as they are.
    """
    from primordia.core.errors import PrimordiaError

    pm = pm or get_plugin_manager()
    for impl in _asking_order(pm, hook_name):
        plugin = impl.plugin_name
        where = f"plugin '{plugin}' ({_origin(pm, plugin)}): hook {hook_name}"
        try:
            answer = impl.function(*(kwargs[name] for name in impl.argnames))
        except PrimordiaError:
            raise
        except Exception as exc:  # noqa: BLE001 - a broken plugin must not break the rest
            if plugin in DEFAULT_PLUGINS:
                raise
            pm.load_report.report(plugin, f"{where} raised {one_line(exc)}; it is skipped")
            continue
        if answer is None:
            continue
        if not validate(answer):
            pm.load_report.report(plugin, f"{where} returned {answer!r}, which is not what it chooses; it is skipped")
            continue
        return answer
    return None


#: The hooks that choose (``firstresult``), and what each chooses.
CHOOSING_HOOKS = {
    "primordia_select_backend": "the backend",
    "primordia_select_splitting_scheme": "the splitting scheme",
}


def choosers(pm: pluggy.PluginManager | None = None) -> dict[str, list[tuple[str, str]]]:
    """hook name -> [(plugin, origin), ...] in the order :func:`choose` asks them (the first answer wins)."""
    pm = pm or get_plugin_manager()
    return {hook: [(impl.plugin_name, _origin(pm, impl.plugin_name)) for impl in _asking_order(pm, hook)]
            for hook in CHOOSING_HOOKS}


def _asking_order(pm, hook_name: str) -> list:
    """A ``firstresult`` hook's implementations in the order pluggy calls them (``trylast`` ones last)."""
    return list(reversed(getattr(pm.hook, hook_name).get_hookimpls()))


def ask_backend_choosers(pm: pluggy.PluginManager | None = None) -> None:
    """Ask the backend choosers for every registered backend that imports, as a run on one rank would,
    and drop the answers: a third-party chooser that raises or answers junk is reported
    (:attr:`LoadReport.broken`) now rather than at the next run.  A user error a chooser raises (an
    unknown name, say) is what a run would print; it is not a broken plugin.
    """
    from mpi4py import MPI

    from primordia.core.errors import PrimordiaError

    pm = pm or get_plugin_manager()
    for name, (entry, _) in sorted(registry("backends", pm).items()):
        if entry.availability() is not None:
            continue
        try:
            make_backend(name, MPI.COMM_SELF, pm)
        except PrimordiaError:
            continue


def make_backend(name: str, comm, pm: pluggy.PluginManager | None = None):
    """The backend ``name`` on ``comm``, as the ``primordia_select_backend`` choosers make it.

    What the backend refuses (an unknown name, one that cannot be imported, the serial skfem on several
    ranks) raises here, in one line: before a run, or runs, do any work.
    """
    from primordia.core.backend import Backend
    from primordia.core.errors import PluginError

    pm = pm or get_plugin_manager()
    entries = {entry_name: entry for entry_name, (entry, _) in registry("backends", pm).items()}
    backend = choose("primordia_select_backend", lambda answer: isinstance(answer, Backend), pm,
                     name=name, entries=entries, comm=comm)
    if backend is None:
        raise PluginError(f"no plugin chose a backend for '{name}'")
    return backend


#: The libraries whose versions a run records (:func:`software`), by the name they are imported as.
RECORDED_LIBRARIES = ("numpy", "ufl", "dolfinx", "skfem")


def software(pm: pluggy.PluginManager | None = None) -> dict:
    """What this process computes with: primordia's, Python's, PETSc's and the imported numerical libraries'
    versions, and every plugin loaded besides the built-ins with where it came from (a distribution and its
    version, or the file given by ``-p``).  A run records it (``summary.json``, its checkpoint), so that a
    result can be made again, and a restart where a plugin is missing names the one that made the run."""
    import platform

    from primordia import __version__

    pm = pm or get_plugin_manager()
    versions = {"primordia": __version__, "python": platform.python_version()}
    petsc = sys.modules.get("petsc4py.PETSc")
    if petsc is not None:
        versions["petsc"] = ".".join(str(part) for part in petsc.Sys.getVersion())
    for name in RECORDED_LIBRARIES:
        module = sys.modules.get(name)
        if module is not None and getattr(module, "__version__", None):
            versions[name] = str(module.__version__)
    plugins = {plugin: origin for plugin, origin in sorted(pm.load_report.sources.items())
               if origin != BUILT_IN and plugin not in pm.load_report.broken}
    return {**versions, "plugins": plugins}


def why_skipped(kind: str, name: str, pm: pluggy.PluginManager | None = None) -> str | None:
    """Why the piece ``name`` of ``kind`` that a plugin gives was skipped at loading (two plugins give it, or the
    contribution was junk), or None: what a config naming it is told instead of "unknown"."""
    return (pm or get_plugin_manager()).load_report.skipped.get((kind, name))


def lookup(kind: str, name: str, pm: pluggy.PluginManager | None = None):
    """The registered piece of ``kind`` called ``name``; an unknown name names the known ones."""
    pm = pm or get_plugin_manager()
    table = registry(kind, pm)
    try:
        return table[name][0]
    except KeyError:
        known = ", ".join(sorted(table)) or "none"
        label = kind.replace("_", " ") if kind in ("physics", "kinetics") else kind.replace("_", " ")[:-1]
        report = pm.load_report
        why = why_skipped(kind, name, pm)
        if why is not None:
            raise PluginError(f"{label} '{name}' was skipped: {why}") from None
        broken = "" if not report.broken else (f"; plugin{'s' if len(report.broken) > 1 else ''} skipped as broken: "
                                               f"{', '.join(sorted(report.broken))}")
        raise PluginError(f"unknown {label} '{name}' (registered: {known}{broken})") from None
