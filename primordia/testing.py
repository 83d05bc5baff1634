"""Testing a plugin against both backends: what primordia's own tests use, shipped for plugin authors.

A plugin (a kinetics, a growth law, a boundary-condition kind, a physics module...)
should run, and give the same answer, on every finite element backend.  This module
gives the three pieces that takes::

    import pytest
    from primordia.testing import BACKENDS, assert_backends_agree, registered, run_on_backends

    @pytest.fixture
    def my_plugin():
        with registered(MyPlugin()):          # in the process-wide plugin manager, for the test
            yield

    def test_my_kinetics_agrees_between_backends(my_plugin, tmp_path):
        sims = run_on_backends(lambda: Model(physics=["chemotaxis"], kinetics="mine", ...), tmp_path)
        assert_backends_agree(sims, rtol=1e-8)

and a pytest fixture, ``primordia_backend``, parametrised over :data:`BACKENDS`
(import it into your ``conftest.py``: ``from primordia.testing import primordia_backend``).

An installed plugin (entry point in the group ``primordia``) needs no
:func:`registered`; it is for plugin objects defined in a test.  A backend that
cannot be imported fails these helpers: a plugin is not tested on a backend it
was never run on.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

import numpy as np

#: The backends every plugin should be tested on.
BACKENDS = ("fenicsx", "skfem")


@contextlib.contextmanager
def registered(*plugins, name: str = "primordia.testing"):
    """Register plugin objects (modules or instances with ``@hookimpl`` methods) for the block.

    A piece of theirs whose name another plugin already has (an installed version of the plugin under test) is
    a :class:`~primordia.core.errors.PluginError` when the pieces are looked up, not a skipped piece.
    """
    from primordia.core.plugins import get_plugin_manager

    pm = get_plugin_manager()
    names = [pm.register(plugin, name=f"{name}.{index}") for index, plugin in enumerate(plugins)]
    pm.load_report.placed.update(names)  # a name an installed plugin has is an error, not the installed piece
    try:
        yield pm
    finally:
        for registered_name in names:
            pm.unregister(name=registered_name)
            pm.load_report.placed.discard(registered_name)


def run_on_backends(model_factory: Callable[[], object], out_dir: str | Path,
                    backends: Iterable[str] = BACKENDS) -> dict[str, object]:
    """Run a fresh model from ``model_factory()`` on each backend; the finished simulations by backend.

    Each run writes to ``out_dir / backend``.  A backend that cannot be imported raises
    (:class:`~primordia.core.errors.PluginError`), it is not skipped.  So does one that cannot run
    here (the serial skfem under ``mpirun``), and an unknown or repeated name: before the first
    run, which would otherwise have run to its end before the next backend refused.
    """
    from mpi4py import MPI

    from primordia.core.errors import ConfigError
    from primordia.core.plugins import make_backend

    out_dir, backends = Path(out_dir), list(backends)
    for backend in backends:
        if backends.count(backend) > 1:
            raise ConfigError(f"backend {backend!r} is named {backends.count(backend)} times: each backend runs "
                              f"once, into out_dir / backend")
        make_backend(backend, MPI.COMM_WORLD)  # what Model.run makes first: its refusal, before any run
    return {backend: model_factory().run(backend=backend, out=out_dir / backend) for backend in backends}


def assert_backends_agree(sims: Mapping[str, object], fields: Iterable[str] | None = None,
                          rtol: float = 1e-8) -> dict[str, float]:
    """Every field (or ``fields``) at the vertices agrees between the backends' runs to ``rtol``.

    The difference is relative to the largest value of the field in the first run; a
    field that is uniform in the first run fails (nothing would be compared).  So does a
    field that is not finite (NaN or inf) in any run: ``NaN > rtol`` is false, and a run
    that ended in NaN would pass; and one a run lacks or holds in another shape, each
    named as such.  Returns the differences by field, for a report.
    """
    names = list(sims)
    if len(names) < 2:
        raise AssertionError("cross-validation needs runs on at least two backends")
    values = {backend: sim.vertex_values() for backend, sim in sims.items()}
    reference = values[names[0]]
    differences = {}
    for field in fields or reference:
        expected = _field_of(values, names[0], field)
        scale = float(np.abs(expected).max())
        if not np.ptp(expected) > 0:
            raise AssertionError(f"field {field} is uniform on {names[0]}: nothing is compared")
        for other in names[1:]:
            actual = _field_of(values, other, field)
            if actual.shape != expected.shape:
                raise AssertionError(f"field {field} has values of shape {actual.shape} on {other}, "
                                     f"{expected.shape} on {names[0]}: not the same vertices")
            difference = float(np.abs(actual - expected).max()) / scale
            differences[field] = max(differences.get(field, 0.0), difference)
            if difference > rtol:
                raise AssertionError(f"field {field}: {other} differs from {names[0]} by {difference:.2e} "
                                     f"(relative), more than {rtol:g}")
    return differences


def _field_of(values: Mapping[str, Mapping], backend: str, field: str) -> np.ndarray:
    """``field``'s vertex values in the run on ``backend``, refused when it lacks the field or a value is not finite."""
    if field not in values[backend]:
        raise AssertionError(f"field {field} is not a field of the run on {backend} "
                             f"(its fields: {', '.join(sorted(values[backend]))})")
    array = np.asarray(values[backend][field], dtype=float)
    bad = int(np.count_nonzero(~np.isfinite(array)))
    if bad:
        raise AssertionError(f"field {field} is not finite on {backend} (at {bad} of its {array.size} values)")
    return array


try:
    import pytest
except ImportError:  # pytest is a test dependency; the helpers above work without it
    pytest = None

if pytest is not None:

    @pytest.fixture(params=BACKENDS)
    def primordia_backend(request) -> str:
        """Each backend's name in turn (import this fixture into your conftest.py)."""
        return request.param
