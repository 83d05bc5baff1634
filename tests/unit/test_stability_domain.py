"""The modes a box admits (primordia.analysis.domain): cos(n_i pi x_i / L_i), k = pi |n / L|.

The enumeration is checked against a plain double loop over (n_1, n_2), the classic
domain-size threshold (no mode grows while pi / L lies above the unstable band), and
the command's line and NetCDF variables for example 1a's 20 x 20 square.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from primordia.analysis.composed import linearise_seed
from primordia.analysis.domain import box_lengths, domain_modes, parse_lengths
from primordia.analysis.dispersion import max_growth_of_kind
from primordia.cli import main as run
from primordia.core.errors import ConfigError
from primordia.core.meshes import rectangle
from primordia.physics.seed_parameters import seed_parameters

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def chemistry():
    """Example 1a's analysis: the seed's chemistry alone, m0 = 0.75, D_m = 0.03 (band k in (0, 5.44])."""
    return linearise_seed(seed_parameters(m0=0.75, D_m=0.03), chemistry_only=True)


def test_the_modes_are_every_n_with_k_in_the_band_and_their_rates_those_of_a_plain_loop(chemistry):
    lengths = (6.0, 4.0)
    turing = chemistry.fastest_mode("stationary")
    modes = domain_modes(chemistry.rates, lengths, turing.band)
    expected = {}
    for n in itertools.product(range(12), range(12)):
        k = np.pi * np.hypot(n[0] / lengths[0], n[1] / lengths[1])
        if k <= turing.band[1]:
            expected[n] = (k, float(max_growth_of_kind(chemistry.rates(np.array([k])), "stationary")[0]))
    found = {tuple(n): (k, rate) for n, k, rate in zip(modes.indices.tolist(), modes.k, modes.growth)}
    assert found.keys() == expected.keys()
    for n, (k, rate) in expected.items():
        assert found[n][0] == pytest.approx(k, rel=1e-14) and found[n][1] == pytest.approx(rate, rel=1e-10)
    best = max(expected, key=lambda n: expected[n][1])
    assert expected[tuple(modes.indices[modes.fastest])][1] == expected[best][1]


def test_a_box_shorter_than_the_band_s_shortest_half_wavelength_forms_no_pattern(chemistry):
    """The domain-size threshold: the band is k in (0, k_hi] (m is conserved, so long waves grow too),
    and a box's first mode, n = (1, 0), has k = pi / L_1: no mode grows while L_1 < pi / k_hi (the thin
    side's modes, k >= pi / 0.05, are far outside the band)."""
    turing = chemistry.fastest_mode("stationary")
    threshold = np.pi / turing.band[1]
    short = domain_modes(chemistry.rates, (0.99 * threshold, 0.05), turing.band)
    assert not np.any(short.unstable) and "no admissible mode grows" in short.describe()
    long = domain_modes(chemistry.rates, (1.01 * threshold, 0.05), turing.band)
    assert [tuple(n) for n in long.indices[long.unstable]] == [(1, 0)]
    assert long.growth[long.fastest] == pytest.approx(
        max_growth_of_kind(chemistry.rates(np.array([np.pi / (1.01 * threshold)])), "stationary")[0], rel=1e-12)


def test_a_box_mesh_gives_its_lengths_and_others_none():
    assert box_lengths(rectangle((0, 0), (20, 10), (4, 2))) == (20.0, 10.0)
    square = rectangle((0, 0), (1, 1), (2, 2))
    square.points[4] += 0.1  # the centre vertex moves: still the square, its cells still fill it
    assert box_lengths(square) == (1.0, 1.0)
    corner = rectangle((0, 0), (1, 1), (2, 2))
    corner.points[np.argmax(corner.points.sum(axis=1))] = (0.8, 0.8)  # the far corner pulled in: no box
    assert box_lengths(corner) is None


@pytest.mark.parametrize("text, d, message", [("3,x", 2, "expects the box's side lengths"),
                                               ("3,3,3", 2, "3 side lengths for d = 2"),
                                               ("3,-1", 2, "positive and finite"), ("3,inf", 2, "positive")])
