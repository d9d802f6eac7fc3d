"""A training run on the compiled path, advanced chunk by chunk."""

from __future__ import annotations

import numpy as np

from delayed_rl.fast import kernel
from delayed_rl.fast.tabular import NotCompilable, inspect_stack

_MODES = {"flush": kernel.FLUSH, "drop": kernel.DROP, "carry": kernel.CARRY}


_NO_SCRIPT = (np.zeros((0, 3), np.int64), np.zeros(0, np.bool_), np.zeros(0))


def _pow2(n: int) -> int:
    return 1 << max(0, int(n - 1).bit_length())


class FusedRun:
    """The state of a compiled training run on one env stack: history, delay ring, clocks.

    The Q-table and its cached maxima belong to the agent and are updated in place.

    Args:
        env: the env stack (see :mod:`delayed_rl.fast.tabular` for what compiles).
        lags: the delay estimates Λ of the agent, one per Q-table model.
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

    def __init__(self, env, lags: np.ndarray, seed: int | None):
        if not kernel.HAVE_NUMBA:
            raise NotCompilable("numba is not installed (a core dependency: pip install numba)")
        self.model, wrapper = inspect_stack(env)
        self.delay = None if wrapper is None else wrapper.delay
        self.max_delay = None if wrapper is None else wrapper.max_delay
        self.mode = _MODES["flush" if wrapper is None else wrapper.on_episode_end]
        self.lags = np.asarray(lags, dtype=np.int64)
        self.history = [
            np.zeros(_pow2(int(self.lags.max()) + 1), dtype=dtype)
            for dtype in (np.int64, np.int64, np.int64, np.bool_)
        ]
        self.buffer = np.zeros(1)
        self.tie_counts = np.zeros(0, dtype=np.int64)
        seed_seq = np.random.SeedSequence(seed)
        kernel_seed, delay_seed = seed_seq.generate_state(2)
        kernel.seed_kernel(int(kernel_seed) & 0x7FFFFFFF)
        self.delay_rng = np.random.default_rng(delay_seed)
        self.state = np.zeros(4, dtype=np.int64)
        self.state[0] = self._initial_state()

    def _initial_state(self) -> int:
        return int(np.searchsorted(self.model.init_cdf, self.delay_rng.random(), side="right"))

    def _draw_delays(self, n: int) -> np.ndarray:
        if self.delay is None:
            return np.zeros(n, dtype=np.int64)
        delays = np.asarray(self.delay.sample(self.delay_rng, n), dtype=np.int64)
        if self.max_delay is not None:
            delays = np.minimum(delays, self.max_delay)
        return delays

    def _fit_buffer(self, longest: int) -> None:
        """Grow the delay ring to hold ``longest``, keeping pending rewards at their due steps."""
        size = _pow2(longest + 1)
        if size <= self.buffer.shape[0]:
            return
        old, clock = self.buffer, int(self.state[3])
        due = clock + np.arange(old.shape[0])
        new = np.zeros(size)
        new[due & (size - 1)] = old[due & (old.shape[0] - 1)]
        self.buffer = new

    def run(
        self,
        q: np.ndarray,
        qmax: np.ndarray,
        qcell: np.ndarray,
        steps: int,
        start_step: int,
        alpha: float,
        gamma: float,
        eps_initial: float,
        eps_final: float,
        eps_steps: int,
    ) -> dict:
        """Advance ``steps`` steps, updating ``q`` and its cache in place; return the step log.

        The log holds one entry per step: ``obs`` (the state acted in), ``action``, ``model``
        (the acting model's index), ``reward`` (delivered), ``undelayed_reward``,
        ``episode_end`` and ``terminated``; :attr:`state` ``[0]`` is the state after the last.

        ``qmax[s]`` is the max of ``q[s]`` and ``qcell[s]`` its flat index into ``q`` (the layout
        of :class:`~delayed_rl.agents.MultipleModelQLearning`'s cache).
        """
        delays = self._draw_delays(steps)
        self._fit_buffer(int(delays.max(initial=0)))
        log = {
            "undelayed_reward": np.zeros(steps),
            "reward": np.zeros(steps),
            "obs": np.zeros(steps, dtype=np.int64),
            "action": np.zeros(steps, dtype=np.int64),
            "model": np.zeros(steps, dtype=np.int64),
            "episode_end": np.zeros(steps, dtype=np.bool_),
            "terminated": np.zeros(steps, dtype=np.bool_),
        }
        m = self.model
        if self.tie_counts.shape != qmax.shape:
            self.tie_counts = np.zeros(qmax.shape, dtype=np.int64)
        kernel.run_chunk(
            q, self.lags, qmax, qcell, self.tie_counts,
            m.out_cdf, m.out_next, m.out_reward, m.out_term, m.init_cdf, m.max_steps,
            delays, self.buffer, self.mode,
            float(alpha), float(gamma), float(eps_initial), float(eps_final), int(eps_steps),
            int(start_step), *self.history, self.state,
            log["undelayed_reward"], log["reward"], log["obs"], log["action"], log["model"],
            log["episode_end"], log["terminated"], *_NO_SCRIPT,
        )  # fmt: skip
        return log
