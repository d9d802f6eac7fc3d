"""Tables, claims and figures of the anonymous-delay settings' runs, setting by setting.

``anonymous-delay`` and ``future-work`` run learners on the same settings
(:mod:`.delay_settings`) and report them alike, from their results by setting, agent and seed
(a nested :func:`~.results.pivot`): :func:`result_table` makes ``summary.json``'s ``table``,
:func:`curves_of` the curves and :func:`setting_figures` the figures; the claims they share are
:func:`optimal_seeds_claim`, :func:`stability_claim` and :func:`paired_gap_claim`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.claims import (
    count_claim,
    direction_claim,
    mean_ci_n,
    paired,
    range_claim,
)
from delayed_rl.experiments.framework.delay_estimates import ESTIMATE_LABELS
from delayed_rl.experiments.framework.delay_settings import LAMBDA_MAX, SettingTask, make_delay
from delayed_rl.experiments.framework.experiment import Claim, Curve
from delayed_rl.experiments.framework.results import curve_groups
from delayed_rl.experiments.framework.snapshot_runs import (
    LOOP_FRACTION,
    optimal_average,
    snapshot_curves,
)

#: The claims' rules: a share of seeds optimal, and the share of second-half snapshots that are.
SEED_SHARE, STABLE_SHARE = 0.95, 0.90


def setting_fields(task_list: Sequence[SettingTask]) -> dict[str, SettingTask]:
    """Each setting's first task, by its label: what the setting's ``size``, ``delay``, ``lam`` are."""
    fields: dict[str, SettingTask] = {}
    for task in task_list:
        fields.setdefault(task.setting, task)
    return fields


def agent_stats(runs: Mapping[int, dict], setting: SettingTask) -> dict[str, Any]:
    """One row of the table: one agent's metrics in one setting, over its seeds.

    Args:
        runs: the agent's results by seed.
        setting: the setting's fields (:func:`setting_fields`).

    Returns:
        ``optimal_seeds`` and ``seeds`` (k of n), then ``(mean, ci95, n)`` of ``greedy``,
        ``average`` (training), ``second_half_optimal``, ``ns_per_step`` and, when the agent
        estimates the delay, ``mean_delay``; with ``true_mean_delay``.
    """
    results = list(runs.values())
    row: dict[str, Any] = {
        "optimal_seeds": int(sum(r["optimal"] for r in results)),
        "seeds": len(results),
    }
    for key in ("greedy", "average", "second_half_optimal", "ns_per_step"):
        row[key] = mean_ci_n([r[key] for r in results])
    if all("mean_delay" in r for r in results):
        row["mean_delay"] = mean_ci_n([r["mean_delay"] for r in results])
    row["true_mean_delay"] = make_delay(setting.delay, setting.lam).mean
    row["paths"] = sorted({r["path"] for r in results})
    return row


def result_table(
    groups: dict[str, dict[str, dict[int, dict]]], settings: dict[str, SettingTask]
) -> list[dict[str, Any]]:
    """The full table for ``summary.json``: one :func:`agent_stats` row per (setting, agent).

    Args:
        groups: the results, ``{setting: {agent: {seed: result}}}``.
        settings: each setting's fields (:func:`setting_fields`).
    """
    table = []
    for setting, by_agent in groups.items():
        for agent, runs in by_agent.items():
            row = agent_stats(runs, settings[setting])
            flat: dict[str, Any] = {"setting": setting, "agent": agent}
            for key, value in row.items():
                if isinstance(value, tuple):
                    flat[key], flat[f"{key}_ci95"], flat[f"{key}_n"] = value
                else:
                    flat[key] = value
            table.append(flat)
    return table


def optimal_seeds_claim(setting: str, agent: str, runs: Mapping[int, dict], thesis: str) -> Claim:
    """``agent``'s seeds whose final greedy policy is optimal, k of n: the share in [SEED_SHARE, 1].

    The count rule (:func:`~delayed_rl.experiments.framework.claims.count_claim`): the Wilson 95 %
    interval of the share against the band ``[SEED_SHARE, 1]``.

    Args:
        setting: the setting's label.
        agent: the agent's name.
        runs: its results in the setting, by seed.
        thesis: what the thesis says.
    """
    flags = [bool(result["optimal"]) for result in runs.values()]
    return count_claim(
        f"{setting}: {agent} seeds whose greedy policy is optimal",
        thesis,
        sum(flags),
        len(flags),
        SEED_SHARE,
        1.0,
        note=f"optimal: a 1000-step greedy walk ≥ {LOOP_FRACTION} of the loop",
    )


def paired_gap_claim(
    quantity: str, thesis: str, ours: Mapping[int, float], theirs: Mapping[int, float]
) -> Claim:
    """``ours`` above ``theirs`` (``{seed: value}``): the direction rule on the paired difference."""
    gaps = paired(ours, theirs)
    return direction_claim(quantity, thesis, mean_ci_n(gaps), "above", note="paired by seed")


def stability_claim(setting: str, agent: str, runs: Mapping[int, dict], thesis: str) -> Claim:
    """``agent``'s share of second-half greedy snapshots that are optimal, in [STABLE_SHARE, 1].

    Per seed, the share of its snapshots after half the steps that are optimal; the 95 % CI
    of its mean over the seeds against the band ``[STABLE_SHARE, 1]``.

    Args:
        setting: the setting's label.
        agent: the agent's name.
        runs: its results in the setting, by seed.
        thesis: what the thesis says.
    """
    stats = mean_ci_n([result["second_half_optimal"] for result in runs.values()])
    return range_claim(
        f"{setting}: {agent} share of second-half greedy snapshots optimal",
        thesis,
        stats,
        STABLE_SHARE,
        1.0,
        note="per seed, the share of its snapshots after half the steps that are optimal",
    )


def curves_of(task_list: Sequence[SettingTask], results: list[dict]) -> list[Curve]:
    """The learning curves and the snapshot optimality of every run, for ``curves.csv``."""
    return [
        curve
        for task, result in zip(task_list, results, strict=True)
        for curve in snapshot_curves(f"{task.setting} | {task.agent}", task.seed, result)
    ]


def slug(task: SettingTask) -> str:
    """A file-name form of a task's setting, from its world and delay kind: ``"7x7_poisson"``."""
    return f"{task.size}x{task.size}_{task.delay.lower()}"


