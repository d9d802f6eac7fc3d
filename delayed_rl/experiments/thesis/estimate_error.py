"""``estimate-error`` (thesis Fig. 5.6): fixed-delay Q-learning with a wrong delay estimate.

Each learner assumes λ̂ = λ + i for an error i up to :data:`MAX_ERROR` either way; the claims,
the shape of the thesis's peak, are in :func:`summarize`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.claims import band_claim, direction_claim, mean_ci_n, paired
from delayed_rl.experiments.framework.experiment import Config, Experiment, Summary, step_count
from delayed_rl.experiments.framework.normalised_runs import (
    GridTask,
    NormalisedRuns,
    grid_task,
    grid_tasks,
)
from delayed_rl.experiments.framework.results import common_seeds
from delayed_rl.experiments.framework.task import optional

#: The grid world's side and the Poisson mean delay λ.
SIZE, LAM = 9, 17
#: The largest error i either way; a quick run takes every :data:`QUICK_ERROR_STEP`-th.
MAX_ERROR, QUICK_ERROR_STEP = 15, 5
#: The steps of a run, and of a quick run.
STEPS, QUICK_STEPS = 150_000, 30_000
#: The thesis's peak of Fig. 5.6: 60 % of the undelayed reward, at i = 0.
THESIS_PEAK = 0.6
PEAK_TOLERANCE = 0.15
"""The band of the peak's height: 0.6 ± 0.15."""
PEAK_ERROR = 3
"""The band of the best estimate's error: 0 ± 3."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class EstimateErrorTask(GridTask):
    """A run of ``estimate-error``.

    Attributes:
        error: the estimate's error i = λ̂ − λ (optional: ``None``, left out of the task's JSON,
            for the undelayed reference run).
    """

    error: int | None = optional()


def tasks(config: Config) -> list[EstimateErrorTask]:
    """Per seed: undelayed Q-learning, then fixed-delay Q-learning with λ̂ = λ + i.

    The errors are i ∈ {−:data:`MAX_ERROR`, ..., :data:`MAX_ERROR`} (every
    :data:`QUICK_ERROR_STEP`-th with ``config.quick``), :data:`STEPS` a run
    (:data:`QUICK_STEPS` with ``config.quick``).
    """
    steps = config.run_steps(STEPS, QUICK_STEPS)
    step = QUICK_ERROR_STEP if config.quick else 1
    errors = range(-MAX_ERROR, MAX_ERROR + 1, step)
    runs = [
        {"size": SIZE, "lam": LAM, "delay_estimates": (LAM + e,), "condition": f"i={e}", "error": e}
        for e in errors
    ]
    return grid_tasks(config, steps, runs, EstimateErrorTask)


def summarize(task_list: list[EstimateErrorTask], results: list[dict], config: Config) -> Summary:
    """Fig. 5.6's shape: a peak of ≈ 0.6 near i = 0, and much less at both ends of the errors.

    Every quantity is formed per seed, its CI over the seeds: the normalised reward at i = 0
    (band 0.6 ± ``PEAK_TOLERANCE``); the error i of the seed's best estimate, its argmax over
    the errors (band 0 ± ``PEAK_ERROR``); and at both ends, i = ±:data:`MAX_ERROR`, the seed's normalised
    reward minus half of its peak (the seed's largest over the errors), below 0: "far below
    the peak" read as less than half of it. A seed whose peak is not positive (a run too short
    to learn) has no such half: NaN, and the row is ``inconclusive``.
    """
    runs = NormalisedRuns.of(task_list, results, by=("error",))
    by_seed, stats = runs.averages(), runs.means()
    errors = sorted(by_seed)
    means = np.array([stats[e][0] for e in errors])
    cis = np.array([stats[e][1] for e in errors])
    seeds = common_seeds(*(by_seed[e] for e in errors))
    table = np.array([[by_seed[e][s] for e in errors] for s in seeds])  # (seeds, errors)
    best = [float(errors[int(np.argmax(row))]) for row in table]
    peaks = table.max(axis=1)  # a seed whose peak is not positive has no "half of it": NaN
    half_peak = dict(zip(seeds, np.where(peaks > 0, 0.5 * peaks, np.nan), strict=True))
    claims = [
        band_claim(
            "normalised reward at i = 0",
            "≈ 0.6 (peak of Fig. 5.6)",
            stats[0],
            THESIS_PEAK,
            PEAK_TOLERANCE,
        ),
        band_claim(
            "error i of each seed's best estimate (argmax over i)",
            "near 0 (Fig. 5.6)",
            mean_ci_n(best),
            0.0,
            PEAK_ERROR,
        ),
    ]
    for end_error in (errors[0], errors[-1]):
        claims.append(
            direction_claim(
                f"normalised reward at i = {end_error:+d} minus half the seed's peak",
                "far below the peak (Fig. 5.6)",
                mean_ci_n(paired(by_seed[end_error], half_peak)),
                "below",
                note="per seed; the peak is the seed's largest normalised reward over i",
            )
        )
    figures = {
        "fig5_6_estimate_error": plotting.figure(
            plotting.errorbar_curve,
            errors,
            means,
            cis,
            f"{SIZE}×{SIZE}, Poisson delays of mean λ = {LAM}: fixed-delay Q-learning assuming λ̂ = λ + i "
            "(Fig. 5.6)\nthesis: a Poisson-like peak at i = 0, far lower at both ends",
            "estimate error i = λ̂ − λ",
            "normalised average reward (Eq. 5.3)",
            n=min(stats[e][2] for e in errors),
            thesis=[(0, THESIS_PEAK, f"thesis: peak ≈ {THESIS_PEAK} at i = 0 (Fig. 5.6)")],
        )
    }
    return Summary(claims, runs.curves(), figures, {"errors": errors, "normalised_means": means})


EXPERIMENT = Experiment(
    name="estimate-error",
    thesis="Fig. 5.6",
    description=f"{2 * MAX_ERROR + 1} fixed-delay Q-learners assume a constant delay "
    f"λ̂ = λ + i (i ∈ [−{MAX_ERROR}, {MAX_ERROR}]) on the {SIZE}×{SIZE} grid world with "
    f"Poisson({LAM}) delays, {step_count(STEPS)} steps each; normalised by undelayed Q-learning "
    "on the same seed (Eq. 5.3).",
    tasks=tasks,
    run_task=grid_task,
    summarize=summarize,
    default_seeds=10,
)
