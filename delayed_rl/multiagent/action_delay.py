"""Action delays per agent for PettingZoo's ``ParallelEnv``: :class:`ParallelActionDelay`."""

from __future__ import annotations

from typing import Any

from gymnasium import spaces
from pettingzoo import ParallelEnv

from delayed_rl.delays import Delay
from delayed_rl.multiagent._agents import per_agent_actions
from delayed_rl.multiagent._base import ParallelDelayWrapper
from delayed_rl.wrappers._samples import as_action, copy_sample
from delayed_rl.wrappers.action_delay import ActionLine, checked_action, neutral_action

__all__ = ["ParallelActionDelay"]


def _initial_action(agent: Any, space: spaces.Space, value: Any, name: str) -> Any:
    """``value`` as ``agent``'s initial action (``None``: the space's neutral action).

    Raises:
        ValueError: ``value`` is not in ``space``, or is ``None`` for a space without a neutral
            action (the message names the agent).
    """
    if value is None:
        try:
            value = neutral_action(space)
        except ValueError as error:  # names initial_action; say whose
            raise ValueError(f"{error} (agent {agent!r})") from None
    return as_action(space, value, name)


class ParallelActionDelay(ParallelDelayWrapper):
    """Delays every agent's actions independently, with the rule of :class:`~delayed_rl.wrappers.ActionDelay`.

    Each agent has its own :class:`~delayed_rl.wrappers.action_delay.ActionLine` and delay
    stream: the action it sends at its step ``t`` arrives at its step ``t + d_t``. An agent's
    actions in transit are discarded when it leaves, and it joins with none. Actions are checked
    and copied as :class:`~delayed_rl.wrappers.ActionDelay` does. ``reset(seed=s)`` seeds agent
    ``i`` with :func:`~delayed_rl.multiagent.agent_seed` ``(s, i)``: it executes the actions of
    an :class:`~delayed_rl.wrappers.ActionDelay` reset with that seed. ``docs/multiagent.md``
    has the rules in full.

    ``info[agent]``, for every agent that sent an action: ``executed_action``,
    ``executed_action_step`` (``-1`` for its initial action) and ``drawn_action_delay``
    (``d_t``); at its last step (or a ``reset()``), ``discarded_actions``, the
    ``(sent step, action)`` pairs it had in transit.

    Args:
        env: a ``pettingzoo.ParallelEnv`` with ``possible_agents``.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean, for every agent; or a mapping from every agent of
            ``possible_agents`` to one of those.
        initial_action: what an agent executes until its first action arrives: one action for
            every agent, or a mapping from every agent to its own; ``None``: the neutral action
            (:func:`~delayed_rl.wrappers.action_delay.neutral_action`).
        max_delay: clip delays to at most this many steps (``None``: unbounded).

    Raises:
        TypeError, ValueError: for an invalid argument, as :class:`~delayed_rl.wrappers.ActionDelay`
            (the message names it: ``initial_action['agent']`` for a mapping's entry).
        ValueError: at a step, an action not in its agent's space (the message names
            ``actions['agent']``), or an agent not in ``possible_agents``.

    Attributes:
        delays: each agent's distribution.
        initial_actions: each agent's initial action.
        lines: each agent's line.

    Example:
        >>> from pettingzoo.classic.rps.rps import parallel_env  # rock-paper-scissors
        >>> from delayed_rl.delays import Constant
        >>> env = ParallelActionDelay(parallel_env(), Constant(1), initial_action=2)
        >>> _ = env.reset(seed=0)
        >>> [int(env.step({"player_0": a, "player_1": 0})[-1]["player_0"]["executed_action"])
        ...  for a in (1, 0, 0)]
        [2, 1, 0]
    """

    def __init__(
        self,
        env: ParallelEnv,
        delay: Delay | float | dict[Any, Any],
        initial_action: Any = None,
        max_delay: int | None = None,
    ):
        super().__init__(env, delay, max_delay, {"initial_action": initial_action})
        self.initial_actions = per_agent_actions(
            initial_action, self.agent_order, self.env.action_space, _initial_action
        )
        self.lines = {
            agent: ActionLine(copy_sample(action)) for agent, action in self.initial_actions.items()
        }
        self._samplers = self.delay_samplers("action")

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the env and every agent's line; ``seed`` also reseeds every agent's delays.

        Raises:
            TypeError, ValueError: ``seed`` is neither ``None`` nor an integer ``>= 0``.
        """
        obs, infos, seeds = self.reset_env(seed, options)
        self.seed_samplers(self._samplers, seeds)
        for agent, line in self.lines.items():
            if line.in_transit and agent in infos:
                infos[agent]["discarded_actions"] = self._discarded(line)
            line.reset()
        return obs, infos

    def step(self, actions: dict[Any, Any]):
        """Send each agent's action; step the env with the actions executed now.

        Raises:
            ValueError: an action is not in its agent's action space, or ``actions`` names an
                agent not in ``possible_agents``.
        """
        checked = {}  # every action checked before any is sent: a refused step sends nothing
        for agent, action in actions.items():
            self.position(agent, "actions")
            space = self.env.action_space(agent)
            checked[agent] = checked_action(space, action, f"actions[{agent!r}]")
        sent = {}
        for agent, action in checked.items():
            delay = self._samplers[agent]()
            sent[agent] = (self.lines[agent].send(action, delay), delay)
        executed = {agent: copy_sample(action) for agent, (action, _) in sent.items()}
        obs, rewards, terminated, truncated, infos = self.env.step(executed)
        infos = self.own_infos(infos)
        for agent, (action, delay) in sent.items():
            info = infos.setdefault(agent, {})
            info["executed_action"] = copy_sample(action)
            info["executed_action_step"] = self.lines[agent].executed_step
            info["drawn_action_delay"] = delay
        for agent in {**terminated, **truncated}:
            if (terminated.get(agent) or truncated.get(agent)) and agent in self.lines:
                line = self.lines[agent]
                infos.setdefault(agent, {})["discarded_actions"] = self._discarded(line)
                line.reset()
        return obs, rewards, terminated, truncated, infos

    @staticmethod
    def _discarded(line: ActionLine) -> tuple[tuple[int, Any], ...]:
        """Copies of the ``(sent step, action)`` pairs in transit on ``line``, by sent step."""
        return tuple((step, copy_sample(action)) for step, action in line.remaining())
