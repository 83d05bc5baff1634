"""Run configurations (primordia.core.config): reading TOML, ``--set`` overrides, structure and types.

What a whole model does with a configuration is in test_model.py; random configurations and
``--set`` strings through the command are in test_config_fuzz.py.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from primordia.core import config
from primordia.core.errors import ConfigError

from small_config import SMALL_CONFIG


def one_line_error(make, *args) -> str:
    with pytest.raises(ConfigError) as caught:
        make(*args)
    message = str(caught.value)
    assert "\n" not in message, message
    return message


# -- reading a file ------------------------------------------------------------------------------
def test_a_toml_file_is_read_with_the_folder_it_lives_in(tmp_path):
    path = tmp_path / "runs" / "small.toml"
    path.parent.mkdir()
    path.write_text(SMALL_CONFIG)
    table = config.load_config(path)
    assert table["mesh"] == {"type": "rectangle", "upper": [4.0, 4.0], "cells": [8, 8]}
    assert table["time"] == {"dt": 0.2, "t_final": 1.0}
    assert table["parameters"]["D_m"] == 0.03
    assert table["_base_dir"] == str(path.parent.resolve())  # relative mesh paths are read from here


def test_a_byte_order_mark_is_not_part_of_the_toml(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes("\ufeff[time]\ndt = 0.5\n".encode())
    assert config.load_config(path)["time"] == {"dt": 0.5}


@pytest.mark.parametrize("make, fragment", [
    (lambda d: d / "missing.toml", "config file not found"),
    (lambda d: d, "is a folder, not a TOML file"),
    (lambda d: Path(os.devnull), "is not a regular file"),
    (lambda d: _write(d / "binary.toml", b"[time]\ndt = \xff\xfe\n"), "is not UTF-8 text (byte 12: b'\\xff')"),
    (lambda d: _write(d / "broken.toml", b"[time\ndt = 1\n"), "invalid TOML"),
    (lambda d: _write(d / "twice.toml", b"[time]\ndt = 1\ndt = 2\n"), "invalid TOML"),
    (lambda d: _write(d / "huge.toml", b"#" * (config.MAX_CONFIG_BYTES + 1)), "larger than 1 MB"),
])
def test_a_file_that_is_no_configuration_is_one_line(tmp_path, make, fragment):
    assert fragment in one_line_error(config.load_config, make(tmp_path))


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


# -- --set overrides ---------------------------------------------------------------------------------
@pytest.mark.parametrize("text, keys, value", [
    ("parameters.D_m=0.05", ["parameters", "D_m"], 0.05),
    (" time.t_final = 1e3 ", ["time", "t_final"], 1000.0),
    ("mesh.cells=[4, 4]", ["mesh", "cells"], [4, 4]),
    ("output.pictures=false", ["output", "pictures"], False),
    ("model.backend=skfem", ["model", "backend"], "skfem"),  # a bare word is a string
    ('model.name="a=b"', ["model", "name"], "a=b"),  # only the first '=' separates
    ("physics.chemotaxis.scheme=\"fitted\"", ["physics", "chemotaxis", "scheme"], "fitted"),
    ("coupling.options={tolerance = 1e-8}", ["coupling", "options"], {"tolerance": 1e-8}),
    ('parameters."D_m"=0.05', ["parameters", "D_m"], 0.05),  # a key is a TOML dotted key: quotes are not part of it
    ("'solver'.chemotaxis_m.ksp_rtol=1e-3", ["solver", "chemotaxis_m", "ksp_rtol"], 1e-3),
    ('solver."my.prefix".ksp_rtol=1e-3', ["solver", "my.prefix", "ksp_rtol"], 1e-3),  # a dot inside quotes
    (" parameters . D_m =0.05", ["parameters", "D_m"], 0.05),
    ("parameters.α=1", ["parameters", "α"], 1),  # no TOML bare key: split at the dots, refused by its name later
])
def test_an_assignment_is_dotted_keys_and_a_toml_value(text, keys, value):
    assert config.parse_assignment(text) == (keys, value)


@pytest.mark.parametrize("text, fragment", [
    ("parameters.D_m", "--set expects section.key=value, got 'parameters.D_m'"),
    ("=1", "--set expects section.key=value"),
    ("D_m=1", "--set key must name a section and a key (e.g. parameters.D_m), got 'D_m'"),
    ("parameters..D_m=1", "must name a section and a key"),
    ("parameters.=1", "must name a section and a key"),
])
def test_a_malformed_assignment_is_one_line(text, fragment):
    assert fragment in one_line_error(config.parse_assignment, text)


def test_overrides_apply_to_a_copy_and_create_tables():
    original = {"time": {"dt": 0.2, "t_final": 1.0}, "mesh": {"cells": [8, 8]}}
    changed = config.apply_overrides(original, ["time.dt=0.1", "mesh.cells=[2, 2]", "solver.chemotaxis_m.ksp_type=cg",
                                                "time.dt=0.05"])
    assert changed == {"time": {"dt": 0.05, "t_final": 1.0}, "mesh": {"cells": [2, 2]},
                       "solver": {"chemotaxis_m": {"ksp_type": "cg"}}}
    assert original == {"time": {"dt": 0.2, "t_final": 1.0}, "mesh": {"cells": [8, 8]}}
    assert config.apply_overrides(original, []) == original


def test_a_lone_string_is_one_override_and_a_non_string_is_one_line():
    """Model.from_file(path, "time.dt=0.1") read the string character by character ("got 't'")."""
    assert config.apply_overrides({"time": {"dt": 0.2}}, "time.dt=0.1") == {"time": {"dt": 0.1}}
    assert "an override is a string section.key=value, got 3" in one_line_error(config.apply_overrides, {}, [3])


@pytest.mark.parametrize("text", ["_base_dir.x=1", "_comment.x=1", '"_x".y=1'])
def test_primordia_s_own_keys_cannot_be_set(text):
    """Every top-level key starting with _ was skipped by the structure check: ignored without a word."""
    assert "unknown config section [_" in one_line_error(config.apply_overrides, {"_base_dir": "/here"}, [text])


@pytest.mark.parametrize("text", ['_comment = "notes"\n', '_base_dir = "/elsewhere"\n', "[_draft]\ndt = 1\n"])
def test_a_file_s_key_starting_with_an_underscore_is_unknown(tmp_path, text):
    """A file's _base_dir moved its relative mesh path without a word, and _comment was ignored."""
    path = tmp_path / "underscore.toml"
    path.write_text(text + "[time]\ndt = 0.5\n")
    assert "unknown config section [_" in one_line_error(config.load_config, path)


