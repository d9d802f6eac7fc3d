"""Tests of :mod:`delayed_rl.parallel.intervals`."""

from __future__ import annotations

import math

import numpy as np
import pytest

from delayed_rl.experiments.framework.claims import count_claim
from delayed_rl.parallel.intervals import mean_ci95, t975, wilson_interval


def test_mean_ci95_matches_the_t_interval():
    mean, half = mean_ci95([1.0, 2.0, 3.0, 4.0])
    assert mean == 2.5
    assert half == pytest.approx(3.182 * np.std([1, 2, 3, 4], ddof=1) / 2, rel=0.02)
    mean, half = mean_ci95([5.0])  # one value: no interval
    assert mean == 5.0 and math.isnan(half)


def test_wilson_interval_values():
    assert wilson_interval(19, 20) == pytest.approx((0.7639, 0.9911), abs=1e-4)
    assert wilson_interval(0, 5) == pytest.approx((0.0, 0.4345), abs=1e-4)
    assert wilson_interval(5, 5)[1] == 1.0
    # 20 of 20 cannot show a share ≥ 0.95 at 95 % confidence
    assert count_claim("q", "t", 20, 20, 0.95).verdict == "inconclusive"


@pytest.mark.parametrize(
    ("df", "quantile"),
    [(1, 12.7062), (2, 4.3027), (10, 2.2281), (30, 2.0423), (31, 2.0395), (60, 2.0003),
     (120, 1.9799), (10**6, 1.9600)],
)  # fmt: skip
def test_t975_is_students_quantile_in_the_table_and_beyond_it(df, quantile):
    assert t975(df) == pytest.approx(quantile, abs=1.5e-3)
