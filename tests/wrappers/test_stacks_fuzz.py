"""Fuzzing action + reward delay stacks: conservation, which action executes, and no aliasing.

Hypothesis draws an action space (``Discrete``, ``Box``, ``MultiDiscrete``, ``MultiBinary``, and
``Dict`` and ``Tuple`` of them, nested), an action delay and a reward delay from every family,
an episode-end mode, a script of rewards and episode ends, and mid-episode resets. The inner env
records a deep copy of each action it executes, then scribbles over the action it was given;
the caller scribbles over its own action after each step and over ``info["executed_action"]``.
At every step, per (sub-)env:

- ``delivered + pending + dropped == emitted`` exactly (rewards are multiples of 1/8);
- the action executed is the latest one sent whose delay has run out in this episode (or the
  initial action), as it was when sent, and ``info`` reports that very action;
- ``initial_action`` is what it was at construction.

The stack is the one ``wrap_delays`` and ``gym.make(..., action_delay=, reward_delay=)`` build:
the action delay inside, the reward delay outside; the vector stack is its twin.
"""

from __future__ import annotations

import copy
import warnings

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support import examples, same, scribble

from delayed_rl.delays import Constant, Empirical, Geometric, Poisson, Uniform
from delayed_rl.wrappers import (
    EPISODE_END_MODES,
    ActionDelay,
    RewardDelay,
    VectorActionDelay,
    VectorRewardDelay,
)

