"""Finite-strain growth (seed section 4) against closed-form answers, in 2D and 3D, on both backends.

Each case is homogeneous, so the P2-P1-P1 discretisation must reproduce it to round-off
(Newton is run to 1e-13, with a direct solve): u linear in X, psi and p constant.  With F = F_e F_g (4.5), J_e = 1 (4.12c),
P = J (mu B_e - (psi + alpha_BW p) I) F^-T ((4.11) plus the fluid stress), and Cauchy stress
sigma = mu B_e - (psi + alpha_BW p) I when J_e = 1:

1. **Free growth**, F_g = g I, rollers on the faces X_1 = 0, X_2 = 0 (and X_3 = 0), the rest free,
   no fluid source: F = F_g, so u = (g - 1) X, J = g^d, B_e = I, and sigma = 0 gives psi = mu,
   P = 0; nothing changes in time, so p = 0.
2. **A bar confined in X_1** (rollers on both X_1 faces, and on X_2 = 0 [, X_3 = 0]), F_g = g I:
   F = diag(1, l, ..), J = l^(d-1) = g^d (J_e = 1) gives the lateral stretch l = g^(d/(d-1)):
   l = g^2 in 2D, g^(3/2) in 3D.  F_e = diag(1/g, l/g, ..), B_e = diag(1/g^2, l^2/g^2, ..), and the
   free lateral faces (sigma_22 = 0) give psi = mu l^2/g^2 (mu g^2 in 2D, mu g in 3D); the axial
   stress sigma_11 = mu (1/g^2 - l^2/g^2) and P_11 = J sigma_11: mu (1 - g^4) in 2D, mu (g - g^4) in 3D.
3. **Growth with a fluid source**, F_g = (1 + r t) I from F_g(0) = I, no flux, no traction, rho = 0:
   F = F_g(t), and (4.12b) with Grad p = 0 is d/dt (C_0 p + alpha_BW (tr C - d)) = ell with
   ell = ell_0 sum_i d gamma_i/dt = ell_0 d r constant.  Backward Euler telescopes, so
   p(t) = (ell t - alpha_BW (tr C - d)) / C_0 at every step, for every dt; traction-free
   faces give psi = mu - alpha_BW p.
4. **An inflow** Q through one face of a freely grown tissue: p starts at 0 and int p dX grows like Q t.
"""

from __future__ import annotations

import numpy as np
import pytest
import ufl

import growth_test_laws
from primordia.core.mesh_data import MeshData
from primordia.core.meshes import box, rectangle
from primordia.coupling.orchestrator import Simulation
from primordia.model import Model

BACKENDS = ("fenicsx", "skfem")
MU = 4.0
TIGHT = {"snes_rtol": 1e-13, "snes_atol": 1e-13}
SOLVERS = {"poroelastic_growth": TIGHT, "poroelastic_growth_initial": TIGHT}


@pytest.fixture(autouse=True)
def test_laws():
    with growth_test_laws.registered():
        yield


def rollers(*boundaries):
    return [{"boundary": b, "type": "normal_displacement"} for b in boundaries]


def mesh(dimension):
    if dimension == 2:
        return rectangle((0.0, 0.0), (2.0, 1.0), (3, 2))
    return box((0.0, 0.0, 0.0), (2.0, 1.0, 1.0), (2, 1, 1))


def distorted(dimension, cells):
    """The mesh of ``mesh(dimension)`` at ``cells`` boxes a side, its interior vertices moved by up to 0.3 h."""
    given = rectangle((0.0, 0.0), (2.0, 1.0), cells) if dimension == 2 else box((0.0,) * 3, (2.0, 1.0, 1.0), cells)
    points = given.points.copy()
    inside = np.all((points > 1e-12) & (points < given.points.max(axis=0) - 1e-12), axis=1)
    h = given.points.max(axis=0) / np.array(cells)
    points[inside] += 0.3 * h * np.random.default_rng(1).uniform(-1.0, 1.0, (inside.sum(), dimension))
    return MeshData(points, given.cells, given.boundaries)


def simulation(backend, dimension, law, parameters, boundary, tmp_path, dt=0.1, steps=2, mesh_data=None,
               solver=SOLVERS, **options):
    model = Model(physics=["poroelastic_growth"], growth_law=law, parameters=parameters,
                  mesh=mesh(dimension) if mesh_data is None else mesh_data, dt=dt, t_final=steps * dt, solver=solver,
                  physics_options={"poroelastic_growth": {"boundary": boundary, "preconditioner": "lu", **options}},
                  output={"pictures": False, "series_every": 10**6})
    return Simulation(model, backend=backend, out_dir=tmp_path / backend).setup()


