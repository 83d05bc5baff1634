"""The exponentially fitted (Scharfetter-Gummel / EAFE) transport operator (primordia.physics.edge_flux).

The operator is assembled through the backend interface only, so it is checked
on every backend: its sign pattern and zero column sums (hence positivity and
conservation), its reduction to the Galerkin stiffness matrix when chi = 0,
and its exact discrete equilibrium m ~ exp(chi a / D) for constant chi.
"""

from __future__ import annotations

import decimal

import numpy as np
import pytest
import scipy.sparse
import ufl

from primordia.core.mesh_data import MeshData
from primordia.core.meshes import rectangle
from primordia.core.plugins import get_plugin_manager, registry
from primordia.physics.discretisation import Discretisation
from primordia.physics.edge_flux import ExponentiallyFittedFlux, bernoulli
from primordia.physics.base import FieldSpec

BACKENDS = ["fenicsx", "skfem"]


# -- B(x) = x / (exp(x) - 1) ------------------------------------------------------------------


def reference_bernoulli(x: float) -> float:
    """B(x) in 80-digit decimal arithmetic (exact conversion of the binary x)."""
    if x == 0:
        return 1.0
    with decimal.localcontext() as context:
        context.prec = 80
        exact = decimal.Decimal(x)
        return float(exact / (exact.exp() - 1))


def test_bernoulli_at_zero_is_one():
    assert bernoulli(0.0) == 1.0
    assert bernoulli(np.array([0.0, -0.0])).tolist() == [1.0, 1.0]


@pytest.mark.parametrize("magnitude", [1e-14, 1e-10, 1e-7, 9.99e-7, 1e-6, 1.01e-6, 1e-5, 1e-3, 0.1])
def test_bernoulli_is_accurate_near_zero(magnitude):
    """x / expm1(x) near 0 (the 1e-6 where a Taylor series used to take over, and around it), to a few ulps."""
    for x in (magnitude, -magnitude):
        assert bernoulli(x) == pytest.approx(reference_bernoulli(x), rel=4e-16, abs=0), x


