"""``anonymous-delay`` (beyond the thesis): anonymous delayed-reward learners beside MMQ.

The thesis's future work asks how MMQ fares against other ways of learning from anonymous,
randomly delayed rewards, and under delays that are not Poisson. This experiment puts seven
learners on the grid world, each with the thesis's hyper-parameters (α = 0.1, γ = 0.9, constant
ε = 0.1, ``q_init`` = 25, see :mod:`~delayed_rl.experiments.framework.training`):

- ``Q``: Q-learning on the delayed reward as it arrives;
- ``MMQ``: Multiple Model Q-learning, Λ = {0, ..., 50} (the thesis's rule);
- ``expected credit``: :class:`~delayed_rl.agents.ExpectedCreditQLearning` given the true delay
  (its pmf clipped to 50 lags, the horizon every learner here has);
- ``DeconvQ known``: :class:`~DeconvolutionQLearning` given the true delay (``max_delay_estimate`` 50);
- ``DeconvQ learned``: :class:`~DeconvolutionQLearning` learning the delay on 0..50;
- ``oracle``: :class:`~delayed_rl.agents.OracleQLearning`, which is told which transition each
  reward came from (the non-anonymous upper bound);
- ``Q undelayed``: Q-learning without any delay (the reference; one run per seed and world,
  shared by its three delays: :func:`shared_run`).

Settings: the 9×9 grid with mean delay λ = 13 (1M steps a run) and the 7×7 grid with λ = 8
(300k steps), each under three delays of mean λ: Poisson(λ) (the thesis's), geometric
(``Geometric(p)`` with ``p = 1 / (λ + 1)``, mean ``(1 − p) / p = λ``) and a bimodal one (mass ½
at 0 and ½ at 2λ, an ``Empirical`` pmf). 20 seeds; a task is one (setting, agent, seed), 840 at
full size. ``--quick``: 7×7 under Poisson only, 2 seeds, 30k steps.

Per run, from the undelayed reward stream (``training_log["undelayed_reward"]``):

- the learning curve (running average reward) and the training mean reward;
- the greedy 1000-step average: the agent's deterministic greedy policy walked from the start
  cell of the undelayed grid; the policy is *optimal* when that average is at least
  ``LOOP_FRACTION`` = 0.95 of the optimum ``10 / (2(n − 1) + 1)``;
- greedy snapshots (:mod:`~delayed_rl.experiments.framework.snapshot_runs`): the run learns in
  ``SNAPSHOTS`` = 50 pieces and after each records whether the greedy policy is optimal: a
  policy that settled, or one that keeps flipping;
- the delay estimate: DeconvQ's ``delay_pmf`` and ``mean_delay``; MMQ's acting-delay share;
- MMQ's runs also keep a greedy window (``greedy_window`` = ``steps // 10``), which changes
  nothing of how MMQ learns; ``future-work`` reports its snapshots from the same runs;
- ns/step: the wall time of ``learn`` over the steps, greedy evaluations excluded, after an
  untimed warm-up run that loads the compiled kernels.

``summary.json`` holds the full table (``table``: one row per setting and agent, every metric
with its 95 % CI). The claims, per setting, with verdicts computed from the runs by
:mod:`~delayed_rl.experiments.framework.claims`' rules (each row's ``criterion`` states its own):

- DeconvQ learned walks the optimal loop on at least 95 % of the seeds: the count rule (the
  Wilson 95 % interval inside [0.95, 1]; at 20 seeds at best ``inconclusive``);
- DeconvQ learned's training reward within 5 % of the oracle's (per seed, relative to the
  oracle's mean): the band 0 ± 0.05;
- DeconvQ learned's mean delay: the band λ ± 10 %;
- MMQ walks the optimal loop on at least 95 % of the seeds (the thesis's Fig. 5.9 and Table 5.1
  result, here carried to other worlds and delays): the count rule, as DeconvQ's;
- MMQ's greedy snapshots in the second half are optimal at least 90 % of the time (CI inside);
- MMQ earns more than delayed Q-learning during learning (paired by seed, the direction rule).

Figures, per setting: learning curves with 95 % bands, the delay estimates over the true pmf,
and the share of seeds whose greedy policy is optimal at each snapshot.

What ``future-work`` (MMQ variants on the same settings) shares with this experiment is in the
framework: :mod:`~delayed_rl.experiments.framework.delay_settings` (settings, learners, the run)
and :mod:`~delayed_rl.experiments.framework.setting_summaries` (tables, claims, figures).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from delayed_rl.experiments.framework.claims import band_claim, mean_ci_n, paired
from delayed_rl.experiments.framework.delay_estimates import DELAY_TOLERANCE, mean_delay_claim
from delayed_rl.experiments.framework.delay_settings import (
    DELAYS,
    LAMBDA_MAX,
    LEARNERS,
    make_delay,
    run_agent,
    setting_label,
    setting_tasks,
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
    current_readout,
)

#: The band of DeconvQ learned's training reward relative to the oracle's: 0 ± this.
REWARD_TOLERANCE = 0.05


def tasks(config: Config) -> list[dict]:
    """Every (setting, agent, seed) of the seven learners (:func:`~.delay_settings.setting_tasks`)."""
    return setting_tasks(config, LEARNERS)


def shared_run(task: dict) -> SharedRun | None:
    """The one run behind a world's undelayed Q-learning (the same under every delay kind).

    MMQ's tasks read its current table (:func:`~.snapshot_runs.current_readout`); every other
    task is its own run.
    """
    if task["agent"] == "MMQ":
        return SharedRun(run_agent, task, current_readout)
    if task["agent"] != "Q undelayed":
        return None
    kind = DELAYS[0]
    label = setting_label(task["size"], kind, task["lam"])
    return SharedRun(run_agent, {**task, "delay": kind, "setting": label})


#: Compiled training cost per step (µs) of each learner on these grids, for scheduling only.
STEP_MICROSECONDS = {"DeconvQ learned": 1.8, "DeconvQ known": 0.9, "MMQ": 0.8}


def cost(task: dict) -> float:
    """A task's estimated core-seconds (its steps at :data:`STEP_MICROSECONDS`, else 0.7 µs)."""
    return 1e-6 * task["steps"] * STEP_MICROSECONDS.get(task["agent"], 0.7)


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