def first_piola(sim):
    disc = sim.disc
    F = ufl.Identity(disc.gdim) + ufl.grad(disc.field("u"))
    physics = sim.model.physics_objects[0]
    from primordia.physics.poroelastic_growth import elastic_stress, fluid_stress

    return (elastic_stress(F, physics.growth_tensor(), disc.field("psi"), MU)
            + fluid_stress(F, disc.field("p"), sim.model.parameters["alpha_BW"]))


def piola_range(sim, i, j):
    return sim.backend.extrema(first_piola(sim)[i, j], sim.disc.mesh)


def assert_close(actual, expected, what, tolerance=1e-10):
    actual, expected = np.asarray(actual, float), np.asarray(expected, float)
    scale = max(1.0, float(np.abs(expected).max()))
    assert np.abs(actual - expected).max() <= tolerance * scale, f"{what}: {actual} != {expected}"


@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("backend", BACKENDS)
def test_free_growth_is_stress_free(backend, dimension, tmp_path):
    g = 1.2
    faces = ("left", "bottom", "front")[:dimension]
    sim = simulation(backend, dimension, "test_uniform", {"g": g}, rollers(*faces), tmp_path)
    sim.run()
    values = sim.vertex_values()
    X = sim.mesh_data.points
    assert_close(values["u"], (g - 1.0) * X, "u = (g - 1) X")
    assert_close(values["psi"], MU, "psi = mu")
    assert_close(values["p"], 0.0, "p = 0")
    diagnostics = sim.diagnostic_values()
    assert_close([diagnostics["J_min"], diagnostics["J_max"]], g**dimension, "J = g^d")
    assert_close(diagnostics["current_volume"], g**dimension * 2.0, "current area/volume = g^d |Omega_0|")
    for i in range(dimension):
        for j in range(dimension):
            assert_close(piola_range(sim, i, j), 0.0, f"P_{i}{j} = 0")


@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("backend", BACKENDS)
def test_a_bar_confined_in_x1_stretches_laterally(backend, dimension, tmp_path):
    g = 1.1
    lateral = g ** (dimension / (dimension - 1.0))
    faces = ("left", "right", "bottom", "front")[:dimension + 1]
    sim = simulation(backend, dimension, "test_uniform", {"g": g}, rollers(*faces), tmp_path)
    sim.run()
    values = sim.vertex_values()
    X = sim.mesh_data.points
    expected_u = np.zeros_like(X)
    expected_u[:, 1:] = (lateral - 1.0) * X[:, 1:]
    assert_close(values["u"], expected_u, f"u = (0, (l - 1) X_2, ..) with l = g^{dimension / (dimension - 1):g}")
    psi = MU * lateral**2 / g**2
    assert_close(values["psi"], psi, "psi = mu l^2 / g^2")
    assert_close(piola_range(sim, 0, 0), MU * g**dimension * (1.0 / g**2 - lateral**2 / g**2), "P_11")
    for i, j in [(1, 1), (0, 1), (1, 0)] + ([(2, 2)] if dimension == 3 else []):
        assert_close(piola_range(sim, i, j), 0.0, f"P_{i}{j} = 0")


@pytest.mark.parametrize("dt", [0.1, 0.5])
@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("backend", BACKENDS)
def test_growth_with_a_fluid_source_is_exact_for_every_dt(backend, dimension, dt, tmp_path):
    r, ell_0, alpha, C_0 = 0.1, 0.02, 0.1, 1e-3
    faces = ("left", "bottom", "front")[:dimension]
    sim = simulation(backend, dimension, "test_linear", {"r": r, "ell_0": ell_0, "alpha_BW": alpha, "C_0": C_0,
                                                        "rho": 0.0}, rollers(*faces), tmp_path, dt=dt, steps=3)
    ell = ell_0 * dimension * r
    X = sim.mesh_data.points
    while sim.step_index < sim.model.num_steps:
        sim.step()
        t = sim.time
        stretch = 1.0 + r * t
        p = (ell * t - alpha * dimension * (stretch**2 - 1.0)) / C_0
        values = sim.vertex_values()
        assert_close(values["u"], (stretch - 1.0) * X, f"F = F_g(t) at t = {t:g}")
        assert_close(values["p"], p, f"p(t) = (ell t - alpha_BW (tr C - d)) / C_0 at t = {t:g}")
        assert_close(values["psi"], MU - alpha * p, f"psi = mu - alpha_BW p at t = {t:g}")
    assert abs(p) > 1.0  # the case is not trivial: the source and the storage both matter


