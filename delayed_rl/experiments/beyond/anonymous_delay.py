"""``anonymous-delay`` (beyond the thesis): anonymous delayed-reward learners beside MMQ.

The thesis's future work asks how MMQ fares against other ways of learning from anonymous,
randomly delayed rewards, and under delays that are not Poisson. This experiment puts the
learners of :data:`~.delay_settings.LEARNERS` on the grid worlds of
:data:`~.delay_settings.SETTINGS` under each of :data:`~.delay_settings.DELAYS` (the framework's
:mod:`~delayed_rl.experiments.framework.delay_settings`, shared with ``future-work``); the
numbers are the constants ``EXPERIMENT.description`` is formatted from. What a run measures is
:func:`~.snapshot_runs.measure`'s; the claims, fixed before the runs, are in :func:`summarize`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np

from delayed_rl.experiments.framework.claims import band_claim, mean_ci_n, paired
from delayed_rl.experiments.framework.delay_estimates import DELAY_TOLERANCE, mean_delay_claim
from delayed_rl.experiments.framework.delay_settings import (
    DELAYS,
    LAMBDA_MAX,
    LEARNERS,
    SettingTask,
    make_delay,
    run_agent,
    setting_label,
    setting_tasks,
    world_texts,
)
from delayed_rl.experiments.framework.experiment import (
    Claim,
    Config,
    Experiment,
    SharedRun,
    Summary,
)
from delayed_rl.experiments.framework.results import common_seeds, pivot
from delayed_rl.experiments.framework.setting_summaries import (
    SEED_SHARE,
    STABLE_SHARE,
    curves_of,
    optimal_seeds_claim,
    paired_gap_claim,
    result_table,
    setting_fields,
    setting_figures,
    stability_claim,
)
from delayed_rl.experiments.framework.snapshot_runs import (
    LOOP_FRACTION,
    SNAPSHOTS,
    WALK_STEPS,
    current_readout,
)
from delayed_rl.experiments.framework.training import hyperparameter_text

#: The worlds of :data:`~.delay_settings.SETTINGS` as the description writes them.
_WORLDS = world_texts()
#: The band of DeconvQ learned's training reward relative to the oracle's: 0 ± this.
REWARD_TOLERANCE = 0.05


def tasks(config: Config) -> list[SettingTask]:
    """Every (setting, agent, seed) of the seven learners (:func:`~.delay_settings.setting_tasks`)."""
    return setting_tasks(config, LEARNERS)


def shared_run(task: SettingTask) -> SharedRun | None:
    """The one run behind a world's undelayed Q-learning (the same under every delay kind).

    MMQ's tasks read its current table (:func:`~.snapshot_runs.current_readout`); every other
    task is its own run.
    """
    if task.agent == "MMQ":
        return SharedRun(run_agent, task, current_readout)
    if task.agent != "Q undelayed":
        return None
    kind = DELAYS[0]
    label = setting_label(task.size, kind, task.lam)
    return SharedRun(run_agent, dataclasses.replace(task, delay=kind, setting=label))


def relative_gap_claim(
    quantity: str,
    thesis: str,
    ours: Mapping[int, float],
    theirs: Mapping[int, float],
    tolerance: float,
) -> Claim:
    """``ours`` (training rewards by seed) within ``tolerance`` of ``theirs``, relative, by seed.

    The statistic is ``(ours_s − theirs_s) / mean(theirs)`` per seed ``s``, tested against the
    band 0 ± ``tolerance``. A baseline that earns nothing on average (mean ≤ 0) leaves no
    relative gap: NaN, and the claim is inconclusive.
    """
    seeds = common_seeds(ours, theirs)
    scale = float(np.mean([theirs[s] for s in seeds])) if seeds else math.nan
    if not seeds or not scale > 0:
        stats = (math.nan, math.nan, len(seeds))
    else:
        stats = mean_ci_n([g / scale for g in paired(ours, theirs)])
    return band_claim(
        quantity, thesis, stats, 0.0, tolerance, note="(ours − theirs) / mean(theirs), by seed"
    )


def delay_claim(quantity: str, runs: Mapping[int, dict], setting: SettingTask) -> Claim:
    """The estimated mean delay (``runs``: results by seed) against the true mean ± ``DELAY_TOLERANCE``.

    ``setting`` is the setting's fields (:func:`~.setting_summaries.setting_fields`).
    """
    true = make_delay(setting.delay, setting.lam).mean
    stats = mean_ci_n([result["mean_delay"] for result in runs.values()])
    return mean_delay_claim(quantity, stats, true)


def _setting_claims(
    setting: str,
    by_agent: dict[str, dict[int, dict]],
    averages: dict[str, dict[int, float]],
    fields: SettingTask,
) -> list[Claim]:
    """The claims of one setting (see :func:`summarize`), for the agents it ran.

    Args:
        setting: the setting's label.
        by_agent: its results, ``{agent: {seed: result}}``.
        averages: their training rewards, ``{agent: {seed: average}}``.
        fields: the setting's fields (:func:`~.setting_summaries.setting_fields`).
    """
    claims = []
    poisson = fields.delay == "Poisson"
    mmq_thesis = (
        "near-optimal greedy policy (Figs. 5.9, Table 5.1: 9×9, Poisson(13))"
        if poisson
        else "extension: as under Poisson (Fig. 5.9)"
    )
    deconv = by_agent.get("DeconvQ learned")
    if deconv:
        claims.append(
            optimal_seeds_claim(setting, "DeconvQ learned", deconv, "extension: ≥ 95 % of seeds")
        )
        if "oracle" in by_agent:
            claims.append(
                relative_gap_claim(
                    f"{setting}: DeconvQ learned training reward relative to the oracle's",
                    "extension: within 5 % of the oracle's",
                    averages["DeconvQ learned"],
                    averages["oracle"],
                    REWARD_TOLERANCE,
                )
            )
        claims.append(delay_claim(f"{setting}: DeconvQ learned mean delay", deconv, fields))
    mmq = by_agent.get("MMQ")
    if mmq:
        claims.append(optimal_seeds_claim(setting, "MMQ", mmq, mmq_thesis))
        claims.append(
            stability_claim(
                setting, "MMQ", mmq, "extension: a settled greedy policy (≥ 90 % optimal)"
            )
        )
        if "Q" in by_agent:
            claims.append(
                paired_gap_claim(
                    f"{setting}: MMQ minus delayed Q training reward",
                    "MMQ above Q (Fig. 5.9)" if poisson else "extension: MMQ above Q",
                    averages["MMQ"],
                    averages["Q"],
                )
            )
    return claims


def summarize(task_list: list[SettingTask], results: list[dict], config: Config) -> Summary:
    """The claims per setting, the full table (``extra["table"]``) and the figures.

    The learners, each with the thesis's hyper-parameters: ``Q`` (Q-learning on the delayed
    reward as it arrives); ``MMQ`` (the thesis's rule, Λ = {0, ..., λ̂max}); ``expected credit``
    (:class:`~delayed_rl.agents.ExpectedCreditQLearning` given the true delay, its pmf clipped
    to λ̂max lags, the horizon every learner here has); ``DeconvQ known`` and ``DeconvQ
    learned`` (:class:`~delayed_rl.agents.DeconvolutionQLearning` given the true delay, or
    learning it on 0..λ̂max); ``oracle`` (:class:`~delayed_rl.agents.OracleQLearning`, told
    which transition each reward came from: the non-anonymous upper bound); ``Q undelayed``
    (the reference; one run per seed and world, shared by its three delays: :func:`shared_run`).
    MMQ's runs also keep a greedy window, which changes nothing of how MMQ learns;
    ``future-work`` reports its snapshots from the same runs.

    ``summary.json`` holds the full table (``table``: one row per setting and agent, every
    metric with its 95 % CI). The claims, per setting, with verdicts by
    :mod:`~delayed_rl.experiments.framework.claims`' rules (each row's ``criterion`` states its
    own):

    - DeconvQ learned walks the optimal loop on at least
      :data:`~.setting_summaries.SEED_SHARE` of the seeds: the count rule (the Wilson 95 %
      interval inside [0.95, 1]; at 20 seeds at best ``inconclusive``);
    - DeconvQ learned's training reward within :data:`REWARD_TOLERANCE` of the oracle's (per
      seed, relative to the oracle's mean): the band 0 ± :data:`REWARD_TOLERANCE`;
    - DeconvQ learned's mean delay: the band λ ± :data:`~.delay_estimates.DELAY_TOLERANCE`;
    - MMQ walks the optimal loop on at least as many seeds (the thesis's Fig. 5.9 and Table 5.1
      result, here carried to other worlds and delays): the count rule, as DeconvQ's;
    - MMQ's greedy snapshots in the second half are optimal at least
      :data:`~.setting_summaries.STABLE_SHARE` of the time (CI inside);
    - MMQ earns more than delayed Q-learning during learning (paired by seed, the direction
      rule).

    Figures, per setting: learning curves with 95 % bands, the delay estimates over the true
    pmf, and the share of seeds whose greedy policy is optimal at each snapshot.
    """
    groups = pivot(task_list, results, by=("setting", "agent"), nested=True)
    averages = pivot(task_list, results, by=("setting", "agent"), value="average", nested=True)
    settings = setting_fields(task_list)
    claims = [
        claim
        for setting, by_agent in groups.items()
        for claim in _setting_claims(setting, by_agent, averages[setting], settings[setting])
    ]
    extra = {
        "table": result_table(groups, settings),
        "rules": {
            "loop_fraction": LOOP_FRACTION,
            "seed_share": SEED_SHARE,
            "reward_tolerance": REWARD_TOLERANCE,
            "delay_tolerance": DELAY_TOLERANCE,
            "stable_share": STABLE_SHARE,
            "snapshots": SNAPSHOTS,
            "max_delay_estimate": LAMBDA_MAX,
        },
    }
    figures = setting_figures(groups, settings, estimators=("DeconvQ learned", "MMQ"))
    return Summary(claims, curves_of(task_list, results), figures, extra)


EXPERIMENT = Experiment(
    name="anonymous-delay",
    thesis="beyond the thesis (its future work; Figs. 5.9, Table 5.1 for MMQ)",
    description="Q-learning, MMQ (Λ = {0.."
    f"{LAMBDA_MAX}}}), expected-credit Q-learning and deconvolution Q-learning (delay known or "
    f"learned on 0..{LAMBDA_MAX}) against the oracle (told each reward's transition) and "
    f"undelayed Q-learning, on the {_WORLDS[0][0]} grid {_WORLDS[0][1]} and the {_WORLDS[1][0]} "
    f"grid {_WORLDS[1][1]} under Poisson, geometric and bimodal (½ at 0, ½ at 2λ) delays of "
    f"mean λ; {hyperparameter_text()}. Greedy policies walked {WALK_STEPS} steps (optimal: ≥ "
    f"{LOOP_FRACTION} of the loop), snapshotted {SNAPSHOTS} times a run; delay estimates; "
    "ns/step. The full table is summary.json's `table`.",
    tasks=tasks,
    run_task=run_agent,
    summarize=summarize,
    default_seeds=20,
    shared_run=shared_run,
)
