"""Composing a model (primordia.model): in Python and from TOML, with every input checked before any assembly.

Reading the TOML file itself is in test_config.py; parameters by their declarations in
test_parameters.py; running a model in test_orchestrator.py.
"""

from __future__ import annotations

import pytest

from primordia.core.errors import ConfigError, PluginError, PrimordiaError
from primordia.core.meshes import rectangle
from primordia.model import Model

from small_config import SMALL_CONFIG

#: The small config of the CLI tests (tests/support/small_config.py), composed in Python.
SMALL = dict(physics=["chemotaxis"], kinetics="painter2018", parameters={"m0": 0.75, "D_m": 0.03},
             mesh={"type": "rectangle", "upper": [4.0, 4.0], "cells": [8, 8]}, dt=0.2, t_final=1.0,
             output={"pictures": False}, name="small")


def small(**changes) -> Model:
    return Model(**{**SMALL, **changes})


def one_line_error(kind, **changes) -> str:
    with pytest.raises(kind) as caught:
        small(**changes)
    message = str(caught.value)
    assert "\n" not in message, message
    return message


# -- what a model holds ------------------------------------------------------------------------
def test_a_model_composed_in_python_fills_in_its_defaults():
    model = small()
    assert [p.name for p in model.physics_objects] == ["chemotaxis"]
    assert model.kinetics_object.name == "painter2018"
    assert model.parameters["m0"] == 0.75 and model.parameters["D_m"] == 0.03
    assert model.parameters["alpha"] == 4.0  # seed Table 3.1, not given
    assert (model.t_start, model.dt, model.t_final, model.num_steps) == (0.0, 0.2, 1.0, 5)
    assert model.adaptive and model.dt_min == pytest.approx(0.2 / 2 ** 10)
    assert model.output["times"] == [1.0]  # the end, unless told
    assert model.output["snapshot_fields"] == ["m"]  # the first field, unless told
    assert model.checkpoint == {"every_steps": 0, "every_minutes": 10.0}
    assert (model.coupling, model.backend) == ("sequential", "fenicsx")
    assert (model.mesh_data.num_vertices, model.mesh_data.num_cells) == (81, 128)


def test_a_model_from_toml_is_the_model_composed_in_python(small_config):
    from_file = Model.from_file(small_config())
    assert from_file.resolved_config() == small().resolved_config()
    assert from_file.base_dir == small_config().parent.resolve()


def test_overrides_reach_the_model_from_a_file(small_config):
    model = Model.from_file(small_config(), ["time.dt=0.1", "output.times=[0.5, 0.3]", "parameters.D_m=0.05",
                                             'coupling.scheme="strang"', "model.backend=skfem"])
    assert (model.dt, model.num_steps) == (0.1, 10)
    assert model.output["times"] == [0.3, 0.5]  # sorted
    assert model.parameters["D_m"] == 0.05
    assert (model.coupling, model.backend) == ("strang", "skfem")


def test_the_resolved_config_states_every_choice():
    resolved = small(output={"times": [0.4, 1.0], "snapshot_fields": ["f", "m"], "pictures": False},
                     coupling={"scheme": "fixed_point", "tolerance": 1e-8},
                     solver={"chemotaxis_m": {"ksp_type": "cg"}}, description="a test").resolved_config()
    assert resolved["model"] == {"name": "small", "physics": ["chemotaxis"], "backend": "fenicsx",
                                 "description": "a test"}
    assert resolved["kinetics"] == {"name": "painter2018", "priming_wave": True}
    assert resolved["time"] == {"t_start": 0.0, "dt": 0.2, "t_final": 1.0, "adaptive": True, "dt_min": 0.2 / 1024}
    assert resolved["output"]["times"] == [0.4, 1.0] and resolved["output"]["snapshot_fields"] == ["f", "m"]
    assert resolved["coupling"] == {"scheme": "fixed_point", "tolerance": 1e-8}
    assert resolved["solver"] == {"chemotaxis_m": {"ksp_type": "cg"}}
    assert resolved["mesh"] == SMALL["mesh"]
    assert resolved["physics"]["chemotaxis"]["flux_scheme"] == "exponential_fitting"  # a default, written out
    assert len(resolved["parameters"]) > 20 and resolved["parameters"]["D_m"] == 0.03


