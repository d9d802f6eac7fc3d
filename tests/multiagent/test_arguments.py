"""The multi-agent wrappers' arguments: checks and messages, JSON records, the lazy import."""

from __future__ import annotations

import json
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

import delayed_rl.multiagent as multiagent
from delayed_rl.delays import Constant, Poisson, Uniform
from delayed_rl.multiagent import (
    ParallelActionDelay,
    ParallelObservationDelay,
    ParallelRewardDelay,
    agent_seed,
)

from .envs import ScriptedParallelEnv, pettingzoo_env

ENDS = {"a": (5, "terminated"), "b": (7, "truncated")}
WRAPPERS = [ParallelRewardDelay, ParallelObservationDelay, ParallelActionDelay]


def env():
    return ScriptedParallelEnv(ENDS)


@pytest.mark.parametrize("cls", WRAPPERS)
@pytest.mark.parametrize(
    ("delay", "error", "message"),
    [
        ("3", TypeError, r"delay must be a delayed_rl\.delays\.Delay .* or a mapping from agent"),
        (True, TypeError, r"delay must be .*got True \(bool\)"),
        (None, TypeError, r"delay must be .*got None"),
        (-1, ValueError, r"delay must be a number in \[0, .*\(a Poisson mean\), got -1"),
        (
            {"type": "Constant", "k": -2},
            ValueError,
            r"delay: k must be an integer in \[0, .*got -2",
        ),
        ({"type": "Nope"}, ValueError, r"delay must be a dict with a 'type' in"),
        ({"a": 1}, ValueError, r"delay must give an entry for every agent .*got none for \['b'\]"),
        ({"a": 1, "b": 1, "c": 1}, ValueError, r"delay names 'c', which is not an agent"),
        ({"a": 1, "b": "x"}, TypeError, r"delay\['b'\] must be a delayed_rl\.delays\.Delay"),
        ({"a": 1, "b": -3.0}, ValueError, r"delay\['b'\] must be a number in \[0, .*got -3\.0"),
        ({"a": 1, "b": {"type": "Uniform", "low": 3, "high": 1}}, ValueError, r"delay\['b'\]: "),
    ],
)
def test_a_bad_delay_is_refused_naming_it(cls, delay, error, message):
    with pytest.raises(error, match=message):
        cls(env(), delay)


@pytest.mark.parametrize("cls", WRAPPERS)
def test_a_bad_max_delay_is_refused_as_the_single_wrappers_refuse_it(cls):
    for value, error in (("3", TypeError), (3.0, TypeError), (True, TypeError), (-1, ValueError)):
        with pytest.raises(error, match=rf"max_delay must be None or an integer .*got {value!r}"):
            cls(env(), 1, max_delay=value)
    assert cls(env(), 1, max_delay=np.int64(4)).max_delay == 4


def test_the_options_of_each_wrapper_are_checked():
    with pytest.raises(
        TypeError, match=r"on_episode_end must be one of \('flush', 'drop', 'carry'\)"
    ):
        ParallelRewardDelay(env(), 1, on_episode_end=1)
    with pytest.raises(ValueError, match=r"on_episode_end must be one of .*got 'later'"):
        ParallelRewardDelay(env(), 1, on_episode_end="later")
    with pytest.raises(
        ValueError, match=r"arrival must be one of \('stale', 'network'\), got 'fast'"
    ):
        ParallelObservationDelay(env(), 1, arrival="fast")
    with pytest.raises(TypeError, match=r"arrival must be one of .*got None \(NoneType\)"):
        ParallelObservationDelay(env(), 1, arrival=None)


def test_initial_actions_are_checked_per_agent():
    box = {"a": spaces.Discrete(5), "b": spaces.Box(-1.0, 1.0, (2,))}
    make = lambda: ScriptedParallelEnv(ENDS, action_spaces=box)  # noqa: E731
    with pytest.raises(
        ValueError, match=r"initial_action must be an action of Discrete\(5\), got 9"
    ):
        ParallelActionDelay(make(), 1, initial_action=9)
    with pytest.raises(ValueError, match=r"initial_action\['b'\] must be an action of Box"):
        ParallelActionDelay(make(), 1, initial_action={"a": 1, "b": [2.0, 0.0]})
    with pytest.raises(ValueError, match=r"initial_action names 'c', which is not an agent"):
        ParallelActionDelay(make(), 1, initial_action={"a": 1, "b": None, "c": 0})
    with pytest.raises(ValueError, match=r"initial_action must give an entry .*none for \['b'\]"):
        ParallelActionDelay(make(), 1, initial_action={"a": 1})
    text = {"a": spaces.Discrete(5), "b": spaces.Text(5)}
    with pytest.raises(ValueError, match=r"initial_action must be given .*Text.*\(agent 'b'\)"):
        ParallelActionDelay(ScriptedParallelEnv(ENDS, action_spaces=text), 1)
    wrapper = ParallelActionDelay(make(), 1, initial_action={"a": None, "b": [0.5, 0.25]})
    assert wrapper.initial_actions["a"] == 0
    assert wrapper.initial_actions["b"].dtype == np.float32
    assert wrapper.initial_actions["b"].tolist() == [0.5, 0.25]


