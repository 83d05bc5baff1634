"""The third-party plugin plugins/primordia-schnakenberg: found by entry point, its textbook Turing conditions.

The derived analysis (primordia.analysis.composed) knows nothing of Schnakenberg's
system: it reads the plugin's species declaration and differentiates its ``rates``.
Here it must reproduce the classical results, written out independently from

    J. D. Murray, *Mathematical Biology II: Spatial Models and Biomedical Applications*,
    3rd ed., Springer (2003), chapter 2, section 2.3 ("general conditions for
    diffusion-driven instability") applied to the Schnakenberg kinetics of section 2.2/2.4.

For u_t = gamma f(u, v) + Laplacian u, v_t = gamma g(u, v) + d Laplacian v with
f = a - u + u^2 v, g = b - u^2 v, at the steady state u_0 = a + b, v_0 = b / (a + b)^2:

    f_u = (b - a)/(a + b),  f_v = (a + b)^2,  g_u = -2b/(a + b),  g_v = -(a + b)^2;

the steady state is driven unstable by diffusion if and only if

    (i)   f_u + g_v < 0,            (ii) f_u g_v - f_v g_u > 0,
    (iii) d f_u + g_v > 0,          (iv) (d f_u + g_v)^2 - 4 d (f_u g_v - f_v g_u) > 0;

the critical diffusion ratio d_c is the root > 1 of

    d_c^2 f_u^2 + 2 (2 f_v g_u - f_u g_v) d_c + g_v^2 = 0,

at which the critical wavenumber is k_c^2 = gamma (d_c f_u + g_v) / (2 d_c), and for
d > d_c the unstable band is between the roots of d k^4 - gamma (d f_u + g_v) k^2 +
gamma^2 (f_u g_v - f_v g_u) = 0.  For a = 0.1, b = 0.9: d_c = 8.5676 (with D_u = 1).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.optimize

from primordia.analysis import linearise_model
from primordia.analysis.composed import homogeneous_steady_state
from primordia.analysis.dispersion import max_growth_of_kind
from primordia.core.meshes import rectangle
from primordia.core.plugins import get_plugin_manager, registry
from primordia.model import Model


def murray(a: float, b: float) -> dict:
    """The Jacobian entries of f, g at the steady state (without gamma), and the critical ratio d_c."""
    f_u, f_v, g_u, g_v = (b - a) / (a + b), (a + b) ** 2, -2 * b / (a + b), -(a + b) ** 2
    roots = np.roots([f_u**2, 2 * (2 * f_v * g_u - f_u * g_v), g_v**2])
    return {"f_u": f_u, "f_v": f_v, "g_u": g_u, "g_v": g_v, "det": f_u * g_v - f_v * g_u,
            "d_c": float(np.max(roots.real))}


def turing_unstable(a: float, b: float, d: float) -> bool:
    """Murray's conditions (i)-(iv)."""
    m = murray(a, b)
    return bool(m["f_u"] + m["g_v"] < 0 and m["det"] > 0 and d * m["f_u"] + m["g_v"] > 0
                and (d * m["f_u"] + m["g_v"]) ** 2 - 4 * d * m["det"] > 0)


def schnakenberg(**parameters) -> Model:
    return Model(physics=["chemotaxis"], kinetics="schnakenberg", parameters=parameters,
                 mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1, t_final=0.1)


def diffusion_driven(linear) -> bool:
    """Stable without diffusion (k = 0), a real growth rate > 0 at some k > 0: a Turing instability."""
    homogeneous = np.max(np.linalg.eigvals(linear.reaction_jacobian).real) < 0
    return bool(homogeneous and linear.fastest_mode("stationary").growth_rate > 1e-12)


def test_it_is_found_through_its_entry_point():
    piece, origin = registry("kinetics", get_plugin_manager())["schnakenberg"]
    assert origin.startswith("primordia-schnakenberg ")
    assert [s.name for s in piece.species] == ["activator", "inhibitor"]


@pytest.mark.parametrize("a, b, gamma", [(0.1, 0.9, 1.0), (0.2, 1.3, 3.0), (0.05, 0.6, 0.5)])
def test_steady_state_and_jacobian_are_murrays(a, b, gamma):
    linear = linearise_model(schnakenberg(a=a, b=b, gamma=gamma))
    assert linear.steady_state.values["activator"] == pytest.approx(a + b, rel=1e-14)
    assert linear.steady_state.values["inhibitor"] == pytest.approx(b / (a + b) ** 2, rel=1e-14)
    m = murray(a, b)
    expected = gamma * np.array([[m["f_u"], m["f_v"]], [m["g_u"], m["g_v"]]])
    np.testing.assert_allclose(linear.reaction_jacobian, expected, rtol=1e-13)


