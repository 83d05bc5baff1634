r"""The mechano-chemical couplings: the moving solid in the chemotaxis balance laws.

This module only couples (it owns no field and states no balance law).  It reads
the motion of the tissue from the kinematics the mechanics module provides
(:mod:`primordia.physics.kinematics`), so the same module serves the small-strain
model (example 1b) and the finite-strain growth model (examples 2a, 2b, 4), and
adds to the chemotaxis balance laws:

* advection of the species the kinetics declares ``advected`` by the solid velocity
  (seed (2.3a), (2.3c), (2.3d)), when the kinematics has an advecting velocity (small strain):
      + du/dt . grad c^n    for c in m, f, b (painter2018)
  explicit, like the rest of the IMEX transport coupling: du/dt is the solid
  velocity of the last completed step and c^n the start-of-step concentration, so
  the species matrices stay constant (factorised once) and the solves linear.  It is
  stable while |du/dt| dt / h << 1, which the seed's runs satisfy by orders of
  magnitude (series.nc records the fields, so a violation shows as growth).  On
  the reference configuration (finite strain) there is none: advection is in the
  material derivative of (4.17a)-(4.17d);
* the sink of volume change, in the balance of each species declared ``volume_sink``
  (FGF for painter2018):
      + xi_f div u              small strain, seed (2.3c)
      + xi_f J (tr C - d)       finite strain, seed (4.17c) multiplied by J
  with u the current displacement (xi_f > 0: dilation consumes FGF).

Active stress (the reverse coupling, m driving the solid) is the separate module
:mod:`primordia.physics.active_stress`; growth driven by m is the growth law's
(:mod:`primordia.physics.growth_laws`).  Requires: ``u`` (a mechanics module) and
the species it couples (declared by the kinetics, transported by chemotaxis).

With the advection term the cell transport matrix is no longer an M-matrix in
general: non-negativity of m is guaranteed without solid motion only (the seed's
velocities are small; ``series.nc`` records min m so it can be checked).
"""

from __future__ import annotations

import ufl

from primordia.core.errors import ConfigError
from primordia.physics.base import Coupling
from primordia.physics.seed_parameters import MECHANOCHEMICAL


def solid_advection(velocity, c_previous, test, dx):
    """du/dt . grad c, explicit in c (seed eqs. (2.3a), (2.3c), (2.3d))."""
    return ufl.inner(velocity, ufl.grad(c_previous)) * test * dx


def fgf_sink(xi_f, volume_change, volume_ratio, test, dx):
    """xi_f div u (seed eq. (2.3c)), or xi_f J (tr C - d) (seed eq. (4.17c) times J)."""
    if isinstance(volume_ratio, (int, float)) and volume_ratio == 1:
        return xi_f * volume_change * test * dx
    return xi_f * volume_ratio * volume_change * test * dx


class MechanoChemical(Coupling):
    """Solid advection of the advected species (m, f, b) and the volume sink xi_f div u (of f)."""

    name = "mechanochemical"
    parameters = MECHANOCHEMICAL

    @property
    def advected(self) -> tuple[str, ...]:
        """Species carried by the solid velocity, as the kinetics declares them (m, f, b: seed (2.3a-d))."""
        return tuple(s.name for s in self.kinetics.species if s.advected)

    @property
    def sinks(self) -> tuple[str, ...]:
        """Species consumed by volume change, as the kinetics declares them (f: seed (2.3c))."""
        return tuple(s.name for s in self.kinetics.species if s.volume_sink)

    @property
    def requires(self) -> tuple[str, ...]:
        return ("u",) + tuple(dict.fromkeys(self.advected + self.sinks))

    def check_composition(self, modules):
        if self.kinetics is None:
            raise ConfigError("mechanochemical couples the species of a kinetics to the solid: "
                              "add chemotaxis to model.physics")

    def setup(self, disc):
        # terms are built when the balance laws are (after every module's setup): the kinematics
        # of the mechanics module are known by then
        for species in self.advected:
            disc.contribute(species, lambda test, species=species: self._advection(disc, species, test), by=self.name)
        for species in self.sinks:
            disc.contribute(species, lambda test: self._sink(disc, test), by=self.name)

    @staticmethod
    def _advection(disc, species: str, test):
        velocity = disc.kinematics.velocity
        if velocity is None:  # material coordinates: advection is in the material derivative
            return None
        return solid_advection(velocity, disc.previous(species), test, disc.dx)  # (2.3a), (2.3c), (2.3d)

    def _sink(self, disc, test):
        motion = disc.kinematics
        if motion.volume_change is None:
            raise ConfigError("mechanochemical: the mechanics module provides no volume-change measure "
                              "for the FGF sink")
        return fgf_sink(self.params["xi_f"], motion.volume_change, motion.volume_ratio, test,  # (2.3c), (4.17c)
                        disc.dx_degree(motion.quadrature_degree))
