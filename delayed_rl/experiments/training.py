"""Thesis-setting training runs on the grid worlds, on the compiled path.

The thesis's hyper-parameters (section 3.2, Algorithm 1): α = 0.1, γ = 0.9, ε-greedy with a
constant ε. The thesis does not state ε nor its optimistic initial value for the grid worlds;
we use ε = 0.1 and ``q_init`` = 10 (above every true value, V* ≈ 2.2 on 9×9, so optimistic).
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from delayed_rl.fast import FusedRun

ALPHA, GAMMA, EPSILON, Q_INIT = 0.1, 0.9, 0.1, 10.0
CHUNK = 250_000


@dataclass
class TabularRun:
    """The outcome of a training run: the Q-table and the per-step record."""

    q: np.ndarray
    undelayed_reward: np.ndarray
    obs: np.ndarray
    model: np.ndarray
    fused: FusedRun


def grid_env(size: int, lam: float) -> gym.Env:
    """``delayed_rl/GridWorld-v0`` of side ``size`` with Poisson(``lam``) delays (none if 0)."""
    import delayed_rl  # noqa: F401  (registers the ids)

    return gym.make("delayed_rl/GridWorld-v0", size=size, reward_delay=lam if lam > 0 else None)


def train(
    env: gym.Env, lags: np.ndarray | list[int], steps: int, seed: int, q_init: float = Q_INIT,
    epsilon: float = EPSILON,
) -> TabularRun:  # fmt: skip
    """Train an MMQ agent with delay estimates ``lags`` (``[0]``: Q-learning; ``[k]``: fixed)."""
    lags = np.asarray(lags, dtype=np.int64)
    n_states, n_actions = env.observation_space.n, env.action_space.n
    q = np.full((n_states, lags.size, n_actions), float(q_init))
    qmax = np.full(n_states, float(q_init))
    qarg_l = np.zeros(n_states, dtype=np.int64)
    qarg_a = np.zeros(n_states, dtype=np.int64)
    fused = FusedRun(env, lags, seed)
    logs = []
    for start in range(0, steps, CHUNK):
        n = min(CHUNK, steps - start)
        logs.append(fused.run(q, qmax, qarg_l, qarg_a, n, start, ALPHA, GAMMA, epsilon, epsilon, 1))
    cat = {key: np.concatenate([log[key] for log in logs]) for key in logs[0]}
    fused.cache = (qmax, qarg_l, qarg_a)
    return TabularRun(q, cat["undelayed_reward"], cat["obs"], cat["model"], fused)


def greedy_average_reward(run: TabularRun, steps: int = 1000) -> float:
    """Average reward of the greedy policy (ε = 0, no learning) from the start state."""
    qmax, qarg_l, qarg_a = (array.copy() for array in run.fused.cache)
    q = run.q.copy()
    run.fused.state[:] = [run.fused.model.init_cdf.searchsorted(0.5, side="right"), 0, 0, 0]
    run.fused.buffer[:] = 0.0
    log = run.fused.run(q, qmax, qarg_l, qarg_a, steps, 0, 0.0, GAMMA, 0.0, 0.0, 1)
    return float(log["undelayed_reward"].mean())


def greedy_policy(q: np.ndarray) -> np.ndarray:
    """The deterministic policy: per state, the action of the best (model, action) entry."""
    flat = q.reshape(q.shape[0], -1)
    return flat.argmax(axis=1) % q.shape[2]