def test_the_steady_state_is_found_from_elsewhere_too():
    """Started off its rest state (a kinetics need not know it), the relaxation lands on Murray's."""
    kinetics = schnakenberg(a=0.1, b=0.9).kinetics_object
    kinetics.initial_state = lambda t0, ops: {"activator": 1.6, "inhibitor": 0.5}
    rest = homogeneous_steady_state(kinetics)
    assert rest.steps > 0 and rest.conserved == ()
    assert rest.values == pytest.approx({"activator": 1.0, "inhibitor": 0.9}, rel=1e-12)


@pytest.mark.parametrize("a, b", [(0.1, 0.9), (0.2, 1.3), (0.05, 0.6)])
def test_critical_diffusion_ratio_and_wavenumber_are_murrays(a, b):
    """d_c: where the largest real growth rate of the derived analysis crosses zero (D_u = 1, gamma = 2)."""
    m, gamma = murray(a, b), 2.0

    def onset(d):
        linear = linearise_model(schnakenberg(a=a, b=b, gamma=gamma, D_u=1.0, D_v=d))
        return linear.fastest_mode("stationary").growth_rate

    d_c = scipy.optimize.brentq(onset, 0.5 * m["d_c"], 2.0 * m["d_c"], xtol=1e-12)
    print(f"\na = {a}, b = {b}: d_c = {d_c:.8f} from the derived analysis, {m['d_c']:.8f} from Murray's formula")
    assert d_c == pytest.approx(m["d_c"], rel=1e-6)
    at_onset = linearise_model(schnakenberg(a=a, b=b, gamma=gamma, D_u=1.0, D_v=m["d_c"] * (1 + 1e-9)))
    k_c = np.sqrt(gamma * (m["d_c"] * m["f_u"] + m["g_v"]) / (2 * m["d_c"]))
    assert at_onset.fastest_mode("stationary").k_max == pytest.approx(k_c, rel=1e-3)
    assert m["d_c"] > 1.0


def test_a_0_1_b_0_9_has_the_textbook_critical_ratio():
    assert murray(0.1, 0.9)["d_c"] == pytest.approx(8.5676, abs=1e-4)


def test_unstable_band_is_between_the_roots_of_h_of_k_squared():
    a, b, gamma, d = 0.1, 0.9, 3.0, 20.0
    m = murray(a, b)
    K = np.sort(np.roots([d, -gamma * (d * m["f_u"] + m["g_v"]), gamma**2 * m["det"]]).real)
    linear = linearise_model(schnakenberg(a=a, b=b, gamma=gamma, D_u=1.0, D_v=d))
    inside = np.sqrt(np.linspace(K[0], K[1], 7)[1:-1])
    outside = np.sqrt(np.array([0.5 * K[0], 0.99 * K[0], 1.01 * K[1], 2.0 * K[1]]))
    assert np.all(max_growth_of_kind(linear.rates(inside), "stationary") > 0)
    assert np.all(max_growth_of_kind(linear.rates(outside), "any") < 0)


def test_just_past_onset_the_band_is_murrays_and_the_box_modes_in_it_grow():
    """D_v = 0.4284 with D_u = 0.05: d = 8.568, 1e-5 past d_c = 8.5676.  The band, k in [2.6040, 2.6239],
    is narrower than the k grid's steps, so no grid point grows: it was reported [nan, nan], and on
    the 20 x 20 box "no admissible mode grows", while n = (14, 9), (9, 14) (k = 2.6143) grow."""
    from primordia.analysis.domain import domain_modes

    a, b, D_u, D_v = 0.1, 0.9, 0.05, 0.4284
    m = murray(a, b)
    K = np.sort(np.roots([D_u * D_v, -(D_v * m["f_u"] + D_u * m["g_v"]), m["det"]]).real)
    linear = linearise_model(schnakenberg(a=a, b=b, D_u=D_u, D_v=D_v))
    turing = linear.fastest_mode("stationary")
    assert turing.growth_rate > 0
    np.testing.assert_allclose(turing.band, np.sqrt(K), rtol=1e-6)
    modes = domain_modes(linear.rates, (20.0, 20.0), turing.band)
    assert sorted(modes.ties(modes.fastest)) == [(9, 14), (14, 9)]
    assert np.count_nonzero(modes.unstable) == 2


