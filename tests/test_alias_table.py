"""Poisson delays by table look-up: the alias table, the Poisson table, and the streams using it.

Goodness of fit as in ``test_delays``: fixed seeds, chi-square at significance 1e-3.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from support import binned_chisquare

import delayed_rl  # noqa: F401
from delayed_rl.compiled import CompiledRun
from delayed_rl.delays import AliasTable, Poisson
from delayed_rl.wrappers import RewardDelay

ALPHA = 1e-3


@pytest.mark.parametrize(
    "pmf", [[1.0], [0.5, 0.5], [0.7, 0.0, 0.2, 0.1], [3.0, 1.0, 0.0, 4.0, 2.0]]
)
def test_alias_table_draws_its_distribution(pmf):
    """Draws fit the normalised pmf; a zero-probability value is never drawn."""
    pmf = np.asarray(pmf) / np.sum(pmf)
    draws = AliasTable(pmf).sample(np.random.default_rng(11), 50_000)
    assert draws.dtype == np.int64 and draws.min() >= 0 and draws.max() < pmf.size
    assert not np.isin(draws, np.flatnonzero(pmf == 0)).any()
    if pmf.size > 1:
        assert binned_chisquare(draws, lambda k: pmf[k]) > ALPHA


def test_alias_table_has_power():
    """The check above rejects a table built from a different distribution."""
    draws = AliasTable([0.55, 0.45]).sample(np.random.default_rng(12), 50_000)
    assert binned_chisquare(draws, lambda k: np.array([0.5, 0.5])[k]) < ALPHA


@pytest.mark.parametrize("pmf", [[], [0.5, -0.1], [np.nan, 1.0], [0.0, 0.0], [[0.5, 0.5]]])
def test_alias_table_rejects_bad_pmfs(pmf):
    with pytest.raises(ValueError, match="pmf"):
        AliasTable(pmf)


@pytest.mark.parametrize("lam", [0.0, 0.3, 4.0, 13.0, 250.0])
def test_poisson_table_fits_poisson(lam):
    table = Poisson(lam).table
    assert Poisson(lam).pmf(table.keep.size) < Poisson.TAIL  # the tail left out is negligible
    draws = Poisson(lam).sample(np.random.default_rng(int(lam * 10)), 50_000)
    if lam == 0:
        assert not draws.any()
    else:
        assert binned_chisquare(draws, Poisson(lam).pmf) > ALPHA


def test_poisson_draws_from_numpy_beyond_the_largest_table():
    huge = Poisson(4.0 * Poisson.MAX_TABLE)
    assert huge.table is None
    draws = huge.sample(np.random.default_rng(1), 2000)
    assert abs(draws.mean() - huge.lam) < 4 * np.sqrt(huge.lam / draws.size)


def test_poisson_scalar_and_shaped_draws():
    rng = np.random.default_rng(2)
    assert isinstance(Poisson(3.0).sample(rng), int)
    assert Poisson(3.0).sample(rng, (4, 5)).shape == (4, 5)


@pytest.mark.parametrize("max_delay", [None, 6])
def test_compiled_run_draws_poisson_delays(max_delay):
    """The compiled run's delays are Poisson(λ), capped like the wrapper's (the tail at the cap)."""
    env = RewardDelay(gym.make("delayed_rl/GridWorld-3x3-v0").unwrapped, 9.0, max_delay=max_delay)
    run = CompiledRun(env, np.array([0]), seed=4)
    draws = np.concatenate([run._draw_delays(10_000) for _ in range(5)])
    pmf = Poisson(9.0).pmf(np.arange(60))
    if max_delay is not None:
        assert draws.max() == max_delay
        pmf[max_delay] = 1.0 - pmf[:max_delay].sum()
        pmf[max_delay + 1 :] = 0.0
    assert binned_chisquare(draws, lambda k: pmf[k]) > ALPHA
