"""``primordia stability`` through a small argparse harness, its inputs, errors and files."""

import argparse

import numpy as np
import pytest
import xarray as xr

from primordia.analysis import cli
from primordia.analysis.inputs import read_parameters
from primordia.analysis.patterning import ParameterRange, save_dataset
from primordia.core.errors import ConfigError


def run(argv):
    parser = argparse.ArgumentParser(prog="primordia")
    cli.register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


def test_dispersion_command_writes_curves_and_reports_the_fastest_mode(tmp_path, capsys):
    config = tmp_path / "run.toml"
    config.write_text('[model]\nname = "ignored"\n[parameters]\nm0 = 0.75\n[mesh]\ncells = [4, 4]\n')
    assert run(["stability", str(config), "--set", "parameters.D_m=0.03", "--uncoupled", "--out",
                str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "Table 3.1 with m0=0.75, D_m=0.03" in printed
    assert "fastest stationary (Turing) mode: k_max =" in printed
    ds = xr.open_dataset(tmp_path / "out" / "dispersion.nc", engine="scipy")
    assert ds.attrs["parameter_m0"] == 0.75 and ds.attrs["parameter_D_m"] == 0.03
    assert ds.attrs["parameter_xi_f"] == 0.0 and ds.attrs["coupled"] == 0
    assert ds["growth_rate_real"].shape == (ds.sizes["k"], 7)
    k_max = ds.attrs["turing_k_max"]
    assert ds.attrs["turing_wavelength"] == pytest.approx(2 * np.pi / k_max)
    assert f"k_max = {k_max:.4g}" in printed
    assert (tmp_path / "out" / "dispersion.png").stat().st_size > 10_000
    ds.close()


def test_map_command_writes_patterning_space(tmp_path, capsys):
    out = tmp_path / "map"
    assert run(["stability", "map", "--x", "m0:0.5:4:9", "--y", "alpha:0.5:8:7", "--uncoupled", "--nk", "12",
                "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "Turing-unstable:" in printed and "critical m0 =" in printed
    ds = xr.open_dataset(out / "patterning_m0_alpha.nc", engine="scipy")
    assert ds["unstable_numerical"].dims == ("m0", "alpha") and ds["unstable_numerical"].shape == (9, 7)
    for name in ("unstable_conditions", "seed_conditions", "condition_3_4", "condition_3_5", "condition_3_6",
                 "constant_term", "dispersion_max_real"):
        assert name in ds
    assert (out / "patterning_m0_alpha.png").is_file()
    assert not list(out.glob(".*.tmp"))  # no temporary files left behind
    ds.close()


@pytest.mark.parametrize("argv, message", [
    (["stability", "--set", "parameters.D_x=1"], "unknown parameter 'D_x'"),
    (["stability", "--set", "parameters.D_m=-1"], "parameter D_m must be > 0"),
    (["stability", "--set", "D_m=1"], "--set key must name a section and a key"),
    (["stability", "--set", "parameters.D_m=fast"], "value must be a number"),
    (["stability", "missing.toml"], "config file not found: missing.toml"),
    (["stability", "--x", "m0:0:1:3"], "--x, --y and --critical apply to 'primordia stability map'"),
    (["stability", "map", "--x", "m0:0.1:4", "--y", "alpha:0:1:5"], "parameter range must be NAME:LO:HI:N"),
    (["stability", "map", "--x", "m0:4:0.1:5", "--y", "alpha:0:1:5"], "need LO < HI"),
    (["stability", "map", "--x", "m0:0.1:4:five", "--y", "alpha:0:1:5"], "N must be an integer"),
    (["stability", "map", "--x", "m0:0.1:4:5", "--y", "alpha:-1:1:5"], "parameter alpha must be >= 0"),
    (["stability", "map", "--x", "m0:0.1:4:5", "--y", "alfa:0:1:5"], "unknown parameter 'alfa'"),
    (["stability", "map", "--x", "m0:0.1:4:5"], "stability map needs --x"),
    (["stability", "map", "--x", "tau:0:1:5", "--y", "m0:1:2:5", "--uncoupled"], "--uncoupled sets xi_f = 0"),
])
def test_bad_input_is_one_line_config_error(argv, message):
    with pytest.raises(ConfigError) as error:
        run(argv)
    assert message in str(error.value)
    assert "\n" not in str(error.value)


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
