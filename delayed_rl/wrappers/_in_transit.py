"""Items in transit, each sent at its own step with its own delay: what arrives when.

The one mechanism behind :class:`~delayed_rl.wrappers.action_delay.ActionLine` (actions on
their way to the actuator) and :class:`~delayed_rl.wrappers.observation_delay.NetworkArrival`
(observations on their way to the agent). Only the items in transit are kept, in a heap by
arrival step, so memory follows what is in flight, not the delay's bound.
"""

from __future__ import annotations

import heapq
from typing import Any

__all__ = ["InTransit"]


class InTransit:
    """Items sent at increasing steps, each arriving ``delay`` steps after it was sent."""

    def __init__(self) -> None:
        self._heap: list[tuple[int, int, Any]] = []  # (arrival step, sent step, item)

    def __len__(self) -> int:
        """How many items have not arrived yet."""
        return len(self._heap)

    def clear(self) -> None:
        """Forget every item in transit."""
        self._heap.clear()

    def send(self, step: int, item: Any, delay: int) -> None:
        """Send ``item`` at ``step`` (each step sends once); it arrives at ``step + delay``."""
        heapq.heappush(self._heap, (step + delay, step, item))  # (arrival, sent) unique

    def remaining(self) -> list[tuple[int, Any]]:
        """The items that have not arrived yet, by sent step (they stay in transit)."""
        return sorted(((sent, item) for _, sent, item in self._heap), key=lambda pair: pair[0])

    def arrived(self, step: int) -> list[tuple[int, Any]]:
        """The items that have arrived by ``step`` and were not yet taken, by sent step."""
        out = []
        while self._heap and self._heap[0][0] <= step:
            _, sent, item = heapq.heappop(self._heap)
            out.append((sent, item))
        out.sort(key=lambda pair: pair[0])
        return out
