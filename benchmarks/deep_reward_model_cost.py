"""What a deep reward model costs SB3's SAC, measured in one run: SAC alone against SAC with it.

Each repeat trains, one after the other (so machine noise hits all alike, and the order turns
each repeat), fresh SAC agents with SB3's defaults for ``--steps`` steps of Pendulum-v1 under
Poisson(20) reward delays flushed at the episode's end, each starting to learn after
``--learning-starts`` steps (the ``deep-rl`` experiment's warm-up, two 200-step episodes):

- SAC alone, on the delayed rewards (SB3's own replay buffer);
- SAC with a :class:`~delayed_rl.deep.RelabelingReplayBuffer` and each reward model with its
  defaults: deconvolution with ``p`` known, with ``p`` learned on ``0..60``, RRD and the return
  regression;
- SAC with an :class:`~delayed_rl.deep.IRCRReplayBuffer` (IRCR has no model: the buffer
  relabels).

A whole ``learn()`` is timed (the env steps, SAC's updates, the model's training and the
relabelling of every sampled batch). Torch runs on one thread. Reported: seconds per run (min,
median, max over the repeats) and each repeat's ratio to SAC alone (min, median, max). Target:
every reward model ≤ 1.3 × SAC alone.

    python benchmarks/deep_reward_model_cost.py [--steps 3000] [--repeats 3]
        [--learning-starts 400] [--models NAME ...]

``--models`` times only the methods named (SAC alone is always timed, as the reference):
``known``, ``learned``, ``rrd``, ``return-regression``, ``ircr``.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym

from delayed_rl.delays import Poisson
from delayed_rl.wrappers import RewardDelay

TARGET = 1.3
DELAY = Poisson(20)
REFERENCE = "SAC alone"
SHORT_NAMES = {
    "known": "deconvolution, p known",
    "learned": "deconvolution, p learned",
    "rrd": "RRD",
    "return-regression": "return regression",
    "ircr": "IRCR",
}
"""``--models``'s names for the methods."""


def _env() -> gym.Env:
    return RewardDelay(gym.make("Pendulum-v1"), DELAY, on_episode_end="flush")


def _buffer_options() -> dict[str, Callable[[gym.Env], dict[str, Any]]]:
    """Each run's SAC buffer settings, made for an env."""
    from delayed_rl.deep import (
        DeconvolutionRewardModel,
        IRCRReplayBuffer,
        RelabelingReplayBuffer,
        ReturnDecompositionRewardModel,
        ReturnRegressionRewardModel,
    )

    def relabeling(model_class: type, **settings: Any) -> Callable[[gym.Env], dict[str, Any]]:
        def options(env: gym.Env) -> dict[str, Any]:
            model = model_class(env.observation_space, env.action_space, seed=0, **settings)
            return {
                "replay_buffer_class": RelabelingReplayBuffer,
                "replay_buffer_kwargs": {"reward_model": model},
            }

        return options

    return {
        REFERENCE: lambda env: {},
        SHORT_NAMES["known"]: relabeling(DeconvolutionRewardModel, delay=DELAY),
        SHORT_NAMES["learned"]: relabeling(
            DeconvolutionRewardModel, delay=None, max_delay_estimate=60
        ),
        SHORT_NAMES["rrd"]: relabeling(ReturnDecompositionRewardModel),
        SHORT_NAMES["return-regression"]: relabeling(ReturnRegressionRewardModel),
        SHORT_NAMES["ircr"]: lambda env: {"replay_buffer_class": IRCRReplayBuffer},
    }


def time_run(
    buffer_options: Callable[[gym.Env], dict[str, Any]], steps: int, learning_starts: int
) -> float:
    """Seconds of one fresh SAC's ``learn(steps)``, with the buffer ``buffer_options`` sets."""
    from stable_baselines3 import SAC

    env = _env()
    options = buffer_options(env)
    agent = SAC("MlpPolicy", env, seed=0, device="cpu", learning_starts=learning_starts, **options)
    start = time.perf_counter()
    agent.learn(steps)
    return time.perf_counter() - start


def _spread(values: list[float], digits: int = 2) -> str:
    return (
        f"{min(values):.{digits}f}–{statistics.median(values):.{digits}f}–{max(values):.{digits}f}"
    )


def main() -> None:
    """Run the repeats and print the table (markdown)."""
    import torch

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--learning-starts", type=int, default=400)
    parser.add_argument("--models", nargs="+", choices=list(SHORT_NAMES), default=list(SHORT_NAMES))
    args = parser.parse_args()
    torch.set_num_threads(1)
    runs = _buffer_options()
    names = [REFERENCE] + [SHORT_NAMES[short] for short in dict.fromkeys(args.models)]
    seconds: dict[str, list[float]] = {name: [] for name in names}
    for repeat in range(args.repeats):
        turn = repeat % len(names)
        for name in names[turn:] + names[:turn]:
            seconds[name].append(time_run(runs[name], args.steps, args.learning_starts))
    print(
        f"SAC on Pendulum-v1 with Poisson(20) reward delays, {args.steps} steps, learning from "
        f"step {args.learning_starts}, torch {torch.__version__} on 1 thread; "
        f"min–median–max of {args.repeats} interleaved repeats\n"
    )
    print("| run | seconds | ratio to SAC alone | target ≤ 1.3 in every repeat |")
    print("|---|---|---|---|")
    for name in names:
        ratios = [s / alone for s, alone in zip(seconds[name], seconds[REFERENCE], strict=True)]
        verdict = "" if name == REFERENCE else ("ok" if max(ratios) <= TARGET else "MISSED")
        print(f"| {name} | {_spread(seconds[name])} | {_spread(ratios)} | {verdict} |")


if __name__ == "__main__":
    main()
