"""``future-work`` (beyond the thesis): variants of MMQ on the ``anonymous-delay`` settings.

Each variant changes one piece of MMQ's rule (:class:`~MultipleModelQLearning`'s keyword
arguments; ``None`` keeps the thesis's rule), all with Λ = {0, ..., 50} and the thesis's
hyper-parameters (α = 0.1, γ = 0.9, constant ε = 0.1, ``q_init`` = 25):

- ``MMQ (thesis)``: the thesis's rule;
- ``MMQ kernel σ=2``, ``MMQ kernel σ=5``: ``reward_kernel=σ``, each reward credited to the
  models λ̂ near the acting one with a Gaussian kernel of width σ over λ̂;
- ``MMQ trace β=0.9``: ``delay_trace=0.9``, a replacing trace along λ̂;
- ``MMQ Λ step 3``: ``delay_step=3``, Λ = {0, 3, ..., 48} (a third of the models);
- ``MMQ greedy window 100k``: ``greedy_window=W``, the greedy policy read from an average of
  the Q-table over the last W steps (``greedy_table``), W = ``steps // 10``: 100k at 1M steps,
  30k at 300k, 3k in the quick run.

The window changes only how the greedy policy is read, not how MMQ learns or acts, so the thesis
rule and the greedy window are read off one run a seed: ``anonymous-delay``'s MMQ run, which
keeps the averaged table beside the current one (:func:`shared_run`). Run together (``delayed-rl
reproduce``), the two experiments share those runs; run alone, this one makes them itself.

Settings, seeds, metrics, snapshots and figures are ``anonymous-delay``'s (the framework's
:mod:`~delayed_rl.experiments.framework.delay_settings`,
:mod:`~delayed_rl.experiments.framework.snapshot_runs` and
:mod:`~delayed_rl.experiments.framework.setting_summaries`, which both call): the 9×9 grid with
λ = 13 (1M steps) and the 7×7 grid with λ = 8 (300k steps), each under Poisson, geometric and
bimodal delays of mean λ, 20 seeds; 720 tasks at full size. ``--quick``: 7×7 under Poisson,
2 seeds, 30k steps. The greedy policy of every variant is what its ``greedy_table`` (or
``predict``) gives; the delay estimate is the acting-delay share (drawn per unit of λ̂ for the
Λ-step-3 variant, so it is on the other curves' scale).

The claims, per setting and variant, with verdicts computed from the runs by
:mod:`~delayed_rl.experiments.framework.claims`' rules (each row's ``criterion`` states its
own), as ``anonymous-delay``'s:

- the variant walks the optimal loop on at least 95 % of the seeds: the Wilson 95 % interval
  of the share of optimal seeds inside [0.95, 1] (at 20 seeds at best ``inconclusive``);
- its greedy snapshots after half the run are optimal at least 90 % of the time (does the
  variant stop the greedy policy flipping between routes?): the per-seed share's CI inside
  [0.9, 1];
- (the variants that act otherwise than the thesis's rule: all but the greedy window, which
  learns and acts exactly as the thesis's rule) its training reward minus the thesis rule's,
  paired by seed: the direction rule, above 0 (the variant earns more while learning).

``summary.json``'s ``table`` holds every metric per (setting, variant).
"""

from __future__ import annotations

from typing import Any

from delayed_rl._validation import check_choice
from delayed_rl.experiments.framework import delay_settings, setting_summaries, snapshot_runs
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
VARIANTS: dict[str, dict[str, Any]] = {
    THESIS: {},
    "MMQ kernel σ=2": {"reward_kernel": 2.0},
    "MMQ kernel σ=5": {"reward_kernel": 5.0},
    "MMQ trace β=0.9": {"delay_trace": 0.9},
    "MMQ Λ step 3": {"delay_step": 3},
    "MMQ greedy window 100k": {"greedy_window": None},  # steps // delay_settings.WINDOW_DIVISOR
}
"""Each variant's keyword arguments to ``MMQ`` (the greedy window's is set from the steps)."""
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