def test_an_in_memory_mesh_is_described_in_the_resolved_config():
    import dataclasses

    generated = rectangle((0.0, 0.0), (4.0, 4.0), cells=(2, 2))
    mesh = dataclasses.replace(generated, points=generated.points * 2)  # no generator's mesh any more
    model = small(mesh=mesh)
    assert model.resolved_config()["mesh"] == {"type": "in-memory", "vertices": 9, "cells": 8,
                                               "description": model.mesh_data.description}
    generated.points[0, 0] = -0.5  # nor is one changed in place
    assert small(mesh=generated).resolved_config()["mesh"]["type"] == "in-memory"
    message = one_line_error(ConfigError, mesh=model.resolved_config()["mesh"])
    assert message.startswith("[mesh] type 'in-memory' is the description of a mesh made in Python")


@pytest.mark.parametrize("make, table", [
    (lambda: rectangle((0, 0), (4, 4), cells=(2, 3), diagonal="left"),
     {"type": "rectangle", "lower": [0.0, 0.0], "upper": [4.0, 4.0], "cells": [2, 3], "diagonal": "left"}),
    (lambda: __import__("primordia.core.meshes", fromlist=["box"]).box((0, 0, 0), (1, 2, 1), cells=(1, 2, 1)),
     {"type": "box", "lower": [0.0, 0.0, 0.0], "upper": [1.0, 2.0, 1.0], "cells": [1, 2, 1]}),
])
def test_a_generated_mesh_is_written_as_the_table_that_builds_it(make, table):
    """README: running from config.toml reproduces the run; with the README's own Python example (a mesh made
    by rectangle()) config.toml said type = "in-memory", which no config can run."""
    model = small(mesh=make())
    assert model.resolved_config()["mesh"] == table
    again = Model.from_config(model.resolved_config())
    assert again.resolved_config() == model.resolved_config()
    for name in ("points", "cells"):
        assert (getattr(again.mesh_data, name) == getattr(model.mesh_data, name)).all()


def test_inputs_varying_in_time_are_checked_over_the_run_and_at_output_times():
    times = small(t_start=1.0, t_final=2.0, output={"times": [1.2, 2.0]}).sample_times(count=3)
    assert times == [1.0, 1.2, 1.5, 2.0]


def test_differences_from_another_run_leave_out_what_a_restart_may_change():
    model = small()
    resolved = model.resolved_config()
    assert model.differences(resolved) == []
    longer = small(t_final=2.0, output={"pictures": True}).resolved_config()
    assert model.differences(longer) == []  # t_final and outputs may change on restart
    other = small(parameters={"m0": 0.75, "D_m": 0.05}, dt=0.1).resolved_config()
    assert model.differences(other) == ["parameters.D_m", "time.dt"]
    del resolved["physics"]["chemotaxis"]["seed"]  # written before the option existed: at its default
    assert model.differences(resolved) == []


def test_a_restart_that_sets_an_option_unset_in_the_checkpointed_run_differs_from_it():
    """An unset option (None) is not in config.toml, TOML having no null: a restart of example 4 that set
    growth_law.directions (default None, the axes) continued with the frame turned, as another model."""
    growing = dict(physics=["chemotaxis", "poroelastic_growth"], growth_law="seed2d",
                   physics_options={"poroelastic_growth": {"boundary": [{"boundary": "left", "type": "robin",
                                                                          "value": 1e-3}]}})
    resolved = small(**growing).resolved_config()
    assert "directions" not in resolved["growth_law"]
    assert small(**growing).differences(resolved) == []
    turned = small(**{**growing, "growth_law": {"name": "seed2d", "directions": [[0, 1], [1, 0]]}})
    assert turned.differences(resolved) == ["growth_law.directions"]


