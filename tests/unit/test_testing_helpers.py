"""``primordia.testing``'s cross-validation helpers: what they must not let pass, and when they refuse.

A backend whose run ends with NaN in a field is the failure cross-validation is there to catch: the
difference ``|nan - x|`` is NaN, ``NaN > rtol`` is false, and ``assert_backends_agree`` passed, reporting a
difference of 0.  ``run_on_backends`` ran each backend in turn, so one that could not run (the serial skfem
under ``mpirun``, an unknown name) refused only after the runs before it had run to their end.
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from primordia.core.errors import ConfigError, PluginError
from primordia.testing import assert_backends_agree, run_on_backends

REPOSITORY = Path(__file__).resolve().parents[2]


class Finished:
    """Stands for a finished Simulation: the helper reads its vertex values only."""

    def __init__(self, **fields):
        self.fields = {name: np.asarray(values, dtype=float) for name, values in fields.items()}

    def vertex_values(self):
        return self.fields


def test_runs_that_agree_pass_and_report_their_differences():
    differences = assert_backends_agree({"fenicsx": Finished(m=[0.0, 1.0, 2.0]),
                                         "skfem": Finished(m=[0.0, 1.0, 2.0 + 1e-12])})
    assert differences == {"m": pytest.approx(5e-13)}


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_field_not_finite_on_the_other_backend_fails(bad):
    sims = {"fenicsx": Finished(m=[0.0, 1.0, 2.0]), "skfem": Finished(m=[0.0, bad, 2.0])}
    with pytest.raises(AssertionError, match=r"field m is not finite on skfem \(at 1 of its 3 values\)"):
        assert_backends_agree(sims)


def test_a_field_not_finite_on_the_first_backend_is_said_so_not_uniform():
    sims = {"fenicsx": Finished(m=[0.0, np.nan, 2.0]), "skfem": Finished(m=[0.0, 1.0, 2.0])}
    with pytest.raises(AssertionError, match=r"field m is not finite on fenicsx \(at 1 of its 3 values\)"):
        assert_backends_agree(sims)


def test_a_field_one_run_lacks_is_named_with_the_run():
    sims = {"fenicsx": Finished(m=[0.0, 1.0], e=[1.0, 2.0]), "skfem": Finished(m=[0.0, 1.0])}
    with pytest.raises(AssertionError, match=r"field e is not a field of the run on skfem \(its fields: m\)"):
        assert_backends_agree(sims)
    with pytest.raises(AssertionError, match=r"field x is not a field of the run on fenicsx \(its fields: e, m\)"):
        assert_backends_agree(sims, fields=["x"])


def test_values_of_another_shape_are_named_not_broadcast():
    sims = {"fenicsx": Finished(m=[0.0, 1.0, 2.0]), "skfem": Finished(m=[0.0, 1.0])}
    with pytest.raises(AssertionError, match=r"field m has values of shape \(2,\) on skfem, \(3,\) on fenicsx"):
        assert_backends_agree(sims)


def _never_built():
    raise AssertionError("a model was built: a run was started before the backends were checked")


def test_an_unknown_backend_is_refused_before_any_run(tmp_path):
    with pytest.raises(PluginError, match=r"^unknown backend 'nope' \(registered: fenicsx, skfem\)$"):
        run_on_backends(_never_built, tmp_path, backends=["skfem", "nope"])
    assert not any(tmp_path.iterdir())


def test_a_backend_named_twice_is_refused_before_any_run(tmp_path):
    with pytest.raises(ConfigError, match=r"^backend 'skfem' is named 2 times: each backend runs once"):
        run_on_backends(_never_built, tmp_path, backends=["skfem", "fenicsx", "skfem"])
    assert not any(tmp_path.iterdir())


RUN_UNDER_MPIRUN = """
import sys
from primordia.core.errors import PrimordiaError
from primordia.testing import run_on_backends

def model():
    sys.stdout.write("a model was built\\n")
    raise SystemExit(1)

try:
    run_on_backends(model, sys.argv[1])
except PrimordiaError as error:
    sys.stdout.write(f"{error}\\n")
"""


@pytest.mark.mpi
def test_skfem_under_mpirun_is_refused_before_the_fenicsx_run(tmp_path):
    command = ["mpirun", "-n", "2", "--oversubscribe", sys.executable, "-c", RUN_UNDER_MPIRUN, str(tmp_path / "out")]
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    result = subprocess.run(command, capture_output=True, text=True, timeout=300, env=env, cwd=REPOSITORY)
    assert result.returncode == 0, result.stderr
    assert result.stdout.count("the skfem backend is serial: run it without mpirun") == 2, result.stdout
    assert "a model was built" not in result.stdout
