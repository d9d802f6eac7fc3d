"""``delay-sweep`` (thesis Fig. 5.2): Q-learning on the 3×3 grid under growing mean delays λ."""

from __future__ import annotations

import numpy as np

from delayed_rl.experiments import plotting
from delayed_rl.experiments.common import claim, curves_and_means, grid_task, normalised, references
from delayed_rl.experiments.runner import Config, Experiment, Summary

LAMS = (1, 2, 5, 10, 20, 50)
QUICK_LAMS = (2, 10, 50)


def tasks(config: Config) -> list[dict]:
    steps = config.steps or (20_000 if config.quick else 150_000)
    lams = QUICK_LAMS if config.quick else LAMS
    out = []
    for i in range(config.seeds):
        seed = config.base_seed + i
        out.append({"size": 3, "lam": 0, "lags": [0], "steps": steps, "seed": seed,
                    "reference": True, "condition": "undelayed"})  # fmt: skip
        out += [{"size": 3, "lam": lam, "lags": [0], "steps": steps, "seed": seed,
                 "condition": f"lambda={lam}"} for lam in lams]  # fmt: skip
    return out


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    per_condition = normalised(task_list, results, references(task_list, results))
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
        )  # fmt: skip
        for lam in lams
    ]
    trend = float(np.corrcoef(lams, means)[0, 1]) if len(lams) > 2 else float("nan")
    decreasing = means[-1] < means[0]
    claims.append(
        claim(
            "largest-λ minus smallest-λ normalised reward",
            "< 0 (larger λ, lower reward)",
            (means[-1] - means[0], 0.0, config.seeds),
            ok=decreasing,
            note=f"Pearson correlation of λ and normalised reward: {trend:.2f}",
        )  # fmt: skip
    )
    groups = {c: [(s, v) for _, s, v, _ in runs] for c, runs in per_condition.items()}
    figures = {"fig5_2_delay_sweep": lambda path: plotting.learning_curves(
        path, groups, "3×3 grid world: effect of the mean delay (Fig. 5.2)",
        "normalised average reward")}  # fmt: skip
    return Summary(
        claims, curves, figures, {"normalised_means": dict(zip(map(str, lams), means, strict=True))}
    )


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
