"""The e-puck line follower in the thesis's setting: env, learners, the pooled training run, metrics.

The setting (thesis section 5.2.4) is :func:`line_env`'s, the learners :func:`make_agent`'s.
``linefollow``, ``linefollow-deconv``, ``controllers`` and ``real-robot`` train the same learners
there, so their tasks name one :func:`training_run` per learner and seed, read at the steps each
needs (:func:`pooled_training`, :func:`logged_run`): run together, each trains once. The
metrics are :func:`run_metrics`'.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._validation import check_choice
from delayed_rl.experiments.framework.delay_estimates import delay_estimate
from delayed_rl.experiments.framework.experiment import (
    Config,
    Curve,
    SharedRun,
    running_average,
    seed_tasks,
)
from delayed_rl.experiments.framework.task import Task
from delayed_rl.experiments.framework.training import thesis_hyperparameters
from delayed_rl.parallel.intervals import mean_ci95

ENV_ID = "delayed_rl/EPuckLineFollow-v0"
#: The stand-in robot of ``real-robot`` (:mod:`delayed_rl.experiments.thesis.real_robot`).
REAL_ENV_ID = "delayed_rl/EPuckLineFollowReal-v0"
#: What a trained agent can continue on (:func:`training_run`): the clean simulation, the robot.
SETTINGS = {"clean": ENV_ID, "real": REAL_ENV_ID}
#: The track of every line-following run.
TRACK = "racetrack"
#: The Poisson mean λ of the reward delay, and the learners' λ̂max (their ``max_delay_estimate``).
LAM, LAMBDA_MAX = 90, 150
#: The line-less steps after which the robot is put back on the track.
LOST_LINE_STEPS = 50
#: The optimistic initial value, 1 / (1 − γ), the largest discounted return when every reward is
#: at most 1 (the thesis does not print its values for the e-puck; α, γ and ε are the thesis's,
#: :mod:`delayed_rl.experiments.framework.training`).
Q_INIT = 10.0
#: The centroid of a centred line, and the error |Δ| an unseen line counts (:func:`line_error`).
CENTRE, UNSEEN_ERROR = 20, 20
#: The learners :func:`make_agent` makes (``linefollow``'s MMQ and Q, and DeconvQ learned): each
#: one's agent in :data:`~delayed_rl.agents.registry.REGISTRY` and its arguments beyond the
#: thesis's hyper-parameters.
_LEARNER_AGENTS: dict[str, tuple[str, dict[str, Any]]] = {
    "MMQ": ("mmq", {"max_delay_estimate": LAMBDA_MAX}),
    "Q": ("q", {}),
    "DeconvQ learned": ("deconv", {"delay": None, "max_delay_estimate": LAMBDA_MAX}),
}
#: The learners :func:`make_agent` makes: ``linefollow``'s MMQ and Q, and DeconvQ learned.
LEARNERS = tuple(_LEARNER_AGENTS)


def line_env(reward_delay: float | None = LAM, env_id: str = ENV_ID, **kwargs: Any) -> gym.Env:
    """The thesis's line-following env: racetrack, manual resets, continuing, reward delay λ.

    ``delayed_rl/EPuckLineFollow-v0`` on the :data:`TRACK` with the discrete Table 5.2 actions
    (|A| = 7) and the centroid state of Eq. 5.6 (|S| = 41, with 0 for "line not seen"), a
    Poisson(:data:`LAM`) reward delay; the robot is put back on the track after
    :data:`LOST_LINE_STEPS` line-less steps (``lost_line="recover"``, as the thesis's
    experimenters did by hand) and the task is continuing (``max_steps=None``).

    Args:
        reward_delay: the Poisson mean λ of the reward delay (``None``: undelayed).
        env_id: the e-puck's id: the simulation (default) or :data:`REAL_ENV_ID`.
        **kwargs: other ``EPuckLineFollow`` arguments (e.g. ``action_mode="continuous"``).
    """
    import delayed_rl  # noqa: F401  (registers the ids)

    options = {
        "track": TRACK,
        "lost_line": "recover",
        "lost_line_steps": LOST_LINE_STEPS,
        "max_steps": None,
        **kwargs,
    }
    return gym.make(env_id, reward_delay=reward_delay, **options)


def make_agent(kind: str, env: gym.Env, seed: int) -> Any:
    """A thesis-setting learner on ``env``, one of :data:`LEARNERS`, built from the registry.

    ``"Q"`` (Q-learning), ``"MMQ"`` (Λ = {0, ..., :data:`LAMBDA_MAX`}) or ``"DeconvQ learned"``
    (:class:`~DeconvolutionQLearning` learning the delay on 0..:data:`LAMBDA_MAX`), with the thesis's
    hyper-parameters and ``q_init`` = :data:`Q_INIT`.

    Raises:
        TypeError: ``kind`` is not a string.
        ValueError: ``kind`` is not one of :data:`LEARNERS`.
    """
    from delayed_rl.agents.registry import agent_class

    check_choice("kind", kind, LEARNERS)
    agent, options = _LEARNER_AGENTS[kind]
    return agent_class(agent)(env, **options, **thesis_hyperparameters(seed, q_init=Q_INIT))


def line_error(centroids: np.ndarray) -> np.ndarray:
    """|Δ| = abs(m − :data:`CENTRE`) per step; :data:`UNSEEN_ERROR` where the line is not seen (m = 0)."""
    centroids = np.asarray(centroids, dtype=np.int64)
    return np.where(centroids == 0, UNSEEN_ERROR, np.abs(centroids - CENTRE))


def line_statistics(runs: dict[str, dict[int, dict]]) -> dict[str, dict[str, tuple[float, float]]]:
    """Mean and 95 % CI, per contestant, of the accumulated error and of the line's visibility.

    Args:
        runs: each contestant's run results by seed (:func:`~.results.pivot`), with
            ``total_error`` (Σ|Δ| over the run) and ``visible`` (the fraction of steps that saw
            the line).

    Returns:
        ``{"accumulated_error": {name: (mean, ci)}, "line_visible_fraction": {name: (mean, ci)}}``.
    """
    return {
        summary: {
            name: mean_ci95([r[key] for r in results.values()]) for name, results in runs.items()
        }
        for summary, key in (
            ("accumulated_error", "total_error"),
            ("line_visible_fraction", "visible"),
        )
    }


def training_task(agent: str, seed: int, *readouts: list) -> dict:
    """The task of :func:`training_run` for ``agent`` and ``seed`` with ``readouts``."""
    return {"agent": agent, "seed": seed, "readouts": list(readouts)}


def only_readout(result: dict) -> dict:
    """The result of a :func:`training_run` read once."""
    return result["readouts"][0]


def pooled_training(
    agent: str, seed: int, readouts: list[list], view: Callable[[dict], dict]
) -> SharedRun:
    """The :func:`training_run` of ``agent`` and ``seed`` read at ``readouts``, as a pooled run.

    Every experiment's readouts of one learner and seed pool into one run
    (:class:`~.experiment.SharedRun`'s ``pooled``); ``view`` makes the task's result of its own
    readouts' results.
    """
    return SharedRun(training_run, training_task(agent, seed, *readouts), view, "readouts")


def logged_run(agent: str, seed: int, steps: int) -> SharedRun:
    """The first ``steps`` steps of :func:`training_run`, read as its log (:func:`only_readout`)."""
    return pooled_training(agent, seed, [["log", steps]], only_readout)


@dataclasses.dataclass(frozen=True, kw_only=True)
class LineTask(Task):
    """A learner's run on the line follower: the first ``steps`` of its :func:`training_run`.

    Attributes:
        agent: the learner, one of :data:`LEARNERS`.
        steps: training steps.
    """

    agent: str
    steps: int

    def cost(self) -> float:
        """The run's estimated core-seconds, for scheduling (:func:`training_cost`)."""
        return training_cost(self.agent, self.steps)


def line_tasks(
    config: Config, learners: Sequence[str], steps: int, quick_steps: int
) -> list[LineTask]:
    """Per seed, one :class:`LineTask` of each of ``learners``, ``steps`` steps long.

    ``quick_steps`` long in a quick run (:meth:`~.experiment.Config.run_steps`).
    """
    return seed_tasks(config, learners, LineTask, steps=config.run_steps(steps, quick_steps))


def line_curves(name: str, seed: int, run: dict) -> list[Curve]:
    """A run's two curves for ``curves.csv``: its average reward and its accumulated error.

    Args:
        name: the curves' condition, e.g. the learner.
        seed: the run's seed.
        run: :func:`run_metrics`' ``steps``, ``curve`` and ``error``.
    """
    return [
        Curve(name, seed, run["steps"], run["curve"]),
        Curve(name, seed, run["steps"], run["error"], "accumulated_error"),
    ]


def logged_task_run(task: LineTask) -> SharedRun:
    """The training run behind a :class:`LineTask` (:func:`logged_run`).

    ``linefollow``'s and ``linefollow-deconv``'s tasks are such tasks: their runs of the same
    learner and seed are one, and the start of ``controllers``' and ``real-robot``'s.
    The run's result: :func:`run_metrics`' (``steps``, ``curve``, ``error``, ``average``,
    ``total_error``, ``visible``), ``ns_per_step`` (``learn``'s wall time over the steps),
    ``path`` (``learn``'s) and the agent's delay estimate, if it holds one
    (:func:`~.delay_estimates.delay_estimate`).

    Raises:
        ValueError: the task's agent is not one of :data:`LEARNERS`.
    """
    check_choice("agent", task.agent, LEARNERS)
    return logged_run(task.agent, task.seed, task.steps)


def training_run(task: dict) -> dict:
    """One learner trained in the thesis's setting, read at the steps its readouts name.

    ``linefollow`` and ``linefollow-deconv`` (150k steps), ``controllers`` (300k) and
    ``real-robot`` (500k) train the same learners — :func:`make_agent` on :func:`line_env`, one
    seed each — so their tasks pool their readouts (:class:`~.experiment.SharedRun`'s ``pooled``):
    run together, each (learner, seed) trains once, to the last readout's steps, instead of
    once per experiment. The training runs in pieces that end at each readout's steps
    (``learn(..., reset_num_timesteps=False)``, which trains exactly as one call does), so every
    readout is what a run of its own would give (the thesis's α and ε are constant: a schedule
    would restart with each piece). Its wall times (``ns_per_step``, ``pretrain_seconds``) are
    those of the pieces up to the readout, recording the log where a log readout asks for it.

    Args:
        task: ``agent`` (one of :data:`LEARNERS`), ``seed`` and ``readouts``, a list of

            - ``["log", n]``: the first ``n`` steps of the training itself: :func:`run_metrics`
              of its log, ``ns_per_step`` (``learn``'s wall time over them), ``path``
              (``learn``'s) and the delay estimate at step ``n``;
            - ``["continue", n, setting, steps]``: a copy of the agent at step ``n`` goes on
              for ``steps`` steps on a fresh env of ``setting`` (a key of :data:`SETTINGS`),
              learning on (its first reset uses the agent's seed): the continuation's
              :func:`run_metrics`, and ``pretrain_seconds``, ``learn``'s wall time over the
              first ``n`` steps.

    Returns:
        ``{"readouts": [...]}``, one result per readout, in the task's order.

    Raises:
        TypeError: ``agent`` is not a string.
        ValueError: a readout is none of these, or ``agent`` is not one of :data:`LEARNERS`.
    """
    readouts = task["readouts"]
    for readout in readouts:
        _check_readout(readout)
    logged = max((readout[1] for readout in readouts if readout[0] == "log"), default=0)
    agent = make_agent(task["agent"], line_env(), task["seed"])
    results: list[dict | None] = [None] * len(readouts)
    pieces: list[dict[str, np.ndarray]] = []
    seconds, done = 0.0, 0
    for mark in sorted({readout[1] for readout in readouts}):
        started = time.perf_counter()
        agent.learn(
            mark - done, log_interval=None, reset_num_timesteps=not done, record=mark <= logged
        )
        seconds += time.perf_counter() - started
        done = mark
        if mark <= logged:
            pieces.append({key: agent.training_log[key] for key in ("undelayed_reward", "obs")})
        for index, readout in enumerate(readouts):
            if readout[1] != mark:
                continue
            if readout[0] == "log":
                training = {key: np.concatenate([p[key] for p in pieces]) for key in pieces[0]}
                results[index] = {
                    **run_metrics(training),
                    "ns_per_step": 1e9 * seconds / mark,
                    "path": agent.last_learn_path,
                    **delay_estimate(agent),
                }
            else:
                learner = copy.deepcopy(agent)
                learner.set_env(line_env(env_id=SETTINGS[readout[2]]))
                learner.learn(readout[3], log_interval=None, reset_num_timesteps=False, record=True)
                results[index] = {**run_metrics(learner.training_log), "pretrain_seconds": seconds}
    return {"readouts": results}


def _check_readout(readout: Any) -> None:
    """Raise a ValueError naming ``readout`` unless it is one :func:`training_run` reads."""
    ok = isinstance(readout, list) and len(readout) >= 2 and _whole(readout[1])
    if ok and readout[0] == "log":
        ok = len(readout) == 2
    elif ok and readout[0] == "continue":
        ok = len(readout) == 4 and isinstance(readout[2], str) and readout[2] in SETTINGS
        ok = ok and _whole(readout[3])
    else:
        ok = False
    if not ok:
        raise ValueError(
            f"a readout must be ['log', n] or ['continue', n, setting, steps] with n, steps "
            f"integers >= 1 and setting one of {sorted(SETTINGS)}, got {readout!r}"
        )


def _whole(value: Any) -> bool:
    """Whether ``value`` is an integer (not a bool) of at least 1."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


def run_metrics(log: Any) -> dict:
    """A line-following run's metrics from its ``training_log``.

    They come from its undelayed streams: the average reward during learning (the running mean
    of the undelayed reward, Figs. 5.20, 5.22), and the accumulated error Σ_t |Δ_t| with
    Δ_t = m_t − :data:`CENTRE` for the centroid m_t of the state the agent acts in
    (:func:`line_error`; Figs. 5.21, 5.23). An unseen line, m_t = 0, counts
    |Δ| = :data:`UNSEEN_ERROR`, the largest offset a visible line can have (m = 40), so losing
    the line is never cheaper than seeing it at the camera's edge.

    Returns:
        ``steps`` and ``curve`` (the running average reward), ``error`` (the accumulated error
        at those steps), and over the whole run the ``average`` reward, ``total_error`` and
        the ``visible`` fraction of steps.
    """
    rewards = log["undelayed_reward"]
    steps, curve = running_average(rewards)
    error = np.cumsum(line_error(log["obs"]))
    return {
        "steps": steps,
        "curve": curve,
        "error": error[steps - 1].astype(np.float64),
        "average": float(rewards.mean()),
        "total_error": float(error[-1]),
        "visible": float(np.mean(log["obs"] != 0)),
    }


#: Training cost per step on the line follower (env and learner on the compiled path, µs, with
#: both cores busy), for scheduling only: MMQ's and Q's, and DeconvQ's.
STEP_MICROSECONDS, DECONV_STEP_MICROSECONDS = 7.0, 14.0


def training_cost(agent: str, steps: int) -> float:
    """The estimated core-seconds of ``steps`` steps of ``agent``, for scheduling.

    DeconvQ learned's at :data:`DECONV_STEP_MICROSECONDS` a step, any other's (MMQ, Q, a
    proportional controller) at :data:`STEP_MICROSECONDS`.
    """
    rate = DECONV_STEP_MICROSECONDS if agent == "DeconvQ learned" else STEP_MICROSECONDS
    return 1e-6 * rate * steps