FUZZ = settings(
    max_examples=examples(60),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
NONE, TERMINATE, TRUNCATE = 0, 1, 2

leaves = st.one_of(
    st.integers(1, 5).map(spaces.Discrete),
    st.integers(1, 3).map(lambda n: spaces.Box(-1.0, 1.0, (n,), dtype=np.float32)),
    st.integers(1, 3).map(lambda n: spaces.Box(0.0, 2.0, (n,), dtype=np.float64)),
    st.lists(st.integers(2, 4), min_size=1, max_size=3).map(spaces.MultiDiscrete),
    st.integers(1, 3).map(spaces.MultiBinary),
)
action_spaces = st.recursive(
    leaves,
    lambda inner: st.one_of(
        st.lists(inner, min_size=1, max_size=3).map(lambda parts: spaces.Tuple(tuple(parts))),
        st.dictionaries(st.sampled_from("abcd"), inner, min_size=1, max_size=3).map(spaces.Dict),
    ),
    max_leaves=5,
)
weights = st.lists(st.integers(0, 5), min_size=1, max_size=6).filter(sum)
delays = st.one_of(
    st.floats(0.0, 6.0).map(Poisson),
    st.integers(0, 6).map(Constant),
    st.floats(0.1, 1.0).map(Geometric),
    st.tuples(st.integers(0, 3), st.integers(0, 4)).map(lambda t: Uniform(t[0], t[0] + t[1])),
    weights.map(lambda w: Empirical([x / sum(w) for x in w])),
)
eighths = st.integers(-64, 64).map(lambda k: k / 8)
ends = st.sampled_from([NONE] * 8 + [TERMINATE, TRUNCATE])
scripts = st.lists(st.tuples(eighths, ends), min_size=1, max_size=40)
modes = st.sampled_from(EPISODE_END_MODES)


class ScriptedEditor(gym.Env):
    """Plays a script of ``(reward, end)`` steps; records and then scribbles over each action."""

    observation_space = spaces.Discrete(1)

    def __init__(self, action_space, script):
        self.action_space = action_space
        self.script = list(script)
        self.t = 0
        self.executed: list = []

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return 0, {}

    def step(self, action):
        assert self.action_space.contains(action)
        self.executed.append(copy.deepcopy(action))
        scribble(action)
        reward, end = self.script[self.t % len(self.script)]
        self.t += 1
        return 0, reward, end == TERMINATE, end == TRUNCATE, {}


class Reference:
    """Which action executes, by brute force: the latest sent whose delay has run out."""

    def __init__(self, initial):
        self.initial = initial
        self.restart()

    def restart(self) -> None:
        self.sent: list = []
        self.delays: list[int] = []

    def send(self, action, delay: int) -> tuple[object, int]:
        self.sent.append(copy.deepcopy(action))
        self.delays.append(delay)
        t = len(self.sent) - 1
        arrived = [i for i in range(t + 1) if i + self.delays[i] <= t]
        return (self.sent[max(arrived)], max(arrived)) if arrived else (self.initial, -1)


@FUZZ
@given(
    space=action_spaces,
    action_delay=delays,
    reward_delay=delays,
    mode=modes,
    script=scripts,
    resets=st.lists(st.sampled_from([False] * 12 + [True]), min_size=1, max_size=50),
    seed=st.integers(0, 2**32),
)
def test_a_single_stack_conserves_rewards_and_executes_each_action_as_sent(
    space, action_delay, reward_delay, mode, script, resets, seed
) -> None:
    space.seed(seed)
    initial = space.sample()
    env = RewardDelay(
        ActionDelay(ScriptedEditor(space, script), action_delay, initial_action=initial),
        reward_delay,
        on_episode_end=mode,
    )
    reference = Reference(copy.deepcopy(initial))
    emitted = delivered = dropped = 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the mid-episode resets' and the flush watch's
        env.reset(seed=seed)
        ended = False
        for reset_now in resets:
            if reset_now or ended:
                _, info = env.reset()
                dropped += info.get("dropped_reward", 0.0)
                assert delivered + info["pending_reward"] + dropped == emitted
                reference.restart()
            action = space.sample()
            _, reward, terminated, truncated, info = env.step(action)
            expected, step = reference.send(action, info["drawn_action_delay"])
            scribble(action)
            assert info["executed_action_step"] == step
            assert same(info["executed_action"], expected)
            assert same(env.unwrapped.executed[-1], expected)
            scribble(info["executed_action"])
            emitted += info["undelayed_reward"]
            delivered += reward
            dropped += info.get("dropped_reward", 0.0)
            assert delivered + info["pending_reward"] + dropped == emitted
            ended = terminated or truncated
    assert same(env.env.initial_action, initial)


@FUZZ
@given(
    space=action_spaces,
    action_delay=delays,
    reward_delay=delays,
    mode=modes,
    autoreset=st.sampled_from([AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP]),
    scripts_=st.lists(scripts, min_size=1, max_size=3),
    steps=st.integers(1, 40),
    seed=st.integers(0, 2**32),
)
def test_a_vector_stack_conserves_rewards_and_executes_each_action_as_sent(
    space, action_delay, reward_delay, mode, autoreset, scripts_, steps, seed
) -> None:
    n = len(scripts_)
    inner = SyncVectorEnv(
        [lambda script=script: ScriptedEditor(space, script) for script in scripts_],
        autoreset_mode=autoreset,
    )
    space.seed(seed)
    initial = space.sample()
    actions_env = VectorActionDelay(inner, action_delay, initial_action=initial)
    env = VectorRewardDelay(actions_env, reward_delay, on_episode_end=mode)
    references = [Reference(copy.deepcopy(initial)) for _ in range(n)]
    emitted = np.zeros(n)
    delivered = np.zeros(n)
    dropped = np.zeros(n)
    env.action_space.seed(seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env.reset(seed=seed)
        resetting = np.zeros(n, dtype=bool)
        for _ in range(steps):
            batch = env.action_space.sample()
            sent = list(gym.vector.utils.iterate(env.action_space, copy.deepcopy(batch)))
            _, rewards, terminated, truncated, info = env.step(batch)
            scribble(batch)
            reported = list(gym.vector.utils.iterate(env.action_space, info["executed_action"]))
            for i in range(n):
                if resetting[i]:  # NEXT_STEP: this step was the sub-env's reset
                    references[i].restart()
                    assert not info["_executed_action"][i]
                    continue
                expected, step = references[i].send(sent[i], int(info["drawn_action_delay"][i]))
                assert info["executed_action_step"][i] == step
                assert same(reported[i], expected)
                assert same(inner.envs[i].executed[-1], expected)
            scribble(info["executed_action"])
            ended = np.asarray(terminated) | np.asarray(truncated)
            emitted += np.where(info["_undelayed_reward"], info["undelayed_reward"], 0.0)
            delivered += rewards
            if "dropped_reward" in info:
                dropped += np.where(info["_dropped_reward"], info["dropped_reward"], 0.0)
            np.testing.assert_array_equal(delivered + info["pending_reward"] + dropped, emitted)
            if autoreset == AutoresetMode.SAME_STEP:
                for i in np.flatnonzero(ended):
                    references[i].restart()
            resetting = ended if autoreset == AutoresetMode.NEXT_STEP else resetting
    assert same(actions_env.initial_action, initial)