# -- what a model refuses, in one line -----------------------------------------------------------------
@pytest.mark.parametrize("changes, fragments", [
    ({"physics": ["chemotaxis", "chemotaxis"]}, "model.physics lists 'chemotaxis' twice"),
    ({"physics": []}, "model.physics must be a non-empty list of names, got []"),
    ({"physics": ["chemotaxis", ""]}, "model.physics must be a non-empty list of names"),
    ({"physics": ["poroelasticity"]}, "[kinetics] is given but no physics module of this model uses reaction kinetics"),
    ({"kinetics": {"name": "painter2018", "nope": 1}}, "kinetics painter2018: unknown option 'nope'"),
    ({"kinetics": 3}, "[kinetics] must be a table with a name"),
    ({"kinetics": {"name": 3}}, "kinetics.name must be the name of a kinetics, got 3"),
    ({"parameters": {"D_mm": 1.0}}, "unknown parameter 'D_mm' (did you mean D_m?)"),
    ({"parameters": {"D_m": -1.0}}, "parameter D_m must be > 0"),
    ({"parameters": [1.0]}, "[parameters] must be a table of name = value"),
    ({"physics_options": {"poroelasticity": {}}}, "[physics.poroelasticity] configures a module that is not in "
                                                  "model.physics (chemotaxis)"),
    ({"physics_options": {"chemotaxis": {"nope": 1}}}, "physics chemotaxis: unknown option 'nope'"),
    ({"physics_options": {"chemotaxis": 3}}, "physics.chemotaxis must be a table of options"),
    ({"physics_options": {"chemotaxis": {"flux_scheme": "upwind"}}}, "physics.chemotaxis.flux_scheme must be one of"),
    ({"dt": 0.0}, ("time.dt must be", "> 0, got 0")),
    ({"dt": True}, ("time.dt must be a number", "got True")),
    ({"dt": float("nan")}, ("time.dt must be a number", "got nan")),
    ({"dt": 0.3}, "time.t_final - time.t_start = 1 is not a multiple of dt = 0.3"),
    # %g printed "time.t_final - time.t_start = 520 is not a multiple of dt = 0.2"
    ({"t_final": 520.0001}, "time.t_final - time.t_start = 520.0001 is not a multiple of dt = 0.2"),
    # 5e-7 of a step: within the tolerance of 1e-9 steps, the last step solved with dt and ending at 520.0000001
    ({"t_final": 520.0000001}, "time.t_final - time.t_start = 520.0000001 is not a multiple of dt = 0.2"),
    ({"output": {"times": [0.4000000001]}}, "output time 0.4000000001 is not a multiple of dt = 0.2"),
    ({"t_final": 3.0, "t_start": 1.0000001}, "time.t_final - time.t_start = 3 - 1.0000001 is not a multiple of "
                                             "dt = 0.2"),
    # 1e-10 is 1e-10 steps of dt = 1, within the tolerance of 0 steps: the run "completed" 0 steps at t = 0
    ({"dt": 1.0, "t_final": 1e-10, "output": {"times": [1e-10]}},
     "time.t_final - time.t_start = 1e-10 is not a multiple of dt = 1"),
    ({"dt": 1e-9}, "more than 10,000,000: is dt in the model's (dimensionless) time units?"),
    ({"t_final": 0.0}, "time.t_final (0) must be greater than time.t_start (0)"),
    ({"t_final": 1.0000001, "t_start": 1.0000002}, "time.t_final (1.0000001) must be greater than time.t_start "
                                                   "(1.0000002)"),
    ({"adaptive": 1}, "time.adaptive must be true or false, got 1"),
    ({"dt_min": 0.5}, ("time.dt_min must be a number in (0, ", "0.2]", "got 0.5")),
    ({"dt_min": 0.0}, ("time.dt_min must be a number in (0, ", "got 0")),
    # a try of 1e-300 leaves t = 0.4 as it was: a failing step was retried 994 times, 77 s on a 4 x 4 mesh
    ({"dt_min": 1e-300}, "time.dt_min = 1e-300 is below what the run's time can tell apart (2^-40 |t| = 9.09e-13 "
                         "at t = 1): a step that short leaves t unchanged"),
    ({"output": {"times": [0.5]}}, "output time 0.5 is not a multiple of dt = 0.2 after t_start"),
    ({"output": {"times": [1.2]}}, "output time 1.2 lies outside (t_start, t_final] = (0, 1]"),
    ({"output": {"times": [0.0]}}, "output time 0 lies outside (t_start, t_final]"),
    # %g printed "output time 1 lies outside (0, 1]"
    ({"output": {"times": [1.0000000001]}}, "output time 1.0000000001 lies outside (t_start, t_final] = (0, 1]"),
    # 5 steps past t_final but within the 1e-12 allowed for round-off: never reached, never written
    ({"dt": 1e-13, "t_final": 1e-12, "output": {"times": [1.5e-12]}},
     "output time 1.5e-12 lies outside (t_start, t_final] = (0, 1e-12]"),
    ({"output": {"times": [0.20000001]}}, "output time 0.20000001 is not a multiple of dt = 0.2"),
    # within 1e-9 of t_start, so of step 0, which the run never writes: the run completed without it
    ({"output": {"times": [1e-12, 1.0]}}, "output time 1e-12 is not a multiple of dt = 0.2 after t_start"),
    # half a step off the grid, but less than 1e-9 in time: reached by a step of dt / 2 solved with dt
    ({"dt": 1e-12, "t_final": 1e-11, "output": {"times": [3.5e-12]}},
     "output time 3.5e-12 is not a multiple of dt = 1e-12 after t_start"),
    ({"output": {"times": "1"}}, "output.times must be a list of numbers, got '1'"),
    ({"output": {"series_every": 0}}, ("output.series_every must be", "(steps), got 0")),
    ({"output": {"pictures": "no"}}, "output.pictures must be true or false, got 'no'"),
    ({"output": {"snapshot_fields": ["u"]}}, "output.snapshot_fields names 'u', which is not a field of this model "
                                             "(m, e, f, b)"),
    ({"output": {"displacement_scale": -1}}, "output.displacement_scale must be a number >= 0, got -1"),
    ({"output": {"format": "vtk"}}, "unknown key output.format (known: times, series_every, pictures, displacement_scale, snapshot_fields"),
    ({"checkpoint": {"every_steps": -1}}, "checkpoint.every_steps must be an integer >= 0"),
    ({"checkpoint": {"every_minutes": "x"}}, "checkpoint.every_minutes must be a number >= 0"),
    ({"checkpoint": {"every_hours": 1}}, "unknown key checkpoint.every_hours"),
    ({"checkpoint": 3}, "[checkpoint] must be a table (every_steps, every_minutes), got 3"),
    ({"coupling": 3}, "[coupling] must be a table (scheme = \"...\" and its options), got 3"),
    ({"coupling": {"scheme": 3}}, "coupling.scheme must be the name of a splitting scheme, got 3"),
    ({"solver": [1]}, "[solver] must be a table of [solver.PREFIX] tables, got [1]"),
    ({"backend": ""}, "model.backend must name a backend"),
    ({"name": 3}, "model.name must be a string, got 3"),
    ({"description": None}, "model.description must be a string, got None"),
    ({"growth_law": "seed2d"}, "[growth_law] is given but no physics module of this model grows"),
    ({"physics": ["poroelastic_growth"], "kinetics": None}, "physics poroelastic_growth needs a growth law"),
    ({"mesh": None}, "a model needs a mesh (a MeshData or a [mesh] table)"),
    ({"mesh": {"type": "disc"}}, "[mesh] type must be one of 'rectangle', 'box', 'file', got 'disc'"),
])
def test_a_bad_input_is_one_config_error_naming_it(changes, fragments):
    message = one_line_error(ConfigError, **changes)
    for fragment in [fragments] if isinstance(fragments, str) else fragments:
        assert fragment in message, message


