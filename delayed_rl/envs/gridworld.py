"""The thesis's square grid world (Campbell 2015, section 5.1)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from delayed_rl._validation import check_choice, check_int
from delayed_rl.envs._actions import ActionCheck

UP, RIGHT, DOWN, LEFT = 0, 1, 2, 3
_MOVES = {UP: (-1, 0), RIGHT: (0, 1), DOWN: (1, 0), LEFT: (0, -1)}

MAX_STATES = 1 << 16
"""The most cells a grid may have: 65 536, a 256 × 256 grid (the thesis's largest is 9 × 9).

The env builds its dynamics for every cell: ``next_state`` and ``reward`` arrays and the toy-text
``P`` dict, about :data:`BYTES_PER_STATE` bytes a cell (some 85 MB at the limit, built in about a
second), and tabular agents then hold a table per cell. A larger ``size`` is refused at
construction, before anything is allocated."""

BYTES_PER_STATE = 1_300
"""About what one cell's tables take (measured: the ``P`` dict's lists and tuples dominate)."""

MAX_SIDE = math.isqrt(MAX_STATES)
"""The largest ``size``: 256 (``size² <= MAX_STATES``)."""


def _count(n: int) -> str:
    """``n`` with thousands separators, or as a power of ten when it is too long to read."""
    return f"{n:,}" if n < 10**30 else f"about 10^{int(n.bit_length() * math.log10(2))}"


def _gigabytes(n_bytes: int) -> str:
    """``n_bytes`` in GB, two significant digits (a power of ten beyond float64's range)."""
    return f"{n_bytes / 1e9:.2g}" if n_bytes < 10**300 else _count(n_bytes // 10**9)


class GridWorldEnv(gym.Env):
    """An ``size × size`` grid whose top-left cell pays +10 and warps the agent home.

    ## Description
    The grid world of the thesis (section 5.1, Figs. 5.1, 5.7 and 5.8). The agent starts in the
    bottom-right cell and must walk to the reward cell in the top-left corner; any action taken
    there pays +10 and warps it back to the bottom-right cell. Walls are penalised. The task is
    continuing: it never terminates, so the optimal average reward is one +10 per round trip of
    ``2(size − 1) + 1`` steps, ``10 / (2(size − 1) + 1)`` (0.588 for 9×9).

    ## Action Space
    ``Discrete(4)``: 0 up, 1 right, 2 down, 3 left (the thesis's actions 1–4). An action is an
    ``int``, a numpy integer or a 0-d integer array; anything else (``True`` and ``False``,
    which Gymnasium's ``Discrete.contains`` would read as 1 and 0, a float, a string...) raises
    ``TypeError``, an integer outside 0–3 ``ValueError``.

    ## Observation Space
    ``Discrete(size²)``: the cell index, row-major from the top-left corner, so the thesis's state
    ``k`` (Fig. 5.8) is index ``k − 1``; the reward cell is 0 and the start cell ``size² − 1``.

    ## Rewards
    - +10 for any action in the reward cell (index 0), which moves the agent to the start cell;
    - −1 for a move into a wall (the agent stays where it is);
    - 0 for every other move.

    ## Starting State
    The bottom-right cell (index ``size² − 1``), as in the thesis; ``reset(options={"state": k})``
    starts in cell ``k`` instead.

    ## Episode End
    Never terminates. With ``max_steps`` set, the episode is truncated after that many steps
    (the env does it itself, so a reward-delay wrapper on top sees the end and can flush).

    ## Tabular model
    ``env.P[s][a]`` is the list ``[(probability, next_state, reward, terminated)]``, the protocol of
    Gymnasium's toy-text envs (FrozenLake, Taxi, CliffWalking); agents and compiled training loops
    may read the dynamics from it.

    ## Arguments
    - ``size``: the side length, an integer ≥ 2 (default 9) with ``size² <= MAX_STATES``
      (``size <= MAX_SIDE``, 256: tables of some 85 MB). A larger size, here or through
      ``gym.make("delayed_rl/GridWorld-v0", size=...)``, raises ``ValueError`` naming the limit
      before anything is allocated.
    - ``max_steps``: truncate after this many steps (``None``, the default, never truncates).
    - ``render_mode``: ``None`` or ``"ansi"`` (a text picture of the grid).

    A wrong type (``size=3.0``, ``max_steps="5"``) raises ``TypeError``, a value out of range
    (``size=1``, ``size=1000``, ``max_steps=0``, ``render_mode="human"``) ``ValueError``.

    ## Registered Configurations
    - ``delayed_rl/GridWorld-3x3-v0``, ``delayed_rl/GridWorld-5x5-v0``,
      ``delayed_rl/GridWorld-9x9-v0``: the thesis's three worlds;
    - ``delayed_rl/GridWorld-v0``: pass ``size=``.

    Every id takes ``reward_delay=λ`` to come wrapped in
    :class:`~delayed_rl.wrappers.PoissonRewardDelay`.
    """

    metadata = {"render_modes": ["ansi"], "render_fps": 4}

    def __init__(self, size: int = 9, max_steps: int | None = None, render_mode: str | None = None):
        self.size = check_int("size", size, 2)
        if self.size > MAX_SIDE:  # before anything is allocated, whatever the size
            states = self.size * self.size
            size = self.size if self.size < 10**30 else _count(self.size)
            raise ValueError(
                f"size={size} would build tables of {_count(states)} states (about "
                f"{_gigabytes(states * BYTES_PER_STATE)} GB); the limit is {MAX_STATES:,} states "
                f"(size <= {MAX_SIDE}): see delayed_rl.envs.gridworld.MAX_STATES"
            )
        self.max_steps = check_int("max_steps", max_steps, 1, optional=True)
        self.render_mode = check_choice(
            "render_mode", render_mode, (None, *self.metadata["render_modes"])
        )
        self.n_states = self.size * self.size
        self.start_state = self.n_states - 1
        self.reward_state = 0
        self.observation_space = spaces.Discrete(self.n_states)
        self.action_space = spaces.Discrete(4)
        self._check_action = ActionCheck(
            self.action_space, "in Discrete(4) (0 up, 1 right, 2 down, 3 left)", integers_only=True
        ).check
        self.next_state, self.reward_table = self._build_tables()
        self.P = {
            s: {a: [(1.0, nxt, reward, False)] for a, (nxt, reward) in enumerate(moves)}
            for s, moves in enumerate(
                zip(row_next, row_reward, strict=True)
                for row_next, row_reward in zip(
                    self.next_state.tolist(), self.reward_table.tolist(), strict=True
                )
            )
        }
        self.initial_state_distrib = np.zeros(self.n_states)
        self.initial_state_distrib[self.start_state] = 1.0
        self.state = self.start_state
        self.steps = 0

    @property
    def optimal_average_reward(self) -> float:
        """The best long-run reward per step: +10 every ``2(size − 1) + 1`` steps."""
        return 10.0 / (2 * (self.size - 1) + 1)

    def _build_tables(self) -> tuple[np.ndarray, np.ndarray]:
        """``(next_state, reward)``, each ``(n_states, 4)``: the deterministic dynamics."""
        states = np.arange(self.n_states)
        row, col = np.divmod(states, self.size)
        next_state = np.empty((self.n_states, 4), dtype=np.int64)
        reward = np.zeros((self.n_states, 4), dtype=np.float64)
        for a, (d_row, d_col) in _MOVES.items():
            inside = (row + d_row >= 0) & (row + d_row < self.size)
            inside &= (col + d_col >= 0) & (col + d_col < self.size)
            next_state[:, a] = np.where(inside, (row + d_row) * self.size + col + d_col, states)
            reward[:, a] = np.where(inside, 0.0, -1.0)  # a wall: stay put, pay -1
        next_state[self.reward_state], reward[self.reward_state] = self.start_state, 10.0
        return next_state, reward

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Put the agent on the start cell, or on cell ``options["state"]`` if given.

        Raises:
            TypeError: ``options["state"]`` is not an integer.
            ValueError: ``options["state"]`` is not a cell index.
        """
        super().reset(seed=seed)
        state = self.start_state
        if options and "state" in options:
            state = check_int("options['state']", options["state"], 0, self.n_states - 1)
        self.state = int(state)
        self.steps = 0
        return self.state, {}

    def step(self, action):
        """Move (or collect the +10 and warp home); truncate after ``max_steps`` if set.

        Raises:
            TypeError: ``action`` is not an integer (a bool, which ``Discrete.contains`` would
                take for 1 or 0, is not an action here, nor a number anywhere in this library).
            ValueError: ``action`` is not in the action space (Gymnasium's
                ``Discrete.contains``, answered fast for ``int`` and numpy integers).
        """
        self._check_action(action)
        reward = float(self.reward_table[self.state, action])
        self.state = int(self.next_state[self.state, action])
        self.steps += 1
        truncated = self.max_steps is not None and self.steps >= self.max_steps
        return self.state, reward, False, truncated, {}

    def render(self) -> str | None:
        """The grid as text (``R`` the reward cell, ``A`` the agent) in ``"ansi"`` mode, else None."""
        if self.render_mode != "ansi":
            return None
        cells = np.full((self.size, self.size), ".", dtype="<U1")
        cells.flat[self.reward_state] = "R"
        cells.flat[self.state] = "A"
        return "\n".join(" ".join(row) for row in cells) + "\n"
