"""``linefollow-deconv`` (beyond the thesis): deconvolution Q-learning on the e-puck line follower.

A module of its own (not a setting of ``anonymous-delay``): the e-puck runs share nothing with
the grid worlds but the agents. The setting, training run and metrics are ``linefollow``'s (the
framework's :mod:`~delayed_rl.experiments.framework.line_following`); MMQ's and Q's runs are
``linefollow``'s, which ``delayed-rl bench all`` runs once for both. The learners are
:data:`LEARNERS`, the numbers the constants ``EXPERIMENT.description`` is formatted from
(:data:`STEPS`, and the framework's); the claims, fixed before the runs, are in :func:`summarize`.
"""

from __future__ import annotations

import numpy as np

from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.claims import (
    direction_claim,
    mean_ci_n,
    paired,
    reference_row,
)
from delayed_rl.experiments.framework.delay_estimates import ESTIMATE_LABELS, mean_delay_claim
from delayed_rl.experiments.framework.experiment import Config, Experiment, Summary, step_count
from delayed_rl.experiments.framework.line_claims import (
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
    LineTask,
    line_curves,
    line_statistics,
    line_tasks,
    logged_task_run,
)
from delayed_rl.experiments.framework.results import pivot
from delayed_rl.experiments.framework.training import hyperparameter_text

LEARNERS = ("MMQ", "DeconvQ learned", "Q")
"""The learners compared, with the thesis's hyper-parameters and ``q_init`` = 1 / (1 − γ).

- ``MMQ``: Λ = {0, ..., λ̂max} (the thesis's λ̂max);
- ``DeconvQ learned``: :class:`~delayed_rl.agents.DeconvolutionQLearning` learning the delay
  on 0..λ̂max (``max_delay_estimate`` = λ̂max, the same horizon), never told it is Poisson;
- ``Q``: Q-learning on the delayed reward.

Every learner's run is also the start of ``controllers``' and ``real-robot``'s longer training
(:func:`~.line_following.training_run`: run together, each learner and seed trains once).
"""
#: The steps of a quick run, and of a full one.
QUICK_STEPS, STEPS = 5_000, 150_000


def tasks(config: Config) -> list[LineTask]:
    """Per seed, one run of each of :data:`LEARNERS`: :data:`STEPS` (:data:`QUICK_STEPS` quick)."""
    return line_tasks(config, LEARNERS, STEPS, QUICK_STEPS)


def _paired(runs: dict[str, dict[int, dict]], ours: str, theirs: str, how: str) -> tuple:
    """(mean, CI, n) by seed of ``ours − theirs`` (average reward) or ``ours / theirs`` (error).

    ``how="difference"`` pairs the average rewards, ``"ratio"`` the accumulated errors, over
    the seeds both agents ran.
    """
    key = "average" if how == "difference" else "total_error"
    values = [{seed: r[key] for seed, r in runs[name].items()} for name in (ours, theirs)]
    return mean_ci_n(paired(*values, how=how))


def summarize(task_list: list[LineTask], results: list[dict], config: Config) -> Summary:
    """The claims, per-agent statistics in ``extra`` and the figures.

    Metrics, as ``linefollow``'s (:func:`~.line_following.run_metrics`): the average reward
    during learning and the accumulated error Σ|Δ|, plus the delay estimate (DeconvQ's
    ``delay_pmf`` and ``mean_delay``, MMQ's acting-delay share and its mean) and ns/step
    (``learn``'s wall time over the steps, on the compiled path). The claims, fixed before the
    runs, with verdicts by :mod:`~.framework.claims`' rules (each row's ``criterion`` states
    its own):

    - MMQ's and Q's average rewards against the thesis's (Fig. 5.22), and MMQ's accumulated
      error over Q's (Fig. 5.23): ``linefollow``'s bands
      (:mod:`~delayed_rl.experiments.framework.line_claims`);
    - DeconvQ learned's average reward: a ``reference`` row (no thesis value; the next rows
      test it);
    - DeconvQ learned minus Q, and minus MMQ, average reward (paired by seed): the direction
      rule, above 0;
    - DeconvQ learned's accumulated error over MMQ's (paired by seed): the direction rule,
      below 1 (DeconvQ keeps closer to the line);
    - DeconvQ learned's mean delay: the band λ ± 10 %.

    Whichever way they fall, the numbers are in the report and in ``summary.json``.
    """
    by_agent = pivot(task_list, results, by=("agent",))
    runs = {agent: by_agent.get(agent, {}) for agent in LEARNERS}
    curves = [
        curve
        for task, result in zip(task_list, results, strict=True)
        for curve in line_curves(task.agent, task.seed, result)
    ]
    return Summary(_claims(runs), curves, _figures(runs), _statistics(runs))


