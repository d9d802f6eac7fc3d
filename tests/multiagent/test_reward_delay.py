"""ParallelRewardDelay: RewardDelay's rule per agent, agents leaving, seeds, streams, errors."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from delayed_rl.delays import Constant, Poisson, Uniform
from delayed_rl.multiagent import ParallelRewardDelay, agent_seed
from delayed_rl.wrappers import RewardDelay

from .envs import (
    AgentReplay,
    ScriptedParallelEnv,
    pettingzoo_env,
    policy,
    record,
    scripted_reward,
)

#: Four agents leaving at different steps, one truncated, one joining late.
ENDS = {
    "a": (4, "terminated"),
    "b": (9, "truncated"),
    "c": (13, "terminated"),
    "d": (11, "terminated"),
}
JOINS = {"d": 3}
#: "a" and "d" share a distribution (one line between them), the others have their own.
DELAYS = {"a": Poisson(2.5), "b": Constant(3), "c": Uniform(0, 6), "d": Poisson(2.5)}
KEYS = (
    "undelayed_reward",
    "drawn_reward_delay",
    "pending_reward",
    "flushed_reward",
    "dropped_reward",
)
SEED = 11


def run(env, schedule, seed=SEED, on_step=None, on_reset=None):
    """Run ``env`` over ``schedule`` (as :func:`envs.record`), calling back each step."""
    t = 0
    for episode, cut in enumerate(schedule):
        obs, infos = env.reset(seed=seed if episode == 0 else None)
        if on_reset is not None:
            on_reset(episode, infos)
        taken = 0
        while env.agents and (cut is None or taken < cut):
            order = env.possible_agents
            actions = {a: policy(t, order.index(a)) for a in env.agents}
            out = env.step(actions)
            t += 1
            taken += 1
            if on_step is not None:
                on_step(episode, *out)


@pytest.mark.parametrize("mode", ["flush", "drop", "carry"])
@pytest.mark.parametrize("seed", [SEED, 3])
def test_every_reward_is_a_single_agent_reward_delays_step_by_step(mode, seed):
    """Each agent gets, step by step, what a RewardDelay seeded agent_seed(s, i) delivers.

    Over four episodes: agents leaving at different steps (one truncated), one joining late,
    and a reset while agents are live (the third episode is cut after 6 steps).
    """
    schedule = [None, None, 6, None]
    recorded = record(ScriptedParallelEnv(ENDS, JOINS), seed, schedule)
    env = ParallelRewardDelay(ScriptedParallelEnv(ENDS, JOINS), DELAYS, on_episode_end=mode)
    refs = {
        agent: RewardDelay(
            AgentReplay([(None, steps) for _, steps in recorded[agent]]),
            DELAYS[agent],
            on_episode_end=mode,
        )
        for agent in ENDS
    }
    compared = []

    def on_reset(episode, infos):
        for i, agent in enumerate(ENDS):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the cut episode's warning, checked elsewhere
                _, ref_info = refs[agent].reset(seed=agent_seed(seed, i) if episode == 0 else None)
            if agent in infos:
                assert infos[agent].get("dropped_reward") == ref_info.get("dropped_reward")
                assert infos[agent]["pending_reward"] == ref_info["pending_reward"]

    def on_step(episode, obs, rewards, terminated, truncated, infos):
        for agent, reward in rewards.items():
            _, expected, ref_terminated, ref_truncated, ref_info = refs[agent].step(0)
            assert type(reward) is float
            assert reward == expected, (episode, agent)
            assert (terminated[agent], truncated[agent]) == (ref_terminated, ref_truncated)
            assert {k: infos[agent].get(k) for k in KEYS} == {k: ref_info.get(k) for k in KEYS}
            compared.append(agent)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run(env, schedule, seed, on_step, on_reset)
    assert set(compared) == set(ENDS) and len(compared) > 80


def test_under_flush_every_agent_receives_its_undelayed_return_exactly_as_agents_leave():
    env = ParallelRewardDelay(ScriptedParallelEnv(ENDS, JOINS), Poisson(4))
    for seed in range(5):
        emitted = dict.fromkeys(ENDS, 0.0)
        delivered = dict.fromkeys(ENDS, 0.0)
        last_step = {}
        env.reset(seed=seed)
        t = 0
        while env.agents:
            _, rewards, terminated, truncated, infos = env.step(dict.fromkeys(env.agents, 0))
            t += 1
            for agent, reward in rewards.items():
                delivered[agent] += reward
                emitted[agent] += infos[agent]["undelayed_reward"]
                if terminated[agent] or truncated[agent]:
                    last_step[agent] = t
                    assert infos[agent]["pending_reward"] == 0.0
                    assert "flushed_reward" in infos[agent]
                else:
                    assert "flushed_reward" not in infos[agent]
        assert last_step == {agent: end for agent, (end, _) in ENDS.items()}
        steps = {agent: end - JOINS.get(agent, 1) + 1 for agent, (end, _) in ENDS.items()}
        assert emitted == {
            agent: math.fsum(scripted_reward(i, 0, k) for k in range(1, steps[agent] + 1))
            for i, agent in enumerate(ENDS)
        }
        assert delivered == emitted  # exactly: every reward is a multiple of 0.5
        env.env.episode = -1  # the same rewards in every run


def test_drop_reports_what_each_leaving_agent_loses():
    env = ParallelRewardDelay(ScriptedParallelEnv(ENDS, JOINS), Poisson(3), on_episode_end="drop")
    env.reset(seed=5)
    emitted = dict.fromkeys(ENDS, 0.0)
    delivered = dict.fromkeys(ENDS, 0.0)
    dropped = {}
    while env.agents:
        _, rewards, terminated, truncated, infos = env.step(dict.fromkeys(env.agents, 0))
        for agent, reward in rewards.items():
            delivered[agent] += reward
            emitted[agent] += infos[agent]["undelayed_reward"]
            if terminated[agent] or truncated[agent]:
                dropped[agent] = infos[agent]["dropped_reward"]
                assert infos[agent]["pending_reward"] == 0.0
            else:
                assert "dropped_reward" not in infos[agent]
    assert set(dropped) == set(ENDS)
    assert {a: delivered[a] + dropped[a] for a in ENDS} == emitted
    assert any(dropped.values())  # something was lost (the test can tell)
    assert delivered != emitted


def test_carry_delivers_a_departed_agents_rewards_in_its_next_episode():
    """Constant(3): "a" leaves at step 4 with its last 3 rewards pending; they come next episode."""
    env = ParallelRewardDelay(ScriptedParallelEnv(ENDS, JOINS), Constant(3), on_episode_end="carry")
    received: dict[int, list[float]] = {0: [], 1: []}

    def on_step(episode, obs, rewards, terminated, truncated, infos):
        if "a" in rewards:
            received[episode].append(rewards["a"])
            if terminated["a"]:
                assert "flushed_reward" not in infos["a"] and "dropped_reward" not in infos["a"]
                assert infos["a"]["pending_reward"] == sum(
                    scripted_reward(0, episode, k) for k in (2, 3, 4)
                )

    pending_at_reset = []
    run(
        env,
        [None, None],
        on_step=on_step,
        on_reset=lambda e, i: pending_at_reset.append(i["a"]["pending_reward"]),
    )
    first = [scripted_reward(0, 0, k) for k in range(1, 5)]
    second = [scripted_reward(0, 1, k) for k in range(1, 5)]
    assert received[0] == [0.0, 0.0, 0.0, first[0]]
    assert received[1] == [first[1], first[2], first[3], second[0]]
    assert pending_at_reset == [0.0, sum(first[1:])]
    assert env.pending_rewards["a"] == sum(second[1:])


def test_each_agent_draws_from_its_own_distribution():
    delays = {"a": Constant(0), "b": Constant(2), "c": Uniform(4, 6), "d": Poisson(1)}
    env = ParallelRewardDelay(ScriptedParallelEnv(ENDS, JOINS), delays)
    seen: dict[str, list[int]] = {agent: [] for agent in ENDS}

    def on_step(episode, obs, rewards, terminated, truncated, infos):
        for agent in rewards:
            seen[agent].append(infos[agent]["drawn_reward_delay"])

    run(env, [None, None], on_step=on_step)
    assert set(seen["a"]) == {0} and set(seen["b"]) == {2}
    assert set(seen["c"]) <= {4, 5, 6} and len(set(seen["c"])) > 1
    assert min(seen["d"]) >= 0 and len(set(seen["d"])) > 1


def _delays(env, seed, steps):
    """Each agent's delays over ``steps`` steps after ``reset(seed=seed)``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the last run's rewards pending, dropped
        env.reset(seed=seed)
    seen = {agent: [] for agent in env.possible_agents}
    for _ in range(steps):
        infos = env.step(dict.fromkeys(env.agents, 0))[-1]
        for agent, info in infos.items():
            seen[agent].append(info["drawn_reward_delay"])
    return {agent: np.array(values) for agent, values in seen.items()}