def test_a_bad_domain_is_one_line(text, d, message):
    with pytest.raises(ConfigError, match=message):
        parse_lengths(text, d)


def test_the_command_lists_example_1a_s_square_and_writes_its_modes(tmp_path, capsys):
    assert run(["stability", str(EXAMPLES / "ex01a.toml"), "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "on the 20 x 20 box (zero-flux cosine modes) the fastest is n = (5, 17), (17, 5): k = 2.783" in printed
    with xr.open_dataset(tmp_path / "dispersion.nc", engine="scipy") as ds:
        assert list(ds.attrs["domain_lengths"]) == [20.0, 20.0]
        assert list(ds.attrs["domain_fastest_n"]) == [5, 17]
        assert ds["mode_n"].shape == (ds.sizes["mode"], 2)
        np.testing.assert_allclose(ds["mode_k"], np.pi * np.hypot(*(ds["mode_n"].values / 20.0).T), rtol=1e-14)
        assert int(ds.attrs["domain_unstable_modes"]) == int((ds["mode_growth_rate"] > 0).sum())


def test_a_growing_tissue_lists_no_modes_and_map_refuses_a_domain(tmp_path, capsys):
    assert run(["stability", str(EXAMPLES / "ex02a.toml"), "--chemistry-only", "--out", str(tmp_path)]) == 0
    assert "admissible modes: none listed (the tissue grows, and its modes with it)" in capsys.readouterr().out
    assert run(["stability", "map", "--domain", "3,3", "--x", "m0:1:2:3", "--y", "alpha:1:2:3",
                "--out", str(tmp_path / "map")]) == 2
    assert "--domain applies to 'primordia stability' (the dispersion relation), not to map" in capsys.readouterr().err


def test_a_box_far_larger_than_the_wavelengths_lists_no_modes(tmp_path, capsys):
    """3000 x 3000 holds millions of modes in the band: they are dense, and the analysis goes on without them."""
    assert run(["stability", str(EXAMPLES / "ex01a.toml"), "--domain", "3000,3000", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "admissible modes: none listed (the 3000 x 3000 box admits more than 2000000 modes" in printed
    assert "fastest stationary (Turing) mode: k_max = 2.784" in printed


def test_a_3d_box_lists_its_modes_in_three_indices_and_a_2d_analysis_of_it_names_the_lengths(tmp_path, capsys):
    """Example 1a's chemistry on a 4 x 4 x 1 box: by hand, k = pi |(n_1/4, n_2/4, n_3)|; the 72 n != 0 with
    k <= 5.44 all grow (n_3 = 1 from (0, 0, 1), k = pi), the fastest is (2, 3, 0), k = pi sqrt(13) / 4."""
    text = (EXAMPLES / "ex01a.toml").read_text()
    config = tmp_path / "slab.toml"
    config.write_text(text[:text.index("[mesh]")] + '[mesh]\ntype = "box"\nupper = [4.0, 4.0, 1.0]\n'
                      "cells = [2, 2, 1]\n\n" + text[text.index("[time]"):])
    assert run(["stability", str(config), "--out", str(tmp_path / "d3")]) == 0
    printed = capsys.readouterr().out
    assert "on the 4 x 4 x 1 box (zero-flux cosine modes) the fastest is n = (2, 3, 0), (3, 2, 0): k = 2.832" in printed
    assert "72 admissible modes grow" in printed
    with xr.open_dataset(tmp_path / "d3" / "dispersion.nc", engine="scipy") as ds:
        n = ds["mode_n"].values
        np.testing.assert_allclose(ds["mode_k"], np.pi * np.linalg.norm(n / [4.0, 4.0, 1.0], axis=1), rtol=1e-14)
        assert sorted(set(n[:, 2])) == [0, 1]
    assert run(["stability", str(config), "--d", "2", "--out", str(tmp_path / "d2")]) == 0
    assert "admissible modes: none listed (the mesh is 3D; --domain L1,L2 gives a box)" in capsys.readouterr().out