def _claims(runs: dict[str, dict[int, dict]]) -> list:
    """The claims of the module docstring, from each agent's runs by seed."""
    stat = {agent: mean_ci_n([r["average"] for r in rs.values()]) for agent, rs in runs.items()}
    over_mmq = _paired(runs, "DeconvQ learned", "MMQ", "difference")
    over_q = _paired(runs, "DeconvQ learned", "Q", "difference")
    delays = mean_ci_n([r["mean_delay"] for r in runs["DeconvQ learned"].values()])
    return [
        *reward_claims(stat),
        reference_row(
            "DeconvQ learned average reward during learning",
            stat["DeconvQ learned"],
            "extension: no thesis value (the next rows compare it)",
        ),
        direction_claim(
            "DeconvQ learned minus Q average reward",
            "extension: DeconvQ above Q",
            over_q,
            "above",
            note="paired by seed",
        ),
        direction_claim(
            "DeconvQ learned minus MMQ average reward",
            "extension: DeconvQ above MMQ",
            over_mmq,
            "above",
            note="paired by seed",
        ),
        direction_claim(
            "DeconvQ learned accumulated error / MMQ accumulated error",
            "extension: below 1",
            _paired(runs, "DeconvQ learned", "MMQ", "ratio"),
            "below",
            1.0,
            note="paired by seed",
        ),
        error_ratio_claim(_paired(runs, "MMQ", "Q", "ratio"), "paired by seed"),
        mean_delay_claim("DeconvQ learned mean delay", delays, LAM),
    ]


def _statistics(by_seed: dict[str, dict[int, dict]]) -> dict:
    """``summary.json``'s statistics per agent: line, reward, ns/step, mean delay, paths."""
    runs = {agent: list(rs.values()) for agent, rs in by_seed.items()}
    return {
        **line_statistics(by_seed),
        "average_reward": {a: mean_ci_n([r["average"] for r in rs])[:2] for a, rs in runs.items()},
        "ns_per_step": {a: mean_ci_n([r["ns_per_step"] for r in rs])[:2] for a, rs in runs.items()},
        "mean_delay": {
            a: mean_ci_n([r["mean_delay"] for r in rs])[:2]
            for a, rs in runs.items()
            if rs and all("mean_delay" in r for r in rs)
        },
        "paths": {a: sorted({r["path"] for r in rs}) for a, rs in runs.items()},
    }


def _figures(by_seed: dict[str, dict[int, dict]]) -> dict:
    """Reward and accumulated-error curves with 95 % bands; the delay estimates over the true pmf."""
    from delayed_rl.delays import Poisson

    runs = {agent: list(rs.values()) for agent, rs in by_seed.items()}
    title = f"line following, Poisson delays of mean λ = {LAM}, λ̂max = {LAMBDA_MAX}"
    rewards = {a: [(r["steps"], r["curve"]) for r in rs] for a, rs in runs.items()}
    errors = {a: [(r["steps"], r["error"]) for r in rs] for a, rs in runs.items()}
    estimates = {
        ESTIMATE_LABELS[a]: [(r["estimate_support"], r["estimate"]) for r in runs[a]]
        for a in ESTIMATE_LABELS
        if runs[a] and all("estimate" in r for r in runs[a])
    }
    true_pmf = np.asarray(Poisson(LAM).pmf(np.arange(LAMBDA_MAX + 1)))
    return {
        "average_reward": plotting.figure(
            plotting.learning_curves,
            rewards,
            f"{title}: average reward (the thesis has no DeconvQ value)",
            "average reward (undelayed stream)",
            thesis_reward_lines(),
        ),
        "accumulated_error": plotting.figure(
            plotting.learning_curves,
            errors,
            f"{title}: accumulated error (the thesis has no DeconvQ value)",
            "accumulated error Σ|Δ| (pixels)",
            thesis_ratios=thesis_error_ratio_lines(),
        ),
        "delay_estimate": plotting.figure(
            plotting.estimate_plot,
            estimates,
            true_pmf,
            f"{title}: delay estimates against the true Poisson({LAM}) pmf",
        ),
    }


EXPERIMENT = Experiment(
    name="linefollow-deconv",
    thesis="beyond the thesis (Figs. 5.22–5.23's setting)",
    description=f"MMQ (λ̂max = {LAMBDA_MAX}) against deconvolution Q-learning (delay learned "
    f"on 0..{LAMBDA_MAX}) and Q-learning on the e-puck line follower (linefollow's setting: "
    f"{TRACK}, discrete actions, centroid states, Poisson({LAM}) reward delays), "
    f"{step_count(STEPS)} steps per run; {hyperparameter_text(Q_INIT)}. Average reward during "
    "learning and accumulated error Σ|Δ|, paired by seed; delay estimates; ns/step.",
    tasks=tasks,
    summarize=summarize,
    default_seeds=5,
    shared_run=logged_task_run,
)
