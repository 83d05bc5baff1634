"""A third party's physics module, coupling and splitting scheme written from docs/plugins.md alone
(:data:`plugin_sources.GUIDANCE`), checked against what can be computed without primordia.

The cells secrete a cue g (dg/dt = D_g lap g + s_g m - k_g g) and climb it; the ``palindromic`` scheme takes
every module over dt/2 forwards, then over dt/2 backwards.  What the suite had no test of: a plugin's field
through its entry point on 2 ranks and across a restart, a scheme of half steps, and a coupling's Fourier symbol
in another module's row.
"""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest
import scipy.io

from primordia import Model
from primordia.analysis.composed import linearise_model
from primordia.core.meshes import rectangle
from primordia.testing import registered

from plugin_sources import GUIDANCE
from run_control import command, environment

M0, S_G, K_G, G0, DT = 0.75, 1.3, 0.4, 0.2, 0.2


@pytest.fixture
def guidance():
    module = types.ModuleType("qa_guidance")
    exec(compile(GUIDANCE, "plugin_sources.GUIDANCE", "exec"), module.__dict__)
    sys.modules[module.__name__] = module
    try:
        with registered(module):
            yield module
    finally:
        del sys.modules[module.__name__]


def _uniform(scheme):
    """No perturbation and no priming wave: m = m0 everywhere for ever, and g the same at every vertex."""
    return Model(physics=["chemotaxis", "guidance_cue", "cue_chemotaxis"],
                 kinetics={"name": "painter2018", "priming_wave": False},
                 parameters={"m0": M0, "D_m": 0.03, "s_g": S_G, "k_g": K_G},
                 mesh=rectangle((0, 0), (4, 4), (4, 4)), dt=DT, t_final=2.0,
                 physics_options={"chemotaxis": {"perturbation": 0.0}, "guidance_cue": {"initial_value": G0}},
                 coupling={"scheme": scheme}, output={"pictures": False})


@pytest.mark.parametrize("backend", ["fenicsx", "skfem"])
@pytest.mark.parametrize("scheme, sub_steps", [("sequential", 1), ("palindromic", 2)])
def test_a_uniform_cue_takes_the_backward_euler_steps_of_its_ode(guidance, backend, scheme, sub_steps, tmp_path):
    """g^{n+1} = (g^n + h s_g m0) / (1 + h k_g) with h = dt / sub_steps: to round-off at every vertex (measured
    4e-15 to 1e-14); the two schemes' answers differ by 0.015, so neither passes for the other."""
    values = _uniform(scheme).run(backend=backend, out=tmp_path).vertex_values()
    rest, h, steps = S_G * M0 / K_G, DT / sub_steps, round(2.0 / DT) * sub_steps
    assert np.abs(values["g"] - (rest + (G0 - rest) * (1 + h * K_G) ** -steps)).max() < 1e-12
    assert np.abs(values["m"] - M0).max() < 1e-13


@pytest.mark.parametrize("backend", ["fenicsx", "skfem"])
def test_the_cells_climbing_a_cue_that_starts_uniform_keep_their_number(guidance, backend, tmp_path):
    """Every term of m's balance law is a divergence, so sum M_L m stays to round-off (measured 4e-14 of 75).
    m's Jacobian, diagonal at the first step (g uniform, no climbing yet), was taken as diagonal for good: the
    tangent lost the climbing term and the cells drifted by 9.5e-5 in 6 steps (both backends)."""
    model = Model(physics=["chemotaxis", "guidance_cue", "cue_chemotaxis"],
                  parameters={"m0": M0, "D_m": 0.03, "k_g": K_G}, mesh=rectangle((0, 0), (10, 10), (8, 8)),
                  dt=DT, t_final=1.2, physics_options={"guidance_cue": {"initial_value": G0}},
                  output={"pictures": False, "series_every": 1})
    model.run(backend=backend, out=tmp_path)
    cells = _series(tmp_path)["m_integral"]
    assert np.abs(cells - cells[0]).max() < 1e-12 * cells[0]


def _series(out):
    with scipy.io.netcdf_file(out / "series.nc", "r", mmap=False) as series:
        return {name: np.array(variable.data) for name, variable in series.variables.items()}


def test_the_installed_plugin_runs_on_two_ranks_and_restarts_as_it_ran_on_skfem(plugin_distribution, tmp_path):
    """Through its entry point, from TOML: fenicsx to t = 0.6 in serial, restarted on 2 ranks to t = 1.2, ends
    where one skfem run does (measured: 3e-15 relative in every field's integral, minimum and maximum)."""
    import subprocess

    env = environment(base=plugin_distribution("qa-guidance", "0.1", {"qa_guidance": GUIDANCE},
                                               {"guidance": "qa_guidance"}))
    config = tmp_path / "guided.toml"
    config.write_text('[model]\nphysics = ["chemotaxis", "guidance_cue", "cue_chemotaxis"]\n'
                      '[kinetics]\nname = "painter2018"\n[physics.guidance_cue]\ninitial_value = 0.2\n'
                      '[parameters]\nm0 = 0.75\nD_m = 0.03\nk_g = 0.4\n[coupling]\nscheme = "palindromic"\n'
                      '[mesh]\ntype = "rectangle"\nlower = [0.0, 0.0]\nupper = [10.0, 10.0]\ncells = [8, 8]\n'
                      '[time]\ndt = 0.2\nt_final = 1.2\n[output]\npictures = false\nseries_every = 1\n')

    def run(*args, ranks=1):
        done = subprocess.run(command("run", *args, "--no-progress", ranks=ranks), env=env, capture_output=True,
                              text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]

    run(config, "--backend", "skfem", "--out", tmp_path / "skfem")
    run(config, "--backend", "fenicsx", "--out", tmp_path / "fenicsx", "--set", "time.t_final=0.6")
    run("--restart", tmp_path / "fenicsx", "--set", "time.t_final=1.2", ranks=2)
    restarted, reference = _series(tmp_path / "fenicsx"), _series(tmp_path / "skfem")
    assert restarted["time"][-1] == pytest.approx(1.2) and len(restarted["time"]) == len(reference["time"])
    assert reference["g_max"][-1] > 1.01 * reference["g_min"][-1]  # the cells moved: a pattern to compare
    for name in reference:
        if name.startswith(("m_", "f_", "g_")) and name.endswith(("_integral", "_min", "_max")):
            assert restarted[name][-1] == pytest.approx(reference[name][-1], rel=1e-10), name


def test_the_cells_climbing_the_cue_have_the_roots_of_the_m_g_block(guidance):
    """Without FGF chemotaxis (alpha = 0) m and g read nothing else: phi(k) is the larger eigenvalue of
    [[-D_m K, chi_g m0 K], [s_g, -(D_g K + k_g)]] (K = k^2) wherever it leads (measured agreement 1e-15)."""
    model = Model(physics=["chemotaxis", "guidance_cue", "cue_chemotaxis"],
                  parameters={"m0": M0, "D_m": 0.03, "alpha": 0.0, "s_g": S_G, "k_g": K_G},
                  mesh=rectangle((0, 0), (1, 1), (2, 2)), dt=0.1, t_final=0.1)
    k = np.array([0.0, 0.5, 1.0, 2.0, 4.0])
    rates = linearise_model(model).rates(k)
    for at_k, wavenumber in zip(rates, k):
        K = wavenumber**2
        block = np.array([[-0.03 * K, 0.5 * M0 * K], [S_G, -(0.05 * K + K_G)]])
        expected = np.linalg.eigvals(block).real.max()
        assert np.nanmax(at_k.real) == pytest.approx(expected, rel=1e-9, abs=1e-12)