LONG = {agent: (100_000, "terminated") for agent in "abc"}


def test_the_same_seed_gives_the_same_delays_and_another_seed_others():
    env = ParallelRewardDelay(ScriptedParallelEnv(LONG), Poisson(3))
    first, again, other = _delays(env, 7, 200), _delays(env, 7, 200), _delays(env, 8, 200)
    for agent in LONG:
        np.testing.assert_array_equal(first[agent], again[agent])
        assert not np.array_equal(first[agent], other[agent])
    twin = ParallelRewardDelay(ScriptedParallelEnv(LONG), Poisson(3))
    assert all(np.array_equal(_delays(twin, 7, 200)[a], first[a]) for a in LONG)


def test_copies_of_an_unseeded_wrapper_draw_their_own_delays():
    """SuperSuit's vector conversion pickles one env into each sub-env, then resets unseeded."""
    import pickle

    original = ParallelRewardDelay(ScriptedParallelEnv(LONG), Poisson(3))
    copies = [pickle.loads(pickle.dumps(original)) for _ in range(2)]
    drawn = [_delays(copy, None, 100) for copy in copies]
    assert all(not np.array_equal(drawn[0][a], drawn[1][a]) for a in LONG)


def test_the_agents_streams_are_independent_and_follow_the_distribution():
    """Same distribution, different sequences; correlations and means within 4 standard errors."""
    steps, lam = 3000, 3.0
    env = ParallelRewardDelay(ScriptedParallelEnv(LONG), Poisson(lam))
    seen = _delays(env, 0, steps)
    bound = 4 / math.sqrt(steps)  # |r| of independent sequences: standard error 1/sqrt(n)
    for agent in LONG:
        assert abs(seen[agent].mean() - lam) < 4 * math.sqrt(lam / steps)
    for x, y in (("a", "b"), ("a", "c"), ("b", "c")):
        assert not np.array_equal(seen[x], seen[y])
        assert abs(np.corrcoef(seen[x], seen[y])[0, 1]) < bound
        assert abs(np.corrcoef(seen[x][1:], seen[y][:-1])[0, 1]) < bound  # lagged too


