"""``linefollow-deconv`` (beyond the thesis): deconvolution Q-learning on the e-puck line follower.

A module of its own (not a setting of ``anonymous-delay``): the e-puck runs share nothing with
the grid worlds but the agents. The setting is ``linefollow``'s (:mod:`delayed_rl.experiments.linefollow`, whose env,
constants and metrics this module reuses): ``delayed_rl/EPuckLineFollow-v0`` on the racetrack,
discrete Table 5.2 actions, centroid states, put back on the track after 50 line-less steps,
Poisson(90) reward delays, 150k steps a run, 5 seeds; α = 0.1, γ = 0.9, constant ε = 0.1,
``q_init`` = 10. Three learners:

- ``MMQ``: Λ = {0, ..., 150} (the thesis's λ̂max = 150);
- ``DeconvQ learned``: :class:`~DeconvolutionQLearning` learning the delay on 0..150
  (``max_delay`` = 150, the same horizon), never told it is Poisson;
- ``Q``: Q-learning on the delayed reward.

``--quick``: 2 seeds, 5k steps. 15 tasks at full size; MMQ's and Q's are ``linefollow``'s runs
(the same env, settings and seeds), which ``delayed-rl reproduce`` runs once for both, and every
learner's run is also the start of ``controllers``' and ``real-robot``'s longer training
(:func:`.linefollow.training_run`: run together, each learner and seed trains once).

Metrics, as ``linefollow``'s: the average reward during learning (the undelayed reward's
running mean) and the accumulated error Σ|Δ| (an unseen line counted as |Δ| = 20), plus the
delay estimate (DeconvQ's ``delay_pmf`` and ``mean_delay``, MMQ's acting-delay share and its
mean) and ns/step (``learn``'s wall time over the steps, on the compiled path).

The claims, with verdicts computed from the runs by :mod:`.common`'s rules (each row's
``criterion`` states its own):

- MMQ's and Q's average rewards against the thesis's ≈ 0.55 and ≈ 0.12 (Fig. 5.22), and
  MMQ's accumulated error over Q's against ≈ 0.4 (Fig. 5.23): ``linefollow``'s bands;
- DeconvQ learned's average reward: a ``reference`` row (no thesis value; the next rows test it);
- DeconvQ learned minus Q, and minus MMQ, average reward (paired by seed): the direction rule,
  above 0;
- DeconvQ learned's accumulated error over MMQ's (paired by seed): the direction rule, below 1
  (DeconvQ keeps closer to the line);
- DeconvQ learned's mean delay: the band λ ± 10 % (90 ± 9).

Whichever way they fall, the numbers are in the report and in ``summary.json``.
"""

from __future__ import annotations

import numpy as np

from delayed_rl._validation import check_choice
from delayed_rl.experiments import linefollow, plotting
from delayed_rl.experiments.anonymous_delay import DELAY_TOLERANCE, estimate_plot
from delayed_rl.experiments.common import (
    band_claim,
    direction_claim,
    mean_ci_n,
    paired,
    reference_row,
    seed_tasks,
)
from delayed_rl.experiments.runner import Config, Curve, Experiment, SharedRun, Summary

#: The learners compared.
AGENTS = ("MMQ", "DeconvQ learned", "Q")
QUICK_STEPS, STEPS = 5_000, 150_000


def tasks(config: Config) -> list[dict]:
    """Per seed, one run of each of :data:`AGENTS`: 150k steps (5k with ``config.quick``)."""
    steps = config.steps or (QUICK_STEPS if config.quick else STEPS)
    return seed_tasks(config, AGENTS, steps=steps)


def run_task(task: dict) -> dict:
    """Train one learner on the line follower; measure reward, error, delay estimate and cost.

    Returns:
        :func:`.linefollow.run_task`'s results: ``linefollow``'s metrics (``steps``,
        ``curve``, ``error``, ``average``, ``total_error``, ``visible``), ``ns_per_step``,
        ``path`` and the delay estimate.
    """
    return shared_run(task).alone()


def shared_run(task: dict) -> SharedRun:
    """Every task's training run, pooled with the other line-following experiments'.

    MMQ's and Q's are ``linefollow``'s runs (the same env, settings and seeds); each learner's
    is also the start of ``controllers``' and ``real-robot``'s (:func:`.linefollow.training_run`).
    """
    check_choice("agent", task["agent"], AGENTS)
    return linefollow.shared_run(task)


#: DeconvQ's training cost per step on the line follower (µs; MMQ's and Q's are linefollow's).
DECONV_STEP_MICROSECONDS = 14.0


def cost(task: dict) -> float:
    """A task's estimated core-seconds, for scheduling (:func:`.linefollow.cost` for MMQ and Q)."""
    if task["agent"] in linefollow.AGENTS:
        return linefollow.cost(task)
    return 1e-6 * DECONV_STEP_MICROSECONDS * task["steps"]


