"""Expected-credit Q-learning: each received reward spread over the past by the delay's pmf.

:class:`ExpectedCreditQLearning` is the cheap, anonymous baseline for rewards delayed by a known
distribution: every recent transition gets a share of the step's TD update in proportion to the
probability that the reward came from it. The exact rule, the credit weights and how the delay
is saved are on the docs' agents page (``docs/agents.md``).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._numba import jit as _jit
from delayed_rl.agents.common.compiled_loop import CompiledTables
from delayed_rl.agents.common.delay_estimate import MAX_DELAY_ESTIMATE, check_max_delay_estimate
from delayed_rl.agents.common.hyperparameters import shares_hyperparameters
from delayed_rl.agents.common.q_agent import QAgent
from delayed_rl.agents.common.q_table import first_max
from delayed_rl.agents.common.transition_ring import TransitionRing
from delayed_rl.delays import Delay, Empirical, as_delay

__all__ = ["ExpectedCreditQLearning", "credit_weights"]

TAIL = 1e-6
"""An unbounded delay is credited up to where less than this much of its mass is left."""


_UNSET: Any = object()  # ``_set_hyperparameters`` without a delay (the constructor's call)


def credit_weights(delay: Delay, max_delay_estimate: int | None = None) -> np.ndarray:
    """The pmf of ``min(d, K)`` on ``0..K`` for ``d ~ delay`` (``K`` as the module says).

    Args:
        delay: the delay distribution.
        max_delay_estimate: ``K`` at most this (the pmf clipped there; ``None``: no clip).

    Returns:
        A ``float64`` array of length ``K + 1`` summing to 1 (up to rounding).

    Raises:
        ValueError: ``K`` would pass ``MAX_DELAY_ESTIMATE`` (give a ``max_delay_estimate``), or the
            distribution's ``pmf`` does not give one probability in [0, 1] per lag summing to 1.
    """
    max_delay_estimate = check_max_delay_estimate(max_delay_estimate)
    limit = MAX_DELAY_ESTIMATE + 1 if max_delay_estimate is None else max_delay_estimate + 1
    bounded = delay.support_max is not None
    top = delay.support_max if bounded else _tail_end(delay, limit)
    if max_delay_estimate is not None and (top is None or top > max_delay_estimate):
        top = max_delay_estimate
    if top is None or top > MAX_DELAY_ESTIMATE:
        raise ValueError(
            f"delay must be modelled on at most {MAX_DELAY_ESTIMATE.text} steps, got {delay!r}, "
            f"which reaches {'further' if top is None else top}: give a max_delay_estimate to "
            "clip it"
        )
    weights = _pmf(delay, top + 1)
    total = weights.sum()
    if bounded and top == delay.support_max and abs(total - 1.0) > TAIL:
        raise ValueError(
            f"delay's pmf must sum to 1 on 0..{top}, got a sum of {total!r} for {delay!r}"
        )
    weights[-1] += max(0.0, 1.0 - total)
    return weights


def _tail_end(delay: Delay, limit: int) -> int | None:
    """The smallest ``K < limit`` with ``P(d ≤ K) ≥ 1 − TAIL``, or ``None``."""
    n = min(256, limit)
    while True:
        cdf = np.cumsum(_pmf(delay, n))
        end = int(np.searchsorted(cdf, 1.0 - TAIL))
        if end < n:
            return end
        if n >= limit:
            return None
        n = min(4 * n, limit)


def _pmf(delay: Delay, n: int) -> np.ndarray:
    """``delay.pmf`` on ``0..n−1``, checked to be one probability per lag."""
    values = np.asarray(delay.pmf(np.arange(n)), dtype=np.float64)
    if values.shape != (n,) or not np.all((values >= 0.0) & (values <= 1.0)):
        raise ValueError(
            f"delay's pmf must give one probability in [0, 1] per lag, got {values!r} for {delay!r}"
        )
    return values


def _describe(delay: Delay, weights: np.ndarray) -> dict[str, Any]:
    """``delay``'s JSON description; a ``Delay`` of your own as ``Empirical`` of ``weights``."""
    try:
        return delay.to_dict()
    except NotImplementedError:
        return Empirical(weights / weights.sum()).to_dict()