def _python_objects_in_the_place_of_tables():
    """What a user in Python reaches for: the pieces themselves, where the model takes their names or tables."""
    import meshio

    from primordia.core.plugins import lookup

    square = rectangle((0, 0), (4, 4), cells=(2, 2))
    return [
        ({"kinetics": lookup("kinetics", "painter2018")},
         "[kinetics] must be a table with a name (in Python: kinetics=\"painter2018\" or {\"name\": ..., options}), "
         "got the class primordia.physics.kinetics.painter2018.Painter2018"),
        ({"physics": ["chemotaxis", "poroelastic_growth"], "growth_law": lookup("growth_laws", "seed2d")},
         "got the class primordia.physics.growth_laws.Seed2D"),
        ({"mesh": meshio.Mesh(square.points, [("triangle", square.cells)])},
         "a model needs a mesh (a MeshData or a [mesh] table), got a meshio._mesh.Mesh object: make one with "
         "MeshData(points, cells, boundaries), or read its file with primordia.core.meshes.read_mesh"),
        ({"mesh": "tissue.msh"}, "a model needs a mesh (a MeshData or a [mesh] table), got 'tissue.msh'"),
    ]


@pytest.mark.parametrize("index", range(4))
def test_a_piece_given_in_the_place_of_its_name_is_refused_saying_what_was_given(index):
    """'[kinetics] must be a table with a name' and 'a model needs a mesh' did not say what they had been given:
    a kinetics class or a meshio mesh read as if nothing had been."""
    changes, fragment = _python_objects_in_the_place_of_tables()[index]
    assert fragment in one_line_error(ConfigError, **changes)


