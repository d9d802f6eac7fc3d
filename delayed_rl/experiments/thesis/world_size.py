"""``world-size`` (thesis Figs. 5.3–5.5): Q-learning on grid worlds of three sizes under delays.

The settings are :data:`SIZES` and :data:`LAMS`; the claims are in :func:`summarize`.
"""

from __future__ import annotations

from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.claims import (
    band_claim,
    direction_claim,
    mean_ci_n,
    paired,
    range_claim,
)
from delayed_rl.experiments.framework.experiment import Config, Experiment, Summary
from delayed_rl.experiments.framework.normalised_runs import (
    GridTask,
    NormalisedRuns,
    delay_grid_tasks,
    grid_task,
)

#: The grid worlds' sides.
SIZES = (3, 5, 9)
#: The Poisson mean delays λ, and a quick run's.
LAMS, QUICK_LAMS = (5, 50, 150), (5, 50)
#: The steps of a run, and of a quick run.
STEPS, QUICK_STEPS = 250_000, 25_000
#: The thesis's 9×9 normalised reward ("fell to 0 %", Figs. 5.3–5.5).
THESIS_9X9 = 0.0
NEAR_ZERO = 0.1
"""The tolerance of the 9×9 rows' "≈ 0 %": a normalised reward within 0 ± 0.1."""


def tasks(config: Config) -> list[GridTask]:
    """Per seed and world size: undelayed Q-learning, then Q-learning under each mean delay λ."""
    return delay_grid_tasks(config, SIZES, (LAMS, QUICK_LAMS), (STEPS, QUICK_STEPS), _condition)


def _condition(size: int, lam: int) -> str:
    """A run's label: its world and its mean delay."""
    return f"{size}x{size} lambda={lam}"


def summarize(task_list: list[GridTask], results: list[dict], config: Config) -> Summary:
    """Per λ: each world's normalised reward, and the 9×9 world below the 3×3 one.

    The 9×9 rows test the band 0 ± ``NEAR_ZERO`` ("≈ 0 %"), the 3×3 and 5×5 rows the range
    [0, 1] ("above 0, below 1": a delayed learner earns something, less than undelayed); the
    last row per λ is the 9×9 minus 3×3 normalised reward, paired by seed (below 0).
    """
    runs = NormalisedRuns.of(task_list, results, by=("size", "lam"))
    by_seed, stats, groups = runs.averages(), runs.means(), runs.curve_groups()
    lams = sorted({lam for _, lam in stats})
    claims, figures = [], {}
    for lam in lams:
        for size in SIZES:
            quantity = f"normalised reward {size}×{size}, λ = {lam}"
            size_stats = stats[(size, lam)]
            if size == 9:
                claims.append(
                    band_claim(quantity, "≈ 0 % (Figs. 5.3–5.5)", size_stats, THESIS_9X9, NEAR_ZERO)
                )
            else:
                claims.append(range_claim(quantity, "above 0, below 1", size_stats, 0.0, 1.0))
        claims.append(
            direction_claim(
                f"9×9 minus 3×3 normalised reward at λ = {lam} (paired by seed)",
                "< 0: larger world, lower reward",
                mean_ci_n(paired(by_seed[(9, lam)], by_seed[(3, lam)])),
                "below",
            )
        )
        figures[f"fig5_3to5_world_size_lambda{lam}"] = plotting.figure(
            plotting.learning_curves,
            {f"{s}×{s}": groups[(s, lam)] for s in SIZES},
            f"Q-learning in three world sizes, Poisson delays of mean λ = {lam} (Figs. 5.3–5.5)\n"
            "thesis: 3×3 and 5×5 above 0 and below 1; 9×9 ≈ 0 %",
            "normalised average reward (Eq. 5.3)",
            thesis=[(THESIS_9X9, "thesis 9×9 ≈ 0 % (Figs. 5.3–5.5)", "9×9")],
            settle=SETTLE,
        )
    return Summary(claims, runs.curves(), figures)


#: The first fifth of training does not set the figures' y-range: the 9×9 curves divide by an
#: undelayed reference that has barely earned anything yet, and fall below −2 for a tenth of it.
SETTLE = 0.2

EXPERIMENT = Experiment(
    name="world-size",
    thesis="Figs. 5.3–5.5",
    description=f"Q-learning on the {', '.join(f'{n}×{n}' for n in SIZES[:-1])} and "
    f"{SIZES[-1]}×{SIZES[-1]} grid worlds under Poisson delays λ ∈ "
    f"{{{', '.join(map(str, LAMS))}}}, normalised by undelayed Q-learning in the same world and "
    "seed (Eq. 5.3).",
    tasks=tasks,
    run_task=grid_task,
    summarize=summarize,
    default_seeds=10,
)
