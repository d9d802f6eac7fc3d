"""``delay-sweep`` (thesis Fig. 5.2): Q-learning on a grid world under growing mean delays λ.

The settings are :data:`LAMS` on the :data:`SIZE` grid; the claim is in :func:`summarize`.
"""

from __future__ import annotations

import numpy as np

from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.claims import (
    direction_claim,
    mean_ci_n,
    paired,
    reference_row,
    trend_claim,
)
from delayed_rl.experiments.framework.experiment import Config, Experiment, Summary
from delayed_rl.experiments.framework.normalised_runs import (
    GridTask,
    NormalisedRuns,
    delay_grid_tasks,
    grid_task,
)
from delayed_rl.experiments.framework.results import common_seeds
from delayed_rl.experiments.framework.training import ALPHA, EPSILON, GAMMA

#: The grid world's side.
SIZE = 3
#: The Poisson mean delays λ, and a quick run's.
LAMS, QUICK_LAMS = (1, 2, 5, 10, 20, 50), (2, 10, 50)
#: The steps of a run, and of a quick run.
STEPS, QUICK_STEPS = 150_000, 20_000
#: What the thesis's Fig. 5.2 shows, in words: it prints no value per λ.
THESIS_TREND = "the normalised reward falls as λ grows"


def tasks(config: Config) -> list[GridTask]:
    """Per seed: undelayed Q-learning on the grid, then Q-learning under each mean delay λ."""
    return delay_grid_tasks(
        config, (SIZE,), (LAMS, QUICK_LAMS), (STEPS, QUICK_STEPS), lambda _, lam: f"lambda={lam}"
    )


def summarize(task_list: list[GridTask], results: list[dict], config: Config) -> Summary:
    """The trend of Fig. 5.2: the normalised reward falls as λ grows.

    Two claims, both per seed: the least-squares slope of the normalised reward against
    log10 λ (below 0), and the largest λ's normalised reward minus the smallest's, paired by
    seed (below 0). Each λ's normalised reward is a ``reference`` row: the thesis gives the
    curves, not a value per λ to test.
    """
    runs = NormalisedRuns.of(task_list, results, by=("lam",))
    by_seed, stats = runs.averages(), runs.means()
    lams = sorted(stats)
    means = [stats[lam][0] for lam in lams]
    seeds = common_seeds(*(by_seed[lam] for lam in lams))
    claims = [
        reference_row(
            f"normalised average reward, λ = {lam}",
            stats[lam],
            "a point of the falling curve (Fig. 5.2)",
        )
        for lam in lams
    ]
    claims.append(
        trend_claim(
            "slope of normalised reward against log10 λ (per seed)",
            "< 0: larger λ, lower reward (Fig. 5.2)",
            np.log10(lams),
            [[by_seed[lam][s] for lam in lams] for s in seeds],
            "below",
            "log10 λ",
        )
    )
    claims.append(
        direction_claim(
            f"λ = {lams[-1]} minus λ = {lams[0]} normalised reward (paired by seed)",
            "< 0 (larger λ, lower reward)",
            mean_ci_n(paired(by_seed[lams[-1]], by_seed[lams[0]])),
            "below",
        )
    )
    figures = {
        "fig5_2_delay_sweep": plotting.figure(
            plotting.learning_curves,
            {f"λ = {lam}": group for lam, group in runs.curve_groups().items()},
            f"{SIZE}×{SIZE} grid world: Q-learning under Poisson delays of mean λ (Fig. 5.2)\n"
            f"thesis: {THESIS_TREND} (it gives no value per λ)",
            "normalised average reward (Eq. 5.3)",
        )
    }
    extra = {"normalised_means": dict(zip(map(str, lams), means, strict=True))}
    return Summary(claims, runs.curves(), figures, extra)


EXPERIMENT = Experiment(
    name="delay-sweep",
    thesis="Fig. 5.2",
    description=f"Q-learning (α = {ALPHA}, γ = {GAMMA}, ε = {EPSILON}) on the {SIZE}×{SIZE} grid "
    "world for growing Poisson mean delays λ; average reward normalised by undelayed Q-learning "
    "on the same seed (Eq. 5.3).",
    tasks=tasks,
    run_task=grid_task,
    summarize=summarize,
    default_seeds=10,
)
