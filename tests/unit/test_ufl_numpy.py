"""The numpy UFL evaluator of the scikit-fem backend, checked against dolfinx / FFCx.

Each form is built once per backend on the same (slightly perturbed) mesh, with
fields interpolated from the same functions, and assembled by both: functionals
are compared directly, vectors and matrices entry by entry after mapping the
DOFs of one backend onto the other's (by component and node coordinates).
"""

from __future__ import annotations

import gc
import math
import sys
from dataclasses import dataclass, field

import numpy as np
import pytest
import scipy.sparse
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from primordia.backends import skfem as skfem_backend
from primordia.backends import ufl_numpy
from primordia.backends.fenicsx import FenicsxBackend
from primordia.backends.skfem import SkfemBackend
from primordia.backends.ufl_numpy import (
    UnsupportedUFL,
    evaluate_integrand,
    integrate_integrand,
    preprocess_form,
    reference_quadrature,
)
from primordia.core.mesh_data import MeshData
from primordia.core.meshes import box, rectangle
from dof_keys import dolfinx_dof_keys, skfem_dof_keys
from generic_meshes import perturbed

#: Largest difference allowed, relative to the largest entry.
TOLERANCE = 1e-10
CELLS = ("triangle", "tetrahedron")


def mesh_data(cell: str) -> MeshData:
    if cell == "triangle":
        return perturbed(rectangle((0.0, 0.0), (1.0, 1.5), (3, 4)), 0.05)
    return perturbed(box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (2, 2, 2)), 0.04)


@dataclass
class Setup:
    """Spaces and fields of one backend, the same for both."""

    backend: object
    data: MeshData
    mesh: object
    spaces: dict = field(default_factory=dict)
    fields: dict = field(default_factory=dict)

    @property
    def gdim(self) -> int:
        return self.data.gdim

    @property
    def domain(self):
        return self.mesh.ufl_domain()

    def __getitem__(self, name: str):
        """A field or constant by name."""
        return self.fields[name]

    def trial(self, space: str):
        return ufl.TrialFunction(self.spaces[space])

    def test(self, space: str):
        return ufl.TestFunction(self.spaces[space])


def positive(x):
    return 0.3 + x[0] ** 2 + 0.5 * x[1]


def wavy(x):
    return 0.5 + 0.5 * np.sin(2.0 * x[0]) + x[1] ** 2


def displacement(x):
    parts = [0.1 * x[0] * x[1], 0.2 * np.sin(x[0]) - 0.05 * x[1]]
    return np.stack(parts + ([0.1 * x[2] ** 2 + 0.05 * x[0]] if len(x) == 3 else []))


def setup(backend, data: MeshData) -> Setup:
    mesh = backend.create_mesh(data)
    s = Setup(backend, data, mesh)
    cell = s.domain.ufl_cell()
    P1, P2 = ufl.FiniteElement("Lagrange", cell, 1), ufl.FiniteElement("Lagrange", cell, 2)
    s.spaces = {
        "P1": backend.function_space(mesh, P1),
        "P2": backend.function_space(mesh, P2),
        "vector P1": backend.function_space(mesh, ufl.VectorElement("Lagrange", cell, 1)),
        "vector P2": backend.function_space(mesh, ufl.VectorElement("Lagrange", cell, 2)),
        "Taylor-Hood": backend.function_space(mesh, ufl.MixedElement([ufl.VectorElement("Lagrange", cell, 2), P1])),
        "P2-P1-P1": backend.function_space(mesh, ufl.MixedElement([ufl.VectorElement("Lagrange", cell, 2), P1, P1])),
    }
    fields = {"m": ("P1", positive), "c": ("P2", wavy), "u": ("vector P2", displacement),
              "u1": ("vector P1", displacement)}
    for name, (space, values) in fields.items():
        s.fields[name] = backend.function(s.spaces[space], name)
        backend.interpolate(s.fields[name], values)
    s.fields["T"] = backend.function(backend.function_space(mesh, ufl.TensorElement("Lagrange", cell, 1)), "T")
    backend.interpolate(s.fields["T"], lambda x: np.vstack([displacement(x) * (i + 1) for i in range(data.gdim)]))
    s.fields["w"] = backend.function(s.spaces["Taylor-Hood"], "w")
    backend.interpolate_component(s.fields["w"], 0, displacement)
    backend.interpolate_component(s.fields["w"], 1, positive)
    s.fields["growth"] = backend.function(s.spaces["P2-P1-P1"], "growth")
    for component, values in enumerate((displacement, positive, wavy)):
        backend.interpolate_component(s.fields["growth"], component, values)
    s.fields["k"] = backend.constant(mesh, 1.7)
    s.fields["a"] = backend.constant(mesh, np.linspace(0.5, 1.0, data.gdim))
    return s


@pytest.fixture(scope="module", params=CELLS)
def pair(request):
    data = mesh_data(request.param)
    return setup(FenicsxBackend(MPI.COMM_WORLD), data), setup(SkfemBackend(), data)


# -- DOF matching ---------------------------------------------------------------------------


def sorting(keys: np.ndarray) -> np.ndarray:
    """DOF order by (component, coordinates); the sorted keys must match between backends."""
    rounded = np.round(keys, 9)
    return np.lexsort(rounded.T[::-1])


def assembled(setup_: Setup, form):
    """The form assembled by the setup's backend, and its DOF orders (one per argument)."""
    backend = setup_.backend
    spaces = [a.ufl_function_space() for a in sorted(form.arguments(), key=lambda a: a.number())]
    keys = [dolfinx_dof_keys(s, setup_.gdim) if backend.name == "fenicsx" else skfem_dof_keys(s) for s in spaces]
    orders = [sorting(k) for k in keys]
    if not spaces:
        return backend.assemble_scalar(form), orders, keys
    if len(spaces) == 1:
        return backend.assemble_vector(form).array.copy()[orders[0]], orders, keys
    A = backend.assemble_matrix(form)
    indptr, indices, values = A.getValuesCSR()
    dense = scipy.sparse.csr_matrix((values, indices, indptr), shape=A.getSize()).toarray()
    return dense[np.ix_(orders[0], orders[1])], orders, keys


def assert_same(pair_, build):
    """Assemble ``build(setup)`` with both backends and compare entry by entry."""
    (reference, ref_orders, ref_keys), (result, orders, keys) = (assembled(s, build(s)) for s in pair_)
    for ref_k, ref_o, k, o in zip(ref_keys, ref_orders, keys, orders):
        np.testing.assert_allclose(np.round(ref_k[ref_o], 9), np.round(k[o], 9), atol=1e-8)
    reference, result = np.asarray(reference), np.asarray(result)
    scale = np.abs(reference).max()
    assert scale > 0.0
    difference = np.abs(result - reference).max() / scale
    assert difference < TOLERANCE, f"relative difference {difference:.2e}"
    return reference


# -- forms, one or a few operators each -------------------------------------------------------


def deformation_gradient(s, u=None):
    u = s.fields["u"] if u is None else u
    return ufl.Identity(s.gdim) + ufl.grad(u)


