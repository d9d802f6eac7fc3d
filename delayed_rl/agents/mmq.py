"""Multiple Model Q-learning (Campbell 2015, section 3.2, Eq. 3.7 and Algorithm 1).

The agent keeps one Q-table per delay hypothesis λ̂ ∈ Λ, stacked as ``q_table[s, λ̂, a]``.

- **Acting** in ``s``: λ̂* = argmax over λ̂ of max_a Q(s, a, λ̂), ε-greedy (with probability ε a
  uniformly random model); then a* = argmax_a Q(s, a, λ̂*), ε-greedy. Ties are broken uniformly
  at random at both levels. With a single model (Q-learning, fixed-delay Q-learning) the first
  level is skipped and draws no random numbers.
- **Learning** at episode step ``t`` from the received reward ``r_t``: for every λ̂ whose step
  ``t − λ̂`` is in this episode's history, with (s, a, s′, done) the transition of that step,
  ``Q(s, a, λ̂) += α (w_t(λ̂) r_t + γ (1 − done) max_{λ̂′, a′} Q(s′, a′, λ̂′) − Q(s, a, λ̂))``. The
  max spans all models, and all targets of a step are computed before any of its writes (the
  parallel update of the thesis's Roulette walk-through, Tables 3.2–3.5). The thesis's rule has
  ``w_t(λ̂) = 1``; the options multiply it, with λ̂*_t the acting model of step ``t``, by the
  reward kernel ``exp(−(λ̂ − λ̂*_t)² / (2σ²))`` (``reward_kernel=σ``) and by the delay trace
  ``e_t(λ̂)`` (``delay_trace=β``: ``e ← β e`` for every model, then ``e(λ̂*_t) ← 1``, each step).
- **Greedy readout**: the deterministic policy reads the current table (the thesis), or, with
  ``greedy_window=W``, an exponential moving average of it over about ``W`` training steps.
- **Cost** O(|Λ|) per step: each state's max over (λ̂, a) is cached with its position and
  recomputed only when the entry at that position decreases; the |Λ| updates of a step are one
  compiled call (:func:`_update_batch`) over a ring buffer of the episode's transitions, a
  single entry's update another (:func:`_write`). They run the operations of the numpy code
  they replaced in its order, so the tables are the same to the last bit; without numba they run
  as Python.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._delay_line import ring_size
from delayed_rl._numba import jit as _jit
from delayed_rl._validation import check_int, check_real
from delayed_rl.agents.common.base import TabularAgent
from delayed_rl.agents.common.compiled_loop import CompiledTables
from delayed_rl.agents.common.hyperparameters import (
    MAX_ABS_VALUE,
    check_limit,
    shares_hyperparameters,
)
from delayed_rl.agents.common.persistence import check_state_array
from delayed_rl.agents.common.python_loop import MAX_TIMESTEPS, MAX_TIMESTEPS_TEXT
from delayed_rl.compiled.state import TableAverage, credit_kernel

__all__ = ["MAX_TABLE_BYTES", "MultipleModelQLearning", "greedy_actions", "table_bytes"]

DEFAULT_MAX_DELAY_ESTIMATE = 50  # the thesis's λ̂max in the 9×9 grid world (section 5.1.1)
MAX_TABLE_BYTES = 2**30
"""The most memory an agent's tables may take (1 GiB), refused at construction above it.

The tables: the Q-table (|S|·|Λ|·|A| float64), its cache, the episode histories of both training
paths (rings of the next power of two above max Λ) and the per-model arrays (see
:func:`table_bytes`). The thesis's 9×9 grid world with |Λ| = 51 takes 0.2 MiB; 10⁵ states × 101
delay models × 10 actions, 0.8 GiB. A request above (``FixedDelayQLearning(delay_estimate=10**9)``,
``MultipleModelQLearning(max_delay_estimate=10**7)``) is refused with the size it would take, before anything is
allocated; a model file declaring such tables is refused the same way. Raise it (with
``save_util.MAX_MODEL_BYTES``, so files load back) for larger tables.
"""
_SMALL_ROW = 16  # rows up to this many entries are scanned in Python (cheaper than numpy calls)
_FULL_CREDIT = np.zeros(0)  # the weights of :func:`_update_batch` without the options
_NO_OPTION = np.zeros(0)  # the trace or the kernel of :func:`_credit_weights` when it is off
_VIEWS = (
    "_q_rows",
    "_q_flat",
    "_hist_s",
    "_hist_s2",
    "_hist_cell",
    "_q_items",
    "_v_max_items",
    "_v_cell_items",
)
"""MMQ's views of its tables (:meth:`MultipleModelQLearning._rebuild_derived`)."""
OPTION_NAMES = ("reward_kernel", "delay_trace", "greedy_window")
"""MMQ's own options beyond the thesis's rule (constructor arguments, saved with the agent)."""
_GREEDY_UPDATES = 100  # the averaged table is updated about this many times per window
_VALUE_RANGE = (-MAX_ABS_VALUE, MAX_ABS_VALUE)  # a model file's tables (see MAX_ABS_VALUE)
_VALUE_NOTE = " (|value| <= MAX_ABS_VALUE = 2**200, delayed_rl.agents.common.hyperparameters)"


