"""``linefollow-deconv`` (beyond the thesis): deconvolution Q-learning on the e-puck line follower.

A module of its own (not a setting of ``anonymous-delay``): the e-puck runs share nothing with
the grid worlds but the agents. The setting is ``linefollow``'s (the framework's
:mod:`~delayed_rl.experiments.framework.line_following`, whose env, learners, training run and
metrics both use): ``delayed_rl/EPuckLineFollow-v0`` on the racetrack,
discrete Table 5.2 actions, centroid states, put back on the track after 50 line-less steps,
Poisson(90) reward delays, 150k steps a run, 5 seeds; α = 0.1, γ = 0.9, constant ε = 0.1,
``q_init`` = 10. Three learners:

- ``MMQ``: Λ = {0, ..., 150} (the thesis's λ̂max = 150);
- ``DeconvQ learned``: :class:`~DeconvolutionQLearning` learning the delay on 0..150
  (``max_delay_estimate`` = 150, the same horizon), never told it is Poisson;
- ``Q``: Q-learning on the delayed reward.

``--quick``: 2 seeds, 5k steps. 15 tasks at full size; MMQ's and Q's are ``linefollow``'s runs
(the same env, settings and seeds), which ``delayed-rl reproduce`` runs once for both, and every
learner's run is also the start of ``controllers``' and ``real-robot``'s longer training
(:func:`~.line_following.training_run`: run together, each learner and seed trains once).

Metrics, as ``linefollow``'s: the average reward during learning (the undelayed reward's
running mean) and the accumulated error Σ|Δ| (an unseen line counted as |Δ| = 20), plus the
delay estimate (DeconvQ's ``delay_pmf`` and ``mean_delay``, MMQ's acting-delay share and its
mean) and ns/step (``learn``'s wall time over the steps, on the compiled path).

The claims, with verdicts computed from the runs by :mod:`~.framework.claims`' rules (each row's
``criterion`` states its own):

- MMQ's and Q's average rewards against the thesis's ≈ 0.55 and ≈ 0.12 (Fig. 5.22), and
  MMQ's accumulated error over Q's against ≈ 0.4 (Fig. 5.23): ``linefollow``'s bands
  (:mod:`~delayed_rl.experiments.framework.line_claims`);
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
from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.claims import (
    direction_claim,
    mean_ci_n,
    paired,
    reference_row,
)
from delayed_rl.experiments.framework.delay_estimates import ESTIMATE_LABELS, mean_delay_claim
from delayed_rl.experiments.framework.experiment import (
    Config,
    Curve,
    Experiment,
    SharedRun,
    Summary,
    seed_tasks,
)
from delayed_rl.experiments.framework.line_claims import (
    error_ratio_claim,
    reward_claims,
    thesis_error_ratio_lines,
    thesis_reward_lines,
)
from delayed_rl.experiments.framework.line_following import (
    LAM,
    LAMBDA_MAX,
    line_statistics,
    logged_run,
    training_cost,
)
from delayed_rl.experiments.framework.results import pivot

#: The learners compared.
LEARNERS = ("MMQ", "DeconvQ learned", "Q")
QUICK_STEPS, STEPS = 5_000, 150_000


def tasks(config: Config) -> list[dict]:
    """Per seed, one run of each of :data:`LEARNERS`: 150k steps (5k with ``config.quick``)."""
    steps = config.steps or (QUICK_STEPS if config.quick else STEPS)
    return seed_tasks(config, LEARNERS, steps=steps)


def run_task(task: dict) -> dict:
    """Train one learner on the line follower; measure reward, error, delay estimate and cost.

    Returns:
        ``linefollow``'s results: :func:`~.line_following.run_metrics`' (``steps``,
        ``curve``, ``error``, ``average``, ``total_error``, ``visible``), ``ns_per_step``,
        ``path`` and the delay estimate.
    """
    return shared_run(task).alone()


def shared_run(task: dict) -> SharedRun:
    """Every task's training run, pooled with the other line-following experiments'.

    MMQ's and Q's are ``linefollow``'s runs (the same env, settings and seeds); each learner's
    is also the start of ``controllers``' and ``real-robot``'s
    (:func:`~.line_following.logged_run`).
    """
    check_choice("agent", task["agent"], LEARNERS)
    return logged_run(task["agent"], task["seed"], task["steps"])


def cost(task: dict) -> float:
    """A task's estimated core-seconds, for scheduling (:func:`~.line_following.training_cost`)."""
    return training_cost(task["agent"], task["steps"])


def _paired(runs: dict[str, dict[int, dict]], ours: str, theirs: str, how: str) -> tuple:
    """(mean, CI, n) by seed of ``ours − theirs`` (average reward) or ``ours / theirs`` (error).

    ``how="difference"`` pairs the average rewards, ``"ratio"`` the accumulated errors, over
    the seeds both agents ran.
    """
    key = "average" if how == "difference" else "total_error"
    values = [{seed: r[key] for seed, r in runs[name].items()} for name in (ours, theirs)]
    return mean_ci_n(paired(*values, how=how))


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """The claims of the module docstring, per-agent statistics in ``extra`` and the figures."""
    by_agent = pivot(task_list, results, by=("agent",))
    runs = {agent: by_agent.get(agent, {}) for agent in LEARNERS}
    curves = []
    for task, result in zip(task_list, results, strict=True):
        agent, seed, steps = task["agent"], task["seed"], result["steps"]
        curves.append(Curve(agent, seed, steps, result["curve"]))
        curves.append(Curve(agent, seed, steps, result["error"], "accumulated_error"))
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
    """Reward and accumulated-error curves with 95 % bands; the delay estimates over Poisson(90)."""
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