def neo_hookean_energy(s, u=None):
    F = deformation_gradient(s, u)
    J = ufl.det(F)
    mu, lmbda = 1.3, s.fields["k"]
    psi = mu / 2 * (ufl.tr(F.T * F) - s.gdim) - mu * ufl.ln(J) + lmbda / 2 * ufl.ln(J) ** 2
    return psi * ufl.dx(metadata={"quadrature_degree": 4})


def first_piola_stress(s):
    """dpsi/dF through ufl.variable / ufl.diff (Variable and VariableDerivative nodes)."""
    F = ufl.variable(deformation_gradient(s))
    psi = 0.65 * (ufl.tr(F.T * F) - s.gdim) - 1.3 * ufl.ln(ufl.det(F)) + s.fields["k"] / 2 * ufl.ln(ufl.det(F)) ** 2
    return ufl.diff(psi, F)


def neo_hookean_residual(s, u=None):
    u = s.fields["u"] if u is None else u
    return ufl.derivative(neo_hookean_energy(s, u), u, s.test("vector P2"))


LUMPED = {"quadrature_rule": "vertex", "quadrature_degree": 1}
DEGREE_4 = {"quadrature_degree": 4}


def ds(s, tags):
    return s.backend.measure("ds", s.mesh)(tags)


FORMS = {
    # differential operators
    "grad P1 matrix": lambda s: ufl.inner(ufl.grad(s.trial("P1")), ufl.grad(s.test("P1"))) * ufl.dx,
    "grad P2 matrix + mass": lambda s: (ufl.inner(ufl.grad(s.trial("P2")), ufl.grad(s.test("P2")))
                                        + s.trial("P2") * s.test("P2")) * ufl.dx,
    "grad of vector field": lambda s: ufl.inner(ufl.grad(s.trial("vector P2")), ufl.grad(s.test("vector P2")))
                                      * ufl.dx,
    "div vector": lambda s: ufl.div(s["u"]) * s.test("P1") * ufl.dx,
    "div rectangular matrix": lambda s: ufl.div(s.trial("vector P2")) * s.test("P1") * ufl.dx,
    "second derivatives": lambda s: (ufl.div(ufl.grad(s["c"])) * s.test("P2")
                                     + ufl.inner(ufl.grad(ufl.grad(s["c"])), ufl.grad(ufl.grad(s.test("P2")))))
                                    * ufl.dx,
    # tensor algebra
    "inner dot": lambda s: (ufl.dot(s["u"], ufl.grad(s.test("P2")))
                            + ufl.inner(ufl.grad(s["u"]), ufl.grad(s["u"])) * s.test("P2")) * ufl.dx,
    "outer": lambda s: ufl.inner(ufl.outer(s["u"], ufl.grad(s["m"])), ufl.grad(s.test("vector P2"))) * ufl.dx,
    "det tr transpose": lambda s: (ufl.det(deformation_gradient(s)) + ufl.tr(deformation_gradient(s).T
                                                                             * deformation_gradient(s)))
                                  * s.test("P1") * ufl.dx,
    "inv": lambda s: ufl.inner(ufl.inv(deformation_gradient(s)).T, ufl.grad(s.test("vector P2"))) * ufl.dx,
    "indexed and component tensors": lambda s: ufl.inner(
        ufl.as_tensor(ufl.grad(s["u"])[ufl.i, ufl.j], (ufl.j, ufl.i))
        + ufl.as_matrix([[s["u"][j] * (i + 1) for j in range(s.gdim)] for i in range(s.gdim)]),
        ufl.grad(s.test("vector P2"))) * ufl.dx,
    "index sums and list tensors": lambda s: (
        ufl.grad(s["u"])[ufl.i, ufl.i] * s.test("P2")
        + ufl.dot(ufl.as_vector([s["u"][s.gdim - 1 - i] for i in range(s.gdim)]), ufl.grad(s.test("P2")))) * ufl.dx,
    "curl sym skew dev cofac": lambda s: (
        ufl.inner(ufl.curl(s["u"]), ufl.curl(s.test("vector P2")))
        + ufl.inner(ufl.sym(ufl.grad(s["u"])) + 2 * ufl.skew(ufl.nabla_grad(s["u"])) + ufl.dev(ufl.grad(s["u"]))
                    + ufl.cofac(deformation_gradient(s)), ufl.grad(s.test("vector P2")))
        + ufl.nabla_div(s["u"]) * ufl.div(s.test("vector P2"))) * ufl.dx,
    # sums over the identity (contract_identities eliminates them; FFCx evaluates them as written)
    "identity contractions": lambda s: (
        ufl.inner(s["m"] * ufl.Identity(s.gdim) - ufl.grad(s["u"]), ufl.grad(s.test("vector P2")))
        + ufl.inner(ufl.dot(ufl.Identity(s.gdim), ufl.grad(s["u"])).T, ufl.grad(s.test("vector P2")))
        + ufl.Identity(s.gdim)[0, ufl.i] * ufl.grad(s["m"])[ufl.i] * s.test("vector P2")[s.gdim - 1]
        + ufl.inner(ufl.outer(s["u"], ufl.grad(s["m"])), s["c"] * ufl.Identity(s.gdim)) * s.test("vector P2")[0]
        + ufl.tr(ufl.Identity(s.gdim)) * ufl.inner(s["u"], s.test("vector P2"))
        # I[i, j] u1[i] u[j]: after either sum the other index is in two factors; left as written
        + ufl.Identity(s.gdim)[ufl.i, ufl.j] * (s["u1"][ufl.i] * s["u"][ufl.j]) * s.test("vector P2")[0]
        # sum_j I[i, j] m: no other factor reads j (each row of I sums to 1); left as written
        + ufl.dot(ufl.as_vector(ufl.classes.IndexSum(ufl.Identity(s.gdim)[ufl.i, ufl.j] * s["m"],
                                                     ufl.classes.MultiIndex((ufl.j,))), ufl.i),
                  s.test("vector P2"))) * ufl.dx,
    # as_tensor(s I, (k, l))[i, j] inlined as s I[i, j]: where B reads i itself (the same index, so the
    # diagonal), and where i is bound by a sum inside B (which must not capture the i put in for k)
    "identity contractions, shared and bound indices": lambda s: (
        ufl.as_vector(ufl.as_tensor(s["u"][ufl.i] * ufl.Identity(s.gdim)[ufl.k, ufl.l], (ufl.k, ufl.l))[ufl.i, ufl.j],
                      ufl.j)[0] * s.test("vector P2")[0]
        + ufl.as_tensor(ufl.Identity(s.gdim)[ufl.l, 0]
                        * (s["u"][ufl.i] * ufl.grad(s["u"])[ufl.k, ufl.i] + s["m"] * s["u"][ufl.k]),  # k inside a sum over i
                        (ufl.k, ufl.l))[ufl.i, ufl.j] * ufl.grad(s.test("vector P2"))[ufl.i, ufl.j]
        # sum_j I[k, j] F(j) as F(k), where F sums over k itself: F's k must not capture the k put in for j
        + ufl.as_vector(ufl.Identity(s.gdim)[ufl.k, ufl.j] * (s["u"][ufl.k] * ufl.grad(s["u"])[ufl.j, ufl.k]),
                        ufl.k)[0] * s.test("vector P2")[1]) * ufl.dx,
    "identity contractions, mixed matrix": lambda s: (
        ufl.inner(ufl.split(s.trial("Taylor-Hood"))[1] * ufl.Identity(s.gdim),
                  ufl.grad(ufl.split(s.test("Taylor-Hood"))[0]))
        + ufl.inner(ufl.dot(ufl.Identity(s.gdim) + ufl.grad(s["u"]), ufl.grad(ufl.split(s.trial("Taylor-Hood"))[0])),
                    ufl.grad(ufl.split(s.test("Taylor-Hood"))[0]))) * ufl.dx,
    # sums over the rows of a mixed test function's vector part, grad([v[0], v[1]]): unrolled where nothing
    # else reads the summed index (example 1b's active-stress load, the traction), left whole where a field does
    "sums over a mixed argument's rows": lambda s: (
        ufl.inner(s["m"] * ufl.Identity(s.gdim), ufl.grad(ufl.split(s.test("Taylor-Hood"))[0]))
        + ufl.inner(ufl.grad(s["u"]), ufl.grad(ufl.split(s.test("Taylor-Hood"))[0]))
        + ufl.dot(s["u"], ufl.split(s.test("Taylor-Hood"))[0]) * s["m"]) * ufl.dx
        + ufl.dot(ufl.as_vector([0.0] * (s.gdim - 1) + [s["m"]]), ufl.split(s.test("Taylor-Hood"))[0]) * ufl.ds,
    "tensor field": lambda s: ufl.inner(ufl.dot(s["T"], s["T"].T), ufl.grad(s.test("vector P1"))) * ufl.dx,
    # a field's function times a P1 gradient (the same at every point): summed over the points first
    # (_Factored), on cells and on facets, in a vector, a matrix and a sum of such terms (1b's active stress)
    "cellwise-constant argument factors": lambda s: (
        s["m"] / (1.0 + s["m"] ** 2) * ufl.div(s.test("vector P1")) * ufl.dx
        + ufl.exp(-s["c"]) * ufl.grad(s.test("vector P1"))[0, s.gdim - 1] * ufl.dx
        + s["m"] ** 2 * ufl.dot(ufl.grad(s.test("vector P1"))[s.gdim - 1, :], ufl.FacetNormal(s.mesh)) * ufl.ds),
    "cellwise-constant argument factors, matrix": lambda s: (
        ufl.exp(-s["m"]) * ufl.inner(ufl.grad(s.trial("P1")), ufl.grad(s.test("P1"))) * ufl.dx
        + s["c"] * s.trial("P1") * s.test("P1") * ufl.dx),
    # math functions
    "exp ln": lambda s: ufl.exp(-s["m"]) * ufl.ln(1 + s["c"] ** 2) * s.test("P2") * ufl.dx,
    "tanh sqrt power": lambda s: (ufl.tanh(s["c"]) + ufl.sqrt(s["m"]) + s["m"] ** 3 + s["c"] ** 1.5
                                  + s["m"] ** s["k"]) * s.test("P1") * ufl.dx,
    "trigonometric erf atan2 abs": lambda s: (
        ufl.sin(s["c"]) + ufl.cos(s["m"]) + ufl.tan(0.5 * s["m"]) + ufl.asin(0.3 * s["c"]) + ufl.acos(0.3 * s["m"])
        + ufl.atan(s["c"]) + ufl.atan_2(s["m"], s["c"]) + ufl.cosh(s["m"]) + ufl.sinh(s["c"]) + ufl.erf(s["m"])
        + abs(s["c"] - 1.0)) * s.test("P1") * ufl.dx,
    "division": lambda s: s["c"] / (1 + s["m"]) * ufl.div(s.test("vector P1")) * ufl.dx,
    # the Bessel functions FFCx compiles (C's jn, yn: integer order), and their derivatives (orders n - 1, n + 1)
    "bessel J Y and their derivatives": lambda s: (
        (ufl.bessel_J(0, s["c"]) + ufl.bessel_J(2, 3 * s["m"]) + ufl.bessel_Y(1, 1 + s["m"])) * s.test("P1")
        + ufl.derivative(ufl.bessel_J(1, s["m"]) + ufl.bessel_Y(2, 1 + s["m"]), s["m"], s.test("P1"))) * ufl.dx,
    "bessel matrix": lambda s: ufl.bessel_J(1, s["c"]) * ufl.bessel_Y(0, 1 + s["m"]) * s.trial("P1") * s.test("P1")
                               * ufl.dx,
    # conditionals
    "conditional": lambda s: (
        ufl.conditional(ufl.lt(s["c"], 0.8), s["c"], 1 - s["c"])
        + ufl.conditional(ufl.And(ufl.ge(s["m"], 0.5), ufl.Not(ufl.gt(s["c"], 1.0))), 1.0, s["m"])
        + ufl.conditional(ufl.Or(ufl.le(s["m"], 0.4), ufl.eq(s["m"], 0.3)), 2.0, 3.0)
        + ufl.conditional(ufl.ne(s["c"], 0.5), s["c"] ** 2, 0.0)
        + ufl.max_value(s["m"], s["c"]) + ufl.min_value(s["m"], s["c"])) * s.test("P2") * ufl.dx,
    "derivative through a conditional": lambda s: ufl.derivative(
        ufl.conditional(ufl.gt(s["c"], 0.9), s["c"] ** 2, ufl.exp(s["c"])) * s.test("P2") * ufl.dx,
        s["c"], s.trial("P2")),
    # terminals
    "spatial coordinate": lambda s: (ufl.exp(ufl.SpatialCoordinate(s.mesh)[0])
                                     * ufl.sin(3 * ufl.SpatialCoordinate(s.mesh)[1]) * s.test("P2") * ufl.dx),
    "spatial coordinate functional": lambda s: (
        ufl.exp(-ufl.dot(ufl.SpatialCoordinate(s.mesh), ufl.SpatialCoordinate(s.mesh))) * s["c"] * ufl.dx),
    "constants": lambda s: (s["k"] * s["m"] * s.test("P1") + ufl.inner(s["a"], ufl.grad(s.test("P1")))) * ufl.dx,
    # facet integrals
    "facet normal on ds": lambda s: ufl.dot(s["u"], ufl.FacetNormal(s.mesh)) * s.test("P2") * ufl.ds,
    "tagged boundaries": lambda s: (s["m"] * s.test("P2") * ds(s, s.data.boundary_id("left"))
                                    + ufl.exp(s["c"]) * s.test("P2") * ds(s, (2, 3))),
    "facet matrix": lambda s: ufl.dot(ufl.grad(s.trial("P2")), ufl.FacetNormal(s.mesh)) * s.test("P2") * ufl.ds,
    "facet functional": lambda s: ufl.dot(ufl.SpatialCoordinate(s.mesh), ufl.FacetNormal(s.mesh)) * s["m"] * ufl.ds,
    # geometry
    "cell size quantities": lambda s: (ufl.CellVolume(s.mesh) + ufl.CellDiameter(s.mesh) + ufl.Circumradius(s.mesh)
                                       + ufl.MinCellEdgeLength(s.mesh) + ufl.MaxCellEdgeLength(s.mesh))
                                      * s.test("P1") * ufl.dx,
    "jacobians": lambda s: (ufl.JacobianDeterminant(s.mesh) + ufl.Jacobian(s.mesh)[0, 1]
                            + ufl.JacobianInverse(s.mesh)[1, 0]) * ufl.exp(s["m"]) * s.test("P1") * ufl.dx,
    "facet area": lambda s: ufl.FacetArea(s.mesh) * s.test("P1") * ufl.ds,
    # nonlinear forms and their derivatives
    "neo-Hookean energy": lambda s: neo_hookean_energy(s, s["u"]),
    "neo-Hookean residual": lambda s: neo_hookean_residual(s),
    "neo-Hookean tangent": lambda s: ufl.derivative(neo_hookean_residual(s), s["u"], s.trial("vector P2")),
    "stress from a variable": lambda s: ufl.inner(first_piola_stress(s), ufl.grad(s.test("vector P2")))
                                        * ufl.dx(metadata=DEGREE_4),
    "vector P1 tangent": lambda s: ufl.derivative(
        ufl.derivative(neo_hookean_energy(s, s["u1"]), s["u1"], s.test("vector P1")), s["u1"], s.trial("vector P1")),
    # mixed spaces
    "Taylor-Hood Stokes matrix": lambda s: stokes(*ufl.split(s.trial("Taylor-Hood")),
                                                  *ufl.split(s.test("Taylor-Hood"))),
    "Taylor-Hood nonlinear tangent": lambda s: ufl.derivative(
        mixed_nonlinear(*ufl.split(s["w"]), *ufl.split(s.test("Taylor-Hood"))), s["w"], s.trial("Taylor-Hood")),
    "P2-P1-P1, one field only": lambda s: s["m"] * ufl.split(s.test("P2-P1-P1"))[1] * ufl.ds,
    "P2-P1-P1 growth residual": lambda s: growth_residual(s),
    "P2-P1-P1 growth tangent": lambda s: ufl.derivative(growth_residual(s), s["growth"], s.trial("P2-P1-P1")),
    "P2-P1-P1 unsplit": lambda s: (ufl.inner(ufl.grad(s.trial("P2-P1-P1")), ufl.grad(s.test("P2-P1-P1")))
                                   + s["m"] * ufl.inner(s.trial("P2-P1-P1"), s.test("P2-P1-P1"))) * ufl.dx,
    # vertex quadrature
    "lumped mass": lambda s: s.trial("P1") * s.test("P1") * ufl.dx(metadata=LUMPED),
    "lumped nonlinear reaction": lambda s: ufl.exp(s["m"]) * ufl.tanh(s["m"]) * s.test("P1") * ufl.dx(metadata=LUMPED),
}


