"""Bounded memory: the delay wrappers (and the SB3 twin's rings) hold only what is pending.

Each test measures with ``tracemalloc`` (numpy reports its buffers to it) that the peak stays under
a small bound however long the delays drawn, and that no pending reward is lost.
"""

from __future__ import annotations

import numpy as np
import pytest
from support import MB, NeverEndingEnv, peak_of

from delayed_rl.delays import Constant, Poisson
from delayed_rl.wrappers import ObservationDelay, RewardDelay


@pytest.mark.sb3
def test_sb3_rings_start_small() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from delayed_rl.wrappers.sb3 import VecRewardDelay

    def run():
        env = VecRewardDelay(DummyVecEnv([NeverEndingEnv, NeverEndingEnv]), Poisson(1e9), seed=0)
        env.reset()
        for _ in range(500):
            *_, infos = env.step(np.zeros(2, dtype=int))
        return infos

    infos, peak = peak_of(run)
    assert peak < 4 * MB, f"peak {peak / MB:.1f} MiB"
    assert [info["pending_reward"] for info in infos] == [500.0, 500.0]


@pytest.mark.parametrize("delay", [Poisson(1e9), Constant(2**63 - 1)], ids=repr)
def test_single_env_wrappers_hold_only_what_is_pending(delay) -> None:
    def run():
        env = ObservationDelay(RewardDelay(NeverEndingEnv(), delay), delay)
        env.reset(seed=0)
        for _ in range(2000):
            info = env.step(0)[4]
        return info

    info, peak = peak_of(run)
    assert peak < 4 * MB, f"peak {peak / MB:.1f} MiB"
    assert info["pending_reward"] == 2000.0
