"""``linefollow`` (thesis Figs. 5.20–5.23): Q-learning against MMQ on the e-puck line follower.

The setting, the learners, the training run (which ``linefollow-deconv``, ``controllers`` and
``real-robot`` pool with this experiment's) and the metrics are the framework's
(:mod:`~delayed_rl.experiments.framework.line_following`); the thesis's values and their bands
too (:mod:`~delayed_rl.experiments.framework.line_claims`). The numbers are the constants
``EXPERIMENT.description`` is formatted from (:data:`STEPS`, and the framework's); the claims
are in :func:`summarize`.
"""

from __future__ import annotations

from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.claims import band_claim, direction_claim, mean_ci_n, paired
from delayed_rl.experiments.framework.experiment import Config, Experiment, Summary, step_count
from delayed_rl.experiments.framework.line_claims import (
    REWARD_TOLERANCE,
    error_ratio_claim,
    reward_claims,
    thesis_error_ratio_lines,
    thesis_reward_lines,
)
from delayed_rl.experiments.framework.line_following import (
    CENTRE,
    LAM,
    LAMBDA_MAX,
    LOST_LINE_STEPS,
    Q_INIT,
    TRACK,
    UNSEEN_ERROR,
    LineTask,
    line_curves,
    line_statistics,
    line_tasks,
    logged_task_run,
)
from delayed_rl.experiments.framework.results import pivot
from delayed_rl.experiments.framework.training import (
    ALPHA,
    EPSILON,
    GAMMA,
    hyperparameter_text,
)

#: The learners compared.
LEARNERS = ("MMQ", "Q")
#: The steps of a run (the thesis's), and of a quick run.
STEPS, QUICK_STEPS = 150_000, 3_000


def tasks(config: Config) -> list[LineTask]:
    """Per seed: one Q-learning and one MMQ run, :data:`STEPS` each (:data:`QUICK_STEPS` quick)."""
    return line_tasks(config, LEARNERS, STEPS, QUICK_STEPS)


def summarize(task_list: list[LineTask], results: list[dict], config: Config) -> Summary:
    """Figs. 5.22–5.23's claims: each agent's average reward, MMQ − Q, and the error ratio.

    The difference and the ratio are paired by seed (MMQ and Q of one seed start alike). The
    values are tested against the thesis's bands (its value
    ± :data:`~.line_claims.REWARD_TOLERANCE`, or ± :data:`~.line_claims.RATIO_TOLERANCE` for the
    ratio); MMQ − Q twice: against the band of +0.43, and for its sign alone (MMQ above Q).
    """
    by_agent = pivot(task_list, results, by=("agent",))
    runs = {agent: by_agent[agent] for agent in LEARNERS}
    curves = [
        curve
        for task, result in zip(task_list, results, strict=True)
        for curve in line_curves(task.agent, task.seed, result)
    ]
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
            "max_delay_estimate": LAMBDA_MAX,
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
    description=f"Q-learning against MMQ (λ̂max = {LAMBDA_MAX}) on the e-puck line follower "
    f"({TRACK}, discrete Table 5.2 actions, centroid states, put back on the track after "
    f"{LOST_LINE_STEPS} line-less steps) with Poisson({LAM}) reward delays, "
    f"{step_count(STEPS)} steps per run; {hyperparameter_text(Q_INIT)}. Average reward from the "
    f"undelayed reward stream; accumulated error Σ|Δ|, Δ = m − {CENTRE}, with an unseen line "
    f"counted as |Δ| = {UNSEEN_ERROR}.",
    tasks=tasks,
    summarize=summarize,
    default_seeds=5,
    shared_run=logged_task_run,
)