def stokes(velocity, pressure, test_velocity, test_pressure):
    return (ufl.inner(ufl.grad(velocity), ufl.grad(test_velocity)) - pressure * ufl.div(test_velocity)
            - test_pressure * ufl.div(velocity)) * ufl.dx


def mixed_nonlinear(velocity, pressure, test_velocity, test_pressure):
    return (ufl.exp(-pressure) * ufl.inner(ufl.grad(velocity), ufl.grad(test_velocity))
            + pressure ** 2 * test_pressure) * ufl.dx


def growth_residual(s):
    """Finite-strain poroelastic growth with (u, psi, p) in P2 x P1 x P1: nonlinear in every block,
    values and gradients of the same mixed argument."""
    u, solid_pressure, fluid_pressure = ufl.split(s["growth"])
    w, phi, q = ufl.split(s.test("P2-P1-P1"))
    growth = 1.0 + 0.2 * ufl.SpatialCoordinate(s.mesh)[0]
    F = deformation_gradient(s, u)
    J = ufl.det(F)
    elastic = F / growth
    stress = J * (1.3 * elastic * elastic.T - solid_pressure * ufl.Identity(s.gdim)) * ufl.inv(F).T
    darcy = J * ufl.dot(ufl.inv(F.T * F) * ufl.grad(fluid_pressure), ufl.grad(q))
    return (ufl.inner(stress, ufl.grad(w)) + (J - growth ** s.gdim) * phi + darcy) * ufl.dx(metadata=DEGREE_4)


