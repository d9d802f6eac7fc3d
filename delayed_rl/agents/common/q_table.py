"""The Q-table every algorithm learns in, with an exact cache of each state's max.

A :class:`QTable` holds ``values[s, λ̂, a]``: one table per delay estimate λ̂ ∈ Λ (a single one,
λ̂ = 0, for the Q-learning agents), and for each state ``s`` the cache ``v_max[s]``, the max
of the state's row of |Λ|·|A| entries, with ``v_cell[s]``, the flat index of an entry holding
it. The cache is exact after every write (:func:`write`): raised when an entry passes the max,
the row rescanned when the entry holding it falls. So the bootstrap ``max Q(s′)`` of every
rule and the acting model's choice cost O(1) instead of O(|Λ|·|A|).

The compiled training path keeps its own, richer cache of the same table (``v_max``, ``v_cell``
and a tie count, :mod:`delayed_rl.compiled.kernel`) and hands the table back with ``v_max`` and
``v_cell`` exact, so the two paths continue each other's runs.

Memory: :func:`table_bytes` counts what an agent's tables take and :func:`check_table_size`
refuses more than :data:`MAX_TABLE_BYTES` before anything is allocated.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from delayed_rl._delay_line import ring_size
from delayed_rl._numba import jit as _jit

__all__ = [
    "MAX_TABLE_BYTES",
    "QTable",
    "check_table_size",
    "greedy_actions",
    "table_bytes",
    "write",
]

MAX_TABLE_BYTES = 2**30
"""The most memory an agent's tables may take (1 GiB), refused at construction above it.

The tables: the Q-table (|S|·|Λ|·|A| float64), its cache, the episode histories of both training
paths (rings of the next power of two above max Λ) and the per-model arrays (see
:func:`table_bytes`). The thesis's 9×9 grid world with |Λ| = 51 takes 0.2 MiB; 10⁵ states × 101
delay models × 10 actions, 0.8 GiB. A request above (``FixedDelayQLearning(delay_estimate=10**9)``,
``MultipleModelQLearning(max_delay_estimate=10**7)``) is refused with the size it would take,
before anything is allocated; a model file declaring such tables is refused the same way. Raise
it (with ``save_util.MAX_MODEL_BYTES``, so files load back) for larger tables.
"""
_SMALL_ROW = 16  # rows up to this many entries are scanned in Python (cheaper than numpy calls)


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
    """The bytes an agent's tables take (to within a few per cent), before any is allocated.

    Args:
        n_states: |S|.
        n_actions: |A|.
        n_models: |Λ|.
        largest_delay: max Λ.
        averaged_table: count MMQ's averaged Q-table (``greedy_window``).
        reward_kernel: count MMQ's reward-kernel weights (one per step of Λ's span).
        delay_trace: count MMQ's delay trace (one per model).
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
    # the value read now, so that a raised MAX_TABLE_BYTES is the one the message names
    limit = f"MAX_TABLE_BYTES = {MAX_TABLE_BYTES / 2**30:g} GiB ({__name__}.MAX_TABLE_BYTES)"
    models = f"{n_models} delay model(s) up to {largest} steps"
    if env is None:
        raise ValueError(
            f"{name} must keep the tables within {limit}, got {value}: {models} would "
            f"take {size / 2**30:.3g} GiB"
        )
    agent = env[0].__name__ + ("" if name is None else f"({name}={value})")
    raise ValueError(
        f"{agent} on an env of {n_states} states and {n_actions} actions needs "
        f"{size / 2**30:.3g} GiB of tables ({models}), over {limit}: use fewer delay "
        "estimates or a smaller state space"
    )


