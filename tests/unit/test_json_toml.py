"""Run metadata and resolved configs as JSON and TOML (primordia.core.json_toml)."""

from __future__ import annotations

import json
import math
import tomllib

import numpy as np
import pytest

from primordia.core.errors import PrimordiaError
from primordia.core.json_toml import write_json, write_toml


def test_write_json_sorts_keys_and_converts_numpy(tmp_path):
    path = write_json(
        tmp_path / "run.json",
        {
            "zeta": np.float64(0.5),
            "alpha": {"n": np.int64(3), "ok": np.bool_(True), "v": np.arange(3)},
            "nan": math.nan,
        },
    )
    text = path.read_text()
    assert text.index('"alpha"') < text.index('"nan"') < text.index('"zeta"')
    data = json.loads(text)
    assert data["alpha"] == {"n": 3, "ok": True, "v": [0, 1, 2]} and data["zeta"] == 0.5
    assert math.isnan(data["nan"])


def test_write_json_rejects_unknown_objects(tmp_path):
    with pytest.raises(PrimordiaError, match="cannot write object value"):
        write_json(tmp_path / "x.json", {"a": object()})
    assert not (tmp_path / "x.json").exists()


def test_write_toml_round_trips_through_tomllib(tmp_path):
    config = {
        "title": 'seed "run" 1\n',
        "steps": np.int64(400),
        "dt": 0.5,
        "big": 1e20,
        "flags": [True, False],
        "limits": [-math.inf, math.inf],
        "mesh": {"type": "rectangle", "cells": np.array([171, 171]), "upper": [20.0, 20.0]},
        "parameters": {"D_m": 0.01, "nested": {"odd key": 1}},
        "outputs": [{"kind": "xdmf", "every": 10}, {"kind": "png", "fields": ["m", "u"]}],
    }
    with open(write_toml(tmp_path / "resolved.toml", config), "rb") as handle:
        back = tomllib.load(handle)
    expected = dict(config, steps=400, mesh={"type": "rectangle", "cells": [171, 171], "upper": [20.0, 20.0]})
    assert back == expected


def test_write_toml_rejects_values_toml_cannot_hold(tmp_path):
    with pytest.raises(PrimordiaError, match="cannot write mesh.shape = None to TOML"):
        write_toml(tmp_path / "x.toml", {"mesh": {"shape": None}})
    assert not (tmp_path / "x.toml").exists()
