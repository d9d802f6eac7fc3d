"""Oracle Q-learning: every delayed reward credited to the transition that emitted it.

:class:`OracleQLearning` is the non-anonymous upper bound for delayed rewards: it reads
``info["reward_arrivals"]`` (:class:`~delayed_rl.wrappers.RewardDelay` with
``record_arrivals=True``) and makes one Q-learning update per transition with its own reward,
when that arrives. The exact rule and the history it keeps are on the docs' agents page
(``docs/agents.md``).
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._delay_line import delay_bound, ring_size
from delayed_rl.agents.common.compiled_loop import CompiledTables
from delayed_rl.agents.common.env_util import make_env
from delayed_rl.agents.common.hyperparameters import check_value, shares_hyperparameters
from delayed_rl.agents.common.q_agent import QAgent
from delayed_rl.wrappers.reward_delay import find_reward_delay

__all__ = ["OracleQLearning"]


class OracleQLearning(QAgent):
    """Q-learning that credits every delayed reward to the transition that emitted it.

    The upper bound of what any delayed-reward agent can learn from the same experience: it reads
    the wrapper's non-anonymous view ``info["reward_arrivals"]`` (who emitted each reward that
    arrives) and makes, for each transition, one textbook Q-learning update with that
    transition's own reward, when the reward arrives (``docs/agents.md`` states the exact
    rule and the history kept). It never reads ``info["undelayed_reward"]``; the received reward
    itself is not used either (the arrivals carry the values). ``q_table`` has shape
    ``(|S|, 1, |A|)`` and acting is Q-learning's (ε-greedy, random tie-breaks), so
    ``predict``, ``greedy_actions`` and ``save``/``load`` work as for
    :class:`~delayed_rl.agents.QLearning`. ``learn()`` runs compiled when the env stack does
    (:mod:`delayed_rl.compiled`): the compiled loop keeps the record of who emitted each reward
    itself (:mod:`delayed_rl.compiled.arrivals`) and makes the same updates in the same order.

    Args:
        env: the training env, wrapped in ``RewardDelay(env, delay, record_arrivals=True)``
            (anywhere in its wrapper stack). ``gym.make(id, reward_delay=...)`` does not record
            arrivals: wrap ``gym.make(id)`` yourself.
        **hyperparameters: the hyper-parameters every agent shares, by keyword: see
            :class:`~delayed_rl.agents.common.base.TabularAgent`.

    ``update(obs, action, reward, next_obs, terminated, truncated, info=info)`` learns from
    ``info["reward_arrivals"]`` as ``learn()`` does (``reward`` is checked but not used). It needs
    the agent's env (its ``RewardDelay`` sets the history kept) and the transitions in the order
    they happened, so that the episode clock is the wrapper's; it raises ``TypeError`` for an
    ``info`` that is not a dict or an arrival that is not an ``(int, number)`` pair, and
    ``ValueError`` without ``"reward_arrivals"``, for an arrival from a later step or of a
    non-finite value, or without an env.

    Raises:
        ValueError: the env has no ``RewardDelay`` with ``record_arrivals=True`` (also from
            :meth:`set_env` and ``load(path, env=...)``).

    Example:
        >>> import gymnasium as gym
        >>> import delayed_rl
        >>> from delayed_rl.agents import OracleQLearning
        >>> from delayed_rl.delays import Poisson
        >>> from delayed_rl.wrappers import RewardDelay
        >>> grid = gym.make("delayed_rl/GridWorld-3x3-v0")
        >>> env = RewardDelay(grid, Poisson(3.0), record_arrivals=True)
        >>> agent = OracleQLearning(env, q_init=20.0, seed=0).learn(2_000)
        >>> agent.predict(8, deterministic=True)[0] in (0, 3)  # from the start: up or left
        True
    """

    @shares_hyperparameters
    def __init__(self, env: gym.Env | str, **hyperparameters: Any):
        super().__init__(env, **hyperparameters)

    # ------------------------------------------------------------------ model
    def _setup_model(self) -> None:
        super()._setup_model()
        self._allocate_history(1)  # set_env sizes it for the env's delays

    def _allocate_history(self, length: int) -> None:
        """An empty ring of at least ``length`` transitions; the clocks restart."""
        size = ring_size(length)
        self._ring_mask = size - 1
        self._past_step = np.full(size, -1, dtype=np.int64)  # the transition's clock, -1: none
        self._past_s2 = np.zeros(size, dtype=np.int64)
        self._past_cell = np.zeros(size, dtype=np.int64)  # s·|A| + a
        self._past_terminated = np.zeros(size, dtype=np.bool_)
        self._clock = 0  # transitions learned since the history was allocated
        self._episode_start = 0  # the clock at the current episode's first step
        self._arrivals: Any = None  # the current step's arrivals, until it is learned

    @property
    def history_length(self) -> int:
        """How many past transitions the agent holds (0 before it has an env)."""
        return 0 if self.env is None else self._ring_mask + 1

    def _end_episode(self) -> None:
        # the next transition is step 0 of a new episode; older transitions are kept (under
        # "carry" their rewards still come, with negative emission steps)
        self._episode_start = self._clock
        self._arrivals = None

    def compiled_tables(self) -> CompiledTables:
        """The Q-table and its cache, and how many recent transitions the oracle credits."""
        return self._q_tables()._replace(held_transitions=self.history_length)

    # ------------------------------------------------------------------ env
    def set_env(self, env: gym.Env | str) -> None:
        """Train on ``env`` from now on (see ``TabularAgent.set_env``); the history restarts.

        Raises:
            TypeError: ``env`` is not an env, or its spaces are not ``Discrete``.
            ValueError: its spaces differ from the agent's, or it has no ``RewardDelay`` with
                ``record_arrivals=True``.
        """
        env = make_env(env)
        wrapper = find_reward_delay(env)
        if wrapper is None or not wrapper.record_arrivals:
            found = (
                "has no RewardDelay wrapper"
                if wrapper is None
                else "has a RewardDelay with record_arrivals=False"
            )
            raise ValueError(
                f"{type(self).__name__} needs the reward-delay wrapper's record of who emitted "
                f"each reward: wrap the env as RewardDelay(env, delay, record_arrivals=True) "
                f"(gym.make(id, reward_delay=...) does not record arrivals: use "
                f"RewardDelay(gym.make(id), delay, record_arrivals=True)); got {env}, which "
                f"{found}"
            )
        super().set_env(env)
        self._allocate_history(delay_bound(wrapper.delay, wrapper.max_delay) + 1)

    # ------------------------------------------------------------------ learning
    def _observe_info(self, info: Mapping[str, Any]) -> None:
        """Take the step's arrivals from its ``info`` (the Python loop calls this first)."""
        self._arrivals = _reward_arrivals(info)

    def _before_update(self, info: Any) -> None:
        """Take the step's arrivals from the ``info`` given to :meth:`update`, checked.

        The oracle learns from them, not from ``reward`` (which is checked but not used). It
        must have its env (the ``RewardDelay`` sets how much history it keeps), and
        transitions must come in the order they happened, episodes ending with ``terminated``
        or ``truncated``, so that the episode clock is the wrapper's.

        Raises:
            TypeError: ``info`` is not a mapping (``None`` included), or an arrival is not an
                ``(emission_step, value)`` pair of an integer and a number.
            ValueError: ``info`` has no ``"reward_arrivals"`` (as in ``learn()``), an arrival
                comes from a later step or has a non-finite value (or one above
                :data:`~delayed_rl.agents.common.hyperparameters.MAX_ABS_VALUE` in magnitude),
                or the agent has no env.
        """
        if self.env is None:
            raise ValueError(
                f"{type(self).__name__}.update needs the agent's env (its RewardDelay sets the "
                "history kept): pass env= to load() or call set_env(env) first"
            )
        if not isinstance(info, Mapping):
            raise TypeError(
                f"{type(self).__name__}.update needs info=, the step's info (a dict holding "
                f"'reward_arrivals'), got {info!r}"
            )
        self._arrivals = self._check_arrivals(_reward_arrivals(info))

    def _check_arrivals(self, arrivals: Any) -> list[tuple[int, float]]:
        """``info["reward_arrivals"]`` as ``(int, float)`` pairs, checked against the episode's clock."""
        if isinstance(arrivals, (str, bytes)) or not isinstance(arrivals, Sequence):
            raise TypeError(
                f"info['reward_arrivals'] must be a sequence of (emission_step, value) pairs, "
                f"got {arrivals!r}"
            )
        name, step = "info['reward_arrivals']", self._clock - self._episode_start
        checked = []
        for i, pair in enumerate(arrivals):
            if isinstance(pair, (str, bytes)) or not isinstance(pair, Sequence) or len(pair) != 2:
                raise TypeError(f"{name}[{i}] must be an (emission_step, value) pair, got {pair!r}")
            emitted, value = pair
            if isinstance(emitted, (bool, np.bool_)) or not isinstance(emitted, numbers.Integral):
                raise TypeError(
                    f"{name}[{i}][0] must be an integer (the emission step), got {emitted!r} "
                    f"({type(emitted).__name__})"
                )
            if emitted > step:
                raise ValueError(
                    f"{name}[{i}][0] must be an emission step <= {step} (this step's), "
                    f"got {emitted!r}"
                )
            checked.append((int(emitted), check_value(f"{name}[{i}][1]", value)))
        return checked

    def _learn_transition(
        self, s: int, a: int, r: float, s2: int, terminated: bool, truncated: bool
    ) -> None:
        arrivals, self._arrivals = self._arrivals, None
        if arrivals is None:
            raise RuntimeError(
                f"{type(self).__name__} got no reward arrivals for this step: learn() hands "
                "them over from info, update() reads them from its info="
            )
        clock, mask = self._clock, self._ring_mask
        j = clock & mask
        self._past_step[j] = clock
        self._past_s2[j] = s2
        self._past_cell[j] = s * self.n_actions + a
        self._past_terminated[j] = terminated
        if arrivals:
            self._credit(sorted(arrivals) if len(arrivals) > 1 else arrivals)
        self._clock = clock + 1  # (an episode's end starts the next one: _end_episode)

    def _credit(self, arrivals: Sequence[tuple[int, float]]) -> None:
        """The update of each arrival's transition, one after the other (see the module)."""
        # the ring's size is a power of 2: a clock's slot is ``clock & mask``; ``.item(j)``
        # reads a Python scalar, cheaper per element than indexing, which makes a numpy scalar
        start, mask, n_actions = self._episode_start, self._ring_mask, self.n_actions
        steps, table = self._past_step, self._table
        alpha, gamma = self._alpha, self.gamma
        for emitted, value in arrivals:
            clock = start + emitted
            j = clock & mask
            if clock < 0 or steps.item(j) != clock:
                continue  # a transition the agent does not hold
            steps[j] = -1  # each transition has one reward: it is updated once
            cell = self._past_cell.item(j)
            s = cell // n_actions
            bootstrap = (
                0.0 if self._past_terminated.item(j) else table.v_max.item(self._past_s2.item(j))
            )
            table.write(s, cell, value + gamma * bootstrap, alpha)


def _reward_arrivals(info: Mapping[str, Any]) -> Any:
    """``info["reward_arrivals"]``: the step's ``(emission_step, value)`` pairs.

    Raises:
        ValueError: ``info`` has none (the env's ``RewardDelay`` does not record them, or is not
            the wrapper whose ``info`` reaches the agent).
    """
    arrivals = info.get("reward_arrivals")
    if arrivals is None:
        raise ValueError(
            "the step's info has no 'reward_arrivals': the env's RewardDelay must have "
            "record_arrivals=True and be the wrapper whose info reaches the agent"
        )
    return arrivals
