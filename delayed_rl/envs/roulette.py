"""The thesis's Roulette example (Campbell 2015, section 3.2, Tables 3.1–3.5)."""

from __future__ import annotations

import gymnasium as gym
from gymnasium import spaces

from delayed_rl._validation import check_choice, check_int
from delayed_rl.envs._actions import ActionCheck

BET_EVEN, BET_13 = 0, 1
POCKETS = 38  # an American wheel: 1-36, 0 and 00
EVEN_WINS = 18  # 2, 4, ..., 36 (0 and 00 lose)


class RouletteEnv(gym.Env):
    """One state, two bets, one American wheel.

    ## Description
    The gambler of the thesis's worked example (section 3.2) bets $1 every round, either on
    *even* or on *number 13*. With a delayed payout (wrap it in
    :class:`~delayed_rl.wrappers.PoissonRewardDelay`) the wagers' outcomes arrive late, overlap
    and arrive out of order: the smallest setting in which MMQ's credit assignment can be traced
    by hand (Tables 3.2–3.5).

    ## Action Space
    ``Discrete(2)``: 0 bets 1 on even, 1 bets 1 on number 13 (the thesis's actions 1 and 2).
    What is not an integer (``True`` and ``False`` included, which Gymnasium's
    ``Discrete.contains`` would read as 1 and 0) raises ``TypeError``.

    ## Observation Space
    ``Discrete(1)``: there is one state, the roulette table (always 0).

    ## Rewards
    - bet even: +1 with probability 18/38, else −1 (expected −2/38 ≈ −0.053);
    - bet 13: +35 with probability 1/38, else −1 (expected −2/38 ≈ −0.053).

    ## Starting State
    0, the only state.

    ## Episode End
    Never terminates. With ``max_steps`` set, truncated after that many rounds.

    ## Tabular model
    ``env.P[0][a]`` lists ``(probability, next_state, reward, terminated)`` outcomes, the protocol
    of Gymnasium's toy-text envs.

    ## Arguments
    - ``max_steps``: truncate after this many rounds (``None``, the default, never truncates).
    - ``render_mode``: ``None`` only (Roulette does not render).

    A wrong type (``max_steps="5"``, ``render_mode=1``) raises ``TypeError``, a value out of
    range (``max_steps=0``, ``render_mode="ansi"``) ``ValueError``.

    ## Registered Configurations
    ``delayed_rl/Roulette-v0`` (takes ``reward_delay=λ`` like every delayed-rl id).
    """

    metadata = {"render_modes": []}

    def __init__(self, max_steps: int | None = None, render_mode: str | None = None):
        self.max_steps = check_int("max_steps", max_steps, 1, optional=True)
        if isinstance(render_mode, str):  # a mode's name, but Roulette has no mode
            raise ValueError(
                f"render_mode must be None (Roulette does not render), got {render_mode!r}"
            )
        self.render_mode = check_choice("render_mode", render_mode, (None,))
        self.observation_space = spaces.Discrete(1)
        self.action_space = spaces.Discrete(2)
        self._check_action = ActionCheck(
            self.action_space, "0 (bet even) or 1 (bet 13)", integers_only=True
        ).check
        self.P = {
            0: {
                BET_EVEN: [
                    (EVEN_WINS / POCKETS, 0, 1.0, False),
                    (1 - EVEN_WINS / POCKETS, 0, -1.0, False),
                ],
                BET_13: [(1 / POCKETS, 0, 35.0, False), (1 - 1 / POCKETS, 0, -1.0, False)],
            }
        }
        self.initial_state_distrib = [1.0]
        self.steps = 0

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start a new session at the table (state 0); ``seed`` seeds the wheel."""
        super().reset(seed=seed)
        self.steps = 0
        return 0, {}

    def step(self, action):
        """Spin the wheel for one $1 bet; ``info["pocket"]`` names the pocket (``"00"``...).

        Raises:
            TypeError: ``action`` is not an integer (a bool included, which
                ``Discrete.contains`` would take for 1 or 0).
            ValueError: ``action`` is not in the action space (Gymnasium's
                ``Discrete.contains``, answered fast for ``int`` and numpy integers).
        """
        self._check_action(action)
        pocket = int(self.np_random.integers(POCKETS))  # 0..35 stand for 1..36; 36, 37 are 0, 00
        if action == BET_EVEN:
            reward = 1.0 if pocket < 36 and (pocket + 1) % 2 == 0 else -1.0
        else:
            reward = 35.0 if pocket == 12 else -1.0
        self.steps += 1
        truncated = self.max_steps is not None and self.steps >= self.max_steps
        return 0, reward, False, truncated, {"pocket": _pocket_name(pocket)}


def _pocket_name(pocket: int) -> str:
    """The label of pocket index ``pocket``: ``"1"``..``"36"``, ``"0"`` (36) or ``"00"`` (37)."""
    return {36: "0", 37: "00"}.get(pocket, str(pocket + 1))
