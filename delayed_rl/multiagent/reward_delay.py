"""Reward delays per agent for PettingZoo's ``ParallelEnv``: :class:`ParallelRewardDelay`."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from pettingzoo import ParallelEnv

from delayed_rl._validation import check_reward
from delayed_rl.delays import Delay
from delayed_rl.multiagent._base import ParallelDelayWrapper
from delayed_rl.wrappers.pending_rewards import PendingRewards
from delayed_rl.wrappers.reward_delay import check_episode_end, flush_watch

__all__ = ["ParallelRewardDelay"]

_SETTLED_KEYS = {"flush": "flushed_reward", "drop": "dropped_reward"}


class ParallelRewardDelay(ParallelDelayWrapper):
    """Delays every agent's rewards independently, with the rule of :class:`~delayed_rl.wrappers.RewardDelay`.

    Each agent has its own pending rewards, clock and delay stream: the reward ``r_t`` it is
    given at its step ``t`` is delivered at its step ``t + d_t``. When an agent leaves
    (terminates or is truncated), its pending rewards follow ``on_episode_end`` at that step,
    its last; a ``reset()`` discards the live agents' (except under ``"carry"``), warning if
    not zero. ``reset(seed=s)`` seeds agent ``i`` with :func:`~delayed_rl.multiagent.agent_seed`
    ``(s, i)``: it draws the delays of a :class:`~delayed_rl.wrappers.RewardDelay` reset with
    that seed. ``docs/multiagent.md`` has the rules in full.

    ``info[agent]``, on every step that names the agent: ``undelayed_reward`` (``r_t``),
    ``drawn_reward_delay`` (``d_t``), ``pending_reward``; at its last step ``flushed_reward`` or
    ``dropped_reward`` (also in the ``infos`` of a ``reset()`` that discarded rewards).

    Args:
        env: a ``pettingzoo.ParallelEnv`` with ``possible_agents``. Its rewards must be real
            scalars, as :class:`~delayed_rl.wrappers.RewardDelay` requires.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean, for every agent; or a mapping from every agent of
            ``possible_agents`` to one of those.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        on_episode_end: ``"flush"``, ``"drop"`` or ``"carry"`` (see above).

    Raises:
        TypeError, ValueError: at construction, for an invalid argument (the message names
            it: ``delay['agent']`` for a mapping's entry; a mapping names every agent, no other).
        TypeError: at a step where the env gives an agent a reward that is not a real scalar.
        ValueError: at a step where the env gives a NaN or infinite reward, names an agent not
            in ``possible_agents``, or where sums pass float64's range.

    Attributes:
        delays: each agent's distribution.

    Example:
        >>> from pettingzoo.classic.rps.rps import parallel_env  # rock-paper-scissors
        >>> from delayed_rl.delays import Constant
        >>> env = ParallelRewardDelay(parallel_env(max_cycles=2), Constant(5))
        >>> _ = env.reset(seed=0)
        >>> env.step({"player_0": 1, "player_1": 0})[1]  # paper beats rock, 5 steps late
        {'player_0': 0.0, 'player_1': 0.0}
        >>> _, rewards, _, truncated, infos = env.step({"player_0": 0, "player_1": 0})
        >>> rewards, infos["player_0"]["flushed_reward"]  # the last step flushes
        ({'player_0': 1.0, 'player_1': -1.0}, 1.0)
    """

    def __init__(
        self,
        env: ParallelEnv,
        delay: Delay | float | dict[Any, Any],
        max_delay: int | None = None,
        on_episode_end: str = "flush",
    ):
        super().__init__(env, delay, max_delay, {"on_episode_end": on_episode_end})
        self.on_episode_end = check_episode_end(on_episode_end)
        rows: dict[Delay, list[int]] = {}
        for i, agent in enumerate(self.agent_order):
            rows.setdefault(self.delays[agent], []).append(i)
        self._groups = [
            (np.array(members), PendingRewards(len(members), delay, self.max_delay))
            for delay, members in rows.items()
        ]
        watches = (flush_watch(self.on_episode_end, d, self.max_delay, 3) for d in rows)
        self._watch = next((watch for watch in watches if watch is not None), None)
        self._in_episode = np.zeros(len(self.agent_order), dtype=bool)

    @property
    def pending_rewards(self) -> dict[Any, float]:
        """Each agent's sum of rewards emitted but not yet delivered."""
        pending = self._pending()
        return {agent: float(pending[i]) for i, agent in enumerate(self.agent_order)}

    def _pending(self) -> np.ndarray:
        if len(self._groups) == 1:  # one distribution for every agent: its rows are in order
            return self._groups[0][1].pending
        pending = np.zeros(len(self.agent_order))
        for rows, group in self._groups:
            pending[rows] = group.pending
        return pending

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the env; ``seed`` also reseeds every agent's delays (see the class docstring).

        The agents still live lose their pending rewards (except under ``"carry"``), reported
        as ``info[agent]["dropped_reward"]``, with a warning if they were not zero.

        Raises:
            TypeError, ValueError: ``seed`` is neither ``None`` nor an integer ``>= 0``.
        """
        obs, infos, seeds = self.reset_env(seed, options)
        if seeds is not None:
            for rows, group in self._groups:
                group.seed([seeds[i] for i in rows.tolist()])
        cut_short = self._in_episode
        if self.on_episode_end != "carry" and cut_short.any():
            lost = np.zeros(len(self.agent_order))
            for rows, group in self._groups:
                lost[rows] = group.clear(cut_short[rows])
            for i in np.flatnonzero(cut_short).tolist():
                agent = self.agent_order[i]
                if agent in infos:
                    infos[agent]["dropped_reward"] = float(lost[i])
            if lost.any():
                warnings.warn(
                    f"reset() while agents were live discarded their pending rewards "
                    f"({self._named(lost, cut_short)}, on_episode_end={self.on_episode_end!r}); "
                    "end the agents' episodes inside the ParallelRewardDelay wrapper to have "
                    "them flushed",
                    stacklevel=2,
                )
        self._in_episode = np.zeros(len(self.agent_order), dtype=bool)
        for agent in getattr(self.env, "agents", obs):
            self._in_episode[self.position(agent, "the env's agents")] = True
        pending = self._pending()
        for agent, info in infos.items():
            if agent in self.agent_index:
                info["pending_reward"] = float(pending[self.agent_index[agent]])
        return obs, infos

    def _named(self, amounts: np.ndarray, mask: np.ndarray) -> str:
        """``"'a': 1.0, 'b': 0.0"``: the amounts of the agents in ``mask``."""
        order = self.agent_order
        return ", ".join(f"{order[i]!r}: {amounts[i]}" for i in np.flatnonzero(mask).tolist())

    def step(self, actions: dict[Any, Any]):
        """Step the env; return each agent's rewards due now (see the class docstring)."""
        obs, rewards, terminated, truncated, infos = self.env.step(actions)
        emitted, active, ended = self._read(rewards, terminated, truncated)
        delivered, delays, settled = self._advance(emitted, active, ended)
        if self._watch is not None and self._watch.see_envs(
            sum(int(group.clock.sum()) for _, group in self._groups), emitted, ended
        ):
            self._watch = None
        self._in_episode |= active
        self._in_episode &= ~ended
        # Python numbers once, read agent by agent below
        delivered, delays, pending = delivered.tolist(), delays.tolist(), self._pending().tolist()
        undelayed = emitted.tolist()
        key = _SETTLED_KEYS.get(self.on_episode_end)
        infos = self.own_infos(infos)
        delivered_rewards = {}
        for agent in rewards:
            i = self.agent_index[agent]
            delivered_rewards[agent] = delivered[i]
            info = infos.setdefault(agent, {})
            info["undelayed_reward"] = undelayed[i]
            info["drawn_reward_delay"] = delays[i]
            info["pending_reward"] = pending[i]
            if key is not None and ended[i]:
                info[key] = float(settled[i])
        return obs, delivered_rewards, terminated, truncated, infos

    def _read(
        self, rewards: dict[Any, Any], terminated: dict[Any, Any], truncated: dict[Any, Any]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """This step's rewards, by agent position, checked; which agents stepped and ended.

        Raises:
            TypeError, ValueError: a reward is not a finite real scalar, or an agent is unknown.
        """
        count = len(self.agent_order)
        emitted = np.zeros(count)
        active = np.zeros(count, dtype=bool)
        ended = np.zeros(count, dtype=bool)
        for agent, reward in rewards.items():
            i = self.position(agent, "the env's rewards")
            if type(reward) is not float:
                reward = self._checked_reward(agent, reward)
            if reward - reward:  # inf or NaN
                raise ValueError(
                    f"the env gave agent {agent!r} a non-finite reward ({reward!r}); "
                    "ParallelRewardDelay refuses to delay it"
                )
            emitted[i] = reward
            active[i] = True
            ended[i] = bool(terminated.get(agent, False) or truncated.get(agent, False))
        return emitted, active, ended

    @staticmethod
    def _checked_reward(agent: Any, reward: Any) -> float:
        """``reward`` as a Python float (:func:`~delayed_rl._validation.check_reward`).

        Raises:
            TypeError: ``reward`` is not a real scalar.
            ValueError: it is an integer beyond float64's range.
        """
        try:
            value = check_reward(f"rewards[{agent!r}]", reward)
        except (TypeError, ValueError) as error:
            raise type(error)(
                f"{error}; the env gave it to agent {agent!r}, and ParallelRewardDelay refuses "
                "to delay it"
            ) from None
        return value

    def _advance(
        self, emitted: np.ndarray, active: np.ndarray, ended: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One step of every agent's pending rewards: what each receives, its delay, what it settled.

        Returns:
            ``(delivered, delays, settled)``, by agent position; ``settled`` is what an agent
            that ended flushed or dropped (0 for the others).
        """
        count = len(self.agent_order)
        if len(self._groups) == 1:  # one distribution for every agent: its rows are in order
            delivered, delays, settled = self._groups[0][1].step(
                emitted, active, ended, self.on_episode_end
            )
            return delivered, delays, np.zeros(count) if settled is None else settled
        delivered, delays, settled = np.zeros(count), np.zeros(count, dtype=np.int64), None
        for rows, group in self._groups:
            got, drawn, amounts = group.step(
                emitted[rows], active[rows], ended[rows], self.on_episode_end
            )
            delivered[rows], delays[rows] = got, drawn
            if amounts is not None:
                settled = np.zeros(count) if settled is None else settled
                settled[rows] = amounts
        return delivered, delays, np.zeros(count) if settled is None else settled