@pytest.mark.parametrize("name", FORMS)
def test_matches_dolfinx(pair, name):
    assert_same(pair, FORMS[name])


class DenseArguments:
    """A quadrature context of the protocol before argument blocks: a chunk whose arguments come
    as dense arrays over all local DOFs and components (zero outside each DOF's component)."""

    def __init__(self, chunk):
        self.chunk = chunk

    def __getattr__(self, name):
        if name == "argument_blocks":
            raise AttributeError(name)
        return getattr(self.chunk, name)

    def argument(self, space, derivatives):
        gdim, blocks = self.chunk.gdim, space.blocks
        parts = {}
        for block in blocks:
            table, mapping = self.chunk._factors(block.element, derivatives)
            table = table.reshape(table.shape[:2] + (1,) * derivatives + table.shape[2:])
            parts[block.component] = sum(table[:, r] * mapping[r] for r in range(len(mapping)))
        points = np.broadcast_shapes(*(part.shape[-2:] for part in parts.values()))
        dense = np.zeros((space.cell_dofs.shape[1], space.value_size) + (gdim,) * derivatives + points)
        for block in blocks:
            dense[block.local, block.component] = parts[block.component]
        return dense.reshape(dense.shape[:1] + space.value_shape + dense.shape[2:])


@pytest.mark.parametrize("name", FORMS)
def test_matches_dolfinx_through_the_protocol_before_blocks(pair, name, monkeypatch):
    """A context with only the dense ``argument`` (no ``argument_blocks``) still assembles every form."""
    chunk = skfem_backend._Chunk
    monkeypatch.setattr(skfem_backend, "_Chunk", lambda *args: DenseArguments(chunk(*args)))
    assert_same(pair, FORMS[name])


def test_constant_value_change_is_seen(pair):
    for s in pair:
        s["k"].value = 0.25
    try:
        assert_same(pair, FORMS["constants"])
    finally:
        for s in pair:
            s["k"].value = 1.7


def test_lumped_mass_is_diagonal_with_cell_volume_shares(pair):
    _, s = pair
    A = s.backend.assemble_matrix(FORMS["lumped mass"](s))
    indptr, indices, values = A.getValuesCSR()
    dense = scipy.sparse.csr_matrix((values, indices, indptr), shape=A.getSize()).toarray()
    assert np.abs(dense - np.diag(np.diag(dense))).max() == 0.0
    shares = np.zeros(s.data.num_vertices)
    np.add.at(shares, s.data.cells, (s.data.cell_volumes() / (s.gdim + 1))[:, None])
    np.testing.assert_allclose(np.diag(dense), shares, rtol=1e-13)


# -- the evaluator on its own -------------------------------------------------------------------


