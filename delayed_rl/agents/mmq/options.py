"""MMQ's options beyond the thesis's rule: the credit options and the averaged greedy table.

- :class:`CreditOptions`: the reward kernel (``reward_kernel=σ``) and the delay trace
  (``delay_trace=β``), which scale the reward each model is credited at a step;
- :class:`GreedyAverage`: the moving average of the Q-table that the deterministic policy reads
  with ``greedy_window=W``.

Their exact rules are in :class:`~delayed_rl.agents.mmq.mmq.MultipleModelQLearning`'s
docstring; both training paths apply them with the same arithmetic, in the same order.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from delayed_rl._validation import check_int, check_limit, check_real
from delayed_rl.agents.common.persistence import check_state_array
from delayed_rl.agents.common.python_loop import MAX_TIMESTEPS
from delayed_rl.agents.common.q_agent import VALUE_NOTE, VALUE_RANGE
from delayed_rl.agents.mmq.updates import NO_OPTION, model_weights
from delayed_rl.compiled.state import TableAverage, credit_kernel

__all__ = ["GREEDY_UPDATES", "OPTION_NAMES", "CreditOptions", "GreedyAverage", "check_options"]

OPTION_NAMES = ("reward_kernel", "delay_trace", "greedy_window")
"""MMQ's own options beyond the thesis's rule (constructor arguments, saved with the agent)."""
GREEDY_UPDATES = 100
"""The averaged table is updated about this many times per window."""


def check_options(
    reward_kernel: Any, delay_trace: Any, greedy_window: Any
) -> tuple[float | None, float | None, int | None]:
    """MMQ's options checked: σ > 0, β in [0, 1], ``W`` an integer in [1, MAX_TIMESTEPS] (or ``None``).

    Raises:
        TypeError: an option of the wrong type (the message names it).
        ValueError: an option out of range.
    """
    return (
        check_real("reward_kernel", reward_kernel, 0.0, low_open=True, optional=True),
        check_real("delay_trace", delay_trace, 0.0, 1.0, optional=True),
        check_limit(
            "greedy_window",
            check_int("greedy_window", greedy_window, 1, optional=True),
            MAX_TIMESTEPS,
        ),
    )


class CreditOptions:
    """Each model's share of a step's reward: the reward kernel's weight times the delay trace.

    Args:
        delay_estimates: Λ, sorted.
        reward_kernel: σ, or ``None`` (off).
        delay_trace: β, or ``None`` (off).

    Attributes:
        kernel: the kernel's weight by the distance ``|λ̂ − λ̂*|`` (``None``: off).
        trace: the delay trace ``e(λ̂)``, one value per model, carried across episodes and
            ``learn()`` calls (``None``: off).
        on: whether any option is on (else every model is credited the whole reward).
    """

    def __init__(
        self, delay_estimates: np.ndarray, reward_kernel: float | None, delay_trace: float | None
    ):
        self.delay_estimates = delay_estimates
        self.decay = delay_trace
        self.kernel = (
            None if reward_kernel is None else credit_kernel(delay_estimates, reward_kernel)
        )
        self.trace = None if delay_trace is None else np.zeros(delay_estimates.size)
        self.on = reward_kernel is not None or delay_trace is not None

    def weights(self, acting: int) -> np.ndarray:
        """Advance the trace to this step; each model's share ``w_t`` when ``acting`` acted.

        The products are the compiled loop's, in its order (kernel weight, then trace): one
        compiled call (:func:`~delayed_rl.agents.mmq.updates.model_weights`).
        """
        return model_weights(
            NO_OPTION if self.trace is None else self.trace,
            0.0 if self.decay is None else self.decay,
            NO_OPTION if self.kernel is None else self.kernel,
            self.delay_estimates,
            acting,
        )

    def check_trace(self, arrays: dict[str, np.ndarray], where: str) -> np.ndarray | None:
        """A model file's ``delay_trace``, checked (in [0, 1], one per model), or ``None``."""
        if self.trace is None:
            return None
        return check_state_array(
            f"{where}: delay_trace", arrays.get("delay_trace"), self.trace.shape, np.float64,
            0.0, 1.0,
        )  # fmt: skip


class GreedyAverage:
    """A moving average ``G`` of the Q-table, updated every ``interval`` training steps.

    It doubles the Q-table's memory (counted against ``MAX_TABLE_BYTES``); an update is a pass
    over the whole table, every ``interval`` steps (inside the compiled loop on the compiled
    path).

    Args:
        q: the Q-table it averages.
        window: ``W``, in training steps.

    Attributes:
        table: ``G``, shaped as the Q-table.
        interval: ``max(1, W // GREEDY_UPDATES)``.
        clock: ``[steps since the last update, updates so far]`` (``int64``).
    """

    def __init__(self, q: np.ndarray, window: int):
        self.q, self.window = q, window
        self.interval = max(1, window // GREEDY_UPDATES)
        self.table = np.zeros_like(q)
        self.clock = np.zeros(2, dtype=np.int64)

    @property
    def source(self) -> np.ndarray:
        """The table the greedy policy reads: ``G``, or the Q-table before the first update."""
        return self.table if self.clock[1] else self.q

    def tick(self) -> None:
        """Count one training step; update ``G`` when ``interval`` steps have passed."""
        clock = self.clock
        clock[0] += 1
        if clock[0] >= self.interval:
            if clock[1]:
                self.table += (self.interval / self.window) * (self.q - self.table)
            else:
                self.table[...] = self.q
            clock[0] = 0
            clock[1] += 1

    def compiled(self) -> TableAverage:
        """The same average for the compiled loop, which updates it in place."""
        return TableAverage(self.table, self.clock, self.interval, self.interval / self.window)

    def check_arrays(self, arrays: dict[str, np.ndarray], where: str) -> tuple[np.ndarray, ...]:
        """A model file's ``greedy_table`` and ``greedy_clock``, checked.

        Raises:
            ValueError: a missing or wrong array, or a clock at or past its interval.
        """
        table = check_state_array(
            f"{where}: greedy_table", arrays.get("greedy_table"), self.table.shape, np.float64,
            *VALUE_RANGE, note=VALUE_NOTE,
        )  # fmt: skip
        clock = check_state_array(
            f"{where}: greedy_clock", arrays.get("greedy_clock"), (2,), np.int64, 0,
            MAX_TIMESTEPS, note=f" ({MAX_TIMESTEPS.text})",
        )  # fmt: skip
        if clock[0] >= self.interval:
            raise ValueError(
                f"{where}: greedy_clock[0] (the steps since the averaged table's last "
                f"update) must be below its interval {self.interval} (greedy_window="
                f"{self.window}), got {int(clock[0])}"
            )
        return table, clock
