"""``estimate-error`` (thesis Fig. 5.6): fixed-delay Q-learning with estimates λ̂ = λ + i."""

from __future__ import annotations

import numpy as np

from delayed_rl.experiments import plotting
from delayed_rl.experiments.common import claim, curves_and_means, grid_task, grid_tasks, normalised
from delayed_rl.experiments.runner import Config, Experiment, Summary

LAM = 17


def tasks(config: Config) -> list[dict]:
    """Per seed: undelayed Q-learning on 9×9, then fixed-delay Q-learning with λ̂ = 17 + i.

    The errors are i ∈ {−15, ..., 15} (every fifth with ``config.quick``), 150k steps a run (30k
    with ``config.quick``).
    """
    steps = config.steps or (30_000 if config.quick else 150_000)
    errors = range(-15, 16, 5) if config.quick else range(-15, 16)
    runs = [
        {"size": 9, "lam": LAM, "lags": [LAM + e], "condition": f"i={e}", "error": e}
        for e in errors
    ]
    return grid_tasks(config, steps, runs)


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """Fig. 5.6's shape: a peak of ≈ 0.6 near i = 0, and much less at both ends of the errors."""
    per_condition = normalised(task_list, results)
    curves, stats = curves_and_means(per_condition)
    errors = sorted({t["error"] for t in task_list if "error" in t})
    means = np.array([stats[f"i={e}"][0] for e in errors])
    cis = np.array([stats[f"i={e}"][1] for e in errors])
    peak = errors[int(np.argmax(means))]
    claims = [
        claim(
            "normalised reward at i = 0",
            "≈ 0.6 (peak of Fig. 5.6)",
            stats["i=0"],
            ok=abs(stats["i=0"][0] - 0.6) <= 0.15 + stats["i=0"][1],
        ),
        claim(
            "error i of the best estimate",
            "near 0",
            (float(peak), 0.0, config.seeds),
            ok=abs(peak) <= 3,
        ),
        claim(
            "normalised reward at i = −15",
            "far below the peak",
            stats[f"i={errors[0]}"],
            ok=stats[f"i={errors[0]}"][0] < 0.5 * means.max(),
        ),
        claim(
            "normalised reward at i = +15",
            "far below the peak",
            stats[f"i={errors[-1]}"],
            ok=stats[f"i={errors[-1]}"][0] < 0.5 * means.max(),
        ),
    ]
    figures = {
        "fig5_6_estimate_error": plotting.figure(
            plotting.errorbar_curve,
            errors,
            means,
            cis,
            f"9×9, λ = {LAM}: fixed-delay Q-learning with λ̂ = λ + i",
            "estimate error i = λ̂ − λ",
            "normalised average reward",
        )
    }
    return Summary(claims, curves, figures, {"errors": errors, "normalised_means": means})


EXPERIMENT = Experiment(
    name="estimate-error",
    thesis="Fig. 5.6",
    description="31 fixed-delay Q-learners assume a constant delay λ̂ = λ + i (i ∈ [−15, 15]) on "
    "the 9×9 grid world with Poisson(17) delays, 150k steps each; normalised by undelayed "
    "Q-learning on the same seed (Eq. 5.3).",
    tasks=tasks,
    run_task=grid_task,
    summarize=summarize,
    default_seeds=10,
)
