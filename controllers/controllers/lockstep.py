"""The lock-step protocol between a stepping controller and the simulator (no ROS).

A lock-step run is a conversation: the controller reads the states of step k, decides, publishes
its commands (topics: ``cmd_vel``, joint trajectories), then asks for the next batch of steps
(a service). Topics and services travel on different DDS writers, and DDS orders messages only
per writer: a command may reach the simulator after the step request that it was meant to
precede. It is then applied one batch late, and the run depends on the machine's load.

The protocol binds every command to its step instead of trusting delivery order:

- the controller counts the commands it publishes (``CommandCounter``) and sends the count with
  the step request (``StepSimulation.commands``);
- the simulator counts the commands it receives (``CommandBarrier``) and does not step until
  it holds at least that many, then starts the next count from zero.

So a step runs only after every command decided before it has been applied, whatever the order
of arrival and however long DDS takes; a command cannot arrive after its step, because that step
waits for it. (A command from a third node is counted too: a run that another node commands
while it is stepped is not reproducible, and the surplus is reported.)

Both sides also share the rule of when a periodic output falls due (``next_on_grid``): the
first step at or after each multiple of its period. ``DueGrid`` replays it on the controller's
side, so that the controller knows which stamps a batch of steps produced and waits for exactly
those messages.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List


def next_on_grid(t_ns: int, period_ns: int) -> int:
    """The first point of the grid k * period strictly after t (skipping missed points)."""
    return (t_ns // period_ns + 1) * period_ns


class DueGrid:
    """The stamps at which the simulator publishes an output of the given period."""

    def __init__(self, dt_ns: int, period_ns: int) -> None:
        if dt_ns <= 0 or period_ns <= 0:
            raise ValueError(f'dt and period must be > 0 ns, got {dt_ns} and {period_ns}')
        self.dt_ns, self.period_ns = dt_ns, max(dt_ns, period_ns)
        self.next_ns = 0

    def start_after(self, t_ns: int) -> None:
        """Outputs up to ``t_ns`` are already out (the first observation waited for them)."""
        self.next_ns = next_on_grid(t_ns, self.period_ns)

    def advance(self, from_step: int, to_step: int) -> List[int]:
        """Stamps [ns] due in steps from_step+1 .. to_step."""
        due = []
        for k in range(from_step + 1, to_step + 1):
            t = k * self.dt_ns
            if t >= self.next_ns:
                due.append(t)
                self.next_ns = next_on_grid(t, self.period_ns)
        return due


class CommandCounter:
    """The controller's side: commands published since the last step request."""

    def __init__(self) -> None:
        self._count = 0

    def sent(self) -> None:
        self._count += 1

    def take(self) -> int:
        """The count for the step request being made now; the next step counts afresh."""
        count, self._count = self._count, 0
        return count


@dataclass(frozen=True)
class Claim:
    """What a step found when it took its commands."""
    expected: int
    received: int

    @property
    def surplus(self) -> int:
        """Commands nobody announced (another node commanding a lock-step run)."""
        return max(0, self.received - self.expected)


class CommandBarrier:
    """The simulator's side: commands received since the last step ran."""

    def __init__(self) -> None:
        self._received = 0

    @property
    def received(self) -> int:
        return self._received

    def arrived(self) -> None:
        self._received += 1

    def ready(self, expected: int) -> bool:
        """Whether a step that was announced ``expected`` commands may run."""
        return self._received >= expected

    def claim(self, expected: int) -> Claim:
        """The step runs now: every command received so far has been applied before it."""
        if not self.ready(expected):
            raise RuntimeError(f'step claimed with {self._received} of {expected} commands')
        claim = Claim(expected, self._received)
        self._received = 0
        return claim
