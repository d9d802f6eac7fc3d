"""``linefollow`` (thesis Figs. 5.20–5.23): Q-learning vs MMQ on the e-puck line follower, λ = 90.

The thesis's setting (section 5.2.4): ``delayed_rl/EPuckLineFollow-v0`` on the ``racetrack``
with the discrete Table 5.2 actions (|A| = 7) and the centroid state of Eq. 5.6 (|S| = 41, with
0 for "line not seen"), a Poisson(90) reward delay, 150k training steps, 5 runs; MMQ considers
λ̂ ∈ {0, 1, ..., 150} (λ̂max = 150). The thesis's experimenters put the robot back on the track
by hand when it was lost; here ``lost_line="recover"`` does that (after 50 line-less steps), and
``max_steps=None`` makes the task continuing, as in the thesis.

Hyper-parameters are the thesis's Algorithm 1 values, as in the grid-world experiments:
α = 0.1, γ = 0.9, constant ε = 0.1, and an optimistic ``q_init`` = 10 = 1 / (1 − γ), the largest
discounted return when every reward is at most 1 (the thesis does not print its values for
the e-puck).

Metrics come from the undelayed streams of ``training_log`` (``learn(..., record=True)``):

- average reward during learning: the running mean of the undelayed reward (Figs. 5.20, 5.22);
- accumulated error: Σ_t |Δ_t| with Δ_t = m_t − 20 for the centroid m_t of the state the agent
  acts in at step t (Figs. 5.21, 5.23). When the line is not seen (m_t = 0) the step counts
  |Δ| = 20, the largest offset a visible line can have (m = 40), so losing the line is never
  cheaper than seeing it at the camera's edge. Observations are not delayed, so ``obs`` is the
  undelayed observation stream.
"""

from __future__ import annotations

import copy
import time
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._validation import check_choice
from delayed_rl.experiments import plotting
from delayed_rl.experiments.anonymous_delay import delay_estimate
from delayed_rl.experiments.common import band_claim, direction_claim, mean_ci_n, seed_tasks
from delayed_rl.experiments.runner import (
    Config,
    Curve,
    Experiment,
    SharedRun,
    Summary,
    mean_ci95,
    running_average,
)
from delayed_rl.experiments.training import ALPHA, EPSILON, GAMMA, thesis_hyperparameters

ENV_ID = "delayed_rl/EPuckLineFollow-v0"
#: The stand-in robot of ``real-robot`` (:mod:`delayed_rl.experiments.real_robot`).
REAL_ENV_ID = "delayed_rl/EPuckLineFollowReal-v0"
#: What a trained agent can continue on (:func:`training_run`): the clean simulation, the robot.
SETTINGS = {"clean": ENV_ID, "real": REAL_ENV_ID}
TRACK = "racetrack"
LAM, LAMBDA_MAX = 90, 150
#: The optimistic initial value, 1 / (1 − γ) (see the module docstring; α, γ and ε are the
#: thesis's, :mod:`delayed_rl.experiments.training`).
Q_INIT = 10.0
CENTRE, UNSEEN_ERROR = 20, 20
#: The learners compared.
AGENTS = ("MMQ", "Q")
#: The learners :func:`make_agent` makes: these and ``linefollow-deconv``'s DeconvQ.
LEARNERS = (*AGENTS, "DeconvQ learned")
#: The band of the average-reward claims (and of MMQ − Q): the thesis's value ± this.
REWARD_TOLERANCE = 0.2
#: The band of the accumulated-error ratio: 0.4 ± this.
RATIO_TOLERANCE = 0.15
#: The thesis's 5-run average rewards during learning (Fig. 5.22).
THESIS_REWARD = {"MMQ": 0.55, "Q": 0.12}
#: The thesis's MMQ accumulated error over Q's (Fig. 5.23: "only about 40 %").
THESIS_ERROR_RATIO = 0.4


def line_env(reward_delay: float | None = LAM, env_id: str = ENV_ID, **kwargs: Any) -> gym.Env:
    """The thesis's line-following env: racetrack, manual resets, continuing, reward delay λ.

    Args:
        reward_delay: the Poisson mean λ of the reward delay (``None``: undelayed).
        env_id: the e-puck's id: the simulation (default) or :data:`REAL_ENV_ID`.
        **kwargs: other ``EPuckLineFollow`` arguments (e.g. ``action_mode="continuous"``).
    """
    import delayed_rl  # noqa: F401  (registers the ids)

    options = {"track": TRACK, "lost_line": "recover", "max_steps": None, **kwargs}
    return gym.make(env_id, reward_delay=reward_delay, **options)


