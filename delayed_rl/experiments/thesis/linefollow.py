"""``linefollow`` (thesis Figs. 5.20–5.23): Q-learning vs MMQ on the e-puck line follower, λ = 90.

The thesis's setting (section 5.2.4): ``delayed_rl/EPuckLineFollow-v0`` on the ``racetrack``
with the discrete Table 5.2 actions (|A| = 7) and the centroid state of Eq. 5.6 (|S| = 41, with
0 for "line not seen"), a Poisson(90) reward delay, 150k training steps, 5 runs; MMQ considers
λ̂ ∈ {0, 1, ..., 150} (λ̂max = 150). The thesis's experimenters put the robot back on the track
by hand when it was lost; here ``lost_line="recover"`` does that (after 50 line-less steps), and
``max_steps=None`` makes the task continuing, as in the thesis.

The setting, the learners, the training run (which ``linefollow-deconv``, ``controllers`` and
``real-robot`` pool with this experiment's) and the metrics are the framework's
(:mod:`~delayed_rl.experiments.framework.line_following`); the thesis's values and their bands
too (:mod:`~delayed_rl.experiments.framework.line_claims`).

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

from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.claims import band_claim, direction_claim, mean_ci_n, paired
from delayed_rl.experiments.framework.experiment import (
    Config,
    Curve,
    Experiment,
    SharedRun,
    Summary,
    seed_tasks,
)
from delayed_rl.experiments.framework.line_claims import (
    REWARD_TOLERANCE,
    error_ratio_claim,
    reward_claims,
    thesis_error_ratio_lines,
    thesis_reward_lines,
)
from delayed_rl.experiments.framework.line_following import (
    LAM,
    LAMBDA_MAX,
    Q_INIT,
    TRACK,
    UNSEEN_ERROR,
    line_statistics,
    logged_run,
    training_cost,
)
from delayed_rl.experiments.framework.results import pivot
from delayed_rl.experiments.framework.training import ALPHA, EPSILON, GAMMA

#: The learners compared.
LEARNERS = ("MMQ", "Q")


def tasks(config: Config) -> list[dict]:
    """Per seed: one Q-learning and one MMQ run, 150k steps each (3k with ``config.quick``)."""
    steps = config.steps or (3_000 if config.quick else 150_000)
    return seed_tasks(config, LEARNERS, steps=steps)


def run_task(task: dict) -> dict:
    """Train one learner on the line follower and measure the run (its :func:`shared_run`).

    Returns:
        :func:`~.line_following.run_metrics`' (``steps``, ``curve``, ``error``, ``average``,
        ``total_error``, ``visible``), ``ns_per_step`` (``learn``'s wall time over the steps), ``path``
        (``learn``'s) and the agent's delay estimate, if it holds one
        (:func:`~.delay_estimates.delay_estimate`).
    """
    return shared_run(task).alone()


def shared_run(task: dict) -> SharedRun:
    """The task's training run, pooled with the other e-puck experiments' (:func:`~.logged_run`)."""
    return logged_run(task["agent"], task["seed"], task["steps"])


def cost(task: dict) -> float:
    """A task's estimated core-seconds, for scheduling (:func:`~.line_following.training_cost`)."""
    return training_cost(task["agent"], task["steps"])


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """Figs. 5.22–5.23's claims: each agent's average reward, MMQ − Q, and the error ratio.

    The difference and the ratio are paired by seed (MMQ and Q of one seed start alike). The
    values are tested against the thesis's bands (its value
    ± :data:`~.line_claims.REWARD_TOLERANCE`, or ± :data:`~.line_claims.RATIO_TOLERANCE` for the
    ratio); MMQ − Q twice: against the band of +0.43, and for its sign alone (MMQ above Q).
    """
    by_agent = pivot(task_list, results, by=("agent",))
    runs = {agent: by_agent[agent] for agent in LEARNERS}
    curves = []
    for task, result in zip(task_list, results, strict=True):
        agent, seed, steps = task["agent"], task["seed"], result["steps"]
        curves.append(Curve(agent, seed, steps, result["curve"]))
        curves.append(Curve(agent, seed, steps, result["error"], "accumulated_error"))
    stat = {agent: mean_ci_n([r["average"] for r in rs.values()]) for agent, rs in runs.items()}
    errors = pivot(task_list, results, by=("agent",), value="total_error")
    averages = pivot(task_list, results, by=("agent",), value="average")
    ratio = mean_ci_n(paired(errors["MMQ"], errors["Q"], "ratio"))
    gap = mean_ci_n(paired(averages["MMQ"], averages["Q"]))
    claims = [
        *reward_claims(stat),
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
        error_ratio_claim(ratio, f"paired by seed; an unseen line counts |Δ| = {UNSEEN_ERROR}"),
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


def _figures(runs: dict[str, dict[int, dict]], seeds: int) -> dict:
    """Figs. 5.20–5.23: reward and accumulated error, of the first seed and of every seed.

    Every panel carries the thesis's 5-run values (Figs. 5.22–5.23): the average rewards as
    dashed levels, the error ratio as a dashed curve, ``THESIS_ERROR_RATIO`` × Q's error.
    """
    rewards = {a: [(r["steps"], r["curve"]) for r in rs.values()] for a, rs in runs.items()}
    errors = {a: [(r["steps"], r["error"]) for r in rs.values()] for a, rs in runs.items()}
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
