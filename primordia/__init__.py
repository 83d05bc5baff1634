"""primordia: feather-bud patterning by chemotaxis on porous, deforming, growing tissue.

From Python (README.md, "The same model in Python", has the whole example)::

    from primordia import Model
    from primordia.core.meshes import rectangle

    model = Model(physics=["chemotaxis"], kinetics="painter2018", parameters={"m0": 0.75},
                  mesh=rectangle((0, 0), (20, 20), cells=(43, 43)), dt=0.2, t_final=20.0)
    sim = model.run(backend="skfem", out="out/quick")   # a Simulation; out/quick holds series.nc, fields.xdmf
    sim.field_statistics()["m"]                         # integral, min, max of m now
    sim.vertex_values()["m"]                            # m at the mesh's vertices (numpy)

The pieces, each with its own docstring:

- :class:`primordia.model.Model`: a validated model (``Model.from_file`` reads a TOML config);
- :mod:`primordia.core.meshes`: ``rectangle``, ``box``, ``read_mesh``; :class:`primordia.core.mesh_data.MeshData`
  for a mesh built by hand;
- :class:`primordia.coupling.orchestrator.Simulation`: one run, what ``Model.run`` returns;
- :mod:`primordia.analysis`: ``linearise_model``, the linear stability of a model;
- :mod:`primordia.analysis.patterns`: ``analyse_run``, ``predicted_mode``, the pattern metrics of a run;
- :mod:`primordia.sweep`: ``Axis``, ``Sweep``, ``run_sweep``, parameter sweeps on dask;
- :mod:`primordia.core.plugins`: ``registry``, the registered physics, kinetics and growth laws;
  :mod:`primordia.testing`, to test a plugin on both backends.
"""

__version__ = "0.1.0"

import os as _os  # noqa: E402

if _os.environ.get("PRIMORDIA_SWEEP_WORKER_STARTING"):  # a sweep's local worker importing this: see primordia.sweep
    import signal as _signal

    _signal.signal(_signal.SIGINT, lambda signum, frame: None)

from primordia.model import Model  # noqa: E402

__all__ = ["Model", "__version__"]
