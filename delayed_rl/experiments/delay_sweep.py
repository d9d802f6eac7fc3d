"""``delay-sweep`` (thesis Fig. 5.2): Q-learning on the 3×3 grid under growing mean delays λ."""

from __future__ import annotations

import numpy as np

from delayed_rl.experiments import plotting
from delayed_rl.experiments.common import (
    claim,
    curves_and_means,
    grid_task,
    grid_tasks,
    learning_curve_groups,
    normalised,
)
from delayed_rl.experiments.runner import Config, Experiment, Summary

LAMS = (1, 2, 5, 10, 20, 50)
QUICK_LAMS = (2, 10, 50)


def tasks(config: Config) -> list[dict]:
    """Per seed: undelayed Q-learning on the 3×3 grid, then Q-learning under each mean delay λ.

    150k steps a run (20k with ``config.quick``, which also keeps only λ ∈ {2, 10, 50}).
    """
    steps = config.steps or (20_000 if config.quick else 150_000)
    lams = QUICK_LAMS if config.quick else LAMS
    runs = [{"size": 3, "lam": lam, "lags": [0], "condition": f"lambda={lam}"} for lam in lams]
    return grid_tasks(config, steps, runs)


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """One claim per λ (its normalised reward) and the trend: the largest λ earns less.

    The per-λ rows always agree: they are the points of the trend, whose row has the verdict.
    """
    per_condition = normalised(task_list, results)
    curves, stats = curves_and_means(per_condition)
    lams = sorted({t["lam"] for t in task_list if not t.get("reference")})
    means = [stats[f"lambda={lam}"][0] for lam in lams]
    claims = [
        claim(
            f"normalised average reward, λ = {lam}",
            "falls as λ grows",
            stats[f"lambda={lam}"],
            ok=True,
            note="one point of the trend below",
        )
        for lam in lams
    ]
    trend = float(np.corrcoef(lams, means)[0, 1]) if len(lams) > 2 else float("nan")
    claims.append(
        claim(
            "largest-λ minus smallest-λ normalised reward",
            "< 0 (larger λ, lower reward)",
            (means[-1] - means[0], 0.0, config.seeds),
            ok=means[-1] < means[0],
            note=f"Pearson correlation of λ and normalised reward: {trend:.2f}",
        )
    )
    figures = {
        "fig5_2_delay_sweep": plotting.figure(
            plotting.learning_curves,
            learning_curve_groups(per_condition),
            "3×3 grid world: effect of the mean delay (Fig. 5.2)",
            "normalised average reward",
        )
    }
    extra = {"normalised_means": dict(zip(map(str, lams), means, strict=True))}
    return Summary(claims, curves, figures, extra)


EXPERIMENT = Experiment(
    name="delay-sweep",
    thesis="Fig. 5.2",
    description="Q-learning (α = 0.1, γ = 0.9, ε = 0.1) on the 3×3 grid world for growing Poisson "
    "mean delays λ; average reward normalised by undelayed Q-learning on the same seed (Eq. 5.3).",
    tasks=tasks,
    run_task=grid_task,
    summarize=summarize,
    default_seeds=10,
)