def setting_figures(
    groups: dict[str, dict[str, dict[int, dict]]],
    settings: dict[str, SettingTask],
    estimators: Sequence[str],
    same_curves: Sequence[str] = (),
) -> dict[str, Callable[[Path], None]]:
    """Per setting: learning curves, the delay estimates of ``estimators``, optimal snapshots.

    Args:
        groups: the results, ``{setting: {agent: {seed: result}}}``.
        settings: each setting's fields (:func:`setting_fields`).
        estimators: the agents whose delay estimates are drawn (those that have one).
        same_curves: agents left out of the learning curves because they train exactly as
            another one (the title says so).
    """
    figures = {}
    for setting, by_agent in groups.items():
        task0 = settings[setting]
        size, name = task0.size, slug(task0)
        optimum = (optimal_average(size), f"optimal loop ({optimal_average(size):.3f})")
        drawn = {a: runs for a, runs in by_agent.items() if a not in same_curves}
        left_out = [a for a in same_curves if a in by_agent]
        suffix = f"\n({', '.join(left_out)}: the same curve as the thesis rule)" if left_out else ""
        thesis = ""  # the thesis's Poisson statement, in words (Fig. 5.9 gives no value here)
        if task0.delay == "Poisson":
            above = ", above Q" if "Q" in by_agent else ""
            thesis = f"\nthesis (Poisson, Fig. 5.9): MMQ near-optimal{above}"
        snaps = curve_groups(by_agent, "snapshot_steps", "snapshot_optimal")
        figures[f"learning_curves_{name}"] = plotting.figure(
            plotting.band_plot,
            curve_groups(drawn),
            f"{setting}: average reward during learning{thesis}{suffix}",
            "time step",
            "average reward (undelayed)",
            None,
            optimum,
        )
        figures[f"optimal_snapshots_{name}"] = plotting.figure(
            plotting.band_plot,
            snaps,
            f"{setting}: share of seeds whose greedy policy is optimal{thesis}",
            "time step",
            "share of seeds optimal",
            (-0.05, 1.05),
        )
        estimates = {
            a: [(r["estimate_support"], r["estimate"]) for r in by_agent[a].values()]
            for a in estimators
            if a in by_agent and all("estimate" in r for r in by_agent[a].values())
        }
        if estimates:
            delay = make_delay(task0.delay, task0.lam)
            true_pmf = np.asarray(delay.pmf(np.arange(LAMBDA_MAX + 1)), dtype=float)
            estimates = {ESTIMATE_LABELS.get(a, a): runs for a, runs in estimates.items()}
            figures[f"delay_estimate_{name}"] = plotting.figure(
                plotting.estimate_plot,
                estimates,
                true_pmf,
                f"{setting}: delay estimates against the true pmf",
            )
    return figures
