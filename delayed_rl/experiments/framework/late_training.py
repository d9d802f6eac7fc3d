"""One SAC run under observation and action delays, scored in the env it acts in.

:func:`train_and_score` trains a task's method (:data:`METHODS`: SB3's SAC on the undelayed
env, on the delayed stack, on the delay-aware view, or :class:`~delayed_rl.deep.HindsightSAC`)
and scores it along the way; :func:`random_score` scores a random policy and
:func:`controller_score` the thesis's proportional line follower.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl.delays import as_delay
from delayed_rl.experiments.framework.deep_training import learn_and_score, mean_return

__all__ = ["CONTROLLERS", "METHODS", "controller_score", "random_score", "train_and_score"]

METHODS = ("oracle", "naive", "augmented", "hindsight", "hindsight-newest")
"""The learners a task can name (see :func:`train_and_score`)."""
CONTROLLERS = ("p-undelayed", "p-delayed")
"""The fixed controllers a task can name (:func:`controller_score`)."""
EVAL_SEED = 2_000_000
"""Evaluation episode ``i`` of seed ``s`` resets with ``EVAL_SEED + 1000 * s + i``."""


def make_env(task: dict, method: str) -> gym.Env:
    """The env ``method`` acts in (see :func:`train_and_score`)."""
    from gymnasium.wrappers import FlattenObservation

    from delayed_rl.wrappers import ActionDelay, DelayAwareObservation, ObservationDelay

    env = gym.make(
        task["env_id"], max_episode_steps=task["episode_steps"], **task.get("env_kwargs", {})
    )
    if method in ("oracle", "random"):
        return env
    if task["action_delay"] is not None:
        env = ActionDelay(env, as_delay(task["action_delay"]))
    env = ObservationDelay(
        env,
        as_delay(task["observation_delay"]),
        max_delay=task.get("observation_max_delay"),
        arrival=task["arrival"],
    )
    if method == "naive":
        return env
    env = DelayAwareObservation(env)
    return FlattenObservation(env) if method == "augmented" else env


def _score(policy: Any, env: gym.Env, task: dict) -> float:
    """The mean return of the evaluation episodes of ``env``, ``policy(obs)`` acting."""
    seeds = [EVAL_SEED + 1000 * task["seed"] + i for i in range(task["eval_episodes"])]
    return mean_return(policy, env, seeds)


def random_score(task: dict) -> dict:
    """``{"score"}``: a uniformly random policy's mean return on the undelayed env."""
    env = make_env(task, "random")
    env.action_space.seed(task["seed"])
    return {"score": _score(lambda _obs: env.action_space.sample(), env, task)}


def controller_score(task: dict) -> dict:
    """``{"score"}``: the proportional line follower's mean return (see :func:`train_and_score`).

    Each evaluation episode starts with no last command (the controller's state), as
    :meth:`~delayed_rl.agents.ProportionalController.predict` does at an episode start.
    """
    from delayed_rl.agents import ProportionalController

    env = make_env(task, "naive" if task["method"] == "p-delayed" else "oracle")
    controller = ProportionalController(env)

    def episode_policy() -> Any:
        state = None

        def act(obs: Any) -> Any:
            nonlocal state
            action, state = controller.predict(obs, state)
            return action

        return act

    seeds = [EVAL_SEED + 1000 * task["seed"] + i for i in range(task["eval_episodes"])]
    return {"score": float(np.mean([mean_return(episode_policy(), env, [s]) for s in seeds]))}


def train_and_score(task: dict) -> dict:
    """Train the task's method and score it along the way.

    A task names the env (``env_id``, its episode length ``episode_steps`` and, optionally, its
    ``env_kwargs``), the delays (``observation_delay`` and ``action_delay``,
    :meth:`~delayed_rl.delays.Delay.to_dict` descriptions; ``action_delay`` may be ``None``, for
    none), how observations arrive (``arrival``: ``"stale"`` or ``"network"``, see
    :class:`~delayed_rl.wrappers.ObservationDelay`), the training ``steps``, the ``method`` and the
    ``seed``. An unbounded observation delay needs ``observation_max_delay``, the wrapper's clip,
    which also bounds the view. The stack is ``ActionDelay`` inside ``ObservationDelay``. The
    methods (:data:`METHODS`), each SB3's SAC with its defaults on one thread:

    - ``oracle``: on the undelayed env;
    - ``naive``: on the delayed stack as it is (the newest observation the stale sensor shows);
    - ``augmented``: on the delay-aware view (:class:`~delayed_rl.wrappers.DelayAwareObservation`),
      flattened, with ``MlpPolicy``;
    - ``hindsight``: :class:`~delayed_rl.deep.HindsightSAC` on the view with
      ``critic_input="made"`` (its critic reads the observation made at each step, once it
      arrived);
    - ``hindsight-newest``: the same with ``critic_input="newest"``, the default (its critic
      reads the newest observation made by each step that arrived, with its age: every step a
      transition).

    The score is the mean return of ``eval_episodes`` deterministic episodes of the env the method
    acts in (delays included; the oracle's is undelayed), reset with seeds fixed per seed and
    episode, read every ``eval_every`` steps and at the end: the learning curve.
    :func:`random_score` scores a uniformly random policy on the undelayed env, and
    :func:`controller_score` the thesis's proportional line follower
    (:class:`~delayed_rl.agents.ProportionalController`, e-puck envs only) on the undelayed env
    (method ``"p-undelayed"``) or on naive SAC's delayed stack (``"p-delayed"``, the thesis's
    baseline fed the same delayed observations as the learners).

    Returns:
        ``{"steps", "scores"}`` (the learning curve, from step 0 to ``steps``), ``"score"`` (the
        last), ``"train_seconds"``, and for the ``hindsight`` methods the transitions they
        stored and dropped.
    """
    import torch
    from stable_baselines3 import SAC

    from delayed_rl.deep import HindsightSAC

    torch.set_num_threads(1)
    method, seed = task["method"], task["seed"]
    env, evaluation = make_env(task, method), make_env(task, method)
    if method.startswith("hindsight"):
        critic_input = "newest" if method == "hindsight-newest" else "made"
        agent = HindsightSAC(
            "MultiInputPolicy", env, critic_input=critic_input, seed=seed, device="cpu"
        )
    else:
        agent = SAC("MlpPolicy", env, seed=seed, device="cpu")
    result = learn_and_score(agent, task, lambda policy: _score(policy, evaluation, task))
    if method.startswith("hindsight"):
        result["transitions_stored"] = agent.transitions_stored
        result["transitions_dropped"] = agent.transitions_dropped
    return result