class ConstantsOnly:
    """A QuadratureContext for integrands made of constants and x, on 2 entities x 3 points."""

    gdim = 2

    def __init__(self, points):
        self.points = points

    def constant(self, constant):
        return constant.values

    def geometry(self, quantity):
        return self.points if quantity == "SpatialCoordinate" else None


class Matrix(ufl.Constant):
    def __init__(self, domain, values):
        super().__init__(domain, shape=np.shape(values))
        self.values = np.asarray(values, dtype=float)


def test_free_index_bookkeeping_against_numpy():
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.triangle, 1))
    rng = np.random.default_rng(5)
    a, b = rng.uniform(size=(2, 2)), rng.uniform(size=(2, 2))
    A, B = Matrix(domain, a), Matrix(domain, b)
    x = ufl.SpatialCoordinate(domain)
    points = rng.uniform(size=(2, 2, 3))  # (gdim, entity, point)
    i, j, k = ufl.indices(3)
    expression = (ufl.as_tensor(A[i, j] * B[j, k], (k, i))[1, 0] + ufl.tr(A * B.T) * x[0]
                  + ufl.dot(ufl.as_vector((x[1], x[0])), ufl.dot(A, x)) + ufl.det(B) * ufl.exp(-x[1]))
    expected = ((a @ b).T[1, 0] + np.trace(a @ b.T) * points[0]
                + np.einsum("ieq,ij,jeq->eq", points[::-1], a, points) + np.linalg.det(b) * np.exp(-points[1]))
    value = evaluate_integrand(ufl.algorithms.apply_algebra_lowering.apply_algebra_lowering(expression),
                               ConstantsOnly(points))
    np.testing.assert_allclose(value[0, 0], expected, rtol=1e-14)


# -- scikit-fem only -------------------------------------------------------------------------


@pytest.fixture(scope="module", params=CELLS)
def skfem_setup(request):
    return setup(SkfemBackend(), mesh_data(request.param))


def test_neo_hookean_tangent_matches_finite_differences(skfem_setup):
    s = skfem_setup
    backend, u = s.backend, s.fields["u"]
    residual = neo_hookean_residual(s)
    tangent = backend.assemble_matrix(ufl.derivative(residual, u, s.trial("vector P2")))
    direction = np.random.default_rng(3).uniform(-1.0, 1.0, u.array.size)
    saved = u.array.copy()

    def central_difference(step):
        u.array[:] = saved + step * direction
        forward = backend.assemble_vector(residual).array.copy()
        u.array[:] = saved - step * direction
        backward = backend.assemble_vector(residual).array.copy()
        u.array[:] = saved
        return (forward - backward) / (2 * step)

    step = 1e-4  # with Richardson extrapolation: truncation error O(step^4)
    finite_difference = (4 * central_difference(step / 2) - central_difference(step)) / 3
    exact = tangent.createVecLeft()
    tangent.mult(PETSc.Vec().createWithArray(direction, comm=PETSc.COMM_SELF), exact)
    error = np.abs(exact.array - finite_difference).max() / np.abs(exact.array).max()
    assert error < 1e-9


def test_reproduces_scikit_fem_assembly(skfem_setup):
    import skfem
    from skfem.helpers import dot, grad

    s = skfem_setup
    space = s.spaces["P2"]
    form = (ufl.inner(ufl.grad(s.trial("P2")), ufl.grad(s.test("P2"))) + s.trial("P2") * s.test("P2")) * ufl.dx
    A = s.backend.assemble_matrix(form)
    indptr, indices, values = A.getValuesCSR()
    ours = scipy.sparse.csr_matrix((values, indices, indptr), shape=A.getSize())

    @skfem.BilinearForm
    def reference(u, v, _):
        return dot(grad(u), grad(v)) + u * v

    theirs = reference.assemble(skfem.Basis(s.mesh.skfem, space.skfem_element, intorder=4))
    assert abs(ours - theirs).max() < 1e-12 * abs(theirs).max()


def test_dense_element_tensors_assemble_to_the_matrix(skfem_setup):
    """integrate_integrand places every block pair's tensors at their local DOFs: summed over the
    cells' DOFs, they give the backend's matrix; evaluate_integrand's values at the points, weighted
    and summed, give the same tensors."""
    s = skfem_setup
    form = FORMS["P2-P1-P1 growth tangent"](s)
    space = s.spaces["P2-P1-P1"]
    (plan,) = preprocess_form(form)
    backend, mesh = s.backend, s.mesh
    context = skfem_backend._Chunk(mesh, backend._rule(mesh, plan), slice(0, s.data.num_cells), None)
    tensors = integrate_integrand(plan.integrand, context, context.weights)
    at_points = evaluate_integrand(plan.integrand, context)                  # (test, trial, cell, point)
    np.testing.assert_allclose(np.einsum("ijeq,eq->eij", at_points, context.weights), tensors,
                               rtol=1e-12, atol=1e-12 * np.abs(tensors).max())
    rows = np.broadcast_to(space.cell_dofs[:, :, None], tensors.shape)
    cols = np.broadcast_to(space.cell_dofs[:, None, :], tensors.shape)
    dense = scipy.sparse.coo_matrix((tensors.ravel(), (rows.ravel(), cols.ravel())), shape=(space.num_dofs,) * 2)
    A = backend.assemble_matrix(form)
    indptr, indices, values = A.getValuesCSR()
    reference = scipy.sparse.csr_matrix((values, indices, indptr), shape=A.getSize())
    assert abs(dense.tocsr() - reference).max() < 1e-12 * abs(reference).max()


def test_reassembly_into_a_matrix_is_seen_by_its_solver(skfem_setup):
    """Re-assembly writes the values of a matrix made by the backend in place: a factorisation redone
    on the same matrix must see them."""
    s = skfem_setup
    form = (ufl.exp(s["m"]) * ufl.inner(ufl.grad(s.trial("P1")), ufl.grad(s.test("P1")))
            + s.trial("P1") * s.test("P1")) * ufl.dx
    A = s.backend.assemble_matrix(form)
    solver = PETSc.KSP().create(PETSc.COMM_SELF)
    solver.setOperators(A)
    solver.setType("preonly")
    solver.getPC().setType("lu")
    rhs, solution = A.createVecLeft(), A.createVecRight()
    rhs.set(1.0)
    solver.solve(rhs, solution)
    before = solution.array.copy()
    saved = s["m"].array.copy()
    s["m"].array[:] += 1.0
    try:
        assert s.backend.assemble_matrix(form, A=A) is A
        solver.solve(rhs, solution)
        fresh = s.backend.assemble_matrix(form)
        expected = fresh.createVecRight()
        fresh_solver = PETSc.KSP().create(PETSc.COMM_SELF)
        fresh_solver.setOperators(fresh)
        fresh_solver.setType("preonly")
        fresh_solver.getPC().setType("lu")
        fresh_solver.solve(rhs, expected)
    finally:
        s["m"].array[:] = saved
    assert np.abs(solution.array - before).max() > 1e-3 * np.abs(before).max()
    np.testing.assert_allclose(solution.array, expected.array, rtol=1e-12)


