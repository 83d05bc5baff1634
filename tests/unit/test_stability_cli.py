"""``primordia stability`` through a small argparse harness, its inputs, errors and files."""

import argparse
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from primordia.analysis import cli
from primordia.analysis.inputs import read_parameters
from primordia.analysis.patterning import ParameterRange, save_dataset
from primordia.core.errors import ConfigError

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def run(argv):
    parser = argparse.ArgumentParser(prog="primordia")
    cli.register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


def test_dispersion_command_writes_curves_and_reports_the_fastest_mode(tmp_path, capsys):
    config = tmp_path / "table.toml"  # no [model]: a parameter set of the seed's full model
    config.write_text("[parameters]\nm0 = 0.75\n")
    assert run(["stability", str(config), "--set", "parameters.D_m=0.03", "--uncoupled", "--out",
                str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "seed: physics chemotaxis, poroelasticity, active_stress, mechanochemical" in printed
    assert "Table 3.1 with m0=0.75, D_m=0.03" in printed
    assert "uncoupled: the volume sink xi_f div u left out (xi_f = 0)" in printed
    assert "fastest stationary (Turing) mode: k_max =" in printed
    ds = xr.open_dataset(tmp_path / "out" / "dispersion.nc", engine="scipy")
    assert ds.attrs["parameter_m0"] == 0.75 and ds.attrs["parameter_D_m"] == 0.03
    assert ds.attrs["coupled"] == 0 and ds.attrs["kinetics"] == "painter2018"
    assert ds.attrs["steady_state_m"] == 0.75
    assert ds["growth_rate_real"].shape == (ds.sizes["k"], 7)  # 4 chemical + 3 poroelastic roots
    assert ds["transverse_real"].shape == (ds.sizes["k"], 2)
    k_max = ds.attrs["turing_k_max"]
    assert ds.attrs["turing_wavelength"] == pytest.approx(2 * np.pi / k_max)
    assert f"k_max = {k_max:.4g}" in printed
    assert (tmp_path / "out" / "dispersion.png").stat().st_size > 10_000
    ds.close()


def test_a_run_configuration_is_analysed_as_it_runs(tmp_path, capsys):
    """examples/ex01a.toml: the chemistry alone, the spacing of seed example 1a's spots (issue 11's numbers)."""
    assert run(["stability", str(EXAMPLES / "ex01a.toml"), "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "physics chemotaxis; kinetics painter2018 (species m, e, f, b); no mechanics" in printed
    assert ("fastest stationary (Turing) mode: k_max = 2.784, wavelength 2 pi / k_max = 2.257, "
            "growth rate 0.1546") in printed
    assert "homogeneous steady state: m = 0.75, e = 0.0313889, f = 0.0313889, b = 0.0165037" in printed
    # the run starts ahead of the priming wave (e = 0.0047 where w = 0): the state printed is the one behind it
    assert ("kinetics painter2018 linearised where its forcing has settled, not at a run's initial state: the same "
            "kinetics behind the priming wave, w = omega_1 everywhere (seed section 3)") in printed
    assert "cross-check: the seed's hand-derived M(phi, k)" in printed
    assert "uncoupled (xi_f = 0 or tau = 0, seed section 3.4): patterns" in printed
    assert "coupled (seed section 3.6)" not in printed  # example 1a has no mechanics to couple


def test_the_dispersion_file_of_a_model_without_mechanics_reads_back(tmp_path):
    """No shear waves: no zero-length transverse_branch, which NetCDF3 would write as the unlimited
    dimension (xarray's scipy engine then failed with "unsupported operand type(s) for *")."""
    assert run(["stability", str(EXAMPLES / "ex01a.toml"), "--out", str(tmp_path)]) == 0
    with xr.open_dataset(tmp_path / "dispersion.nc", engine="scipy") as ds:
        assert "transverse_real" not in ds and "transverse_branch" not in ds.dims
        assert ds["growth_rate_real"].shape == (ds.sizes["k"], 4)  # m, e, f, b
        best = float(ds["k"][int(np.argmax(ds["turing_growth_rate"].values))])
        assert ds.attrs["turing_k_max"] == pytest.approx(best, rel=0.05)
    with pytest.raises(ValueError, match="no zero-length dimension .empty."):
        save_dataset(xr.Dataset({"x": (("empty",), np.zeros(0))}), tmp_path / "empty.nc")


def test_a_map_of_a_model_without_active_stress_has_no_tau(tmp_path, capsys):
    """The FGF sink without the active stress: the loop is open (seed section 3.4).  The map of
    such a run configuration took Table 3.1's tau = 60 for the stress the model does not have,
    and called (m0, alpha) = (2, 4) stable where the model's own analysis has k_max = 4.494."""
    from primordia.analysis.patterns.run import linear_model
    from primordia.core.config import load_config

    text = (EXAMPLES / "ex01b.toml").read_text().replace(
        'physics = ["chemotaxis", "poroelasticity", "active_stress", "mechanochemical"]',
        'physics = ["chemotaxis", "poroelasticity", "mechanochemical"]')
    text = "\n".join(line for line in text.splitlines() if not line.startswith(("tau =", "zeta =")))
    config = tmp_path / "no_active_stress.toml"
    config.write_text(text)
    table = ["--set", "parameters.m0=2", "--set", "parameters.D_m=0.01", "--set", "parameters.xi_f=0.15"]
    assert run(["stability", str(config), *table, "--out", str(tmp_path / "dispersion")]) == 0
    assert "fastest stationary (Turing) mode: k_max = 4.494" in capsys.readouterr().out
    with xr.open_dataset(tmp_path / "dispersion" / "dispersion.nc", engine="scipy") as ds:
        assert ds.attrs["coupled"] == 0  # the sink alone does not close the loop (it said 1)
        # CF-1.8 (cfchecks 4.1: no error, no warning); until 2026-12-05 k's units were "dimensionless", which
        # UDUNITS-2 does not know, and the roots' index had neither long_name nor units
        assert ds.attrs["Conventions"] == "CF-1.8"
        assert [ds[name].attrs["units"] for name in ("k", "branch", "transverse_branch")] == ["1", "1", "1"]
    out = tmp_path / "map"
    assert run(["stability", "map", str(config), *table, "--x", "m0:1:3:5", "--y", "alpha:2:6:5", "--nk", "32",
                "--out", str(out)]) == 0
    assert "uncoupled, seed's model, parameters: Table 3.1 with tau=0" in capsys.readouterr().out
    with xr.open_dataset(out / "patterning_m0_alpha.nc", engine="scipy") as ds:
        assert ds.attrs["parameter_tau"] == 0.0 and ds.attrs["coupled"] == 0
        assert int(ds["unstable_numerical"].sel(m0=2.0, alpha=4.0)) == 1
        assert ds.attrs["Conventions"] == "CF-1.8" and ds["m0"].attrs["units"] == "1"
        # CF: the flag values of the flags' own type; they were the text "0 1"
        assert ds["unstable_numerical"].attrs["flag_values"].tolist() == [0, 1]
    params, coupled = linear_model(load_config(config))  # the sweep map's linear analysis
    assert not coupled and params["tau"] == 0.0 and params["xi_f"] == 0.001


def test_example_1b_is_the_coupled_analysis_at_its_own_tau_and_xi_f(tmp_path, capsys):
    assert run(["stability", str(EXAMPLES / "ex01b.toml"), "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "with mechanics" in printed and "tau=0.001, xi_f=0.001" in printed
    assert "coupled (seed section 3.6): Turing patterns" in printed
    ds = xr.open_dataset(tmp_path / "dispersion.nc", engine="scipy")
    assert ds.attrs["coupled"] == 1 and ds.attrs["parameter_tau"] == 0.001
    ds.close()


def test_an_oscillatory_instability_is_placed_on_the_box_too(tmp_path, capsys):
    """The fastest mode oscillates with a wavelength of 400 on a 20 x 20 box: only the stationary modes were
    listed, so nothing said that no admissible mode grows (found by the stability QA pass)."""
    assert run(["stability", str(EXAMPLES / "ex01b.toml"), "--set", "parameters.tau=-60", "--set",
                "parameters.xi_f=0.15", "--set", "parameters.alpha=1", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "wavelength 2 pi / k_max = 399.7, growth rate 3.05e-06 (oscillatory" in printed
    assert ("on the 20 x 20 box (zero-flux cosine modes) no admissible mode grows as an oscillatory mode (its "
            "unstable band ends at k = 0.06651, below the box's lowest k, pi / 20 = 0.1571)") in printed
    # a box far larger than 400: the oscillatory modes are dense, said so, and the files are still written
    assert run(["stability", str(EXAMPLES / "ex01b.toml"), "--set", "parameters.tau=-60", "--set",
                "parameters.xi_f=0.15", "--set", "parameters.alpha=1", "--domain", "70000,70000",
                "--out", str(tmp_path / "large")]) == 0
    printed = capsys.readouterr().out
    assert "70000 x 70000 box (zero-flux cosine modes) no admissible mode grows as a stationary mode" in printed
    assert ("admissible oscillatory modes: none listed (the 70000 x 70000 box admits more than 2000000 modes below "
            "k = 0.06651: they are dense, as the continuous analysis assumes)") in printed
    assert (tmp_path / "large" / "dispersion.nc").is_file() and (tmp_path / "large" / "dispersion.png").is_file()


def test_a_third_party_kinetics_is_analysed(tmp_path, capsys):
    assert run(["stability", str(EXAMPLES / "schnakenberg.toml"), "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "kinetics schnakenberg (species activator, inhibitor)" in printed
    assert "homogeneous steady state: activator = 1, inhibitor = 0.9" in printed
    assert "k_max = 2.176, wavelength 2 pi / k_max = 2.887, growth rate 0.2632" in printed
    assert "cross-check" not in printed  # the seed's matrix does not describe this model
    with pytest.raises(ConfigError, match="kinetics schnakenberg: primordia stability"):
        run(["stability", "map", str(EXAMPLES / "schnakenberg.toml"), "--x", "a:0:1:3", "--y", "b:0:1:3"])


def test_a_growing_tissue_is_one_line_and_exit_2_unless_the_chemistry_is_asked_for(tmp_path, capsys):
    from primordia.cli import main

    config = str(EXAMPLES / "ex02a.toml")
    assert main(["stability", config, "--out", str(tmp_path)]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count("\n") == 0 and error.startswith("primordia: error: ex02a grows at finite strain")
    assert main(["stability", config, "--chemistry-only", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "chemistry only: poroelastic_growth, mechanochemical left out" in printed
    assert "k_max = 2.784" in printed


def test_map_command_writes_patterning_space(tmp_path, capsys):
    out = tmp_path / "map"
    assert run(["stability", "map", "--x", "m0:0.5:4:9", "--y", "alpha:0.5:8:7", "--uncoupled", "--nk", "12",
                "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "Turing-unstable:" in printed and "critical m0 =" in printed
    ds = xr.open_dataset(out / "patterning_m0_alpha.nc", engine="scipy")
    assert ds["unstable_numerical"].dims == ("m0", "alpha") and ds["unstable_numerical"].shape == (9, 7)
    for name in ("unstable_conditions", "seed_conditions", "condition_3_7a", "condition_3_7b", "condition_3_7c",
                 "constant_term", "dispersion_max_real"):
        assert name in ds
    assert (out / "patterning_m0_alpha.png").is_file()
    assert not list(out.glob(".*tmp*"))  # no temporary files left behind
    ds.close()


@pytest.mark.parametrize("argv, message", [
    (["stability", "--set", "parameters.D_x=1"], "unknown parameter 'D_x'"),
    (["stability", "--set", "parameters.D_m=-1"], "parameter D_m must be > 0"),
    (["stability", "--set", "D_m=1"], "--set key must name a section and a key"),
    (["stability", "--set", "parameters.D_m=fast"], "value must be a number"),
    (["stability", "missing.toml"], "config file not found: missing.toml"),
    (["stability", "--x", "m0:0:1:3"], "--x, --y, --critical, --theta and --nk apply to 'primordia stability map'"),
    (["stability", "--nk", "-3"], "--nk apply to 'primordia stability map'"),  # was silently ignored
    (["stability", "map", "--x", "m0:0.1:4", "--y", "alpha:0:1:5"], "parameter range must be NAME:LO:HI:N"),
    (["stability", "map", "--x", "m0:4:0.1:5", "--y", "alpha:0:1:5"], "need LO < HI"),
    (["stability", "map", "--x", "m0:0.1:4:five", "--y", "alpha:0:1:5"], "N must be an integer"),
    (["stability", "map", "--x", "m0:0.1:4:5", "--y", "alpha:-1:1:5"], "parameter alpha must be >= 0"),
    (["stability", "map", "--x", "m0:0.1:4:5", "--y", "alfa:0:1:5"], "unknown parameter 'alfa'"),
    (["stability", "map", "--x", "m0:0.1:4:5"], "stability map needs --x"),
    (["stability", "map", "--x", "tau:0:1:5", "--y", "m0:1:2:5", "--uncoupled"], "--uncoupled sets xi_f = 0"),
    (["stability", str(Path(__file__).resolve().parents[2] / "examples" / "ex01a.toml"), "--set", "parameters.tau=1"],
     "parameter 'tau' belongs to physics active_stress, which this model does not use"),  # 1a has no active stress
    # a steep Hill switch or an absurd density overflowed Python's floats: a traceback
    (["stability", "--set", "parameters.P_2=2000"], "kinetics painter2018: its rates cannot be evaluated"),
    (["stability", "--set", "parameters.m0=1e300"], "kinetics painter2018: its rates cannot be evaluated"),
    (["stability", str(Path(__file__).resolve().parents[2] / "examples" / "ex01a.toml"), "--set",
      "parameters.P_2=2000"], "kinetics painter2018: the initial state cannot be evaluated"),
    # ex01a has no mechanics: its "coupled" map was the uncoupled one with Table 3.1's mechanics, labelled coupled
    (["stability", "map", str(Path(__file__).resolve().parents[2] / "examples" / "ex01a.toml"), "--coupled",
      "--x", "m0:0.1:4:3", "--y", "alpha:0:1:3"], "--coupled: the model of"),
    # the dispersion relation of ex01a's chemistry alone was printed under --coupled without a word
    (["stability", str(Path(__file__).resolve().parents[2] / "examples" / "ex01a.toml"), "--coupled"],
     "--coupled: the model ex01a has no closed mechano-chemical loop"),
    (["stability", "--coupled", "--chemistry-only"], "--coupled: --chemistry-only leaves the mechanics out"),
    # the map of ex01b with mu, lambda given as options was the map of Table 3.1's E and nu, without a word
    (["stability", "map", str(Path(__file__).resolve().parents[2] / "examples" / "ex01b.toml"), "--set",
      "physics.poroelasticity.shear_modulus=1000", "--x", "m0:0.1:4:3", "--y", "alpha:0:1:3"],
     "ex01b sets its Lame constants by physics.poroelasticity options (mu = 1000, lambda = 42857.1)"),
    # a grid that cannot fit had the kernel kill the process (24 GB at --y alpha:0:12:100000000)
    (["stability", "map", "--x", "m0:0.1:4:3", "--y", "alpha:0:1:100000000"], "use fewer points"),
    (["stability", "map", "--x", "m0:0.1:4:3", "--y", "alpha:0:1:3", "--nk", "100000000"], "use fewer points"),
    # NaN coefficients at some grid points stopped the eigenvalue search with an AssertionError
    (["stability", "map", "--x", "P_2:2:3000:3", "--y", "alpha:0:1:3"],
     "the linearisation is not finite at P_2 = 1501, alpha = 0"),
])
def test_bad_input_is_one_line_config_error(argv, message):
    with pytest.raises(ConfigError) as error:
        run(argv)
    assert message in str(error.value)
    assert "\n" not in str(error.value)


@pytest.mark.parametrize("argv", [["stability"], ["stability", "map", "--x", "m0:0.1:4:3", "--y", "alpha:0:1:3"]],
                         ids=["dispersion", "map"])
def test_an_output_that_is_a_file_is_refused_before_the_analysis(tmp_path, capsys, argv):
    """The whole analysis was computed and printed before the output path was refused."""
    target = tmp_path / "a_file"
    target.write_text("x")
    with pytest.raises(ConfigError, match="is a file, not a directory"):
        run([*argv, "--out", str(target)])
    assert capsys.readouterr().out == ""


def test_invalid_toml_and_non_numeric_parameter(tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text("[parameters\nm0 = 1\n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        read_parameters(broken)
    text = tmp_path / "text.toml"
    text.write_text('[parameters]\nm0 = "two"\n')
    with pytest.raises(ConfigError, match="parameter m0 must be a number"):
        read_parameters(text)


def test_set_overrides_the_config_file(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text("[parameters]\ntau = -20\nxi_f = 0.3\n")
    params = read_parameters(config, ["parameters.xi_f=0.05"])
    assert params["tau"] == -20.0 and params["xi_f"] == 0.05 and params["m0"] == 2.0


def test_parameter_range_parsing():
    r = ParameterRange.parse("kappa_4:0.01:5:11")
    assert (r.name, r.low, r.high, r.n) == ("kappa_4", 0.01, 5.0, 11)
    assert r.values[[0, -1]] == pytest.approx([0.01, 5.0])


def test_save_dataset_keeps_the_old_file_when_writing_fails(tmp_path, monkeypatch):
    path = tmp_path / "result.nc"
    save_dataset(xr.Dataset({"a": ("x", np.arange(3.0))}), path)
    before = path.read_bytes()

    def fail(self, *args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", fail)
    with pytest.raises(RuntimeError):
        save_dataset(xr.Dataset({"a": ("x", np.arange(5.0))}), path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["result.nc"]


def test_public_api_names_resolve_lazily():
    import primordia.analysis as analysis

    for name in analysis.__all__:
        assert callable(getattr(analysis, name)), name
    with pytest.raises(AttributeError):
        analysis.no_such_function  # noqa: B018


@pytest.mark.parametrize("example, refusal", [("ex02a.toml", "grows at finite strain"),
                                              ("schnakenberg.toml", "uses kinetics schnakenberg")])
def test_the_sweep_map_has_no_seed_analysis_for_a_growing_tissue_or_another_kinetics(example, refusal):
    """The sweep map's overlay is the seed's analysis read as the model that runs: none for a
    growing tissue (seed section 6) or a plugin's kinetics, rather than Table 3.1's model."""
    from primordia.analysis.patterns.run import linear_model
    from primordia.core.config import load_config

    with pytest.raises(ConfigError, match=refusal):
        linear_model(load_config(EXAMPLES / example))
    params, coupled = linear_model(load_config(EXAMPLES / "ex01b.toml"))
    assert coupled and (params["tau"], params["xi_f"]) == (0.001, 0.001)
    params, coupled = linear_model(load_config(EXAMPLES / "ex01a.toml"))
    assert not coupled and (params["tau"], params["xi_f"]) == (0.0, 0.0)


def test_the_map_usage_names_chemistry_only_which_its_refusal_of_a_growing_tissue_suggests():
    """``stability map`` of a growing tissue says "--chemistry-only analyses the chemistry alone", which map takes,
    but its usage did not list it (the 3D QA pass)."""
    import primordia.analysis.cli as stability_cli

    usage = stability_cli.__doc__
    map_usage = usage[usage.index("primordia stability map"):usage.index("the patterning space")]
    assert "[--chemistry-only]" in map_usage, map_usage
