"""Pieces shared by the experiments: verdict rules, and the grid-world runs normalised by Eq. 5.3.

**Verdicts.** Every report row is built by one of the helpers below, which compute its verdict
from the measurement's 95 % interval and the thesis's value by a stated rule, and write that
rule into the row's ``criterion``:

- :func:`band_claim` / :func:`range_claim`: a value against a band (the thesis's value ± a
  tolerance, or a range such as "in (0, 1)"): ``agrees`` when the 95 % CI lies inside the band,
  ``differs`` when it lies wholly outside, ``inconclusive`` when it straddles an edge;
- :func:`direction_claim`: a sign or a side ("MMQ above Q", "a ratio below 1"): ``agrees``
  when the CI lies wholly on the claimed side of the reference value, ``differs`` when it lies
  wholly on the other side (the reference value itself counts as the other side),
  ``inconclusive`` otherwise;
- :func:`count_claim`: k of n seeds, against a band of the share: the rule of
  :func:`range_claim` applied to the Wilson 95 % interval of k / n;
- :func:`trend_claim`: a trend: :func:`direction_claim` on the least-squares slope fitted per
  seed (:func:`per_seed_slopes`), its CI over the seeds;
- :func:`reference_row`: a number shown for context with no thesis value to test (verdict
  ``reference``, see :mod:`.runner`).

An interval that is NaN (no data, or a quantity that could not be formed) is ``inconclusive``.
Differences and ratios of two conditions are formed per seed first (:func:`paired`), so their CI
is over seeds too.

**Normalised grid-world runs.** The grid-world experiments (``delay-sweep``, ``world-size``,
``estimate-error``) share one design: for every seed and world size, an undelayed Q-learning
*reference* run, and delayed runs whose average reward is divided by the reference's (the
thesis's Eq. 5.3). :func:`grid_tasks` builds those tasks, :func:`grid_task` runs one, and
:func:`normalised` pairs each delayed run with its reference.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Mapping, Sequence

import numpy as np

from delayed_rl.experiments.runner import (
    AGREES,
    DIFFERS,
    INCONCLUSIVE,
    REFERENCE,
    Claim,
    Config,
    Curve,
    mean_ci95,
    running_average,
)
from delayed_rl.experiments.training import grid_env, train

#: The standard normal 0.975 quantile, of the Wilson interval.
_Z975 = 1.959964


def mean_ci_n(values: Sequence[float]) -> tuple[float, float, int]:
    """The mean, the half-width of its 95 % confidence interval and the count of ``values``.

    This is the ``stats`` triple the claim helpers take.
    """
    return (*mean_ci95(values), len(values))


def _fmt(value: float) -> str:
    """A band edge in a criterion: ``0.55``, ``49.215``, ``-inf``."""
    return f"{value:.6g}"


def interval_verdict(low: float, high: float, band_low: float, band_high: float) -> str:
    """The verdict of an interval ``[low, high]`` against the band ``[band_low, band_high]``.

    ``agrees`` when the interval lies inside the band (edges included), ``differs`` when it
    lies wholly outside (no point in common), ``inconclusive`` otherwise or when the interval
    is NaN.

    >>> interval_verdict(0.4, 0.5, 0.35, 0.75), interval_verdict(0.1, 0.2, 0.35, 0.75)
    ('agrees', 'differs')
    >>> interval_verdict(0.3, 0.4, 0.35, 0.75)
    'inconclusive'
    """
    if math.isnan(low) or math.isnan(high):
        return INCONCLUSIVE
    if band_low <= low and high <= band_high:
        return AGREES
    if high < band_low or low > band_high:
        return DIFFERS
    return INCONCLUSIVE


def range_claim(
    quantity: str,
    thesis: str,
    stats: tuple[float, float, int],
    low: float,
    high: float,
    criterion: str = "",
    note: str = "",
) -> Claim:
    """A value against the range ``[low, high]`` (either end may be infinite).

    Args:
        quantity: what is measured, e.g. ``"MMQ average reward during learning"``.
        thesis: the thesis's value or statement, with its figure or table.
        stats: the measurement as (mean, 95 % CI half-width, number of runs).
        low: the lower edge of the band the CI must lie in.
        high: the upper edge.
        criterion: the rule in words (default: built from the band).
        note: anything else the report should say about the row.

    Returns:
        The row, its verdict by :func:`interval_verdict` on mean ± CI.
    """
    mean, ci, n = stats
    criterion = criterion or (
        f"differs if the 95 % CI lies wholly outside [{_fmt(low)}, {_fmt(high)}]; "
        "agrees if it lies inside"
    )
    verdict = interval_verdict(mean - ci, mean + ci, low, high)
    return Claim(quantity, thesis, mean, ci, n, verdict, criterion, note, mean - ci, mean + ci)


def band_claim(
    quantity: str,
    thesis: str,
    stats: tuple[float, float, int],
    target: float,
    tolerance: float,
    note: str = "",
) -> Claim:
    """A value against the thesis's ``target`` ± ``tolerance`` (:func:`range_claim`'s rule).

    >>> band_claim("MMQ reward", "≈ 0.55", (0.5, 0.1, 5), 0.55, 0.2).verdict
    'agrees'
    >>> band_claim("MMQ − Q", "≈ +0.43", (0.11, 0.05, 5), 0.43, 0.2).criterion
    'differs if the 95 % CI lies wholly outside 0.43 ± 0.2 = [0.23, 0.63]; agrees if it lies inside'
    """
    low, high = target - tolerance, target + tolerance
    criterion = (
        f"differs if the 95 % CI lies wholly outside {_fmt(target)} ± {_fmt(tolerance)} = "
        f"[{_fmt(low)}, {_fmt(high)}]; agrees if it lies inside"
    )
    return range_claim(quantity, thesis, stats, low, high, criterion, note)


def direction_claim(
    quantity: str,
    thesis: str,
    stats: tuple[float, float, int],
    side: str,
    reference: float = 0.0,
    note: str = "",
) -> Claim:
    """A side claim: the value above (``side="above"``) or below (``"below"``) ``reference``.

    ``agrees`` when the 95 % CI lies wholly on the claimed side, ``differs`` when it lies wholly
    on the other side, the ``reference`` value included (a difference that is exactly 0 is not
    "above 0"), ``inconclusive`` when the CI holds points of both sides, or is NaN.

    Raises:
        ValueError: ``side`` is neither ``"above"`` nor ``"below"``.

    >>> direction_claim("MMQ − Q", "MMQ above Q", (0.11, 0.05, 5), "above").verdict
    'agrees'
    >>> direction_claim("ratio", "below 1", (0.9, 0.2, 5), "below", 1.0).verdict
    'inconclusive'
    """
    if side not in ("above", "below"):
        raise ValueError(f"side must be 'above' or 'below', got {side!r}")
    mean, ci, n = stats
    low, high = mean - ci, mean + ci
    if math.isnan(low) or math.isnan(high):
        verdict = INCONCLUSIVE
    elif (low > reference) if side == "above" else (high < reference):
        verdict = AGREES
    elif (high <= reference) if side == "above" else (low >= reference):
        verdict = DIFFERS
    else:
        verdict = INCONCLUSIVE
    other = "at or below" if side == "above" else "at or above"
    criterion = (
        f"differs if the 95 % CI lies wholly {other} {_fmt(reference)}; agrees if it lies "
        f"wholly {side} it"
    )
    return Claim(quantity, thesis, mean, ci, n, verdict, criterion, note, low, high)


def wilson_interval(k: int, n: int) -> tuple[float, float]:
    """The Wilson score 95 % interval of a binomial share ``k / n`` (NaN for ``n = 0``).

    >>> [round(x, 3) for x in wilson_interval(19, 20)]
    [0.764, 0.991]
    """
    if n == 0:
        return math.nan, math.nan
    z2 = _Z975**2
    centre = (k + z2 / 2) / (n + z2)
    half = _Z975 / (n + z2) * math.sqrt(k * (n - k) / n + z2 / 4)
    return max(0.0, centre - half), min(1.0, centre + half)


def count_claim(
    quantity: str,
    thesis: str,
    k: int,
    n: int,
    low: float,
    high: float = 1.0,
    what: str = "seeds",
    note: str = "",
) -> Claim:
    """``k`` of ``n`` (seeds, say) against a band ``[low, high]`` of the share ``k / n``.

    The Wilson 95 % interval of the share takes the place of mean ± CI in
    :func:`interval_verdict`; the row's ``mean`` is ``k / n`` and its ``ci95`` half the
    interval's width (the report prints the interval itself).

    Args:
        quantity: what is counted.
        thesis: the thesis's value or statement.
        k: how many of the ``n`` have the property.
        n: how many there are.
        low: the lower edge of the share's band.
        high: its upper edge.
        what: what is counted, for the note (``"seeds"``).
        note: anything else the report should say (after ``"k of n seeds"``).

    >>> count_claim("optimal seeds", "most", 15, 20, 0.5).verdict
    'agrees'
    >>> count_claim("optimal seeds", "≥ 95 %", 20, 20, 0.95).verdict  # 20 seeds cannot show it
    'inconclusive'
    """
    share = k / n if n else math.nan
    lo, hi = wilson_interval(k, n)
    criterion = (
        f"differs if the Wilson 95 % interval of the share lies wholly outside "
        f"[{_fmt(low)}, {_fmt(high)}]; agrees if it lies inside"
    )
    note = f"{k} of {n} {what}" + (f"; {note}" if note else "")
    verdict = interval_verdict(lo, hi, low, high)
    return Claim(quantity, thesis, share, (hi - lo) / 2, n, verdict, criterion, note, lo, hi)


def per_seed_slopes(x: Sequence[float], ys: Sequence[Sequence[float]]) -> list[float]:
    """The least-squares slope of each seed's ``y`` against ``x`` (NaN where ``y`` has NaN).

    Args:
        x: the abscissae, shared by every seed (at least two distinct values).
        ys: one sequence of ordinates per seed, aligned with ``x``.

    >>> per_seed_slopes([0, 1, 2], [[0, 1, 2], [2, 1, 0]])
    [1.0, -1.0]
    """
    x = np.asarray(x, dtype=float)
    centred = x - x.mean()
    slopes = []
    for y in ys:
        y = np.asarray(y, dtype=float)
        slopes.append(float(np.sum(centred * (y - y.mean())) / np.sum(centred * centred)))
    return slopes


def trend_claim(
    quantity: str,
    thesis: str,
    x: Sequence[float],
    ys: Sequence[Sequence[float]],
    side: str,
    x_label: str,
    note: str = "",
) -> Claim:
    """A trend: the per-seed slope of ``ys`` against ``x``, its 95 % CI over the seeds.

    The verdict is :func:`direction_claim`'s on the slopes: ``side="below"`` claims a falling
    trend (slope below 0), ``"above"`` a rising one.

    Args:
        quantity: what trend is measured (the row shows the mean slope).
        thesis: the thesis's statement.
        x: the abscissae, e.g. the mean delays λ or their logarithms.
        ys: per seed, the measurement at each ``x``.
        side: ``"below"`` (falls with ``x``) or ``"above"`` (rises).
        x_label: what ``x`` is, for the criterion (e.g. ``"log10 λ"``).
        note: anything else the report should say.
    """
    row = direction_claim(quantity, thesis, mean_ci_n(per_seed_slopes(x, ys)), side, 0.0, note)
    row.criterion = f"least-squares slope against {x_label} per seed; " + row.criterion.replace(
        "95 % CI", "95 % CI of the slope over seeds"
    )
    return row


def paired(
    ours: Mapping[int, float], theirs: Mapping[int, float], how: str = "difference"
) -> list[float]:
    """Per seed present in both, ``ours − theirs`` (``how="difference"``) or ``ours / theirs``.

    Args:
        ours: ``{seed: value}``.
        theirs: ``{seed: value}``, the baseline.
        how: ``"difference"`` or ``"ratio"`` (NaN where the baseline is 0).

    Raises:
        ValueError: ``how`` is neither.
    """
    if how not in ("difference", "ratio"):
        raise ValueError(f"how must be 'difference' or 'ratio', got {how!r}")
    seeds = [seed for seed in ours if seed in theirs]
    if how == "difference":
        return [float(ours[s] - theirs[s]) for s in seeds]
    return [float(ours[s] / theirs[s]) if theirs[s] != 0 else math.nan for s in seeds]


def reference_row(
    quantity: str,
    stats: tuple[float, float, int],
    thesis: str = "reference (no thesis value)",
    note: str = "",
) -> Claim:
    """A row shown for context, with no thesis value to test: verdict ``reference``."""
    mean, ci, n = stats
    criterion = "none: a reference, not tested"
    return Claim(quantity, thesis, mean, ci, n, REFERENCE, criterion, note, mean - ci, mean + ci)


def seed_tasks(config: Config, agents: Sequence[str], **fields: object) -> list[dict]:
    """One task per (seed, agent): ``{"agent", "seed", **fields}``, seed-major.

    Seeds run from ``config.base_seed``, ``config.seeds`` of them.
    """
    return [
        {"agent": agent, "seed": config.base_seed + i, **fields}
        for i in range(config.seeds)
        for agent in agents
    ]


def grid_tasks(config: Config, steps: int, runs: Sequence[dict]) -> list[dict]:
    """The tasks of a normalised grid-world experiment, for every seed of ``config``.

    Per seed, and per world size in the order ``runs`` first name it: the undelayed Q-learning
    reference run in that world, then each of ``runs`` in that world.

    Args:
        config: the seeds (``config.seeds`` of them, from ``config.base_seed``).
        steps: training steps of every run.
        runs: one dict per delayed condition: ``size`` (the world's side), ``lam`` (the Poisson
            mean delay), ``lags`` (the agent's delay estimates, ``[0]`` for Q-learning) and
            ``condition`` (its label), plus any keys its experiment's ``summarize`` reads.

    Returns:
        The task dicts :func:`grid_task` runs, each with its ``steps`` and ``seed``; reference
        runs have ``reference=True``.
    """
    sizes = list(dict.fromkeys(run["size"] for run in runs))
    out = []
    for i in range(config.seeds):
        seed = config.base_seed + i
        for size in sizes:
            reference = {"size": size, "lam": 0, "lags": [0], "condition": "undelayed"}
            out.append({**reference, "steps": steps, "seed": seed, "reference": True})
            out += [{**run, "steps": steps, "seed": seed} for run in runs if run["size"] == size]
    return out


def grid_task(task: dict) -> dict:
    """Train on ``GridWorld(size)`` with Poisson(``lam``) delays and estimates ``lags``.

    Returns:
        The learning curve (``steps``, ``curve``: the running average reward) and the
        ``average`` reward over the whole run, from the undelayed reward stream.
    """
    agent = train(grid_env(task["size"], task["lam"]), task["lags"], task["steps"], task["seed"])
    rewards = agent.training_log["undelayed_reward"]
    steps, curve = running_average(rewards)
    return {"steps": steps, "curve": curve, "average": float(rewards.mean())}


def _references(tasks: list[dict], results: list[dict]) -> dict:
    """The undelayed reference runs' results, keyed by ``(size, seed)``."""
    return {
        (task["size"], task["seed"]): result
        for task, result in zip(tasks, results, strict=True)
        if task.get("reference")
    }


def normalised(tasks: list[dict], results: list[dict]) -> dict:
    """Eq. 5.3 per delayed task: its average reward over that of the matching undelayed run.

    The curve is normalised step by step (NaN while the reference has earned nothing yet).

    Returns:
        ``{condition: [(seed, steps, normalised curve, normalised average), ...]}``, the
        conditions in the order of ``tasks``.
    """
    reference = _references(tasks, results)
    out = defaultdict(list)
    for task, result in zip(tasks, results, strict=True):
        if task.get("reference"):
            continue
        base = reference[(task["size"], task["seed"])]
        with np.errstate(divide="ignore", invalid="ignore"):
            curve = np.where(base["curve"] > 0, result["curve"] / base["curve"], np.nan)
        out[task["condition"]].append(
            (task["seed"], result["steps"], curve, result["average"] / base["average"])
        )
    return out


def curves_and_means(
    per_condition: dict,
) -> tuple[list[Curve], dict[str, tuple[float, float, int]]]:
    """Curves for the CSV and (mean, 95 % CI, n) of the normalised average per condition.

    Args:
        per_condition: what :func:`normalised` returns.
    """
    curves, stats = [], {}
    for condition, runs in per_condition.items():
        for seed, steps, curve, _ in runs:
            curves.append(Curve(condition, seed, steps, curve, "normalised_average_reward"))
        stats[condition] = mean_ci_n([average for *_, average in runs])
    return curves, stats


def learning_curve_groups(per_condition: dict) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """``{condition: [(steps, normalised curve), ...]}``: the groups a learning-curve figure draws.

    Args:
        per_condition: what :func:`normalised` returns.
    """
    return {c: [(steps, curve) for _, steps, curve, _ in runs] for c, runs in per_condition.items()}
