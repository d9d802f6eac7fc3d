"""Thesis-setting training runs on the grid worlds, through the agents' ``learn()``.

The thesis's hyper-parameters (section 3.2, Algorithm 1): α = 0.1, γ = 0.9, ε-greedy with a
constant ε. The thesis does not state ε nor its optimistic initial value for the grid worlds;
we use ε = 0.1 and ``q_init`` = 25. Optimistic means above every value the estimates will
reach, and MMQ's estimates do not converge to the true values (V* ≈ 2.2 on 9×9): the max over
all models in every target inflates them, to ≈ 21.4 along the route in the thesis's Table 5.1
(≈ 18 in ours). A sensitivity check (seeds 0–4, 1M steps, greedy reward over 1000 steps) is
in ``benchmarks/REPORT.md``.
On these tabular envs ``learn()`` takes its compiled path (:mod:`delayed_rl.compiled`).
"""

from __future__ import annotations

import gymnasium as gym

from delayed_rl._validation import check_int
from delayed_rl.agents import MultipleModelQLearning
from delayed_rl.agents.common.q_table import greedy_actions

#: The thesis's α and γ (Algorithm 1), the constant ε and the grid worlds' optimistic q_init.
ALPHA, GAMMA, EPSILON, Q_INIT = 0.1, 0.9, 0.1, 25.0


def hyperparameter_text(q_init: float = Q_INIT) -> str:
    """The thesis's hyper-parameters as the descriptions write them: ``α = 0.1, ..., q_init = 25``."""
    return f"α = {ALPHA}, γ = {GAMMA}, ε = {EPSILON}, q_init = {q_init:g}"


def grid_env(size: int, lam: float) -> gym.Env:
    """``delayed_rl/GridWorld-v0`` of side ``size`` with Poisson(``lam``) delays (none if 0)."""
    import delayed_rl  # noqa: F401  (registers the ids)

    return gym.make("delayed_rl/GridWorld-v0", size=size, reward_delay=lam if lam > 0 else None)


def thesis_hyperparameters(seed: int, q_init: float = Q_INIT) -> dict[str, float | int]:
    """The thesis's Algorithm 1 hyper-parameters as agent keywords: α, γ, constant ε, seeded.

    Args:
        seed: the agent's seed.
        q_init: the optimistic initial value (default :data:`Q_INIT`, the grid worlds').
    """
    return {
        "learning_rate": ALPHA,
        "gamma": GAMMA,
        "exploration_initial_eps": EPSILON,
        "exploration_final_eps": EPSILON,
        "q_init": q_init,
        "seed": seed,
    }


def train(
    env: gym.Env, delay_estimates: list[int], steps: int, seed: int
) -> MultipleModelQLearning:
    """Train MMQ with ``delay_estimates`` Λ (``[0]``: Q-learning; ``[k]``: fixed delay k).

    The agent's ``training_log`` holds the per-step record (``undelayed_reward``, ``obs``, ...).
    """
    agent = MultipleModelQLearning(
        env, delay_estimates=list(delay_estimates), **thesis_hyperparameters(seed)
    )
    return agent.learn(steps, log_interval=None, record=True)


def greedy_average_reward(agent: MultipleModelQLearning, size: int, steps: int = 1000) -> float:
    """Average reward of the deterministic greedy policy over ``steps`` from the start cell.

    Args:
        agent: the trained agent; only its ``q_table`` is read.
        size: the side of the undelayed grid world to walk.
        steps: how many steps to walk.
    """
    check_int("steps", steps, 1)
    env = grid_env(size, 0).unwrapped
    env.reset(seed=0)
    state, total = env.start_state, 0.0
    policy = greedy_actions(agent.q_table)
    for _ in range(steps):
        state, reward, *_ = env.step(int(policy[state]))
        total += reward
    return total / steps
