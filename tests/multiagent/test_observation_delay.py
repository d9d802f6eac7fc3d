"""ParallelObservationDelay: ObservationDelay's rules per agent, joins and departures, copies."""

from __future__ import annotations

import numpy as np
import pytest

from delayed_rl.delays import Constant, Poisson, Uniform
from delayed_rl.multiagent import ParallelObservationDelay, agent_seed
from delayed_rl.wrappers import ObservationDelay

from .envs import AgentReplay, ScriptedParallelEnv, pettingzoo_env, policy, record

ENDS = {
    "a": (4, "terminated"),
    "b": (9, "truncated"),
    "c": (13, "terminated"),
    "d": (11, "terminated"),
}
JOINS = {"d": 3}
DELAYS = {"a": Poisson(2.5), "b": Constant(3), "c": Uniform(0, 6), "d": Poisson(2.5)}


def _replay(episodes):
    """The agent's episodes as :class:`AgentReplay` sees them: its first observation, then steps.

    An agent that joins late has its first observation at its first step; an episode it did not
    join is left out.
    """
    out = []
    for first, steps in episodes:
        if first is not None:
            out.append((first, steps))
        elif steps:
            out.append((steps[0][1], steps[1:]))
    return out


def _same(shown, info, expected, ref_info):
    np.testing.assert_array_equal(shown, expected)
    assert info["observation_age"] == ref_info["observation_age"]
    got, want = info["arrived_observations"], ref_info["arrived_observations"]
    assert [i for i, _ in got] == [i for i, _ in want]
    for (_, a), (_, b) in zip(got, want, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("arrival", ["stale", "network"])
@pytest.mark.parametrize("seed", [2, 9])
def test_every_observation_is_a_single_agent_observation_delays_step_by_step(arrival, seed):
    """Agents leaving, one joining late, a reset while agents are live; the env reuses its arrays."""
    schedule = [None, 2, 6, None]  # the second episode ends before "d" joins
    recorded = record(ScriptedParallelEnv(ENDS, JOINS, fresh=True), seed, schedule)
    env = ParallelObservationDelay(ScriptedParallelEnv(ENDS, JOINS), DELAYS, arrival=arrival)
    refs = {
        agent: ObservationDelay(AgentReplay(_replay(recorded[agent])), DELAYS[agent], None, arrival)
        for agent in ENDS
    }
    seeded = set()

    def ref_reset(agent):
        i = list(ENDS).index(agent)
        out = refs[agent].reset(seed=None if agent in seeded else agent_seed(seed, i))
        seeded.add(agent)
        return out

    compared = 0
    t = 0
    for episode, cut in enumerate(schedule):
        obs, infos = env.reset(seed=seed if episode == 0 else None)
        for agent in obs:
            _same(obs[agent], infos[agent], *ref_reset(agent))
        live = set(obs)
        taken = 0
        while env.agents and (cut is None or taken < cut):
            actions = {a: policy(t, list(ENDS).index(a)) for a in env.agents}
            obs, _, terminated, truncated, infos = env.step(actions)
            t += 1
            taken += 1
            for agent in obs:
                if agent in live:
                    expected, _, ref_term, ref_trunc, ref_info = refs[agent].step(0)
                    assert (terminated[agent], truncated[agent]) == (ref_term, ref_trunc)
                    _same(obs[agent], infos[agent], expected, ref_info)
                    compared += 1
                else:  # joins now: its o_0, as at a reset
                    _same(obs[agent], infos[agent], *ref_reset(agent))
                    live.add(agent)
            live -= {a for a in obs if terminated[a] or truncated[a]}
    assert compared > 50 and seeded == set(ENDS)


def test_an_agent_that_joins_starts_with_its_own_first_observation_and_leaves_nothing_behind():
    env = ParallelObservationDelay(ScriptedParallelEnv(ENDS, JOINS, fresh=True), Constant(2))
    env.reset(seed=0)
    for t in range(1, 14):
        obs, _, terminated, truncated, infos = env.step(dict.fromkeys(env.agents, 0))
        if t == JOINS["d"]:
            assert infos["d"]["observation_age"] == 0
            assert obs["d"][0] == t  # made at the join step
            assert [i for i, _ in infos["d"]["arrived_observations"]] == [0]
        for agent in obs:
            if terminated[agent] or truncated[agent]:
                assert env.rules[agent].made == 0  # its observations are let go
                assert obs[agent][0] == t - 2  # its last observation is delayed too
    assert env.agents == []


def test_observations_are_copies_where_they_come_in_and_where_they_go_out():
    env = ParallelObservationDelay(ScriptedParallelEnv(ENDS), Constant(1), arrival="network")
    obs, infos = env.reset(seed=0)
    inner = env.env.buffers  # the arrays the env hands out and changes at every step
    assert all(obs[a] is not inner[a] for a in obs)
    obs["a"][:] = -7.0
    infos["a"]["arrived_observations"][0][1][:] = -8.0
    shown, _, _, _, infos = env.step(dict.fromkeys(env.agents, 0))
    assert shown["a"][0] == 0.0  # o_0, as made: neither the env's change nor the caller's
    assert infos["a"]["arrived_observations"] == ()
    shown["a"][:] = -9.0
    shown, _, _, _, infos = env.step(dict.fromkeys(env.agents, 0))
    assert shown["a"][0] == 1.0 and infos["a"]["arrived_observations"][0][0] == 1


def test_each_agent_keeps_only_the_images_its_delay_can_reach():
    env = ParallelObservationDelay(
        pettingzoo_env("butterfly/pistonball-v6", n_pistons=4, max_cycles=50),
        {
            "piston_0": Constant(0),
            "piston_1": Uniform(0, 4),
            "piston_2": Uniform(1, 3),
            "piston_3": 2,
        },
    )
    obs, _ = env.reset(seed=0)
    space = env.observation_space("piston_1")
    assert space.shape == obs["piston_1"].shape and space.shape[-1] == 3  # RGB images
    assert env.histories == {
        "piston_0": 1,
        "piston_1": 5,
        "piston_2": 4,
        "piston_3": 37,
    }  # the bound + 1
    for i, agent in enumerate(env.possible_agents):
        env.action_space(agent).seed(i)
    for _ in range(40):
        obs = env.step({a: env.action_space(a).sample() for a in env.agents})[0]
        assert set(obs) == set(env.possible_agents)  # nobody left: every history is full
        assert all(space.contains(o) for o in obs.values())
    # the rule's history (private) holds at most what the delay can reach
    assert {a: len(rule._observations) for a, rule in env.rules.items()} == env.histories


def test_the_delays_come_from_each_agents_own_seeded_stream():
    long = {agent: (10_000, "terminated") for agent in "abc"}
    env = ParallelObservationDelay(ScriptedParallelEnv(long, fresh=True), Poisson(4))

    def ages(seed):
        env.reset(seed=seed)
        seen = {agent: [] for agent in long}
        for _ in range(100):
            for agent, info in env.step(dict.fromkeys(env.agents, 0))[-1].items():
                seen[agent].append(info["observation_age"])
        return seen

    first, again, other = ages(3), ages(3), ages(4)
    assert first == again and first != other
    assert first["a"] != first["b"] != first["c"] != first["a"]


def test_an_observation_entry_that_names_no_agent_passes_undelayed():
    """PettingZoo allows extra keys (a shared ``"common"`` entry): shown as they come."""

    class Common(ScriptedParallelEnv):
        def reset(self, seed=None, options=None):
            obs, infos = super().reset(seed=seed, options=options)
            self.shared = 0
            return {**obs, "common": np.full(3, -1.0)}, infos

        def step(self, actions):
            out = super().step(actions)
            self.shared += 1
            out[0]["common"] = np.full(3, float(self.shared))
            return out

    env = ParallelObservationDelay(Common(ENDS), Poisson(5))
    plain = ParallelObservationDelay(ScriptedParallelEnv(ENDS), Poisson(5))
    obs, infos = env.reset(seed=0)
    twin, _ = plain.reset(seed=0)
    assert obs["common"].tolist() == [-1.0] * 3 and "common" not in infos
    for t in range(1, 4):
        obs, _, _, _, infos = env.step(dict.fromkeys(env.agents, 0))
        twin = plain.step(dict.fromkeys(plain.agents, 0))[0]
        assert obs["common"].tolist() == [float(t)] * 3 and "common" not in infos
        assert all(np.array_equal(obs[a], twin[a]) for a in twin)  # the agents' are delayed
