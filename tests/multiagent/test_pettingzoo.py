"""The wrappers as PettingZoo envs: PettingZoo's API and seed tests, AEC round trips, SuperSuit."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence

from delayed_rl.delays import Constant, Poisson, Uniform
from delayed_rl.multiagent import ParallelActionDelay, ParallelObservationDelay, ParallelRewardDelay

from .envs import pettingzoo_env

#: Small settings, for speed: PettingZoo ids and their arguments.
ENVS = {
    "pistonball": ("butterfly/pistonball-v6", {"n_pistons": 4, "max_cycles": 15}),
    "cooperative_pong": ("butterfly/cooperative_pong-v6", {"max_cycles": 15}),
    "pursuit": (
        "sisl/pursuit-v5",
        {"max_cycles": 15, "x_size": 8, "y_size": 8, "n_evaders": 2, "n_pursuers": 3},
    ),
    "rps": ("classic/rps-v2", {"max_cycles": 15}),
}


def make(name, kind="parallel"):
    env_id, kwargs = ENVS[name]
    return pettingzoo_env(env_id, kind, **kwargs)


def stack(env):
    """All three delays on ``env``, with per-agent delays for the rewards."""
    env = ParallelActionDelay(env, Uniform(0, 2))
    env = ParallelObservationDelay(env, Poisson(1), max_delay=3, arrival="network")
    agents = env.possible_agents
    return ParallelRewardDelay(env, {a: Constant(i % 3) for i, a in enumerate(agents)})


WRAPPERS = {
    "reward": lambda env: ParallelRewardDelay(env, Poisson(2)),
    "reward-carry": lambda env: ParallelRewardDelay(env, Uniform(0, 4), on_episode_end="carry"),
    "observation-stale": lambda env: ParallelObservationDelay(env, Uniform(0, 3)),
    "observation-network": lambda env: ParallelObservationDelay(env, 2, arrival="network"),
    "action": lambda env: ParallelActionDelay(env, Uniform(0, 3)),
    "stack": stack,
}
CASES = [(env, wrapper) for env in ENVS for wrapper in WRAPPERS]
# cooperative_pong calls its own render() at every step, which warns without a render mode;
# pettingzoo.test imports envs the way PettingZoo 1.27 deprecates
pytestmark = [
    pytest.mark.filterwarnings("ignore:.*render method without specifying any render mode"),
    pytest.mark.filterwarnings("ignore:The old environment creation API:DeprecationWarning"),
]


@pytest.mark.parametrize(("env_name", "wrapper"), CASES)
def test_pettingzoos_parallel_api_and_seed_tests_pass(env_name, wrapper):
    from pettingzoo.test import parallel_api_test, parallel_seed_test

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # api_test resets in mid-episode
        parallel_api_test(WRAPPERS[wrapper](make(env_name)), num_cycles=20)
    parallel_seed_test(lambda: WRAPPERS[wrapper](make(env_name)), num_cycles=20)


def _run(env, seed, steps):
    """Everything ``env`` returns over ``steps`` steps of seeded random actions (or to its end)."""
    out = [env.reset(seed=seed)]
    for i, agent in enumerate(env.possible_agents):
        env.action_space(agent).seed(seed + i)
    for _ in range(steps):
        if not env.agents:
            break
        out.append(env.step({a: env.action_space(a).sample() for a in env.agents}))
    return out


@pytest.mark.parametrize("env_name", list(ENVS))
def test_the_same_seed_gives_the_same_run_and_another_seed_another(env_name):
    """A stronger seed test than PettingZoo's (which stops after one step): 12 steps."""
    first, again = _run(stack(make(env_name)), 4, 12), _run(stack(make(env_name)), 4, 12)
    assert len(first) > 5 and data_equivalence(first, again)
    delays = [info.get("drawn_reward_delay") for *_, infos in first[1:] for info in infos.values()]
    assert len(set(delays)) > 1
    other = _run(stack(make(env_name)), 5, 12)
    assert not data_equivalence(first, other)


@pytest.mark.parametrize(
    ("env_name", "wrapper"),
    [("pursuit", name) for name in ("reward", "observation-network", "action", "stack")]
    + [("pistonball", "stack")],
)
def test_an_aec_env_is_wrapped_through_aec_to_parallel_and_back(env_name, wrapper):
    """``parallel_to_aec(wrapper(aec_to_parallel(aec)))``: PettingZoo's AEC API test passes.

    And it gives, cycle by cycle, what the parallel wrapper gives.
    """
    from pettingzoo.test import api_test
    from pettingzoo.utils.conversions import aec_to_parallel, parallel_to_aec

    def wrapped_aec():
        return parallel_to_aec(WRAPPERS[wrapper](aec_to_parallel(make(env_name, "aec"))))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # api_test resets in mid-episode
        api_test(wrapped_aec(), num_cycles=20)
    parallel = WRAPPERS[wrapper](aec_to_parallel(make(env_name, "aec")))
    aec = wrapped_aec()
    parallel.reset(seed=3)
    aec.reset(seed=3)
    for i, agent in enumerate(parallel.possible_agents):
        parallel.action_space(agent).seed(i)
    cycles = 0
    while parallel.agents:
        actions = {agent: parallel.action_space(agent).sample() for agent in parallel.agents}
        obs, rewards, terminated, truncated, infos = parallel.step(actions)
        for agent in list(aec.agents):
            assert aec.agent_selection == agent
            aec.step(actions[agent])
        assert data_equivalence(dict(aec.rewards), dict(rewards))
        assert data_equivalence(aec.infos, infos)
        assert data_equivalence({a: aec.observe(a) for a in obs}, obs)
        cycles += 1
    assert cycles > 5


def _supersuit(base_class):
    import supersuit as ss

    envs = []
    for name in ("reward", "observation-stale", "action", "stack"):
        env = WRAPPERS[name](make("pursuit"))
        vec = ss.pettingzoo_env_to_vec_env_v1(env)
        envs.append(ss.concat_vec_envs_v1(vec, 2, num_cpus=0, base_class=base_class))
    return envs


def test_supersuits_vector_conversion_accepts_the_wrappers():
    for vec in _supersuit("gymnasium"):
        obs, infos = vec.reset(seed=0)
        assert vec.num_envs == 6 and obs.shape == (6, 7, 7, 3)  # 3 pursuers x 2 copies
        for _ in range(20):  # past the end of an episode (15 cycles): SuperSuit resets
            actions = np.array([vec.action_space.sample() for _ in range(vec.num_envs)])
            obs, rewards, terminated, truncated, infos = vec.step(actions)
            assert obs.shape == (6, 7, 7, 3) and rewards.shape == (6,)
        assert any(
            key in infos[0]
            for key in ("drawn_reward_delay", "observation_age", "drawn_action_delay")
        )
        vec.close()


@pytest.mark.sb3
def test_stable_baselines3_trains_one_shared_policy_through_supersuit():
    from stable_baselines3 import PPO

    for vec in _supersuit("stable_baselines3"):
        vec.reset()
        for _ in range(30):
            vec.step(np.array([vec.action_space.sample() for _ in range(vec.num_envs)]))
    # no seed: SB3 would call vec.seed(), which SuperSuit's ConcatVecEnv does not have
    model = PPO("MlpPolicy", vec, n_steps=8, batch_size=24, n_epochs=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # learn() resets in mid-episode
        model.learn(total_timesteps=96)
    assert model.num_timesteps >= 96
    vec.close()
