"""One PPO run with parameter sharing on a PettingZoo env whose agents' rewards arrive late.

:func:`train_and_score` trains a task's method (:data:`METHODS`) with one PPO policy for every
agent (SuperSuit's vector conversion, :func:`~delayed_rl.multiagent.sb3_vec_env`) and scores it
along the way on the undelayed env; :func:`random_score` scores random actions on the same
episodes.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

import numpy as np

from delayed_rl.delays import as_delay
from delayed_rl.experiments.framework.deep_training import (
    learn_and_score,
    relabeling_options,
    task_reward_model,
)

__all__ = ["ENVS", "METHODS", "make_env", "random_score", "train_and_score"]

METHODS = ("oracle", "raw", "deconv-known", "deconv-learned")
"""The methods a task can name (see :func:`train_and_score`)."""
EVAL_SEED = 3_000_000
"""Evaluation episode ``i`` of seed ``s`` resets with ``EVAL_SEED + 1000 * s + i``."""


def _pursuit(**kwargs: Any) -> Any:
    """SISL's ``pursuit_v5``: from PettingZoo's registry (1.27 on), else from its module."""
    import pettingzoo

    if hasattr(pettingzoo, "make"):
        return pettingzoo.make("parallel", "sisl/pursuit-v5", **kwargs)
    return importlib.import_module("pettingzoo.sisl.pursuit_v5").parallel_env(**kwargs)


ENVS: dict[str, Callable[..., Any]] = {"pursuit": _pursuit}
"""The envs a task can name: ``"pursuit"``, SISL's ``pursuit_v5`` (a ``ParallelEnv``)."""


def make_env(task: dict, delayed: bool) -> Any:
    """The task's ``ParallelEnv``, behind its reward delay unless ``delayed`` is false."""
    from delayed_rl.multiagent import ParallelRewardDelay

    env = ENVS[task["env"]](**task.get("env_kwargs", {}))
    if delayed:
        env = ParallelRewardDelay(env, as_delay(task["delay"]), on_episode_end="flush")
    return env


def _score(policy: Callable[[np.ndarray], Any], env: Any, task: dict) -> float:
    """The mean per-agent return of the evaluation episodes of ``env`` (the undelayed env).

    ``policy`` maps the stack of the live agents' observations to their actions.
    """
    returns = []
    for i in range(task["eval_episodes"]):
        observations, _ = env.reset(seed=EVAL_SEED + 1000 * task["seed"] + i)
        total = dict.fromkeys(env.agents, 0.0)
        while env.agents:
            agents = list(env.agents)
            actions = policy(np.stack([observations[agent] for agent in agents]))
            step = {a: np.asarray(action).item() for a, action in zip(agents, actions, strict=True)}
            observations, rewards, _, _, _ = env.step(step)
            for agent, reward in rewards.items():
                total[agent] = total.get(agent, 0.0) + float(reward)
        returns.append(np.mean(list(total.values())))
    return float(np.mean(returns))


def random_score(task: dict) -> dict:
    """``{"score"}``: uniformly random actions' mean per-agent return on the evaluation episodes.

    The actions are drawn from the first agent's action space (parameter sharing needs every
    agent's to be the same), seeded with the task's seed.
    """
    env = make_env(task, delayed=False)
    space = env.action_space(env.possible_agents[0])
    space.seed(task["seed"])
    score = _score(lambda stack: [space.sample() for _ in stack], env, task)
    env.close()
    return {"score": score}


def train_and_score(task: dict) -> dict:
    """Train the task's method and score it along the way.

    A task names the env (``env``, a name of :data:`ENVS`, built with ``env_kwargs``), the reward
    delay (``delay``, a :meth:`~delayed_rl.delays.Delay.to_dict` description: every agent draws its
    own delays, :class:`~delayed_rl.multiagent.ParallelRewardDelay`, flushed when its episode
    ends), the training ``steps``, PPO's settings beyond SB3's defaults (``ppo``), the ``method``
    and the ``seed``.

    **Parameter sharing.** SuperSuit's ``pettingzoo_env_to_vec_env_v1`` makes every agent a sub-env
    of one vector env, and ``concat_vec_envs_v1`` hands it to stable-baselines3: one PPO policy
    acts for every agent, on each agent's own observation, and learns from every agent's steps.
    ``steps`` counts agent-steps, as SB3 counts sub-env steps (an env step of 4 agents is 4).
    The conversion is :func:`~delayed_rl.multiagent.sb3_vec_env`, whose ``seed()`` seeds the next
    reset (SuperSuit's own adapter has none).

    The methods (:data:`METHODS`):

    - ``oracle``: PPO on the undelayed env;
    - ``raw``: PPO on the delayed rewards as they arrive;
    - ``deconv-known``: :class:`~delayed_rl.deep.DeconvolutionRewardModel` given the delay, in a
      :class:`~delayed_rl.deep.RelabelingRolloutBuffer` (PPO learns from ``R̂(s, a)`` in place of
      the delivered rewards) with its callback; the model reads the stacked sub-envs as it reads
      any vector env's, each agent's delivered rewards a stream of their own;
    - ``deconv-learned``: the same learning the delay's pmf on ``0..max_delay_estimate`` (the task's
      ``max_delay_estimate``, a bound the user would choose, not the delay).

    The score is the mean per-agent return of ``eval_episodes`` episodes of the *undelayed* env,
    every agent acting greedily with the shared policy, reset with seeds fixed per seed and
    episode; it is read every ``eval_every`` steps and at the end (the learning curve).
    :func:`random_score` scores uniformly random actions on the same episodes.

    Returns:
        ``{"steps", "scores"}`` (the learning curve, from step 0 to ``steps``), ``"score"`` (the
        last), ``"train_seconds"``, and for a model method the reward model's ``"rmse"``
        against the true reward over its last 10 000 steps, its ``"updates"`` and its
        ``"mean_delay"``.
    """
    import torch
    from stable_baselines3 import PPO

    from delayed_rl.multiagent import sb3_vec_env

    torch.set_num_threads(1)
    method = task["method"]
    env = sb3_vec_env(make_env(task, delayed=method != "oracle"))
    evaluation = make_env(task, delayed=False)
    options: dict[str, Any] = dict(task["ppo"])
    callbacks, model = [], None
    if method.startswith("deconv"):
        model = task_reward_model(task, env)
        relabeling, callbacks = relabeling_options(model, on_policy=True)
        options.update(relabeling)
    agent = PPO("MlpPolicy", env, seed=task["seed"], device="cpu", **options)
    result = learn_and_score(
        agent, task, lambda policy: _score(policy, evaluation, task), callbacks
    )
    if model is not None:
        result["rmse"] = model.rmse()
        result["updates"] = model.updates_taken
        result["mean_delay"] = model.mean_delay
    env.close()
    evaluation.close()
    return result
