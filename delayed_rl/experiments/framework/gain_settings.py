"""What the experiments that score methods between a random policy and an oracle share.

A *setting* is a dict of run fields; each (setting, method, seed) is a task, a
:class:`GainTask`. A method's *gain*
in a setting is ``(score − random) / (oracle − random)``, with the mean scores of the random
policy (method ``"random"``) and of the oracle (method ``"oracle"``) over the setting's seeds:
0 is the random policy's level, 1 the oracle's. The experiments read their results by setting,
method and seed (``{setting: {method: {seed: result}}}``), a nested
:func:`~delayed_rl.experiments.framework.results.pivot`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, TypeVar

import numpy as np

from delayed_rl.experiments.framework import claims as rules
from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.experiment import Claim, Config, Curve, Summary
from delayed_rl.experiments.framework.results import curve_groups
from delayed_rl.experiments.framework.task import Task

__all__ = [
    "GainTask",
    "RewardDelayTask",
    "curve_means",
    "delay_fields",
    "gain_rows",
    "gain_summary",
    "gain_tasks",
    "learning_curves",
    "method_gains",
    "method_colours",
]


@dataclasses.dataclass(frozen=True, kw_only=True)
class GainTask(Task):
    """A (setting, method, seed) of an experiment that scores methods by their gain.

    Attributes:
        setting: the setting's name.
        method: the method (``"random"`` and ``"oracle"`` among them).
        steps: training steps.
        eval_every: the steps between two scorings of the policy.
    """

    setting: str
    method: str
    steps: int
    eval_every: int


@dataclasses.dataclass(frozen=True, kw_only=True)
class RewardDelayTask(GainTask):
    """A :class:`GainTask` under a reward delay (what :func:`delay_fields` reads).

    Attributes:
        delay: the reward delay, as :meth:`~delayed_rl.delays.Delay.to_dict` writes it.
        max_delay_estimate: the longest delay a learned delay pmf models.
    """

    delay: dict[str, Any]
    max_delay_estimate: int


TaskType = TypeVar("TaskType", bound=GainTask)


def gain_tasks(
    config: Config,
    settings: dict[str, dict[str, Any]],
    quick: dict[str, tuple[int, int]],
    methods: tuple[str, ...] | dict[str, tuple[str, ...]],
    kind: type[TaskType],
) -> list[TaskType]:
    """Every (setting, method, seed) as a task of type ``kind``, in that order of loops.

    ``methods`` holds every setting's methods, or maps each setting to its own. A setting's
    ``"seeds"`` entry, where present, is its own number of seeds, capped by ``config.seeds``
    (the experiment's default is the largest, so ``--seeds`` lowers them all); it is not a task
    field. ``config.quick`` keeps only the settings of ``quick``, with its ``(steps, eval_every)``;
    ``config.steps`` sets the steps of every run (evaluated ten times along the way).
    """
    chosen = quick if config.quick else {name: None for name in settings}
    out = []
    for name, scaled in chosen.items():
        setting = dict(settings[name])
        seeds = min(config.seeds, setting.pop("seeds", config.seeds))
        if scaled is not None:
            setting["steps"], setting["eval_every"] = scaled
        if config.steps is not None:
            setting["steps"] = config.steps
            setting["eval_every"] = max(1, config.steps // 10)
        for i in range(seeds):
            for method in methods[name] if isinstance(methods, dict) else methods:
                seed = config.base_seed + i
                out.append(kind(setting=name, method=method, seed=seed, **setting))
    return out


def curve_means(by_method: dict[str, dict[int, dict]]) -> dict[str, dict[int, float]]:
    """Each run's mean score over its learning curve's evaluations, by method and seed.

    With evaluations every ``eval_every`` steps from step 0, it is the area under the curve
    over its length: how early a method learns, where final scores tie.
    """
    return {
        method: {seed: float(sum(r["scores"]) / len(r["scores"])) for seed, r in runs.items()}
        for method, runs in by_method.items()
        if method != "random"
    }


def delay_fields(task: RewardDelayTask) -> dict[str, Any]:
    """What a reward-delay method's run reads of ``task`` beyond the setting's own fields.

    The ``delay`` (not the oracle's, which is undelayed, so that settings that differ only by
    the delay share its run) and, for ``deconv-learned``, the bound ``max_delay_estimate`` it learns on.
    """
    fields = {} if task.method == "oracle" else {"delay": task.delay}
    if task.method == "deconv-learned":
        fields["max_delay_estimate"] = task.max_delay_estimate
    return fields


def _mean_score(runs: dict[int, dict]) -> float:
    """The mean ``score`` of a method's runs over its seeds."""
    return rules.mean_ci_n([r["score"] for r in runs.values()])[0]


def method_gains(
    by_method: dict[str, dict[int, dict]],
) -> tuple[dict[str, dict[int, float]], float, float]:
    """Each method's gain per seed (the random policy's left out), and the random and oracle means."""
    low, high = _mean_score(by_method["random"]), _mean_score(by_method["oracle"])
    span = high - low
    out = {
        method: {seed: (r["score"] - low) / span if span else math.nan for seed, r in runs.items()}
        for method, runs in by_method.items()
        if method != "random"
    }
    return out, low, high


def learning_curves(
    setting: str,
    by_method: dict[str, dict[int, dict]],
    labels: dict[str, str],
    random_mean: float,
    scored_in: str,
    references: tuple[tuple[float, str], ...] = (),
    colours: Mapping[str, str] | None = None,
) -> tuple[list[Curve], Any]:
    """Each run's learning curve, and the setting's figure of them, method by method.

    Args:
        setting: the setting's name.
        by_method: its results, ``{method: {seed: {"steps", "scores", ...}}}``.
        labels: the methods to draw, by name, with their labels (in drawing order).
        random_mean: the random policy's mean score, drawn as a line.
        scored_in: the env the scores come from, for the title (``"the undelayed env"``).
        references: other ``(score, label)`` levels to draw as lines (fixed controllers).
        colours: the colours of the curves and levels, by label (:func:`method_colours`).
    """
    curves = []
    for method in labels:
        for seed, r in by_method[method].items():
            steps, values = np.asarray(r["steps"]), np.asarray(r["scores"])
            curves.append(Curve(f"{setting}/{method}", seed, steps, values, "score"))
    figure = plotting.figure(
        plotting.learning_curves,
        groups=curve_groups(
            {label: by_method[method] for method, label in labels.items()}, y="scores"
        ),
        title=f"{setting}: mean return of 10 greedy episodes of {scored_in}",
        ylabel="return",
        thesis=[(random_mean, "random policy")],
        levels=references,
        colours=colours,
        ylim=None,
        xlabel="training step",
    )
    return curves, figure


def method_colours(labels: Mapping[str, str]) -> dict[str, str]:
    """A colour per label, by its method's place among all of an experiment's ``labels``.

    A method keeps its colour in every setting's figure, whichever methods the setting has.

    >>> method_colours({"raw": "raw", "oracle": "oracle (undelayed)"})
    {'raw': 'C0', 'oracle (undelayed)': 'C1'}
    """
    return {label: f"C{i % 10}" for i, label in enumerate(labels.values())}


def gain_rows(
    setting: str,
    gains: dict[str, dict[int, float]],
    labels: Mapping[str, str],
    notes: Mapping[str, str] | None = None,
) -> list[Claim]:
    """A reference row of each method's gain in ``setting``: its mean and 95 % CI over the seeds.

    Args:
        setting: the setting's name.
        gains: each method's gain per seed (:func:`method_gains`).
        labels: the methods to report, by name, with their labels (in row order).
        notes: a note for a method's row, where it has one.
    """
    notes = notes or {}
    return [
        rules.reference_row(
            f"{setting}: {label} gain",
            rules.mean_ci_n(list(gains[method].values())),
            note=notes.get(method, ""),
        )
        for method, label in labels.items()
    ]


def gain_summary(
    grouped: dict[str, dict[str, dict[int, dict]]],
    labels: Mapping[str, str],
    scored_in: str,
    claims: list[Claim],
    extra: dict[str, Any],
) -> Summary:
    """A gain experiment's summary: its claims and extra, and each setting's learning curves.

    Every run's learning curve goes to ``curves.csv``, and each setting has a figure of its
    curves, ``curves_<setting>`` (:func:`learning_curves`).

    Args:
        grouped: the results, ``{setting: {method: {seed: result}}}``.
        labels: the methods to draw, by name, with their labels (in drawing order); each setting
            draws those it has.
        scored_in: the env the scores come from, for the figures' titles.
        claims: the experiment's claims.
        extra: what ``summary.json`` holds beside them.
    """
    curves, figures = [], {}
    for setting, by_method in grouped.items():
        drawn = {method: label for method, label in labels.items() if method in by_method}
        random_mean = _mean_score(by_method["random"])
        setting_curves, figures[f"curves_{setting}"] = learning_curves(
            setting, by_method, drawn, random_mean, scored_in, colours=method_colours(labels)
        )
        curves += setting_curves
    return Summary(claims, curves, figures, extra)