def make_agent(kind: str, env: gym.Env, seed: int) -> Any:
    """A thesis-setting learner on ``env``, one of :data:`LEARNERS`.

    ``"Q"`` (Q-learning), ``"MMQ"`` (Λ = {0, ..., 150}) or ``"DeconvQ learned"``
    (:class:`~DeconvolutionQLearning` learning the delay on 0..150), with the thesis's
    hyper-parameters and ``q_init`` = :data:`Q_INIT`.

    Raises:
        TypeError: ``kind`` is not a string.
        ValueError: ``kind`` is not one of :data:`LEARNERS`.
    """
    from delayed_rl.agents import DeconvolutionQLearning, MultipleModelQLearning, QLearning

    check_choice("kind", kind, LEARNERS)
    common = thesis_hyperparameters(seed, q_init=Q_INIT)
    if kind == "Q":
        return QLearning(env, **common)
    if kind == "MMQ":
        return MultipleModelQLearning(env, max_delay_estimate=LAMBDA_MAX, **common)
    return DeconvolutionQLearning(env, delay=None, max_delay=LAMBDA_MAX, **common)


def line_error(centroids: np.ndarray) -> np.ndarray:
    """|Δ| = |m − 20| per step, and 20 where the line is not seen (m = 0)."""
    centroids = np.asarray(centroids, dtype=np.int64)
    return np.where(centroids == 0, UNSEEN_ERROR, np.abs(centroids - CENTRE))


def line_statistics(runs: dict[str, list[dict]]) -> dict[str, dict[str, tuple[float, float]]]:
    """Mean and 95 % CI, per contestant, of the accumulated error and of the line's visibility.

    Args:
        runs: each contestant's run results, with ``total_error`` (Σ|Δ| over the run) and
            ``visible`` (the fraction of steps that saw the line).

    Returns:
        ``{"accumulated_error": {name: (mean, ci)}, "line_visible_fraction": {name: (mean, ci)}}``.
    """
    return {
        summary: {name: mean_ci95([r[key] for r in results]) for name, results in runs.items()}
        for summary, key in (
            ("accumulated_error", "total_error"),
            ("line_visible_fraction", "visible"),
        )
    }


def tasks(config: Config) -> list[dict]:
    """Per seed: one Q-learning and one MMQ run, 150k steps each (3k with ``config.quick``)."""
    steps = config.steps or (3_000 if config.quick else 150_000)
    return seed_tasks(config, AGENTS, steps=steps)


def run_task(task: dict) -> dict:
    """Train one learner on the line follower and measure the run (:func:`training_run`).

    Returns:
        :func:`run_metrics`'s (``steps``, ``curve``, ``error``, ``average``, ``total_error``,
        ``visible``), ``ns_per_step`` (``learn``'s wall time over the steps), ``path``
        (``learn``'s) and the agent's delay estimate, if it holds one
        (:func:`~delayed_rl.experiments.anonymous_delay.delay_estimate`).
    """
    return shared_run(task).alone()


def shared_run(task: dict) -> SharedRun:
    """The task's :func:`training_run`, pooled with the other line-following experiments'."""
    run = training_task(task["agent"], task["seed"], ["log", task["steps"]])
    return SharedRun(training_run, run, only_readout, "readouts")


def only_readout(result: dict) -> dict:
    """The result of a :func:`training_run` read once."""
    return result["readouts"][0]


def training_task(agent: str, seed: int, *readouts: list) -> dict:
    """The task of :func:`training_run` for ``agent`` and ``seed`` with ``readouts``."""
    return {"agent": agent, "seed": seed, "readouts": list(readouts)}


def training_run(task: dict) -> dict:
    """One learner trained in the thesis's setting, read at the steps its readouts name.

    ``linefollow`` and ``linefollow-deconv`` (150k steps), ``controllers`` (300k) and
    ``real-robot`` (500k) train the same learners — :func:`make_agent` on :func:`line_env`, one
    seed each — so their tasks pool their readouts (:class:`~.runner.SharedRun`'s ``pooled``):
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


#: Training cost per step on the line follower (env and learner on the compiled path, µs, with
#: both cores busy), for scheduling only.
STEP_MICROSECONDS = 7.0


def cost(task: dict) -> float:
    """A task's estimated core-seconds: its steps at :data:`STEP_MICROSECONDS`."""
    return 1e-6 * STEP_MICROSECONDS * task["steps"]


