"""A training run on the compiled path, advanced chunk by chunk."""

from __future__ import annotations

import contextlib
import math
import warnings

import numpy as np

from delayed_rl._delay_line import delay_bound, draw_delays, regrow_ring, ring_size
from delayed_rl.compiled import arrivals, kernel, state
from delayed_rl.compiled.robot import RobotLink, linked
from delayed_rl.compiled.tabular import NotCompilable, inspect_stack

_MODES = {"flush": state.FLUSH, "drop": state.DROP, "carry": state.CARRY}

RING_LIMIT = 1 << 22
"""The most pending-reward slots a compiled run keeps (32 MiB of float64).

A compiled run holds its pending rewards in a ring as long as the longest delay it can draw. A
delay distribution that can reach further (e.g. ``Uniform(0, 2**27)`` on a continuing env) runs on
the Python path instead, whose ring holds only the rewards actually pending.
"""

DELAY_BLOCK = 4096
"""Delays are drawn in blocks of this many, whatever the chunks: a seeded run does not depend on
how ``learn()`` splits it (``log_interval``, callbacks)."""


class CompiledRun:
    """The state of a compiled training run on one env stack: history, delay ring, clocks.

    The Q-table and its cached maxima belong to the agent and are updated in place. A tabular
    env is simulated from its tables with the run's generator; its env object is not stepped.
    The e-puck env (:mod:`delayed_rl.compiled.robot`) is stepped itself, with its own generator
    drawing its noise: the run starts where the env is (reset it first, as ``learn()`` does) and
    leaves it where the run is.

    Args:
        env: the env stack (see :mod:`delayed_rl.compiled.tabular` for what compiles).
        delay_estimates: Λ, the agent's delay estimates (sorted), one per Q-table model.
        seed: seeds the run's own generators: one in the compiled code (actions, env
            outcomes: :func:`~delayed_rl.compiled.kernel.next_uniform`) and, apart from it, the
            reward delays'. No other run, thread or copy draws from them.
        held_transitions: for the oracle (who learns each transition from its own reward,
            :mod:`delayed_rl.compiled.arrivals`), how many recent transitions it credits; ``None``:
            the run learns from the delivered rewards.

    Attributes:
        state: ``[s, history length, episode steps, clock]``, carried from one call to the next.
        rng_state: the compiled generator's state (four ``uint64`` words).
        delay_rng: the generator of the reward delays.
        tie_counts: after :meth:`run`, how many entries of each state's Q-row hold its max (the
            compiled code keeps them to read the acting model off the cached arg-max unless the
            max is tied).
        arrivals: the oracle's record of who emitted each pending reward
            (:class:`~delayed_rl.compiled.arrivals.Arrivals`), or ``None``.
        wrapper: the stack's reward-delay wrapper, or ``None``; its flush-trap watch sees the
            run's steps (:meth:`~delayed_rl.wrappers.RewardDelay.watch_steps_taken_elsewhere`).
        robot: the link to the e-puck env the run steps (:class:`~delayed_rl.compiled.robot.RobotLink`),
            or ``None`` for a tabular env.

    Raises:
        NotCompilable: if numba is missing or the stack is outside the protocol.
    """

    def __init__(
        self,
        env,
        delay_estimates: np.ndarray,
        seed: int | None,
        *,
        held_transitions: int | None = None,
    ):
        if not kernel.HAVE_NUMBA:
            raise NotCompilable("numba is not installed (a core dependency: pip install numba)")
        self.robot = RobotLink(env.unwrapped) if linked(env.unwrapped) else None
        self.model, wrapper = inspect_stack(env, tables=self.robot is None)
        self.wrapper = wrapper
        self.delay = None if wrapper is None else wrapper.delay
        self.max_delay = None if wrapper is None else wrapper.max_delay
        self.on_episode_end = "flush" if wrapper is None else wrapper.on_episode_end
        self.mode = _MODES[self.on_episode_end]
        self.delay_clip = self._delay_clip()
        self.delay_estimates = np.asarray(delay_estimates, dtype=np.int64)
        self.history = state.History.empty(int(self.delay_estimates.max()))
        self.state = self.history.clocks
        self.ring = np.zeros(1)
        self.arrivals = (
            None if held_transitions is None else arrivals.Arrivals.empty(1, held_transitions)
        )
        self.tie_counts = np.zeros(0, dtype=np.int64)
        kernel_seeds, delay_seeds = np.random.SeedSequence(seed).spawn(2)
        self.rng_state = kernel.generator_state(kernel_seeds)
        self.delay_rng = np.random.default_rng(delay_seeds)
        if self.robot is None:
            first = np.searchsorted(self.model.init_cdf, self.delay_rng.random(), side="right")
        else:
            first = self.robot.observation()
        self.state[0] = first
        self._delay_block = np.zeros(0, dtype=np.int64)

    def _delay_clip(self) -> int | None:
        """The longest delay the ring must hold, or ``None`` (no reward delay).

        ``max_delay`` clips every delay. When episodes last at most ``n`` steps (the model's
        ``max_steps`` or ``cut_steps``) and pending rewards do not outlive an episode
        (``"flush"``, ``"drop"``), a delay of ``n`` or more comes due after the episode's end
        either way, so delays are clipped there too: that changes no delivery, only how far the
        ring must reach.

        Raises:
            NotCompilable: the delays can reach further than :data:`RING_LIMIT` slots.
        """
        if self.delay is None:
            return None
        clip = self.max_delay
        longest = min(n for n in (self.model.max_steps, self.model.cut_steps, math.inf) if n)
        if longest < math.inf and self.mode != state.CARRY:
            clip = int(longest) if clip is None else min(clip, int(longest))
        reach = delay_bound(self.delay, clip)
        if reach >= RING_LIMIT:
            raise NotCompilable(
                f"the reward delay ({self.delay!r}) can reach {reach} steps: the compiled ring "
                f"would take {ring_size(reach + 1) * 8 / 2**20:.0f} MiB (the limit is "
                f"{RING_LIMIT} slots); the Python path keeps only the rewards pending"
            )
        return clip

    def _draw_delays(self, n: int) -> np.ndarray:
        """The next ``n`` delays of the run's stream, drawn in blocks of :data:`DELAY_BLOCK`."""
        if self.delay is None or n == 0:
            return np.zeros(n, dtype=np.int64)
        parts, needed = [], n
        while needed > 0:
            if not self._delay_block.size:
                self._delay_block = draw_delays(
                    self.delay, self.delay_rng, DELAY_BLOCK, self.delay_clip
                )
            take = self._delay_block[:needed]
            self._delay_block = self._delay_block[needed:]
            parts.append(take)
            needed -= take.size
        return np.concatenate(parts) if len(parts) > 1 else parts[0]

    def _fit_ring(self, longest: int) -> None:
        """Grow the delay ring to hold ``longest``, keeping pending rewards at their due steps."""
        size = ring_size(longest + 1)
        if size > self.ring.shape[0]:
            self.ring = regrow_ring(self.ring, int(self.state[3]), size)
            if self.arrivals is not None:
                self.arrivals = arrivals.regrow(self.arrivals, int(self.state[3]), size)

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
        reward_model: state.RewardEstimates | None = None,
        credit_kernel: np.ndarray | None = None,
        trace_decay: float | None = None,
        trace: np.ndarray | None = None,
        lag_rates: np.ndarray | None = None,
        average: state.TableAverage | None = None,
    ) -> state.StepLog:
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
            reward_model: learn from estimated mean rewards (see
                :class:`~delayed_rl.compiled.state.RewardEstimates`); ``None``: the delivered rewards.
            credit_kernel: the reward kernel's weights by distance in steps
                (:func:`~delayed_rl.compiled.state.credit_kernel`); ``None``: off.
            trace_decay: β of the delay trace (``None``: off; then ``trace`` is not read).
            trace: the delay trace, one float64 per model, updated in place (the agent's).
            lag_rates: the learning rate of each lag, for a rule crediting several lags in one
                table (:attr:`~delayed_rl.compiled.state.Rule.lag_rates`); ``None``: α for all.
            average: a moving average of ``q`` to keep up to date
                (:class:`~delayed_rl.compiled.state.TableAverage`, its table shaped as ``q``);
                ``None``: none.

        Returns:
            One entry per step (:class:`~delayed_rl.compiled.state.StepLog`); :attr:`state`
            ``[0]`` is the state after the last.

        Raises:
            TypeError: ``steps`` is not an integer.
            ValueError: ``steps`` is negative (0 steps is a run that takes none), or
                ``credit_kernel`` is shorter than Λ's span, or ``trace_decay`` is given
                without a ``trace`` of one float64 per model (the compiled code does not check
                its indices), or ``lag_rates`` is not one float64 per lag, or ``average`` is not
                one it can keep (its table a C-contiguous float64 array shaped as ``q``, its
                clock two int64 counters, ``every`` ≥ 1, ``rate`` finite).
        """
        _check_steps(steps)
        delays = self._draw_delays(steps)
        self._fit_ring(int(delays.max(initial=0)))
        self._fit_tie_counts(v_max.shape)
        trace = _checked_credit(self.delay_estimates, credit_kernel, trace_decay, trace, lag_rates)
        if average is not None:
            _check_average(average, q.shape)
        cache = state.QCache(q, v_max, v_cell, self.tie_counts, trace)
        rule = state.Rule(
            delay_estimates=self.delay_estimates,
            learning_rate=float(learning_rate),
            gamma=float(gamma),
            eps_initial=float(eps_initial),
            eps_final=float(eps_final),
            eps_steps=int(eps_steps),
            credit_kernel=credit_kernel,
            trace_decay=None if trace_decay is None else float(trace_decay),
            lag_rates=lag_rates,
        )
        return self._advance(cache, rule, delays, steps, start_step, reward_model, average)

    def _fit_tie_counts(self, shape: tuple[int, ...]) -> None:
        """Give :attr:`tie_counts` the shape of the agent's ``v_max`` (zeros when it changes)."""
        if self.tie_counts.shape != shape:
            self.tie_counts = np.zeros(shape, dtype=np.int64)

    def _advance(
        self,
        cache: state.QCache,
        rule: state.Rule,
        delays: np.ndarray,
        steps: int,
        start_step: int,
        reward_model: state.RewardEstimates | None,
        average: state.TableAverage | None,
    ) -> state.StepLog:
        """Take the chunk's ``steps`` in the compiled loop, with its ``delays``; return their log.

        The e-puck's arguments are lent to the loop for the chunk
        (:meth:`~delayed_rl.compiled.robot.RobotLink.arguments`); what the loop saw is then
        passed on (:meth:`_report`).
        """
        line = state.DelayLine(delays, self.ring, self.mode, np.zeros(1))
        log = state.StepLog.empty(steps)
        with contextlib.ExitStack() as stack:
            robot = None if self.robot is None else stack.enter_context(self.robot.arguments())
            kernel.run_chunk(
                cache,
                rule,
                self.model,
                line,
                self.history,
                log,
                None,
                int(start_step),
                self.rng_state, reward_model, self.arrivals, average, robot,
            )  # fmt: skip
        self._report(line, log)
        return log

    def _report(self, line: state.DelayLine, log: state.StepLog) -> None:
        """Pass on what the chunk's loop saw: reward the resets discarded, the steps it took.

        The discarded reward (by a TimeLimit above the RewardDelay) is warned of; the steps go to
        the wrapper's flush-trap watch. Both warnings name the line that called the agent's
        ``learn()``: the stack levels count the calls from there down to this one.
        """
        if line.discarded[0] != 0.0:
            warnings.warn(
                f"a TimeLimit above the RewardDelay cut episodes short: the resets discarded "
                f"{line.discarded[0]} of pending reward (on_episode_end={self.on_episode_end!r}); "
                "end episodes inside the RewardDelay wrapper to have them flushed",
                stacklevel=7,
            )
        if self.wrapper is not None:
            ends = log.episode_end.astype(bool)
            self.wrapper.watch_steps_taken_elsewhere(log.undelayed_reward, ends, stacklevel=8)


def _check_steps(steps: object) -> None:
    """Refuse a step count that is not an integer ``>= 0`` (a bool is not one).

    Raises:
        TypeError: ``steps`` is not an integer.
        ValueError: ``steps`` is negative.
    """
    if isinstance(steps, (bool, np.bool_)) or not isinstance(steps, (int, np.integer)):
        raise TypeError(f"steps must be an integer >= 0, got {steps!r}")
    if steps < 0:
        raise ValueError(f"steps must be an integer >= 0, got {steps!r}")


def _checked_credit(
    estimates: np.ndarray,
    credit_kernel: np.ndarray | None,
    trace_decay: float | None,
    trace: np.ndarray | None,
    lag_rates: np.ndarray | None,
) -> np.ndarray | None:
    """Check the credit options against Λ (``estimates``); return the trace the loop is to read.

    The kernel first, then the trace, then the lag rates. The trace is ``None`` (not read) when
    ``trace_decay`` is, whatever was passed.

    Raises:
        ValueError: ``credit_kernel`` is not a float64 weight per distance in Λ's span, or
            ``trace_decay`` is given without a ``trace`` of one float64 per model, or
            ``lag_rates`` is not one float64 per lag.
    """
    span = int(estimates[-1] - estimates[0])
    if credit_kernel is not None and (
        credit_kernel.dtype != np.float64 or credit_kernel.shape[0] <= span
    ):
        raise ValueError("credit_kernel must hold a float64 weight per distance in Λ's span")
    if trace_decay is None:
        trace = None
    elif trace is None or trace.dtype != np.float64 or trace.shape != estimates.shape:
        raise ValueError(f"trace must be a float64 array of shape {estimates.shape}")
    if lag_rates is not None and (
        lag_rates.dtype != np.float64 or lag_rates.shape != estimates.shape
    ):
        raise ValueError(f"lag_rates must be a float64 array of shape {estimates.shape}")
    return trace


def _check_average(average: state.TableAverage, shape: tuple[int, ...]) -> None:
    """Refuse a :class:`~delayed_rl.compiled.state.TableAverage` the compiled loop cannot use.

    Raises:
        ValueError: the table is not a C-contiguous float64 array of ``shape``, the clock not
            two int64 counters, ``every`` not a positive integer or ``rate`` not a finite float.
    """
    table, clock = average.table, average.clock
    if table.dtype != np.float64 or table.shape != shape or not table.flags.c_contiguous:
        raise ValueError(f"average's table must be a C-contiguous float64 array of {shape}")
    if clock.dtype != np.int64 or clock.shape != (2,):
        raise ValueError(
            f"average's clock must be 2 int64 counters, got {clock.dtype} {clock.shape}"
        )
    if not isinstance(average.every, int) or average.every < 1:
        raise ValueError(f"average's every must be an integer >= 1, got {average.every!r}")
    if not isinstance(average.rate, float) or not np.isfinite(average.rate):
        raise ValueError(f"average's rate must be a finite float, got {average.rate!r}")