class ExpectedCreditQLearning(QAgent):
    """Q-learning that spreads every received reward over the past by the delay's pmf.

    For rewards delayed by a known distribution (e.g. :class:`~delayed_rl.wrappers.RewardDelay`
    with ``delay``): the TD update of each step is shared among the transitions 1, 2, ... steps
    back in proportion to the probability that the reward came from them (``docs/agents.md``
    states the exact rule and the weights). It is anonymous: it reads only the received
    reward, never the wrapper's ``info``. ``q_table`` has shape ``(|S|, 1, |A|)`` and acting is
    Q-learning's, so ``predict``, ``greedy_actions`` and ``save``/``load`` work as for
    :class:`~delayed_rl.agents.QLearning`. ``learn()`` runs compiled when the env stack does
    (:mod:`delayed_rl.compiled`), with the same rule.

    Args:
        env: the training env (``Discrete`` observation and action spaces) or an env id.
        delay: the delay distribution, a :class:`~delayed_rl.delays.Delay`, a number ``>= 0``
            read as a Poisson mean (as ``gym.make(id, reward_delay=...)`` reads it) or a
            :meth:`~delayed_rl.delays.Delay.to_dict` description.
        max_delay_estimate: ``K``, the last lag credited: the wrapper's ``max_delay`` when
            delays are clipped (the weight of the last lag is then the clipped mass), or a cap
            on the lags credited. ``None``: no clip. At most ``MAX_DELAY_ESTIMATE`` (1024).
        **hyperparameters: the hyper-parameters every agent shares, by keyword: see
            :class:`~delayed_rl.agents.common.base.TabularAgent`.

    Raises:
        TypeError: ``delay`` is neither a ``Delay``, a number nor a description, or
            ``max_delay_estimate`` is not an integer.
        ValueError: ``delay`` is a negative or non-finite number or describes no distribution,
            ``max_delay_estimate`` is negative, or the delay reaches too far (see
            :func:`credit_weights`).

    Example:
        >>> import gymnasium as gym
        >>> import delayed_rl
        >>> from delayed_rl.agents import ExpectedCreditQLearning
        >>> env = gym.make("delayed_rl/GridWorld-3x3-v0", reward_delay=2)
        >>> agent = ExpectedCreditQLearning(env, delay=2, q_init=20.0, seed=0)
        >>> agent.credit_weights.round(3)[:4]  # Poisson(2): p(0), p(1), p(2), p(3)
        array([0.135, 0.271, 0.271, 0.18 ])
        >>> agent = agent.learn(3_000)
        >>> agent.predict(8, deterministic=True)[0] in (0, 3)  # from the start: up or left
        True
    """

    _hyperparameter_names = (*QAgent._hyperparameter_names, "delay", "max_delay_estimate")

    @shares_hyperparameters
    def __init__(
        self,
        env: gym.Env | str,
        delay: Delay | float,
        max_delay_estimate: int | None = None,
        **hyperparameters: Any,
    ):
        self._set_credit(as_delay(delay, "delay"), max_delay_estimate)
        super().__init__(env, **hyperparameters)

    def _set_credit(self, delay: Delay, max_delay_estimate: Any) -> None:
        self.max_delay_estimate = check_max_delay_estimate(max_delay_estimate)
        weights = credit_weights(delay, self.max_delay_estimate)
        self.delay = delay
        self._weights = weights
        lags = np.flatnonzero(weights > 0.0)
        self._lags = lags.astype(np.int64)
        self._lag_weights = weights[lags]
        self._first_lag = int(lags[0])
        self._first_weight = float(weights[lags[0]])
        self._last_lag = int(lags[-1])
        # how many lags can be credited at episode step t < the last lag: those with k <= t
        self._credit_valid = np.searchsorted(
            lags, np.arange(self._last_lag + 1), side="right"
        ).tolist()

    def _set_hyperparameters(
        self, *, delay: Any = _UNSET, max_delay_estimate: Any = None, **kwargs: Any
    ) -> None:
        """Also the delay and ``max_delay_estimate`` when loading (the constructor sets them itself).

        A file's ``delay`` is checked as the constructor checks it: ``null`` (or any other
        value that is not a delay) is refused.
        """
        if delay is not _UNSET:  # loading: they come along
            self._set_credit(as_delay(delay, "delay"), max_delay_estimate)
        super()._set_hyperparameters(**kwargs)

    def _get_hyperparameters(self) -> dict[str, Any]:
        params = super()._get_hyperparameters()
        params["delay"] = _describe(self.delay, self._weights)
        return params

    @property
    def credit_weights(self) -> np.ndarray:
        """``w(k)`` for ``k = 0..K``: the share of a received reward credited ``k`` steps back."""
        return self._weights.copy()

    # ------------------------------------------------------------------ model
    def _setup_model(self) -> None:
        super()._setup_model()
        self._history = TransitionRing(self._last_lag)

    def compiled_tables(self) -> CompiledTables:
        """The Q-table and its cache, the lags and each lag's rate ``α·w(k)``: the rule compiles.

        The compiled loop credits the lags into the one table, TD errors first and increments
        in lag order, as :meth:`_credit_many` does.
        """
        tables = self._q_tables()
        rates = self._alpha * self._lag_weights
        return tables._replace(delay_estimates=self._lags, lag_rates=rates)

    # ------------------------------------------------------------------ learning
    def _learn_transition(
        self, s: int, a: int, r: float, s2: int, terminated: bool, truncated: bool
    ) -> None:
        t = self._episode_step
        self._history.record(t, s, s2, s * self.n_actions + a)
        n = self._lags.size if t >= self._last_lag else self._credit_valid[t]
        if n == 1:
            self._credit_one(t, r, terminated)
        elif n:
            self._credit_many(t, n, r, terminated)

    def _credit_one(self, t: int, r: float, terminated: bool) -> None:
        """The update of the one creditable lag, the smallest (Python scalars, faster)."""
        lag, table, history = self._first_lag, self._table, self._history
        j = (t - lag) & history.mask
        bootstrap = 0.0 if terminated and lag == 0 else table.v_max_items[history.s2[j]]
        target = r + self.gamma * bootstrap
        table.write(history.s[j], history.cell[j], target, self._alpha * self._first_weight)

    def _credit_many(self, t: int, n: int, r: float, terminated: bool) -> None:
        """The updates of the first ``n`` lags: all TD errors first, increments summed."""
        table = self._table
        _credit_lags(
            table.flat,
            table.v_max,
            table.v_cell,
            self._history.rows,
            self._lags[:n],
            self._alpha * self._lag_weights[:n],
            t,
            self._history.mask,
            r,
            self.gamma,
            terminated and self._first_lag == 0,  # only the current step can be terminal
        )


