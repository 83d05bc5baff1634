r"""Cross-validation of the two backends: the same model assembles the same algebra and runs the same.

``fenicsx`` (dolfinx, FFCx-compiled forms) and ``skfem`` (scikit-fem, the same
UFL forms evaluated with numpy) behind one assembly interface:

1. **Assembly, physics by physics.**  For every configuration in :data:`CASES`
   (a list: later physics join it as they land, and
   :func:`test_every_built_in_physics_is_cross_validated` fails until they do),
   the model is built on the same mesh with both backends and run a few steps
   on fenicsx; its state is then copied to skfem DOF by DOF, and at the start of
   the next step (current = an extrapolated guess != previous, so every term of
   every residual is non-zero) each subproblem's residual vector, Jacobian
   matrix (with and without the Dirichlet rows and columns), Newton right-hand
   side with lifting, and algebraic operator (the exponentially fitted flux) are
   assembled by both and compared entry by entry: relative difference (to the
   largest entry) below 1e-10.  DOFs are matched by (value component, node
   coordinates): dolfinx's ``tabulate_dof_coordinates`` of each collapsed
   scalar sub-space against the skfem space's ``dof_component`` / ``dof_coordinates``.
2. **Examples, end to end.**  Seed examples 1a and 1b (``examples/ex01a.toml``,
   ``ex01b.toml``) on 40 x 40 squares to t = 50 (250 steps, same seed) on both
   backends: every field of ``fields.xdmf``, at every snapshot, agrees to 1e-6 in
   relative L2 (measured: ~1e-13).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import meshio
import numpy as np
import pytest
import scipy.sparse

from primordia.core.meshes import rectangle
from primordia.core.plugins import registry
from primordia.coupling.orchestrator import Simulation
from primordia.model import Model
from dof_keys import dof_keys
from generic_meshes import perturbed

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
BACKENDS = ("fenicsx", "skfem")
#: Largest assembled difference allowed, relative to the largest entry.
ASSEMBLY_TOLERANCE = 1e-10
#: Largest relative L2 difference of the example fields.
EXAMPLE_TOLERANCE = 1e-6


# -- the configurations ------------------------------------------------------------------------
#: Every boundary-condition kind of primordia.physics.boundary_conditions, time-dependent where
#: it can be: u kinds one per side, p kinds on two sides each.
EVERY_CONDITION = [
    {"boundary": "left", "type": "clamped"},
    {"boundary": "left", "type": "fluid_pressure", "value": "0.2 * sin(x[1]) * t"},
    {"boundary": "bottom", "type": "normal_displacement", "value": "0.05 * x[0] * t"},
    {"boundary": "bottom", "type": "fluid_pressure", "value": "0.1 * t"},
    {"boundary": "right", "type": "displacement", "value": ["0.02 * x[1] * t", "-0.03 * t * x[1] ** 2"]},
    {"boundary": "right", "type": "fluid_flux", "value": "0.3 * x[1] * t"},
    {"boundary": "top", "type": "traction", "value": ["0.5 * t", "-s0 * sin(pi * t / t_hat) * x[0]"],
     "constants": {"s0": 2.0, "t_hat": 1.0}},
    {"boundary": "top", "type": "fluid_flux", "value": "-0.2"},
]
#: Ex01b's loading (bottom clamped, periodic traction on top), strong enough to move in a few steps.
EX01B_CONDITIONS = [
    {"boundary": "bottom", "type": "clamped"},
    {"boundary": "top", "type": "traction", "value": ["0", "s0 * sin(pi * t / t_hat)"],
     "constants": {"s0": 50.0, "t_hat": 4.0}},
]
MECHANICS = {"E": 100.0, "nu": 0.3, "C_0": 0.1, "kappa": 0.05, "eta": 0.5, "alpha_BW": 0.8, "rho": 1.0}
CHEMISTRY = {"m0": 0.75, "D_m": 0.03}


@dataclass
class Case:
    """A model configuration to cross-validate."""

    name: str
    physics: list[str]
    options: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)
    kinetics: dict | None = None
    growth_law: dict | None = None
    cells: int = 5
    mesh_perturbation: float = 0.0
    steps: int = 3
    dt: float = 0.1

    def model(self) -> Model:
        mesh = rectangle((0.0, 0.0), (2.0, 2.0), (self.cells, self.cells))
        if self.mesh_perturbation:
            mesh = perturbed(mesh, self.mesh_perturbation * 2.0 / self.cells, seed=3)
        return Model(physics=self.physics, kinetics=self.kinetics, parameters=self.parameters, mesh=mesh,
                     dt=self.dt, t_final=(self.steps + 1) * self.dt, physics_options=self.options,
                     output={"pictures": False, "series_every": 10**6}, growth_law=self.growth_law)


def _chemotaxis(flux_scheme: str) -> dict:
    return {"flux_scheme": flux_scheme, "perturbation": 0.3, "seed": 7}


def _poroelasticity(degree: int, boundary: list, **extra) -> dict:
    return {"displacement_degree": degree, "boundary": boundary, **extra}


PAINTER2018 = {"name": "painter2018", "priming_wave": True}
#: Finite-strain growth (seed section 4): every condition kind it uses, the seed's 2D law, faster growth.
GROWTH_CONDITIONS = [
    {"boundary": "left", "type": "normal_displacement"},
    {"boundary": "right", "type": "robin", "value": "0.5 * (1 + 0.2 * x[1])"},
    {"boundary": "top", "type": "robin", "value": "0.3"},
    {"boundary": "bottom", "type": "traction", "value": ["0.1 * t", "-0.2 * x[0] * t"]},
    {"boundary": "top", "type": "fluid_pressure", "value": "0.05 * x[0] * t"},
    {"boundary": "right", "type": "fluid_flux", "value": "0.1 * x[1]"},
]
GROWTH = {"delta_2": 0.5, "delta_3": 0.4, "kappa": 0.05, "C_0": 0.1, "alpha_BW": 0.5, "ell_0": 0.2, "xi_f": 0.3}
CASES = [
    Case("chemotaxis-exponential_fitting", ["chemotaxis"], {"chemotaxis": _chemotaxis("exponential_fitting")},
         {**CHEMISTRY, "omega_3": 1.0}, PAINTER2018),
    Case("chemotaxis-galerkin", ["chemotaxis"], {"chemotaxis": _chemotaxis("galerkin")},
         {**CHEMISTRY, "omega_3": 1.0}, PAINTER2018, mesh_perturbation=0.15),
    Case("poroelasticity-P1-P1", ["poroelasticity"], {"poroelasticity": _poroelasticity(1, EVERY_CONDITION)},
         MECHANICS, mesh_perturbation=0.15),
    Case("poroelasticity-P2-P1", ["poroelasticity"], {"poroelasticity": _poroelasticity(2, EVERY_CONDITION)},
         MECHANICS, mesh_perturbation=0.15),
    Case("poroelasticity-P1-P1-lame-conductivity", ["poroelasticity"],
         {"poroelasticity": _poroelasticity(1, EVERY_CONDITION, shear_modulus=30.0, lame_lambda=80.0,
                                            conductivity="kappa * (1 + 0.5 * x[0] * x[1])")},
         MECHANICS, mesh_perturbation=0.15),
    Case("ex01b-coupled-P1-P1", ["chemotaxis", "poroelasticity", "active_stress", "mechanochemical"],
         {"chemotaxis": _chemotaxis("exponential_fitting"), "poroelasticity": _poroelasticity(1, EX01B_CONDITIONS)},
         {**CHEMISTRY, **MECHANICS, "tau": 2.0, "xi_f": 0.5, "zeta": 1.0, "omega_3": 1.0}, PAINTER2018),
    Case("ex01b-coupled-P2-P1-galerkin", ["chemotaxis", "poroelasticity", "active_stress", "mechanochemical"],
         {"chemotaxis": _chemotaxis("galerkin"), "poroelasticity": _poroelasticity(2, EX01B_CONDITIONS)},
         {**CHEMISTRY, **MECHANICS, "tau": 2.0, "xi_f": 0.5, "zeta": 1.0, "omega_3": 1.0}, PAINTER2018,
         mesh_perturbation=0.15),
    Case("ex02a-growth-fitted", ["chemotaxis", "poroelastic_growth", "mechanochemical"],
         {"chemotaxis": _chemotaxis("exponential_fitting"), "poroelastic_growth": {"boundary": GROWTH_CONDITIONS}},
         {**CHEMISTRY, **GROWTH, "omega_3": 1.0}, PAINTER2018, growth_law={"name": "seed2d"}, cells=4),
    Case("ex02a-growth-galerkin-conservative", ["chemotaxis", "poroelastic_growth", "mechanochemical"],
         {"chemotaxis": {**_chemotaxis("galerkin"), "accumulation": "conservative"},
          "poroelastic_growth": {"boundary": GROWTH_CONDITIONS, "quadrature_degree": 3}},
         {**CHEMISTRY, **GROWTH, "omega_3": 1.0}, PAINTER2018, growth_law={"name": "seed2d"}, cells=4,
         mesh_perturbation=0.15),
]


def test_every_built_in_physics_is_cross_validated():
    built_in = {name for name, (_, source) in registry("physics").items() if source == "primordia (built-in)"}
    covered = {name for case in CASES for name in case.physics}
    assert built_in, "no built-in physics registered"
    assert built_in <= covered, f"physics without a cross-validation case: {sorted(built_in - covered)}"


# -- DOF matching ---------------------------------------------------------------------------------
class DofMap:
    """Orders of the DOFs of each space of both backends, by (component, coordinates)."""

    def __init__(self, sims: dict):
        self.sims = sims
        self._orders: dict = {}

    def order(self, backend_name: str, space) -> np.ndarray:
        key = (backend_name, id(space))
        if key not in self._orders:
            keys = np.round(dof_keys(backend_name, space, self.sims[backend_name].disc.gdim), 9)
            self._orders[key] = (space, np.lexsort(keys.T[::-1]), keys)
        return self._orders[key][1]

    def check(self, reference_space, other_space) -> None:
        """The two spaces have the same DOFs (component and node), one to one."""
        (_, ref_order, ref_keys), (_, order, keys) = (
            self._orders[("fenicsx", id(reference_space))], self._orders[("skfem", id(other_space))])
        assert len(ref_keys) == len(keys), "the backends' spaces differ in size"
        assert np.unique(ref_keys, axis=0).shape[0] == len(ref_keys), "DOF keys are not unique"
        np.testing.assert_allclose(ref_keys[ref_order], keys[order], atol=1e-8)


# -- states ------------------------------------------------------------------------------------------
def group_functions(disc, group: str) -> dict:
    """The state functions of a field group: current, previous, rate if used, and the copies taken at other
    groups' balances (``at_balance``), by kind."""
    return {key.partition("/")[2]: function for key, function in disc.state_functions().items()
            if key.partition("/")[0] == group}


