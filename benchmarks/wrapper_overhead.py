"""Per-step cost of the reward-delay wrapper against Gymnasium's RecordEpisodeStatistics.

Runs GridWorld-9x9 bare, under ``RecordEpisodeStatistics`` and under ``PoissonRewardDelay(λ=13)``
in one process, interleaving repeats so machine noise hits all three alike (each cost is the
fastest repeat, the least disturbed by other processes), and prints the
per-step cost, each wrapper's overhead over the bare env, and the ratio of the two overheads
(target: at most 1.5).

The ratio is a quotient of two small differences (about 0.2 and 0.3 µs on a 2 µs step), so a
1 % wobble of one timing moves it by 0.1 or more: besides the ratio of the fastest repeats it is
computed within each repeat (the three stacks timed back to back) and reported as the median and
range of those.

    python benchmarks/wrapper_overhead.py [--steps 200000] [--repeats 11]
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


def measure(steps: int, repeats: int) -> tuple[dict[str, float], list[float]]:
    """Fastest seconds per step of each stack, and the overhead ratio within each repeat."""
    actions = np.random.default_rng(0).integers(0, 4, steps).tolist()
    stacks = make_stacks()
    samples: dict[str, list[float]] = {name: [] for name in stacks}
    for _ in range(repeats):
        for name, env in stacks.items():
            samples[name].append(time_steps(env, actions))
    per_repeat = [
        overhead_ratio({name: values[i] for name, values in samples.items()})
        for i in range(repeats)
    ]
    return {name: min(values) for name, values in samples.items()}, per_repeat


def overhead_ratio(cost: dict[str, float]) -> float:
    """The delay wrapper's overhead over the bare env, in units of RecordEpisodeStatistics'."""
    bare = cost["bare"]
    return (cost["PoissonRewardDelay(13)"] - bare) / (cost["RecordEpisodeStatistics"] - bare)


def summary(cost: dict[str, float], per_repeat: list[float]) -> str:
    """One line: the ratio of the fastest repeats, and the median and range within repeats."""
    low, median, high = np.percentile(per_repeat, [0, 50, 100])
    return (
        f"Overhead ratio PoissonRewardDelay / RecordEpisodeStatistics: "
        f"{overhead_ratio(cost):.2f} (fastest repeats), median {median:.2f} within repeats "
        f"(range {low:.2f}–{high:.2f}); target ≤ 1.5"
    )


def main() -> None:
    """Time the three stacks and print their costs, overheads and the overhead ratio."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=11)
    args = parser.parse_args()
    cost, per_repeat = measure(args.steps, args.repeats)
    bare = cost["bare"]
    print(f"{'stack':<26}{'µs/step':>10}{'overhead µs':>14}")
    for name, value in cost.items():
        print(f"{name:<26}{value * 1e6:>10.3f}{(value - bare) * 1e6:>14.3f}")
    print("\n" + summary(cost, per_repeat))


if __name__ == "__main__":
    main()