def rotation(angle, dimension):
    """A rotation by ``angle`` about X_3 (in 3D after one by 0.4 * sign(angle) about X_1; none at 0)."""
    c, s = np.cos(angle), np.sin(angle)
    planar = np.array([[c, -s], [s, c]])
    if dimension == 2:
        return planar
    tip = 0.4 * np.sign(angle)
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(tip), -np.sin(tip)], [0.0, np.sin(tip), np.cos(tip)]])
    return np.block([[planar, np.zeros((2, 1))], [np.zeros((1, 2)), np.ones((1, 1))]]) @ tilt


@pytest.mark.parametrize("superposed", [0.0, 0.6], ids=["", "rotated"])
@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("backend", BACKENDS)
def test_a_patch_of_distorted_cells_takes_the_homogeneous_stress(backend, dimension, superposed, tmp_path):
    """u = t (A - I) X on the faces X_i = 0, t times their nominal traction P e_i on the faces opposite, F_g = g I
    with g^d = det A, rho = 0: at t = 1, F = A, J_e = 1, and the Cauchy stress mu A A^T / g^2 - psi_0 I with
    psi_0 as chosen, whatever the cells ((4.11), P = J sigma A^-T), with psi + alpha_BW p = psi_0: at every vertex,
    and every cell's P at its vertices.  With a rigid rotation Q by 34 degrees superposed (A -> Q A, so
    P -> Q P: objectivity), the same psi and J.  The values start from 0: the initial state's continuation
    ramps the growth, not the boundary values, and from u = 0 the rotated values at once made Newton fail
    (README, "Initial state")."""
    A = np.array([[1.3, 0.2, 0.05], [0.1, 1.1, -0.1], [0.0, 0.15, 1.2]])[:dimension, :dimension]
    J, psi, alpha = np.linalg.det(A), 2.5, 0.1
    g = J ** (1.0 / dimension)
    P = J * (MU * A @ A.T / g**2 - psi * np.eye(dimension)) @ np.linalg.inv(A).T
    Q = rotation(superposed, dimension)
    A, P = Q @ A, Q @ P
    displacement = [f"t * ({' + '.join(f'{A[i, j] - (i == j)!r} * x[{j}]' for j in range(dimension))})"
                    for i in range(dimension)]
    boundary = [{"boundary": face, "type": "displacement", "value": displacement}
                for face in ("left", "bottom", "front")[:dimension]]
    boundary += [{"boundary": face, "type": "traction", "value": [f"t * {float(v)!r}" for v in P[:, axis]]}
                 for axis, face in enumerate(("right", "top", "back")[:dimension])]
    sim = simulation(backend, dimension, "test_uniform", {"g": g, "rho": 0.0, "alpha_BW": alpha}, boundary, tmp_path,
                     dt=0.25, steps=4, mesh_data=distorted(dimension, (6, 4) if dimension == 2 else (3, 2, 2)),
                     solver={name: {"snes_rtol": 1e-12, "snes_atol": 1e-10} for name in SOLVERS})
    sim.run()
    values = sim.vertex_values()
    assert_close(values["u"], sim.mesh_data.points @ (A - np.eye(dimension)).T, "u = (A - I) X")
    assert_close(values["psi"] + alpha * values["p"], psi, "psi + alpha_BW p = psi_0", tolerance=1e-9)
    diagnostics = sim.diagnostic_values()
    assert_close([diagnostics["J_min"], diagnostics["J_max"]], J, "J = det A")
    assert_close([diagnostics["J_e_minus_1_min"], diagnostics["J_e_minus_1_max"]], 0.0, "J_e = 1")
    for i in range(dimension):
        for j in range(dimension):
            assert_close(piola_range(sim, i, j), P[i, j], f"P_{i}{j}", tolerance=1e-9)