def start_next_step(sim) -> None:
    """What the orchestrator does before the solves of a step; then current = 2 u^n - u^{n-1} (a guess)."""
    disc, t, dt = sim.disc, sim.time + sim.dt, sim.dt
    guess = {}
    for group in disc.groups():
        functions = group_functions(disc, group)
        guess[group] = 2.0 * sim.backend.local_array(functions["current"]) \
            - sim.backend.local_array(functions["previous"])
    disc.set_time(t, dt)
    for physics in sim.model.physics_objects:
        physics.before_step(t, dt)
    disc.store_previous()
    for group in disc.groups():
        sim.backend.local_array(group_functions(disc, group)["current"])[:] = guess[group]


def copy_state(sims: dict, dofs: DofMap) -> None:
    """skfem's fields, previous values and rates <- fenicsx's, DOF by DOF; the same time."""
    reference, other = sims["fenicsx"], sims["skfem"]
    for group in reference.disc.groups():
        source, target = group_functions(reference.disc, group), group_functions(other.disc, group)
        assert set(source) == set(target), f"{group}: the backends keep different states"
        for kind, function in source.items():
            space, other_space = function.ufl_function_space(), target[kind].ufl_function_space()
            order, other_order = dofs.order("fenicsx", space), dofs.order("skfem", other_space)
            dofs.check(space, other_space)
            values = other.backend.local_array(target[kind])
            values[other_order] = reference.backend.local_array(function)[order]
            other.backend.update_ghosts(target[kind])
    other.time, other.step_index = reference.time, reference.step_index
    for sim in sims.values():
        sim._vertex_cache = None  # vertex values are cached per step: the state changed within one
    other.disc.set_time(reference.disc.time, float(reference.disc.dt.value))
    for physics in other.model.physics_objects:
        physics.before_step(other.disc.time, float(other.disc.dt.value))


