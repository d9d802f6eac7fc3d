"""VectorActionDelay: one action delay per sub-env, as the single-env wrapper delays it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from support import Echo

from delayed_rl.delays import Poisson
from delayed_rl.wrappers import ActionDelay, VectorActionDelay


@pytest.mark.parametrize("mode", list(AutoresetMode))
def test_the_vector_twin_is_one_action_delay_per_sub_env(mode):
    n, steps, seed = 3, 120, 5

    def make():
        return ActionDelay(Echo(length=17), Poisson(2.0), initial_action=1)

    vector = gym.vector.SyncVectorEnv(
        [lambda: Echo(length=17) for _ in range(n)], autoreset_mode=mode
    )
    wrapped = VectorActionDelay(vector, Poisson(2.0), initial_action=1)
    wrapped.reset(seed=seed)
    rng = np.random.default_rng(0)
    sent = rng.integers(0, 50, (steps, n))
    for t in range(steps):
        *_, terminated, truncated, info = wrapped.step(sent[t])
        if mode == AutoresetMode.DISABLED and (terminated | truncated).any():
            wrapped.reset(options={"reset_mask": terminated | truncated})
    for i, sub in enumerate(vector.envs):
        single = make()
        single.reset(seed=seed + i)
        resets = 0
        for t in range(steps):
            if mode == AutoresetMode.NEXT_STEP and single.unwrapped.t == 17:
                single.reset()  # the vector env's reset step: no action sent
                resets += 1
                continue
            *_, truncated, _ = single.step(int(sent[t, i]))
            if truncated and mode != AutoresetMode.NEXT_STEP:
                single.reset()
        assert sub.executed == single.unwrapped.executed, (mode, i)
        assert (resets > 0) == (mode == AutoresetMode.NEXT_STEP)
