"""What watching a reward model costs a SAC step, measured in one run.

:class:`~delayed_rl.deep.RewardModelCallback` makes the buffer hand the model each relabelled
batch beside its undelayed rewards (:meth:`~delayed_rl.deep.RewardModel.watch`), and writes the
model's loss, RMSE, correlation, mean delay and updates to SB3's logger at each rollout's end,
which off-policy is every step. Target: ≤ 5 % of a SAC step.

Setup: SB3's SAC with its defaults on Pendulum-v1 under Poisson(20) reward delays, with a
:class:`~delayed_rl.deep.RelabelingReplayBuffer` and a deconvolution model learning ``p`` on
``0..60``, trained ``--steps`` steps (past its warm-up) with the callback. Torch on one thread.
Each repeat, in turns:

- **a SAC step**: SAC alone (SB3's buffer) trained ``--step-sample`` more steps, timed per step;
- **what watching adds to one step**: the same sampled batch relabelled ``--calls`` times with
  the buffer watched and ``--calls`` times without, the callback's ``on_step`` and its rollout's
  end (the logging) ``--calls`` times each; the difference and the two calls, per step.

Reported: min–median–max over ``--repeats`` of each, and the share of a SAC step.

    python benchmarks/reward_model_watch_cost.py [--steps 1500] [--repeats 5] [--calls 2000]
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np
from interleaved import seconds_per_call

from delayed_rl.delays import Poisson
from delayed_rl.wrappers import RewardDelay

TARGET = 0.05
DELAY = Poisson(20)


def _env() -> gym.Env:
    return RewardDelay(gym.make("Pendulum-v1"), DELAY, on_episode_end="flush")


def _spread(values: list[float], scale: float = 1.0, digits: int = 3) -> str:
    low, mid, high = min(values), statistics.median(values), max(values)
    return f"{low * scale:.{digits}f}–{mid * scale:.{digits}f}–{high * scale:.{digits}f}"


def main() -> None:
    """Train, then time the repeats and print the table (markdown)."""
    import torch
    from stable_baselines3 import SAC

    from delayed_rl.deep import (
        DeconvolutionRewardModel,
        RelabelingReplayBuffer,
        RewardModelCallback,
    )

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--calls", type=int, default=2000)
    parser.add_argument("--step-sample", type=int, default=300)
    args = parser.parse_args()
    torch.set_num_threads(1)

    env = _env()
    model = DeconvolutionRewardModel(
        env.observation_space, env.action_space, delay=None, max_delay_estimate=60, seed=0
    )
    agent = SAC(
        "MlpPolicy",
        env,
        replay_buffer_class=RelabelingReplayBuffer,
        replay_buffer_kwargs={"reward_model": model},
        seed=0,
        device="cpu",
    )
    callback = RewardModelCallback()
    agent.learn(args.steps, callback=callback)
    buffer = agent.replay_buffer
    assert model.ready and model.diagnostics(), "the model must be past its warm-up and watched"
    alone = SAC("MlpPolicy", _env(), seed=0, device="cpu")
    alone.learn(max(args.step_sample, alone.learning_starts + 1))
    inds = np.random.default_rng(0).integers(0, buffer.pos, size=agent.batch_size)

    def relabel(watched: bool):
        def call():
            buffer.watched = watched
            buffer._get_samples(inds)

        return call

    sac_step, added, on_step, logging = [], [], [], []
    for _ in range(args.repeats):
        start = time.perf_counter()
        alone.learn(args.step_sample, reset_num_timesteps=False)
        sac_step.append((time.perf_counter() - start) / args.step_sample)
        watched = seconds_per_call(relabel(True), args.calls)
        unwatched = seconds_per_call(relabel(False), args.calls)
        added.append(max(0.0, watched - unwatched))
        on_step.append(seconds_per_call(callback.on_step, args.calls))
        logging.append(seconds_per_call(callback.on_rollout_end, args.calls))
    buffer.watched = True
    total = [sum(parts) for parts in zip(added, on_step, logging, strict=True)]
    shares = [cost / step for cost, step in zip(total, sac_step, strict=True)]
    print(
        f"SAC on Pendulum-v1, Poisson(20) reward delays, deconvolution with p learned on 0..60; "
        f"torch {torch.__version__} on 1 thread; min–median–max of {args.repeats} repeats\n"
    )
    print("| what | ms a step |")
    print("|---|---|")
    print(f"| SAC step (SAC alone) | {_spread(sac_step, 1e3)} |")
    print(f"| relabelling watched − unwatched | {_spread(added, 1e3, 4)} |")
    print(f"| callback on_step | {_spread(on_step, 1e3, 4)} |")
    print(f"| callback rollout end (the logging) | {_spread(logging, 1e3, 4)} |")
    print(f"| watching, in all | {_spread(total, 1e3, 4)} |")
    verdict = "met" if max(shares) <= TARGET else "MISSED"
    print(
        f"\nwatching / SAC step: {_spread(shares, 100, 2)} % "
        f"(target ≤ 5 % in every repeat: {verdict})"
    )


if __name__ == "__main__":
    main()
