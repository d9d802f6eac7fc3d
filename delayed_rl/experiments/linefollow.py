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

from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl.experiments import plotting
from delayed_rl.experiments.common import claim
from delayed_rl.experiments.runner import (
    Config,
    Curve,
    Experiment,
    Summary,
    mean_ci95,
    running_average,
)

ENV_ID = "delayed_rl/EPuckLineFollow-v0"
TRACK = "racetrack"
LAM, LAMBDA_MAX = 90, 150
ALPHA, GAMMA, EPSILON, Q_INIT = 0.1, 0.9, 0.1, 10.0
CENTRE, UNSEEN_ERROR = 20, 20
AGENTS = ("MMQ", "Q")
#: The verdict rule of the average-reward claims: |measured − thesis| ≤ this.
REWARD_TOLERANCE = 0.2
#: The verdict rule of the accumulated-error ratio: |measured − 0.4| ≤ this.
RATIO_TOLERANCE = 0.15


def line_env(reward_delay: float | None = LAM, **kwargs: Any) -> gym.Env:
    """The thesis's line-following env: racetrack, manual resets, continuing, reward delay λ.

    Args:
        reward_delay: the Poisson mean λ of the reward delay (``None``: undelayed).
        **kwargs: other ``EPuckLineFollow`` arguments (e.g. ``action_mode="continuous"``).
    """
    import delayed_rl  # noqa: F401  (registers the ids)

    return gym.make(
        ENV_ID, track=TRACK, lost_line="recover", max_steps=None, reward_delay=reward_delay,
        **kwargs,
    )  # fmt: skip


def make_agent(kind: str, env: gym.Env, seed: int) -> Any:
    """A thesis-setting learner: ``"Q"`` (Q-learning) or ``"MMQ"`` (Λ = {0, ..., 150})."""
    from delayed_rl.agents import MultipleModelQLearning, QLearning

    common = {"learning_rate": ALPHA, "gamma": GAMMA, "exploration_initial_eps": EPSILON,
              "exploration_final_eps": EPSILON, "q_init": Q_INIT, "seed": seed}  # fmt: skip
    if kind == "Q":
        return QLearning(env, **common)
    if kind == "MMQ":
        return MultipleModelQLearning(env, max_delay_estimate=LAMBDA_MAX, **common)
    raise ValueError(f"agent kind must be one of {AGENTS}, got {kind!r}")


def line_error(centroids: np.ndarray) -> np.ndarray:
    """|Δ| = |m − 20| per step, and 20 where the line is not seen (m = 0)."""
    centroids = np.asarray(centroids, dtype=np.int64)
    return np.where(centroids == 0, UNSEEN_ERROR, np.abs(centroids - CENTRE))


def tasks(config: Config) -> list[dict]:
    steps = config.steps or (3_000 if config.quick else 150_000)
    return [
        {"agent": agent, "steps": steps, "seed": config.base_seed + i}
        for i in range(config.seeds)
        for agent in AGENTS
    ]


def run_task(task: dict) -> dict:
    agent = make_agent(task["agent"], line_env(), task["seed"])
    agent.learn(task["steps"], log_interval=None, record=True)
    log = agent.training_log
    steps, curve = running_average(log["undelayed_reward"])
    error = np.cumsum(line_error(log["obs"]))
    return {
        "steps": steps,
        "curve": curve,
        "error": error[steps - 1].astype(np.float64),
        "average": float(log["undelayed_reward"].mean()),
        "total_error": float(error[-1]),
        "visible": float(np.mean(log["obs"] != 0)),
    }


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    runs: dict[str, list[tuple[int, dict]]] = {agent: [] for agent in AGENTS}
    for task, result in zip(task_list, results, strict=True):
        runs[task["agent"]].append((task["seed"], result))
    curves = []
    for agent, agent_runs in runs.items():
        for seed, r in agent_runs:
            curves.append(Curve(agent, seed, r["steps"], r["curve"], "average_reward"))
            curves.append(Curve(agent, seed, r["steps"], r["error"], "accumulated_error"))
    stat = {a: mean_ci95([r["average"] for _, r in rs]) + (len(rs),) for a, rs in runs.items()}
    ratios = [m["total_error"] / q["total_error"]
              for (_, m), (_, q) in zip(runs["MMQ"], runs["Q"], strict=True)]  # fmt: skip
    gaps = [m["average"] - q["average"]
            for (_, m), (_, q) in zip(runs["MMQ"], runs["Q"], strict=True)]  # fmt: skip
    ratio, gap = mean_ci95(ratios) + (len(ratios),), mean_ci95(gaps) + (len(gaps),)
    rule = f"agrees when |measured − thesis| ≤ {REWARD_TOLERANCE}"
    claims = [
        claim("MMQ average reward during learning", "≈ 0.55 (Fig. 5.22)", stat["MMQ"],
              ok=abs(stat["MMQ"][0] - 0.55) <= REWARD_TOLERANCE, note=rule),
        claim("Q average reward during learning", "≈ 0.12 (Fig. 5.22)", stat["Q"],
              ok=abs(stat["Q"][0] - 0.12) <= REWARD_TOLERANCE, note=rule),
        claim("MMQ minus Q average reward (paired by seed)", "≈ +0.43, MMQ above Q", gap,
              ok=gap[0] - gap[1] > 0,
              note="agrees when the 95 % CI of the paired difference lies above 0"),
        claim("MMQ accumulated error / Q accumulated error", "≈ 0.4 (Fig. 5.23)", ratio,
              ok=abs(ratio[0] - 0.4) <= RATIO_TOLERANCE,
              note=f"paired by seed; agrees when |measured − 0.4| ≤ {RATIO_TOLERANCE}; "
              f"an unseen line counts |Δ| = {UNSEEN_ERROR}"),
    ]  # fmt: skip
    rewards = {a: [(r["steps"], r["curve"]) for _, r in rs] for a, rs in runs.items()}
    errors = {a: [(r["steps"], r["error"]) for _, r in rs] for a, rs in runs.items()}
    title = f"line following, λ = {LAM}, λ̂max = {LAMBDA_MAX}"
    figures = {
        "fig5_20_single_run_reward": lambda path: plotting.learning_curves(
            path, {a: rs[:1] for a, rs in rewards.items()},
            f"{title}: first seed (Fig. 5.20)", "average reward"),
        "fig5_21_single_run_error": lambda path: plotting.learning_curves(
            path, {a: rs[:1] for a, rs in errors.items()},
            f"{title}: first seed (Fig. 5.21)", "accumulated error Σ|Δ| (pixels)"),
        "fig5_22_average_reward": lambda path: plotting.learning_curves(
            path, rewards, f"{title}: {config.seeds} runs, 95 % band (Fig. 5.22)",
            "average reward"),
        "fig5_23_accumulated_error": lambda path: plotting.learning_curves(
            path, errors, f"{title}: {config.seeds} runs, 95 % band (Fig. 5.23)",
            "accumulated error Σ|Δ| (pixels)"),
    }  # fmt: skip
    extra = {
        "accumulated_error": {a: mean_ci95([r["total_error"] for _, r in rs])
                              for a, rs in runs.items()},
        "line_visible_fraction": {a: mean_ci95([r["visible"] for _, r in rs])
                                  for a, rs in runs.items()},
        "hyperparameters": {"alpha": ALPHA, "gamma": GAMMA, "epsilon": EPSILON,
                            "q_init": Q_INIT, "lambda": LAM, "lambda_max": LAMBDA_MAX,
                            "track": TRACK, "lost_line": "recover"},
    }  # fmt: skip
    return Summary(claims, curves, figures, extra)


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
)
