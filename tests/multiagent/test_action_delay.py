"""ParallelActionDelay: ActionDelay's rule per agent, actions discarded when an agent leaves."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from delayed_rl.delays import Constant, Poisson, Uniform
from delayed_rl.multiagent import ParallelActionDelay, agent_seed
from delayed_rl.wrappers import ActionDelay

from .envs import ScriptedParallelEnv

ENDS = {
    "a": (4, "terminated"),
    "b": (9, "truncated"),
    "c": (13, "terminated"),
    "d": (11, "terminated"),
}
JOINS = {"d": 3}
SPACES = {
    "a": spaces.Discrete(5),
    "b": spaces.Box(-1.0, 1.0, (2,), np.float32),
    "c": spaces.MultiDiscrete([3, 4]),
    "d": spaces.Discrete(5, start=1),
}
DELAYS = {"a": Constant(2), "b": Uniform(0, 3), "c": Poisson(1.5), "d": Constant(1)}
INITIAL = {"a": 4, "b": [0.5, -0.5], "c": None, "d": 2}


class ActionRecorder(gym.Env):
    """A single-agent env that only records the actions it executes."""

    observation_space = spaces.Discrete(1)

    def __init__(self, action_space):
        self.action_space = action_space
        self.received = []

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return 0, {}

    def step(self, action):
        self.received.append(action)
        return 0, 0.0, False, False, {}


def _equal(a, b):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def _pairs_equal(got, want):
    assert [step for step, _ in got] == [step for step, _ in want]
    for (_, a), (_, b) in zip(got, want, strict=True):
        _equal(a, b)


@pytest.mark.parametrize("seed", [0, 5])
def test_every_executed_action_is_a_single_agent_action_delays_step_by_step(seed):
    """Four agents of four action spaces, leaving at different steps, one joining late."""
    env = ParallelActionDelay(
        ScriptedParallelEnv(ENDS, JOINS, action_spaces=SPACES), DELAYS, initial_action=INITIAL
    )
    refs = {
        agent: ActionDelay(ActionRecorder(SPACES[agent]), DELAYS[agent], INITIAL[agent])
        for agent in ENDS
    }
    senders = {agent: SPACES[agent] for agent in ENDS}
    for i, space in enumerate(senders.values()):
        space.seed(100 + i)
    sent = discarded = 0
    for episode, cut in enumerate([None, 5, None]):
        _, infos = env.reset(seed=seed if episode == 0 else None)
        for i, agent in enumerate(ENDS):
            if agent in infos and refs[agent].line.in_transit:  # the cut episode's
                _pairs_equal(infos[agent]["discarded_actions"], refs[agent].line.remaining())
            refs[agent].reset(seed=agent_seed(seed, i) if episode == 0 else None)
        taken = 0
        while env.agents and (cut is None or taken < cut):
            actions = {agent: senders[agent].sample() for agent in env.agents}
            _, _, terminated, truncated, infos = env.step(actions)
            taken += 1
            given = env.env.received[-1]
            assert set(given) == set(actions)
            for agent, action in actions.items():
                ref_info = refs[agent].step(action)[-1]
                _equal(given[agent], refs[agent].env.received[-1])
                for key in ("executed_action", "executed_action_step", "drawn_action_delay"):
                    _equal(infos[agent][key], ref_info[key])
                sent += 1
            for agent in infos:
                if terminated[agent] or truncated[agent]:
                    _pairs_equal(infos[agent]["discarded_actions"], refs[agent].line.remaining())
                    discarded += len(infos[agent]["discarded_actions"])
                    refs[agent].reset()  # its line restarts, as the wrapper's does
                else:
                    assert "discarded_actions" not in infos[agent]
    assert sent > 60 and discarded > 3


def test_the_actions_in_transit_when_an_agent_leaves_are_reported_in_its_last_info():
    """Constant(3): "a" leaves at its 4th step with its last 3 actions still in transit."""
    env = ParallelActionDelay(ScriptedParallelEnv(ENDS, JOINS), Constant(3))
    env.reset(seed=0)
    for t in range(4):
        infos = env.step({agent: (t + 1) % 5 for agent in env.agents})[-1]
    assert "a" not in env.agents
    assert infos["a"]["discarded_actions"] == ((1, 2), (2, 3), (3, 4))
    assert infos["a"]["executed_action"] == 1 and infos["a"]["executed_action_step"] == 0
    assert "discarded_actions" not in infos["b"]
    assert env.lines["a"].in_transit == 0 and env.lines["b"].in_transit == 3


def test_a_reset_discards_the_live_agents_actions_in_transit_and_reports_them():
    env = ParallelActionDelay(ScriptedParallelEnv(ENDS, JOINS), Constant(3))
    env.reset(seed=0)
    env.step({agent: 1 for agent in env.agents})
    env.step({agent: 2 for agent in env.agents})
    _, infos = env.reset()
    assert {agent: info["discarded_actions"] for agent, info in infos.items()} == {
        agent: ((0, 1), (1, 2)) for agent in "abc"
    }
    assert all(line.in_transit == 0 for line in env.lines.values())
    infos = env.step({agent: 3 for agent in env.agents})[-1]
    assert [infos[a]["executed_action"] for a in "abc"] == [0, 0, 0]  # neutral: nothing arrived


def test_an_agent_that_joins_starts_with_an_empty_line():
    env = ParallelActionDelay(ScriptedParallelEnv(ENDS, JOINS), Constant(2), initial_action=3)
    env.reset(seed=0)
    executed = []
    for t in range(1, 9):
        infos = env.step({agent: t % 5 for agent in env.agents})[-1]
        if "d" in infos and "executed_action" in infos["d"]:
            executed.append(infos["d"]["executed_action"])
    # "d" joins at step 3 (no action that step); it sends 4, 0, 1, 2, 3 at steps 4 to 8
    assert executed == [3, 3, 4, 0, 1]


def test_actions_are_copied_where_they_come_in_and_where_they_go_out():
    class Editing(ScriptedParallelEnv):
        def step(self, actions):
            for action in actions.values():
                action[:] = 0.0  # an env that edits its actions in place
            return super().step(actions)

    box = {agent: spaces.Box(-1.0, 1.0, (2,), np.float32) for agent in ENDS}
    env = ParallelActionDelay(Editing(ENDS, action_spaces=box), Constant(1))
    env.reset(seed=0)
    mine = np.array([0.5, 0.5], np.float32)
    infos = env.step(dict.fromkeys(env.agents, mine))[-1]
    mine[:] = -1.0
    infos["a"]["executed_action"][:] = 0.25
    infos = env.step({agent: np.zeros(2, np.float32) for agent in env.agents})[-1]
    _equal(infos["a"]["executed_action"], [0.5, 0.5])  # what was sent at step 0


def test_initial_actions_per_agent_and_for_dict_action_spaces():
    dict_space = spaces.Dict({"move": spaces.Discrete(3), "speed": spaces.Box(0.0, 1.0, (1,))})
    both = {agent: dict_space for agent in ENDS}
    env = ParallelActionDelay(
        ScriptedParallelEnv(ENDS, action_spaces=both),
        Constant(1),
        initial_action={"move": 2, "speed": [0.5]},  # one Dict action for every agent
    )
    assert all(action["move"] == 2 for action in env.initial_actions.values())
    per_agent = {agent: {"move": i % 3, "speed": [0.1]} for i, agent in enumerate(ENDS)}
    env = ParallelActionDelay(
        ScriptedParallelEnv(ENDS, action_spaces=both), Constant(1), initial_action=per_agent
    )
    assert [env.initial_actions[a]["move"] for a in ENDS] == [0, 1, 2, 0]
    env = ParallelActionDelay(ScriptedParallelEnv(ENDS, action_spaces=SPACES), Constant(1))
    assert env.initial_actions["d"] == 1 and env.initial_actions["c"].tolist() == [0, 0]


def test_an_action_outside_its_agents_space_or_for_an_unknown_agent_is_refused():
    env = ParallelActionDelay(ScriptedParallelEnv(ENDS), Constant(1))
    env.reset(seed=0)
    with pytest.raises(
        ValueError, match=r"actions\['b'\] must be an action of Discrete\(5\), got 7"
    ):
        env.step({"a": 1, "b": 7, "c": 0, "d": 0})
    with pytest.raises(ValueError, match="actions names agent 'zed'"):
        env.step({"a": 1, "zed": 0})
    # a refused step sent nothing: "a" executes its first action one step after sending it
    executed = [env.step(dict.fromkeys(env.agents, k))[-1]["a"]["executed_action"] for k in (3, 4)]
    assert executed == [0, 3]
