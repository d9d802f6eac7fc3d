"""Per-step cost of the reward-delay wrapper against Gymnasium's RecordEpisodeStatistics.

Runs GridWorld-9x9 bare (the floor), under ``RecordEpisodeStatistics`` and under
``PoissonRewardDelay(λ=13)`` in one process and prints the per-step cost of each, each wrapper's
overhead over the bare env, and the ratio of the two overheads (target: at most 1.5 in every
repeat).

The ratio is a quotient of two small differences (a few tenths of a µs on a step of under a µs),
so a 1 % wobble of one timing moves it by 0.1 or more. A repeat is therefore ``--rounds`` rounds,
each timing the three stacks once, back to back, with the garbage collector off (as ``timeit``
does). A repeat's cost of a stack is its fastest round (the one least disturbed by other
processes); its ratio is the median over its rounds of each round's ratio, whose three timings
were taken back to back and so were slowed alike (as ``agent_step_cost.py`` pairs its timings).
Ratios of the stacks' separate fastest rounds pair timings from different moments: on this
shared machine one repeat's bare env ran slow in all its rounds and such a ratio came out at
0.41, less than the wrapper's own work allows. Figures are min–median–max over the repeats,
beside the floor (the bare env's cost) measured in the same run; a first round warms up.

    python benchmarks/wrapper_overhead.py [--steps 10000] [--rounds 15] [--repeats 11]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
from interleaved import Repeat, fastest, interleave, seconds_per_step, shown, spread, target_summary

from delayed_rl.envs.gridworld import GridWorldEnv
from delayed_rl.wrappers import PoissonRewardDelay

TARGET = 1.5
"""The most the delay wrapper's overhead may be, in units of RecordEpisodeStatistics'."""


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
    """Seconds per step over ``actions``, resetting at episode ends (garbage collector off)."""
    env.reset(seed=0)
    step, reset = env.step, env.reset

    def run() -> None:
        for action in actions:
            _, _, terminated, truncated, _ = step(action)
            if terminated or truncated:
                reset()

    return seconds_per_step(run, len(actions))


def measure(steps: int, repeats: int, rounds: int = 15) -> list[Repeat]:
    """Seconds per step of each stack in each round, one dict per repeat.

    A round times the three stacks once each, back to back (garbage collector off).
    """
    actions = np.random.default_rng(0).integers(0, 4, steps).tolist()
    stacks = make_stacks()
    for env in stacks.values():  # warm-up
        time_steps(env, actions)
    timed = {name: lambda env=env: time_steps(env, actions) for name, env in stacks.items()}
    return interleave(timed, repeats, rounds)


def overhead_ratio(cost: dict[str, float]) -> float:
    """The delay wrapper's overhead over the bare env, in units of RecordEpisodeStatistics'."""
    bare = cost["bare"]
    return (cost["PoissonRewardDelay(13)"] - bare) / (cost["RecordEpisodeStatistics"] - bare)


def repeat_ratio(repeat: Repeat) -> float:
    """A repeat's overhead ratio: the median over its rounds of each round's ratio."""
    rounds = len(next(iter(repeat.values())))
    ratios = [
        overhead_ratio({name: times[i] for name, times in repeat.items()}) for i in range(rounds)
    ]
    return float(np.median(ratios))


def cost_rows(repeats: list[Repeat]) -> list[tuple[str, str, str]]:
    """Per stack: its name, its µs/step and its overhead over the bare env, each min–median–max.

    A repeat's figure is its fastest round's.
    """
    best = [fastest(r) for r in repeats]
    rows = []
    for name in best[0]:
        cost = [r[name] * 1e6 for r in best]
        overhead = [(r[name] - r["bare"]) * 1e6 for r in best]
        rows.append((name, shown(spread(cost), 3), shown(spread(overhead), 3)))
    return rows


def summary(repeats: list[Repeat]) -> str:
    """One line: the overhead ratio within each repeat (min–median–max) beside the floor."""
    ratios = [repeat_ratio(r) for r in repeats]
    what = "Overhead ratio PoissonRewardDelay / RecordEpisodeStatistics:"
    return target_summary(what, ratios, TARGET, repeats, "bare", "the bare env", floor_digits=3)


def main() -> None:
    """Time the three stacks and print their costs, overheads and the overhead ratio."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=10_000, help="steps per timing")
    parser.add_argument(
        "--rounds",
        type=int,
        default=15,
        help="rounds per repeat (costs: the fastest; ratio: the median)",
    )
    parser.add_argument("--repeats", type=int, default=11, help="repeats")
    args = parser.parse_args()
    repeats = measure(args.steps, args.repeats, args.rounds)
    print(f"{'stack':<26}{'µs/step':>22}{'overhead µs':>22}")
    for name, cost, overhead in cost_rows(repeats):
        print(f"{name:<26}{cost:>22}{overhead:>22}")
    print("(min–median–max over repeats)\n\n" + summary(repeats))


if __name__ == "__main__":
    main()
