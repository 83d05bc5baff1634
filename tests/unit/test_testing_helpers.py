"""``primordia.testing.assert_backends_agree`` on states made by hand: what it must not let pass.

A backend whose run ends with NaN in a field is the failure cross-validation is there to catch: the
difference ``|nan - x|`` is NaN, ``NaN > rtol`` is false, and the helper passed, reporting a difference of 0.
"""

import numpy as np
import pytest

from primordia.testing import assert_backends_agree


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
