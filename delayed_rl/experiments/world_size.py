"""``world-size`` (thesis Figs. 5.3–5.5): Q-learning on 3×3, 5×5 and 9×9 grids, λ ∈ {5, 50, 150}."""

from __future__ import annotations

from delayed_rl.experiments import plotting
from delayed_rl.experiments.common import claim, curves_and_means, grid_task, normalised, references
from delayed_rl.experiments.runner import Config, Experiment, Summary

SIZES = (3, 5, 9)
LAMS = (5, 50, 150)


def tasks(config: Config) -> list[dict]:
    steps = config.steps or (25_000 if config.quick else 250_000)
    lams = (5, 50) if config.quick else LAMS
    out = []
    for i in range(config.seeds):
        seed = config.base_seed + i
        for size in SIZES:
            out.append({"size": size, "lam": 0, "lags": [0], "steps": steps, "seed": seed,
                        "reference": True, "condition": f"{size}x{size} undelayed"})  # fmt: skip
            out += [{"size": size, "lam": lam, "lags": [0], "steps": steps, "seed": seed,
                     "condition": f"{size}x{size} lambda={lam}"} for lam in lams]  # fmt: skip
    return out


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    per_condition = normalised(task_list, results, references(task_list, results))
    curves, stats = curves_and_means(per_condition)
    lams = sorted({t["lam"] for t in task_list if not t.get("reference")})
    claims = []
    for lam in lams:
        row = [stats[f"{size}x{size} lambda={lam}"] for size in SIZES]
        claims += [
            claim(
                f"normalised reward {size}×{size}, λ = {lam}",
                "≈ 0 % (Fig. 5.3–5.5)" if size == 9 else "above 0, below 1",
                stats_,
                ok=(stats_[0] < 0.1) if size == 9 else (0 < stats_[0] < 1),
            )  # fmt: skip
            for size, stats_ in zip(SIZES, row, strict=True)
        ]
        claims.append(claim(f"9×9 below 3×3 at λ = {lam}", "larger world, lower reward",
                            (row[2][0] - row[0][0], 0.0, row[0][2]), ok=row[2][0] < row[0][0]))  # fmt: skip
    figures = {}
    for lam in lams:
        groups = {f"{s}x{s}": [(st, v) for _, st, v, _ in per_condition[f"{s}x{s} lambda={lam}"]]
                  for s in SIZES}  # fmt: skip
        figures[f"fig5_3to5_world_size_lambda{lam}"] = (
            lambda path, groups=groups, lam=lam: plotting.learning_curves(
                path, groups, f"Normalised average reward, λ = {lam}", "normalised average reward"))  # fmt: skip
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