def test_a_field_read_by_several_forms_is_interpolated_once_while_its_values_stay(skfem_setup, monkeypatch):
    """The forms of a step read the same fields (example 1b: the solid velocity in the advection of
    m, f and b): the values at the points are kept across forms, and interpolated again once the
    field's DOF values change, written in place as solvers do."""
    s = skfem_setup
    backend, m, w = s.backend, s["m"], s["w"]
    calls = []
    interpolate = skfem_backend._Chunk._interpolate
    monkeypatch.setattr(skfem_backend._Chunk, "_interpolate",
                        lambda self, values, block, derivatives: calls.append(derivatives)
                        or interpolate(self, values, block, derivatives))
    velocity = ufl.as_vector([w[i] for i in range(s.gdim)])  # a part of a mixed field, as 1b's rate
    # the same quadrature degree (the same points), different integrands
    one = (m * m * ufl.div(velocity) * s.test("P1")) * ufl.dx
    other = ((m * m + 1.0) * ufl.div(velocity) * s.test("P1")) * ufl.dx
    shift = ufl.div(velocity) * s.test("P1") * ufl.dx
    first = backend.assemble_vector(one).array.copy()
    assert calls, "the first form interpolates its fields"
    shifted = backend.assemble_vector(shift).array.copy()  # another degree: other points, other values
    calls.clear()
    np.testing.assert_allclose(backend.assemble_vector(other).array, first + shifted, rtol=1e-12, atol=1e-14)
    assert calls == [], "m and w had the same values: nothing to interpolate again for the second form"

    saved = m.array.copy()
    try:
        m.array[:] += 0.5  # in place, as a solve through the PETSc vector writes it
        calls.clear()
        changed = backend.assemble_vector(one).array.copy()
        assert calls == [0], "only m changed: its values interpolated again, w's gradient reused"
        s.mesh.field_values = skfem_backend._FieldValues()  # nothing kept: what the values must be
        np.testing.assert_array_equal(backend.assemble_vector(one).array, changed)
        assert np.abs(changed - first).max() > 1e-3 * np.abs(first).max()
    finally:
        m.array[:] = saved
    np.testing.assert_array_equal(backend.assemble_vector(one).array, first)

    (plan,) = preprocess_form(one)
    context = skfem_backend._Chunk(s.mesh, backend._rule(s.mesh, plan), slice(0, s.data.num_cells), None)
    assert not context.coefficient(m, 0).flags.writeable, "a form must not change the values the next one reads"


def test_a_p1_gradient_on_a_run_of_cells_is_the_gathered_one(skfem_setup):
    """Over a run of cells the gradient of a P1 part (one value per cell) is one sparse product with
    the DOF values (SkfemMesh.constant_gradient_operator); it equals the gather, reference product and
    mapping that cells given one by one still take, for a P1 field, the components of a vector P1 one
    and the P1 parts of a mixed field (DOFs after the P2 ones), and reads nothing of the other parts."""
    s = skfem_setup
    backend, mesh = s.backend, s.mesh
    form = s["m"] * s.test("P1") * ufl.dx
    (plan,) = preprocess_form(form)
    rule = backend._rule(mesh, plan)
    cells = np.arange(s.data.num_cells)
    run = skfem_backend._Chunk(mesh, rule, slice(0, len(cells)), None)
    one_by_one = skfem_backend._Chunk(mesh, rule, cells, None)
    for name in ("m", "u1", "growth"):
        function = s[name]
        blocks = [block for block in function.function_space.blocks if type(block.element) is type(
            function.function_space.blocks[-1].element)]
        for block in blocks:
            ours = run._interpolate(function.array, block, 1)
            assert ours.shape == (s.gdim, 1, len(cells))
            np.testing.assert_allclose(ours, one_by_one._interpolate(function.array, block, 1),
                                       rtol=1e-13, atol=1e-13 * np.abs(ours).max())
            others = function.array.copy()
            others[np.setdiff1d(np.arange(others.size), block.cell_dofs)] = np.nan
            np.testing.assert_array_equal(run._interpolate(others, block, 1), ours)
    assert len(mesh._gradient_operators) >= 1 + s.gdim + 2

    kept = len(mesh._gradient_operators)
    space = backend.function_space(mesh, ufl.FiniteElement("Lagrange", s.domain.ufl_cell(), 1))
    function = backend.function(space, "short-lived")
    run._interpolate(function.array, space.blocks[0], 1)
    assert len(mesh._gradient_operators) == kept + 1
    del space, function
    gc.collect()
    assert len(mesh._gradient_operators) == kept, "an operator outlived its space's DOF layout"


def test_a_form_reading_some_components_of_a_field_interpolates_only_theirs(skfem_setup, monkeypatch):
    """Where an integrand reads fixed components of a field (u of split(w), grad(w)[k, j], w[k]), the
    chunk interpolates only those components' blocks, and the vector is the one assembled from the
    whole field's values (the protocol without ``coefficient_components``); a form that also reads the
    whole field has its components sliced from it."""
    s = skfem_setup
    growth = s["growth"]                                   # (u, psi, p): P2 vector, P1, P1
    u, psi, p = ufl.split(growth)
    gdim, v = s.gdim, s.test("P2")
    read = {                                               # form -> the flat components it reads
        "u of split": (ufl.inner(u, u) * v * ufl.dx, set(range(gdim))),
        "grad p": (ufl.inner(ufl.grad(p), ufl.grad(v)) * ufl.dx, {gdim + 1}),
        "one component": (growth[gdim - 1] * psi * v * ufl.dx, {gdim - 1, gdim}),
        "grad of a component": (ufl.grad(growth)[0, 1] * v * ufl.dx, {0}),
        # a tensor field: flat components k = i gdim + j
        "tensor components": ((s["T"][1, 0] + ufl.grad(s["T"])[0, gdim - 1, 1]) * v * ufl.dx, {gdim, gdim - 1}),
        "tensor row": (ufl.inner(ufl.as_vector([s["T"][1, j] for j in range(gdim)]), ufl.grad(v)) * ufl.dx,
                       set(range(gdim, 2 * gdim))),
    }
    interpolated = []
    interpolate = skfem_backend._Chunk._interpolate

    def spy(chunk, values, block, derivatives):
        if values is growth.array or values is s["T"].array:
            interpolated.append(block.component)
        return interpolate(chunk, values, block, derivatives)

    def whole_field_only(chunk, function, derivatives, components):
        return None

    for name, (form, components) in read.items():
        monkeypatch.setattr(s.mesh, "field_values", skfem_backend._FieldValues())  # nothing kept from before
        monkeypatch.setattr(skfem_backend._Chunk, "_interpolate", spy)
        interpolated.clear()
        ours = s.backend.assemble_vector(form).array.copy()
        assert set(interpolated) == components, name
        monkeypatch.setattr(skfem_backend._Chunk, "coefficient_components", whole_field_only)
        monkeypatch.setattr(s.mesh, "field_values", skfem_backend._FieldValues())
        interpolated.clear()
        whole = s.backend.assemble_vector(form).array
        assert set(interpolated) == set(range(gdim * gdim if "tensor" in name else gdim + 2)), name
        np.testing.assert_allclose(ours, whole, rtol=1e-14, atol=1e-14 * np.abs(whole).max(), err_msg=name)
        monkeypatch.undo()

    both = (ufl.inner(growth, growth) + growth[0] * p) * v * ufl.dx  # the whole field first, then parts of it
    (plan,) = preprocess_form(both)
    chunk = skfem_backend._Chunk(s.mesh, s.backend._rule(s.mesh, plan), slice(0, s.data.num_cells), None)
    whole = chunk.coefficient(growth, 0)
    part = chunk.coefficient_components(growth, 0, slice(gdim, gdim + 2))
    assert np.shares_memory(part, whole), "components of a field already at the points are sliced from it"
    np.testing.assert_array_equal(part, whole[gdim:gdim + 2])


