"""``future-work`` (beyond the thesis): variants of MMQ on the ``anonymous-delay`` settings.

Each variant (:data:`VARIANTS`) changes one piece of MMQ's rule; settings, seeds, metrics,
snapshots and figures are ``anonymous-delay``'s (the framework's
:mod:`~delayed_rl.experiments.framework.delay_settings`,
:mod:`~delayed_rl.experiments.framework.snapshot_runs` and
:mod:`~delayed_rl.experiments.framework.setting_summaries`). The thesis rule and the greedy
window are read off ``anonymous-delay``'s MMQ runs (:func:`shared_run`). The numbers are the
constants ``EXPERIMENT.description`` is formatted from; the claims are in :func:`summarize`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from delayed_rl._validation import check_choice
from delayed_rl.experiments.framework import delay_settings, setting_summaries, snapshot_runs
from delayed_rl.experiments.framework.delay_settings import SettingTask
from delayed_rl.experiments.framework.experiment import (
    Claim,
    Config,
    Experiment,
    SharedRun,
    Summary,
)
from delayed_rl.experiments.framework.results import pivot
from delayed_rl.experiments.framework.training import thesis_hyperparameters

THESIS = "MMQ (thesis)"
#: The kernel variants' widths σ, the trace variant's β and the coarse variant's step of Λ.
KERNEL_WIDTHS, TRACE, DELAY_STEP = (2.0, 5.0), 0.9, 3
VARIANTS: dict[str, dict[str, Any]] = {
    THESIS: {},
    **{f"MMQ kernel σ={width:g}": {"reward_kernel": width} for width in KERNEL_WIDTHS},
    f"MMQ trace β={TRACE}": {"delay_trace": TRACE},
    f"MMQ Λ step {DELAY_STEP}": {"delay_step": DELAY_STEP},
    "MMQ greedy window 100k": {"greedy_window": None},  # steps // delay_settings.WINDOW_DIVISOR
}
"""Each variant's keyword arguments to ``MMQ`` (:class:`~delayed_rl.agents.MultipleModelQLearning`).

All have Λ = {0, ..., λ̂max} and the thesis's hyper-parameters; ``{}`` keeps the thesis's rule:

- ``MMQ kernel σ=...``: ``reward_kernel=σ``, each reward credited to the models λ̂ near the
  acting one with a Gaussian kernel of width σ over λ̂;
- ``MMQ trace β=...``: ``delay_trace=β``, a replacing trace along λ̂;
- ``MMQ Λ step ...``: ``delay_step``, Λ in those steps (a third of the models at 3);
- ``MMQ greedy window 100k``: ``greedy_window=W``, the greedy policy read from an average of
  the Q-table over the last W steps (``greedy_table``), W = ``steps // WINDOW_DIVISOR`` (100k
  at 1M steps; the name is the full run's). The window changes only how the greedy policy is
  read, not how MMQ learns or acts.
