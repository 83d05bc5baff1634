r"""How the tissue moves, as the transport equations see it: the kinematics contract.

The chemotaxis balance laws are stated once, in the configuration where the
mesh lives, and read the motion of the tissue only through a
:class:`Kinematics` object that the mechanics module of the run provides
(``disc.provide_kinematics``); a run without mechanics gets
:data:`MOTIONLESS`.  Written with these quantities, a transported species c
with flux coefficient D obeys, in weak form on the mesh's domain,

    (accumulation)   J dc/dt v                         J: volume ratio
    (transport)      D K grad c . grad v               K: metric (J C^-1)
    (reaction)     - J R v
    (FGF sink)       xi_f J theta v                    theta: volume-change measure
    (advection)      w . grad c v                      w: advecting velocity (or none)

and the three mechanics of the seed give

=====================  =======  ===========  ===============  ================
kinematics             J        K            theta            w
=====================  =======  ===========  ===============  ================
motionless (ex. 1a)    1        I            0                none
small strain (1b)      1        I            div u  (2.3c)    u_t  (2.3a,c,d)
finite strain (2a)     det F    J C^-1       tr C - d (4.17c) none (4.17a-d)
=====================  =======  ===========  ===============  ================

In the finite-strain row the equations live on the reference configuration:
(4.17a) is d m/dt - (1/J) Div(D_m J C^-1 Grad m - ...) = 0, which multiplied
by J is the first two rows; advection is absorbed by the material derivative.
The small-strain row is the linearisation of the finite-strain one about
u = 0 (J = 1, J C^-1 = I), with advection kept explicitly as in (2.3a).  Note
that tr C - d = 2 div u + O(|Grad u|^2): for the same xi_f, the seed's
finite-strain sink (4.17c) is twice its small-strain sink (2.3c) at small strains.

A mechanics module that provides no kinematics leaves the motionless defaults;
the identity entries are plain numbers (``1``, ``None``) so that the forms of
example 1a and 1b stay exactly what they were.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import ufl


@dataclass(frozen=True)
class Kinematics:
    """The motion of the tissue, provided by the mechanics module (UFL expressions or identity defaults).

    ``volume_ratio``            J = det F (dimensionless); ``1`` without finite strain.
    ``volume_ratio_previous``   J at the start of the mechanics' time step; ``1`` without finite strain.
    ``volume_ratio_of``         J of a given displacement (a callable), or ``None`` without finite strain:
                                the conservative accumulation reads J where its species was last
                                balanced (:meth:`~primordia.physics.discretisation.Discretisation.at_balance`).
    ``metric``                  the pulled-back diffusion metric J C^-1 (d x d); ``None`` = identity.
    ``volume_change``           the volume-change measure of the FGF sink: div u (seed (2.3c)) or
                                tr C - d (seed (4.17c)); ``None`` = no motion.
    ``velocity``                the velocity advecting the species explicitly (seed (2.3a)); ``None``
                                when the equations are written in material coordinates.
    ``deformation_gradient``    F = I + Grad u on the reference configuration; ``None`` for small strain.
    ``quadrature_degree``       a degree the mechanics recommends for terms holding these
                                expressions (they are rational in Grad u); ``None``: the default.
    """

    volume_ratio: Any = 1
    volume_ratio_previous: Any = 1
    metric: Any = None
    volume_change: Any = None
    velocity: Any = None
    deformation_gradient: Any = None
    quadrature_degree: int | None = None
    volume_ratio_of: Any = None

    @property
    def finite_strain(self) -> bool:
        """Whether the equations live on a reference configuration that the tissue has left."""
        return self.deformation_gradient is not None

    @property
    def moves(self) -> bool:
        """Whether any quantity differs from the motionless identity."""
        return self != MOTIONLESS


#: A tissue that does not move (seed example 1a): every quantity is the identity.
MOTIONLESS = Kinematics()


def deformation_gradient(u):
    """F = I + Grad u (seed section 4)."""
    return ufl.Identity(len(u)) + ufl.grad(u)


def right_cauchy_green(F):
    """C = F^T F."""
    return F.T * F


def finite_strain_kinematics(displacement, displacement_previous,
                             quadrature_degree: int | None = None) -> Kinematics:
    """The finite-strain row of the table above, from the displacement u on the reference configuration.

    F = I + Grad u, C = F^T F, J = det F: the volume ratio J (and J at the start of the step,
    from ``displacement_previous``), the metric J C^-1 and the volume change tr C - d of seed
    (4.17a)-(4.17d), no advecting velocity.  Stated once, for every mechanics module that moves
    the reference configuration (and for the tests that move it by a prescribed motion).
    """
    F = deformation_gradient(displacement)
    C = right_cauchy_green(F)
    J = ufl.det(F)
    return Kinematics(volume_ratio=J, volume_ratio_previous=volume_ratio(displacement_previous),
                      metric=J * ufl.inv(C),                       # J C^-1 (4.17a)-(4.17d)
                      volume_change=ufl.tr(C) - len(displacement),  # tr C - d (4.17c)
                      velocity=None, deformation_gradient=F, quadrature_degree=quadrature_degree,
                      volume_ratio_of=volume_ratio)


def volume_ratio(displacement):
    """J = det(I + Grad u)."""
    return ufl.det(deformation_gradient(displacement))


def rigid_motions(points: np.ndarray) -> np.ndarray:
    """The rigid-body motions of a body at ``points`` (n, d): d translations along the axes and the
    rotations in the (x_0, x_1), (x_1, x_2), (x_2, x_0) planes (one in 2D), shape (modes, n, d)."""
    n, d = points.shape
    motions = [np.broadcast_to(np.eye(d)[axis], (n, d)) for axis in range(d)]
    for i, j in ((0, 1), (1, 2), (2, 0))[: 1 if d == 2 else 3]:
        rotation = np.zeros((n, d))
        rotation[:, i], rotation[:, j] = -points[:, j], points[:, i]
        motions.append(rotation)
    return np.array(motions)
