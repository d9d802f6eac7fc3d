"""The arrays a compiled training run works on, in the named groups :func:`~delayed_rl.compiled.kernel.run_chunk` takes.

Each group is a ``NamedTuple`` of numpy arrays and numbers, which numba compiles as a tuple:
the Q-table and its cache (:class:`QCache`), the learning rule's constants (:class:`Rule`), the
reward delay (:class:`DelayLine`), the episode's transitions (:class:`History`), the per-step
record (:class:`StepLog`), scripted transitions (:class:`Script`), deconvolution's reward model
(:class:`RewardEstimates`) and MMQ's averaged table (:class:`TableAverage`). This module imports
no env: the agents build these groups without loading the e-puck's physics.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from delayed_rl import _portable_math as portable_math
from delayed_rl._delay_line import ring_size

#: Episode-end modes of the reward delay, as integers for the compiled code.
FLUSH, DROP, CARRY = 0, 1, 2


class QCache(NamedTuple):
    """The agent's Q-table and its exact cache, updated in place by :func:`run_chunk`.

    Attributes:
        q: the Q-values, shape (|S|, |Λ|, |A|).
        v_max: each state's max over (λ̂, a).
        v_cell: the flat index into ``q`` of an entry holding it.
        ties: how many entries of the state's row hold it (counted afresh at the start of each
            call, then kept exact).
        trace: the delay trace ``e(λ̂)``, one value per model, updated in place when
            :attr:`Rule.trace_decay` is on; else ``None``.
    """

    q: np.ndarray
    v_max: np.ndarray
    v_cell: np.ndarray
    ties: np.ndarray
    trace: np.ndarray | None = None


class Rule(NamedTuple):
    """The learning rule's constants: Λ, α, γ, the ε schedule and MMQ's credit options.

    With both options off (the defaults) every model is credited the delivered reward ``r_t``
    (the thesis's rule). Otherwise model ``j`` is credited ``r_t · w_t(j)``, ``w_t(j)`` the
    product of the options that are on: the kernel's ``credit_kernel[|Λ[j] − Λ[m_t]|]`` and the
    trace's ``e_t(j)``, ``m_t`` the acting model of step ``t``.

    Attributes:
        delay_estimates: Λ, sorted ascending (``int64``).
        learning_rate: α.
        gamma: γ.
        eps_initial: ε at step 0.
        eps_final: ε from step ``eps_steps`` on (linear in between).
        eps_steps: the length of the ε ramp, in steps (>= 1).
        credit_kernel: the reward kernel's weight by the distance ``|λ̂ − λ̂*|`` in steps (index
            0 to ``max Λ − min Λ``, from :func:`credit_kernel`); ``None``: off.
        trace_decay: β of the delay trace (each step ``e ← β e``, then ``e(m_t) ← 1``; the
            trace is :attr:`QCache.trace`); ``None``: off.
        lag_rates: the learning rate of each lag (one per entry of ``delay_estimates``), for a
            rule that credits several lags in *one* table (expected credit: ``α·w(k)``);
            ``None``: α for every lag.

    The Q-table has either one table per lag (MMQ: lag ``j`` updates table ``j``) or a single
    table that every lag updates (expected credit); the loop tells them by the table's shape.
    """

    delay_estimates: np.ndarray
    learning_rate: float
    gamma: float
    eps_initial: float
    eps_final: float
    eps_steps: int
    credit_kernel: np.ndarray | None = None
    trace_decay: float | None = None
    lag_rates: np.ndarray | None = None


def credit_kernel(delay_estimates: np.ndarray, width: float) -> np.ndarray:
    """The reward kernel's weights ``exp(−d² / (2σ²))`` for ``d = 0 .. max Λ − min Λ`` steps.

    Both training paths read a model's weight off this one array (so they agree to the bit):
    the weight of model λ̂ when λ̂* acts is ``weights[|λ̂ − λ̂*|]``. The exponential is
    ``delayed_rl._portable_math.exp``, the same bits on every CPU.

    Args:
        delay_estimates: Λ, sorted ascending.
        width: σ > 0, in steps (so large that ``σ²`` overflows: every weight 1).
    """
    distance = np.arange(int(delay_estimates[-1] - delay_estimates[0]) + 1, dtype=np.float64)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        weights = portable_math.exp_array(-(distance * distance) / (2.0 * width * width))
    weights[0] = 1.0  # d = 0 is full credit, even where σ² underflows to 0
    return weights


class DelayLine(NamedTuple):
    """The reward delay: this chunk's delays, the ring of pending rewards, the episode-end mode.

    Attributes:
        delays: one delay per step of the chunk (its length is the chunk's length).
        ring: the pending rewards, a power-of-two ring longer than every delay in ``delays``.
        episode_end_mode: :data:`FLUSH`, :data:`DROP` or :data:`CARRY`.
        discarded: one float, to which the loop adds the pending reward it discards when a
            ``TimeLimit`` above the reward delay cuts an episode
            (:attr:`~delayed_rl.compiled.tabular.TabularModel.cut_steps`; not under "carry").
    """

    delays: np.ndarray
    ring: np.ndarray
    episode_end_mode: int
    discarded: np.ndarray = np.zeros(1)


class History(NamedTuple):
    """The episode's transitions (rings of a power-of-two length > max Λ) and the run's clocks.

    Attributes:
        s: the state of each step.
        a: the action.
        s2: the next state.
        terminated: whether the step was terminal.
        clocks: ``[s, history length, episode steps, delay clock]``, carried between chunks.
    """

    s: np.ndarray
    a: np.ndarray
    s2: np.ndarray
    terminated: np.ndarray
    clocks: np.ndarray

    @classmethod
    def empty(cls, longest_delay: int) -> History:
        """An empty history whose rings hold ``longest_delay + 1`` steps, clocks at 0."""
        size = ring_size(longest_delay + 1)
        rings = [np.zeros(size, dtype) for dtype in (np.int64, np.int64, np.int64, np.bool_)]
        return cls(*rings, np.zeros(4, np.int64))


class StepLog(NamedTuple):
    """One entry per step of a chunk (arrays of the chunk's length, filled by :func:`run_chunk`).

    Attributes:
        undelayed_reward: the env's reward.
        reward: the reward delivered (delayed).
        obs: the state acted in.
        action: the action.
        acting_delay_index: the acting model's index into Λ.
        episode_end: the episode ended at this step (terminated or truncated).
        terminated: the step was terminal.
    """

    undelayed_reward: np.ndarray
    reward: np.ndarray
    obs: np.ndarray
    action: np.ndarray
    acting_delay_index: np.ndarray
    episode_end: np.ndarray
    terminated: np.ndarray

    @classmethod
    def empty(cls, steps: int) -> StepLog:
        """A log of ``steps`` zeroed entries."""
        floats = [np.zeros(steps) for _ in range(2)]
        ints = [np.zeros(steps, np.int64) for _ in range(3)]
        return cls(*floats, *ints, np.zeros(steps, np.bool_), np.zeros(steps, np.bool_))


class Script(NamedTuple):
    """Scripted transitions replayed instead of acting in the env.

    Attributes:
        transitions: rows ``(s, a, s′)``.
        terminated: one flag per row.
        rewards: the reward received at each row's step.
        acting: the acting model's index into Λ at each row's step (what the reward kernel
            centres on and the delay trace marks); empty: the greedy model of the row's state,
            the lowest index whose table holds the state's max (as MMQ's ``update()``), looked
            up only when a credit option is on (else 0).
    """

    transitions: np.ndarray
    terminated: np.ndarray
    rewards: np.ndarray
    acting: np.ndarray = np.zeros(0, np.int64)


class RewardEstimates(NamedTuple):
    """Learn from estimated mean rewards instead of the delivered ones (deconvolution).

    Attributes:
        rewards: ``R̂`` per (state, action) pair ``s·|A| + a``.
        stats: the regression's statistics, fed every step's pair, delivered reward and
            episode end (:func:`delayed_rl.compiled.deconvolution_statistics.observe`).
    """

    rewards: np.ndarray
    stats: tuple


class TableAverage(NamedTuple):
    """A moving average of the Q-table, updated every ``every`` steps (MMQ's greedy window).

    Attributes:
        table: the average, shaped as the Q-table, updated in place after every ``every``-th
            step's update: ``table ← table + rate · (q − table)``, the first time ``table ← q``.
        clock: ``[steps since the last update, updates so far]`` (``int64``), carried between
            calls.
        every: the steps between updates (>= 1).
        rate: the weight of an update.
    """

    table: np.ndarray
    clock: np.ndarray
    every: int
    rate: float