# -- assembled objects, mapped to a common DOF order -------------------------------------------------
def argument_spaces(form) -> list:
    return [a.ufl_function_space() for a in sorted(form.arguments(), key=lambda a: a.number())]


def mapped_vector(vector, order) -> np.ndarray:
    return vector.array.copy()[order]


def mapped_matrix(matrix, row_order, column_order) -> np.ndarray:
    indptr, indices, values = matrix.getValuesCSR()
    dense = scipy.sparse.csr_matrix((values, indices, indptr), shape=matrix.getSize()).toarray()
    return dense[np.ix_(row_order, column_order)]


def assembled_objects(sim, dofs: DofMap, sub) -> dict[str, np.ndarray]:
    """Residual, Jacobian (without and with Dirichlet conditions), Newton right-hand side, operator."""
    backend, name = sim.backend, sim.backend.name
    (test,) = argument_spaces(sub.residual)
    rows, columns = (dofs.order(name, space) for space in argument_spaces(sub.jacobian))
    objects = {
        "residual": mapped_vector(backend.assemble_vector(sub.residual), dofs.order(name, test)),
        "jacobian": mapped_matrix(backend.assemble_matrix(sub.jacobian), rows, columns),
    }
    if sub.bcs:
        objects["jacobian with Dirichlet rows"] = mapped_matrix(backend.assemble_matrix(sub.jacobian, sub.bcs),
                                                                rows, columns)
        objects["Newton right-hand side"] = mapped_vector(
            backend.assemble_residual(sub.residual, sub.jacobian, sub.bcs, sub.unknown), rows)
    if sub.operator is not None:
        sub.operator.update()
        objects["algebraic operator"] = mapped_matrix(sub.operator.matrix(), rows, columns)
    return objects