def greedy_actions(q_table: np.ndarray, states: np.ndarray | None = None) -> np.ndarray:
    """The deterministic greedy policy read off a Q-table of shape ``(|S|, |Λ|, |A|)``.

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
def first_max(values, start, stop):
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
def write(q_flat, v_max, v_cell, s, cell, target, rate):
    """``Q[cell] += rate · (target − Q[cell])`` for an entry of state ``s``, the cache kept exact.

    The cache of state ``s`` is raised to the new value when it passes the max, and its row
    rescanned when the cached cell fell: the one write of every rule's single-entry update.
    """
    old = q_flat[cell]
    new = old + rate * (target - old)
    q_flat[cell] = new
    if new > v_max[s]:
        v_max[s] = new
        v_cell[s] = cell
    elif new < old and v_cell[s] == cell:
        size = q_flat.shape[0] // v_max.shape[0]
        v_max[s], v_cell[s] = first_max(q_flat, s * size, (s + 1) * size)


class QTable:
    """Q-values ``values[s, λ̂, a]`` with each state's max over (λ̂, a) cached exactly.

    Args:
        n_states: |S|.
        n_models: |Λ| (1 for a single table).
        n_actions: |A|.
        q_init: every entry's initial value.

    Attributes:
        values: the Q-values, shape ``(|S|, |Λ|, |A|)``, ``float64``.
        v_max: each state's max over its row of |Λ|·|A| entries.
        v_cell: the flat index into ``values`` of an entry holding it.
        flat: ``values`` as one flat view; ``rows``: one row of |Λ|·|A| entries a state.

    Single entries are read and written through memoryviews (``items``, ``v_max_items``,
    ``v_cell_items``) as Python numbers, at half the cost of numpy's scalar indexing; they are
    rebuilt after a copy (``copy.deepcopy`` and ``pickle`` copy the arrays only).
    """

    _VIEWS = ("flat", "rows", "items", "v_max_items", "v_cell_items")

    def __init__(self, n_states: int, n_models: int, n_actions: int, q_init: float):
        self.n_states, self.n_models, self.n_actions = n_states, n_models, n_actions
        self.row_size = n_models * n_actions
        self.values = np.full((n_states, n_models, n_actions), q_init)
        self.v_max = np.zeros(n_states)
        self.v_cell = np.zeros(n_states, dtype=np.int64)
        self._make_views()
        self.rebuild_cache()

    def _make_views(self) -> None:
        self.flat = self.values.reshape(-1)
        self.rows = self.values.reshape(self.n_states, self.row_size)
        self.items = memoryview(self.flat)
        self.v_max_items = memoryview(self.v_max)
        self.v_cell_items = memoryview(self.v_cell)

    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in vars(self).items() if k not in self._VIEWS}

    def __setstate__(self, state: dict[str, Any]) -> None:
        vars(self).update(state)
        self._make_views()

    def rebuild_cache(self) -> None:
        """Recompute every state's cached max and its cell (after the values were set)."""
        self.repair(np.arange(self.n_states))

    def repair(self, states: np.ndarray) -> None:
        """Recompute the cached max and its cell for ``states`` (distinct state indices)."""
        rows = self.rows[states]
        arg = rows.argmax(axis=1)
        self.v_max[states] = rows[np.arange(states.size), arg]
        self.v_cell[states] = states * self.row_size + arg

    def write(self, s: int, cell: int, target: float, rate: float) -> None:
        """``Q[cell] += rate · (target − Q[cell])`` for an entry of state ``s`` (:func:`write`)."""
        write(self.flat, self.v_max, self.v_cell, s, cell, target, rate)

    def greedy_model(self, s: int, uniform: Callable[[], float]) -> int:
        """A model whose table holds state ``s``'s max, ties broken at random.

        When the max is not tied (the common case) it is the cached cell's model, found by
        counting the row's entries equal to the max, without listing them.
        """
        best, size = self.v_max_items[s], self.row_size
        start = s * size
        if size <= _SMALL_ROW:
            ties = self.items[start : start + size].tolist().count(best)
        else:
            ties = _count_equal(self.flat, start, start + size, best)
        if ties == 1:
            return (self.v_cell_items[s] - start) // self.n_actions
        models = _models_holding(self.flat, start, self.n_models, self.n_actions, best)
        return int(models[0] if models.size == 1 else models[int(uniform() * models.size)])

    def choose_action(
        self,
        s: int,
        eps: float,
        uniform: Callable[[], float],
        model: int = 0,
        explored: bool = False,
    ) -> int:
        """An ε-greedy action of ``model``'s table at ``s``, ties broken at random.

        Unless the model was ``explored`` (chosen at random), its table holds the state's max,
        read off the cache. Small rows are read as Python floats (cheaper than numpy calls);
        an untied max, the common case, is found without building the list of ties.
        """
        n_actions = self.n_actions
        if uniform() < eps:
            return int(uniform() * n_actions)
        start = (s * self.n_models + model) * n_actions
        if n_actions <= _SMALL_ROW:
            row = self.items[start : start + n_actions].tolist()
            best = max(row) if explored else self.v_max_items[s]
            if row.count(best) == 1:
                return row.index(best)
            ties: Any = [i for i, value in enumerate(row) if value == best]
        else:
            values = self.flat[start : start + n_actions]
            ties = np.flatnonzero(values == (values.max() if explored else self.v_max_items[s]))
        n = len(ties)
        return int(ties[0] if n == 1 else ties[int(uniform() * n)])
