"""Per-step cost of the reward-delay wrapper against Gymnasium's RecordEpisodeStatistics.

Runs GridWorld-9x9 bare, under ``RecordEpisodeStatistics`` and under ``PoissonRewardDelay(λ=13)``
in one process, interleaving repeats so machine noise hits all three alike (each cost is the
fastest repeat, the least disturbed by other processes), and prints the
per-step cost, each wrapper's overhead over the bare env, and the ratio of the two overheads
(target: at most 1.5).

    python benchmarks/wrapper_overhead.py [--steps 200000] [--repeats 7]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

from delayed_rl.envs.gridworld import GridWorldEnv
from delayed_rl.wrappers import PoissonRewardDelay


def make_stacks() -> dict[str, gym.Env]:
    """The three stacks, each on its own GridWorld-9x9 (``max_steps`` gives episode ends)."""
    return {
        "bare": GridWorldEnv(size=9, max_steps=1000),
        "RecordEpisodeStatistics": gym.wrappers.RecordEpisodeStatistics(
            GridWorldEnv(size=9, max_steps=1000)
        ),
        "PoissonRewardDelay(13)": PoissonRewardDelay(GridWorldEnv(size=9, max_steps=1000), 13),
    }


def time_steps(env: gym.Env, actions: list[int]) -> float:
    """Seconds per step over ``actions``, resetting at episode ends."""
    env.reset(seed=0)
    step, reset = env.step, env.reset
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = step(action)
        if terminated or truncated:
            reset()
    return (time.perf_counter() - start) / len(actions)


def measure(steps: int, repeats: int) -> dict[str, float]:
    """Fastest seconds per step of each stack (the least disturbed of interleaved repeats)."""
    actions = np.random.default_rng(0).integers(0, 4, steps).tolist()
    stacks = make_stacks()
    samples: dict[str, list[float]] = {name: [] for name in stacks}
    for _ in range(repeats):
        for name, env in stacks.items():
            samples[name].append(time_steps(env, actions))
    return {name: min(values) for name, values in samples.items()}


def overhead_ratio(cost: dict[str, float]) -> float:
    """The delay wrapper's overhead over the bare env, in units of RecordEpisodeStatistics'."""
    bare = cost["bare"]
    return (cost["PoissonRewardDelay(13)"] - bare) / (cost["RecordEpisodeStatistics"] - bare)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    cost = measure(args.steps, args.repeats)
    bare = cost["bare"]
    print(f"{'stack':<26}{'µs/step':>10}{'overhead µs':>14}")
    for name, value in cost.items():
        print(f"{name:<26}{value * 1e6:>10.3f}{(value - bare) * 1e6:>14.3f}")
    ratio = overhead_ratio(cost)
    print(
        f"\noverhead ratio PoissonRewardDelay / RecordEpisodeStatistics = {ratio:.2f} (target <= 1.5)"
    )


if __name__ == "__main__":
    main()
