"""Deconvolution Q-learning on Gymnasium's own tabular envs, beside Q-learning, Python path.

Each env (``Taxi-v4``, ``CliffWalking-v1``, ``FrozenLake-v1``, as ``gym.make`` builds them) gets
Poisson(``--reward-delay``) reward delays from :class:`~delayed_rl.wrappers.PoissonRewardDelay` (pending
rewards flushed at episode ends, the wrapper's default). Per seed it trains:

- ``Q``: Q-learning on the delayed reward;
- ``DeconvQ``: deconvolution Q-learning, the delay learned on ``0..--max-delay-estimate``;
- ``Q undelayed``: Q-learning without delays (the reference).

All with the library's default hyper-parameters (α = 0.1, γ = 0.9, ε = 0.1, ``q_init`` = 0) and
``learn(..., compiled=False)``: the Python path, the one that runs any ``Discrete`` env. The score
is the greedy policy's mean undelayed return over 100 episodes (reset seeds 0..99) of the plain
env, each cut at 200 steps (CliffWalking has no time limit of its own; a policy that loops
scores −200 there). Reported: the mean over seeds with its 95 % CI (Student t), each seed's
score, and seconds per run.

    python benchmarks/deconvolution_third_party.py [--seeds 3] [--reward-delay 5] [--max-delay-estimate 20]
        [--env Taxi-v4:1000000 --env CliffWalking-v1:500000 --env FrozenLake-v1:200000]
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

from delayed_rl.agents import DeconvolutionQLearning, QLearning, TabularAgent
from delayed_rl.parallel.intervals import mean_ci95
from delayed_rl.wrappers import PoissonRewardDelay

DEFAULT_ENVS = ("Taxi-v4:1000000", "CliffWalking-v1:500000", "FrozenLake-v1:200000")
EPISODES, EPISODE_CAP = 100, 200


def greedy_return(agent: TabularAgent, env_id: str) -> float:
    """The greedy policy's mean return over :data:`EPISODES` capped episodes of the plain env."""
    env = gym.make(env_id)
    policy = agent.predict(np.arange(env.observation_space.n), deterministic=True)[0]
    returns = []
    for episode in range(EPISODES):
        obs, _ = env.reset(seed=episode)
        total, done, steps = 0.0, False, 0
        while not done and steps < EPISODE_CAP:
            obs, reward, terminated, truncated, _ = env.step(int(policy[obs]))
            total += float(reward)
            done, steps = terminated or truncated, steps + 1
        returns.append(total)
    return float(np.mean(returns))


def make_agent(
    name: str, env_id: str, lam: float, max_delay_estimate: int, seed: int
) -> TabularAgent:
    """One of the three agents on its own env."""
    if name == "Q undelayed":
        return QLearning(gym.make(env_id), seed=seed)
    env = PoissonRewardDelay(gym.make(env_id), lam)
    if name == "Q":
        return QLearning(env, seed=seed)
    return DeconvolutionQLearning(env, max_delay_estimate=max_delay_estimate, seed=seed)


def main() -> None:
    """Train every agent on every env and seed; print one table per env."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--reward-delay", type=float, default=5.0, metavar="λ")
    parser.add_argument("--max-delay-estimate", type=int, default=20)
    parser.add_argument("--env", action="append", help="ENV_ID:STEPS (repeatable)")
    args = parser.parse_args()
    for spec in args.env or DEFAULT_ENVS:
        env_id, steps = spec.split(":")
        print(f"\n{env_id}, Poisson({args.reward_delay:g}) delays, {int(steps):,} steps, "
              f"seeds 0..{args.seeds - 1}, greedy return over {EPISODES} episodes")  # fmt: skip
        print("| agent | mean ± 95% CI | per seed | seconds per run |")
        print("|---|---|---|---|")
        for name in ("Q", "DeconvQ", "Q undelayed"):
            scores, seconds = [], []
            for seed in range(args.seeds):
                agent = make_agent(name, env_id, args.reward_delay, args.max_delay_estimate, seed)
                started = time.perf_counter()
                agent.learn(int(steps), log_interval=None, compiled=False)
                seconds.append(time.perf_counter() - started)
                scores.append(greedy_return(agent, env_id))
            mean, ci = mean_ci95(scores)
            shown = ", ".join(f"{s:.2f}" for s in scores)
            print(f"| {name} | {mean:.2f} ± {ci:.2f} | {shown} | {statistics.median(seconds):.0f} |",
                  flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
