"""Random configurations and ``--set`` values (hypothesis): never a traceback, never a hang (issue 10).

Random trees of TOML values, grafted onto a small valid configuration at known and
unknown keys, go to the loader (:meth:`Model.from_config`) and, written as TOML
files, to the command's entry point (``primordia run CONFIG --dry-run``); random
``--set`` strings go to the command too.  Each must either be accepted or refused
with exactly one line ``primordia: error: ...`` and exit status 2, within a time
bound.
"""

from __future__ import annotations

import copy
import time
import tomllib

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from primordia.cli import main
from primordia.core.json_toml import write_toml
from primordia.core.errors import PrimordiaError
from primordia.model import Model

from small_config import SMALL_CONFIG

BASE = tomllib.loads(SMALL_CONFIG)
#: Keys the fuzzing grafts values onto: real ones of every section, and some that exist nowhere.
KEYS = [
    ("model", "physics"), ("model", "backend"), ("model", "name"), ("kinetics", "name"),
    ("kinetics", "priming_wave"), ("physics", "chemotaxis"), ("physics", "poroelasticity"),
    ("parameters", "D_m"), ("parameters", "alpha"), ("parameters", "m0"), ("mesh", "type"), ("mesh", "cells"),
    ("mesh", "upper"), ("mesh", "lower"), ("mesh", "diagonal"), ("mesh", "path"), ("time", "dt"),
    ("time", "t_final"), ("time", "t_start"), ("time", "adaptive"), ("time", "dt_min"), ("output", "times"),
    ("output", "pictures"), ("output", "series_every"), ("output", "snapshot_fields"),
    ("output", "displacement_scale"), ("coupling", "scheme"), ("coupling", "inner_steps"),
    ("coupling", "tolerance"), ("checkpoint", "every_steps"), ("checkpoint", "every_minutes"),
    ("growth_law", "name"), ("nonsense", "key"), ("time", "nonsense"),
]
SECTIONS = sorted({section for section, _ in KEYS})

#: Numbers a user writes, mistakes included: tiny, huge, negative, not finite.
numbers = st.one_of(
    st.sampled_from([0, 1, 2, 8, -1, 0.2, 1.0, -0.2, 1e-300, 1e300, 10**12, 2**62, float("nan"), float("inf")]),
    st.integers(-5, 12), st.floats(-1e3, 1e3, allow_nan=False),
)
words = st.one_of(st.sampled_from(["", " ", "false", "true", "chemotaxis", "painter2018", "rectangle", "box",
                                   "file", "fenicsx", "skfem", "m", "1/0", "x[2]", "nan"]),
                  st.text(max_size=12))
scalars = st.one_of(st.booleans(), numbers, words)
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(["name", "type", "m", "x", "a"]), inner, max_size=3)),
    max_leaves=8)


@st.composite
def config_trees(draw):
    """A small valid config with random values grafted at known and unknown keys, or whole sections replaced."""
    config = copy.deepcopy(BASE)
    for section, key in draw(st.lists(st.sampled_from(KEYS), min_size=1, max_size=4)):
        table = config.setdefault(section, {})
        if isinstance(table, dict):
            table[key] = draw(values)
    if draw(st.booleans()):
        config[draw(st.sampled_from(SECTIONS))] = draw(values)
    return config


FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                          HealthCheck.too_slow])
#: Longer than any configuration takes to be read, checked and refused (a mesh of at most ~1e5 cells).
BOUND_S = 20.0


def _bounded(call):
    start = time.perf_counter()
    result = call()
    assert time.perf_counter() - start < BOUND_S, "took too long to answer"
    return result


@FUZZ
@given(config=config_trees())
def test_the_loader_accepts_or_refuses_in_one_line(config):
    try:
        _bounded(lambda: Model.from_config(copy.deepcopy(config)))
    except PrimordiaError as error:
        assert str(error) and "\n" not in str(error).strip()


def _assert_answered(status: int, stdout: str, stderr: str) -> None:
    lines = stderr.splitlines()
    assert "Traceback" not in stderr
    if status == 0:
        assert stdout.startswith("primordia: the input is valid"), (stdout, stderr)
    else:
        assert status == 2, stderr
        assert len(lines) == 1 and lines[0].startswith("primordia: error: "), stderr


@FUZZ
@given(config=config_trees())
def test_the_command_answers_any_config_file_in_one_line(config, tmp_path_factory, capsys):
    path = tmp_path_factory.mktemp("fuzz") / "config.toml"
    try:
        write_toml(path, config)
    except PrimordiaError:
        pytest.skip("not writable as TOML")  # e.g. a NaN key; never happens with these strategies
    status = _bounded(lambda: main(["run", str(path), "--dry-run", "--out", str(path.parent / "out")]))
    captured = capsys.readouterr()
    _assert_answered(status, captured.out, captured.err)


assignments = st.one_of(
    st.builds(lambda key, value: f"{key[0]}.{key[1]}={value}", st.sampled_from(KEYS),
              st.one_of(st.text(max_size=16), st.sampled_from(["[1,2]", "{a=1}", "true", "\"x\"", "1e999", "[[]]",
                                                               "[0, 8]", "'1/0'", "inf", "-1"]))),
    st.text(max_size=24),
)


@FUZZ
@given(sets=st.lists(assignments, min_size=1, max_size=3))
def test_the_command_answers_any_set_value_in_one_line(sets, small_config, capsys):
    config = small_config()
    arguments = ["run", str(config), "--dry-run", "--out", str(config.parent / "out")]
    for assignment in sets:
        arguments += ["--set", assignment]
    status = _bounded(lambda: main(arguments))
    captured = capsys.readouterr()
    _assert_answered(status, captured.out, captured.err)
