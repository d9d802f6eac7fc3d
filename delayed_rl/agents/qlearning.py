"""Q-learning and fixed-delay Q-learning: one Q-table, each reward credited to one step.

``QLearning`` credits every reward to the step that just happened (the textbook rule, thesis
Eq. 3.2); ``FixedDelayQLearning(delay_estimate=k)`` credits it to the step ``k`` steps back (the
constant-delay agents of thesis Fig. 5.6). Both are Multiple Model Q-learning with a single
model, Λ = {0} and Λ = {k}: ``QLearning`` and ``MultipleModelQLearning(delay_estimates=[0])``
produce identical tables for the same seed and env, and so do ``FixedDelayQLearning`` and
``MultipleModelQLearning(delay_estimates=[k])`` (the rules are written plainly in
:mod:`delayed_rl.agents.reference`).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._validation import check_int
from delayed_rl.agents.common.compiled_loop import CompiledTables
from delayed_rl.agents.common.hyperparameters import shares_hyperparameters
from delayed_rl.agents.common.q_agent import QAgent, check_delay_estimates
from delayed_rl.agents.common.transition_ring import TransitionRing

__all__ = ["FixedDelayQLearning", "QLearning"]


class QLearning(QAgent):
    """Tabular Q-learning (Watkins), ε-greedy with random tie-breaks.

    ``Q(s, a) += α (r + γ (1 − terminated) max_a′ Q(s′, a′) − Q(s, a))`` after every step. Under
    delayed rewards it credits each reward to the wrong step, which is what the thesis measures.
    ``q_table`` has shape ``(|S|, 1, |A|)`` (one delay model, λ̂ = 0), like MMQ's.

    Args:
        env: the training env (``Discrete`` observation and action spaces) or an env id.
        **hyperparameters: the hyper-parameters every agent shares, by keyword: see
            :class:`~delayed_rl.agents.common.base.TabularAgent`.

    Example:
        >>> import delayed_rl
        >>> from delayed_rl.agents import QLearning
        >>> agent = QLearning("delayed_rl/GridWorld-3x3-v0", q_init=20.0, seed=0).learn(2_000)
        >>> agent.predict(8, deterministic=True)[0] in (0, 3)  # from the start: up or left
        True
    """

    @shares_hyperparameters
    def __init__(self, env: gym.Env | str, **hyperparameters: Any):
        super().__init__(env, **hyperparameters)

    def compiled_tables(self) -> CompiledTables:
        """The Q-table and its cache: the compiled loop runs MMQ's rule, with Λ = {0} this rule."""
        return self._q_tables()

    def _learn_transition(
        self, s: int, a: int, r: float, s2: int, terminated: bool, truncated: bool
    ) -> None:
        self._q_learning_update(s, a, r, s2, terminated)


class FixedDelayQLearning(QAgent):
    """Q-learning that assumes every reward arrives exactly ``delay_estimate`` steps late.

    The reward received at step ``t`` is credited to the transition of step
    ``t − delay_estimate`` (steps before the episode's start are not updated). Under a constant
    delay ``k`` with ``delay_estimate=k`` this is exact credit assignment; under random delays it
    is right only as often as the delay equals ``delay_estimate`` (thesis Eq. 3.8 and Fig. 5.6).
    It acts from its only table: MMQ with Λ = {``delay_estimate``}.

    Args:
        env: the training env (``Discrete`` observation and action spaces) or an env id.
        delay_estimate: the assumed delay, a number of steps (an integer >= 0; 0 is plain
            Q-learning). (``delay`` names delay *distributions* in this library:
            :mod:`delayed_rl.delays`.)
        **hyperparameters: the hyper-parameters every agent shares, by keyword: see
            :class:`~delayed_rl.agents.common.base.TabularAgent`.

    Example:
        >>> import gymnasium as gym
        >>> from delayed_rl.delays import Constant
        >>> env = gym.make("delayed_rl/GridWorld-3x3-v0", reward_delay=Constant(2))
        >>> agent = FixedDelayQLearning(env, delay_estimate=2, q_init=20.0, seed=0).learn(2_000)
        >>> agent.delay_estimate, agent.q_table.shape, agent.last_learn_path
        (2, (9, 1, 4), 'compiled')
    """

    @shares_hyperparameters
    def __init__(
        self,
        env: gym.Env | str,
        delay_estimate: int | None = None,
        **hyperparameters: Any,
    ):
        if delay_estimate is None:
            raise TypeError("FixedDelayQLearning needs delay_estimate, the assumed delay in steps")
        check_int("delay_estimate", delay_estimate, 0)
        estimates = check_delay_estimates([delay_estimate], "delay_estimate")
        super().__init__(
            env,
            delay_estimates=estimates,
            delay_argument=("delay_estimate", int(delay_estimate)),
            **hyperparameters,
        )

    @property
    def delay_estimate(self) -> int:
        """The assumed delay, in steps."""
        return int(self._delay_estimates[0])

    def _check_saved_delay_estimates(self, values: Any) -> np.ndarray:
        checked = check_delay_estimates(values)
        if checked.size != 1:
            raise ValueError(
                f"FixedDelayQLearning has one delay estimate, got delay_estimates={values!r}"
            )
        return checked

    def _setup_model(self) -> None:
        super()._setup_model()
        self._history = TransitionRing(self.delay_estimate)

    def compiled_tables(self) -> CompiledTables:
        """The Q-table, its cache and Λ: the compiled loop runs MMQ's rule, with one λ̂ this rule."""
        return self._q_tables()

    def _learn_transition(
        self, s: int, a: int, r: float, s2: int, terminated: bool, truncated: bool
    ) -> None:
        lag, t = self.delay_estimate, self._episode_step
        if not lag:
            self._q_learning_update(s, a, r, s2, terminated)
        else:  # the transition lag steps back, never terminal (only the current step can be)
            history, table = self._history, self._table
            history.record(t, s, s2, s * table.row_size + a)
            if t >= lag:
                j = (t - lag) & history.mask
                target = r + self.gamma * table.v_max_items[history.s2[j]]
                table.write(history.s[j], history.cell[j], target, self._alpha)
