"""One run of a sweep: its env and agent built from the run's configuration, trained, evaluated.

:func:`run_sweep_task` is what the backends run: a top-level function, so that joblib, Ray and
Dask workers import it by its module path. :func:`check_sweep` builds each (agent, env, delay)
of a sweep once, before any run.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

from delayed_rl.agents.registry import ARRIVAL_AGENTS, agent_class
from delayed_rl.delays import Delay, as_delay
from delayed_rl.sweep.schema import (
    SB3_ON_POLICY,
    SB3_PREFIX,
    Evaluation,
    Sweep,
)

#: Added to a run's seed to seed its evaluation env (training and evaluation differ).
EVAL_SEED_OFFSET = 1_000_000
#: The longest evaluation episode: one that runs longer fails its run (a continuing env).
MAX_EVAL_EPISODE_STEPS = 100_000
_NO_DELAY = {"type": "Constant", "k": 0}


class RunError(RuntimeError):
    """A run of a sweep failed: the message names the run and the original error."""


def reward_delay(config: Mapping[str, Any]) -> Delay:
    """The run's reward delay: its ``reward`` delay, or ``Constant(0)`` when it has none."""
    return as_delay(config["delays"].get("reward", _NO_DELAY))


def resolve_placeholders(kwargs: Mapping[str, Any], delay: Delay) -> dict[str, Any]:
    """``kwargs`` with each placeholder value replaced by ``delay``.

    The placeholders are :data:`~delayed_rl.sweep.schema.PLACEHOLDERS`; the sweep
    file's reference, :mod:`delayed_rl.sweep`, says what each one becomes.
    """
    values = {"$delay": delay, "$delay_mean": delay.mean, "$delay_steps": round(delay.mean)}
    return {
        key: values[value] if isinstance(value, str) and value in values else value
        for key, value in kwargs.items()
    }


def make_env(config: Mapping[str, Any]) -> gym.Env:
    """The run's env: ``gym.make(id, **kwargs)`` behind the run's delays.

    Action and observation delays are stacked by :func:`~delayed_rl.wrappers.wrap_delays`; the
    reward delay, outermost, is a :class:`~delayed_rl.wrappers.RewardDelay` that records
    arrivals for the agents of :data:`~delayed_rl.agents.registry.ARRIVAL_AGENTS` (which get ``Constant(0)`` when the run
    delays no reward).
    """
    from delayed_rl.wrappers import RewardDelay, wrap_delays

    delays = config["delays"]
    env = gym.make(config["env"]["id"], **config["env"]["kwargs"])
    env = wrap_delays(
        env, action_delay=delays.get("action"), observation_delay=delays.get("observation")
    )
    arrivals = config["agent"]["name"] in ARRIVAL_AGENTS
    if "reward" not in delays and not arrivals:
        return env
    return RewardDelay(env, reward_delay(config), record_arrivals=arrivals)


def _sb3_class(name: str) -> type:
    try:
        import stable_baselines3
    except ImportError:
        raise RuntimeError(
            f"agent {name!r} needs stable-baselines3: pip install 'delayed-rl[sb3]'"
        ) from None
    return getattr(stable_baselines3, name.removeprefix(SB3_PREFIX))


def make_model(config: Mapping[str, Any], env: gym.Env) -> Any:
    """The run's agent on ``env``, seeded with the run's seed, its placeholders resolved.

    An SB3 agent with a ``reward_model`` gets the relabelling buffer of its kind
    (:func:`relabeling_buffer`), whose model the algorithm's seed seeds.
    """
    name = config["agent"]["name"]
    kwargs = resolve_placeholders(config["agent"]["kwargs"], reward_delay(config))
    if name.startswith(SB3_PREFIX):
        kwargs = {"policy": "MlpPolicy", **kwargs}
        reward_model = config["agent"].get("reward_model")
        if reward_model is not None:
            model = resolve_placeholders(reward_model, reward_delay(config))
            kwargs.update(relabeling_buffer(name, env.observation_space, model, kwargs))
        return _sb3_class(name)(env=env, seed=config["seed"], **kwargs)
    return agent_class(name)(env, seed=config["seed"], **kwargs)