@pytest.fixture(scope="module", params=CASES, ids=[case.name for case in CASES])
def case_sims(request, tmp_path_factory):
    """The case on both backends, fenicsx run a few steps, skfem given the same state."""
    case = request.param
    out = tmp_path_factory.mktemp(case.name)
    sims = {backend: Simulation(case.model(), backend=backend, out_dir=out / backend).setup()
            for backend in BACKENDS}
    for _ in range(case.steps):
        sims["fenicsx"].step()
    start_next_step(sims["fenicsx"])
    dofs = DofMap(sims)
    copy_state(sims, dofs)
    return case, sims, dofs


def test_states_are_non_trivial_and_identical(case_sims):
    case, sims, _ = case_sims
    values = {backend: sim.vertex_values() for backend, sim in sims.items()}
    assert set(values["fenicsx"]) == set(values["skfem"])
    for name, reference in values["fenicsx"].items():
        assert np.ptp(reference) > 1e-6, f"{case.name}: field {name} is uniform, nothing is tested"
        np.testing.assert_allclose(values["skfem"][name], reference, rtol=0, atol=1e-13 * np.abs(reference).max())


def test_subproblems_assemble_the_same_algebra(case_sims):
    case, sims, dofs = case_sims
    subproblems = {backend: [solver.sub for solver in sim.solvers] for backend, sim in sims.items()}
    assert [s.name for s in subproblems["fenicsx"]] == [s.name for s in subproblems["skfem"]]
    assert subproblems["fenicsx"], f"{case.name} has no subproblem"
    report, compared = [], 0
    for reference_sub, other_sub in zip(subproblems["fenicsx"], subproblems["skfem"]):
        reference = assembled_objects(sims["fenicsx"], dofs, reference_sub)
        other = assembled_objects(sims["skfem"], dofs, other_sub)
        assert set(reference) == set(other)
        for what, expected in reference.items():
            scale = np.abs(expected).max()
            assert scale > 0.0, f"{case.name}, {reference_sub.name}: the {what} is zero, nothing is tested"
            difference = np.abs(other[what] - expected).max() / scale
            report.append(f"{reference_sub.name:24s} {what:30s} {expected.shape} relative difference {difference:.1e}")
            compared += 1
            assert difference < ASSEMBLY_TOLERANCE, "\n".join(report)
    print(f"[{case.name}]\n" + "\n".join(report))
    assert compared >= 2 * len(subproblems["fenicsx"])