"""
#: The settings' worlds as the description writes them.
_WORLDS = delay_settings.world_texts()
GREEDY_ONLY = ("MMQ greedy window 100k",)
"""Variants that act as the thesis's rule (only their greedy policy differs): no training-reward
claim, and no curve of their own in the learning-curve and delay-estimate figures (they are the
thesis rule's)."""


def options(variant: str, steps: int) -> dict[str, Any]:
    """The ``MMQ`` keyword arguments of ``variant`` for a run of ``steps`` steps.

    Raises:
        TypeError: ``variant`` is not a string.
        ValueError: ``variant`` is not one of :data:`VARIANTS`.
    """
    check_choice("variant", variant, tuple(VARIANTS))
    chosen = dict(VARIANTS[variant])
    if "greedy_window" in chosen:
        chosen["greedy_window"] = max(1, steps // delay_settings.WINDOW_DIVISOR)
    return chosen


def make_variant(variant: str, size: int, delay: Any, steps: int, seed: int) -> Any:
    """MMQ with Λ = {0..50} and ``variant``'s options on the ``size`` grid under ``delay``."""
    from delayed_rl.agents import MultipleModelQLearning

    return MultipleModelQLearning(
        delay_settings.grid(size, delay),
        max_delay_estimate=delay_settings.LAMBDA_MAX,
        **options(variant, steps),
        **thesis_hyperparameters(seed),
    )


#: Compiled training cost per step (µs) of the variants on these grids, for scheduling only.
STEP_MICROSECONDS = {"MMQ kernel σ=2": 1.2, "MMQ kernel σ=5": 1.1, "MMQ Λ step 3": 0.35}


@dataclasses.dataclass(frozen=True, kw_only=True)
class VariantTask(SettingTask):
    """A variant's run in one of ``anonymous-delay``'s settings (``agent``: the variant)."""

    def cost(self) -> float:
        """The run's estimated core-seconds (its steps at :data:`STEP_MICROSECONDS`, else 0.85 µs)."""
        return 1e-6 * self.steps * STEP_MICROSECONDS.get(self.agent, 0.85)


def shared_run(task: SettingTask) -> SharedRun | None:
    """The thesis rule and the greedy window: ``anonymous-delay``'s MMQ run, read two ways.

    Its current table for ``MMQ (thesis)``, its averaged table for the greedy-window variant;
    every other variant is its own run.
    """
    if task.agent not in (THESIS, *GREEDY_ONLY):
        return None
    thesis = task.agent == THESIS
    view = snapshot_runs.current_readout if thesis else snapshot_runs.averaged_readout
    return SharedRun(delay_settings.run_agent, dataclasses.replace(task, agent="MMQ"), view)


def tasks(config: Config) -> list[SettingTask]:
    """Every (setting, variant, seed), as ``anonymous-delay``'s (:func:`~.setting_tasks`)."""
    return delay_settings.setting_tasks(config, tuple(VARIANTS), VariantTask)


def run_task(task: SettingTask) -> dict:
    """Train one variant in its setting and measure it as ``anonymous-delay`` does.

    The thesis rule and the greedy window are its MMQ run, read as :func:`shared_run` says.
    """
    run = shared_run(task)
    if run is not None:
        return run.alone()
    delay = delay_settings.make_delay(task.delay, task.lam)
    size, steps, seed = task.size, task.steps, task.seed
    variant = task.agent
    snapshot_runs.warm_up(
        lambda: make_variant(variant, size, delay, steps, seed + 1), steps, variant
    )
    return snapshot_runs.measure(make_variant(task.agent, size, delay, steps, seed), steps, size)


def _setting_claims(
    fields: SettingTask,
    by_variant: dict[str, dict[int, dict]],
    averages: dict[str, dict[int, float]],
) -> list[Claim]:
    """Per variant: optimal seeds, second-half stability and (variants) reward against the thesis.

    Args:
        fields: the setting's fields (:func:`~.setting_summaries.setting_fields`).
        by_variant: its results, ``{variant: {seed: result}}``.
        averages: their training rewards, ``{variant: {seed: average}}``.
    """
    setting = fields.setting
    claims = []
    thesis = by_variant.get(THESIS)
    for variant, runs in by_variant.items():
        is_thesis = variant == THESIS
        claims.append(
            setting_summaries.optimal_seeds_claim(
                setting,
                variant,
                runs,
                "near-optimal greedy policy (Fig. 5.9)"
                if is_thesis and fields.delay == "Poisson"
                else "future work: ≥ 95 % of seeds",
            )
        )
        claims.append(
            setting_summaries.stability_claim(
                setting, variant, runs, "future work: a settled greedy policy (≥ 90 %)"
            )
        )
        if not is_thesis and thesis and variant not in GREEDY_ONLY:
            claims.append(
                setting_summaries.paired_gap_claim(
                    f"{setting}: {variant} minus {THESIS} training reward",
                    "future work: above the thesis rule",
                    averages[variant],
                    averages[THESIS],
                )
            )
    return claims


def summarize(task_list: list[SettingTask], results: list[dict], config: Config) -> Summary:
    """The claims per setting and variant, the full table (``extra["table"]``), the figures.

    The greedy policy of every variant is what its ``greedy_table`` (or ``predict``) gives; the
    delay estimate is the acting-delay share (drawn per unit of λ̂ for the Λ-step variant, so it
    is on the other curves' scale). The claims, per setting and variant, with verdicts by
    :mod:`~delayed_rl.experiments.framework.claims`' rules, as ``anonymous-delay``'s:

    - the variant walks the optimal loop on at least :data:`~.setting_summaries.SEED_SHARE` of
      the seeds: the Wilson 95 % interval of the share of optimal seeds inside [0.95, 1] (at 20
      seeds at best ``inconclusive``);
    - its greedy snapshots after half the run are optimal at least
      :data:`~.setting_summaries.STABLE_SHARE` of the time (does the variant stop the greedy
      policy flipping between routes?): the per-seed share's CI inside [0.9, 1];
    - (the variants that act otherwise than the thesis's rule: all but :data:`GREEDY_ONLY`)
      its training reward minus the thesis rule's, paired by seed: the direction rule, above 0
      (the variant earns more while learning).

    ``summary.json``'s ``table`` holds every metric per (setting, variant).
    """
    groups = pivot(task_list, results, by=("setting", "agent"), nested=True)
    averages = pivot(task_list, results, by=("setting", "agent"), value="average", nested=True)
    settings = setting_summaries.setting_fields(task_list)
    claims = [
        claim
        for setting, runs in groups.items()
        for claim in _setting_claims(settings[setting], runs, averages[setting])
    ]
    extra = {
        "table": setting_summaries.result_table(groups, settings),
        "variants": {
            name: options(name, task_list[0].steps) if task_list else VARIANTS[name]
            for name in VARIANTS
        },
        "rules": {
            "loop_fraction": snapshot_runs.LOOP_FRACTION,
            "seed_share": setting_summaries.SEED_SHARE,
            "stable_share": setting_summaries.STABLE_SHARE,
            "snapshots": snapshot_runs.SNAPSHOTS,
            "max_delay_estimate": delay_settings.LAMBDA_MAX,
        },
    }
    estimators = tuple(name for name in VARIANTS if name not in GREEDY_ONLY)
    figures = setting_summaries.setting_figures(
        groups, settings, estimators=estimators, same_curves=GREEDY_ONLY
    )
    curves = setting_summaries.curves_of(task_list, results)
    return Summary(claims, curves, figures, extra)


EXPERIMENT = Experiment(
    name="future-work",
    thesis="beyond the thesis (its future work)",
    description=f"MMQ (Λ = {{0..{delay_settings.LAMBDA_MAX}}}) with the thesis's rule against "
    "five variants — a Gaussian reward kernel over λ̂ "
    f"(σ = {', '.join(f'{width:g}' for width in KERNEL_WIDTHS)}), a replacing trace along λ̂ "
    f"(β = {TRACE}), Λ in steps of {DELAY_STEP}, and a greedy policy read from the Q-table "
    f"averaged over steps/{delay_settings.WINDOW_DIVISOR} — on anonymous-delay's settings: "
    f"{_WORLDS[0][0]} {_WORLDS[0][1]} and {_WORLDS[1][0]} {_WORLDS[1][1]} under Poisson, "
    f"geometric and bimodal delays of mean λ; greedy {snapshot_runs.WALK_STEPS}-step walks, "
    f"{snapshot_runs.SNAPSHOTS} greedy snapshots a run, acting-delay shares, ns/step. The full "
    "table is summary.json's `table`.",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=20,
    shared_run=shared_run,
)