def test_help_on_model_says_what_every_argument_is():
    """help(Model) gave the signature and one line: which table each argument is, and what a mesh may be, was in
    no docstring."""
    import inspect

    arguments = [name for name in inspect.signature(Model).parameters]
    assert arguments and [name for name in arguments if f"``{name}``" not in Model.__doc__] == []


def test_a_folder_of_the_wrong_type_is_one_line(tmp_path):
    """base_dir=None and run(out=None) were a TypeError from inside pathlib, naming neither."""
    assert "base_dir must be a folder (a str or a pathlib.Path), got None" in one_line_error(ConfigError, base_dir=None)
    with pytest.raises(ConfigError, match=r"^out must be a folder \(a str or a pathlib.Path\), got None$"):
        small().run(out=None)


def test_a_model_whose_construction_raised_says_so_in_its_repr():
    """A traceback's or debugger's view of the half-made model showed the AttributeError its repr raised."""
    with pytest.raises(ConfigError) as error:
        small(output={"times": [7.0]})
    half_made = next(entry.locals["self"] for entry in error.traceback if entry.name == "__init__")
    assert repr(half_made) == "Model(not set up: its construction raised)"


def test_another_models_parameters_may_be_given_as_they_are():
    """``model.parameters`` (a read-only mapping) was refused as "not a table of name = value"."""
    first = small(parameters={"m0": 0.5, "D_m": 0.04})
    assert dict(small(parameters=first.parameters).parameters) == dict(first.parameters)


@pytest.mark.parametrize("changes, fragment", [
    ({"physics": ["chemotaxs"]}, "unknown physics 'chemotaxs' (registered: active_stress, chemotaxis"),
    ({"kinetics": "painter2019"}, "unknown kinetics 'painter2019' (registered: painter2018"),
])
def test_an_unknown_plugin_name_lists_the_registered_ones(changes, fragment):
    assert fragment in one_line_error(PluginError, **changes)


@pytest.mark.parametrize("text, fragment", [
    (SMALL_CONFIG.replace("[time]\ndt = 0.2\n", "[time]\n"), "the configuration needs [time] dt and t_final"),
    (SMALL_CONFIG.replace('[mesh]\ntype = "rectangle"\nupper = [4.0, 4.0]\ncells = [8, 8]\n', ""),
     "the configuration needs a [mesh] table"),
    (SMALL_CONFIG + "\n[nonsense]\nkey = 1\n", "unknown config section [nonsense]"),
    (SMALL_CONFIG.replace("t_final = 1.0", "t_final = 1.0\nstop = 2.0"), "unknown key time.stop"),
])
def test_a_config_missing_or_adding_a_table_is_refused(small_config, text, fragment):
    with pytest.raises(PrimordiaError) as caught:
        Model.from_file(small_config(text))
    assert fragment in str(caught.value)


