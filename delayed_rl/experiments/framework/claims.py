"""The results' statistics and verdicts: 95 % intervals, and the rules that judge them.

Every report row is built by one of the helpers below, which compute its verdict from the
measurement's 95 % interval and the thesis's value by a stated rule and write that rule into
the row's ``criterion``: :func:`band_claim` / :func:`range_claim` (a value against a band),
:func:`direction_claim` (a sign or a side), :func:`count_claim` (k of n seeds, by the share's
Wilson interval), :func:`trend_claim` (a slope fitted per seed) and :func:`reference_row` (a
number shown for context). An interval that is NaN is ``inconclusive``. Differences and ratios
of two conditions are formed per seed first (:func:`paired`), so their CI is over seeds too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from delayed_rl.experiments.framework.experiment import (
    AGREES,
    DIFFERS,
    INCONCLUSIVE,
    REFERENCE,
    Claim,
)
from delayed_rl.parallel.intervals import mean_ci95, t975, wilson_interval


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


def seed_rule_claim(
    quantity: str, thesis: str, values: Sequence[float], threshold: float, at_least: int
) -> Claim:
    """A target stated as a rule on the seeds: ``values ≥ threshold`` on ``at_least`` of them.

    The verdict is the rule itself, on these seeds (agrees or differs, never inconclusive); the
    row also carries the Wilson 95 % interval of the share, which says how little a handful of
    seeds tells about the rate (5 of 5 is compatible with a rate near 0.5).

    >>> seed_rule_claim("gain ≥ 0.9", "4 of 5", [0.95, 0.92, 0.99, 0.5, 0.91], 0.9, 4).verdict
    'agrees'
    """
    k, n = sum(value >= threshold for value in values), len(values)
    low, high = wilson_interval(k, n)
    verdict = AGREES if n and k >= at_least else DIFFERS
    criterion = (
        f"agrees if at least {at_least} of the {n} seeds reach {_fmt(threshold)} (a rule on "
        "these seeds; the interval is the share's Wilson 95 % interval, for the rate)"
    )
    note = f"{k} of {n} seeds; values " + ", ".join(f"{value:.2f}" for value in values)
    share = k / n if n else math.nan
    return Claim(quantity, thesis, share, (high - low) / 2, n, verdict, criterion, note, low, high)


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


def paired_direction_claim(
    quantity: str,
    thesis: str,
    ours: Mapping[int, float],
    theirs: Mapping[int, float],
    side: str = "above",
) -> Claim:
    """``ours − theirs`` paired by seed, on ``side`` of 0 (:func:`direction_claim`).

    Its note says how many seeds the differences' spread would need to resolve it
    (:func:`seeds_to_resolve`), when that is a number.
    """
    differences = paired(ours, theirs)
    needed = seeds_to_resolve(differences)
    note = "" if needed is None else f"at this spread, about {needed} seeds would resolve it"
    return direction_claim(quantity, thesis, mean_ci_n(differences), side, note=note)


def seeds_to_resolve(
    values: Sequence[float], reference: float = 0.0, limit: int = 1000
) -> int | None:
    """The seeds a 95 % CI of the mean would need to exclude ``reference``, at these values' spread.

    The smallest ``n`` with ``t(n − 1) · sd / √n < |mean − reference|``, ``mean`` and ``sd`` (the
    sample's, ``n − 1`` in the denominator) those of ``values``: a power estimate from a pilot
    (the chance of resolving at that ``n`` is about one half, as the mean may come out on either
    side). ``None`` with fewer than two values, a zero spread, a mean at ``reference``, or
    more than ``limit`` seeds.

    >>> seeds_to_resolve([0.1, 0.5, 0.3, 0.2, 0.4])
    4
    """
    array = np.asarray(values, dtype=float)
    if array.size < 2:
        return None
    gap, sd = abs(float(array.mean()) - reference), float(array.std(ddof=1))
    if gap == 0 or sd == 0 or not math.isfinite(gap + sd):
        return None
    for n in range(2, limit + 1):
        if t975(n - 1) * sd / math.sqrt(n) < gap:
            return n
    return None


def identical_note(values: Sequence[float]) -> str:
    """Why a row's interval has zero width, when it has: every seed gave the same value.

    Empty unless there are at least two values and they are all equal.

    >>> identical_note([500.0, 500.0, 500.0])
    'zero width: all 3 seeds gave exactly 500'
    """
    if len(values) < 2 or any(value != values[0] for value in values):
        return ""
    return f"zero width: all {len(values)} seeds gave exactly {values[0]:.6g}"


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
