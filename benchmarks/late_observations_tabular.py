"""Q-learning on the delay-aware view's index against Q-learning on the delayed stream.

On the thesis's 5×5 grid world (optimal average reward 10/9 ≈ 1.11 a step), observations
delayed by the stale-sensor rule and actions delayed too, Q-learning (α = 0.1, γ = 0.9,
ε = 0.1, ``q_init`` 10, the Python loop) learns for ``--steps`` steps:

- **plain**: on the delayed stream's ``Discrete`` observations, as it comes;
- **view**: on :class:`~delayed_rl.wrappers.DiscreteDelayAwareObservation`, the index of
  (newest observation, its age, the last K actions sent).

Each is scored by its greedy policy's mean reward over ``--eval-steps`` steps of the same
delayed env (seeded per seed). Reported per setting: the number of states each learns over,
and the score per seed and its mean over ``--seeds`` seeds. The settings:

- observation delay U{0..2}, action delay 1 (K = 3);
- observation delay U{0..3}, action delay U{0..2} (K = 5).

    python benchmarks/late_observations_tabular.py [--steps 200000] [--seeds 5]
"""

from __future__ import annotations

import argparse
import statistics

import gymnasium as gym

import delayed_rl  # noqa: F401  (registers the grid worlds)
from delayed_rl.agents import QLearning
from delayed_rl.delays import Constant, Uniform
from delayed_rl.wrappers import (
    ActionDelay,
    DelayAwareObservation,
    DiscreteDelayAwareObservation,
    ObservationDelay,
)

SETTINGS = {
    "observation U{0..2}, action 1": (Uniform(0, 2), Constant(1)),
    "observation U{0..3}, action U{0..2}": (Uniform(0, 3), Uniform(0, 2)),
}
OPTIMUM = 10 / 9


def make(setting: str, method: str) -> gym.Env:
    """The grid world under the setting's delays, as ``method`` observes it."""
    observation_delay, action_delay = SETTINGS[setting]
    env = gym.make("delayed_rl/GridWorld-5x5-v0")
    env = ObservationDelay(ActionDelay(env, action_delay), observation_delay)
    if method == "view":
        env = DiscreteDelayAwareObservation(DelayAwareObservation(env))
    return env


def score(agent: QLearning, env: gym.Env, steps: int, seed: int) -> float:
    """The greedy policy's mean reward a step over ``steps`` steps of ``env``."""
    obs, _ = env.reset(seed=seed)
    total = 0.0
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(agent.predict(obs, deterministic=True)[0])
        total += float(reward)
        if terminated or truncated:
            obs, _ = env.reset()
    return total / steps


def main() -> None:
    """Train both methods in every setting and print the table (markdown)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200_000)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--eval-steps", type=int, default=10_000)
    args = parser.parse_args()
    print(
        f"5×5 grid world, Q-learning for {args.steps} steps, greedy reward a step over "
        f"{args.eval_steps} steps (optimum {OPTIMUM:.2f}); seeds 0–{args.seeds - 1}\n"
    )
    print("| setting | observed as | states | score per seed | mean |")
    print("|---|---|---|---|---|")
    for setting in SETTINGS:
        for method in ("plain", "view"):
            env = make(setting, method)
            scores = []
            for seed in range(args.seeds):
                agent = QLearning(env, q_init=10.0, seed=seed).learn(args.steps, compiled=False)
                scores.append(score(agent, make(setting, method), args.eval_steps, 10_000 + seed))
            states = env.observation_space.n
            shown = ", ".join(f"{value:.2f}" for value in scores)
            print(
                f"| {setting} | {method} | {states:,} | {shown} | {statistics.mean(scores):.2f} |"
            )


if __name__ == "__main__":
    main()