def run_metrics(log: Any) -> dict:
    """A line-following run's metrics from its ``training_log``.

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


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """Figs. 5.22–5.23's claims: each agent's average reward, MMQ − Q, and the error ratio.

    The difference and the ratio are paired by seed (MMQ and Q of one seed start alike). The
    values are tested against the thesis's bands (its value ± :data:`REWARD_TOLERANCE`, or
    ± :data:`RATIO_TOLERANCE` for the ratio); MMQ − Q twice: against the band of +0.43, and
    for its sign alone (MMQ above Q).
    """
    runs: dict[str, list[dict]] = {agent: [] for agent in AGENTS}
    curves = []
    for task, result in zip(task_list, results, strict=True):
        runs[task["agent"]].append(result)
        steps = result["steps"]
        curves.append(Curve(task["agent"], task["seed"], steps, result["curve"]))
        curves.append(
            Curve(task["agent"], task["seed"], steps, result["error"], "accumulated_error")
        )
    stat = {agent: mean_ci_n([r["average"] for r in rs]) for agent, rs in runs.items()}
    pairs = list(zip(runs["MMQ"], runs["Q"], strict=True))
    ratio = mean_ci_n([m["total_error"] / q["total_error"] for m, q in pairs])
    gap = mean_ci_n([m["average"] - q["average"] for m, q in pairs])
    claims = [
        band_claim(
            "MMQ average reward during learning",
            "≈ 0.55 (Fig. 5.22)",
            stat["MMQ"],
            THESIS_REWARD["MMQ"],
            REWARD_TOLERANCE,
        ),
        band_claim(
            "Q average reward during learning",
            "≈ 0.12 (Fig. 5.22)",
            stat["Q"],
            THESIS_REWARD["Q"],
            REWARD_TOLERANCE,
        ),
        band_claim(
            "MMQ minus Q average reward (paired by seed)",
            "≈ +0.43 (Fig. 5.22: 0.55 − 0.12)",
            gap,
            0.43,
            REWARD_TOLERANCE,
        ),
        direction_claim(
            "MMQ above Q: MMQ minus Q average reward (paired by seed)",
            "> 0, MMQ above Q (Fig. 5.22)",
            gap,
            "above",
        ),
        band_claim(
            "MMQ accumulated error / Q accumulated error",
            "≈ 0.4 (Fig. 5.23)",
            ratio,
            THESIS_ERROR_RATIO,
            RATIO_TOLERANCE,
            note=f"paired by seed; an unseen line counts |Δ| = {UNSEEN_ERROR}",
        ),
    ]
    extra = {
        **line_statistics(runs),
        "hyperparameters": {
            "alpha": ALPHA,
            "gamma": GAMMA,
            "epsilon": EPSILON,
            "q_init": Q_INIT,
            "lambda": LAM,
            "lambda_max": LAMBDA_MAX,
            "track": TRACK,
            "lost_line": "recover",
        },
    }
    return Summary(claims, curves, _figures(runs, config.seeds), extra)


def _figures(runs: dict[str, list[dict]], seeds: int) -> dict:
    """Figs. 5.20–5.23: reward and accumulated error, of the first seed and of every seed.

    Every panel carries the thesis's 5-run values (Figs. 5.22–5.23): the average rewards as
    dashed levels, the error ratio as a dashed curve, ``THESIS_ERROR_RATIO`` × Q's error.
    """
    rewards = {a: [(r["steps"], r["curve"]) for r in rs] for a, rs in runs.items()}
    errors = {a: [(r["steps"], r["error"]) for r in rs] for a, rs in runs.items()}
    first_rewards = {a: rs[:1] for a, rs in rewards.items()}
    first_errors = {a: rs[:1] for a, rs in errors.items()}
    title = f"line following, Poisson delays of mean λ = {LAM}, MMQ with λ̂max = {LAMBDA_MAX}"
    every = f"{seeds} runs"
    reward_label, error_label = (
        "average reward (undelayed stream)",
        "accumulated error Σ|Δ| (pixels)",
    )
    levels = thesis_reward_lines()
    ratios = thesis_error_ratio_lines()
    curves = plotting.learning_curves
    return {
        "fig5_20_single_run_reward": plotting.figure(
            curves, first_rewards, f"{title}: first seed (Fig. 5.20)", reward_label, levels
        ),
        "fig5_21_single_run_error": plotting.figure(
            curves,
            first_errors,
            f"{title}: first seed (Fig. 5.21)",
            error_label,
            thesis_ratios=ratios,
        ),
        "fig5_22_average_reward": plotting.figure(
            curves, rewards, f"{title}: {every} (Fig. 5.22)", reward_label, levels
        ),
        "fig5_23_accumulated_error": plotting.figure(
            curves, errors, f"{title}: {every} (Fig. 5.23)", error_label, thesis_ratios=ratios
        ),
    }


def thesis_reward_lines() -> list[tuple[float, str, str]]:
    """The thesis's average rewards (Fig. 5.22) as :func:`.plotting.learning_curves` lines."""
    return [
        (value, f"thesis {agent} ≈ {value} (Fig. 5.22, 5-run mean)", agent)
        for agent, value in THESIS_REWARD.items()
    ]


def thesis_error_ratio_lines() -> list[tuple[str, float, str, str]]:
    """The thesis's error ratio (Fig. 5.23) as a :func:`.plotting.learning_curves` ratio curve."""
    label = f"thesis MMQ = {THESIS_ERROR_RATIO} × Q's error (Fig. 5.23)"
    return [("Q", THESIS_ERROR_RATIO, label, "MMQ")]


EXPERIMENT = Experiment(
    name="linefollow",
    thesis="Figs. 5.20–5.23",
    description="Q-learning against MMQ (λ̂max = 150) on the e-puck line follower (racetrack, "
    "discrete Table 5.2 actions, centroid states, put back on the track after 50 line-less "
    "steps) with Poisson(90) reward delays, 150k steps per run; α = 0.1, γ = 0.9, ε = 0.1, "
    "q_init = 10. Average reward from the undelayed reward stream; accumulated error Σ|Δ|, "
    "Δ = m − 20, with an unseen line counted as |Δ| = 20.",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=5,
    shared_run=shared_run,
    cost=cost,
)