@pytest.mark.parametrize("cls", WRAPPERS)
def test_only_a_parallel_env_with_possible_agents_is_wrapped(cls):
    with pytest.raises(TypeError, match=r"env must be a pettingzoo\.ParallelEnv, got .*CartPole"):
        cls(gym.make("CartPole-v1"), 1)
    aec = pettingzoo_env("classic/rps-v2", "aec")
    with pytest.raises(TypeError, match=r"\(an AEC env: wrap .*aec_to_parallel\(env\)"):
        cls(aec, 1)
    nobody = ScriptedParallelEnv(ENDS)
    nobody.possible_agents = []
    with pytest.raises(ValueError, match=r"non-empty possible_agents list .*possible_agents=\[\]"):
        cls(nobody, 1)


@pytest.mark.parametrize("cls", WRAPPERS)
def test_a_bad_seed_is_refused_before_the_env_is_reset(cls):
    wrapper = cls(env(), 1)
    for seed, error in (("1", TypeError), (1.0, TypeError), (True, TypeError), (-1, ValueError)):
        with pytest.raises(error, match=rf"seed must be an integer >= 0, got {seed!r}"):
            wrapper.reset(seed=seed)
    assert wrapper.env.episode == -1  # never reset


def test_agent_seed_is_checked_and_separates_agents_and_seeds():
    seeds = {agent_seed(seed, index) for seed in range(20) for index in range(20)}
    assert len(seeds) == 400 and all(0 <= s < 2**128 for s in seeds)
    with pytest.raises(TypeError, match="seed must be an integer >= 0, got '1'"):
        agent_seed("1", 0)
    with pytest.raises(ValueError, match="index must be an integer >= 0, got -1"):
        agent_seed(0, -1)


@pytest.mark.parametrize(
    ("cls", "kwargs"),
    [
        (ParallelRewardDelay, {"delay": {"a": Uniform(0, 3), "b": 2.5}, "on_episode_end": "drop"}),
        (ParallelObservationDelay, {"delay": Poisson(2), "max_delay": np.int64(5)}),
        (ParallelObservationDelay, {"delay": {"type": "Constant", "k": 1}, "arrival": "network"}),
        (
            ParallelActionDelay,
            {"delay": {"a": 1, "b": Constant(2)}, "initial_action": {"a": 3, "b": np.int64(1)}},
        ),
    ],
)
def test_the_constructor_records_are_json_and_rebuild_the_same_wrapper(cls, kwargs):
    wrapper = cls(ScriptedParallelEnv(ENDS, fresh=True), **kwargs)
    text = json.dumps(wrapper._saved_kwargs)
    rebuilt = cls(ScriptedParallelEnv(ENDS, fresh=True), **json.loads(text))
    assert rebuilt.delays == wrapper.delays

    def run(w):
        out = [w.reset(seed=3)]
        while w.agents:
            out.append(w.step(dict.fromkeys(w.agents, 1)))
        return out

    np.testing.assert_equal(run(wrapper), run(rebuilt))  # np.int64(1) read back as 1


def test_importing_the_package_imports_no_pettingzoo_and_a_missing_one_names_the_extra(
    monkeypatch,
):
    assert (
        multiagent.__all__ == sorted(multiagent.__all__) and dir(multiagent) == multiagent.__all__
    )
    with pytest.raises(AttributeError, match="has no attribute 'Nope'"):
        multiagent.Nope  # noqa: B018
    monkeypatch.setitem(sys.modules, "pettingzoo", None)  # what a missing package looks like
    for name in ("delayed_rl.multiagent.reward_delay", "delayed_rl.multiagent._base"):
        monkeypatch.delitem(sys.modules, name)
    with pytest.raises(
        ImportError, match=r"needs PettingZoo.*pip install \"delayed-rl\[multiagent\]\""
    ):
        multiagent.__getattr__("ParallelRewardDelay")
    assert multiagent.__getattr__("agent_seed") is agent_seed  # needs no PettingZoo
