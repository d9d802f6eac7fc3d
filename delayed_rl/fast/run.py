"""A training run on the compiled path, advanced chunk by chunk."""

from __future__ import annotations

import numpy as np

from delayed_rl._delay_line import draw_delays, regrow_ring, ring_size
from delayed_rl.fast import kernel
from delayed_rl.fast.tabular import NotCompilable, inspect_stack

_MODES = {"flush": kernel.FLUSH, "drop": kernel.DROP, "carry": kernel.CARRY}


class FusedRun:
    """The state of a compiled training run on one env stack: history, delay ring, clocks.

    The Q-table and its cached maxima belong to the agent and are updated in place.

    Args:
        env: the env stack (see :mod:`delayed_rl.fast.tabular` for what compiles).
        delay_estimates: Λ, the agent's delay estimates (sorted), one per Q-table model.
        seed: seeds the compiled generator (actions, env outcomes) and, through a separate
            stream, the reward delays.

    Attributes:
        state: ``[s, history length, episode steps, clock]``, carried from one call to the next.
        tie_counts: after :meth:`run`, how many entries of each state's Q-row hold its max (the
            compiled code keeps them to read the acting model off the cached arg-max unless the
            max is tied).

    Raises:
        NotCompilable: if numba is missing or the stack is outside the protocol.
    """

    def __init__(self, env, delay_estimates: np.ndarray, seed: int | None):
        if not kernel.HAVE_NUMBA:
            raise NotCompilable("numba is not installed (a core dependency: pip install numba)")
        self.model, wrapper = inspect_stack(env)
        self.delay = None if wrapper is None else wrapper.delay
        self.max_delay = None if wrapper is None else wrapper.max_delay
        self.mode = _MODES["flush" if wrapper is None else wrapper.on_episode_end]
        self.delay_estimates = np.asarray(delay_estimates, dtype=np.int64)
        self.history = kernel.History.empty(int(self.delay_estimates.max()))
        self.state = self.history.clocks
        self.ring = np.zeros(1)
        self.tie_counts = np.zeros(0, dtype=np.int64)
        kernel_seed, delay_seed = np.random.SeedSequence(seed).generate_state(2)
        kernel.seed_kernel(int(kernel_seed) & 0x7FFFFFFF)
        self.delay_rng = np.random.default_rng(delay_seed)
        self.state[0] = np.searchsorted(self.model.init_cdf, self.delay_rng.random(), side="right")

    def _draw_delays(self, n: int) -> np.ndarray:
        if self.delay is None:
            return np.zeros(n, dtype=np.int64)
        return draw_delays(self.delay, self.delay_rng, n, self.max_delay)

    def _fit_ring(self, longest: int) -> None:
        """Grow the delay ring to hold ``longest``, keeping pending rewards at their due steps."""
        size = ring_size(longest + 1)
        if size > self.ring.shape[0]:
            self.ring = regrow_ring(self.ring, int(self.state[3]), size)

    def run(
        self,
        q: np.ndarray,
        v_max: np.ndarray,
        v_cell: np.ndarray,
        steps: int,
        *,
        start_step: int,
        learning_rate: float,
        gamma: float,
        eps_initial: float,
        eps_final: float,
        eps_steps: int,
    ) -> kernel.StepLog:
        """Advance ``steps`` steps, updating ``q`` and its cache in place; return the step log.

        Args:
            q: the Q-table, shape (|S|, |Λ|, |A|).
            v_max: each state's max of ``q[s]`` (the agent's cache, kept exact).
            v_cell: the flat index into ``q`` of an entry holding it.
            steps: how many steps.
            start_step: the training step of the first of them (for the ε schedule).
            learning_rate: α.
            gamma: γ.
            eps_initial: ε at training step 0.
            eps_final: ε from training step ``eps_steps`` on (linear in between).
            eps_steps: the length of the ε ramp (>= 1).

        Returns:
            One entry per step (:class:`~delayed_rl.fast.kernel.StepLog`); :attr:`state`
            ``[0]`` is the state after the last.
        """
        delays = self._draw_delays(steps)
        self._fit_ring(int(delays.max(initial=0)))
        if self.tie_counts.shape != v_max.shape:
            self.tie_counts = np.zeros(v_max.shape, dtype=np.int64)
        cache = kernel.QCache(q, v_max, v_cell, self.tie_counts)
        rule = kernel.Rule(
            delay_estimates=self.delay_estimates,
            learning_rate=float(learning_rate),
            gamma=float(gamma),
            eps_initial=float(eps_initial),
            eps_final=float(eps_final),
            eps_steps=int(eps_steps),
        )
        line = kernel.DelayLine(delays, self.ring, self.mode)
        log = kernel.StepLog.empty(steps)
        kernel.run_chunk(
            cache, rule, self.model, line, self.history, log, kernel.NO_SCRIPT, int(start_step)
        )
        return log
