"""``world-size`` (thesis Figs. 5.3–5.5): Q-learning on 3×3, 5×5 and 9×9 grids, λ ∈ {5, 50, 150}."""

from __future__ import annotations

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

SIZES = (3, 5, 9)
LAMS = (5, 50, 150)


def tasks(config: Config) -> list[dict]:
    """Per seed and world size: undelayed Q-learning, then Q-learning under each mean delay λ.

    250k steps a run (25k with ``config.quick``, which also leaves out λ = 150).
    """
    steps = config.steps or (25_000 if config.quick else 250_000)
    lams = (5, 50) if config.quick else LAMS
    runs = [
        {"size": size, "lam": lam, "lags": [0], "condition": f"{size}x{size} lambda={lam}"}
        for size in SIZES
        for lam in lams
    ]
    return grid_tasks(config, steps, runs)


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """Per λ: each world's normalised reward (≈ 0 on 9×9, in (0, 1) below), and 9×9 below 3×3."""
    per_condition = normalised(task_list, results)
    curves, stats = curves_and_means(per_condition)
    groups = learning_curve_groups(per_condition)
    lams = sorted({t["lam"] for t in task_list if not t.get("reference")})
    claims, figures = [], {}
    for lam in lams:
        row = [stats[f"{size}x{size} lambda={lam}"] for size in SIZES]
        claims += [
            claim(
                f"normalised reward {size}×{size}, λ = {lam}",
                "≈ 0 % (Fig. 5.3–5.5)" if size == 9 else "above 0, below 1",
                size_stats,
                ok=(size_stats[0] < 0.1) if size == 9 else (0 < size_stats[0] < 1),
            )
            for size, size_stats in zip(SIZES, row, strict=True)
        ]
        claims.append(
            claim(
                f"9×9 below 3×3 at λ = {lam}",
                "larger world, lower reward",
                (row[2][0] - row[0][0], 0.0, row[0][2]),
                ok=row[2][0] < row[0][0],
            )
        )
        figures[f"fig5_3to5_world_size_lambda{lam}"] = plotting.figure(
            plotting.learning_curves,
            {f"{s}x{s}": groups[f"{s}x{s} lambda={lam}"] for s in SIZES},
            f"Normalised average reward, λ = {lam}",
            "normalised average reward",
        )
    return Summary(claims, curves, figures)


EXPERIMENT = Experiment(
    name="world-size",
    thesis="Figs. 5.3–5.5",
    description="Q-learning on the 3×3, 5×5 and 9×9 grid worlds under Poisson delays λ ∈ {5, 50, "
    "150}, normalised by undelayed Q-learning in the same world and seed (Eq. 5.3).",
    tasks=tasks,
    run_task=grid_task,
    summarize=summarize,
    default_seeds=10,
)
