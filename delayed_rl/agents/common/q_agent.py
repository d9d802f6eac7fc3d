"""The tabular Q base: a :class:`~delayed_rl.agents.common.base.TabularAgent` that learns a :class:`QTable`.

:class:`QAgent` is what every algorithm of :mod:`delayed_rl.agents` subclasses. It holds Λ (the
delay estimates, one table each: ``[0]`` for the Q-learning agents) and the
:class:`~delayed_rl.agents.common.q_table.QTable`, and gives every agent the same greedy
policy, ε-greedy behaviour on a single table, the one-step Q-learning update, the compiled
tables and the model-file arrays (``q_table`` and ``delay_estimates``). An algorithm adds its
learning rule (``_learn_transition``) and whatever state that rule keeps.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from delayed_rl._validation import check_int
from delayed_rl.agents.common.base import TabularAgent
from delayed_rl.agents.common.compiled_loop import CompiledTables
from delayed_rl.agents.common.hyperparameters import HYPERPARAMETER_NAMES, MAX_ABS_VALUE
from delayed_rl.agents.common.persistence import check_state_array
from delayed_rl.agents.common.q_table import QTable, check_table_size, greedy_actions

__all__ = ["QAgent", "check_delay_estimates", "shown"]

VALUE_RANGE = (-MAX_ABS_VALUE, MAX_ABS_VALUE)
"""The range of a model file's Q-values (see ``MAX_ABS_VALUE``)."""
VALUE_NOTE = f" (|value| <= {MAX_ABS_VALUE.text})"
"""How a message about a model file's Q-values states the range."""


def shown(values: Any) -> str:
    """``values`` for a message, shortened when long."""
    values = list(values)
    return (
        repr(values)
        if len(values) <= 8
        else f"[{values[0]}, ..., {values[-1]}] ({len(values)} values)"
    )


def check_delay_estimates(values: Any, name: str = "delay_estimates") -> np.ndarray:
    """Λ given as a sequence, validated: a sorted ``int64`` array of distinct integers ``>= 0``.

    Λ must fit :data:`~delayed_rl.agents.common.q_table.MAX_TABLE_BYTES` (checked with one
    state and one action; the constructor checks again with the env's spaces). ``name`` is the
    argument a message names (``"delay_estimate"`` shows its one value).

    Raises:
        TypeError: ``values`` is not a sequence of integers.
        ValueError: it is empty, has repeats or negative values, or makes too large tables.
    """
    if isinstance(values, (str, bytes)) or not isinstance(values, (Sequence, np.ndarray, range)):
        raise TypeError(
            f"delay_estimates must be a sequence of distinct integers >= 0, got {values!r}"
        )
    checked = [check_int(f"delay_estimates[{i}]", v, 0) for i, v in enumerate(values)]
    if not checked:
        raise ValueError("delay_estimates must be a non-empty sequence of distinct integers >= 0")
    if len(set(checked)) != len(checked):
        raise ValueError(f"delay_estimates must be distinct, got {values!r}")
    value = checked[0] if name == "delay_estimate" else shown(checked)
    check_table_size(name, value, len(checked), max(checked))
    return np.array(sorted(checked), dtype=np.int64)


