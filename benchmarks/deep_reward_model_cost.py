"""What a deep reward model costs SB3's SAC, measured in one run: SAC alone against SAC with it.

Each repeat trains, one after the other (so machine noise hits all alike, and the order turns
each repeat), fresh SAC agents with SB3's defaults for ``--steps`` steps of Pendulum-v1 under
Poisson(20) reward delays flushed at the episode's end:

- SAC alone, on the delayed rewards (SB3's own replay buffer);
- SAC with a :class:`~delayed_rl.deep.RelabelingReplayBuffer` and each reward model with its
  defaults: deconvolution with ``p`` known, with ``p`` learned on ``0..60``, RRD and IRCR.

A whole ``learn()`` is timed (the env steps, SAC's updates, the model's training and the
relabelling of every sampled batch). Torch runs on one thread. Reported: seconds per run (min,
median, max over the repeats) and each repeat's ratio to SAC alone (min, median, max). Target:
every reward model ≤ 1.3 × SAC alone.

    python benchmarks/deep_reward_model_cost.py [--steps 3000] [--repeats 3] [--models NAME ...]

``--models`` times only the reward models named (SAC alone is always timed, as the reference):
``known``, ``learned``, ``rrd``, ``ircr``.
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
    "ircr": "IRCR",
}
"""``--models``'s names for the reward models."""


def _env() -> gym.Env:
    return RewardDelay(gym.make("Pendulum-v1"), DELAY, on_episode_end="flush")


def _models() -> dict[str, Callable[[gym.Env], Any] | None]:
    from delayed_rl.deep import (
        DeconvolutionRewardModel,
        IRCRRewardModel,
        ReturnDecompositionRewardModel,
    )

    def spaces(env: gym.Env) -> tuple:
        return env.observation_space, env.action_space

    return {
        REFERENCE: None,
        SHORT_NAMES["known"]: lambda env: DeconvolutionRewardModel(
            *spaces(env), delay=DELAY, seed=0
        ),
        SHORT_NAMES["learned"]: lambda env: DeconvolutionRewardModel(
            *spaces(env), delay=None, max_delay_estimate=60, seed=0
        ),
        SHORT_NAMES["rrd"]: lambda env: ReturnDecompositionRewardModel(*spaces(env), seed=0),
        SHORT_NAMES["ircr"]: lambda env: IRCRRewardModel(*spaces(env), seed=0),
    }


def time_run(make_model: Callable[[gym.Env], Any] | None, steps: int) -> float:
    """Seconds of one fresh SAC's ``learn(steps)``, with the reward model ``make_model`` makes."""
    from stable_baselines3 import SAC

    from delayed_rl.deep import RelabelingReplayBuffer

    env = _env()
    options: dict[str, Any] = {}
    if make_model is not None:
        options = {
            "replay_buffer_class": RelabelingReplayBuffer,
            "replay_buffer_kwargs": {"reward_model": make_model(env)},
        }
    agent = SAC("MlpPolicy", env, seed=0, device="cpu", **options)
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
    parser.add_argument("--models", nargs="+", choices=list(SHORT_NAMES), default=list(SHORT_NAMES))
    args = parser.parse_args()
    torch.set_num_threads(1)
    models = _models()
    names = [REFERENCE] + [SHORT_NAMES[short] for short in dict.fromkeys(args.models)]
    seconds: dict[str, list[float]] = {name: [] for name in names}
    for repeat in range(args.repeats):
        turn = repeat % len(names)
        for name in names[turn:] + names[:turn]:
            seconds[name].append(time_run(models[name], args.steps))
    print(
        f"SAC on Pendulum-v1 with Poisson(20) reward delays, {args.steps} steps, torch "
        f"{torch.__version__} on 1 thread; min–median–max of {args.repeats} interleaved repeats\n"
    )
    print("| run | seconds | ratio to SAC alone | target ≤ 1.3 in every repeat |")
    print("|---|---|---|---|")
    for name in names:
        ratios = [s / alone for s, alone in zip(seconds[name], seconds[REFERENCE], strict=True)]
        verdict = "" if name == REFERENCE else ("ok" if max(ratios) <= TARGET else "MISSED")
        print(f"| {name} | {_spread(seconds[name])} | {_spread(ratios)} | {verdict} |")


if __name__ == "__main__":
    main()