def test_an_argument_factor_the_same_at_every_point_meets_the_point_sum_of_the_rest(skfem_setup, monkeypatch):
    """A root product (or sum of them) of an argument factor that does not vary over the points (a P1
    gradient) with an argument-free one that does is integrated as argument * sum_q free w_q (_Factored),
    on cells and facets; the element tensors are those of the product taken point by point, and the
    factored path is taken (its point sums are computed once per free factor and chunk)."""
    s = skfem_setup
    sums = []
    weighted = ufl_numpy._weighted

    def spy(value, weights, kept, *tables):
        if isinstance(value, ufl_numpy._Factored) and all(table.shape[3] == 1 for table in tables):
            sums.append(id(value.free) not in kept)
        return weighted(value, weights, kept, *tables)

    for name in ("cellwise-constant argument factors", "cellwise-constant argument factors, matrix"):
        form = FORMS[name](s)
        linear = len(form.arguments()) == 1
        assemble = s.backend.assemble_vector if linear else s.backend.assemble_matrix
        monkeypatch.setattr(ufl_numpy, "_weighted", spy)
        sums.clear()
        ours = assemble(form)
        assert sums and any(sums), f"{name}: the factored path was not taken"
        assert sum(sums) <= 3, f"{name}: a free factor's point sum was computed again for another block pair"
        monkeypatch.setattr(ufl_numpy._Evaluator, "_terms", lambda self, o: [self._value(o)])
        plain = assemble(form)
        monkeypatch.undo()
        if linear:
            ours, plain = ours.array, plain.array
        else:
            ours, plain = ours.getValuesCSR()[2], plain.getValuesCSR()[2]
        np.testing.assert_allclose(ours, plain, rtol=1e-13, atol=1e-13 * np.abs(plain).max(), err_msg=name)


def test_a_fixed_component_of_a_mixed_argument_is_its_block_alone(skfem_setup, monkeypatch):
    """v[k] or grad(v)[k, j] of a test or trial function on a mixed space, k fixed: on k's block the
    evaluator takes the block's map alone instead of placing it among zeros for the other components
    (Evaluator.argument); the element tensors are those of the whole argument indexed."""
    s = skfem_setup
    u, p = ufl.split(s.test("Taylor-Hood"))
    du, dp = ufl.split(s.trial("Taylor-Hood"))
    forms = {
        "vector": (s["m"] * ufl.grad(u)[0, s.gdim - 1] + ufl.exp(s["c"]) * u[s.gdim - 1] + s["m"] * p) * ufl.dx
                  + s["m"] * u[0] * ufl.ds,
        "matrix": (ufl.grad(du)[1, 0] * ufl.grad(u)[1, 0] + s["c"] * dp * ufl.div(u) + du[0] * p) * ufl.dx,
    }
    whole = []
    argument = ufl_numpy._Evaluator.argument

    def spy(self, o, derivatives=0):
        whole.append(o.number())
        return argument(self, o, derivatives)

    for name, form in forms.items():
        assemble = s.backend.assemble_vector if name == "vector" else s.backend.assemble_matrix
        monkeypatch.setattr(ufl_numpy._Evaluator, "argument", spy)
        whole.clear()
        ours = assemble(form)
        assert not whole, f"{name}: a fixed component was placed among zeros"  # div(u): its rows are unrolled
        monkeypatch.setattr(ufl_numpy._Evaluator, "_fixed_component_value", lambda self, e, m: None)
        whole.clear()
        plain = assemble(form)
        assert whole, "the reference path places the components among zeros"
        monkeypatch.undo()
        ours, plain = (ours.array, plain.array) if name == "vector" else (ours.getValuesCSR()[2], plain.getValuesCSR()[2])
        np.testing.assert_allclose(ours, plain, rtol=1e-13, atol=1e-13 * np.abs(plain).max(), err_msg=name)


def test_the_dofs_a_vector_form_adds_to_are_kept_for_its_next_assembly(skfem_setup):
    """A form assembled at every step adds to the same DOFs: their flattened array is built once per
    layout of blocks, read-only, and the vector taken through the kept array is the one assembled through
    a freshly built one."""
    s = skfem_setup
    form = s["m"] * s["m"] * s.test("P2") * ufl.dx
    space = form.arguments()[0].ufl_function_space()
    first = s.backend.assemble_vector(form).array.copy()
    kept = dict(space._scatter)
    assert len(kept) == 1 and not any(indices.flags.writeable for indices in kept.values())
    np.testing.assert_array_equal(s.backend.assemble_vector(form).array, first)
    assert space._scatter.keys() == kept.keys() and all(space._scatter[k] is kept[k] for k in kept)
    space._scatter.clear()
    np.testing.assert_array_equal(s.backend.assemble_vector(form).array, first)


def test_the_fields_kept_at_the_points_hold_at_most_their_limit(skfem_setup, monkeypatch):
    s = skfem_setup
    monkeypatch.setattr(s.mesh, "field_values", skfem_backend._FieldValues())
    values = s.mesh.field_values
    monkeypatch.setattr(values, "LIMIT", 1)  # below one entry: only the last is kept
    for name in ("m", "c"):
        s.backend.assemble_vector(s[name] * s[name] * s.test("P2") * ufl.dx)
    assert len(values) == 1
    assert values._bytes == sum(entry[2].nbytes + entry[3].nbytes for entry in values._entries.values())


def test_unsupported_operator_is_named(skfem_setup):
    s = skfem_setup
    with pytest.raises(UnsupportedUFL, match="'BesselI' is not supported by the scikit-fem backend"):
        s.backend.assemble_scalar(ufl.bessel_I(1, s.fields["m"]) * ufl.dx)


def test_interior_facet_integrals_are_unsupported(skfem_setup):
    s = skfem_setup
    with pytest.raises(UnsupportedUFL, match="dS"):
        s.backend.assemble_scalar(ufl.avg(s.fields["m"]) * ufl.dS)


def test_cell_subdomains_are_unsupported(skfem_setup):
    s = skfem_setup
    with pytest.raises(UnsupportedUFL, match="subdomain"):
        s.backend.assemble_scalar(s.fields["m"] * ufl.dx(1))