def test_bernoulli_is_accurate_over_many_magnitudes():
    """Random x with |x| from 1e-15 to 30, both signs, evaluated as one array (the operator's path)."""
    rng = np.random.default_rng(7)
    x = np.concatenate([sign * 10.0 ** rng.uniform(-15, 1.5, 1000) for sign in (1, -1)])
    expected = np.array([reference_bernoulli(value) for value in x])
    assert np.abs(bernoulli(x) / expected - 1).max() < 4e-16
    out = np.empty_like(x)
    assert bernoulli(x, out=out) is out and np.array_equal(out, bernoulli(x))
    with pytest.raises(ValueError, match="out must be a writeable array of shape"):
        bernoulli(x, out=np.empty((2, x.size // 2)))  # a reshape would be written to and lost


def compiled_bernoulli(x: np.ndarray) -> np.ndarray:
    """B(x) and B(-x) by the compiled loop of the operator (Pe = x: chi = x on edges from a = 0 to a = 1, D = 1)."""
    from primordia.core import compiled

    library = compiled.kernels()
    assert library is not None, compiled.status()
    x = np.ascontiguousarray(x, dtype=float)
    a, table = np.array([0.0, 1.0]), np.empty(2 * x.size)
    low, high = np.zeros(x.size, np.int64), np.ones(x.size, np.int64)
    library.primordia_edge_bernoulli(x.size, compiled.address(x), compiled.address(a), compiled.address(low, np.int64),
                                     compiled.address(high, np.int64), 1.0, compiled.address(table))
    return table[: x.size], table[x.size:]


def test_the_compiled_bernoulli_is_accurate_over_many_magnitudes():
    """libmvec's expm1 instead of numpy's: B within a few ulps of the 80-digit value, B(-x) = B(x) + x as numpy's,
    B(0) = 1, and the limits beyond overflow."""
    rng = np.random.default_rng(7)
    x = np.concatenate([sign * 10.0 ** rng.uniform(-15, 2.5, 1000) for sign in (1, -1)])
    expected = np.array([reference_bernoulli(value) for value in x])
    forward, backward = compiled_bernoulli(x)
    assert np.abs(forward / expected - 1).max() < 1e-15
    np.testing.assert_array_equal(backward, forward + x)
    with np.errstate(over="ignore"):
        forward, backward = compiled_bernoulli(np.array([0.0, -0.0, 800.0, 1e4, -800.0, -1e4]))
    np.testing.assert_array_equal(forward[:2], [1.0, 1.0])
    assert 0 <= forward[2] < 1e-300 and 0 <= forward[3] < 1e-300
    np.testing.assert_array_equal(forward[4:], [800.0, 1e4])


@pytest.mark.parametrize("magnitude", [1.0, 5.0, 20.0, 50.0, 200.0, 700.0])
def test_bernoulli_is_accurate_for_large_arguments(magnitude):
    assert bernoulli(magnitude) == pytest.approx(reference_bernoulli(magnitude), rel=1e-14, abs=0)
    assert bernoulli(-magnitude) == pytest.approx(reference_bernoulli(-magnitude), rel=1e-14, abs=0)


def test_bernoulli_beyond_overflow_is_finite_and_right():
    with np.errstate(over="ignore"):
        values = bernoulli(np.array([800.0, 1e4, -800.0, -1e4]))
    assert np.all(np.isfinite(values))
    assert values[0] >= 0 and values[1] >= 0 and values[0] < 1e-300
    np.testing.assert_array_equal(values[2:], [800.0, 1e4])


def test_bernoulli_identity_b_minus_x_is_b_x_plus_x():
    """B(-x) = B(x) + x: the upwind and downwind weights of an edge differ by the Peclet number."""
    x = np.concatenate([-np.logspace(-12, 2.5, 200), np.logspace(-12, 2.5, 200)])
    np.testing.assert_allclose(bernoulli(-x) - bernoulli(x), x, rtol=1e-12, atol=1e-15)


# -- the operator -----------------------------------------------------------------------------------


def make_backend(name: str):
    from mpi4py import MPI

    entries = {key: entry for key, (entry, _) in registry("backends").items()}
    return get_plugin_manager().hook.primordia_select_backend(name=name, entries=entries, comm=MPI.COMM_WORLD)


def discretisation(backend_name: str, mesh: MeshData) -> Discretisation:
    """A density m and an attractant f, each a P1 field of its own."""
    disc = Discretisation(make_backend(backend_name), mesh)
    for name in ("m", "f"):
        disc.add_group(name, [FieldSpec(name)], owners={name: "test"})
    return disc


def set_previous(disc, name: str, values) -> None:
    array = disc.backend.local_array(disc.previous(name))
    array[:] = values(array.size) if callable(values) else values


def random_start_of_step(disc, seed: int) -> None:
    """Random positive m^n and f^n: FGF differences give Peclet numbers up to ~100 with D = 0.05."""
    rng = np.random.default_rng(seed)
    set_previous(disc, "m", lambda n: rng.uniform(0.05, 4.0, n))
    set_previous(disc, "f", lambda n: rng.uniform(0.0, 3.0, n))


def dense(matrix) -> np.ndarray:
    indptr, columns, values = matrix.getValuesCSR()
    return scipy.sparse.csr_matrix((values, columns, indptr), shape=matrix.getSize()).toarray()


def fitted_operator(disc, diffusivity: float, sensitivity) -> np.ndarray:
    operator = ExponentiallyFittedFlux(disc, "m", "f", diffusivity=diffusivity, sensitivity=sensitivity)
    operator.update()
    return dense(operator.matrix())


def stiffness(disc) -> np.ndarray:
    space = disc.field("m").ufl_function_space()
    u, v = ufl.TrialFunction(space), ufl.TestFunction(space)
    return dense(disc.backend.assemble_matrix(ufl.inner(ufl.grad(u), ufl.grad(v)) * disc.dx))


MESHES = {
    "right": rectangle((0.0, 0.0), (2.0, 1.0), (7, 4), diagonal="right"),
    "crossed": rectangle((0.0, 0.0), (1.0, 1.0), (4, 4), diagonal="crossed"),
}


@pytest.mark.parametrize("mesh_name", list(MESHES))
@pytest.mark.parametrize("backend", BACKENDS)
def test_off_diagonals_are_non_positive_and_columns_sum_to_zero(backend, mesh_name):
    disc = discretisation(backend, MESHES[mesh_name])
    random_start_of_step(disc, seed=3)
    A = fitted_operator(disc, diffusivity=0.05, sensitivity=lambda m: 4.0 * np.exp(-m))
    off = A - np.diag(np.diag(A))
    scale = np.abs(A).max()
    assert np.all(off <= 0.0)
    assert np.all(np.diag(A) > 0.0)
    np.testing.assert_allclose(A.sum(axis=0), 0.0, atol=1e-13 * scale)  # conservation: 1^T A = 0
    assert np.abs(A.sum(axis=1)).max() > 1e-3 * scale  # rows do not: the flux is not symmetric


@pytest.mark.parametrize("backend", BACKENDS)
def test_with_the_lumped_mass_it_is_an_m_matrix(backend):
    """(M_L/dt + A)^{-1} >= 0 entrywise: a non-negative m^n gives a non-negative m^{n+1} for any dt."""
    disc = discretisation(backend, MESHES["right"])
    random_start_of_step(disc, seed=5)
    A = fitted_operator(disc, diffusivity=0.05, sensitivity=lambda m: 4.0 * np.exp(-m))
    space = disc.field("m").ufl_function_space()
    lumped = disc.backend.assemble_vector(ufl.TestFunction(space) * disc.dx_lumped).getArray().copy()
    assert lumped.sum() == pytest.approx(2.0)  # |Omega|
    for dt in (1e-3, 0.2, 1e3):
        inverse = np.linalg.inv(np.diag(lumped / dt) + A)
        assert inverse.min() >= -1e-12 * np.abs(inverse).max(), dt


@pytest.mark.parametrize("backend", BACKENDS)
def test_on_a_moving_mesh_an_update_gives_the_operator_of_the_current_metric(backend):
    """With a metric that follows the deformation (the pulled-back J C^-1 of section 4), every update
    reassembles the weights and rewrites the fitted operator's entries in place: after the metric
    changes, it equals an operator made afresh for the new metric, update after update."""
    disc = discretisation(backend, MESHES["right"])
    disc.add_group("g", [FieldSpec("g")], owners={"g": "test"})
    g = disc.field("g")
    metric = ufl.as_matrix([[1.0 + g, 0.25 * g], [0.25 * g, 1.0 + 2.0 * g]])  # anisotropic, SPD for g >= 0
    random_start_of_step(disc, seed=11)
    sensitivity = lambda m: 4.0 * np.exp(-m)  # noqa: E731
    moving = ExponentiallyFittedFlux(disc, "m", "f", diffusivity=0.05, sensitivity=sensitivity, metric=metric)
    rng = np.random.default_rng(3)
    for _ in range(3):
        values = disc.backend.local_array(g)
        values[:] = rng.uniform(0.0, 1.5, values.size)
        disc.backend.update_ghosts(g)
        moving.update()
        fresh = ExponentiallyFittedFlux(disc, "m", "f", diffusivity=0.05, sensitivity=sensitivity, metric=metric)
        fresh.update()
        expected = dense(fresh.matrix())
        np.testing.assert_allclose(dense(moving.matrix()), expected, rtol=1e-14, atol=1e-14 * np.abs(expected).max())
    assert np.abs(expected - fitted_operator(disc, 0.05, sensitivity)).max() > 1e-3 * np.abs(expected).max()


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_shifted_operator_adds_the_diagonal_and_leaves_a_itself_intact(backend):
    """``shifted(d)`` (the cell density's lumped mass added in place, for the solve) is A + diag(d);
    afterwards ``matrix()`` and ``apply`` are A again, and the next update starts from A."""
    disc = discretisation(backend, MESHES["right"])
    random_start_of_step(disc, seed=5)
    operator = ExponentiallyFittedFlux(disc, "m", "f", diffusivity=0.05, sensitivity=lambda m: 4.0 * np.exp(-m))
    operator.update()
    A = dense(operator.matrix())
    diagonal = operator.matrix().createVecLeft()
    diagonal.setArray(np.linspace(1.0, 2.0, diagonal.getLocalSize()))
    shifted = operator.shifted(diagonal)
    assert shifted is not None  # in the operator's own matrix (on any number of processes)
    np.testing.assert_allclose(dense(shifted), A + np.diag(diagonal.getArray()), rtol=1e-15, atol=1e-15)
    x, y = diagonal.duplicate(), diagonal.duplicate()
    x.setArray(np.cos(np.arange(x.getLocalSize())))
    y.zeroEntries()
    operator.apply(x, y)
    np.testing.assert_allclose(y.getArray(), A @ x.getArray(), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(dense(operator.matrix()), A, rtol=1e-15, atol=1e-15)
    operator.shifted(diagonal)
    operator.update()  # rewrites every value: no shift left
    np.testing.assert_allclose(dense(operator.matrix()), A, rtol=1e-15, atol=1e-15)


@pytest.mark.parametrize("backend", BACKENDS)
def test_reduces_to_the_galerkin_stiffness_when_chi_is_zero(backend):
    disc = discretisation(backend, MESHES["right"])
    random_start_of_step(disc, seed=9)
    diffusivity = 0.3
    A = fitted_operator(disc, diffusivity, sensitivity=lambda m: np.zeros_like(m))
    S = stiffness(disc)
    np.testing.assert_allclose(A, diffusivity * S, rtol=0, atol=1e-13 * np.abs(S).max())


@pytest.mark.parametrize("backend", BACKENDS)
def test_boltzmann_distribution_is_the_exact_discrete_equilibrium(backend):
    """For constant chi the edge flux vanishes iff m_j / m_i = exp(chi (a_j - a_i) / D)."""
    disc = discretisation(backend, MESHES["crossed"])
    rng = np.random.default_rng(13)
    chi, diffusivity = 2.0, 0.4
    attractant = rng.uniform(0.0, 1.0, disc.backend.local_array(disc.previous("f")).size)
    set_previous(disc, "f", attractant)
    set_previous(disc, "m", np.exp(chi * attractant / diffusivity))
    A = fitted_operator(disc, diffusivity, sensitivity=lambda m: np.full_like(m, chi))
    equilibrium = np.exp(chi * attractant / diffusivity)
    residual = A @ equilibrium
    assert np.abs(residual).max() < 1e-12 * np.abs(A).max() * equilibrium.max()
    # not true of a non-equilibrium density
    assert np.abs(A @ np.ones_like(equilibrium)).max() > 1e-2 * np.abs(A).max()


@pytest.mark.parametrize("backend", BACKENDS)
def test_obtuse_meshes_have_negative_edge_weights(backend, capsys):
    base = rectangle((0.0, 0.0), (1.0, 1.0), (3, 3))
    points = base.points.copy()
    interior = np.flatnonzero((points[:, 0] > 0) & (points[:, 0] < 1) & (points[:, 1] > 0) & (points[:, 1] < 1))
    points[interior[0]] += (0.15, -0.12)  # skews the triangles around one vertex past 90 degrees
    disc = discretisation(backend, MeshData(points, base.cells, base.boundaries))
    operator = ExponentiallyFittedFlux(disc, "m", "f", diffusivity=1.0, sensitivity=lambda m: m)
    assert operator.negative_weights == 3 and operator.most_negative_weight < 0
    assert capsys.readouterr().err == ""  # the module that makes the operator tells it, once a run (below)


def sheared_square(cells: int = 8, shift: float = 0.45) -> MeshData:
    """(0, 4)^2 in squares split in two, every other row of vertices moved by ``shift`` cells along x (the
    walls' aside): the diagonals face angles summing past 180 degrees, edges of negative stiffness weight."""
    base = rectangle((0.0, 0.0), (4.0, 4.0), (cells, cells))
    points = base.points.copy()
    h = 4.0 / cells
    moved = (np.rint(points[:, 1] / h).astype(int) % 2 == 1) & (points[:, 0] > 0) & (points[:, 0] < 4)
    points[moved, 0] += shift * h
    return MeshData(points, base.cells, base.boundaries)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_mesh_with_negative_edge_weights_is_told_once_and_its_negative_m_recorded_not_rejected(
        backend, tmp_path, capsys):
    """Such a mesh's fitted matrix is no M-matrix, so m may dip below 0: a run rejected that step as a broken
    promise, retried it down to dt_min and stopped (a cylinder of unstructured tetrahedra at t = 58 of 200), and
    warned again at every checkpoint and retry (12 times)."""
    import xarray as xr

    from primordia import Model

    model = Model(physics=["chemotaxis"], kinetics={"name": "painter2018", "priming_wave": False},
                  parameters={"m0": 0.75, "D_m": 0.01, "alpha": 20.0}, mesh=sheared_square(), dt=1.0, t_final=9.0,
                  physics_options={"chemotaxis": {"perturbation": 0.5, "seed": 1}}, backend=backend,
                  output={"times": [9.0], "pictures": False, "series_every": 1}, checkpoint={"every_steps": 2})
    model.run(out=tmp_path / "out")
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert warnings == ["primordia: warning: the mesh has 32 edges of negative stiffness weight (angles opposite an "
                        "inner edge summing past 180 degrees, or an obtuse angle opposite a boundary edge): the "
                        "exponentially fitted flux no longer keeps m >= 0, so a negative m is recorded (series.nc's "
                        "m_min), not rejected; a Delaunay triangulation with no obtuse angle at the boundary has none"]
    with xr.open_dataset(tmp_path / "out" / "series.nc") as series:
        assert series["m_min"].values.min() < -1e-3
        assert series["rejections"].values[-1] == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_compiled_loops_give_the_numpy_operator(backend):
    """The table by the compiled loops (:mod:`primordia.core.compiled`) and by numpy: the same operator to the
    ulps of libmvec's expm1 and exp (the sensitivity's exp goes through the compiled loop in a run), update
    after update, with a sensitivity that is an array, a scalar, or not contiguous."""
    from primordia.core.compiled import vector_exp

    disc = discretisation(backend, MESHES["right"])
    for sensitivity in (lambda m: 4.0 * vector_exp(-m), lambda m: 2.5, lambda m: np.repeat(4.0 * np.exp(-m), 2)[::2]):
        operator = ExponentiallyFittedFlux(disc, "m", "f", diffusivity=0.05, sensitivity=sensitivity)
        for seed in (3, 4):
            random_start_of_step(disc, seed=seed)
            operator._compiled = None  # decided again at this update: the loops (CI has them)
            operator.update()
            assert operator._compiled, "the compiled loops were not used"
            fast = dense(operator.matrix())
            operator._compiled = False
            operator.update()
            reference = dense(operator.matrix())
            scale = np.abs(reference).max()
            np.testing.assert_allclose(fast, reference, rtol=4e-15, atol=4e-15 * scale)
            assert np.abs(fast - reference).max() <= 8 * np.spacing(scale)


@pytest.mark.parametrize("backend", BACKENDS)
def test_on_a_moving_mesh_the_compiled_loops_follow_the_weights(backend):
    """With a metric, every update reassembles the weights: the compiled loops read the new ones, as the
    entry matrix of the numpy branch does."""
    disc = discretisation(backend, MESHES["right"])
    disc.add_group("g", [FieldSpec("g")], owners={"g": "test"})
    g = disc.field("g")
    metric = ufl.as_matrix([[1.0 + g, 0.25 * g], [0.25 * g, 1.0 + 2.0 * g]])
    random_start_of_step(disc, seed=11)
    operators = [ExponentiallyFittedFlux(disc, "m", "f", diffusivity=0.05, sensitivity=lambda m: 4.0 * np.exp(-m),
                                         metric=metric) for _ in range(2)]
    operators[1]._compiled = False
    rng = np.random.default_rng(5)
    for _ in range(3):
        values = disc.backend.local_array(g)
        values[:] = rng.uniform(0.0, 1.5, values.size)
        disc.backend.update_ghosts(g)
        for operator in operators:
            operator.update()
        assert operators[0]._compiled
        fast, reference = (dense(operator.matrix()) for operator in operators)
        scale = np.abs(reference).max()
        np.testing.assert_allclose(fast, reference, rtol=4e-15, atol=4e-15 * scale)