@_jit
def _credit_lags(q_flat, v_max, v_cell, history, lags, rates, t, mask, r, gamma, terminal_first):
    """:meth:`ExpectedCreditQLearning._credit_many`, compiled (one call a step, not a dozen).

    Every TD error first (each bootstrapping from the cached max), then the increments
    ``rates[j] · δ_j`` added in lag order, then each touched state's max and its first arg-max
    recomputed: the order of operations of the numpy version it replaced, to the last bit.
    """
    hist_s, hist_s2, hist_cell = history[0], history[1], history[2]
    n = lags.shape[0]
    n_actions = q_flat.shape[0] // v_max.shape[0]
    errors = np.empty(n)
    cells = np.empty(n, dtype=np.int64)
    states = np.empty(n, dtype=np.int64)
    for j in range(n):
        position = (t - lags[j]) & mask
        cells[j] = hist_cell[position]
        states[j] = hist_s[position]
        bootstrap = 0.0 if j == 0 and terminal_first else v_max[hist_s2[position]]
        errors[j] = r + gamma * bootstrap - q_flat[cells[j]]
    for j in range(n):
        q_flat[cells[j]] += rates[j] * errors[j]
    for j in range(n):
        s = states[j]
        seen = False
        for i in range(j):
            if states[i] == s:
                seen = True
                break
        if seen:
            continue
        v_max[s], v_cell[s] = first_max(q_flat, s * n_actions, (s + 1) * n_actions)