def test_an_override_through_a_value_that_is_not_a_table():
    message = one_line_error(config.apply_overrides, {"time": 5}, ["time.dt=1"])
    assert message == "--set time.dt=1: time is not a table"


# -- structure -------------------------------------------------------------------------------------------
def test_a_valid_structure_passes_with_open_sections_taking_any_key():
    config.check_structure({"_base_dir": "/somewhere", "model": {"physics": ["chemotaxis"], "backend": "skfem"},
                            "parameters": {"anything": 1.0}, "mesh": {"type": "rectangle", "whatever": 1},
                            "physics": {"chemotaxis": {"option": 1}}, "solver": {"chemotaxis_m": {"ksp_type": "cg"}},
                            "time": {"dt": 0.1, "t_final": 1.0, "t_start": 0.0, "adaptive": False, "dt_min": 0.01}})


@pytest.mark.parametrize("table, expected", [
    ({"nonsense": {}}, "unknown config section [nonsense] (known: model, kinetics, growth_law, physics"),
    ({"time": {"dt": 1, "nonsense": 2}}, "unknown key time.nonsense (known: adaptive, dt, dt_min, t_final, t_start)"),
    ({"checkpoint": {"every_seconds": 1}}, "unknown key checkpoint.every_seconds"),
    ({"model": {"physic": ["chemotaxis"]}}, "unknown key model.physic"),
    ({"time": 3}, "config section [time] must be a table"),
    ({"physics": {"chemotaxis": 3}}, "physics.chemotaxis must be a table ([physics.NAME]), got 3"),
    ({"solver": {"chemotaxis_m": "cg"}}, "solver.chemotaxis_m must be a table ([solver.PREFIX])"),
])
def test_unknown_and_misshapen_tables_are_named(table, expected):
    assert expected in one_line_error(config.check_structure, table)


# -- types of values and options ---------------------------------------------------------------------------
DEFAULTS = {"flag": False, "count": 2, "scale": 1.0, "scheme": "fitted", "names": ["m"], "table": {}, "free": None}


def test_options_merge_over_their_defaults():
    merged = config.merge_options("physics p", DEFAULTS, {"count": 3, "scale": 2, "free": object})
    assert merged == {**DEFAULTS, "count": 3, "scale": 2, "free": object}  # an integer is a number; None: anything
    assert DEFAULTS["count"] == 2
    assert config.merge_options("physics p", DEFAULTS, {}) == DEFAULTS
    # as config.toml gives them back: a tuple is a list, numpy's scalars are Python's (both were refused)
    merged = config.merge_options("physics p", DEFAULTS, {"names": ("m", "f"), "count": np.int64(3),
                                                          "flag": np.bool_(True), "scale": np.float32(0.5)})
    assert merged["names"] == ["m", "f"]
    assert [type(merged[key]) for key in ("count", "flag", "scale")] == [int, bool, float]