def delay_claim(quantity: str, runs: Mapping[int, dict], setting: dict) -> Claim:
    """The estimated mean delay (``runs``: results by seed) against the true mean ± ``DELAY_TOLERANCE``.

    ``setting`` is the setting's fields (:func:`~.setting_summaries.setting_fields`).
    """
    true = make_delay(setting["delay"], setting["lam"]).mean
    stats = mean_ci_n([result["mean_delay"] for result in runs.values()])
    return mean_delay_claim(quantity, stats, true)


def _setting_claims(
    setting: str,
    by_agent: dict[str, dict[int, dict]],
    averages: dict[str, dict[int, float]],
    fields: dict,
) -> list[Claim]:
    """The claims of one setting (see the module docstring), for the agents it ran.

    Args:
        setting: the setting's label.
        by_agent: its results, ``{agent: {seed: result}}``.
        averages: their training rewards, ``{agent: {seed: average}}``.
        fields: the setting's fields (:func:`~.setting_summaries.setting_fields`).
    """
    claims = []
    poisson = "Poisson" in setting
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


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """The claims per setting, the full table (``extra["table"]``) and the figures."""
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
            "lambda_max": LAMBDA_MAX,
        },
    }
    figures = setting_figures(groups, settings, estimators=("DeconvQ learned", "MMQ"))
    return Summary(claims, curves_of(task_list, results), figures, extra)


EXPERIMENT = Experiment(
    name="anonymous-delay",
    thesis="beyond the thesis (its future work; Figs. 5.9, Table 5.1 for MMQ)",
    description="Q-learning, MMQ (Λ = {0..50}), expected-credit Q-learning and deconvolution "
    "Q-learning (delay known or learned on 0..50) against the oracle (told each reward's "
    "transition) and undelayed Q-learning, on the 9×9 grid (λ = 13, 1M steps) and the 7×7 grid "
    "(λ = 8, 300k steps) under Poisson, geometric and bimodal (½ at 0, ½ at 2λ) delays of mean "
    "λ; α = 0.1, γ = 0.9, ε = 0.1, q_init = 25. Greedy policies walked 1000 steps (optimal: ≥ "
    "0.95 of the loop), snapshotted 50 times a run; delay estimates; ns/step. The full table "
    "is summary.json's `table`.",
    tasks=tasks,
    run_task=run_agent,
    summarize=summarize,
    default_seeds=20,
    shared_run=shared_run,
    cost=cost,
)
