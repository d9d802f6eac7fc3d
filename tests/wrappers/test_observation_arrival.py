"""ObservationDelay's two arrival rules, and what both report in ``info["arrived_observations"]``.

``"stale"``: step t shows o_{t+1-d_t}. ``"network"``: o_i arrives at index i + d_i, and step t
shows the newest arrived by t + 1. The stale rule's own tests are in test_observation_delay.py.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import ScriptedDelay, examples, same, scribble

from delayed_rl.delays import Constant, Geometric, Poisson, Uniform
from delayed_rl.wrappers import ObservationDelay
from delayed_rl.wrappers._delay_draws import delay_rng
from delayed_rl.wrappers.observation_delay import ARRIVAL_RULES, NetworkArrival


class Counter(gym.Env):
    """Observation ``o_i = i`` (the steps taken this episode); ends after ``length`` steps."""

    observation_space = gym.spaces.Discrete(10**6)
    action_space = gym.spaces.Discrete(1)

    def __init__(self, length: int | None = None):
        self.length = length

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return 0, {}

    def step(self, action):
        self.t += 1
        return self.t, 0.0, self.t == self.length, False, {}


def network_reference(delays: list[int], steps: int) -> list[tuple[tuple[int, ...], int]]:
    """The network rule by brute force: ``(indices arriving, index shown)`` at each step.

    ``delays[i - 1]`` is ``d_i``, drawn when ``o_i`` is made (step ``i − 1``).
    """
    out = []
    for t in range(steps):
        arrived = [i for i in range(1, t + 2) if i + delays[i - 1] <= t + 1]
        now = tuple(i for i in arrived if i + delays[i - 1] == t + 1)
        out.append((now, max(arrived, default=0)))
    return out


def run(env: gym.Env, steps: int, seed: int | None = 0) -> list[tuple]:
    """``(observation, info["observation_age"], arrived indices)`` of each step after a reset."""
    env.reset(seed=seed)
    rows = []
    for _ in range(steps):
        obs, *_, info = env.step(0)
        rows.append((obs, info["observation_age"], [i for i, _ in info["arrived_observations"]]))
    return rows


@pytest.mark.parametrize(
    ("delay", "max_delay"), [(Poisson(3.0), None), (Poisson(9.0), 4), (Uniform(0, 7), None)]
)
def test_every_observation_arrives_at_its_index_plus_its_delay(delay, max_delay) -> None:
    seed, steps = 5, 300
    delays = delay.sample(delay_rng(seed, "observation"), 1024)  # the wrapper's stream
    if max_delay is not None:
        delays = np.minimum(delays, max_delay)
    env = ObservationDelay(Counter(), delay, max_delay=max_delay, arrival="network")
    obs, info = env.reset(seed=seed)
    assert (obs, info["observation_age"], info["arrived_observations"]) == (0, 0, ((0, 0),))
    for t, (now, shown) in enumerate(network_reference(delays.tolist(), steps)):
        obs, *_, info = env.step(0)
        assert tuple(i for i, _ in info["arrived_observations"]) == now, t
        assert all(i == o for i, o in info["arrived_observations"])  # o_i is i
        assert obs == shown and info["observation_age"] == t + 1 - shown, t
    overtaken = sum(len(now) > 1 for now, _ in network_reference(delays.tolist(), steps))
    assert overtaken > 0  # several observations arrived at once, older ones among them


@settings(max_examples=examples(100), deadline=None)
@given(st.lists(st.integers(0, 12), min_size=1, max_size=60))
def test_scripted_delays_follow_the_network_rule(delays: list[int]) -> None:
    env = ObservationDelay(Counter(), ScriptedDelay(delays), arrival="network")
    got = run(env, len(delays), seed=None)
    expected = network_reference(delays, len(delays))
    assert [(list(now), shown) for now, shown in expected] == [(r[2], r[0]) for r in got]
    assert [t + 1 - shown for t, (_, shown) in enumerate(expected)] == [r[1] for r in got]


@settings(max_examples=examples(100), deadline=None)
@given(st.lists(st.integers(0, 12), min_size=1, max_size=60))
def test_the_stale_rule_receives_the_one_it_shows(delays: list[int]) -> None:
    env = ObservationDelay(Counter(), ScriptedDelay(delays))  # "stale", the default
    for t, (obs, age, arrived) in enumerate(run(env, len(delays), seed=None)):
        assert obs == max(0, t + 1 - delays[t]) and age == t + 1 - obs
        assert arrived == [obs]


@pytest.mark.parametrize("k", [0, 1, 3])
def test_a_constant_delay_shows_the_same_observations_under_both_rules(k: int) -> None:
    stale, network = (
        run(ObservationDelay(Counter(), Constant(k), arrival=rule), 20) for rule in ARRIVAL_RULES
    )
    assert [r[:2] for r in stale] == [r[:2] for r in network]
    assert [r[0] for r in network] == [max(0, t + 1 - k) for t in range(20)]
    assert [r[2] for r in network] == [[] if t + 1 < k + 1 else [t + 1 - k] for t in range(20)]


def test_the_stale_rule_is_the_default_and_draws_the_same_delays() -> None:
    default = run(ObservationDelay(Counter(), Poisson(4.0)), 200, seed=3)
    assert default == run(ObservationDelay(Counter(), Poisson(4.0), arrival="stale"), 200, seed=3)
    network = run(ObservationDelay(Counter(), Poisson(4.0), arrival="network"), 200, seed=3)
    assert default != network


@pytest.mark.parametrize("rule", ARRIVAL_RULES)
def test_the_same_seed_gives_the_same_observations(rule: str) -> None:
    env = ObservationDelay(Counter(), Geometric(0.3), arrival=rule)
    assert run(env, 200, seed=8) == run(env, 200, seed=8)
    assert run(env, 200, seed=8) != run(env, 200, seed=9)


def test_observations_in_transit_are_discarded_at_reset() -> None:
    env = ObservationDelay(Counter(length=5), Constant(4), arrival="network")
    assert run(env, 5)[-1][:2] == (1, 4)  # o_2..o_5 still in transit when the episode ends
    obs, info = env.reset()
    assert (obs, info["arrived_observations"]) == (0, ((0, 0),))
    assert [r[2] for r in run(env, 5, seed=None)] == [[], [], [], [], [1]]


def test_memory_follows_what_is_in_transit() -> None:
    rule = NetworkArrival()
    rule.reset(0)
    rng = np.random.default_rng(1)
    most = 0
    for i in range(1, 20_000):
        rule.receive(i, int(rng.integers(0, 1000)))
        most = max(most, rule.in_transit)
    assert most <= 1000  # never more than one a step of the longest transit


@pytest.mark.parametrize("rule", ARRIVAL_RULES)
def test_observations_reported_are_copies(rule: str) -> None:
    env = ObservationDelay(gym.make("Pendulum-v1"), Uniform(0, 3), arrival=rule)
    obs, info = env.reset(seed=0)
    kept = {}  # o_i as first reported
    for t in range(40):
        for i, arrived in info["arrived_observations"]:
            assert arrived is not obs
            np.testing.assert_array_equal(arrived, kept.setdefault(i, arrived.copy()))
        np.testing.assert_array_equal(obs, kept[t - info["observation_age"]])
        for _, arrived in info["arrived_observations"]:
            scribble(arrived)  # the caller writes into what info reports
        scribble(obs)  # and into the observation returned
        obs, *_, info = env.step(np.zeros(1, np.float32))
    assert len(kept) > 20


def test_check_env_passes_under_the_network_rule() -> None:
    from gymnasium.utils.env_checker import check_env

    env = ObservationDelay(gym.make("CartPole-v1"), Uniform(0, 3), arrival="network")
    check_env(env, skip_render_check=True)


def test_the_rule_round_trips_through_the_spec() -> None:
    env = gym.make(
        "delayed_rl/GridWorld-5x5-v0",
        max_steps=30,
        observation_delay=Uniform(0, 4),
        observation_arrival="network",
    )
    spec = gym.envs.registration.EnvSpec.from_json(env.spec.to_json())
    rebuilt = gym.make(spec)
    assert rebuilt.get_wrapper_attr("arrival") == "network"

    def trajectory(env):
        env.reset(seed=2)
        env.action_space.seed(2)
        return [
            (obs, info["observation_age"], info["arrived_observations"])
            for obs, *_, info in (env.step(env.action_space.sample()) for _ in range(100))
        ]

    assert same(tuple(trajectory(env)), tuple(trajectory(rebuilt)))
    by_hand = ObservationDelay(gym.make("CartPole-v1"), Constant(2), arrival="network")
    assert gym.make(by_hand.spec).get_wrapper_attr("arrival") == "network"


@pytest.mark.parametrize(
    ("arrival", "exc"), [("fast", ValueError), ("", ValueError), (1, TypeError), (None, TypeError)]
)
def test_a_bad_arrival_rule_is_refused_naming_the_argument(arrival, exc) -> None:
    with pytest.raises(exc, match=r"^arrival must be one of \('stale', 'network'\), got"):
        ObservationDelay(Counter(), 2, arrival=arrival)
    with pytest.raises(exc, match=r"^observation_arrival must be one of"):
        gym.make("delayed_rl/GridWorld-3x3-v0", observation_delay=2, observation_arrival=arrival)


def test_a_stacks_observation_and_action_delays_are_independent():
    from delayed_rl.wrappers import ActionDelay

    # the same distribution on both signals, one seed for the stack: two streams, not one
    delay, steps = Uniform(0, 3), 1000
    env = ObservationDelay(ActionDelay(gym.make("Pendulum-v1"), delay), delay)
    env.reset(seed=1)
    acted = [
        env.step(np.zeros(1, dtype=np.float32))[-1]["drawn_action_delay"] for _ in range(steps)
    ]
    assert acted == delay.sample(delay_rng(1, "action"), steps).tolist()
    observed = delay.sample(delay_rng(1, "observation"), steps)
    # independent streams: their correlation is within 4 standard errors of 0
    assert abs(np.corrcoef(np.asarray(acted), observed)[0, 1]) < 4 / np.sqrt(steps)
