"""Lumped forms evaluated at the nodes (coupling/nodal.py) equal their cell-by-cell assembly."""

import numpy as np
import pytest
import ufl
from mpi4py import MPI
from ufl.algorithms.apply_algebra_lowering import apply_algebra_lowering

from primordia.backends.fenicsx import FenicsxBackend
from primordia.backends.skfem import SkfemBackend
from primordia.core.meshes import box, rectangle
from primordia.backends.ufl_numpy import evaluate_integrand
from primordia.coupling.nodal import NodalGroup, _NodeContext, _shared_subexpressions, nodal_form
from primordia.coupling.nodal_program import NodalProgram

BACKENDS = {"fenicsx": lambda: FenicsxBackend(MPI.COMM_WORLD), "skfem": lambda: SkfemBackend()}


@pytest.fixture(params=list(BACKENDS))
def backend(request):
    return BACKENDS[request.param]()


def _p1_fields(backend, mesh, names, seed=3):
    """P1 fields with random positive vertex values, each in its own space (as the species are)."""
    rng = np.random.default_rng(seed)
    fields = []
    for name in names:
        space = backend.function_space(mesh, ufl.FiniteElement("Lagrange", mesh.ufl_cell(), 1))
        field = backend.function(space, name)
        backend.local_array(field)[:] = rng.uniform(0.1, 2.0, backend.local_array(field).shape)
        fields.append(field)
    return fields


def _reaction_form(backend, mesh):
    """The shape of the seed's explicit reactions (2.3b)-(2.3d): rational, exponential, a
    conditional on time and position, constants, several species, and two measures."""
    m, b, e = _p1_fields(backend, mesh, "mbe")
    v = ufl.TestFunction(e.ufl_function_space())
    x = ufl.SpatialCoordinate(mesh)
    t = backend.constant(mesh, 3.0)
    k = backend.constant(mesh, 0.05)
    dx_lumped = backend.lumped_dx(mesh)
    wave = ufl.conditional(ufl.lt(x[0], 0.4 * t), 1.0, 0.0)
    production = k * m * m / (1 + b ** 2) + wave * ufl.exp(-m) + 0.3 * x[1] ** 2
    form = -(production - 2.0 * e) * v * dx_lumped - e * m * v * backend.lumped_dx(mesh)
    other_measure = backend.measure("dx", mesh, metadata={"quadrature_rule": "vertex", "quadrature_degree": 2})
    return form + abs(b - 1.0) * v * other_measure, t


@pytest.mark.filterwarnings("ignore:Explicitly selected vertex quadrature")  # FFCx on the second measure
@pytest.mark.parametrize("make_mesh", [lambda: rectangle((0, 0), (2, 1), (7, 5)),
                                       lambda: box((0, 0, 0), (1, 1, 1), (3, 3, 2))], ids=["2d", "3d"])
def test_a_lumped_reaction_at_the_nodes_is_its_assembly(backend, make_mesh):
    mesh = backend.create_mesh(make_mesh())
    form, time = _reaction_form(backend, mesh)
    nodal = nodal_form(backend, form)
    assert nodal is not None
    for t in (3.0, 6.0):  # a changed constant is read at the next evaluation
        time.value = t
        expected = backend.assemble_vector(form).getArray()
        got = nodal.assemble().getArray()
        assert np.abs(expected).max() > 1e-3
        assert np.allclose(got, expected, rtol=1e-13, atol=1e-15)


def test_forms_evaluated_together_equal_their_assembly_and_follow_the_fields(backend):
    """A solve's remainder and its Jacobian's diagonal, as AffineResidual evaluates them: one
    pass for both, and a new pass once a member asks again or the group is expired."""
    mesh = backend.create_mesh(rectangle((0, 0), (2, 1), (6, 4)))
    m, e = _p1_fields(backend, mesh, "me")
    v = ufl.TestFunction(e.ufl_function_space())
    hill = m ** 2 / (1 + m ** 2)
    remainder = -(0.05 * hill - e * (0.05 * hill + 1 - hill)) * v * backend.lumped_dx(mesh)
    diagonal = (0.05 * hill + 1 - hill) * v * backend.lumped_dx(mesh)
    group = NodalGroup(backend)
    first, second = nodal_form(backend, remainder, group), nodal_form(backend, diagonal, group)

    def check():
        assert np.allclose(first.assemble().getArray(), backend.assemble_vector(remainder).getArray(), rtol=1e-13)
        assert np.allclose(second.assemble().getArray(), backend.assemble_vector(diagonal).getArray(), rtol=1e-13)

    check()
    backend.local_array(m)[:] *= 1.5  # the fields move: the remainder asks again, so both are evaluated anew
    check()
    backend.local_array(m)[:] *= 2.0
    group.expire()  # the start of a solve
    assert np.allclose(second.assemble().getArray(), backend.assemble_vector(diagonal).getArray(), rtol=1e-13)


