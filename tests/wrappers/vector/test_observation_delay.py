"""VectorObservationDelay: each sub-env is an ObservationDelay, step by step, in every autoreset mode.

The reference is Gymnasium's own vectorisation of the single wrapper: a ``SyncVectorEnv`` of
:class:`ObservationDelay` sub-envs (``gym.make_vec(..., wrappers=[...])``), which resets sub-env
``i`` with the seed ``s + i``, and whose ``info`` (masks, ``final_obs``, ``final_info``) the
vector twin must give entry for entry.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from support import actions, same, scribble

from delayed_rl.delays import Constant, Poisson, Uniform
from delayed_rl.wrappers import ObservationDelay, VectorObservationDelay
from delayed_rl.wrappers.observation_delay import ARRIVAL_RULES, NetworkArrival, StaleArrival

ENVS = {
    # id: (gym.make kwargs): Box observations and actions, Box and Discrete, Discrete and Discrete
    "Pendulum-v1": {"max_episode_steps": 23},
    "CartPole-v1": {},
    "FrozenLake-v1": {"max_episode_steps": 17},
}
DELAYS = [  # (delay, max_delay, num_envs)
    (Uniform(0, 3), None, 3),
    (Constant(2), None, 1),
    (Poisson(2.0), 4, 2),
]
KEYS = ("observation_age", "arrived_observations")


def make_pair(env_id, n, mode, delay, max_delay, rule):
    """The vector twin over a plain vector env, and the vector env of single wrappers."""
    common = {
        "num_envs": n,
        "vectorization_mode": "sync",
        "vector_kwargs": {"autoreset_mode": mode},
        **ENVS[env_id],
    }
    twin = VectorObservationDelay(gym.make_vec(env_id, **common), delay, max_delay, rule)
    wrap = [lambda env: ObservationDelay(env, delay, max_delay=max_delay, arrival=rule)]
    return twin, gym.make_vec(env_id, wrappers=wrap, **common)


def same_info(got, expected, where="info") -> None:
    """Assert two vector ``info`` dicts hold the same keys and entries (nested, masks included)."""
    assert sorted(got) == sorted(expected), where
    for key, value in expected.items():
        if isinstance(value, dict):
            same_info(got[key], value, f"{where}[{key!r}]")
        elif isinstance(value, np.ndarray) and value.dtype == object:
            assert got[key].dtype == object and len(got[key]) == len(value), (where, key)
            for i, (a, b) in enumerate(zip(got[key], value, strict=True)):
                assert same(a, b), (where, key, i, a, b)
        else:
            assert np.array_equal(got[key], value), (where, key, got[key], value)


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("rule", ARRIVAL_RULES)
@pytest.mark.parametrize(("delay", "max_delay", "n"), DELAYS)
@pytest.mark.parametrize("env_id", list(ENVS))
def test_each_sub_env_is_an_observation_delay_reset_with_seed_s_plus_i(
    env_id, delay, max_delay, n, rule, mode
) -> None:
    twin, reference = make_pair(env_id, n, mode, delay, max_delay, rule)
    obs, info = twin.reset(seed=7)
    expected_obs, expected_info = reference.reset(seed=7)
    assert same(obs, expected_obs)
    same_info(info, expected_info)
    ends = ages = 0
    for t, batch in enumerate(actions(twin, 250, seed=3)):
        obs, rewards, terminated, truncated, info = twin.step(batch)
        expected = reference.step(batch)
        assert same(obs, expected[0]), t
        assert np.array_equal(rewards, expected[1]) and np.array_equal(terminated, expected[2])
        assert np.array_equal(truncated, expected[3]), t
        same_info(info, expected[4], f"step {t}")
        ends += int((terminated | truncated).sum())
        ages += int(info["observation_age"].sum())
    assert ends > 0  # episodes restarted, under the autoreset mode
    assert ages > 0  # and observations were delayed


@pytest.mark.parametrize("rule", ARRIVAL_RULES)
def test_under_disabled_autoreset_a_reset_mask_restarts_only_its_sub_envs(rule) -> None:
    mode = AutoresetMode.DISABLED
    twin, reference = make_pair("CartPole-v1", 3, mode, Uniform(0, 4), None, rule)
    same_info(twin.reset(seed=[4, 11, 9])[1], reference.reset(seed=[4, 11, 9])[1])
    masked = 0
    for t, batch in enumerate(actions(twin, 200, seed=1)):
        obs, _, terminated, truncated, info = twin.step(batch)
        expected = reference.step(batch)
        assert same(obs, expected[0]), t
        same_info(info, expected[4], f"step {t}")
        ended = terminated | truncated
        if ended.any():
            mask = {"reset_mask": ended}
            obs, info = twin.reset(options=dict(mask))
            expected_obs, expected_info = reference.reset(options=dict(mask))
            assert same(obs, expected_obs), t  # the others show again what they showed
            same_info(info, expected_info, f"reset {t}")
            assert np.array_equal(info["_observation_age"], ended)
            masked += 1
    assert masked > 0


def test_same_step_reports_the_delayed_final_observation_not_the_undelayed_one() -> None:
    def plain():
        return gym.make_vec(
            "CartPole-v1",
            num_envs=2,
            vectorization_mode="sync",
            vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP},
        )

    twin, bare = VectorObservationDelay(plain(), Constant(3)), plain()
    twin.reset(seed=0)
    made = [[row] for row in bare.reset(seed=0)[0]]  # each sub-env's episode: o_0, o_1, ...
    finals = 0
    for batch in actions(twin, 200, seed=0):
        shown, _, terminated, truncated, info = twin.step(batch)
        rows, *_, undelayed = bare.step(batch)
        for i in range(2):
            if not (terminated[i] or truncated[i]):
                made[i].append(rows[i])
                continue
            made[i].append(undelayed["final_obs"][i])  # o_T, which the delay hides
            assert same(info["final_obs"][i], made[i][-4])  # o_{T-3}, as shown at step T-1
            assert not same(info["final_obs"][i], made[i][-1])
            assert info["final_info"]["observation_age"][i] == 3
            assert info["final_info"]["arrived_observations"][i][0][0] == len(made[i]) - 4
            assert same(shown[i], rows[i])  # the new episode's o_0, undelayed
            assert info["observation_age"][i] == 0 and info["arrived_observations"][i][0][0] == 0
            made[i] = [rows[i]]
            finals += 1
    assert finals > 2


@pytest.mark.parametrize("rule", ARRIVAL_RULES)
def test_nothing_handed_out_is_kept_or_shared(rule) -> None:
    """Scribbling on everything returned changes nothing later; the inner batch is reused."""
    mode = AutoresetMode.SAME_STEP
    inner = gym.vector.SyncVectorEnv(
        [lambda: gym.make("CartPole-v1")] * 2,
        copy=False,  # the inner env rewrites one batch in place every step
        autoreset_mode=mode,
    )
    twin = VectorObservationDelay(inner, Uniform(0, 3), arrival=rule)
    reference = make_pair("CartPole-v1", 2, mode, Uniform(0, 3), None, rule)[1]
    got, expected = twin.reset(seed=5), reference.reset(seed=5)
    finals = 0
    for t, batch in enumerate(actions(twin, 150, seed=2)):
        assert same(got[0], expected[0]), t
        same_info(got[-1], expected[-1], f"step {t}")
        scribble(got[0])
        for entries in got[-1]["arrived_observations"]:
            scribble(entries)
        if "final_obs" in got[-1]:
            finals += 1
            for final in got[-1]["final_obs"]:
                scribble(final)
        got, expected = twin.step(batch), reference.step(batch)
    assert finals > 0


def test_the_rules_are_the_single_wrappers_classes_one_per_sub_env() -> None:
    vec = gym.make_vec("CartPole-v1", num_envs=3, vectorization_mode="sync")
    stale = VectorObservationDelay(vec, Uniform(0, 5))
    network = VectorObservationDelay(vec, Uniform(0, 5), arrival="network")
    assert all(type(rule) is StaleArrival for rule in stale.rules)
    assert all(type(rule) is NetworkArrival for rule in network.rules)
    assert len({id(rule) for rule in stale.rules}) == 3
    assert stale.history == ObservationDelay(gym.make("CartPole-v1"), Uniform(0, 5)).history == 6
    rebuilt = VectorObservationDelay(vec, **network._saved_kwargs)
    assert (rebuilt.delay, rebuilt.max_delay, rebuilt.arrival) == (Uniform(0, 5), None, "network")


@pytest.mark.parametrize(
    ("kwargs", "exc", "name"),
    [
        ({"delay": "2"}, TypeError, "delay"),
        ({"delay": -1.0}, ValueError, "delay"),
        ({"delay": 2.0, "max_delay": 2.5}, TypeError, "max_delay"),
        ({"delay": 2.0, "max_delay": -1}, ValueError, "max_delay"),
        ({"delay": 2.0, "arrival": "late"}, ValueError, "arrival"),
        ({"delay": 2.0, "arrival": 1}, TypeError, "arrival"),
    ],
)
def test_bad_arguments_are_refused_as_the_single_wrapper_refuses_them(kwargs, exc, name) -> None:
    vec = gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync")
    with pytest.raises(exc) as single:
        ObservationDelay(gym.make("CartPole-v1"), **kwargs)
    with pytest.raises(exc) as vector:
        VectorObservationDelay(vec, **kwargs)
    assert str(vector.value) == str(single.value)
    assert str(vector.value).startswith(name)


def test_an_unknown_autoreset_mode_and_bad_seeds_are_refused() -> None:
    vec = gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync")
    vec.metadata = {**vec.metadata, "autoreset_mode": "sometimes"}
    with pytest.raises(ValueError, match="^unsupported autoreset_mode 'sometimes'"):
        VectorObservationDelay(vec, 2.0)
    env = VectorObservationDelay(gym.make_vec("CartPole-v1", num_envs=2), 2.0)
    with pytest.raises(ValueError, match=r"^seed must be"):
        env.reset(seed=-1)
    with pytest.raises(ValueError, match=r"^seed must be a list of one seed per sub-env \(2\)"):
        env.reset(seed=[1, 2, 3])