@pytest.mark.parametrize("key, value, kind", [
    ("flag", 1, "true or false"), ("count", 1.5, "an integer"), ("count", True, "an integer"),
    ("scale", "1", "a number"), ("scale", False, "a number"), ("scheme", 1, "a string"),
    ("names", "m", "a list"), ("names", {"m"}, "a list"), ("table", [], "a table"),
])
def test_an_option_of_the_wrong_type_is_named_with_the_type_its_default_has(key, value, kind):
    assert one_line_error(config.merge_options, "physics p", DEFAULTS, {key: value}) == \
        f"physics p: option '{key}' must be {kind}, got {value!r}"


def test_an_unknown_option_lists_the_known_ones():
    assert one_line_error(config.merge_options, "kinetics k", DEFAULTS, {"cuont": 1}) == \
        "kinetics k: unknown option 'cuont' (known: flag, count, scale, scheme, names, table, free)"
    assert one_line_error(config.merge_options, "kinetics k", {}, {"a": 1}) == \
        "kinetics k: unknown option 'a' (known: none)"
    assert "options must be a table of name = value, got [1]" in one_line_error(
        config.merge_options, "kinetics k", DEFAULTS, [1])


def test_an_inline_table_adds_to_the_table_it_names():
    """It replaced the whole table: ex01b's boundary conditions went without a word."""
    original = {"physics": {"poroelasticity": {"boundary": [{"boundary": "bottom", "type": "clamped"}],
                                               "solver": {"a": 1, "b": 2}}}}
    changed = config.apply_overrides(original, ["physics.poroelasticity={displacement_degree=1, solver={b=3}}"])
    assert changed["physics"]["poroelasticity"] == {"boundary": [{"boundary": "bottom", "type": "clamped"}],
                                                    "solver": {"a": 1, "b": 3}, "displacement_degree": 1}
    assert config.apply_overrides(original, ["physics.poroelasticity.boundary=[]"])["physics"]["poroelasticity"][
        "boundary"] == []  # a list is replaced whole
    assert config.apply_overrides({}, ["solver.m={ksp_type='cg'}"]) == {"solver": {"m": {"ksp_type": "cg"}}}


# -- options a model leaves without effect ----------------------------------------------------------
def _model_warnings(capsys, make) -> list[str]:
    """The model ``make()`` composes, and the warnings composing it printed (stderr lines)."""
    capsys.readouterr()
    model = make()
    assert capsys.readouterr().err == ""  # said by what runs or checks it, not by each model composed
    model.warn_about_inert_settings()
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("primordia: warning:")]
    return model, lines


def _small(*overrides):
    import tomllib

    from primordia.model import Model

    return Model.from_config(config.apply_overrides(tomllib.loads(SMALL_CONFIG), list(overrides)))


def test_the_coupled_solves_preconditioner_under_the_split_solve_is_one_warning(capsys):
    """It was taken without a word: the species were solved one by one whatever it said."""
    _, told = _model_warnings(capsys, lambda: _small('physics.chemotaxis.preconditioner="lu"'))
    assert told == ['primordia: warning: physics.chemotaxis.preconditioner = "lu" has no effect: it is the coupled '
                    'solve\'s (solve = "coupled"); under solve = "split" each species\' solver is '
                    '[solver.chemotaxis_SPECIES]']
    _, told = _model_warnings(capsys, lambda: _small('physics.chemotaxis.preconditioner="lu"',
                                                     'physics.chemotaxis.solve="coupled"',
                                                     'physics.chemotaxis.flux_scheme="galerkin"'))
    assert told == []


def test_a_default_left_without_effect_is_not_told_so_a_resolved_config_restarts_quietly(capsys):
    """config.toml holds every default (preconditioner = "block_jacobi" beside solve = "split"): a restart reads
    it back, and refusing or warning about the key itself would stop or clutter every restart of example 1a."""
    model, told = _model_warnings(capsys, _small)
    assert told == []
    resolved = model.resolved_config()
    assert resolved["physics"]["chemotaxis"]["preconditioner"] == "block_jacobi"
    from primordia.model import Model

    _, told = _model_warnings(capsys, lambda: Model.from_config(resolved))
    assert told == []