def _interpreted(integrands, context) -> np.ndarray:
    with np.errstate(all="ignore"):
        values = evaluate_integrand(ufl.as_vector(integrands), context)
    return np.broadcast_to(np.reshape(values, (len(integrands), -1)), (len(integrands), context.size))


def test_the_compiled_program_gives_the_interpreters_numbers_bit_for_bit(backend):
    """Every node kind the program compiles, against the UFL interpreter it replaces: literal
    powers (numpy's fast cases), constants read at each run, the coordinates, conditionals of
    arrays and of scalars, math functions, min/max, abs, and a field as a whole integrand."""
    mesh = backend.create_mesh(rectangle((0, 0), (2, 1), (7, 5)))
    m, e = _p1_fields(backend, mesh, "me")
    x = ufl.SpatialCoordinate(mesh)
    t, k = backend.constant(mesh, 3.0), backend.constant(mesh, (0.5, 2.0))
    hill = m ** 2 / (1 + m ** 2)
    integrands = [
        -(0.05 * 0.5 * (1.0 + ufl.tanh(5.0 * (t - x[1] / 0.04))) * hill - e * (hill + 1 - hill)) + e / t,
        ufl.conditional(ufl.lt(x[0], 0.4 * t), m ** 0.5, e ** -1.0) + ufl.conditional(ufl.gt(t, 2.0), 1.0, 2.0),
        ufl.conditional(ufl.And(ufl.ge(m, 1.0), ufl.Not(ufl.eq(e, 0.0))), ufl.exp(-m), abs(e - 1.0)),
        ufl.max_value(m, k[1]) * ufl.min_value(e, k[0]) + m ** 3.0 + m ** t + ufl.atan_2(m, e) + ufl.ln(m) * ufl.erf(e),
        m,
        t * k[0] + 2.0,
        -(-(m * e)) - 2.0 * m + (-e + 3.0),  # -(-a) is a; a + (-1 b) is a - b, in either order
    ]
    integrands.insert(-1, ufl.conj(m) * ufl.real(e) + ufl.variable(m * e))  # the operand's value itself
    context = _NodeContext(backend, m.ufl_function_space())
    program = NodalProgram.compile(integrands, context.coordinates, context.field, context.constant)
    assert program is not None
    for time in (3.0, 1.5):  # a changed constant is read at the next run, and the fields are
        t.value = time
        backend.local_array(m)[:] *= 1.1
        expected = _interpreted(integrands, context)
        got = program.run()
        assert got.shape == expected.shape
        assert np.array_equal(got, expected)
    # buffers are shared by values that do not overlap in time, and the integrands are computed into the
    # result but for the two that are read whole (m and a constant)
    arrays = [buffer for buffer in program._buffers if buffer is not None]
    assert len({id(buffer) for buffer in arrays}) < len(arrays) / 2
    assert len(program._copies) == 2
    # the last integrand: -(-a) is a, and a + (-1 b) is a - b: no multiplication by -1 is left
    last = NodalProgram.compile(integrands[-1:], context.coordinates, context.field, context.constant)
    assert sorted(function.__name__ for function, *_ in last._code) == ["add", "multiply", "multiply", "subtract",
                                                                       "subtract"]
    assert np.array_equal(last.run(), expected[-1:])


def test_an_integrand_the_program_does_not_know_keeps_the_interpreter(backend):
    mesh = backend.create_mesh(rectangle((0, 0), (2, 1), (6, 4)))
    m, e = _p1_fields(backend, mesh, "me")
    context = _NodeContext(backend, m.ufl_function_space())
    k = backend.constant(mesh, (0.5, 2.0))
    contracted = apply_algebra_lowering(ufl.dot(k, ufl.as_vector([m, e * e])))  # nodal, but a sum over an index
    assert NodalProgram.compile([m * 2.0, contracted], context.coordinates, context.field, context.constant) is None
    v = ufl.TestFunction(m.ufl_function_space())
    form = (m * 2.0 + ufl.dot(k, ufl.as_vector([m, e * e]))) * v * backend.lumped_dx(mesh)
    nodal = nodal_form(backend, form)
    assert nodal is not None
    assert np.allclose(nodal.assemble().getArray(), backend.assemble_vector(form).getArray(), rtol=1e-13)
    assert nodal._group._program is False  # the interpreter evaluated it