def table_bytes(
    n_states: int,
    n_actions: int,
    n_models: int,
    largest_delay: int,
    *,
    averaged_table: bool = False,
    reward_kernel: bool = False,
    delay_trace: bool = False,
) -> int:
    """The bytes MMQ's tables take (to within a few per cent), before any is allocated.

    Args:
        n_states: |S|.
        n_actions: |A|.
        n_models: |Λ|.
        largest_delay: max Λ.
        averaged_table: count the greedy readout's averaged Q-table (``greedy_window``).
        reward_kernel: count the reward kernel's weights (one per step of Λ's span).
        delay_trace: count the delay trace (one per model).
    """
    history = ring_size(largest_delay + 1)
    # Q (float64), cache (max and cell), per model (Λ, offsets, counts), histories (Python 3
    # int64 rings, compiled 3 int64 + 1 bool), the valid-model count of each early episode step
    return (
        8 * n_states * n_models * n_actions * (2 if averaged_table else 1)
        + 16 * n_states
        + (40 if delay_trace else 32) * n_models
        + 49 * history
        + 8 * (largest_delay + 1) * (2 if reward_kernel else 1)
    )


def check_table_size(
    name: str | None,
    value: Any,
    n_models: int,
    largest: int,
    env: tuple[Any, int, int] | None = None,
    **options: bool,
) -> None:
    """Refuse tables above :data:`MAX_TABLE_BYTES`, before any is allocated.

    Args:
        name: the argument that sets Λ (``None``: none, as ``QLearning``'s).
        value: its value, for the message.
        n_models: |Λ|.
        largest: max Λ.
        env: ``(agent class, |S|, |A|)``; ``None`` checks Λ alone (one state, one action).
        **options: the options' tables to count (:func:`table_bytes`'s keywords).

    Raises:
        ValueError: the message names the argument and the memory the tables would take.
    """
    n_states, n_actions = (1, 1) if env is None else env[1:]
    size = table_bytes(n_states, n_actions, n_models, largest, **options)
    if size <= MAX_TABLE_BYTES:
        return
    limit = (
        f"MAX_TABLE_BYTES = {MAX_TABLE_BYTES / 2**30:g} GiB (delayed_rl.agents.mmq.MAX_TABLE_BYTES)"
    )
    models = f"{n_models} delay model(s) up to {largest} steps"
    if env is None:
        raise ValueError(
            f"{name} must keep the tables within {limit}, got {value}: {models} would take "
            f"{size / 2**30:.3g} GiB"
        )
    agent = env[0].__name__ + ("" if name is None else f"({name}={value})")
    raise ValueError(
        f"{agent} on an env of {n_states} states and {n_actions} actions needs "
        f"{size / 2**30:.3g} GiB of tables ({models}), over {limit}: use fewer delay estimates "
        "or a smaller state space"
    )


def _delay_argument_name(cls: type, delay_estimates: Any) -> str | None:
    """The constructor argument of ``cls`` that set Λ, for messages (``None``: none sets it).

    ``delay_estimates`` when given and ``cls`` takes it (MMQ), ``delay_estimate`` when ``cls``
    takes that instead (``FixedDelayQLearning``), none when ``cls`` fixes Λ itself
    (``QLearning``); else ``max_delay_estimate``.
    """
    if delay_estimates is None:
        return "max_delay_estimate"
    parameters = inspect.signature(cls).parameters
    for name in ("delay_estimates", "delay_estimate"):
        if name in parameters:
            return name
    return None


def _shown(values: Any) -> str:
    """``values`` for a message, shortened when long."""
    values = list(values)
    return (
        repr(values)
        if len(values) <= 8
        else f"[{values[0]}, ..., {values[-1]}] ({len(values)} values)"
    )


