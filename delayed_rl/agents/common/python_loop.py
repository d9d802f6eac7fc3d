"""The Python training loop of :meth:`~delayed_rl.agents.common.base.TabularAgent.learn`.

:meth:`~delayed_rl.agents.common.base.TabularAgent.learn` is split as stable-baselines3 splits its own:
a setup that checks the arguments and builds a :class:`LearnRun`, one of two step loops —
:func:`python_loop` here, which runs any ``Discrete`` env, or the compiled loop of
:mod:`delayed_rl.agents.common.compiled_loop` — and a finish that logs and closes the callbacks.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from delayed_rl._validation import Limit, check_bool, check_int, check_limit
from delayed_rl.agents.common.callbacks import as_callback
from delayed_rl.agents.common.statistics import TrainingStatistics

__all__ = [
    "MAX_RECORD_BYTES",
    "MAX_TIMESTEPS",
    "RECORD_DTYPES",
    "LearnRun",
    "advance_schedules",
    "finish_learn",
    "log_metrics",
    "python_loop",
    "setup_learn",
    "step_locals",
]

RECORD_DTYPES = {
    "obs": np.int64,
    "action": np.int64,
    "reward": np.float64,
    "undelayed_reward": np.float64,
    "acting_delay_index": np.int64,
    "episode_end": np.bool_,
}
"""The arrays of ``agent.training_log`` after ``learn(..., record=True)``, and their types."""
_RECORD_STEP_BYTES = sum(np.dtype(dtype).itemsize for dtype in RECORD_DTYPES.values())

MAX_TIMESTEPS = Limit(2**40, "MAX_TIMESTEPS", __name__, "2**40")
"""The most training steps an agent counts (about 1.1e12): ``learn()``'s bound, and a file's.

``learn(total_timesteps)`` refuses more, and with ``reset_num_timesteps=False`` refuses to take
the agent's step count (``num_timesteps``) past it, before anything starts; a model file whose
``num_timesteps`` (or acting count) passes it is refused. Days of training at the compiled
path's millions of steps a second; the bound keeps every step count, schedule clock and
``learn()``'s progress arithmetic far inside int64 and float64's exact integers (``2**53``).
"""
MAX_RECORD_BYTES = 2**30
"""The most memory ``learn(..., record=True)`` may allocate for its record (1 GiB).

