"""Small PettingZoo envs for the multi-agent wrappers' tests, and single-agent replays of one agent.

:class:`ScriptedParallelEnv`: agents with known rewards and observations that join and leave at
chosen steps; :class:`AgentReplay`: one agent's part of it as a Gymnasium env, for the
single-agent wrappers that the multi-agent ones must match step by step.
"""

from __future__ import annotations

import functools
import importlib

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv


def pettingzoo_env(env_id: str, kind: str = "parallel", **kwargs):
    """A PettingZoo env by its registry id (``"sisl/pursuit-v5"``), its ``kind`` ``"parallel"`` or ``"aec"``.

    PettingZoo 1.27 makes it from its registry (``pettingzoo.make``; importing the env's module
    is deprecated there), the versions before from its module (``pettingzoo.sisl.pursuit_v5``).
    """
    import pettingzoo

    if hasattr(pettingzoo, "make"):
        return pettingzoo.make(kind, env_id, **kwargs)
    family, name = env_id.split("/")
    module = importlib.import_module(f"pettingzoo.{family}.{name.replace('-', '_')}")
    return module.parallel_env(**kwargs) if kind == "parallel" else module.env(**kwargs)


def scripted_reward(agent_index: int, episode: int, step: int) -> float:
    """The reward of agent ``agent_index`` at its ``step`` (from 1) of ``episode``: halves, zeros."""
    value = ((agent_index + 1) * 7 + step * 3 + episode * 5) % 11 - 5
    return value + 0.5 * (step % 2) if value else 0.0


class ScriptedParallelEnv(ParallelEnv):
    """Agents with known rewards that join and leave at chosen steps.

    Agent ``a`` is in the episode from step ``joins.get(a, 0)`` (0: from the reset) to step
    ``ends[a][0]``, where it terminates (``ends[a][1] == "terminated"``) or is truncated. At
    every step it is in, it gets :func:`scripted_reward` of its own step count (so 1 at the step
    it joins at) and an observation ``[episode step, agent index, noise]``, the noise drawn from
    the env's own ``np_random``. The observation arrays are the env's own, changed in place at
    every step (as envs that hand out views of their state do), unless ``fresh``.

    Args:
        ends: each agent's last step and how it ends.
        joins: the step at which an agent joins (absent: at the reset).
        action_spaces: each agent's action space (default ``Discrete(5)``).
        fresh: hand out new observation arrays (default: the env's own, reused).

    Attributes:
        received: the actions the env was given at each step of the episode, in order.
    """

    metadata = {"name": "scripted_v0", "render_modes": [], "is_parallelizable": True}

    def __init__(self, ends, joins=None, action_spaces=None, fresh=False):
        self.possible_agents = list(ends)
        self.ends = dict(ends)
        self.joins = dict(joins or {})
        self._action_spaces = dict(action_spaces or {})
        self.fresh = fresh
        self.episode = -1
        self.render_mode = None

    @functools.cache  # noqa: B019 (PettingZoo's advice: one space object)
    def observation_space(self, agent):
        return spaces.Box(-np.inf, np.inf, (3,), np.float64)

    @functools.cache  # noqa: B019
    def action_space(self, agent):
        return self._action_spaces.get(agent, spaces.Discrete(5))

    def reset(self, seed=None, options=None):
        if seed is not None or not hasattr(self, "np_random"):
            self.np_random = np.random.default_rng(seed)
        self.episode += 1
        self.t = 0
        self.steps = dict.fromkeys(self.possible_agents, 0)
        self.buffers = {agent: np.zeros(3) for agent in self.possible_agents}
        self.agents = [a for a in self.possible_agents if self.joins.get(a, 0) == 0]
        self.received = []
        return {agent: self._observe(agent) for agent in self.agents}, {
            agent: {} for agent in self.agents
        }

    def _observe(self, agent):
        buffer = self.buffers[agent]
        buffer[:] = (self.t, self.possible_agents.index(agent), self.np_random.normal())
        return buffer.copy() if self.fresh else buffer

    def step(self, actions):
        self.received.append(dict(actions))
        self.t += 1
        joining = [a for a in self.possible_agents if self.joins.get(a, 0) == self.t]
        present = [*self.agents, *joining]
        obs, rewards, terminated, truncated = {}, {}, {}, {}
        for agent in present:
            self.steps[agent] += 1
            index = self.possible_agents.index(agent)
            rewards[agent] = scripted_reward(index, self.episode, self.steps[agent])
            last, how = self.ends[agent]
            terminated[agent] = self.t >= last and how == "terminated"
            truncated[agent] = self.t >= last and how == "truncated"
            obs[agent] = self._observe(agent)
        self.agents = [a for a in present if not (terminated[a] or truncated[a])]
        return obs, rewards, terminated, truncated, {agent: {} for agent in present}

    def render(self):
        return None

    def close(self):
        pass

    def state(self):
        return np.array([self.t], dtype=np.float64)


class AgentReplay(gym.Env):
    """One agent's rewards and observations, replayed as a single-agent Gymnasium env.

    Args:
        episodes: per episode, the list of ``(reward, observation, terminated, truncated)`` of
            the agent's steps, and its first observation: ``(first, steps)``.
        action_space: the agent's action space.

    Attributes:
        received: the actions the env was given, over every episode.
    """

    def __init__(self, episodes, action_space=None, observation_space=None):
        self.episodes = episodes
        self.action_space = action_space or spaces.Discrete(5)
        self.observation_space = observation_space or spaces.Box(-np.inf, np.inf, (3,))
        self.episode = -1
        self.received = []

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.episode += 1
        self.t = 0
        return self.episodes[self.episode][0], {}

    def step(self, action):
        self.received.append(action)
        reward, obs, terminated, truncated = self.episodes[self.episode][1][self.t]
        self.t += 1
        return obs, reward, terminated, truncated, {}


def policy(t: int, agent_index: int) -> int:
    """The ``Discrete(5)`` action that the tests send for an agent at the ``t``-th step of a run."""
    return (3 * t + agent_index) % 5


def record(env, seed, schedule):
    """What each agent sees of ``env`` (unwrapped) over episodes, under :func:`policy`.

    Args:
        env: a :class:`ScriptedParallelEnv` (or any ParallelEnv with ``Discrete(5)`` actions).
        seed: the first reset's seed (the later resets have none).
        schedule: per episode, the most steps to take (``None``: until no agent is left); a
            number below the episode's length resets while agents are live.

    Returns:
        Per agent, per episode, ``[reset observation or None, steps]``, ``steps`` the
        ``(reward, observation, terminated, truncated)`` of every step whose dicts name it.
    """
    out = {agent: [] for agent in env.possible_agents}
    t = 0
    for episode, cut in enumerate(schedule):
        obs, _ = env.reset(seed=seed if episode == 0 else None)
        for agent in env.possible_agents:
            first = np.copy(obs[agent]) if agent in obs else None
            out[agent].append([first, []])
        taken = 0
        while env.agents and (cut is None or taken < cut):
            order = env.possible_agents
            actions = {a: policy(t, order.index(a)) for a in env.agents}
            obs, rewards, terminated, truncated, _ = env.step(actions)
            t += 1
            taken += 1
            for agent in rewards:
                step = (rewards[agent], np.copy(obs[agent]), terminated[agent], truncated[agent])
                out[agent][-1][1].append(step)
    return out