def shared_run(task: dict) -> SharedRun | None:
    """The thesis rule and the greedy window: ``anonymous-delay``'s MMQ run, read two ways.

    Its current table for ``MMQ (thesis)``, its averaged table for the greedy-window variant;
    every other variant is its own run.
    """
    if task["agent"] not in (THESIS, *GREEDY_ONLY):
        return None
    if task["agent"] == THESIS:
        view = snapshot_runs.current_readout
    else:
        view = snapshot_runs.averaged_readout
    return SharedRun(delay_settings.run_agent, {**task, "agent": "MMQ"}, view)


#: Compiled training cost per step (µs) of each variant on these grids, for scheduling only.
STEP_MICROSECONDS = {"MMQ kernel σ=2": 1.2, "MMQ kernel σ=5": 1.1, "MMQ Λ step 3": 0.35}


def cost(task: dict) -> float:
    """A task's estimated core-seconds (its steps at :data:`STEP_MICROSECONDS`, else 0.85 µs)."""
    return 1e-6 * task["steps"] * STEP_MICROSECONDS.get(task["agent"], 0.85)


def tasks(config: Config) -> list[dict]:
    """Every (setting, variant, seed), as ``anonymous-delay``'s (:func:`~.setting_tasks`)."""
    return delay_settings.setting_tasks(config, tuple(VARIANTS))


def run_task(task: dict) -> dict:
    """Train one variant in its setting and measure it as ``anonymous-delay`` does.

    The thesis rule and the greedy window are its MMQ run, read as :func:`shared_run` says.
    """
    run = shared_run(task)
    if run is not None:
        return run.alone()
    delay = delay_settings.make_delay(task["delay"], task["lam"])
    size, steps, seed = task["size"], task["steps"], task["seed"]
    variant = task["agent"]
    snapshot_runs.warm_up(
        lambda: make_variant(variant, size, delay, steps, seed + 1), steps, variant
    )
    return snapshot_runs.measure(make_variant(task["agent"], size, delay, steps, seed), task)


def _setting_claims(
    setting: str, by_variant: dict[str, dict[int, dict]], averages: dict[str, dict[int, float]]
) -> list[Claim]:
    """Per variant: optimal seeds, second-half stability and (variants) reward against the thesis.

    Args:
        setting: the setting's label.
        by_variant: its results, ``{variant: {seed: result}}``.
        averages: their training rewards, ``{variant: {seed: average}}``.
    """
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
                if is_thesis and "Poisson" in setting
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


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """The claims per setting and variant, the full table (``extra["table"]``), the figures."""
    groups = pivot(task_list, results, by=("setting", "agent"), nested=True)
    averages = pivot(task_list, results, by=("setting", "agent"), value="average", nested=True)
    settings = setting_summaries.setting_fields(task_list)
    claims = [
        claim
        for setting, runs in groups.items()
        for claim in _setting_claims(setting, runs, averages[setting])
    ]
    extra = {
        "table": setting_summaries.result_table(groups, settings),
        "variants": {
            name: options(name, task_list[0]["steps"]) if task_list else VARIANTS[name]
            for name in VARIANTS
        },
        "rules": {
            "loop_fraction": snapshot_runs.LOOP_FRACTION,
            "seed_share": setting_summaries.SEED_SHARE,
            "stable_share": setting_summaries.STABLE_SHARE,
            "snapshots": snapshot_runs.SNAPSHOTS,
            "lambda_max": delay_settings.LAMBDA_MAX,
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
    description="MMQ (Λ = {0..50}) with the thesis's rule against five variants — a Gaussian "
    "reward kernel over λ̂ (σ = 2, 5), a replacing trace along λ̂ (β = 0.9), Λ in steps of 3, "
    "and a greedy policy read from the Q-table averaged over steps/10 — on anonymous-delay's "
    "settings: 9×9 (λ = 13, 1M steps) and 7×7 (λ = 8, 300k steps) under Poisson, geometric and "
    "bimodal delays of mean λ; greedy 1000-step walks, 50 greedy snapshots a run, acting-delay "
    "shares, ns/step. The full table is summary.json's `table`.",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=20,
    shared_run=shared_run,
    cost=cost,
)