The record takes 41 bytes a step (:data:`RECORD_DTYPES`), allocated when ``learn()`` starts: up
to about 26 million steps. A longer recorded call is refused before anything is allocated.
"""


@dataclass
class LearnRun:
    """One ``learn()`` call: what it was asked, and what its loop has done so far.

    Attributes:
        n_steps: how many steps this call takes.
        start_timesteps: the agent's step count when it started.
        total_timesteps: the absolute step count at which it ends (SB3's meaning).
        callback: the callback (``None``: none).
        locals_: the ``locals`` dict handed to the callback.
        log_interval: log every this many steps (``None``: only at the end).
        log: the per-step record (empty without ``record=True``).
        steps_done: steps taken so far.
        reward_total: the received rewards since the last log.
        undelayed_total: the undelayed rewards since the last log.
        next_log: the ``steps_done`` at which the next log is due.
    """

    n_steps: int
    start_timesteps: int
    total_timesteps: int
    callback: Any
    locals_: dict[str, Any]
    log_interval: int | None
    log: dict[str, np.ndarray] = field(default_factory=dict)
    steps_done: int = 0
    reward_total: float = 0.0
    undelayed_total: float = 0.0
    next_log: int = 0

    def __post_init__(self) -> None:
        self.next_log = self.n_steps + 1 if self.log_interval is None else self.log_interval

    def log_if_due(self, agent: Any) -> None:
        """Log the metrics since the last log when ``steps_done`` reaches the next log step."""
        if self.steps_done == self.next_log:
            self.next_log += self.log_interval
            log_metrics(agent, self.reward_total, self.undelayed_total)
            self.reward_total = self.undelayed_total = 0.0


def log_metrics(agent: Any, reward_total: float, undelayed_total: float) -> None:
    """Record the metrics of the steps since the last log (the agent's own too), then dump."""
    agent._statistics.record(agent.logger, agent, reward_total, undelayed_total)
    agent._record_model_metrics(agent.logger)
    agent.logger.dump(agent.num_timesteps)


def advance_schedules(agent: Any, step: int, total_timesteps: int) -> float:
    """Set the progress, ε and α for training step ``step`` of ``total_timesteps``; return ε."""
    agent._progress_remaining = 1.0 - step / total_timesteps
    if agent.exploration_initial_eps != agent.exploration_final_eps:
        agent.exploration_rate = agent.exploration_schedule(agent._progress_remaining)
    if not agent._lr_constant:
        agent._alpha = agent._current_learning_rate()
    return agent.exploration_rate


def step_locals(
    obs: int,
    action: int,
    reward: float,
    undelayed: float,
    terminated: bool,
    truncated: bool,
    info: dict[str, Any],
    acting: int,
    next_obs: int,
) -> dict[str, Any]:
    """A step's variables for ``callback.locals``: SB3's batched names, then the plain values."""
    return {
        "obs": obs,
        "action": action,
        "reward": reward,
        "undelayed_reward": undelayed,
        "terminated": terminated,
        "truncated": truncated,
        "info": info,
        "acting_delay_index": acting,
        "new_obs": np.array([next_obs]),
        "actions": np.array([action]),
        "rewards": np.array([reward]),
        "dones": np.array([terminated or truncated]),
        "infos": [info],
    }


def python_loop(agent: Any, run: LearnRun) -> None:
    """Take ``run.n_steps`` steps of ``agent.env``, learning from each as it happens.

    Each step: ``agent._choose``, ``env.step``, ``agent._observe_info(info)`` if the agent has it
    (the oracle reads the arrivals there), ``agent._learn_transition``, the record, the callback;
    an episode's end resets the env. Running sums live in locals (the hot spot), written back;
    the episode's length is counted from the step it started at, not step by step.
    """
    env, stats, callback, log = agent.env, agent._statistics, run.callback, run.log
    obs_start, action_start = agent._obs_index.start, agent._action_index.start
    eps_constant = agent.exploration_initial_eps == agent.exploration_final_eps
    schedules_constant = eps_constant and agent._lr_constant
    eps, uniform = agent.exploration_rate, agent._uniform.next
    choose, learn_transition = agent._choose, agent._learn_transition
    first_timestep = agent.num_timesteps
    observe_info = getattr(agent, "_observe_info", None)
    acting_counts = stats.acting_counts
    s = agent._obs
    steps_done = 0
    episode_reward, episode_start = stats.episode_reward, -stats.episode_length
    reward_total, undelayed_total, next_log = run.reward_total, run.undelayed_total, run.next_log
    for steps_done in range(1, run.n_steps + 1):
        if not schedules_constant:
            timestep = run.start_timesteps + steps_done - 1
            eps = advance_schedules(agent, timestep, run.total_timesteps)
        acting, a = choose(s, eps, uniform)
        acting_counts[acting] += 1
        obs, reward, terminated, truncated, info = env.step(a + action_start)
        s2 = (obs if type(obs) is int else int(obs)) - obs_start  # int() costs more than a test
        reward = float(reward)
        undelayed = info.get("undelayed_reward", reward)
        if observe_info is not None:
            observe_info(info)
        learn_transition(s, a, reward, s2, terminated, truncated)
        agent.num_timesteps = first_timestep + steps_done  # the shell counts, not the rule
        agent._episode_step = 0 if (terminated or truncated) else agent._episode_step + 1
        reward_total += reward
        undelayed_total += undelayed
        episode_reward += undelayed
        if log:
            step = steps_done - 1
            log["obs"][step] = s + obs_start
            log["action"][step] = a + action_start
            log["reward"][step] = reward
            log["undelayed_reward"][step] = undelayed
            log["acting_delay_index"][step] = acting
            log["episode_end"][step] = terminated or truncated
        if callback is not None:
            run.locals_.update(
                step_locals(
                    s + obs_start,
                    a + action_start,
                    reward,
                    undelayed,
                    terminated,
                    truncated,
                    info,
                    acting,
                    obs,
                )
            )
            callback.update_locals(run.locals_)
        if terminated or truncated:
            stats.end_episode(episode_reward, steps_done - episode_start)
            s = agent._reset_env()
            episode_reward, episode_start = 0.0, steps_done
        else:
            s = s2
        if callback is not None:
            agent._obs = s
            if not callback.on_step():
                break
        if steps_done == next_log:
            next_log += run.log_interval
            log_metrics(agent, reward_total, undelayed_total)
            reward_total = undelayed_total = 0.0
    agent._obs = s
    stats.episode_reward, stats.episode_length = episode_reward, steps_done - episode_start
    run.reward_total, run.undelayed_total, run.next_log = reward_total, undelayed_total, next_log
    run.steps_done = steps_done


def setup_learn(
    agent: Any,
    total_timesteps: int,
    callback: Any,
    log_interval: int | None,
    tb_log_name: str,
    reset_num_timesteps: bool,
    progress_bar: bool,
    record: bool,
) -> LearnRun:
    """Check ``learn()``'s arguments, reset what must be, start the callbacks; return the run.

    Raises:
        TypeError: an argument has the wrong type.
        ValueError: a bad value (``total_timesteps`` above :data:`MAX_TIMESTEPS`, or a record
            above :data:`MAX_RECORD_BYTES`), or the agent has no env.
    """
    n_steps = check_limit(
        "total_timesteps", check_int("total_timesteps", total_timesteps, 0), MAX_TIMESTEPS
    )
    log_interval = check_int("log_interval", log_interval, 1, optional=True)
    check_bool("reset_num_timesteps", reset_num_timesteps)
    check_bool("progress_bar", progress_bar)
    check_bool("record", record)
    if not reset_num_timesteps and agent.num_timesteps + n_steps > MAX_TIMESTEPS:
        raise ValueError(
            f"total_timesteps must keep the agent's step count within {MAX_TIMESTEPS.text} "
            f"with reset_num_timesteps=False, got "
            f"{n_steps} after {agent.num_timesteps} steps"
        )
    if record and n_steps * _RECORD_STEP_BYTES > MAX_RECORD_BYTES:
        raise ValueError(
            f"total_timesteps with record=True must keep the record within MAX_RECORD_BYTES = "
            f"1 GiB (delayed_rl.agents.common.python_loop.MAX_RECORD_BYTES; {_RECORD_STEP_BYTES} bytes a "
            f"step: at most {MAX_RECORD_BYTES // _RECORD_STEP_BYTES} steps), got {n_steps}"
        )
    if agent.env is None:
        raise ValueError(
            "the agent has no env to learn from: pass env= to load() or call set_env(env)"
        )
    callback = as_callback(callback, progress_bar)
    if reset_num_timesteps:
        agent.num_timesteps = 0
        agent._statistics = TrainingStatistics(agent.n_models, 0)
        agent._episode_ended = True
    start = agent.num_timesteps
    if agent._episode_ended:
        agent._obs = agent._reset_env()
    log = {key: np.zeros(n_steps, dtype) for key, dtype in RECORD_DTYPES.items()} if record else {}
    locals_ = {"self": agent, "total_timesteps": start + n_steps, "tb_log_name": tb_log_name}
    if callback is not None:
        callback.init_callback(agent)
        callback.on_training_start(locals_, globals())
        callback.on_rollout_start()
    agent._statistics.restart_clock(agent.num_timesteps)
    return LearnRun(n_steps, start, start + n_steps, callback, locals_, log_interval, log)


def finish_learn(agent: Any, run: LearnRun) -> None:
    """What ends every ``learn()``: the record, the last metrics, the callbacks' ends."""
    agent._progress_remaining = 1.0 - agent.num_timesteps / max(run.total_timesteps, 1)
    if run.log:
        agent.training_log = dict((key, value[: run.steps_done]) for key, value in run.log.items())
    if agent.num_timesteps > agent._statistics.log_start[1]:
        log_metrics(agent, run.reward_total, run.undelayed_total)
    if run.callback is not None:
        run.callback.on_rollout_end()
        run.callback.on_training_end()
