"""Q-learning and fixed-delay Q-learning: Multiple Model Q-learning with a single model.

``QLearning`` is MMQ with Λ = {0} (every reward credited to the step that just happened, the
textbook rule, thesis Eq. 3.2); ``FixedDelayQLearning(delay_estimate=k)`` is MMQ with Λ = {k} (every
reward credited to the step ``k`` steps back, the constant-delay agents of thesis Fig. 5.6). Both
run MMQ's code, so ``QLearning`` and ``MultipleModelQLearning(delay_estimates=[0])`` produce
identical tables for the same seed and env.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from delayed_rl._validation import check_int
from delayed_rl.agents.common.hyperparameters import shares_hyperparameters
from delayed_rl.agents.mmq import OPTION_NAMES, MultipleModelQLearning, check_delay_estimates

__all__ = ["FixedDelayQLearning", "QLearning"]

_SINGLE_MODEL_NAMES = tuple(
    name for name in MultipleModelQLearning._hyperparameter_names if name not in OPTION_NAMES
)  # MMQ's options are not exposed: with one model, the kernel and the trace are moot


def _estimates(delay_estimates: Any) -> list[int]:
    """Λ as a file gives it, checked as MMQ checks it (a sequence of distinct integers >= 0)."""
    return check_delay_estimates(None, None, delay_estimates).tolist()


class QLearning(MultipleModelQLearning):
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

    _hyperparameter_names = _SINGLE_MODEL_NAMES
    _choose = MultipleModelQLearning._choose_action  # one model: the choice is its action's

    @shares_hyperparameters
    def __init__(self, env: gym.Env | str, **hyperparameters: Any):
        super().__init__(env, delay_estimates=[0], **hyperparameters)

    def _set_hyperparameters(self, *, delay_estimates: Any = None, **kwargs: Any) -> None:
        if delay_estimates is not None and _estimates(delay_estimates) != [0]:
            raise ValueError(f"QLearning has delay_estimates [0], got {delay_estimates!r}")
        super()._set_hyperparameters(delay_estimates=delay_estimates, **kwargs)


class FixedDelayQLearning(MultipleModelQLearning):
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
    """

    _hyperparameter_names = _SINGLE_MODEL_NAMES
    _choose = MultipleModelQLearning._choose_action  # one model: the choice is its action's

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
        super().__init__(env, delay_estimates=[int(delay_estimate)], **hyperparameters)

    @property
    def delay_estimate(self) -> int:
        """The assumed delay, in steps."""
        return int(self._delay_estimates[0])

    def _set_hyperparameters(self, *, delay_estimates: Any = None, **kwargs: Any) -> None:
        if delay_estimates is not None and len(_estimates(delay_estimates)) != 1:
            raise ValueError(
                f"FixedDelayQLearning has one delay estimate, got delay_estimates="
                f"{delay_estimates!r}"
            )
        super()._set_hyperparameters(delay_estimates=delay_estimates, **kwargs)
