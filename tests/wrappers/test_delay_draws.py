"""The delays the reward wrapper applies: its ``info["drawn_reward_delay"]`` stream, fitted.

Each stream is drawn with a fixed seed and checked against its distribution by a chi-square
test at :data:`~support.ALPHA` (bins merged until every expected count is at least 5); a clipped
stream's clip cell by its binomial count, within :data:`~support.N_SE` standard errors.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from support import ALPHA, N_SE, POISSON_MEANS, NeverEndingEnv, assert_mean_close, binned_chisquare

from delayed_rl.delays import Delay, Empirical, Geometric, Poisson, Uniform
from delayed_rl.wrappers import PoissonRewardDelay, RewardDelay

N_DRAWS = 20_000


def delay_stream(env: gym.Env, n: int, seed: int) -> np.ndarray:
    env.reset(seed=seed)
    return np.array([env.step(0)[4]["drawn_reward_delay"] for _ in range(n)])


@pytest.mark.parametrize("lam", POISSON_MEANS)
def test_wrapper_delay_stream_is_poisson(lam: float) -> None:
    draws = delay_stream(PoissonRewardDelay(NeverEndingEnv(), lam), N_DRAWS, seed=7)
    assert binned_chisquare(draws, Poisson(lam).pmf) > ALPHA
    assert_mean_close(draws, lam, lam)


@pytest.mark.parametrize(
    "dist", [Geometric(0.25), Uniform(3, 12), Empirical([0.2, 0.1, 0.0, 0.3, 0.4])], ids=repr
)
def test_wrapper_delay_stream_other_distributions(dist: Delay) -> None:
    draws = delay_stream(RewardDelay(NeverEndingEnv(), dist), N_DRAWS, seed=8)
    assert binned_chisquare(draws, dist.pmf) > ALPHA


@pytest.mark.parametrize(("lam", "clip"), [(13.7, 10), (5, 0), (90, 80)])
def test_max_delay_puts_the_tail_mass_at_the_clip(lam: float, clip: int) -> None:
    draws = delay_stream(PoissonRewardDelay(NeverEndingEnv(), lam, max_delay=clip), N_DRAWS, seed=9)
    assert draws.max() <= clip
    from scipy import stats

    ref = stats.poisson(lam)

    def clipped_pmf(k):
        k = np.asarray(k)
        return np.where(k < clip, ref.pmf(k), np.where(k == clip, ref.sf(clip - 1), 0.0))

    if clip == 0:
        assert draws.tolist() == [0] * N_DRAWS
        return
    assert binned_chisquare(draws, clipped_pmf) > ALPHA
    # the clip cell alone: binomial count within N_SE standard errors
    p_clip = ref.sf(clip - 1)
    count = int((draws == clip).sum())
    assert abs(count - N_DRAWS * p_clip) <= N_SE * math.sqrt(N_DRAWS * p_clip * (1 - p_clip))
