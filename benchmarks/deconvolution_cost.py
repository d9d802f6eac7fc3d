"""What deconvolution Q-learning costs beside MMQ, on the compiled path, measured in one run.

Each repeat trains fresh agents for ``--steps`` steps of ``GridWorld-9x9`` with Poisson(13)
reward delays — MMQ with |Λ| = 51 (the thesis's λ̂max = 50), ``DeconvQ`` with the delay learned on
``0..50``, and ``DeconvQ`` told the delay — one after the other, so machine noise hits all alike.
A whole run is timed, solves included (``DeconvQ`` solves after 1000, 2000, 4000, ... steps and
then every 20,000), from a fresh agent whose compiled code is already loaded. Reported: seconds
per run (min, median, max over the repeats) and the ratio to MMQ of each repeat (min, median,
max). Target: learned-delay ``DeconvQ`` ≤ 3 × MMQ.

    python benchmarks/deconvolution_cost.py [--steps 1000000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import gymnasium as gym

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl.agents import DeconvolutionQLearning, MultipleModelQLearning, TabularAgent

LAM = 13


def _env() -> gym.Env:
    return gym.make("delayed_rl/GridWorld-9x9-v0", reward_delay=LAM)


FACTORIES: dict[str, Callable[[], TabularAgent]] = {
    "MMQ, 51 models": lambda: MultipleModelQLearning(
        _env(), max_delay_estimate=50, q_init=25.0, seed=1
    ),
    "DeconvQ, delay learned": lambda: DeconvolutionQLearning(
        _env(), max_delay_estimate=50, q_init=25.0, seed=1
    ),
    "DeconvQ, delay known": lambda: DeconvolutionQLearning(
        _env(), delay=float(LAM), q_init=25.0, seed=1
    ),
}


def time_run(make: Callable[[], TabularAgent], steps: int) -> float:
    """Seconds of one fresh agent's compiled ``learn(steps)``."""
    agent = make()
    start = time.perf_counter()
    agent.learn(steps, log_interval=None)
    elapsed = time.perf_counter() - start
    assert agent.last_learn_path == "compiled"
    return elapsed


def _spread(values: list[float]) -> str:
    return f"{min(values):.3f} / {statistics.median(values):.3f} / {max(values):.3f}"


def main() -> None:
    """Run the interleaved repeats and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    for make in FACTORIES.values():  # load the compiled code once before timing
        make().learn(5_000)
    seconds: dict[str, list[float]] = {name: [] for name in FACTORIES}
    for _ in range(args.repeats):
        for name, make in FACTORIES.items():
            seconds[name].append(time_run(make, args.steps))
    reference = seconds["MMQ, 51 models"]
    print(f"GridWorld-9x9, Poisson({LAM}), {args.steps:,} steps, {args.repeats} repeats")
    print("| agent | seconds per run (min / median / max) | ratio to MMQ (min / median / max) |")
    print("|---|---|---|")
    for name, values in seconds.items():
        ratios = [value / ref for value, ref in zip(values, reference, strict=True)]
        print(f"| {name} | {_spread(values)} | {_spread(ratios)} |")


if __name__ == "__main__":
    main()