def test_an_agents_stream_is_the_single_wrappers_for_its_seed_whatever_the_others_do():
    env = ParallelRewardDelay(
        ScriptedParallelEnv(LONG), {"a": Poisson(3), "b": Constant(1), "c": Poisson(3)}
    )
    seen = _delays(env, 21, 50)
    ref = RewardDelay(AgentReplay([(None, [(1.0, None, False, False)] * 50)]), Poisson(3))
    ref.reset(seed=agent_seed(21, 2))
    np.testing.assert_array_equal(
        seen["c"], [ref.step(0)[-1]["drawn_reward_delay"] for _ in range(50)]
    )


def test_the_envs_own_randomness_is_unaffected():
    """The wrapped env's observations (its own noise, pursuit's evaders) are the unwrapped env's."""

    def make_pursuit():
        return pettingzoo_env(
            "sisl/pursuit-v5", max_cycles=30, x_size=8, y_size=8, n_evaders=3, n_pursuers=3
        )

    for make in (lambda: ScriptedParallelEnv(ENDS, JOINS, fresh=True), make_pursuit):
        plain, wrapped = make(), ParallelRewardDelay(make(), Poisson(5))
        obs_plain, _ = plain.reset(seed=4)
        obs_wrapped, _ = wrapped.reset(seed=4)
        for agent in plain.possible_agents:
            plain.action_space(agent).seed(0)
        steps = 0
        while plain.agents:
            actions = {agent: plain.action_space(agent).sample() for agent in plain.agents}
            np.testing.assert_equal(obs_wrapped, obs_plain)
            obs_plain, rewards_plain = plain.step(actions)[:2]
            obs_wrapped, _, _, _, infos = wrapped.step(actions)
            assert {a: info["undelayed_reward"] for a, info in infos.items()} == {
                a: float(r) for a, r in rewards_plain.items()
            }
            steps += 1
        assert wrapped.agents == [] and steps > 10


