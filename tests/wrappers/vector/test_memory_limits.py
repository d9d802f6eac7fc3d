"""Bounded memory: the vector reward delay's rings hold only what is pending, up to their limit.

Each test measures with ``tracemalloc`` (numpy reports its buffers to it) that the peak stays under
a small bound however long the delays drawn, or that the rings stop growing at their limit.
"""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from support import MB, NeverEndingEnv, peak_of

from delayed_rl.delays import Constant, Geometric, Poisson
from delayed_rl.wrappers import VectorRewardDelay
from delayed_rl.wrappers.pending_rewards import MAX_RING_ENTRIES


@pytest.mark.large
@pytest.mark.parametrize("delay", [Poisson(1e9), Constant(2**63 - 1), Geometric(1e-9)], ids=repr)
def test_vector_rings_start_small_and_hold_only_what_is_pending(delay) -> None:
    def run():
        vec = SyncVectorEnv(
            [NeverEndingEnv, NeverEndingEnv], autoreset_mode=AutoresetMode.NEXT_STEP
        )
        env = VectorRewardDelay(vec, delay)
        env.reset(seed=0)
        for _ in range(2000):
            *_, info = env.step(np.zeros(2, dtype=int))
        return env, info

    (env, info), peak = peak_of(run)
    assert peak < 4 * MB, f"peak {peak / MB:.1f} MiB"
    np.testing.assert_array_equal(info["pending_reward"], [2000.0, 2000.0])  # nothing lost


def test_vector_ring_grows_with_the_delays_drawn_and_stops_at_its_limit() -> None:
    vec = SyncVectorEnv([NeverEndingEnv] * 4, autoreset_mode=AutoresetMode.NEXT_STEP)
    env = VectorRewardDelay(vec, Poisson(1e6))
    env.reset(seed=0)
    assert env.pending_rewards.ring.size <= 4 * 64  # small at first
    for _ in range(50):
        env.step(np.zeros(4, dtype=int))
    assert env.pending_rewards.ring.size <= MAX_RING_ENTRIES
    np.testing.assert_array_equal(env.pending_rewards.pending, [50.0] * 4)