def test_quadrature_degree_is_ffcx_estimate(skfem_setup):
    s = skfem_setup
    v = s.test("P2")
    plans = preprocess_form(ufl.exp(ufl.SpatialCoordinate(s.mesh)[0]) * v * ufl.dx
                            + v * ufl.dx(metadata={"quadrature_degree": 7}))
    assert sorted(p.degree for p in plans) == [5, 7]  # exp(x): degree 1 + 2, times P2


@pytest.mark.parametrize("cellname", ["interval", "triangle", "tetrahedron"])
@pytest.mark.parametrize("degree", [1, 2, 4, 6])
def test_fallback_quadrature_without_basix_is_exact(monkeypatch, cellname, degree):
    monkeypatch.setitem(sys.modules, "basix", None)
    points, weights = reference_quadrature(cellname, degree)
    tdim = points.shape[1]
    # integral of x^degree over the reference simplex: degree! / (degree + tdim)!
    exact = math.factorial(degree) / math.factorial(degree + tdim)
    assert np.isclose(weights @ points[:, 0] ** degree, exact, rtol=1e-13)


def test_an_integrand_rewired_by_ufl_after_its_analysis_still_assembles():
    """UFL shares operands between equal expressions when it compares them (eager DAGification in
    ``nonrecursive_expr_equals``): a tree analysed once may later hold an equal twin of a node, with
    another id.  The evaluator must notice and analyse it again, not fail or mix up values."""
    backend = SkfemBackend()
    mesh = backend.create_mesh(rectangle((0.0, 0.0), (1.0, 1.0), (3, 3)))
    space = backend.function_space(mesh, ufl.FiniteElement("Lagrange", mesh.ufl_cell(), 1))
    x = ufl.SpatialCoordinate(mesh.ufl_domain())
    v = ufl.TestFunction(space)
    form = ufl.sin(ufl.pi * x[1]) * v * backend.measure("dx", mesh, metadata={"quadrature_degree": 4})
    first = backend.assemble_vector(form).array.copy()
    (plan,) = backend._form_plans(form)
    twin = ufl.sin(ufl.pi * x[1])  # an equal expression built anew: other node objects
    rewired = [node for node in ufl.corealg.traversal.unique_pre_traversal(plan.integrand)
               if isinstance(node, ufl.classes.Sin)]
    assert rewired and rewired[0] == twin  # UFL's comparison makes one share the other's operands
    assert backend.assemble_vector(form).array == pytest.approx(first, rel=1e-14)


def test_a_sum_over_a_mixed_arguments_rows_is_unrolled_only_where_nothing_else_reads_its_index(skfem_setup):
    """``inner(m I, grad v_u)`` on a Taylor-Hood test function is m (dv_0/dx_0 + dv_1/dx_1): no list tensor
    left, each term one component's derivative; ``inner(grad u, grad v_u)`` keeps its sum (grad u reads the
    index too).  Both assemble to the forms evaluated as written (to round-off)."""
    from ufl.corealg.traversal import unique_pre_traversal

    s = skfem_setup
    v = ufl.split(s.test("Taylor-Hood"))[0]
    load = ufl.inner(s["m"] * ufl.Identity(s.gdim), ufl.grad(v)) * ufl.dx
    kept = ufl.inner(ufl.grad(s["u"]), ufl.grad(v)) * ufl.dx
    (plan,) = preprocess_form(load)
    assert not [o for o in unique_pre_traversal(plan.integrand) if isinstance(o, ufl.classes.ListTensor)]
    assert isinstance(plan.integrand, ufl.classes.Sum), plan.integrand
    (plan,) = preprocess_form(kept)
    assert [o for o in unique_pre_traversal(plan.integrand) if isinstance(o, ufl.classes.ListTensor)]
    for form in (load, kept):
        assert_as_written(s, form, "_sum_over_rows")


def test_sums_over_the_identity_are_eliminated_and_their_value_kept(skfem_setup):
    """``inner(m I, grad v)`` is evaluated as m div v: no identity is left where it is summed over, and the
    vector is the one of the form evaluated as written (to round-off)."""
    from ufl.corealg.traversal import unique_pre_traversal

    s = skfem_setup
    v = s.test("vector P2")
    form = (ufl.inner(s["m"] * ufl.Identity(s.gdim), ufl.grad(v))
            + ufl.inner(ufl.dot(ufl.Identity(s.gdim), ufl.grad(s["u"])), ufl.grad(v))) * ufl.dx
    (plan,) = preprocess_form(form)
    identities = [o for o in unique_pre_traversal(plan.integrand)
                  if isinstance(o, ufl.classes.Identity)]
    assert not identities, plan.integrand
    assert_as_written(s, form, "contract_identities")


def assert_as_written(s, form, rewrite: str) -> None:
    """The vector of ``form`` equals, to round-off, the one assembled with ``ufl_numpy``'s ``rewrite`` left out."""
    from primordia.backends import ufl_numpy

    rewritten = s.backend.assemble_vector(form).array.copy()
    kept = getattr(ufl_numpy, rewrite)
    try:
        setattr(ufl_numpy, rewrite, lambda expression: expression)
        as_written = s.backend.assemble_vector(ufl.replace(form, {})).array  # a new form: planned again
    finally:
        setattr(ufl_numpy, rewrite, kept)
    assert np.abs(rewritten - as_written).max() <= 1e-13 * np.abs(as_written).max()


def test_numpys_tanh_is_exactly_one_where_the_evaluator_stops_calling_it():
    """The assumption of ``saturating_tanh``, on this machine's numpy: tanh(x) is +-1.0 for every |x| >= 22."""
    beyond = np.concatenate([np.linspace(ufl_numpy.TANH_SATURATED, 40.0, 200_001), np.geomspace(40.0, 1e308, 20_001),
                             [np.inf]])
    assert np.all(np.tanh(beyond) == 1.0) and np.all(np.tanh(-beyond) == -1.0)


@pytest.mark.parametrize("layout", ["front", "all inside", "transposed", "in place"])
def test_saturating_tanh_gives_numpys_bits(layout):
    """Against np.tanh bit for bit (signed zeros, NaN, infinities included), on a travelling front
    (mostly saturated: the sparing path), on values mostly inside (numpy's own path), on a non-contiguous
    array and into an ``out`` that is its input."""
    rng = np.random.default_rng(3)
    x = 5.0 * (2.0 - rng.uniform(0.0, 20.0, (40, 37)) / 0.04)  # seed eq. (2.4)'s argument, 1% unsaturated
    x.flat[:8] = [0.0, -0.0, np.nan, np.inf, -np.inf, 21.999999999999996, 18.5, -18.5]  # tanh(18.5) < 1
    if layout == "all inside":
        x = rng.uniform(-25.0, 25.0, x.shape)
    expected = np.tanh(x)
    if layout == "transposed":
        x, expected = x.T, expected.T
    if layout == "in place":
        got = ufl_numpy.saturating_tanh(x, out=x)
        assert got is x
    else:
        out = np.full_like(x, 7.0)
        got = ufl_numpy.saturating_tanh(x, out=out)
        assert got is out
        assert ufl_numpy.saturating_tanh(x).tobytes() == expected.tobytes()
    assert got.tobytes() == expected.tobytes()
    assert ufl_numpy.saturating_tanh(0.5) == np.tanh(0.5)