def test_a_reset_while_agents_are_live_drops_their_pending_rewards_with_a_warning():
    env = ParallelRewardDelay(ScriptedParallelEnv(ENDS, JOINS), Constant(5))
    env.reset(seed=0)
    for _ in range(5):  # "a" has left (flushed); "b", "c" and "d" are live with rewards pending
        env.step(dict.fromkeys(env.agents, 0))
    pending = env.pending_rewards
    assert pending["a"] == 0.0 and pending["b"] != 0.0
    with pytest.warns(UserWarning, match="reset\\(\\) while agents were live discarded"):
        _, infos = env.reset()
    assert {a: infos[a]["dropped_reward"] for a in ("b", "c")} == {a: pending[a] for a in "bc"}
    assert "dropped_reward" not in infos["a"]
    assert env.pending_rewards == dict.fromkeys(ENDS, 0.0)

    carry = ParallelRewardDelay(
        ScriptedParallelEnv(ENDS, JOINS), Constant(5), on_episode_end="carry"
    )
    carry.reset(seed=0)
    for _ in range(5):
        carry.step(dict.fromkeys(carry.agents, 0))
    kept = carry.pending_rewards
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, infos = carry.reset()
    assert carry.pending_rewards == kept and "dropped_reward" not in infos["b"]


def test_the_flush_trap_is_watched_over_all_agents():
    class FinalOnly(ScriptedParallelEnv):
        def step(self, actions):
            out = super().step(actions)
            for agent in out[1]:
                out[1][agent] = 1.0 if out[2][agent] or out[3][agent] else 0.0
            return out

    env = ParallelRewardDelay(FinalOnly(ENDS, JOINS), Poisson(3))
    with pytest.warns(UserWarning, match="carry"):
        run(env, [None] * 3)  # 4 agents' episodes with a reward each: 12 >= 10


def test_a_reward_that_is_not_a_finite_real_scalar_is_refused_naming_the_agent():
    class Bad(ScriptedParallelEnv):
        value = None

        def step(self, actions):
            out = super().step(actions)
            out[1]["b"] = self.value
            return out

    env = ParallelRewardDelay(Bad(ENDS), Poisson(1))
    env.reset(seed=0)
    for value, error, message in (
        (np.array([1.0]), TypeError, r"rewards\['b'\] must be a real scalar"),
        (True, TypeError, r"rewards\['b'\]"),
        (float("nan"), ValueError, r"agent 'b' a non-finite reward"),
        (float("inf"), ValueError, r"agent 'b' a non-finite reward"),
    ):
        env.env.value = value
        with pytest.raises(error, match=message):
            env.step(dict.fromkeys(env.agents, 0))
    env.env.value = 2  # an int is a real scalar: accepted, as RewardDelay accepts it
    assert env.step(dict.fromkeys(env.agents, 0))[-1]["b"]["undelayed_reward"] == 2.0


def test_a_reward_for_an_unknown_agent_is_refused():
    class Stranger(ScriptedParallelEnv):
        def step(self, actions):
            out = super().step(actions)
            out[1]["zed"] = 1.0
            return out

    env = ParallelRewardDelay(Stranger(ENDS), Poisson(1))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="names agent 'zed', which is not one of possible_agents"):
        env.step(dict.fromkeys(env.agents, 0))


def test_the_infos_are_new_dicts():
    class Shared(ScriptedParallelEnv):
        def step(self, actions):
            out = super().step(actions)
            shared = {"env": 1}
            self.last_infos = {agent: shared for agent in out[1]}
            return (*out[:4], self.last_infos)

    env = ParallelRewardDelay(
        Shared(ENDS), {"a": Constant(0), "b": Constant(1), "c": Constant(2), "d": Constant(3)}
    )
    env.reset(seed=0)
    infos = env.step(dict.fromkeys(env.agents, 0))[-1]
    assert [infos[a]["drawn_reward_delay"] for a in "abcd"] == [0, 1, 2, 3]
    assert all(info == {"env": 1} for info in env.env.last_infos.values())
