"""Adaptive time steps: a failed step is undone and retried in smaller pieces, then dt grows back.

A run marches on the grid of its nominal steps, t_k = t_start + k dt (output times
are points of this grid, so they are hit exactly; the step of an output time or of t_final
reaches that time as written, not its rounded t_start + k dt: ``Model.step_time``).  Within a nominal step it takes
sub-steps of dt / 2^level.  A sub-step that fails (a Newton or Krylov solve that
does not converge, non-finite values, a negative density where the scheme promises
none) is undone and retried at the next level; after ``grow_after`` accepted
sub-steps in a row the level drops by one again, as soon as the sub-steps line up
with the coarser ones.  Below ``dt_min`` the run gives up.  Levels are powers of
two so that every sub-step ends on a representable point of the nominal interval
and the last one lands exactly on t_{k+1}.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass
class StepController:
    """Which fraction of a nominal step the next sub-step covers, and how that changes."""

    dt: float  # the nominal step
    dt_min: float
    adaptive: bool = True
    grow_after: int = 2
    level: int = 0  # sub-steps of dt / 2**level
    streak: int = 0  # sub-steps accepted in a row at this level

    @property
    def fraction(self) -> float:
        """The part of a nominal step the next sub-step covers (exact: a power of two)."""
        return 2.0 ** -self.level

    @property
    def step(self) -> float:
        """The length of the next sub-step."""
        return self.dt * self.fraction

    def accepted(self, done: float) -> None:
        """A sub-step was accepted; ``done`` is the part of the nominal step now behind."""
        self.streak += 1
        coarser = 2.0 * self.fraction
        if self.level > 0 and self.streak >= self.grow_after and (done % coarser == 0.0 or done == 1.0):
            self.level -= 1
            self.streak = 0

    def rejected(self) -> bool:
        """A sub-step failed: halve it.  False when the halved step would fall below ``dt_min``."""
        if not self.adaptive or self.step / 2.0 < self.dt_min:
            return False
        self.level += 1
        self.streak = 0
        return True

    def state(self) -> dict:
        return asdict(self)

    def restore(self, state: dict) -> None:
        self.level, self.streak = int(state["level"]), int(state["streak"])