def test_equal_subexpressions_become_one_node():
    mesh = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.triangle, 1))
    m = ufl.Coefficient(ufl.FunctionSpace(mesh, ufl.FiniteElement("Lagrange", ufl.triangle, 1)))
    first, second = m ** 2 / (1 + m ** 2), m ** 2 / (1 + m ** 2)
    assert first is not second
    shared = _shared_subexpressions(first * 0.5 + second * (1 - second), {})
    quotients = {id(node) for node in ufl.corealg.traversal.pre_traversal(shared) if isinstance(node, ufl.classes.Division)}
    assert len(quotients) == 1
    assert shared == first * 0.5 + second * (1 - second)  # last: UFL's == rewires equal operands in place


def test_a_form_that_is_not_nodal_is_left_to_assembly(backend):
    mesh = backend.create_mesh(rectangle((0, 0), (1, 1), (4, 4)))
    cell = mesh.ufl_cell()
    (m,) = _p1_fields(backend, mesh, "m")
    v = ufl.TestFunction(m.ufl_function_space())
    lumped, exact = backend.lumped_dx(mesh), backend.measure("dx", mesh)
    p2 = backend.function(backend.function_space(mesh, ufl.FiniteElement("Lagrange", cell, 2)), "q")
    vector = backend.function(backend.function_space(mesh, ufl.VectorElement("Lagrange", cell, 1)), "w")
    refused = {
        "a gradient of a field (discontinuous at the vertices)": ufl.grad(m)[0] * v * lumped,
        "a gradient of the test function": ufl.grad(v)[0] * m * lumped,
        "a P2 field": p2 * v * lumped,
        "a vector field": vector[0] * v * lumped,
        "Gauss quadrature (not lumped)": m * v * exact,
        "a boundary integral": m * v * backend.measure("ds", mesh),
        "a cell quantity": ufl.CellVolume(mesh) * v * lumped,
        "a bilinear form": m * v * ufl.TrialFunction(m.ufl_function_space()) * lumped,
    }
    for what, form in refused.items():
        assert nodal_form(backend, form) is None, what
    assert nodal_form(backend, m * v * lumped + m * m * v * lumped) is not None


def test_a_field_on_a_space_with_other_dofs_is_refused():
    """Nodal values line up only when every field numbers its DOFs as the test space does."""
    backend = FenicsxBackend(MPI.COMM_WORLD)
    mesh = backend.create_mesh(rectangle((0, 0), (1, 1), (4, 4)))
    other = backend.create_mesh(rectangle((0, 0), (1, 1), (4, 4)))
    (m,) = _p1_fields(backend, mesh, "m")
    (n,) = _p1_fields(backend, other, "n")
    assert not backend.shares_dofs(m.ufl_function_space(), n.ufl_function_space())
    v = ufl.TestFunction(m.ufl_function_space())
    assert nodal_form(backend, n * v * backend.lumped_dx(mesh)) is None


def test_a_backend_without_the_optional_dof_layout_assembles_and_agrees(tmp_path):
    """Contract 1.3: ``shares_dofs`` / ``owned_dof_coordinates`` are optional. A backend written for 1.2
    (without them) assembles the lumped reactions, and its run equals the nodal evaluation's."""
    from contract_backends import Contract12Plugin
    from primordia.coupling.orchestrator import Simulation
    from primordia.model import Model
    from primordia.testing import registered

    def run(backend):
        model = Model.from_file("examples/ex01a.toml", ["mesh.cells=[6,6]", "time.t_final=1.0",
                                                        "output.times=[1.0]", "output.pictures=false"])
        sim = Simulation(model, backend=backend, out_dir=tmp_path / backend).setup()
        while sim.step_index < model.num_steps:
            sim.step()
        nodal = [solver._affine._nodal_remainder for solver in sim.solvers if solver._affine.remainder is not None]
        return {name: sim.backend.local_array(sim.disc.field(name)).copy() for name in "mefb"}, nodal

    with registered(Contract12Plugin()):
        assembled, none = run("skfem_contract_1_2")
    evaluated, nodal = run("skfem")
    assert none and all(form is None for form in none) and all(form is not None for form in nodal)
    for name in "mefb":
        np.testing.assert_allclose(assembled[name], evaluated[name], rtol=1e-11, atol=1e-13)
