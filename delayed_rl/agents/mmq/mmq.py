"""Multiple Model Q-learning (Campbell 2015, section 3.2, Eq. 3.7 and Algorithm 1).

:class:`MultipleModelQLearning` keeps one Q-table per delay hypothesis λ̂ ∈ Λ, acts from the
best and credits each received reward, in table λ̂, to the transition λ̂ steps back. The exact
rule (acting, learning, the credit options, the greedy readout, the cost) is on the docs' agents
page (``docs/agents.md``); :class:`delayed_rl.agents.reference.ReferenceMMQ` writes it plainly.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._validation import check_int
from delayed_rl.agents.common.compiled_loop import CompiledTables
from delayed_rl.agents.common.delay_estimate import (
    DEFAULT_MAX_DELAY_ESTIMATE,
    check_max_delay_estimate,
)
from delayed_rl.agents.common.hyperparameters import shares_hyperparameters
from delayed_rl.agents.common.q_agent import QAgent, check_delay_estimates, shown
from delayed_rl.agents.common.q_table import check_table_size, greedy_actions
from delayed_rl.agents.common.transition_ring import TransitionRing
from delayed_rl.agents.mmq.options import (
    OPTION_NAMES,
    CreditOptions,
    GreedyAverage,
    check_options,
)
from delayed_rl.agents.mmq.updates import FULL_CREDIT, update_models

__all__ = ["MultipleModelQLearning", "delay_estimates_from"]


def delay_estimates_from(
    max_delay_estimate: Any, delay_step: Any, delay_estimates: Any
) -> np.ndarray:
    """Λ from MMQ's two ways of giving it: ``delay_estimates``, or ``max_delay_estimate``/``delay_step``.

    Returns:
        Λ, a sorted ``int64`` array of distinct integers ``>= 0`` that fits
        ``MAX_TABLE_BYTES`` (:func:`~delayed_rl.agents.common.q_agent.check_delay_estimates`).

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
        return check_delay_estimates(delay_estimates)
    if max_delay_estimate is None:
        max_delay_estimate = DEFAULT_MAX_DELAY_ESTIMATE
    if delay_step is None:
        delay_step = 1
    max_delay_estimate = check_max_delay_estimate(max_delay_estimate)
    delay_step = check_int("delay_step", delay_step, 1)
    largest = max_delay_estimate - max_delay_estimate % delay_step
    check_table_size("max_delay_estimate", max_delay_estimate, largest // delay_step + 1, largest)
    return np.arange(0, max_delay_estimate + 1, delay_step, dtype=np.int64)


class MultipleModelQLearning(QAgent):
    """Multiple Model Q-learning (MMQ): Q-learning over parallel delay hypotheses.

    For rewards that arrive a random number of steps late (e.g. under
    :class:`~delayed_rl.wrappers.PoissonRewardDelay`), MMQ keeps one Q-table per delay estimate
    λ̂ ∈ Λ. Each step's reward is credited, in table λ̂, to the transition λ̂ steps back; the agent
    acts from the table whose best value is highest, so it learns which delay hypothesis pays
    (``docs/agents.md`` states the exact rule). ``QLearning`` is the case Λ = {0} and
    ``FixedDelayQLearning(delay_estimate=k)`` the case Λ = {k}.

    Args:
        env: the training env (``Discrete`` observation and action spaces) or an env id.
        max_delay_estimate: λ̂max; Λ = {0, delay_step, 2·delay_step, ...} up to λ̂max
            (default 50, the thesis's grid-world setting; at most
            :data:`~delayed_rl.agents.common.delay_estimate.MAX_DELAY_ESTIMATE`, 1024, as for
            every agent).
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
            exploring ``predict`` still use the current table. It doubles the Q-table's
            memory (:class:`~delayed_rl.agents.mmq.options.GreedyAverage`).
        **hyperparameters: the hyper-parameters every agent shares, by keyword: see
            :class:`~delayed_rl.agents.common.base.TabularAgent`. ε applies at both levels; an
            optimistic ``q_init`` explores (the thesis's; e.g. 50 in the Roulette example).

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

    _hyperparameter_names = (*QAgent._hyperparameter_names, *OPTION_NAMES)
    _optional_hyperparameter_names = OPTION_NAMES  # files written before the options lack them

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
        self._set_options(reward_kernel, delay_trace, greedy_window)
        estimates = delay_estimates_from(max_delay_estimate, delay_step, delay_estimates)
        if delay_estimates is not None:
            argument = ("delay_estimates", shown(estimates.tolist()))
        else:
            given = estimates[-1] if max_delay_estimate is None else max_delay_estimate
            argument = ("max_delay_estimate", given)
        super().__init__(env, delay_estimates=estimates, delay_argument=argument, **hyperparameters)

    def _set_options(
        self, reward_kernel: Any = None, delay_trace: Any = None, greedy_window: Any = None
    ) -> None:
        self.reward_kernel, self.delay_trace, self.greedy_window = check_options(
            reward_kernel, delay_trace, greedy_window
        )

    def _set_hyperparameters(self, **kwargs: Any) -> None:
        """Also the options, when loading (the constructor sets them itself)."""
        options = {name: kwargs.pop(name) for name in OPTION_NAMES if name in kwargs}
        if options or "greedy_window" not in vars(self):  # loading (a file may lack them)
            self._set_options(**options)
        super()._set_hyperparameters(**kwargs)

    def _check_saved_delay_estimates(self, values: Any) -> np.ndarray:
        return check_delay_estimates(values)

    def _table_options(self) -> dict[str, bool]:
        names = ("averaged_table", "reward_kernel", "delay_trace")
        given = (self.greedy_window, self.reward_kernel, self.delay_trace)
        return {name: value is not None for name, value in zip(names, given, strict=True)}

    # ------------------------------------------------------------------ model
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
        """The delay trace ``e(λ̂)``, indexed like :attr:`delay_estimates` (a copy; ``None``: off)."""
        trace = self._credit.trace
        return None if trace is None else trace.copy()

    def _greedy_source(self) -> np.ndarray:
        return self._table.values if self._average is None else self._average.source

    def _setup_model(self) -> None:
        super()._setup_model()
        estimates = self._delay_estimates
        self._history = TransitionRing(int(estimates[-1]))
        self._back = -estimates  # each model's transition is λ̂ steps back
        # how many models can learn at episode step t < max Λ: those with λ̂ <= t
        self._n_valid = np.searchsorted(
            estimates, np.arange(int(estimates[-1]) + 1), side="right"
        ).tolist()
        self._credit = CreditOptions(estimates, self.reward_kernel, self.delay_trace)
        window = self.greedy_window
        self._average = None if window is None else GreedyAverage(self._table.values, window)
        self._acting: int | None = None  # the acting model _choose picked for the next step

    def compiled_tables(self) -> CompiledTables:
        """The Q-table, its cache and Λ: MMQ's rule runs compiled for every Λ, options included.

        With ``greedy_window``, the compiled loop keeps the averaged table itself, at the same
        training steps and with the same arithmetic as on the Python path.
        """
        tables = self._q_tables()
        credit = self._credit
        if credit.on:
            tables = tables._replace(
                credit_kernel=credit.kernel, trace_decay=credit.decay, trace=credit.trace
            )
        if self._average is not None:
            tables = tables._replace(average=self._average.compiled())
        return tables

    # ------------------------------------------------------------------ acting
    def _choose(self, s: int, eps: float, uniform: Callable[[], float]) -> tuple[int, int]:
        """The behaviour policy at ``s`` (``QAgent``'s), remembering the acting model."""
        model, action = super()._choose(s, eps, uniform)
        self._acting = model
        return model, action

    def _greedy_actions(self, states: np.ndarray) -> np.ndarray:
        return greedy_actions(self._greedy_source(), states)

    # ------------------------------------------------------------------ learning
    def _before_update(self, info: Mapping[str, Any] | None) -> None:
        """Clear the acting model: ``update()``'s transition was not chosen by ``learn()``.

        The reward kernel and the delay trace then take the greedy model of ``obs``
        (:meth:`preferred_delay`, before the update) as the acting model.
        """
        self._acting = None

    def _learn_transition(
        self, s: int, a: int, r: float, s2: int, terminated: bool, truncated: bool
    ) -> None:
        table, history, t = self._table, self._history, self._episode_step
        weights = self._step_weights(s) if self._credit.on else None
        cell = s * table.row_size + a
        largest = len(self._n_valid) - 1
        if largest:  # the transition joins the ring (only a λ̂ > 0 reads it back)
            history.record(t, s, s2, cell)
        n = self.n_models if t >= largest else self._n_valid[t]
        if n == 1:  # one model learns: Python scalars, one compiled write
            credited = r if weights is None else float(r * weights[0])
            lag = int(self._delay_estimates[0])
            if lag:  # its transition, λ̂ steps back, is not terminal
                j = (t - lag) & history.mask
                target = credited + self.gamma * table.v_max_items[history.s2[j]]
                table.write(history.s[j], history.cell[j], target, self._alpha)
            else:  # λ̂ = 0: this very transition
                bootstrap = 0.0 if terminated else table.v_max_items[s2]
                table.write(s, cell, credited + self.gamma * bootstrap, self._alpha)
        elif n:
            self._update_models(n, r, terminated, weights, t)
        if self._average is not None:
            self._average.tick()

    def _step_weights(self, s: int) -> np.ndarray:
        """Each model's share of the reward, about the acting model (:meth:`update`: ``s``'s greedy one)."""
        acting = self._acting
        if acting is None:
            acting = int(self._table.rows[s].argmax()) // self.n_actions
        self._acting = None
        return self._credit.weights(acting)

    def _update_models(
        self, n: int, r: float, terminated: bool, weights: np.ndarray | None, t: int
    ) -> None:
        """Update Q(s_{t−λ̂}, a_{t−λ̂}, λ̂) for the first ``n`` models, all targets first."""
        table = self._table
        update_models(
            table.flat, table.v_max, table.v_cell, self._history.rows, self._back, n, t,
            self._history.mask, r, FULL_CREDIT if weights is None else weights, self._alpha,
            self.gamma, terminated and not self._delay_estimates[0], self.n_actions,
        )  # fmt: skip

    # ------------------------------------------------------------------ diagnostics
    def _record_model_metrics(self, logger: Any) -> None:
        counts = self._statistics.acting_counts_since_log() if self.n_models > 1 else None
        total = 0 if counts is None else counts.sum()
        if total:
            delays = self._delay_estimates
            logger.record("mmq/acting_delay_mean", float(np.sum(counts * delays) / total))
            logger.record("mmq/acting_delay_mode", int(delays[int(np.argmax(counts))]))
            logger.record("mmq/acting_delay_mode_share", float(counts.max() / total))

    # ------------------------------------------------------------------ persistence
    def _state_array_specs(self) -> dict[str, tuple[tuple[int, ...], Any]]:
        specs = super()._state_array_specs()
        if self.delay_trace is not None:
            specs["delay_trace"] = ((len(self._delay_estimates),), np.float64)
        if self.greedy_window is not None:
            specs["greedy_table"] = specs["q_table"]
            specs["greedy_clock"] = ((2,), np.int64)
        return specs

    def _get_state_arrays(self) -> dict[str, np.ndarray]:
        arrays = super()._get_state_arrays()
        if self._credit.trace is not None:
            arrays["delay_trace"] = self._credit.trace.copy()
        if self._average is not None:
            arrays["greedy_table"] = self._average.table.copy()
            arrays["greedy_clock"] = self._average.clock.copy()
        return arrays

    def _set_extra_state_arrays(self, arrays: dict[str, np.ndarray], where: str) -> None:
        """Check the options' state (:mod:`~delayed_rl.agents.mmq.options`), then set it."""
        trace = self._credit.check_trace(arrays, where)
        average = None if self._average is None else self._average.check_arrays(arrays, where)
        if trace is not None:
            self._credit.trace[...] = trace
        if average is not None:
            self._average.table[...], self._average.clock[...] = average