def _paired(runs: dict[str, list[dict]], ours: str, theirs: str, how: str) -> tuple:
    """(mean, CI, n) by seed of ``ours − theirs`` (average reward) or ``ours / theirs`` (error).

    ``how="difference"`` pairs the average rewards, ``"ratio"`` the accumulated errors; the
    runs of every agent are in the order of the seeds (:func:`tasks`).
    """
    key = "average" if how == "difference" else "total_error"
    values = [{i: r[key] for i, r in enumerate(runs[name])} for name in (ours, theirs)]
    return mean_ci_n(paired(*values, how=how))


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """The claims of the module docstring, per-agent statistics in ``extra`` and the figures."""
    runs: dict[str, list[dict]] = {agent: [] for agent in AGENTS}
    curves = []
    for task, result in zip(task_list, results, strict=True):
        runs[task["agent"]].append(result)
        agent, seed, steps = task["agent"], task["seed"], result["steps"]
        curves.append(Curve(agent, seed, steps, result["curve"]))
        curves.append(Curve(agent, seed, steps, result["error"], "accumulated_error"))
    stat = {agent: mean_ci_n([r["average"] for r in rs]) for agent, rs in runs.items()}
    tolerance = linefollow.REWARD_TOLERANCE
    over_mmq = _paired(runs, "DeconvQ learned", "MMQ", "difference")
    over_q = _paired(runs, "DeconvQ learned", "Q", "difference")
    error_ratio = _paired(runs, "DeconvQ learned", "MMQ", "ratio")
    thesis_ratio = _paired(runs, "MMQ", "Q", "ratio")
    delays = mean_ci_n([r["mean_delay"] for r in runs["DeconvQ learned"]])
    lam = linefollow.LAM
    claims = [
        band_claim(
            "MMQ average reward during learning",
            "≈ 0.55 (Fig. 5.22)",
            stat["MMQ"],
            linefollow.THESIS_REWARD["MMQ"],
            tolerance,
        ),
        band_claim(
            "Q average reward during learning",
            "≈ 0.12 (Fig. 5.22)",
            stat["Q"],
            linefollow.THESIS_REWARD["Q"],
            tolerance,
        ),
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
            error_ratio,
            "below",
            1.0,
            note="paired by seed",
        ),
        band_claim(
            "MMQ accumulated error / Q accumulated error",
            "≈ 0.4 (Fig. 5.23)",
            thesis_ratio,
            linefollow.THESIS_ERROR_RATIO,
            linefollow.RATIO_TOLERANCE,
            note="paired by seed",
        ),
        band_claim(
            "DeconvQ learned mean delay",
            f"extension: the true mean {lam}",
            delays,
            lam,
            DELAY_TOLERANCE * lam,
        ),
    ]
    extra = {
        **linefollow.line_statistics(runs),
        "average_reward": {agent: stat[agent][:2] for agent in AGENTS},
        "ns_per_step": {a: mean_ci_n([r["ns_per_step"] for r in rs])[:2] for a, rs in runs.items()},
        "mean_delay": {
            a: mean_ci_n([r["mean_delay"] for r in rs])[:2]
            for a, rs in runs.items()
            if rs and all("mean_delay" in r for r in rs)
        },
        "paths": {a: sorted({r["path"] for r in rs}) for a, rs in runs.items()},
    }
    return Summary(claims, curves, _figures(runs), extra)


def _figures(runs: dict[str, list[dict]]) -> dict:
    """Reward and accumulated-error curves with 95 % bands; the delay estimates over Poisson(90)."""
    from delayed_rl.delays import Poisson

    title = (
        f"line following, Poisson delays of mean λ = {linefollow.LAM}, "
        f"λ̂max = {linefollow.LAMBDA_MAX}"
    )
    rewards = {a: [(r["steps"], r["curve"]) for r in rs] for a, rs in runs.items()}
    errors = {a: [(r["steps"], r["error"]) for r in rs] for a, rs in runs.items()}
    labels = {"MMQ": "MMQ acting share", "DeconvQ learned": "DeconvQ learned pmf"}
    estimates = {
        labels[a]: [(r["estimate_support"], r["estimate"]) for r in runs[a]]
        for a in labels
        if runs[a] and all("estimate" in r for r in runs[a])
    }
    true_pmf = np.asarray(Poisson(linefollow.LAM).pmf(np.arange(linefollow.LAMBDA_MAX + 1)))
    return {
        "average_reward": plotting.figure(
            plotting.learning_curves,
            rewards,
            f"{title}: average reward (the thesis has no DeconvQ value)",
            "average reward (undelayed stream)",
            linefollow.thesis_reward_lines(),
        ),
        "accumulated_error": plotting.figure(
            plotting.learning_curves,
            errors,
            f"{title}: accumulated error (the thesis has no DeconvQ value)",
            "accumulated error Σ|Δ| (pixels)",
            thesis_ratios=linefollow.thesis_error_ratio_lines(),
        ),
        "delay_estimate": plotting.figure(
            estimate_plot,
            estimates,
            true_pmf,
            f"{title}: delay estimates against the true Poisson({linefollow.LAM}) pmf",
        ),
    }


EXPERIMENT = Experiment(
    name="linefollow-deconv",
    thesis="beyond the thesis (Figs. 5.22–5.23's setting)",
    description="MMQ (λ̂max = 150) against deconvolution Q-learning (delay learned on 0..150) "
    "and Q-learning on the e-puck line follower (linefollow's setting: racetrack, discrete "
    "actions, centroid states, Poisson(90) reward delays), 150k steps per run; α = 0.1, "
    "γ = 0.9, ε = 0.1, q_init = 10. Average reward during learning and accumulated error "
    "Σ|Δ|, paired by seed; delay estimates; ns/step.",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=5,
    shared_run=shared_run,
    cost=cost,
)