@pytest.mark.parametrize("overrides, told", [
    (["physics.chemotaxis.perturbation=0.0", 'physics.chemotaxis.perturbation_shape="cosine"'],
     ['physics.chemotaxis.perturbation_shape = "cosine" has no effect: perturbation = 0']),
    (["physics.chemotaxis.wavenumber=[1.0, 0.5]"],
     ['physics.chemotaxis.wavenumber = [1.0, 0.5] has no effect: it is the cosine perturbation\'s '
      '(perturbation_shape = "random")']),
    (['physics.chemotaxis.perturbation_shape="cosine"', "physics.chemotaxis.seed=3"],
     ['physics.chemotaxis.seed = 3 has no effect: it seeds the random perturbation (perturbation_shape = "cosine")']),
    (['physics.chemotaxis.accumulation="conservative"'],
     ['physics.chemotaxis.accumulation = "conservative" has no effect: the tissue\'s volume ratio J is 1 without '
      'finite strain, so both forms are one']),
    (['physics.chemotaxis.perturbation_shape="cosine"', "physics.chemotaxis.wavenumber=[1.0, 0.5]"], []),
])
def test_chemotaxis_options_another_choice_leaves_without_effect_are_told(capsys, overrides, told):
    _, lines = _model_warnings(capsys, lambda: _small(*overrides))
    assert lines == [f"primordia: warning: {line}" for line in told]


def _ex02a(*overrides):
    from primordia.model import Model

    root = Path(__file__).resolve().parents[2]
    return Model.from_file(root / "examples" / "ex02a.toml", ["mesh.cells=[4,4]", *overrides])


@pytest.mark.parametrize("overrides, told", [
    (["physics.poroelastic_growth.stabilisation=[2.0, 0.1]"],  # 2D: "auto" is the direct solve
     ["physics.poroelastic_growth.stabilisation = [2.0, 0.1] has no effect: it preconditions the Schur split's "
      '(psi, p) block; the preconditioner here is a direct solve of the tangent (preconditioner = "schur" uses it)']),
    (["physics.poroelastic_growth.stabilisation=[2.0, 0.1]", 'physics.poroelastic_growth.preconditioner="schur"'],
     []),
    (["physics.poroelastic_growth.stabilisation=[2.0, 0.1]", 'solver.poroelastic_growth.PC_TYPE="fieldsplit"'], []),
    (["physics.poroelastic_growth.initial_equilibrium=false", "physics.poroelastic_growth.initial_load_steps=8"],
     ["physics.poroelastic_growth.initial_load_steps = 8 has no effect: initial_equilibrium = false "
      "(no initial solve to ramp)"]),
    (["physics.poroelastic_growth.initial_equilibrium=false", "solver.poroelastic_growth_initial.ksp_rtol=1e-3"],
     ["[solver.poroelastic_growth_initial] has no effect: initial_equilibrium = false (the initial state is not "
      "solved)"]),
    ([], []),
])
def test_growth_options_the_chosen_solver_leaves_without_effect_are_told(capsys, overrides, told):
    _, lines = _model_warnings(capsys, lambda: _ex02a(*overrides))
    assert lines == [f"primordia: warning: {line}" for line in told]


def test_a_dry_run_says_what_the_model_leaves_without_effect(capsys, small_config, tmp_path):
    from primordia.cli import main

    status = main(["run", str(small_config()), "--out", str(tmp_path / "out"), "--dry-run",
                   "--set", 'physics.chemotaxis.preconditioner="lu"'])
    lines = capsys.readouterr().err.splitlines()
    assert status == 0 and lines == ['primordia: warning: physics.chemotaxis.preconditioner = "lu" has no effect: it '
                                     'is the coupled solve\'s (solve = "coupled"); under solve = "split" each '
                                     'species\' solver is [solver.chemotaxis_SPECIES]']


def test_a_refused_input_is_one_line_even_with_a_setting_left_without_effect(capsys, small_config, tmp_path):
    """The warning is said once the input passed its checks: before them, a refused run printed two lines."""
    from primordia.cli import main

    for extra in (["--dry-run"], []):
        status = main(["run", str(small_config()), "--out", str(tmp_path / "out"), *extra, "--no-progress",
                       "--set", 'physics.chemotaxis.preconditioner="lu"', "--set", 'coupling.scheme="nope"'])
        lines = capsys.readouterr().err.splitlines()
        assert status == 2 and len(lines) == 1 and "unknown splitting scheme 'nope'" in lines[0], lines



def test_a_simulation_set_up_from_python_says_what_the_model_leaves_without_effect(capsys, tmp_path):
    """Only Model.run and the command line said it: Simulation(model).setup(), the README's loop, said nothing."""
    from primordia.coupling.orchestrator import Simulation
    from primordia.core.meshes import rectangle
    from primordia.model import Model

    model = Model(physics=["chemotaxis"], kinetics="painter2018", mesh=rectangle((0, 0), (4, 4), (4, 4)), dt=0.2,
                  t_final=0.4, physics_options={"chemotaxis": {"preconditioner": "lu"}}, output={"pictures": False})
    capsys.readouterr()
    Simulation(model, out_dir=tmp_path / "run").setup()
    assert capsys.readouterr().err.count('primordia: warning: physics.chemotaxis.preconditioner = "lu" has no '
                                         'effect') == 1
    model.run(out=tmp_path / "again")
    assert capsys.readouterr().err.count("has no effect") == 1