def test_an_output_time_given_twice_is_one_output_time():
    """config.toml kept [0.4, 0.4, 1.0], and [0.3, 0.1 + 0.2] as two times on one step."""
    assert small(output={"times": [1.0, 0.4, 0.4]}).output["times"] == [0.4, 1.0]
    assert small(output={"times": [0.6, 0.2 + 0.4, 1.0]}).output["times"] == [0.6, 1.0]


def test_snapshot_fields_may_be_a_tuple_as_output_times_may():
    assert small(output={"times": (0.4, 1.0), "snapshot_fields": ("f", "m")}).output["snapshot_fields"] == ["f", "m"]


def test_a_model_its_mesh_and_its_simulation_say_what_they_are_in_one_line(tmp_path):
    """The default reprs said nothing (``<primordia.model.Model object at 0x...>``), and MeshData's printed every
    coordinate and cell of the mesh."""
    from primordia.coupling.orchestrator import Simulation

    mesh = rectangle((0, 0), (20, 20), cells=(16, 16))
    assert repr(mesh) == ("MeshData(2D, 289 vertices, 512 triangles, boundaries=['bottom', 'left', 'right', 'top'], "
                          "description='rectangle [0, 20] x [0, 20], 16 x 16 squares, diagonal right')")
    model = Model(physics=["chemotaxis"], mesh=mesh, dt=0.2, t_final=2.0, name="quick")
    assert repr(model) == (f"Model(name='quick', physics=['chemotaxis'], kinetics='painter2018', mesh={mesh!r}, "
                           f"dt=0.2, t=0..2, coupling='sequential', backend='fenicsx')")
    sim = Simulation(model, backend="skfem", out_dir=tmp_path)
    assert repr(sim) == f"Simulation('quick' on skfem, setting up, t = 0 after 0 steps, out_dir='{tmp_path}')"
    # its pieces: which, and their settings, not <primordia.physics.chemotaxis.Chemotaxis object at 0x...>
    (chemotaxis,) = model.physics_objects
    assert repr(chemotaxis).startswith("Chemotaxis(name='chemotaxis', settings={'flux_scheme': 'exponential_fitting'")
    assert repr(model.kinetics_object) == "Painter2018(name='painter2018', settings={'priming_wave': True})"


@pytest.mark.parametrize("t_start, dt, t_final, steps", [
    (0.0, 0.1, 0.1 * 7, 7),  # 0.7000000000000001
    (0.0, 0.2, 520.0, 2600),
    (1e6 + 0.1, 0.1, 1e6 + 0.7, 6),  # the subtraction's round-off: 6.000000001 steps
    (0.0, 0.2 / 3, 520.0, 7800),
])
def test_times_off_the_step_grid_by_round_off_only_are_accepted(t_start, dt, t_final, steps):
    model = small(t_start=t_start, dt=dt, t_final=t_final, output={"times": [t_final]})
    assert model.num_steps == steps


def test_the_package_docstring_names_only_what_exists():
    """help(primordia) said one line; it now maps the Python API, and each module, class and name it cites must
    be importable as written."""
    import importlib
    import re

    import primordia

    pieces = primordia.__doc__.split("The pieces", 1)[1]
    cited = 0
    for bullet in pieces.split("\n- "):
        for role, dotted in re.findall(r":(mod|class):`([\w.]+)`", bullet):
            module_name, _, attribute = dotted.rpartition(".") if role == "class" else (dotted, "", "")
            module = importlib.import_module(module_name)
            assert not attribute or hasattr(module, attribute), dotted
            for name in re.findall(r"``(\w+)``", bullet.split(f"`{dotted}`", 1)[1].split(":mod:")[0]):
                assert hasattr(module, name) or hasattr(getattr(module, attribute, None), name), (dotted, name)
                cited += 1
    assert cited >= 10


