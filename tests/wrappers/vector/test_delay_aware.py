"""VectorDelayAwareObservation: each sub-env observes the view of a DelayAwareObservation.

The reference is Gymnasium's own vectorisation of the single stack: a ``SyncVectorEnv`` of
``DelayAwareObservation(ObservationDelay(ActionDelay(env)))`` sub-envs, reset with ``s + i``,
against ``VectorDelayAwareObservation(VectorObservationDelay(VectorActionDelay(vector_env)))``
with the same arguments: the views, the observation delays' entries and the view's ``info``
entries (``final_obs`` and ``final_info`` included) must agree at every step.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space
from support import actions, same, scribble

from delayed_rl.delays import Constant, Poisson, Uniform
from delayed_rl.wrappers import (
    ActionDelay,
    DelayAwareObservation,
    ObservationDelay,
    VectorActionDelay,
    VectorDelayAwareObservation,
    VectorObservationDelay,
)

ENVS = {
    # id: (gym.make kwargs): Box observations and actions, Box and Discrete, Discrete and Discrete
    "Pendulum-v1": {"max_episode_steps": 23},
    "CartPole-v1": {},
    "FrozenLake-v1": {"max_episode_steps": 17},
}
STACKS = {  # name: (observation delay, its max_delay, arrival, action delay, its max_delay, K, n)
    "both bounded": (Uniform(0, 3), None, "stale", Constant(1), None, None, 3),
    "both, Poisson clipped": (Poisson(2.0), 4, "network", Uniform(0, 2), None, None, 2),
    "observations only": (Constant(2), None, "network", None, None, None, 1),
    "actions only": (None, None, None, Poisson(1.5), 3, None, 2),
    "unbounded, ages clipped": (Poisson(3.0), None, "network", Constant(1), None, 2, 3),
    "no delay": (None, None, None, None, None, None, 2),
}
VIEW_INFO_KEYS = ("arrived_observations", "age_clipped")
DELAY_KEYS = ("observation_age",)  # (the view rewrites arrived_observations, the same pairs)


def make_pair(env_id, stack, mode, wrappers=()):
    """The vector stack with its view, and the vector env of single stacks with theirs."""
    observation, observation_max, rule, action, action_max, k, n = STACKS[stack]
    common = {
        "num_envs": n,
        "vectorization_mode": "sync",
        "vector_kwargs": {"autoreset_mode": mode},
        **ENVS[env_id],
    }

    def single(env):
        if action is not None:
            env = ActionDelay(env, action, max_delay=action_max)
        if observation is not None:
            env = ObservationDelay(env, observation, max_delay=observation_max, arrival=rule)
        return DelayAwareObservation(env, action_history=k)

    twin = vector_stack(gym.make_vec(env_id, **common), stack)
    return twin, gym.make_vec(env_id, wrappers=[single], **common)


def vector_stack(env, stack, between=None):
    """``env`` under the vector delays of ``stack`` and the vector view (``between`` them)."""
    observation, observation_max, rule, action, action_max, k, _ = STACKS[stack]
    if action is not None:
        env = VectorActionDelay(env, action, max_delay=action_max)
    if observation is not None:
        env = VectorObservationDelay(env, observation, max_delay=observation_max, arrival=rule)
    return VectorDelayAwareObservation(env if between is None else between(env), action_history=k)


class Reuse(gym.vector.VectorWrapper):
    """Returns the same observation array at every step, rewritten in place (as ``copy=False``)."""

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self.buffer = np.array(obs)
        return self.buffer, info

    def step(self, actions):
        obs, *rest = self.env.step(actions)
        self.buffer[...] = obs
        return (self.buffer, *rest)


def same_entries(got, expected, keys, where) -> None:
    """Assert the ``keys`` of two vector ``info`` dicts agree: masks, and values where masked."""
    for key in keys:
        assert (key in got) == (key in expected), (where, key)
        if key not in expected:
            continue
        mask = expected["_" + key]
        assert np.array_equal(got["_" + key], mask), (where, key)
        for i in np.flatnonzero(mask):
            assert same(got[key][i], expected[key][i]), (where, key, i)


def compare_step(got, expected, t) -> None:
    """Assert one step (or reset) of the twin and of the reference agree."""
    assert same(got[0], expected[0]), t
    info, expected_info = got[-1], expected[-1]
    same_entries(info, expected_info, VIEW_INFO_KEYS + DELAY_KEYS, f"step {t}")
    assert ("final_obs" in info) == ("final_obs" in expected_info), t
    if "final_obs" in expected_info:
        assert np.array_equal(info["_final_obs"], expected_info["_final_obs"]), t
        for i in np.flatnonzero(expected_info["_final_obs"]):
            assert same(info["final_obs"][i], expected_info["final_obs"][i]), (t, i)
        keys = VIEW_INFO_KEYS + DELAY_KEYS
        same_entries(info["final_info"], expected_info["final_info"], keys, f"final {t}")


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("stack", list(STACKS))
@pytest.mark.parametrize("env_id", list(ENVS))
def test_each_sub_env_observes_the_view_of_its_single_stack(env_id, stack, mode) -> None:
    twin, reference = make_pair(env_id, stack, mode)
    assert twin.single_observation_space == reference.single_observation_space
    assert twin.observation_space == batch_space(twin.single_observation_space, twin.num_envs)
    compare_step(twin.reset(seed=11), reference.reset(seed=11), "reset")
    ends = clipped = 0
    for t, batch in enumerate(actions(twin, 250, seed=4)):
        got, expected = twin.step(batch), reference.step(batch)
        compare_step(got, expected, t)
        for a, b in zip(got[1:4], expected[1:4], strict=True):
            assert np.array_equal(a, b), t
        ends += int((got[2] | got[3]).sum())
        clipped += int(got[-1]["age_clipped"].sum())
    assert ends > 0
    assert (clipped > 0) == (stack == "unbounded, ages clipped")


@pytest.mark.parametrize("stack", ["both bounded", "both, Poisson clipped"])
def test_under_disabled_autoreset_a_reset_mask_restarts_only_its_views(stack) -> None:
    twin, reference = make_pair("CartPole-v1", stack, AutoresetMode.DISABLED)
    compare_step(twin.reset(seed=2), reference.reset(seed=2), "reset")
    masked = 0
    for t, batch in enumerate(actions(twin, 200, seed=8)):
        got = twin.step(batch)
        compare_step(got, reference.step(batch), t)
        ended = got[2] | got[3]
        if ended.any():
            mask = {"reset_mask": ended}
            reset = twin.reset(options=dict(mask))
            compare_step(reset, reference.reset(options=dict(mask)), f"reset {t}")
            assert np.array_equal(reset[1]["_arrived_observations"], ended)
            masked += 1
    assert masked > 0


def test_the_view_reads_the_bounds_and_the_initial_action_of_the_vector_delays() -> None:
    vec = gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync")
    actions_delayed = VectorActionDelay(vec, Uniform(1, 2), initial_action=1)
    env = VectorDelayAwareObservation(VectorObservationDelay(actions_delayed, Uniform(0, 3)))
    assert (env.action_history, env.max_age, env.initial_action) == (5, 3, 1)
    views, info = env.reset(seed=0)
    assert views["actions"].tolist() == [[1] * 5] * 2
    assert views["age"].tolist() == [0, 0] and info["_arrived_observations"].all()
    rebuilt = VectorDelayAwareObservation(env.env, **env._saved_kwargs)
    assert rebuilt.action_history == 5


@pytest.mark.parametrize("stack", ["both bounded", "actions only"])
def test_nothing_handed_out_is_kept_or_shared(stack) -> None:
    """Scribbling on anything returned changes nothing later, nor any other entry of the step."""
    mode = AutoresetMode.SAME_STEP
    inner = gym.vector.SyncVectorEnv(
        [lambda: gym.make("Pendulum-v1", max_episode_steps=23)] * STACKS[stack][-1],
        copy=False,  # the inner env rewrites one batch in place every step
        autoreset_mode=mode,
    )
    twin = vector_stack(inner, stack, between=Reuse)  # the view must copy what it keeps
    reference = make_pair("Pendulum-v1", stack, mode)[1]
    got, expected = twin.reset(seed=5), reference.reset(seed=5)
    finals = 0
    for t, batch in enumerate(actions(twin, 100, seed=2)):
        compare_step(got, expected, t)
        info = got[-1]
        scribble(got[0])
        for entries in info["arrived_observations"]:
            scribble(entries)
        if "final_obs" in info:
            finals += 1
            for final in info["final_obs"]:
                scribble(final)
        same_entries(info, expected[-1], DELAY_KEYS, f"step {t}, scribbled")
        sent = batch.copy()
        got, expected = twin.step(sent), reference.step(batch)
        scribble(sent)  # the caller reuses its action array
    assert finals > 0


def test_an_action_outside_the_space_is_refused_before_the_stack_steps() -> None:
    vec = gym.make_vec("CartPole-v1", num_envs=3, vectorization_mode="sync")
    env = VectorDelayAwareObservation(VectorObservationDelay(vec, Constant(1)))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"^actions\[1\] must be an action of Discrete\(2\)"):
        env.step(np.array([0, 2, 1]))
    with pytest.raises(ValueError, match="^actions must be a batch of 3 actions"):
        env.step(np.array([0, 1]))
    assert [sub.get_wrapper_attr("_elapsed_steps") for sub in vec.envs] == [0, 0, 0]
    env.step(np.array([0, 1, 1]))
    assert [sub.get_wrapper_attr("_elapsed_steps") for sub in vec.envs] == [1, 1, 1]


def _vec(wrappers=None, n=2):
    return gym.make_vec("CartPole-v1", num_envs=n, vectorization_mode="sync", wrappers=wrappers)


@pytest.mark.parametrize(
    ("build", "exc", "match"),
    [
        (
            lambda: VectorDelayAwareObservation(_vec(), action_history=0),
            ValueError,
            "^action_history",
        ),
        (
            lambda: VectorDelayAwareObservation(_vec(), action_history=2.0),
            TypeError,
            "^action_history",
        ),
        (
            lambda: VectorDelayAwareObservation(VectorObservationDelay(_vec(), Poisson(2.0))),
            ValueError,
            "^VectorDelayAwareObservation needs action_history .* VectorObservationDelay of "
            "unbounded delay Poisson",
        ),
        (
            lambda: VectorDelayAwareObservation(
                VectorObservationDelay(VectorObservationDelay(_vec(), 1.0, 2), 1.0, 2)
            ),
            ValueError,
            "^env must hold at most one VectorObservationDelay for VectorDelayAwareObservation",
        ),
        (
            lambda: VectorDelayAwareObservation(
                VectorActionDelay(VectorActionDelay(_vec(), Constant(1)), Constant(1))
            ),
            ValueError,
            "^env must hold at most one VectorActionDelay",
        ),
    ],
)
def test_bad_arguments_are_refused_naming_them(build, exc, match) -> None:
    with pytest.raises(exc, match=match):
        build()


def test_an_unknown_autoreset_mode_is_refused() -> None:
    vec = _vec()
    vec.metadata = {**vec.metadata, "autoreset_mode": "sometimes"}
    with pytest.raises(ValueError, match="^unsupported autoreset_mode 'sometimes'"):
        VectorDelayAwareObservation(vec)


def test_delays_inside_the_sub_envs_are_refused_not_ignored() -> None:
    observed = VectorDelayAwareObservation(_vec([lambda e: ObservationDelay(e, Constant(1))]))
    with pytest.raises(ValueError, match="^env reports info\\['observation_age'\\] but holds no"):
        observed.reset(seed=0)
    acted = VectorDelayAwareObservation(_vec([lambda e: ActionDelay(e, Constant(1))]))
    acted.reset(seed=0)
    with pytest.raises(ValueError, match="holds no VectorActionDelay: its sub-envs hold an Act"):
        acted.step(np.array([0, 1]))
