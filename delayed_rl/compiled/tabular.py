"""Read a tabular env's dynamics, and its reward delay, so the loop can run compiled.

:func:`inspect_stack` reads an env that follows the protocol of Gymnasium's toy-text envs
(``env.P[s][a]``, ``env.initial_state_distrib`` and optionally ``env.max_steps``), under
Gymnasium's bookkeeping wrappers, a ``TimeLimit`` and at most one
:class:`~delayed_rl.wrappers.RewardDelay`, into a :class:`TabularModel`; any other stack is
:class:`NotCompilable`. The protocol, what a ``TimeLimit``'s place does to pending rewards and a
user's own env: the docs' compiled-path page (``docs/compiled.md``, "Your own tabular env").
"""

from __future__ import annotations

import math
from typing import NamedTuple

import gymnasium as gym
import numpy as np

from delayed_rl.wrappers.reward_delay import RewardDelay

TRANSPARENT_WRAPPERS = (gym.wrappers.OrderEnforcing, gym.wrappers.PassiveEnvChecker)


class NotCompilable(Exception):
    """The env stack cannot run on the compiled path; the message says why."""


class TabularModel(NamedTuple):
    """An env's dynamics as arrays of shape (S, A, K) over its K outcomes per (state, action).

    Attributes:
        out_cdf: the cumulative probabilities of the outcomes.
        out_next: their next states.
        out_reward: their rewards.
        out_term: whether they are terminal.
        init_cdf: the cumulative initial-state distribution.
        max_steps: the env truncates its episodes after this many steps, seen by the reward
            delay (0: never): the env's own ``max_steps`` and the ``TimeLimit`` wrappers below it.
        cut_steps: a ``TimeLimit`` above the reward delay truncates the episodes after this
            many steps, unseen by it (0: never, or not before ``max_steps``).
    """

    out_cdf: np.ndarray
    out_next: np.ndarray
    out_reward: np.ndarray
    out_term: np.ndarray
    init_cdf: np.ndarray
    max_steps: int
    cut_steps: int = 0

    @classmethod
    def empty(cls) -> TabularModel:
        """Tables of one state and action, for runs that replay a script or step a robot."""
        none = np.zeros((1, 1, 1))
        return cls(none, none.astype(np.int64), none, none.astype(np.bool_), np.ones(1), 0)

    @classmethod
    def from_env(cls, env: gym.Env) -> TabularModel:
        """Read the tables of ``env`` (an unwrapped env following the protocol above)."""
        table = getattr(env, "P", None)
        if not isinstance(table, dict):
            raise NotCompilable(f"{type(env).__name__} has no toy-text table P[s][a]")
        if not isinstance(env.observation_space, gym.spaces.Discrete) or not isinstance(
            env.action_space, gym.spaces.Discrete
        ):
            raise NotCompilable("the observation and action spaces must be Discrete")
        init = getattr(env, "initial_state_distrib", None)
        if init is None:
            raise NotCompilable(f"{type(env).__name__} has no initial_state_distrib")
        n_states, n_actions = int(env.observation_space.n), int(env.action_space.n)
        if any(s not in table or len(table[s]) != n_actions for s in range(n_states)):
            raise NotCompilable("P must list every action of every state")
        k = max(len(table[s][a]) for s in range(n_states) for a in range(n_actions))
        prob = np.zeros((n_states, n_actions, k))
        out_next = np.zeros((n_states, n_actions, k), dtype=np.int64)
        out_reward = np.zeros((n_states, n_actions, k))
        out_term = np.zeros((n_states, n_actions, k), dtype=np.bool_)
        for s in range(n_states):
            for a in range(n_actions):
                for i, (p, s2, r, term) in enumerate(table[s][a]):
                    prob[s, a, i], out_next[s, a, i] = p, s2
                    out_reward[s, a, i], out_term[s, a, i] = r, term
        _check_tables(type(env).__name__, prob, out_next, out_reward, n_states)
        init = np.asarray(init, dtype=float)
        if init.shape != (n_states,) or not np.all(np.isfinite(init)) or np.any(init < 0):
            raise ValueError(
                f"{type(env).__name__}.initial_state_distrib must hold {n_states} finite "
                f"probabilities >= 0, got {init!r}"
            )
        cdf = np.cumsum(prob, axis=2)
        cdf[:, :, -1] = 1.0 + 1e-12  # every uniform draw falls inside the last outcome
        init_cdf = np.cumsum(init)
        init_cdf[-1] = 1.0 + 1e-12
        max_steps = getattr(env, "max_steps", None) or 0
        return cls(cdf, out_next, out_reward, out_term, init_cdf, int(max_steps))