class QAgent(TabularAgent):
    """A tabular agent that learns in a :class:`~delayed_rl.agents.common.q_table.QTable`.

    Args:
        env: the training env (``Discrete`` observation and action spaces) or an env id.
        delay_estimates: Λ, one table per delay estimate (checked by the subclass: see
            :func:`check_delay_estimates`); ``None``: ``[0]``, a single Q-table.
        delay_argument: ``(name, value)`` of the constructor argument that set Λ, for a
            message about the tables' size (``None``: none, Λ is the class's own).
        **hyperparameters: the shared hyper-parameters of
            :class:`~delayed_rl.agents.common.base.TabularAgent`.

    A subclass implements ``_learn_transition`` (its rule: :meth:`_q_learning_update` is the
    textbook one); it trains on the Python path unless it also returns its tables from
    ``compiled_tables`` (:meth:`_q_tables`), for a rule the compiled loop runs. To keep more
    state than the table, it extends ``_setup_model``,
    ``_get_state_arrays``, ``_state_array_specs`` and ``_set_extra_state_arrays``. The
    ``q_table`` has shape ``(|S|, |Λ|, |A|)``.

    Example:
        >>> class HalvedRewardQ(QAgent):  # a rule of its own: Q-learning on half the reward
        ...     def _learn_transition(self, s, a, r, s2, terminated, truncated):
        ...         self._q_learning_update(s, a, 0.5 * r, s2, terminated)
        >>> agent = HalvedRewardQ("delayed_rl/GridWorld-3x3-v0", seed=0).learn(300)
        >>> agent.q_table.shape, agent.last_learn_path  # (|S|, |Λ|, |A|); no compiled rule
        ((9, 1, 4), 'python')
    """

    _hyperparameter_names: ClassVar[tuple[str, ...]] = (*HYPERPARAMETER_NAMES, "delay_estimates")

    def __init__(
        self,
        env: gym.Env | str,
        *,
        delay_estimates: np.ndarray | None = None,
        delay_argument: tuple[str, Any] | None = None,
        **hyperparameters: Any,
    ):
        self._delay_estimates = (
            np.zeros(1, np.int64) if delay_estimates is None else delay_estimates
        )
        self._delay_argument = delay_argument
        super().__init__(env, **hyperparameters)

    def _set_hyperparameters(self, *, delay_estimates: Any = None, **kwargs: Any) -> None:
        """Also Λ, when loading (a model file gives it; the constructor sets it itself)."""
        if delay_estimates is not None:
            self._delay_estimates = self._check_saved_delay_estimates(delay_estimates)
            self._delay_argument = None
        elif "_delay_estimates" not in vars(self):
            raise TypeError(
                "delay_estimates must be a sequence of distinct integers >= 0, got None"
            )
        super()._set_hyperparameters(**kwargs)

    def _check_saved_delay_estimates(self, values: Any) -> np.ndarray:
        """Λ as a model file gives it: ``[0]`` unless the class learns over other delays."""
        checked = check_delay_estimates(values)
        if checked.tolist() != [0]:
            raise ValueError(f"{type(self).__name__} has delay_estimates [0], got {values!r}")
        return checked

    def _table_options(self) -> dict[str, bool]:
        """The optional tables to count against ``MAX_TABLE_BYTES`` (``table_bytes``' keywords)."""
        return {}

    # ------------------------------------------------------------------ model
    @property
    def delay_estimates(self) -> list[int]:
        """Λ, the delay hypotheses (sorted): ``q_table[:, i, :]`` assumes delay ``Λ[i]``."""
        return self._delay_estimates.tolist()

    @property
    def q_table(self) -> np.ndarray:
        """The Q-values, shape ``(|S|, |Λ|, |A|)`` (a read-only view; change it via learning)."""
        view = self._table.values.view()
        view.flags.writeable = False
        return view

    def _setup_model(self) -> None:
        """Check the tables' size, then allocate the Q-table (every entry ``q_init``)."""
        n_models = len(self._delay_estimates)
        name, value = self._delay_argument or ("delay_estimates", shown(self.delay_estimates))
        if self._delay_argument is None and n_models == 1 and not self._delay_estimates[0]:
            name = None
        check_table_size(
            name,
            value,
            n_models,
            int(self._delay_estimates[-1]),
            (type(self), self.n_states, self.n_actions),
            **self._table_options(),
        )
        self.n_models = n_models
        self._table = QTable(self.n_states, n_models, self.n_actions, self.q_init)

    def _q_tables(self) -> CompiledTables:
        """The Q-table, its cache and Λ, for a subclass's :meth:`compiled_tables`.

        ``QAgent`` has no compiled rule of its own (a subclass's rule may be anything): a
        subclass whose rule the compiled loop runs returns these, with its options, from
        ``compiled_tables``.
        """
        table = self._table
        return CompiledTables(table.values, table.v_max, table.v_cell, self._delay_estimates)

    # ------------------------------------------------------------------ acting
    def _choose(self, s: int, eps: float, uniform: Callable[[], float]) -> tuple[int, int]:
        """The acting model, then its ε-greedy action, ties broken at random.

        One table: model 0. Several (MMQ's acting): with probability ε a model drawn uniformly,
        else the one whose table holds the state's max; then ε-greedy on that model's table.
        """
        table, explored = self._table, False
        if self.n_models == 1:
            model = 0
        elif uniform() < eps:
            model, explored = int(uniform() * self.n_models), True
        else:
            model = table.greedy_model(s, uniform)
        return model, table.choose_action(s, eps, uniform, model, explored)

    def _greedy_actions(self, states: np.ndarray) -> np.ndarray:
        return greedy_actions(self._table.values, states)

    def preferred_delay(self, observation: Any) -> Any:
        """λ̂* at ``observation``: the delay estimate whose table holds the state's best value.

        Ties go to the smallest estimate. Returns an ``int`` for one observation and an ``int64``
        array for a batch.
        """
        index, single = self._obs_index.indices(observation, "observation")
        models = self._table.rows[index.reshape(-1)].argmax(axis=1) // self.n_actions
        delays = self._delay_estimates[models]
        return int(delays[0]) if single else delays

    @property
    def acting_delay_share(self) -> np.ndarray:
        """The share of ``learn()`` steps each λ̂ was the acting model (since the counter reset).

        Indexed like :attr:`delay_estimates`; all zeros before any training step.
        """
        counts = np.asarray(self._statistics.acting_counts, dtype=np.float64)
        total = counts.sum()
        return counts / total if total else counts

    # ------------------------------------------------------------------ learning
    def _q_learning_update(self, s: int, a: int, r: float, s2: int, terminated: bool) -> None:
        """``Q(s, a) += α (r + γ (1 − terminated) max Q(s2) − Q(s, a))`` (thesis Eq. 3.2).

        The max is read off the cache; for an agent of one table, λ̂ = 0.
        """
        table = self._table
        bootstrap = 0.0 if terminated else table.v_max_items[s2]
        table.write(s, s * table.row_size + a, r + self.gamma * bootstrap, self._alpha)

    # ------------------------------------------------------------------ persistence
    def _state_array_specs(self) -> dict[str, tuple[tuple[int, ...], Any]]:
        n_models = len(self._delay_estimates)
        return {
            "q_table": ((self.n_states, n_models, self.n_actions), np.float64),
            "delay_estimates": ((n_models,), np.int64),
        }

    def _get_state_arrays(self) -> dict[str, np.ndarray]:
        return {
            "q_table": self._table.values.copy(),
            "delay_estimates": self._delay_estimates.copy(),
        }

    def _set_state_arrays(self, arrays: dict[str, np.ndarray], where: str) -> None:
        """Check every state array against this agent's tables, then set them.

        ``q_table`` must be float64 of the agent's shape with every entry within
        ±:data:`~delayed_rl.agents.common.hyperparameters.MAX_ABS_VALUE`; ``delay_estimates``
        must be Λ as the metadata gives it; a subclass's own arrays are checked by its
        ``_set_extra_state_arrays``. Nothing is set unless every array passes.

        Raises:
            ValueError: an array is missing or wrong (the message names the file and it).
        """
        expected = (self.n_states, self.n_models, self.n_actions)
        q = check_state_array(
            f"{where}: q_table", arrays.get("q_table"), expected, np.float64, *VALUE_RANGE,
            note=VALUE_NOTE,
        )  # fmt: skip
        delays = arrays.get("delay_estimates")
        if delays is None or not np.array_equal(delays, self._delay_estimates):
            found = "missing" if delays is None else shown(np.ravel(delays).tolist())
            raise ValueError(
                f"{where}: the delay_estimates array ({found}) does not match the "
                f"metadata ({shown(self.delay_estimates)})"
            )
        self._set_extra_state_arrays(arrays, where)
        self._table.values[...] = q
        self._table.rebuild_cache()

    def _set_extra_state_arrays(self, arrays: dict[str, np.ndarray], where: str) -> None:
        """Check and set a subclass's own state arrays (none here), before the Q-table is set."""