@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("backend", BACKENDS)
def test_a_rotated_tissue_grows_into_the_rotated_answer(backend, dimension, tmp_path):
    """No direction is preferred: a clamped bar with anisotropic growth along turned directions k_i, springs on
    its far end (4.16a) and a fluid at work, then the same with its mesh (its reference configuration) and k_i
    rotated by Q.  F -> Q F Q^T: the stresses of (4.11), tr C, J C^-1 and J F^-T u are invariant or turn with Q,
    so u -> Q u and psi, p, J, J_e are unchanged (to round-off: the two runs take the same Newton steps)."""
    Q, frame = rotation(0.7, dimension), rotation(0.5, dimension)
    given = distorted(dimension, (8, 4) if dimension == 2 else (4, 2, 2))
    runs = {}
    for name, points, directions in (("given", given.points, frame), ("rotated", given.points @ Q.T, frame @ Q.T)):
        sim = simulation(backend, dimension, {"name": "test_anisotropic", "directions": directions.tolist()},
                         {"ell_0": 0.02, "C_0": 1e-3, "kappa": 1.0},
                         [{"boundary": "left", "type": "clamped"},
                          {"boundary": "right", "type": "robin", "value": 3.0}],
                         tmp_path / name, mesh_data=MeshData(points, given.cells, given.boundaries),
                         solver={"poroelastic_growth": {"snes_rtol": 1e-12, "snes_atol": 1e-11},
                                 "poroelastic_growth_initial": {"snes_rtol": 1e-12, "snes_atol": 1e-11}})
        sim.run()
        runs[name] = sim.vertex_values(), sim.diagnostic_values()
    (given_values, given_diagnostics), (values, diagnostics) = runs["given"], runs["rotated"]
    assert np.abs(given_values["u"]).max() > 0.2 and np.ptp(given_values["psi"]) > 1.0  # not homogeneous
    assert_close(values["u"], given_values["u"] @ Q.T, "u -> Q u")
    for name in ("psi", "p"):
        assert_close(values[name], given_values[name], name)
    for name, value in given_diagnostics.items():
        assert_close(diagnostics[name], value, name)


@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("backend", BACKENDS)
def test_an_inflow_fills_the_tissue_from_p_0(backend, dimension, tmp_path):
    """Free growth F_g = g I with an inflow Q through the face X_1 = 0 (``fluid_flux``): p starts at 0 ((2.6)), and
    (4.12b) times J tested with q = 1 is J C_0 d/dt int p dX = Q |Gamma|, so int p dX = Q |Gamma| t / (g^d C_0) at
    every step (the solid stays stress free: psi = mu - alpha_BW p).  The initial static solve once added the
    flux's boundary term to p = 0: p(0) was Q on the face, int p dX = Q |Gamma| ever after."""
    g, inflow, C_0, alpha = 1.2, 1e-3, 1e-3, 0.1
    faces = ("left", "bottom", "front")[:dimension]
    boundary = rollers(*faces) + [{"boundary": "left", "type": "fluid_flux", "value": inflow}]
    sim = simulation(backend, dimension, "test_uniform", {"g": g, "C_0": C_0, "alpha_BW": alpha}, boundary,
                     tmp_path, dt=0.5, steps=2)
    face = 1.0  # |Gamma|: the face X_1 = 0 of (0, 2) x (0, 1) [x (0, 1)]
    amount = sim.disc.field("p") * sim.model.physics_objects[0].dx
    assert_close(sim.vertex_values()["p"], 0.0, "p(0) = 0")
    while sim.step_index < sim.model.num_steps:
        sim.step()
        expected = inflow * face * sim.time / (g**dimension * C_0)
        assert_close(sim.backend.assemble_scalar(amount), expected, f"int p dX at t = {sim.time:g}")
    values = sim.vertex_values()
    assert_close(values["psi"] + alpha * values["p"], MU, "psi + alpha_BW p = mu")


@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("backend", BACKENDS)
def test_the_run_starts_moving_with_the_growth(backend, dimension, tmp_path):
    """The initial velocity follows the growth (the linearised static equilibrium's secant over the first
    step): for F_g = (1 + r t) I on rollers it is u_t = r X up to O(r dt), not the seed's u_t(0) = 0,
    which would have to be accelerated to the growth's rate at once."""
    r, dt = 0.1, 0.5
    faces = ("left", "bottom", "front")[:dimension]
    sim = simulation(backend, dimension, "test_linear", {"r": r}, rollers(*faces), tmp_path, dt=dt)
    velocity = sim.backend.vertex_values(sim.disc.rate_function("u"), 0)
    X = sim.mesh_data.points
    np.testing.assert_allclose(velocity, r * X, rtol=0, atol=2 * r * dt * r * np.abs(X).max())
    assert np.abs(velocity - r * X).max() < 0.1 * np.abs(r * X).max()
