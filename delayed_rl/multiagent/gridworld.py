"""A cooperative two-agent version of the thesis's grid world, as a PettingZoo ``ParallelEnv``."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from delayed_rl._validation import check_choice, check_int
from delayed_rl.envs._actions import ActionCheck
from delayed_rl.envs.gridworld import GridWorldEnv

__all__ = ["CooperativeGridWorldEnv"]

#: The reward both agents get when they meet on the reward cell (the thesis's +10).
MEETING_REWARD = 10.0


class CooperativeGridWorldEnv(ParallelEnv):
    """Two agents on the thesis's grid world, paid +10 only when both stand on the reward cell.

    ## Description
    The grid world of :class:`~delayed_rl.envs.gridworld.GridWorldEnv`, walked by two agents,
    ``"agent_0"`` and ``"agent_1"``, both live from the reset to the episode's end. Both start
    in the bottom-right cell; an agent on the top-left reward cell waits there until the other
    arrives, and then both are paid and go home, so the team must walk the single world's loop
    in step. The optimal average reward is the single world's, 1.11 for 5×5. The rules in full
    are on the multi-agent page of the docs.

    ## Spaces
    Actions: ``Discrete(4)`` per agent (0 up, 1 right, 2 down, 3 left), one for every live
    agent. Observations: ``Discrete(size²)`` per agent, its *own* cell, row-major from the
    top-left corner; the joint position is :meth:`state`.

    ## Rewards
    Shared: +10 when both agents are on the reward cell at the start of the step (then both
    warp to the start cell), −1 for each agent that moves into a wall, 0 otherwise.

    ## Episode End
    Never terminates; both agents are truncated after ``max_steps`` steps. It draws nothing at random.

    Args:
        size: the side length, an integer ≥ 2 (at most 256).
        max_steps: the episode's length, an integer ≥ 1, or ``None`` (never ends).
        render_mode: ``None`` or ``"ansi"`` (a text picture of the grid).

    Raises:
        TypeError: an argument of the wrong type (``size=3.0``).
        ValueError: an argument out of range (``size=1``, ``max_steps=0``,
            ``render_mode="human"``).

    Example:
        >>> env = CooperativeGridWorldEnv(size=3)
        >>> env.reset(seed=0, options={"states": {"agent_0": 0, "agent_1": 1}})[0]
        {'agent_0': 0, 'agent_1': 1}
        >>> rewards = env.step({"agent_0": 1, "agent_1": 3})[1]  # agent_1 steps left onto it
        >>> rewards, env.step({"agent_0": 0, "agent_1": 0})[1]  # both on it: +10, both home
        ({'agent_0': 0.0, 'agent_1': 0.0}, {'agent_0': 10.0, 'agent_1': 10.0})
    """

    metadata = {"name": "cooperative_gridworld_v0", "render_modes": ["ansi"]}

    def __init__(self, size: int = 5, max_steps: int | None = 100, render_mode: str | None = None):
        single = GridWorldEnv(size)  # checks size, and holds the single world's moves
        self.size = single.size
        self.max_steps = check_int("max_steps", max_steps, 1, optional=True)
        self.render_mode = check_choice(
            "render_mode", render_mode, (None, *self.metadata["render_modes"])
        )
        self.n_states = single.n_states
        self.start_state = single.start_state
        self.reward_state = single.reward_state
        self.next_state = single.next_state  # (cell, action): the single world's move...
        self.wall_penalty = single.reward_table  # ...and its -1 for a wall (the reward cell's
        # row, its +10 and warp, is never read: there an agent waits or both collect)
        self.possible_agents = ["agent_0", "agent_1"]
        self.agents: list[str] = []
        self._observation_space = spaces.Discrete(self.n_states)
        self._action_space = spaces.Discrete(4)
        self.state_space = spaces.Discrete(self.n_states * self.n_states)
        self._check_action = ActionCheck(
            self._action_space,
            "in Discrete(4) (0 up, 1 right, 2 down, 3 left)",
            integers_only=True,
        ).check
        self.positions = dict.fromkeys(self.possible_agents, self.start_state)
        self.steps = 0

    @property
    def optimal_average_reward(self) -> float:
        """The best long-run reward per step: +10 every ``2(size − 1) + 1`` steps, as alone."""
        return MEETING_REWARD / (2 * (self.size - 1) + 1)

    def optimal_episode_reward(self, steps: int) -> float:
        """The best total reward of ``steps`` steps from the start: +10 every full loop."""
        return MEETING_REWARD * (check_int("steps", steps, 0) // (2 * (self.size - 1) + 1))

    def observation_space(self, agent: Any) -> spaces.Discrete:
        """``Discrete(size²)``, the same object for every agent and call."""
        return self._observation_space

    def action_space(self, agent: Any) -> spaces.Discrete:
        """``Discrete(4)``, the same object for every agent and call."""
        return self._action_space

    def reset(self, seed: int | None = None, options: dict | None = None):
        """Put both agents on the start cell, or where ``options["states"]`` says.

        Raises:
            TypeError: ``options["states"]`` is not a dict, or a cell is not an integer.
            ValueError: it names an unknown agent, or a cell that is not a cell index.
        """
        if seed is not None or not hasattr(self, "np_random"):
            self.np_random = np.random.default_rng(seed)
        self.positions = dict.fromkeys(self.possible_agents, self.start_state)
        states = (options or {}).get("states", {})
        if not isinstance(states, dict):
            raise TypeError(
                f"options['states'] must be a dict from agent to cell, got {states!r} "
                f"({type(states).__name__})"
            )
        for agent, cell in states.items():
            if agent not in self.positions:
                raise ValueError(
                    f"options['states'] names {agent!r}, not one of {self.possible_agents}"
                )
            self.positions[agent] = check_int(
                f"options['states'][{agent!r}]", cell, 0, self.n_states - 1
            )
        self.agents = list(self.possible_agents)
        self.steps = 0
        return dict(self.positions), {agent: {} for agent in self.agents}

    def step(self, actions: dict[Any, Any]):
        """Move both agents (or pay both +10 and warp them home); truncate after ``max_steps``.

        Raises:
            TypeError: an action is not an integer.
            ValueError: an action is outside ``Discrete(4)``, a live agent has none, an action
                names an agent that is not live, or the episode has ended (call ``reset()``).
        """
        if not self.agents:
            raise ValueError("the episode has ended (no live agents): call reset() first")
        if set(actions) != set(self.agents):
            raise ValueError(
                f"actions must name every live agent {self.agents} and no other, got "
                f"{sorted(map(str, actions))}"
            )
        for action in actions.values():
            self._check_action(action)
        if all(cell == self.reward_state for cell in self.positions.values()):
            reward = MEETING_REWARD
            self.positions = dict.fromkeys(self.possible_agents, self.start_state)
        else:
            reward, moved = 0.0, {}
            for agent, cell in self.positions.items():
                if cell == self.reward_state:  # on it alone, an agent waits
                    moved[agent] = cell
                    continue
                action = int(actions[agent])
                reward += float(self.wall_penalty[cell, action])
                moved[agent] = int(self.next_state[cell, action])
            self.positions = moved
        self.steps += 1
        ended = self.max_steps is not None and self.steps >= self.max_steps
        agents = self.agents
        self.agents = [] if ended else agents
        return (
            dict(self.positions),
            dict.fromkeys(agents, reward),
            dict.fromkeys(agents, False),
            dict.fromkeys(agents, ended),
            {agent: {} for agent in agents},
        )

    def state(self) -> int:
        """The joint position, ``s_0 · size² + s_1`` (in ``state_space``)."""
        return self.positions["agent_0"] * self.n_states + self.positions["agent_1"]

    def render(self) -> str | None:
        """The grid as text (``R`` the reward cell, ``0``/``1``/``B`` the agents) in ``"ansi"`` mode."""
        if self.render_mode != "ansi":
            return None
        cells = np.full((self.size, self.size), ".", dtype="<U1")
        cells.flat[self.reward_state] = "R"
        first, second = self.positions["agent_0"], self.positions["agent_1"]
        cells.flat[first], cells.flat[second] = "0", "1"
        if first == second:
            cells.flat[first] = "B"
        return "\n".join(" ".join(row) for row in cells) + "\n"

    def close(self) -> None:
        """Nothing to release."""