def check_delay_estimates(
    max_delay_estimate: Any, delay_step: Any, delay_estimates: Any, name: str | None = None
) -> np.ndarray:
    """Λ from MMQ's three ways of giving it, validated; sorted ``int64`` array of distinct values.

    Λ must fit :data:`MAX_TABLE_BYTES` (checked before anything is allocated, with one state
    and one action; the constructor checks again with the env's spaces). ``name`` is the
    argument a message about it names when ``delay_estimates`` is given (default
    ``"delay_estimates"``; ``"delay_estimate"`` shows its one value).

    Raises:
        TypeError, ValueError: an invalid or contradictory argument (the message names it).
    """
    if delay_estimates is not None:
        if max_delay_estimate is not None or delay_step is not None:
            raise ValueError(
                "give either delay_estimates or max_delay_estimate/delay_step, not both "
                f"(got delay_estimates={delay_estimates!r}, max_delay_estimate="
                f"{max_delay_estimate!r}, delay_step={delay_step!r})"
            )
        if isinstance(delay_estimates, (str, bytes)) or not isinstance(
            delay_estimates, (Sequence, np.ndarray, range)
        ):
            raise TypeError(
                "delay_estimates must be a sequence of distinct integers >= 0, "
                f"got {delay_estimates!r}"
            )
        values = [check_int(f"delay_estimates[{i}]", v, 0) for i, v in enumerate(delay_estimates)]
        if not values:
            raise ValueError(
                "delay_estimates must be a non-empty sequence of distinct integers >= 0"
            )
        if len(set(values)) != len(values):
            raise ValueError(f"delay_estimates must be distinct, got {delay_estimates!r}")
        name = name or "delay_estimates"
        value = values[0] if name == "delay_estimate" else _shown(values)
        check_table_size(name, value, len(values), max(values))
        return np.array(sorted(values), dtype=np.int64)
    if max_delay_estimate is None:
        max_delay_estimate = DEFAULT_MAX_DELAY_ESTIMATE
    if delay_step is None:
        delay_step = 1
    max_delay_estimate = check_int("max_delay_estimate", max_delay_estimate, 0)
    delay_step = check_int("delay_step", delay_step, 1)
    largest = max_delay_estimate - max_delay_estimate % delay_step
    check_table_size("max_delay_estimate", max_delay_estimate, largest // delay_step + 1, largest)
    return np.arange(0, max_delay_estimate + 1, delay_step, dtype=np.int64)


def greedy_actions(q_table: np.ndarray, states: np.ndarray | None = None) -> np.ndarray:
    """MMQ's deterministic greedy policy read off a Q-table of shape ``(|S|, |Λ|, |A|)``.

    Per state, the action of the first arg-max over (λ̂, a) in row-major order: the lowest-index
    λ̂* whose table holds the state's max, then the lowest-index a* in that table.

    Args:
        q_table: the Q-values (e.g. ``agent.q_table`` or a snapshot of it).
        states: 0-based state indices (``None``: every state).

    Returns:
        The 0-based action index of each state, ``int64``.
    """
    rows = q_table.reshape(q_table.shape[0], -1)
    if states is not None:
        rows = rows[states]
    return rows.argmax(axis=1) % q_table.shape[2]


@_jit
def _first_max(values, start, stop):
    """The max of ``values[start:stop]`` and the index of its first occurrence (as ``argmax``)."""
    best, first = values[start], start
    for i in range(start + 1, stop):
        if values[i] > best:
            best, first = values[i], i
    return best, first


@_jit
def _count_equal(values, start, stop, value):
    """How many entries of ``values[start:stop]`` equal ``value`` (a loop the compiler vectorises)."""
    count = 0
    for i in range(start, stop):
        count += values[i] == value
    return count


@_jit
def _models_holding(q_flat, start, n_models, n_actions, value):
    """The models (ascending) whose table in the row at ``q_flat[start:]`` holds ``value``."""
    models = np.empty(n_models, np.int64)
    count = 0
    for model in range(n_models):
        first = start + model * n_actions
        for i in range(first, first + n_actions):
            if q_flat[i] == value:
                models[count] = model
                count += 1
                break
    return models[:count]


@_jit
def _write(q_flat, v_max, v_cell, s, cell, target, rate):
    """:meth:`MultipleModelQLearning._write_entry`, compiled (cheaper than Python for one entry).

    ``Q[cell] += rate · (target − Q[cell])``; the cache of state ``s`` is raised to the new
    value when it passes the max, and its row rescanned when the cached cell fell.
    """
    old = q_flat[cell]
    new = old + rate * (target - old)
    q_flat[cell] = new
    if new > v_max[s]:
        v_max[s] = new
        v_cell[s] = cell
    elif new < old and v_cell[s] == cell:
        size = q_flat.shape[0] // v_max.shape[0]
        v_max[s], v_cell[s] = _first_max(q_flat, s * size, (s + 1) * size)


@_jit
def _textbook_update(q_flat, v_max, v_cell, s, a, r, s2, terminated, alpha, gamma):
    """Q-learning's update of the transition ``(s, a, r, s2)``, compiled: one call a step.

    ``Q(s, a) += α (r + γ (1 − terminated) max Q(s2) − Q(s, a))`` with the max read off the
    cache (:func:`_write`), for an agent of one model whose λ̂ is 0.
    """
    size = q_flat.shape[0] // v_max.shape[0]
    bootstrap = 0.0 if terminated else v_max[s2]
    _write(q_flat, v_max, v_cell, s, s * size + a, r + gamma * bootstrap, alpha)


@_jit
def _credit_weights(trace, decay, kernel, estimates, acting):
    """:meth:`MultipleModelQLearning._credit_weights`, compiled: each model's share of ``r``.

    The delay trace (empty: off) decays by ``decay`` and the acting model's entry becomes 1;
    model ``j``'s weight is ``kernel[|Λ[j] − Λ[acting]|]`` (empty: off) times its trace entry.
    """
    if trace.shape[0]:
        for j in range(trace.shape[0]):
            trace[j] *= decay
        trace[acting] = 1.0
        if not kernel.shape[0]:
            return trace
    weights = np.empty(estimates.shape[0])
    for j in range(estimates.shape[0]):
        weights[j] = kernel[abs(estimates[j] - estimates[acting])]
        if trace.shape[0]:
            weights[j] *= trace[j]
    return weights


@_jit
def _update_batch(
    q_flat, v_max, v_cell, history, back, n, t, mask, r, weights, alpha, gamma, terminal, n_actions
):
    """:meth:`MultipleModelQLearning._update_models`, compiled: one call a step, not two dozen.

    Model ``j < n`` learns from the transition at ring position ``p = (t + back[j]) & mask``: it
    moves the cell ``hist_cell[p] + j·|A|`` towards ``r·weights[j] + γ·v_max[hist_s2[p]]``
    (``weights`` empty: ``r``; ``terminal``: model 0 does not bootstrap), every target read off
    the cache as it was before the step. Then the cache: the states whose cached cell fell are
    rescanned, and the entries that rose above their state's old max raise it, the last of equal
    ones taking the cell. These are the operations, in their order, of the numpy version this
    replaced, to the last bit.

    Args:
        q_flat: the Q-table, flat.
        v_max: each state's max over its row.
        v_cell: the flat index of an entry holding it.
        history: the ring, rows ``s``, ``s2`` and model 0's cell.
        back: per model, its transition's offset from ``t`` in the ring (``−λ̂``).
        n: how many models learn (the first ``n``).
        t: the episode step.
        mask: the ring's length minus one (a power of two minus one).
        r: the received reward.
        weights: each model's share of ``r`` (the options), or empty.
        alpha: the learning rate.
        gamma: the discount.
        terminal: model 0's transition is terminal.
        n_actions: |A|.
    """
    size = q_flat.shape[0] // v_max.shape[0]
    states = np.empty(n, np.int64)
    cells = np.empty(n, np.int64)
    values = np.empty(n)
    fell = np.zeros(n, np.bool_)
    rose = np.zeros(n, np.bool_)
    for j in range(n):
        p = (t + back[j]) & mask
        s = history[0, p]
        cell = history[2, p] + j * n_actions
        bootstrap = 0.0 if j == 0 and terminal else v_max[history[1, p]]
        credit = r * weights[j] if weights.shape[0] else r
        target = credit + gamma * bootstrap
        old = q_flat[cell]
        new = old + alpha * (target - old)
        q_flat[cell] = new
        states[j], cells[j], values[j] = s, cell, new
        fell[j] = v_cell[s] == cell and new < old
        rose[j] = new > v_max[s]
    for j in range(n):
        if fell[j]:
            s = states[j]
            v_max[s], v_cell[s] = _first_max(q_flat, s * size, (s + 1) * size)
    for j in range(n):
        if rose[j] and values[j] > v_max[states[j]]:
            v_max[states[j]] = values[j]
    for j in range(n):
        if rose[j] and values[j] == v_max[states[j]]:
            v_cell[states[j]] = cells[j]


class MultipleModelQLearning(TabularAgent):
    """Multiple Model Q-learning (MMQ): Q-learning over parallel delay hypotheses.

    For rewards that arrive a random number of steps late (e.g. under
    :class:`~delayed_rl.wrappers.PoissonRewardDelay`), MMQ keeps one Q-table per delay estimate
    λ̂ ∈ Λ. Each step's reward is credited, in table λ̂, to the transition λ̂ steps back; the agent
    acts from the table whose best value is highest, so it learns which delay hypothesis pays
    (see the module docstring for the exact rule). ``QLearning`` is the case Λ = {0} and
    ``FixedDelayQLearning(delay_estimate=k)`` the case Λ = {k}.

    Args:
        env: the training env (``Discrete`` observation and action spaces) or an env id.
        max_delay_estimate: λ̂max; Λ = {0, delay_step, 2·delay_step, ...} up to λ̂max
            (default 50, the thesis's grid-world setting).
        delay_step: the resolution of Λ (default 1).
        delay_estimates: Λ given explicitly (distinct integers ≥ 0; stored sorted), instead of
            ``max_delay_estimate``/``delay_step``.
        reward_kernel: ``None`` (default: the thesis's rule, every table is credited the
            received reward ``r_t``) or a width σ > 0, in steps of delay: at step ``t`` the
            table of λ̂ is credited ``r_t · exp(−(λ̂ − λ̂*_t)² / (2σ²))`` instead, λ̂*_t the
            acting model that chose ``a_t`` (full credit to the hypothesis that drives
            behaviour, less the farther a hypothesis is from it). Only the reward is scaled:
            every table that can learn at step ``t`` still updates, bootstrapping as before. A
            σ far above the span of Λ is the thesis's rule.
        delay_trace: ``None`` (default: no trace) or a decay β in [0, 1]: an eligibility trace
            over the models, ``e(λ̂)``, that shares the reward with the hypotheses that acted
            recently. Each training step first decays it, ``e(λ̂) ← β·e(λ̂)`` for every model,
            then sets ``e(λ̂*_t) ← 1`` (a replacing trace); the reward credited to table λ̂ is
            then multiplied by ``e_t(λ̂)``. β = 0 credits only the acting model's table; β = 1
            credits every model that has ever acted in full. The trace starts at 0 for every
            model and is carried over episode ends and across ``learn()`` calls (the delay is a
            property of the env, not of an episode); it is saved and copied with the agent
            (:attr:`delay_trace_values`). With ``reward_kernel`` too, the two weights multiply.
        greedy_window: ``None`` (default: the deterministic policy reads the current table, as
            in the thesis) or a window ``W`` ≥ 1, in training steps: ``predict(...,
            deterministic=True)`` then reads :attr:`greedy_table`, an exponential moving
            average of the Q-table with time constant ``W``: every ``max(1, W // 100)``
            training steps (counted from the agent's construction, by ``learn()`` and
            ``update()`` alike), ``G ← G + (interval / W)·(Q − G)``, the first update setting
            ``G = Q``; before it the greedy policy reads ``Q``. Acting while training and the
            exploring ``predict`` still use the current table. The averaged table doubles the
            Q-table's memory (counted against :data:`MAX_TABLE_BYTES`); an update is a pass
            over the whole table, every ``interval`` steps (inside the compiled loop on the
            compiled path).
        **hyperparameters: the hyper-parameters every agent shares, by keyword
            (``learning_rate``, ``gamma``, ``exploration_initial_eps``,
            ``exploration_final_eps``, ``exploration_fraction``, ``q_init``, ``seed``,
            ``verbose``): see :class:`~delayed_rl.agents.common.base.TabularAgent`. ε applies at both
            levels; set ``q_init`` above the achievable values for optimistic exploration (the
            thesis does; e.g. 50 in the Roulette example).

    The acting model λ̂*_t is the one the behaviour policy chose at step ``t`` in ``learn()``;
    for a transition given to :meth:`update`, which the agent did not choose, it is the greedy
    model of the transition's state (:meth:`preferred_delay`), read before the update.

    Example:
        >>> import gymnasium as gym
        >>> import delayed_rl
        >>> from delayed_rl.agents import MultipleModelQLearning
        >>> env = gym.make("delayed_rl/GridWorld-5x5-v0", reward_delay=3)
        >>> agent = MultipleModelQLearning(env, max_delay_estimate=10, q_init=20.0, seed=0).learn(2_000)
        >>> agent.q_table.shape
        (25, 11, 4)
    """

    _hyperparameter_names = (*TabularAgent._hyperparameter_names, "delay_estimates", *OPTION_NAMES)
    _optional_hyperparameter_names = OPTION_NAMES  # files written before the options lack them
    _derived = (*TabularAgent._derived, *_VIEWS)  # views of the tables: rebuilt on copies

    @shares_hyperparameters
    def __init__(
        self,
        env: gym.Env | str,
        max_delay_estimate: int | None = None,
        delay_step: int | None = None,
        delay_estimates: Sequence[int] | None = None,
        *,
        reward_kernel: float | None = None,
        delay_trace: float | None = None,
        greedy_window: int | None = None,
        **hyperparameters: Any,
    ):
        given = zip(OPTION_NAMES, (reward_kernel, delay_trace, greedy_window), strict=True)
        for option, given_value in given:  # a subclass that does not take them (QLearning)
            if given_value is not None and option not in self._hyperparameter_names:
                raise TypeError(
                    f"{type(self).__name__}.__init__() got an unexpected keyword argument "
                    f"{option!r}"
                )
        self._set_options(reward_kernel, delay_trace, greedy_window)
        name = _delay_argument_name(type(self), delay_estimates)
        self._delay_estimates = check_delay_estimates(
            max_delay_estimate, delay_step, delay_estimates, name
        )
        value: Any = _shown(self.delay_estimates)
        if name == "max_delay_estimate":
            value = self.delay_estimates[-1] if max_delay_estimate is None else max_delay_estimate
        elif name == "delay_estimate":
            value = self.delay_estimates[0]
        self._delay_argument = (name, value)  # what a message about the tables' size names
        super().__init__(env, **hyperparameters)

    def _set_options(
        self, reward_kernel: Any = None, delay_trace: Any = None, greedy_window: Any = None
    ) -> None:
        """Check and set the options (see the class docstring).

        Raises:
            TypeError: an option of the wrong type (the message names it).
            ValueError: an option out of range.
        """
        self.reward_kernel = check_real(
            "reward_kernel", reward_kernel, 0.0, low_open=True, optional=True
        )
        self.delay_trace = check_real("delay_trace", delay_trace, 0.0, 1.0, optional=True)
        self.greedy_window = check_limit(
            "greedy_window",
            check_int("greedy_window", greedy_window, 1, optional=True),
            MAX_TIMESTEPS,
            MAX_TIMESTEPS_TEXT,
        )

    # ------------------------------------------------------------------ model
    @property
    def delay_estimates(self) -> list[int]:
        """Λ, the delay hypotheses (sorted): ``q_table[:, i, :]`` assumes delay ``Λ[i]``."""
        return self._delay_estimates.tolist()

    @property
    def q_table(self) -> np.ndarray:
        """The Q-values, shape ``(|S|, |Λ|, |A|)`` (a read-only view; change it via learning)."""
        view = self._q.view()
        view.flags.writeable = False
        return view

    @property
    def greedy_table(self) -> np.ndarray:
        """The table the deterministic policy reads, shape ``(|S|, |Λ|, |A|)`` (read-only view).

        :attr:`q_table` itself without ``greedy_window`` (and before the average's first
        update); else the moving average of the Q-table (see the class docstring).
        """
        view = self._greedy_source().view()
        view.flags.writeable = False
        return view

    @property
    def delay_trace_values(self) -> np.ndarray | None:
        """The delay trace ``e(λ̂)``, indexed like :attr:`delay_estimates` (a copy).

        ``None`` without ``delay_trace``.
        """
        return None if self._trace is None else self._trace.copy()

    def _greedy_source(self) -> np.ndarray:
        """The array :attr:`greedy_table` shows."""
        if self._greedy_q is None or not self._greedy_clock[1]:
            return self._q
        return self._greedy_q

    def _state_array_specs(self) -> dict[str, tuple[tuple[int, ...], Any]]:
        n_models = len(self._delay_estimates)
        shape = (self.n_states, n_models, self.n_actions)
        specs: dict[str, tuple[tuple[int, ...], Any]] = {
            "q_table": (shape, np.float64),
            "delay_estimates": ((n_models,), np.int64),
        }
        if self.delay_trace is not None:
            specs["delay_trace"] = ((n_models,), np.float64)
        if self.greedy_window is not None:
            specs["greedy_table"] = (shape, np.float64)
            specs["greedy_clock"] = ((2,), np.int64)
        return specs

    def _setup_model(self) -> None:
        n_models = len(self._delay_estimates)
        name, value = getattr(
            self, "_delay_argument", ("delay_estimates", _shown(self.delay_estimates))
        )
        env = (type(self), self.n_states, self.n_actions)
        check_table_size(
            name,
            value,
            n_models,
            int(self._delay_estimates[-1]),
            env,
            averaged_table=self.greedy_window is not None,
            reward_kernel=self.reward_kernel is not None,
            delay_trace=self.delay_trace is not None,
        )
        self.n_models = n_models
        self._row_size = n_models * self.n_actions
        self._q = np.full((self.n_states, n_models, self.n_actions), self.q_init)
        self._v_max = np.zeros(self.n_states)
        self._v_cell = np.zeros(self.n_states, dtype=np.int64)
        self._smallest_estimate = int(self._delay_estimates[0])
        self._largest_estimate = int(self._delay_estimates[-1])
        history = ring_size(self._largest_estimate + 1)
        self._history_mask = history - 1
        self._history = np.zeros((3, history), dtype=np.int64)  # rows: s, s2, model 0's cell
        self._back = -self._delay_estimates  # each model's transition is λ̂ steps back
        self._rebuild_derived()
        self._rebuild_cache()
        # how many models can learn at episode step t < max Λ: those with λ̂ <= t
        self._n_valid = np.searchsorted(
            self._delay_estimates, np.arange(self._largest_estimate + 1), side="right"
        ).tolist()
        self._has_zero_estimate = bool(self._delay_estimates[0] == 0)
        self._t = 0
        self._setup_options()

    def _setup_options(self) -> None:
        """The options' arrays: the kernel's weights, the trace, the averaged table."""
        self._credit_kernel = (
            None
            if self.reward_kernel is None
            else credit_kernel(self._delay_estimates, self.reward_kernel)
        )
        self._trace = None if self.delay_trace is None else np.zeros(self.n_models)
        window = self.greedy_window
        self._greedy_interval = 0 if window is None else max(1, window // _GREEDY_UPDATES)
        self._greedy_q = None if window is None else np.zeros_like(self._q)
        self._greedy_clock = np.zeros(2, dtype=np.int64)  # [steps since an update, updates]
        self._weighted = self.reward_kernel is not None or self.delay_trace is not None
        # one model, λ̂ = 0, no options: the update is the textbook one (thesis Eq. 3.2)
        self._textbook = self.n_models == 1 and self._has_zero_estimate and not self._weighted
        self._acting: int | None = None  # the acting model _choose picked for the next step

    def _rebuild_derived(self) -> None:
        """The views of the tables (:data:`_VIEWS`).

        ``_q_rows`` (one row of |Λ|·|A| entries a state) and ``_q_flat`` are numpy views of the
        Q-table. The memoryviews ``_q_items``, ``_v_max_items``, ``_v_cell_items`` and the rows
        of the history ring, ``_hist_s``, ``_hist_s2`` and ``_hist_cell``, read and write single
        entries as Python numbers, at half the cost of numpy's scalar indexing.
        """
        super()._rebuild_derived()
        self._q_rows = self._q.reshape(self.n_states, self._row_size)
        self._q_flat = self._q.reshape(-1)
        self._hist_s, self._hist_s2, self._hist_cell = (memoryview(row) for row in self._history)
        self._q_items = memoryview(self._q_flat)
        self._v_max_items = memoryview(self._v_max)
        self._v_cell_items = memoryview(self._v_cell)

    def _rebuild_cache(self) -> None:
        """Recompute every state's max over (λ̂, a) (``_v_max``) and its cell (``_v_cell``)."""
        self._repair(np.arange(self.n_states))

    def _end_episode(self) -> None:
        self._t = 0

    def compiled_tables(self) -> CompiledTables:
        """The Q-table, its cache and Λ: MMQ's rule runs compiled for every Λ, options included.

        With ``greedy_window``, the compiled loop keeps the averaged table itself, at the same
        training steps and with the same arithmetic as :meth:`_average_greedy` on the Python
        path.
        """
        tables = CompiledTables(self._q, self._v_max, self._v_cell, self._delay_estimates)
        if not (self._weighted or self._greedy_interval):
            return tables
        tables = tables._replace(
            credit_kernel=self._credit_kernel, trace_decay=self.delay_trace, trace=self._trace
        )
        if self._greedy_interval:
            rate = self._greedy_interval / self.greedy_window
            average = TableAverage(self._greedy_q, self._greedy_clock, self._greedy_interval, rate)
            tables = tables._replace(average=average)
        return tables

    def _average_greedy(self) -> None:
        """One update of the averaged table: ``G ← G + (interval / W)(Q − G)`` (first: ``Q``)."""
        clock, greedy = self._greedy_clock, self._greedy_q
        if clock[1]:
            greedy += (self._greedy_interval / self.greedy_window) * (self._q - greedy)
        else:
            greedy[...] = self._q
        clock[0] = 0
        clock[1] += 1

    # ------------------------------------------------------------------ acting
    def _choose(self, s: int, eps: float, uniform: Callable[[], float]) -> tuple[int, int]:
        """The behaviour policy at ``s``: the acting model, then its action (see the module)."""
        if self.n_models == 1:
            return self._choose_action(s, eps, uniform)
        if uniform() < eps:  # explore the models
            model = int(uniform() * self.n_models)
            return self._choose_action(s, eps, uniform, model, explored=True)
        return self._choose_action(s, eps, uniform, self._greedy_model(s, uniform))

    def _greedy_model(self, s: int, uniform: Callable[[], float]) -> int:
        """A model whose table holds state ``s``'s max, ties broken at random.

        When the max is not tied (the common case) it is the cached cell's model, found by
        counting the row's entries equal to the max, without listing them.
        """
        best, size = self._v_max_items[s], self._row_size
        start = s * size
        if size <= _SMALL_ROW:
            ties = self._q_items[start : start + size].tolist().count(best)
        else:
            ties = _count_equal(self._q_flat, start, start + size, best)
        if ties == 1:
            return (self._v_cell_items[s] - start) // self.n_actions
        models = _models_holding(self._q_flat, start, self.n_models, self.n_actions, best)
        return int(models[0] if models.size == 1 else models[int(uniform() * models.size)])

    def _choose_action(
        self,
        s: int,
        eps: float,
        uniform: Callable[[], float],
        model: int = 0,
        explored: bool = False,
    ) -> tuple[int, int]:
        """``(model, action)``: an ε-greedy action of ``model``'s table at ``s``, random ties.

        ``model`` becomes the acting model (the options centre on it). Unless it was
        ``explored``, its table holds the state's max, read off the cache. With one model this
        is the whole behaviour policy: Q-learning and fixed-delay Q-learning use it as their
        ``_choose``. Small rows are read as Python floats (cheaper than numpy calls); an
        untied max, the common case, is found without building the list of ties.
        """
        self._acting = model
        n_actions = self.n_actions
        if uniform() < eps:
            return model, int(uniform() * n_actions)
        start = (s * self.n_models + model) * n_actions
        if n_actions <= _SMALL_ROW:
            row = self._q_items[start : start + n_actions].tolist()
            best = max(row) if explored else self._v_max_items[s]
            if row.count(best) == 1:
                return model, row.index(best)
            ties: Any = [i for i, value in enumerate(row) if value == best]
        else:
            row = self._q_flat[start : start + n_actions]
            ties = np.flatnonzero(row == (row.max() if explored else self._v_max_items[s]))
        n = len(ties)
        return model, int(ties[0] if n == 1 else ties[int(uniform() * n)])

    def _greedy_actions(self, states: np.ndarray) -> np.ndarray:
        return greedy_actions(self._greedy_source(), states)

    def preferred_delay(self, observation: Any) -> Any:
        """λ̂* at ``observation``: the delay estimate whose table holds the state's best value.

        Ties go to the smallest estimate. Returns an ``int`` for one observation and an ``int64``
        array for a batch.
        """
        index, single = self._obs_index.indices(observation, "observation")
        flat = index.reshape(-1)
        models = self._q_rows[flat].argmax(axis=1) // self.n_actions
        delays = self._delay_estimates[models]
        return int(delays[0]) if single else delays

    # ------------------------------------------------------------------ learning
    def update(
        self,
        obs: Any,
        action: Any,
        reward: float,
        next_obs: Any,
        terminated: bool = False,
        truncated: bool = False,
    ) -> None:
        """One learning step from a transition you drove yourself (see ``TabularAgent.update``).

        The reward kernel and the delay trace take the greedy model of ``obs``
        (:meth:`preferred_delay`, before the update) as the acting model.
        """
        self._acting = None
        super().update(obs, action, reward, next_obs, terminated, truncated)

    def _learn_transition(
        self, s: int, a: int, r: float, s2: int, terminated: bool, truncated: bool
    ) -> None:
        if self._textbook:  # Q-learning's own update of this transition
            _textbook_update(
                self._q_flat,
                self._v_max,
                self._v_cell,
                s,
                a,
                r,
                s2,
                terminated,
                self._alpha,
                self.gamma,
            )
        else:  # the transition joins the history ring (only a λ̂ > 0 reads it back)
            weights = self._step_weights(s) if self._weighted else None
            t = self._t
            cell = s * self._row_size + a
            if self._largest_estimate:
                j = t & self._history_mask
                self._hist_s[j] = s
                self._hist_s2[j] = s2
                self._hist_cell[j] = cell
            n = self.n_models if t >= self._largest_estimate else self._n_valid[t]
            if n == 1:
                credited = r if weights is None else float(r * weights[0])
                if self._smallest_estimate:
                    self._update_first_model(t, credited)
                else:  # λ̂ = 0: this very transition
                    bootstrap = 0.0 if terminated else self._v_max_items[s2]
                    self._write_entry(s, cell, credited + self.gamma * bootstrap, self._alpha)
            elif n:
                self._update_models(n, self._back, r, terminated, weights, t)
        self.num_timesteps += 1
        self._t = 0 if (terminated or truncated) else self._t + 1
        if self._greedy_interval:
            self._greedy_clock[0] += 1
            if self._greedy_clock[0] >= self._greedy_interval:
                self._average_greedy()

    def _step_weights(self, s: int) -> np.ndarray:
        """This step's share of the reward per model (the options), about the acting model.

        The acting model is the one :meth:`_choose` picked, or for a transition the agent did
        not choose (:meth:`update`) the greedy model of ``s``.
        """
        acting = self._acting
        if acting is None:
            acting = int(self._q_rows[s].argmax()) // self.n_actions
        self._acting = None
        return self._credit_weights(acting)

    def _credit_weights(self, acting: int) -> np.ndarray:
        """Advance the delay trace to this step; each model's share of the reward, ``w_t``.

        The products are the compiled loop's, in its order (kernel weight, then trace): one
        compiled call (:func:`_credit_weights`).
        """
        trace, kernel = self._trace, self._credit_kernel
        return _credit_weights(
            _NO_OPTION if trace is None else trace,
            0.0 if self.delay_trace is None else self.delay_trace,
            _NO_OPTION if kernel is None else kernel,
            self._delay_estimates,
            acting,
        )

    def _update_models(
        self,
        n: int,
        back: np.ndarray,
        r: float,
        terminated: bool,
        weights: np.ndarray | None = None,
        t: int = 0,
    ) -> None:
        """Update Q(s_{t−λ̂}, a_{t−λ̂}, λ̂) for the first ``n`` models, all targets first.

        Args:
            n: how many models learn (the first ``n``).
            back: per model, where its transition is in the history ring relative to ``t``:
                ``−λ̂`` (or, with ``t = 0``, the ring positions themselves).
            r: the received reward.
            terminated: the current step (model 0's, when λ̂ = 0 is in Λ) is terminal.
            weights: each model's share of ``r`` (the options; ``None``: all of it).
            t: the episode step.
        """
        _update_batch(
            self._q_flat,
            self._v_max,
            self._v_cell,
            self._history,
            back,
            n,
            t,
            self._history_mask,
            r,
            _FULL_CREDIT if weights is None else weights,
            self._alpha,
            self.gamma,
            terminated and self._has_zero_estimate,
            self.n_actions,
        )

    def _update_first_model(self, t: int, r: float) -> None:
        """The update of the one model that can learn at step ``t``, a λ̂ > 0 (Python scalars).

        Its transition, ``λ̂`` steps back, is read off the history; it is not terminal (only the
        current step can be, in an episode).
        """
        position = (t - self._smallest_estimate) & self._history_mask
        target = r + self.gamma * self._v_max_items[self._hist_s2[position]]
        self._write_entry(self._hist_s[position], self._hist_cell[position], target, self._alpha)

    def _write_entry(self, s: int, cell: int, target: float, rate: float) -> None:
        """``Q[cell] += rate · (target − Q[cell])`` for an entry of state ``s``, cache kept exact.

        The one-entry update every single-table rule shares (Q-learning, fixed delay, the oracle,
        expected credit): one compiled call (:func:`_write`).
        """
        _write(self._q_flat, self._v_max, self._v_cell, s, cell, target, rate)

    def _repair(self, states: np.ndarray) -> None:
        """Recompute the cached max and its cell for ``states`` (distinct state indices)."""
        rows = self._q_rows[states]
        arg = rows.argmax(axis=1)
        self._v_max[states] = rows[np.arange(states.size), arg]
        self._v_cell[states] = states * self._row_size + arg

    # ------------------------------------------------------------------ diagnostics
    @property
    def acting_delay_share(self) -> np.ndarray:
        """The share of ``learn()`` steps each λ̂ was the acting model (since the counter reset).

        Indexed like :attr:`delay_estimates`; all zeros before any training step.
        """
        counts = np.asarray(self._statistics.acting_counts, dtype=np.float64)
        total = counts.sum()
        return counts / total if total else counts

    def _record_model_metrics(self, logger: Any) -> None:
        if self.n_models == 1:
            return
        counts = self._statistics.acting_counts_since_log()
        total = counts.sum()
        if total:
            logger.record(
                "mmq/acting_delay_mean", float(np.sum(counts * self._delay_estimates) / total)
            )
            logger.record(
                "mmq/acting_delay_mode", int(self._delay_estimates[int(np.argmax(counts))])
            )
            logger.record("mmq/acting_delay_mode_share", float(counts.max() / total))

    # ------------------------------------------------------------------ persistence
    def _get_state_arrays(self) -> dict[str, np.ndarray]:
        arrays = {"q_table": self._q.copy(), "delay_estimates": self._delay_estimates.copy()}
        if self._trace is not None:
            arrays["delay_trace"] = self._trace.copy()
        if self._greedy_q is not None:
            arrays["greedy_table"] = self._greedy_q.copy()
            arrays["greedy_clock"] = self._greedy_clock.copy()
        return arrays

    def _set_state_arrays(self, arrays: dict[str, np.ndarray], where: str) -> None:
        """Check every state array against this agent's tables, then set them.

        ``q_table`` (and ``greedy_table``) must be float64 of the agent's shape with every entry
        within ±:data:`~delayed_rl.agents.common.hyperparameters.MAX_ABS_VALUE`; ``delay_estimates``
        must be Λ as the metadata gives it; ``delay_trace`` in [0, 1]; ``greedy_clock`` the
        steps since the average's last update (below its interval) and the updates made (at
        most ``MAX_TIMESTEPS``). Nothing is set unless every array passes.

        Raises:
            ValueError: an array is missing or wrong (the message names the file and it).
        """
        expected = (self.n_states, self.n_models, self.n_actions)
        q = check_state_array(
            f"{where}: q_table",
            arrays.get("q_table"),
            expected,
            np.float64,
            *_VALUE_RANGE,
            note=_VALUE_NOTE,
        )
        delays = arrays.get("delay_estimates")
        if delays is None or not np.array_equal(delays, self._delay_estimates):
            shown = "missing" if delays is None else _shown(np.ravel(delays).tolist())
            raise ValueError(
                f"{where}: the delay_estimates array ({shown}) does not match the "
                f"metadata ({_shown(self.delay_estimates)})"
            )
        self._set_option_arrays(arrays, where)
        self._q[...] = q
        self._rebuild_cache()

    def _set_option_arrays(self, arrays: dict[str, np.ndarray], where: str) -> None:
        """Check and set the options' state (the trace, the averaged table and its clock)."""
        trace = greedy = clock = None
        if self._trace is not None:
            trace = check_state_array(
                f"{where}: delay_trace",
                arrays.get("delay_trace"),
                self._trace.shape,
                np.float64,
                0.0,
                1.0,
            )
        if self._greedy_q is not None:
            greedy = check_state_array(
                f"{where}: greedy_table",
                arrays.get("greedy_table"),
                self._greedy_q.shape,
                np.float64,
                *_VALUE_RANGE,
                note=_VALUE_NOTE,
            )
            clock = check_state_array(
                f"{where}: greedy_clock",
                arrays.get("greedy_clock"),
                (2,),
                np.int64,
                0,
                MAX_TIMESTEPS,
                note=f" ({MAX_TIMESTEPS_TEXT})",
            )
            if clock[0] >= self._greedy_interval:
                raise ValueError(
                    f"{where}: greedy_clock[0] (the steps since the averaged table's last "
                    f"update) must be below its interval {self._greedy_interval} (greedy_window="
                    f"{self.greedy_window}), got {int(clock[0])}"
                )
        if trace is not None:
            self._trace[...] = trace
        if greedy is not None:
            self._greedy_q[...] = greedy
            self._greedy_clock[...] = clock

    def _set_hyperparameters(self, *, delay_estimates: Any = None, **kwargs: Any) -> None:
        """Also Λ and the options, when loading (the constructor sets them itself)."""
        if delay_estimates is not None:
            self._delay_estimates = check_delay_estimates(None, None, delay_estimates)
        elif "_delay_estimates" not in vars(self):
            raise TypeError(
                "delay_estimates must be a sequence of distinct integers >= 0, got None"
            )
        options = {name: kwargs.pop(name) for name in OPTION_NAMES if name in kwargs}
        if options or "greedy_window" not in vars(self):  # loading (a file may lack them)
            self._set_options(**options)
        super()._set_hyperparameters(**kwargs)
