"""95 % intervals: of a mean (Student t) and of a binomial share (Wilson), without scipy."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

# Student t 0.975 quantiles for 1..30 degrees of freedom (no scipy at run time).
_T975 = (12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179,
         2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064,
         2.060, 2.056, 2.052, 2.048, 2.045, 2.042)  # fmt: skip


#: The standard normal 0.975 quantile.
Z975 = 1.959964


def mean_ci95(values: Sequence[float]) -> tuple[float, float]:
    """Mean and the half-width of a 95 % Student-t confidence interval.

    One value gives no interval: its half-width is NaN (a 0 would claim no spread, and a rule
    on the interval would then give a verdict from one run). No values: both NaN.
    """
    values = np.asarray(values, dtype=float)
    n = values.size
    if n == 0:
        return math.nan, math.nan
    if n == 1:
        return float(values[0]), math.nan
    return float(values.mean()), float(t975(n - 1) * values.std(ddof=1) / math.sqrt(n))


def t975(df: int) -> float:
    """Student's t 0.975 quantile with ``df`` (≥ 1) degrees of freedom."""
    if df <= len(_T975):
        return _T975[df - 1]
    # Cornish–Fisher expansion of the normal quantile, accurate to 1e-3 beyond 30 df
    z = Z975
    return z + (z**3 + z) / (4 * df) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * df**2)


def wilson_interval(k: int, n: int) -> tuple[float, float]:
    """The Wilson score 95 % interval of a binomial share ``k / n`` (NaN for ``n = 0``).

    >>> [round(x, 3) for x in wilson_interval(19, 20)]
    [0.764, 0.991]
    """
    if n == 0:
        return math.nan, math.nan
    z2 = Z975**2
    centre = (k + z2 / 2) / (n + z2)
    half = Z975 / (n + z2) * math.sqrt(k * (n - k) / n + z2 / 4)
    return max(0.0, centre - half), min(1.0, centre + half)