# -- the examples, end to end ----------------------------------------------------------------------
COARSE = ["mesh.cells=[40, 40]", "time.t_final=50.0", "output.times=[25.0, 50.0]", "output.pictures=false"]


def read_fields(out: Path) -> list[tuple[float, dict]]:
    with meshio.xdmf.TimeSeriesReader(out / "fields.xdmf") as reader:
        reader.read_points_cells()
        return [reader.read_data(k)[:2] for k in range(reader.num_steps)]


@pytest.mark.parametrize("example, fields", [("ex01a", {"m", "e", "f", "b"}),
                                             ("ex01b", {"m", "e", "f", "b", "u", "p"})])
def test_examples_agree_on_both_backends(example, fields, tmp_path):
    frames = {}
    for backend in BACKENDS:
        model = Model.from_file(EXAMPLES / f"{example}.toml", COARSE)
        sim = model.run(backend=backend, out=tmp_path / backend)
        assert sim.status == "completed" and sim.time == pytest.approx(50.0)
        frames[backend] = read_fields(tmp_path / backend)
    assert [t for t, _ in frames["fenicsx"]] == [t for t, _ in frames["skfem"]] == [25.0, 50.0]
    report = []
    for (t, reference), (_, other) in zip(frames["fenicsx"], frames["skfem"]):
        assert set(reference) == set(other) == fields
        for name in sorted(fields):
            assert np.ptp(reference[name]) > 0.0, f"{example}: {name} is uniform at t = {t:g}"
            difference = np.linalg.norm(other[name] - reference[name]) / np.linalg.norm(reference[name])
            report.append(f"t = {t:g} {name}: relative L2 difference {difference:.1e}")
            assert difference < EXAMPLE_TOLERANCE, "\n".join(report)
    print(f"[{example}]\n" + "\n".join(report))


@pytest.mark.parametrize("scheme", ["strang", "fixed_point", "monolithic"])
def test_every_splitting_scheme_agrees_on_both_backends(scheme, tmp_path):
    """Example 1b, coarse and short, under each non-default scheme: the backends give the same fields."""
    overrides = ["mesh.cells=[12,12]", "time.t_final=4", "output.times=[4]", "output.pictures=false",
                 f'coupling.scheme="{scheme}"']
    if scheme == "monolithic":
        overrides.append('physics.chemotaxis.flux_scheme="galerkin"')
    fields = {}
    for backend in BACKENDS:
        Model.from_file(EXAMPLES / "ex01b.toml", overrides).run(backend=backend, out=tmp_path / backend)
        fields[backend] = read_fields(tmp_path / backend)[-1][1]
    for name, reference in fields["fenicsx"].items():
        assert np.ptp(reference) > 0.0, name
        difference = np.linalg.norm(fields["skfem"][name] - reference) / np.linalg.norm(reference)
        assert difference < EXAMPLE_TOLERANCE, (scheme, name, difference)