def test_turing_space_is_murrays_conditions():
    """Over random (a, b, d), the derived analysis patterns exactly where Murray's (i)-(iv) hold."""
    rng = np.random.default_rng(4)
    agree = patterns = 0
    for _ in range(40):
        a, b, d = rng.uniform(0.0, 0.4), rng.uniform(0.1, 2.0), rng.uniform(1.0, 60.0)
        unstable = diffusion_driven(linearise_model(schnakenberg(a=a, b=b, D_u=1.0, D_v=d)))
        expected = turing_unstable(a, b, d)
        m = murray(a, b)
        margin = min(abs(d - m["d_c"]) / m["d_c"], abs(m["f_u"] + m["g_v"]))  # far from every boundary
        if margin > 1e-3:
            assert unstable == expected, (a, b, d)
            agree += 1
            patterns += expected
    assert agree >= 35 and 5 <= patterns <= agree - 5  # both sides of the boundary were sampled


def test_a_hopf_instability_of_the_kinetics_grows_fastest_at_k_0():
    """a = 0.05, b = 0.5: f_u + g_v = 0.516 > 0, det = 0.3025, so the well-mixed kinetics oscillate and grow at
    Re phi = (f_u + g_v) / 2 = 0.2578; with D_u = D_v diffusion only damps, so k = 0 grows fastest. It was
    reported as k_max = 0.001 (the grid's first k), wavelength 6283, "at the end of the k range searched"."""
    from primordia.analysis import cli

    a, b = 0.05, 0.5
    m = murray(a, b)
    linear = linearise_model(schnakenberg(a=a, b=b, D_u=0.05, D_v=0.05))
    mode = linear.fastest_mode()
    assert mode.k_max == 0.0 and not mode.at_edge and not mode.stationary
    assert mode.growth_rate == pytest.approx((m["f_u"] + m["g_v"]) / 2, rel=1e-12)
    assert mode.frequency == pytest.approx(np.sqrt(m["det"] - (m["f_u"] + m["g_v"]) ** 2 / 4), rel=1e-12)
    assert mode.band[0] == 0.0 and mode.band[1] == pytest.approx(np.sqrt((m["f_u"] + m["g_v"]) / 2 / 0.05), rel=1e-6)
    assert cli._mode_text(mode).startswith("k_max = 0: the well-mixed kinetics are unstable on their own")


def test_the_command_says_which_kind_of_mode_is_missing_when_the_kinetics_oscillate(tmp_path, capsys):
    """The same Hopf case from the shell: no real root anywhere was printed as "largest Re phi -inf", and the
    box's line said "no admissible mode grows" while its homogeneous mode n = (0, 0) grows, oscillating."""
    from primordia.cli import main as run

    config = Path(__file__).resolve().parents[2] / "examples" / "schnakenberg.toml"
    assert run(["stability", str(config), "--set", "parameters.a=0.05", "--set", "parameters.b=0.5",
                "--set", "parameters.D_v=0.05", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "fastest stationary (Turing) mode: none: no stationary root at any k searched" in printed
    assert "-inf" not in printed
    assert "no admissible mode grows as a stationary mode" in printed
    # and the box's say on the oscillating modes: n = (0, 0), the homogeneous one, is the fastest of them
    assert ("on the 20 x 20 box (zero-flux cosine modes) the fastest is n = (0, 0): k = 0, the homogeneous mode, "
            "growth rate 0.2578; 181 admissible modes grow") in printed


def test_the_dispersion_datasets_constant_term_has_dets_sign_and_no_spikes():
    """Scaled by the product of M's diagonal entries it spiked where one crossed zero (here the activator's,
    gamma f_u - k^2 with f_u = (b - a) / (a + b) = 0.8: at k = 0.894); scaled by the rows' norms (Hadamard's
    inequality) it lies in [-1, 1] with det's sign."""
    from primordia.analysis.dispersion import wave_vectors
    from primordia.analysis.patterning import model_dispersion_relation

    a, b, gamma = 0.1, 0.9, 1.0
    linear = linearise_model(schnakenberg(a=a, b=b, gamma=gamma, D_u=1.0, D_v=20.0))
    k = np.linspace(0.05, 8.0, 400)
    term = model_dispersion_relation(linear, k=k)["constant_term"].values
    M0 = linear.pencil(wave_vectors(k, 2))[0]
    assert np.all(np.abs(term) <= 1.0 + 1e-12)
    assert np.array_equal(np.sign(term), np.sign(np.linalg.det(M0).real))
    diagonal = np.diagonal(M0, axis1=-2, axis2=-1).real
    crossing = np.flatnonzero(np.diff(np.sign(diagonal[:, 0])))  # where the activator's entry changes sign
    assert crossing.size  # the case the old scaling spiked at
    assert np.all(np.abs(np.diff(term)) < 0.1)  # a smooth curve on this grid