def relabeling_buffer(
    name: str, observation_space: Any, model: dict[str, Any], kwargs: Mapping[str, Any]
) -> dict[str, Any]:
    """The SB3 arguments that give algorithm ``name`` the buffer that relabels with ``model``.

    On-policy algorithms (:data:`~delayed_rl.sweep.schema.SB3_ON_POLICY`) get a rollout
    buffer, the others a replay buffer; each the ``Dict`` kind for a ``Dict`` observation space.
    A ``model`` whose ``type`` is a guidance buffer (:data:`~delayed_rl.deep.GUIDANCE_BUFFERS`)
    is that replay buffer, its other keys the buffer's arguments.

    Raises:
        ValueError: ``kwargs`` already choose the buffer.
    """
    from delayed_rl import deep

    on_policy = name.removeprefix(SB3_PREFIX) in SB3_ON_POLICY
    kind = "rollout" if on_policy else "replay"
    for key in (f"{kind}_buffer_class", f"{kind}_buffer_kwargs"):
        if key in kwargs:
            raise ValueError(
                f"an agent with a reward_model must not set {key}: the reward model brings its "
                "own buffer"
            )
    if model["type"] in deep.GUIDANCE_BUFFERS:
        settings = {key: value for key, value in model.items() if key != "type"}
        return {
            f"{kind}_buffer_class": getattr(deep, model["type"]),
            f"{kind}_buffer_kwargs": settings,
        }
    prefix = "RelabelingDict" if isinstance(observation_space, gym.spaces.Dict) else "Relabeling"
    buffer = getattr(deep, f"{prefix}{'Rollout' if on_policy else 'Replay'}Buffer")
    return {f"{kind}_buffer_class": buffer, f"{kind}_buffer_kwargs": {"reward_model": model}}


def check_sweep(sweep: Sweep) -> None:
    """Build every (agent, env, delay) of ``sweep`` once, with its first seed, and close it.

    An argument value an agent refuses, or an env it cannot use (a tabular agent on a ``Box``
    observation space), fails here, before any run, naming the agent, env and delay.

    Raises:
        TypeError, ValueError: one of them cannot be built, or building it asks for more memory
            than the machine has; the message says which and why.
        RuntimeError: an extra the sweep needs is not installed (stable-baselines3).
    """
    seen = set()
    for task in sweep.runs():
        combination = (task["agent"], task["env"], task["delay"])
        if combination in seen:
            continue
        seen.add(combination)
        where = f"agent {task['agent']!r} on env {task['env']!r} under delay {task['delay']!r}"
        env = None
        try:
            env = make_env(task["config"])
            make_model(task["config"], env)
        except TypeError as error:
            raise TypeError(f"{where}: {_one_line(error)}") from None
        except (ValueError, AssertionError, ImportError, gym.error.Error) as error:
            raise ValueError(f"{where}: {_one_line(error)}") from None
        except (MemoryError, OverflowError) as error:  # e.g. SB3's n_steps: 10**11
            raise ValueError(
                f"{where}: its arguments ask for more memory than this machine has "
                f"({type(error).__name__}: {_one_line(error)}); check its kwargs"
            ) from None
        finally:
            if env is not None:
                env.close()


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split()) or type(error).__name__


class UndelayedRewardTally(gym.Wrapper):
    """Counts the steps taken and sums their undelayed rewards (an SB3 run's training reward).

    The undelayed reward is ``info["undelayed_reward"]`` of the reward-delay wrapper, else the
    reward itself.
    """

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.steps = 0
        self.total = 0.0

    def step(self, action: Any) -> Any:
        """Step the env and count the step's undelayed reward."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        self.total += float(info.get("undelayed_reward", reward))
        return obs, reward, terminated, truncated, info

    @property
    def mean(self) -> float:
        """The mean undelayed reward per step so far (NaN before any step)."""
        return self.total / self.steps if self.steps else math.nan


def train(config: Mapping[str, Any]) -> tuple[Any, float]:
    """Train the run's agent for its steps; return it and its mean undelayed reward per step."""
    if config["agent"]["name"].startswith(SB3_PREFIX):
        tally = UndelayedRewardTally(make_env(config))
        model = make_model(config, tally)
        callback = None
        reward_model = config["agent"].get("reward_model")
        if reward_model is not None:
            from delayed_rl.deep import GUIDANCE_BUFFERS, RewardModelCallback

            if reward_model["type"] not in GUIDANCE_BUFFERS:
                callback = RewardModelCallback()
        model.learn(total_timesteps=config["steps"], callback=callback)
        return model, tally.mean
    model = make_model(config, make_env(config))
    model.learn(config["steps"], log_interval=None)
    return model, float(model.logger.dumps[-1]["rollout/undelayed_reward_per_step"])


def _greedy_step(model: Any, env: gym.Env, obs: Any) -> tuple[Any, float, bool]:
    """One greedy step: the next observation, the undelayed reward, whether the episode ended."""
    action, _ = model.predict(obs, deterministic=True)
    if isinstance(env.action_space, gym.spaces.Discrete):
        action = int(action)
    obs, reward, terminated, truncated, info = env.step(action)
    return obs, float(info.get("undelayed_reward", reward)), bool(terminated or truncated)


