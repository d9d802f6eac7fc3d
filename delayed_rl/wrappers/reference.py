"""The reward-delay rule, written plainly: a schedule keyed by the step clock.

:class:`ReferenceRewardDelay` is the one statement of what every reward-delay implementation of
the library does, for reading and for tests: each implementation is tested against it step by
step (``docs/semantics.md`` lists them and the tests).
"""

from __future__ import annotations

import math
from collections import defaultdict

__all__ = ["ReferenceRewardDelay"]


class ReferenceRewardDelay:
    """The reward-delay rule for one env, step by step.

    The reward ``r_t`` emitted at step ``t`` (on the clock of steps since construction) with
    delay ``d_t`` is due at step ``t + d_t``; a step delivers the sum of the rewards due then.
    When an episode ends at step ``t`` (terminated or truncated), what is still pending is, by
    ``on_episode_end``: delivered at that step too (``"flush"``), discarded (``"drop"``), or
    kept, due at its own steps in the next episodes (``"carry"``). A reset in the middle of an
    episode discards what is pending except under ``"carry"``.

    Args:
        on_episode_end: ``"flush"``, ``"drop"`` or ``"carry"``.

    Attributes:
        clock: the steps taken.
        due: per step of the clock, the ``(emission step, reward)`` pairs due then.
    """

    def __init__(self, on_episode_end: str):
        self.mode = on_episode_end
        self.clock = 0
        self.due: dict[int, list[tuple[int, float]]] = defaultdict(list)

    def pending(self) -> float:
        """The exact sum of the rewards emitted and not yet delivered."""
        return math.fsum(r for items in self.due.values() for _, r in items)

    def step(
        self, reward: float, delay: int, ended: bool
    ) -> tuple[list[tuple[int, float]], float, float]:
        """Emit ``reward`` with ``delay``; deliver what is due now.

        Returns:
            ``(arrivals, flushed, dropped)``: the ``(emission step, reward)`` pairs delivered at
            this step (in the order the rewards fall due, then of emission), what the episode's
            end flushed into them and what it dropped (0.0 unless ``ended``). The step's
            delivered reward is the sum of the arrivals' rewards.
        """
        self.due[self.clock + delay].append((self.clock, reward))
        arrivals = self.due.pop(self.clock, [])
        self.clock += 1
        flushed = dropped = 0.0
        if ended and self.mode != "carry":
            rest = [item for when in sorted(self.due) for item in self.due[when]]
            self.due.clear()
            if self.mode == "flush":
                arrivals = arrivals + rest
                flushed = math.fsum(r for _, r in rest)
            else:
                dropped = math.fsum(r for _, r in rest)
        return arrivals, flushed, dropped

    def delivered(self, reward: float, delay: int, ended: bool) -> float:
        """:meth:`step`, giving the exact sum delivered at this step."""
        arrivals, _, _ = self.step(reward, delay, ended)
        return math.fsum(r for _, r in arrivals)

    def reset_mid_episode(self) -> float:
        """A reset before the episode ended: what it discards (nothing under ``"carry"``)."""
        if self.mode == "carry":
            return 0.0
        lost = self.pending()
        self.due.clear()
        return lost
