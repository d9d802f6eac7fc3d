"""One stable-baselines3 run on a delayed-reward env, scored on the undelayed env.

:func:`train_and_score` trains a task's method (:data:`METHODS`) with a reward model or buffer
of :mod:`delayed_rl.deep` where the method has one, after one warm-up for every method
(:data:`WARMUP_EPISODES`), and scores it along the way; :func:`random_score` scores a random
policy on the same episodes.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl.delays import as_delay

__all__ = [
    "METHODS",
    "MODEL_METHODS",
    "mean_return",
    "learn_and_score",
    "relabeling_options",
    "random_score",
    "task_reward_model",
    "train_and_score",
]

METHODS = ("raw", "oracle", "rrd", "ircr", "return-regression", "deconv-known", "deconv-learned")
"""The methods a task can name.

- ``raw``: the algorithm on the delayed rewards as they arrive;
- ``oracle``: the algorithm on the undelayed env (the delay plays no part);
- ``rrd``: :class:`~delayed_rl.deep.ReturnDecompositionRewardModel` with the authors'
  settings (its defaults);
- ``ircr``: :class:`~delayed_rl.deep.IRCRReplayBuffer`, IRCR as its authors wrote it (off-policy
  only: half of its batches replay the best episodes), under the same algorithm as every other
  method: SB3's SAC with its defaults, so a batch is 128 ring plus 128 heap transitions (the
  authors' SAC: 512 + 512, ``tau=0.001``, initial temperature 0.1, a 300k buffer). The
  comparison holds the learner fixed and varies only what it learns from;
- ``return-regression``: :class:`~delayed_rl.deep.ReturnRegressionRewardModel`, IRCR's target
  learned by a network;
- ``deconv-known``: :class:`~delayed_rl.deep.DeconvolutionRewardModel` with the delay's pmf;
- ``deconv-learned``: the same with ``p`` learned on ``0..max_delay_estimate`` (the task's
  ``max_delay_estimate``, a bound the user would choose, not the delay).

The reward models have their defaults (an update a vector-env step and a warm-up of 1000
updates before they relabel, trained when the algorithm trains) and the run's seed; off-policy
algorithms get a :class:`~delayed_rl.deep.RelabelingReplayBuffer`, on-policy ones a
:class:`~delayed_rl.deep.RelabelingRolloutBuffer` with its callback. Torch runs on one thread.
"""
MODEL_METHODS = ("rrd", "return-regression", "deconv-known", "deconv-learned")
"""The methods that train a reward model."""
WARMUP_EPISODES = 2
"""Episodes of steps before an off-policy algorithm's first update, for every method.