class EpisodeTooLong(ValueError):
    """A greedy episode ran its whole step limit without ending: the env looks continuing."""


@dataclass
class GreedyRollout:
    """What :func:`greedy_rollout` ran.

    Attributes:
        steps: the steps taken.
        total: the sum of their undelayed rewards.
        returns: the undelayed return of each episode that ended, in order.
    """

    steps: int = 0
    total: float = 0.0
    returns: list[float] = field(default_factory=list)


def greedy_rollout(
    model: Any, env: gym.Env, obs: Any, length: Evaluation, max_eval_episode_steps: int
) -> GreedyRollout:
    """Run ``model``'s greedy policy on ``env``, without learning, for ``length``.

    Every step's reward is the undelayed one (``info["undelayed_reward"]``, else the reward);
    an episode's end resets ``env`` (unseeded: seeding the first reset is the caller's).

    Args:
        model: anything with SB3's ``predict(obs, deterministic=True)``.
        env: the env, already reset.
        obs: the observation of that reset.
        length: ``count`` whole episodes (``unit="episode"``) or ``count`` steps (``"step"``).
        max_eval_episode_steps: with episodes, the steps an episode may take at the most.

    Raises:
        EpisodeTooLong: with episodes, one took ``max_eval_episode_steps`` steps without ending.
    """
    run = GreedyRollout()
    episode_steps, episode_return = 0, 0.0
    by_steps = length.unit == "step"
    while run.steps < length.count if by_steps else len(run.returns) < length.count:
        if not by_steps and episode_steps == max_eval_episode_steps:
            raise EpisodeTooLong(f"no episode ended within {max_eval_episode_steps} steps")
        obs, reward, ended = _greedy_step(model, env, obs)
        run.steps, run.total = run.steps + 1, run.total + reward
        episode_steps, episode_return = episode_steps + 1, episode_return + reward
        if ended:
            run.returns.append(episode_return)
            episode_steps, episode_return = 0, 0.0
            obs, _ = env.reset()
    return run


def evaluate(model: Any, env: gym.Env, evaluation: Evaluation, seed: int) -> float:
    """The greedy policy's mean undelayed return per episode, or reward per step, on ``env``.

    Args:
        model: anything with SB3's ``predict(obs, deterministic=True)``.
        env: a fresh env (it is reset here, with ``seed`` + :data:`EVAL_SEED_OFFSET`).
        evaluation: ``count`` episodes (``unit="episode"``) or steps (``"step"``).
        seed: the run's seed.

    Raises:
        ValueError: with episodes, one runs longer than :data:`MAX_EVAL_EPISODE_STEPS`.
    """
    obs, _ = env.reset(seed=seed + EVAL_SEED_OFFSET)
    try:
        run = greedy_rollout(model, env, obs, evaluation, MAX_EVAL_EPISODE_STEPS)
    except EpisodeTooLong:
        raise ValueError(
            f"no evaluation episode ended within {MAX_EVAL_EPISODE_STEPS} steps: it looks "
            "like a continuing env; evaluate it with eval_steps"
        ) from None
    if evaluation.unit == "step":
        return run.total / evaluation.count
    return sum(run.returns) / len(run.returns)


@contextlib.contextmanager
def _one_torch_thread(config: Mapping[str, Any]) -> Iterator[None]:
    """For an SB3 run: torch on one thread (sums that do not depend on the thread count)."""
    if not config["agent"]["name"].startswith(SB3_PREFIX):
        yield
        return
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def run_sweep_task(task: Mapping[str, Any]) -> dict[str, Any]:
    """Train and evaluate one run of :meth:`Sweep.runs`; return its ``results.csv`` row.

    Raises:
        RunError: the run failed; the message names it and the original error.
    """
    config = task["config"]
    started = time.perf_counter()
    try:
        evaluation = Evaluation(**config["eval"])
        with _one_torch_thread(config):
            model, train_reward = train(config)
            model.env.close()  # the training env (SB3's VecEnv around it)
            with contextlib.closing(make_env(config)) as env:
                eval_reward = evaluate(model, env, evaluation, config["seed"])
    except Exception as error:
        run = f"({task['agent']}, {task['env']}, {task['delay']}, seed {task['seed']})"
        raise RunError(f"run {run} failed: {type(error).__name__}: {error}") from error
    return {
        "agent": task["agent"],
        "env": task["env"],
        "delay": task["delay"],
        "seed": task["seed"],
        "steps": config["steps"],
        "train_reward": train_reward,
        "eval_reward": eval_reward,
        "wall_s": round(time.perf_counter() - started, 3),
        "eval_unit": evaluation.unit,
        "run_id": task["run_id"],
    }