def _check_tables(
    name: str, prob: np.ndarray, out_next: np.ndarray, out_reward: np.ndarray, n_states: int
) -> None:
    """Refuse tables the compiled loop would run wrong: it reads them without checks.

    Raises:
        ValueError: a reward that is not finite (the Python path raises when it meets one; the
            compiled path checks every entry once, before it runs), a probability that is not a
            number in [0, 1], outcomes of a (state, action) that do not sum to 1, or a next state
            outside the observation space. The message names the first bad entry.
    """
    problems = (
        (~np.isfinite(out_reward), "a non-finite reward", out_reward),
        (~np.isfinite(prob) | (prob < 0) | (prob > 1), "a probability outside [0, 1]", prob),
        (
            (out_next < 0) | (out_next >= n_states),
            f"a next state outside 0..{n_states - 1}",
            out_next,
        ),
    )
    for bad, what, values in problems:
        if bad.any():
            s, a, k = (int(i) for i in np.argwhere(bad)[0])
            raise ValueError(
                f"{name}.P[{s}][{a}][{k}] holds {what} ({values[s, a, k].item()!r}): the compiled path "
                "refuses tables it would run wrong"
            )
    totals = prob.sum(axis=2)
    off = np.abs(totals - 1.0) > 1e-6
    if off.any():
        s, a = (int(i) for i in np.argwhere(off)[0])
        raise ValueError(
            f"{name}.P[{s}][{a}]'s probabilities sum to {totals[s, a].item()!r}, not 1"
        )


def inspect_stack(env: gym.Env, tables: bool = True) -> tuple[TabularModel, RewardDelay | None]:
    """Split ``env`` into its compiled model and its reward-delay wrapper (or ``None``).

    The model's ``max_steps`` and ``cut_steps`` include the stack's ``TimeLimit`` wrappers (see
    ``docs/compiled.md``). With ``tables=False`` the env's own tables are not read (an env the
    compiled loop steps itself, :mod:`delayed_rl.compiled.robot`): the model's are empty.

    Raises:
        NotCompilable: if a wrapper or the env itself is outside the protocol.
    """
    delay_wrapper = None
    above, below = [], []  # the TimeLimits above the RewardDelay, and those below it
    layer = env
    while isinstance(layer, gym.Wrapper):
        if isinstance(layer, RewardDelay):
            if delay_wrapper is not None:
                raise NotCompilable("more than one RewardDelay wrapper")
            delay_wrapper = layer
        elif isinstance(layer, gym.wrappers.TimeLimit):
            (below if delay_wrapper is not None else above).append(_time_limit(layer))
        elif not isinstance(layer, TRANSPARENT_WRAPPERS):
            raise NotCompilable(f"wrapper {type(layer).__name__} is not supported")
        layer = layer.env
    model = TabularModel.from_env(layer) if tables else TabularModel.empty()
    if delay_wrapper is None:  # nothing is pending: every limit ends the episode alike
        below, above = below + above, []
    inner = min([model.max_steps or math.inf, *below])
    outer = min(above, default=math.inf)
    return model._replace(
        max_steps=0 if inner == math.inf else int(inner),
        cut_steps=int(outer) if outer < inner else 0,
    ), delay_wrapper


def _time_limit(layer: gym.wrappers.TimeLimit) -> int:
    """The episode length ``layer`` truncates at.

    Raises:
        NotCompilable: it is not a positive integer (the compiled loop counts steps in int64).
    """
    limit = getattr(layer, "_max_episode_steps", None)
    if isinstance(limit, (bool, np.bool_)) or not isinstance(limit, (int, np.integer)) or limit < 1:
        raise NotCompilable(f"TimeLimit with max_episode_steps={limit!r} (not an integer >= 1)")
    return int(limit)