**One warm-up for every method.** An off-policy algorithm takes its first update after
``warmup_episodes`` episodes of steps (``learning_starts``; SB3's default, 100 steps, without
it), whatever the method, raw and oracle included. With two, by then every reward model can be
fitted (RRD and the return regression need a finished episode, IRCR two distinct returns, as its authors' two exploration episodes), and at
the first update each model takes the updates its schedule owes for those steps plus its
warm-up, so the algorithm never learns from an untrained ``R̂`` nor from the raw rewards
first. (SB3's default, 100 steps, gave the deconvolution a head start over the episode-sum
baselines, which could only start after an episode.) On-policy algorithms learn from the first
rollout, which holds many episodes; the models warm up before it is relabelled.
"""
UPRIGHT_COS = 0.9
"""The ``"upright"`` reward's region: ``cos θ ≥ 0.9``, within about 26° of upright."""
REWARDS = ("upright",)
"""The rewards a task can put in place of the env's: ``"upright"``, Pendulum's 1 at each step
in the region :data:`UPRIGHT_COS` and 0 elsewhere."""


class UprightReward(gym.Wrapper):
    """Pendulum-v1's reward replaced by 1 where ``cos θ ≥`` :data:`UPRIGHT_COS` (upright), else 0."""

    def step(self, action: Any) -> Any:
        """Step the env; the reward is whether the pendulum ends the step upright."""
        obs, _, terminated, truncated, info = self.env.step(action)
        return obs, float(obs[0] >= UPRIGHT_COS), terminated, truncated, info


EVAL_SEED = 1_000_000
"""Evaluation episode ``i`` of seed ``s`` resets with ``EVAL_SEED + 1000 * s + i``."""


def _env(task: dict, delayed: bool) -> gym.Env:
    """The task's env, with its reward delay (flushed) unless ``delayed`` is false."""
    from delayed_rl.wrappers import RewardDelay

    env = gym.make(task["env_id"], max_episode_steps=task["episode_steps"])
    if task.get("reward") == "upright":
        env = UprightReward(env)
    if delayed:
        env = RewardDelay(env, as_delay(task["delay"]), on_episode_end="flush")
    return env


def task_reward_model(task: dict, env: Any) -> Any:
    """The reward model of a model method (``task["method"]``), seeded with the run's seed.

    ``env`` gives the spaces (a vector env's, for the stacked sub-envs); ``deconv-known`` reads
    ``task["delay"]``, ``deconv-learned`` ``task["max_delay_estimate"]``.
    """
    from delayed_rl.deep import (
        DeconvolutionRewardModel,
        ReturnDecompositionRewardModel,
        ReturnRegressionRewardModel,
    )

    spaces, seed = (env.observation_space, env.action_space), task["seed"]
    method = task["method"]
    if method == "rrd":
        return ReturnDecompositionRewardModel(*spaces, seed=seed)
    if method == "return-regression":
        return ReturnRegressionRewardModel(*spaces, seed=seed)
    delay = as_delay(task["delay"]) if method == "deconv-known" else None
    max_delay_estimate = None if method == "deconv-known" else task["max_delay_estimate"]
    return DeconvolutionRewardModel(
        *spaces, delay=delay, max_delay_estimate=max_delay_estimate, seed=seed
    )


def relabeling_options(model: Any, on_policy: bool) -> tuple[dict[str, Any], list[Any]]:
    """The algorithm's keyword arguments and callbacks that relabel its buffer with ``model``'s R̂.

    On-policy: a :class:`~delayed_rl.deep.RelabelingRolloutBuffer` and its
    :class:`~delayed_rl.deep.RewardModelCallback`; off-policy: a
    :class:`~delayed_rl.deep.RelabelingReplayBuffer` (no callback).
    """
    from delayed_rl.deep import (
        RelabelingReplayBuffer,
        RelabelingRolloutBuffer,
        RewardModelCallback,
    )

    if on_policy:
        options = {"rollout_buffer_class": RelabelingRolloutBuffer}
        return {**options, "rollout_buffer_kwargs": {"reward_model": model}}, [
            RewardModelCallback()
        ]
    options = {"replay_buffer_class": RelabelingReplayBuffer}
    return {**options, "replay_buffer_kwargs": {"reward_model": model}}, []


def mean_return(policy: Any, env: gym.Env, seeds: Any) -> float:
    """The mean return of one deterministic episode of ``env`` per reset seed, ``policy(obs)`` acting."""
    returns = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    return float(np.mean(returns))


def _scores(policy: Any, task: dict) -> float:
    """The mean return of the evaluation episodes, ``policy(obs)`` acting."""
    env = _env(task, delayed=False)
    seeds = [EVAL_SEED + 1000 * task["seed"] + i for i in range(task["eval_episodes"])]
    score = mean_return(policy, env, seeds)
    env.close()
    return score


def random_score(task: dict) -> dict:
    """``{"score"}``: a uniformly random policy's mean return on the task's evaluation episodes.

    Its actions come from the action space seeded with the task's seed.
    """
    space = _env(task, delayed=False).action_space
    space.seed(task["seed"])
    return {"score": _scores(lambda _obs: space.sample(), task)}


def learn_and_score(
    agent: Any,
    task: dict,
    score: Callable[[Callable[[Any], Any]], float],
    callbacks: Sequence[Any] = (),
) -> dict:
    """Train an SB3 ``agent`` for ``task["steps"]`` steps, scoring it along the way.

    ``score(policy)`` scores the greedy policy (``obs -> action``) at step 0, each time training
    passes ``task["eval_every"]`` steps, and at the end. (PPO trains in whole rollouts, so it may
    pass ``steps``: the curve stops there.)

    Args:
        agent: the SB3 algorithm.
        task: the run's fields (``steps``, ``eval_every``).
        score: the scorer of a policy.
        callbacks: SB3 callbacks to run after the scoring one.

    Returns:
        ``{"steps", "scores"}`` (the learning curve, the step 0 score first and the last at
        ``steps``), ``"score"`` (the last) and ``"train_seconds"``.
    """
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList

    curve: list[tuple[int, float]] = []

    def greedy(obs: Any) -> Any:
        return agent.predict(obs, deterministic=True)[0]

    class Scores(BaseCallback):
        """Scores the policy when training passes each ``eval_every`` steps, up to ``steps``."""

        def _on_step(self) -> bool:
            while len(curve) * task["eval_every"] <= min(self.num_timesteps, task["steps"]):
                curve.append((len(curve) * task["eval_every"], score(greedy)))
            return True

    started = time.perf_counter()
    agent.learn(task["steps"], callback=CallbackList([Scores(), *callbacks]))
    seconds = time.perf_counter() - started
    if curve[-1][0] < task["steps"]:  # the last score at the end of training
        curve.append((task["steps"], score(greedy)))
    return {
        "steps": [step for step, _ in curve],
        "scores": [value for _, value in curve],
        "score": curve[-1][1],
        "train_seconds": seconds,
    }


def train_and_score(task: dict) -> dict:
    """Train the task's method and score it.

    A task names the env (``env_id``, its episode length ``episode_steps`` and, optionally, a
    ``reward`` of :data:`REWARDS` in place of the env's), the algorithm (``SAC`` or ``PPO``, with
    SB3's defaults), the sub-envs (``n_envs``), the reward delay (``delay``, a
    :meth:`~delayed_rl.delays.Delay.to_dict` description, flushed at each episode's end), the
    off-policy warm-up (``warmup_episodes``, see below), the training ``steps``, the ``method`` and
    the ``seed``. The methods are :data:`METHODS`.

    The score is the mean return of ``eval_episodes`` deterministic episodes of the *undelayed* env
    (the same seeds for every method of a seed), read every ``eval_every`` steps and at the end: the
    learning curve. :func:`random_score` scores a uniformly random policy on the same episodes.

    Returns:
        ``{"steps", "scores"}`` (the learning curve, the step 0 score first and the last at
        ``steps``), ``"score"`` (the last), ``"train_seconds"``, and for a model method the
        reward model's ``"rmse"`` against the true reward over its last 10 000 steps, its
        ``"updates"`` and, for the deconvolution, its ``"mean_delay"``.
    """
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.env_util import make_vec_env

    from delayed_rl.deep import IRCRReplayBuffer

    torch.set_num_threads(1)
    method, seed = task["method"], task["seed"]
    vec_env = make_vec_env(
        lambda: _env(task, delayed=method != "oracle"), n_envs=task["n_envs"], seed=seed
    )
    algorithm = {"SAC": SAC, "PPO": PPO}[task["algorithm"]]
    options: dict[str, Any] = {}
    callbacks = []
    model = None
    if "warmup_episodes" in task:
        options["learning_starts"] = task["warmup_episodes"] * task["episode_steps"]
    if method == "ircr":
        if algorithm is PPO:
            raise ValueError("method 'ircr' needs an off-policy algorithm (SAC), got PPO")
        options["replay_buffer_class"] = IRCRReplayBuffer
    if method in MODEL_METHODS:
        model = task_reward_model(task, vec_env)
        relabeling, callbacks = relabeling_options(model, on_policy=algorithm is PPO)
        options.update(relabeling)
    agent = algorithm("MlpPolicy", vec_env, seed=seed, device="cpu", **options)
    result = learn_and_score(agent, task, lambda policy: _scores(policy, task), callbacks)
    if model is not None:
        result["rmse"] = model.rmse()
        result["updates"] = model.updates_taken
        if method.startswith("deconv"):
            result["mean_delay"] = model.mean_delay
    vec_env.close()
    return result
