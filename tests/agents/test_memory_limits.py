"""Bounded memory: deconvolution Q-learning's tables and a file's statistics, checked before allocating.

A request that truly needs more than a stated limit fails at construction (or at loading, for a
file), before anything large is allocated (``tracemalloc`` measures it), with an error naming the
argument and the size it would take.
"""

from __future__ import annotations

import pytest
from support import MB, peak_of_error

from delayed_rl.envs.gridworld import GridWorldEnv


def test_deconvq_tables_too_large_fail_before_allocating() -> None:
    from delayed_rl.agents import DeconvolutionQLearning

    env = GridWorldEnv(size=200)  # 160,000 pairs: 1025 reward sums each would take 1.2 GiB
    peak = peak_of_error(
        lambda: DeconvolutionQLearning(env, max_delay_estimate=1024),
        ValueError,
        r"DeconvolutionQLearning\(max_delay_estimate=1024\) on an env of 40000 states and 4 actions needs "
        r"1.\d+ GiB of tables .*over MAX_TABLE_BYTES = 1 GiB",
    )
    assert peak < MB
    peak = peak_of_error(
        lambda: DeconvolutionQLearning(env, max_delay_estimate=10**9),
        ValueError,
        "max_delay_estimate must be at most MAX_DELAY_ESTIMATE = 1024",
    )
    assert peak < MB


def test_deconvq_statistics_a_file_declares_are_checked_before_they_are_read(
    tmp_path, monkeypatch
) -> None:
    from delayed_rl.agents import DeconvolutionQLearning
    from delayed_rl.agents.common import save_util
    from delayed_rl.agents.deconvolution import agent as deconvolution

    path = (
        DeconvolutionQLearning(GridWorldEnv(size=3), max_delay_estimate=5, seed=0)
        .learn(50)
        .save(tmp_path / "d")
    )
    monkeypatch.setattr(deconvolution, "STATISTICS_LIMIT", 2**10)  # its counts take 7.8 KiB

    def never(*args, **kwargs):
        raise AssertionError("an array was read before the sizes were checked")

    monkeypatch.setattr(save_util.ModelFile, "read", never)
    with pytest.raises(
        ValueError, match=r"regression_cooc and regression_keys declare 0 MiB, more"
    ):
        DeconvolutionQLearning.load(path)
