"""Adaptive time steps: a failed step is undone and retried in smaller pieces, then dt grows back.

A run marches on the grid of its nominal steps, t_k = t_start + k dt (output times
are points of this grid, so they are hit exactly; the step of an output time or of t_final
reaches that time as written, not its rounded t_start + k dt: ``Model.step_time``).  Within a nominal step it takes
sub-steps of dt / 2^level.  A sub-step that fails (a Newton or Krylov solve that
does not converge, non-finite values, a negative density where the scheme promises
none) is undone and retried at the next level; after ``grow_after`` accepted
sub-steps in a row the level drops by one again, as soon as the sub-steps line up
with the coarser ones.  A sub-step that fails at once at the level it grew back to
doubles the wait before the next try (a dt still too large then costs one failed
sub-step per 2, 4, 8, ... good ones, not one in three); a grown-back level that holds
resets it.  Below ``dt_min`` the run gives up.  Levels are powers of
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
    wait: int = 0  # accepted sub-steps in a row before the level drops (0: grow_after)
    grown: bool = False  # the level was reached by growing back and no sub-step at it is done yet

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
        if self.grown:  # the larger sub-step holds
            self.grown, self.wait = False, 0
        self.streak += 1
        coarser = 2.0 * self.fraction
        if self.level > 0 and self.streak >= (self.wait or self.grow_after) and (done % coarser == 0.0
                                                                                 or done == 1.0):
            self.level -= 1
            self.streak = 0
            self.grown = True

    def rejected(self) -> bool:
        """A sub-step failed: halve it.  False when the halved step would fall below ``dt_min``."""
        if not self.adaptive or self.step / 2.0 < self.dt_min:
            return False
        if self.grown:  # the level it grew back to failed at once: wait twice as long before the next try
            self.wait, self.grown = 2 * (self.wait or self.grow_after), False
        self.level += 1
        self.streak = 0
        return True

    def state(self) -> dict:
        return asdict(self)

    def restore(self, state: dict) -> None:
        self.level, self.streak = int(state["level"]), int(state["streak"])
        # checkpoints written before the wait doubled have neither
        self.wait, self.grown = int(state.get("wait", 0)), bool(state.get("grown", False))