def test_numpy_scalars_and_tuples_are_taken_where_numbers_flags_and_lists_are():
    """np.int64(3) for an integer option was "must be an integer, got 3", np.bool_(False) "must be true or
    false, got False", and a tuple of boundary conditions "must be a list": what numpy and Python hand a
    notebook user, refused in words that contradicted themselves."""
    import numpy as np

    model = small(physics_options={"chemotaxis": {"seed": np.int64(3)}}, adaptive=np.bool_(False),
                  output={"pictures": np.bool_(False)},
                  coupling={"scheme": "fixed_point", "max_iterations": np.int64(5)})
    assert model.physics_objects[0].settings["seed"] == 3 and type(model.physics_objects[0].settings["seed"]) is int
    assert model.adaptive is False and model.output["pictures"] is False
    assert model.resolved_config()["coupling"]["max_iterations"] == 5
    clamped = ({"boundary": "bottom", "type": "clamped"},)
    grown = small(physics=["chemotaxis", "poroelasticity"], physics_options={"poroelasticity": {"boundary": clamped}})
    assert grown.physics_options["poroelasticity"]["boundary"] == clamped
    # np.linspace for the output times was "must be a list of numbers, got array([...])"
    times = small(output={"times": np.linspace(0.4, 1.0, 4)}).output["times"]
    assert times == pytest.approx([0.4, 0.6, 0.8, 1.0]) and all(type(t) is float for t in times)


def test_a_model_with_tuples_inside_its_options_is_the_model_its_config_toml_describes(tmp_path):
    """A boundary condition's value given as a tuple stayed a tuple in the resolved config, and config.toml gave
    it back as a list: a restart of the same model from Python was refused as "physics.poroelasticity.boundary
    differs from the checkpointed run's"."""
    import tomllib

    import numpy as np

    from primordia.core.json_toml import write_toml

    held = [{"boundary": "bottom", "type": "clamped"},
            {"boundary": "top", "type": "traction", "value": ("0", "s"), "constants": {"s": np.float64(0.1)}}]
    model = small(physics=["chemotaxis", "poroelasticity"], physics_options={"poroelasticity": {"boundary": held}})
    written = write_toml(tmp_path / "config.toml", model.resolved_config())
    assert model.differences(tomllib.loads(written.read_text()), allowed=()) == []


def test_a_run_into_an_empty_out_is_refused(tmp_path, monkeypatch):
    """``Model.run(out="")`` (an unset variable) wrote the whole run into the current folder, among its files,
    where ``--out ""`` and a sweep's ``out=""`` are refused."""
    from primordia.coupling.orchestrator import Simulation

    monkeypatch.chdir(tmp_path)
    for out in ("", "  "):
        with pytest.raises(ConfigError, match=r"^a run's out needs a directory name \(\"\.\" for the current"):
            small().run(out=out)
        with pytest.raises(ConfigError, match="a run's out needs a directory name"):
            Simulation(small(), out_dir=out)
    assert list(tmp_path.iterdir()) == []


def test_a_built_model_is_read_only_by_attribute():
    """model.dt = 0.1 was taken and read back, while the run's output times and physics objects, and its
    config.toml, kept what the model was built with."""
    model = Model(physics=["chemotaxis"], parameters={"m0": 0.75, "D_m": 0.03},
                  mesh=rectangle((0.0, 0.0), (1.0, 1.0), (2, 2)), dt=0.2, t_final=0.4)
    for name, value in (("dt", 0.1), ("t_final", 1.0), ("physics_objects", []), ("a_new_one", 1)):
        with pytest.raises(AttributeError, match=r"^a Model is read-only once built \(model\." + name):
            setattr(model, name, value)
    assert model.dt == 0.2 and model.t_final == 0.4 and not hasattr(model, "a_new_one")
    assert model.step_time(2) == 0.4  # its own caches still work
