"""DelayAwareObservation and DiscreteDelayAwareObservation: what the agent can know, and no more.

The view is compared with a plain reference (:func:`reference_run`) that recomputes it from what
a twin of the stack reports (its observations and ``info["arrived_observations"]``) and the
actions sent, on random delay stacks, over ``Discrete`` and ``Box`` spaces, under both arrival
rules.
"""

from __future__ import annotations

import copy
import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st
from support import ScriptedDelay, examples, layers, same, scribble

from delayed_rl.delays import Constant, Geometric, Poisson, Uniform
from delayed_rl.wrappers import (
    ActionDelay,
    DelayAwareObservation,
    DiscreteDelayAwareObservation,
    ObservationDelay,
    wrap_delays,
)
from delayed_rl.wrappers.action_delay import neutral_action
from delayed_rl.wrappers.delay_aware import MAX_ACTION_HISTORY, MAX_DISCRETE_STATES
from delayed_rl.wrappers.observation_delay import ARRIVAL_RULES

N = 11  # the discrete walk's observations


class Walk(gym.Env):
    """Observations that show the step and every action executed; ends after ``length`` steps.

    ``"discrete"``: ``Discrete(N)`` observations ``(3·t + Σ executed actions) mod N`` and
    ``Discrete(3)`` actions. ``"box"``: observations ``[t, Σ executed actions]`` (unbounded) and
    ``Box(-1, 1, (1,))`` actions. ``altered``: the step whose observation is reported changed
    (``+1`` modulo ``N``, or ``+1000``) without changing the walk.
    """

    def __init__(self, kind: str = "discrete", length: int = 25, altered: int | None = None):
        self.kind, self.length, self.altered = kind, length, altered
        if kind == "discrete":
            self.observation_space, self.action_space = spaces.Discrete(N), spaces.Discrete(3)
        else:
            self.observation_space = spaces.Box(-np.inf, np.inf, (2,), dtype=np.float64)
            self.action_space = spaces.Box(-1.0, 1.0, (1,), dtype=np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t, self.total = 0, 0.0
        return self._observation(), {}

    def step(self, action):
        self.t += 1
        self.total += float(np.sum(action))
        return self._observation(), 1.0, self.t == self.length, False, {"t": self.t}

    def _observation(self):
        shift = self.t == self.altered
        if self.kind == "discrete":
            return (3 * self.t + int(self.total) + shift) % N
        return np.array([self.t, self.total + 1000.0 * shift])


INITIAL = {"discrete": 2, "box": np.array([0.5], dtype=np.float32)}


def stack(kind, observation=None, action=None, rule="stale", altered=None, length=25):
    """A Walk under an ActionDelay and an ObservationDelay, each ``(delay, max_delay)`` or None."""
    env = Walk(kind, length, altered)
    if action is not None:
        env = ActionDelay(env, action[0], initial_action=INITIAL[kind], max_delay=action[1])
    if observation is not None:
        env = ObservationDelay(env, observation[0], max_delay=observation[1], arrival=rule)
    return env


def bound(pair) -> int | None:
    """The longest delay of ``(delay, max_delay)`` (0 for None, None if unbounded)."""
    if pair is None:
        return 0
    limits = [b for b in (pair[0].support_max, pair[1]) if b is not None]
    return min(limits, default=None)


def actions_for(kind: str, seed: int, n: int) -> list:
    """``n`` random actions of the walk's action space."""
    space = Walk(kind).action_space
    space.seed(seed)
    return [space.sample() for _ in range(n)]


def reference_run(bare, actions, seed, initial, k, max_age):
    """What the class docstring says, from ``bare`` (a twin of the stack) and the actions sent.

    Returns, for the reset and each step: the expected view, the observations received, and
    whether the age was clipped. An episode that ends is followed by a reset.
    """

    def view(t, newest, sent):
        history = [sent[t - 1 - j] if t - 1 - j >= 0 else initial for j in range(k)]
        age = t - newest[0]
        return {"actions": np.array(history), "age": min(age, max_age), "observation": newest[1]}

    out, t, sent = [], 0, []
    obs, info = bare.reset(seed=seed)
    newest = (0, obs)
    out.append((view(0, newest, sent), info.get("arrived_observations", ((0, obs),)), False))
    for action in actions:
        obs, _, terminated, truncated, info = bare.step(action)
        t += 1
        sent.append(action)
        received = info.get("arrived_observations", ((t, obs),))
        for i, o in received:
            if i > newest[0]:
                newest = (i, o)
        out.append((view(t, newest, sent), received, t - newest[0] > max_age))
        if terminated or truncated:
            obs, info = bare.reset()
            t, sent, newest = 0, [], (0, obs)
            out.append((view(0, newest, sent), ((0, obs),), False))
    return out


def view_run(env, actions, seed):
    """The view's ``(observation, arrived_observations, age_clipped)`` at the reset and each step."""
    obs, info = env.reset(seed=seed)
    out = [(obs, info["arrived_observations"], info["age_clipped"])]
    for action in actions:
        obs, _, terminated, truncated, info = env.step(action)
        assert env.observation_space.contains(obs)
        out.append((obs, info["arrived_observations"], info["age_clipped"]))
        if terminated or truncated:
            obs, info = env.reset()
            out.append((obs, info["arrived_observations"], info["age_clipped"]))
    return out


BOUNDED = st.one_of(
    st.builds(lambda k: (Constant(k), None), st.integers(0, 4)),
    st.builds(
        lambda low, span: (Uniform(low, low + span), None), st.integers(0, 3), st.integers(0, 4)
    ),
    st.builds(lambda lam, top: (Poisson(lam), top), st.floats(0.5, 6.0), st.integers(0, 6)),
    st.builds(lambda p, top: (Geometric(p), top), st.floats(0.2, 1.0), st.integers(0, 5)),
)
DELAY_OR_NONE = st.one_of(st.none(), BOUNDED)


@settings(max_examples=examples(200), deadline=None)
@given(
    kind=st.sampled_from(["discrete", "box"]),
    observation=DELAY_OR_NONE,
    action=DELAY_OR_NONE,
    rule=st.sampled_from(ARRIVAL_RULES),
    seed=st.integers(0, 2**16),
)
def test_the_view_is_the_reference_on_random_stacks(kind, observation, action, rule, seed) -> None:
    k = max(bound(observation) + bound(action), 1)
    env = DelayAwareObservation(stack(kind, observation, action, rule))
    assert (env.action_history, env.max_age) == (k, bound(observation))
    initial = INITIAL[kind] if action is not None else neutral_action(Walk(kind).action_space)
    actions = actions_for(kind, seed, 60)
    got = view_run(env, actions, seed)
    expected = reference_run(
        stack(kind, observation, action, rule), actions, seed, initial, k, bound(observation)
    )
    assert len(got) == len(expected) > 60  # an episode ended: a reset on the way
    for step, (view, want) in enumerate(zip(got, expected, strict=True)):
        assert same(view[0], want[0]), step
        assert same(view[1], want[1]) and view[2] is want[2] is False, step


@pytest.mark.parametrize("rule", ARRIVAL_RULES)
@pytest.mark.parametrize("kind", ["discrete", "box"])
def test_an_unbounded_delay_observes_action_history_actions_and_clips_ages(kind, rule) -> None:
    observation, action = (Poisson(3.0), None), (Geometric(0.3), None)
    env = DelayAwareObservation(stack(kind, observation, action, rule), action_history=2)
    assert (env.action_history, env.max_age) == (2, 2)
    assert env.observation_space["age"] == spaces.Discrete(3)
    actions = actions_for(kind, 1, 200)
    got = view_run(env, actions, 4)
    expected = reference_run(
        stack(kind, observation, action, rule), actions, 4, INITIAL[kind], 2, 2
    )
    assert all(same(g, w) for g, w in zip(got, expected, strict=True))
    assert sum(g[2] for g in got) > 10  # ages beyond 2 happened, clipped and said so


@settings(max_examples=examples(200), deadline=None)
@given(
    kind=st.sampled_from(["discrete", "box"]),
    observation=BOUNDED,
    action=DELAY_OR_NONE,
    rule=st.sampled_from(ARRIVAL_RULES),
    seed=st.integers(0, 2**16),
    altered=st.integers(1, 20),
)
def test_an_observation_not_yet_received_changes_nothing(
    kind, observation, action, rule, seed, altered
) -> None:
    actions = actions_for(kind, seed, 24)  # one episode: the walk lasts 25 steps
    runs = []
    for change in (None, altered):
        env = DelayAwareObservation(stack(kind, observation, action, rule, altered=change))
        obs, info = env.reset(seed=seed)
        run = [(obs, info["arrived_observations"])]
        run += [(s[0], s[1], s[-1]["arrived_observations"]) for s in map(env.step, actions)]
        runs.append(run)
    arrival = next(
        (t for t, row in enumerate(runs[1]) if any(i == altered for i, _ in row[-1])), None
    )
    before = len(runs[0]) if arrival is None else arrival
    assert same(tuple(runs[0][:before]), tuple(runs[1][:before]))
    if arrival is not None:  # received at last: it shows (rows: the reset, then each step)
        assert arrival >= altered and not same(runs[0][arrival][-1], runs[1][arrival][-1])


def test_an_older_observation_received_later_does_not_replace_the_view() -> None:
    env = DelayAwareObservation(
        ObservationDelay(Walk(), ScriptedDelay([0, 2, 0, 3, 1]), max_delay=3)
    )
    env.reset(seed=0)
    steps = [env.step(0) for _ in range(5)]  # the stale rule shows o1, o0, o3, o1, o4
    received = [[i for i, _ in s[-1]["arrived_observations"]] for s in steps]
    assert received == [[1], [0], [3], [1], [4]]
    made = {i: o for s in steps for i, o in s[-1]["arrived_observations"]}
    assert [s[0]["observation"] for s in steps] == [made[i] for i in (1, 1, 3, 3, 4)]
    assert [int(s[0]["age"]) for s in steps] == [0, 1, 0, 1, 1]
    assert [s[-1]["observation_age"] for s in steps] == [0, 2, 0, 3, 1]  # the stack's own


@pytest.mark.parametrize(
    ("observation", "action", "history", "k", "age_bound"),
    [
        (None, None, None, 1, 0),
        ((Constant(0), None), (Constant(0), None), None, 1, 0),
        ((Constant(3), None), None, None, 3, 3),
        (None, (Uniform(1, 4), None), None, 4, 0),
        ((Uniform(0, 9), None), (Constant(2), None), None, 11, 9),
        ((Uniform(0, 9), 2), (Poisson(5.0), 3), None, 5, 2),  # the smaller of the two bounds
        ((Uniform(0, 9), None), (Uniform(0, 9), None), 4, 4, 9),
        ((Poisson(2.0), None), None, 6, 6, 6),  # unbounded: the ages' bound is action_history
    ],
)
def test_the_number_of_actions_and_the_age_bound(observation, action, history, k, age_bound):
    view = DelayAwareObservation(stack("discrete", observation, action), action_history=history)
    assert (view.action_history, view.max_age) == (k, age_bound)
    assert view.observation_space["actions"] == spaces.MultiDiscrete([3] * k)
    assert view.observation_space["age"] == spaces.Discrete(age_bound + 1)
    assert view.observation_space["observation"] == Walk().observation_space


@pytest.mark.parametrize(
    ("space", "actions_space"),
    [
        (spaces.Discrete(4, start=-1), spaces.MultiDiscrete([4, 4, 4], start=[-1, -1, -1])),
        (
            spaces.Box(np.float32([-1.0, 0.0]), np.float32([1.0, 2.0])),
            spaces.Box(np.float32([[-1.0, 0.0]] * 3), np.float32([[1.0, 2.0]] * 3)),
        ),
        (
            spaces.MultiDiscrete([2, 5], start=[0, 1]),
            spaces.MultiDiscrete([[2, 5]] * 3, start=[[0, 1]] * 3),
        ),
        (spaces.MultiBinary(2), spaces.MultiBinary([3, 2])),
    ],
    ids=["discrete", "box", "multi-discrete", "multi-binary"],
)
def test_every_action_space_is_stacked_and_check_env_passes(space, actions_space) -> None:
    env = DelayAwareObservation(ActionDelay(Sensor(space), Uniform(0, 3)))
    assert env.observation_space["actions"] == actions_space
    view, _ = env.reset(seed=0)
    neutral = np.broadcast_to(neutral_action(space), (3, *space.shape))
    np.testing.assert_array_equal(view["actions"], neutral)
    space.seed(0)
    sent = [space.sample() for _ in range(3)]
    for action in sent:
        view = env.step(action)[0]
    np.testing.assert_array_equal(view["actions"], np.array(sent[::-1]))
    check_env(env, skip_render_check=True)


class Sensor(gym.Env):
    """Random ``Box`` observations, any action space; never ends."""

    observation_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)

    def __init__(self, action_space: gym.Space):
        self.action_space = action_space

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self._observation(), {}

    def step(self, action):
        return self._observation(), 0.0, False, False, {}

    def _observation(self):
        return self.np_random.uniform(-1, 1, 2).astype(np.float32)


class DiscreteSensor(Sensor):
    """Random ``Discrete(4)`` observations, any action space; never ends."""

    observation_space = spaces.Discrete(4)

    def _observation(self):
        return int(self.np_random.integers(4))


def test_the_rows_before_the_first_action_hold_the_initial_action() -> None:
    env = DelayAwareObservation(ActionDelay(Walk(), Constant(2), initial_action=1))
    view, _ = env.reset(seed=0)
    assert view["actions"].tolist() == [1, 1]
    assert env.step(0)[0]["actions"].tolist() == [0, 1]
    assert env.step(2)[0]["actions"].tolist() == [2, 0]
    assert env.reset()[0]["actions"].tolist() == [1, 1]  # a new episode starts over
    no_delay = DelayAwareObservation(Sensor(spaces.Discrete(3, start=5)))
    assert no_delay.reset(seed=0)[0]["actions"].tolist() == [5]  # the neutral action


def test_without_an_observation_delay_every_observation_is_received_at_once() -> None:
    env = DelayAwareObservation(ActionDelay(Walk(), Constant(1)))
    obs, info = env.reset(seed=0)
    assert info["arrived_observations"] == ((0, obs["observation"]),)
    for t in range(1, 6):
        obs, *_, info = env.step(1)
        assert info["arrived_observations"] == ((t, obs["observation"]),)
        assert obs["age"] == 0 and "observation_age" not in info and info["t"] == t


@pytest.mark.parametrize("rule", ARRIVAL_RULES)
def test_everything_handed_out_is_a_copy(rule: str) -> None:
    def run(scribbling: bool):
        env = DelayAwareObservation(stack("box", (Uniform(0, 3), None), (Constant(1), None), rule))
        obs, info = env.reset(seed=3)
        out = [copy.deepcopy((obs, info["arrived_observations"]))]
        for action in actions_for("box", 3, 20):
            if scribbling:
                scribble(obs)  # the caller writes into the view returned
                scribble(info["arrived_observations"])  # and into what info reports
            obs, *_, info = env.step(action)
            if scribbling:
                scribble(action)  # and reuses its action array
            out.append(copy.deepcopy((obs, info["arrived_observations"])))
        return out

    assert same(tuple(run(False)), tuple(run(True)))


@pytest.mark.parametrize("rule", ARRIVAL_RULES)
def test_the_same_seed_gives_the_same_views(rule: str) -> None:
    env = DelayAwareObservation(
        stack("box", (Poisson(2.0), 5), (Geometric(0.5), 4), rule, length=1000)
    )
    actions = actions_for("box", 0, 100)
    first, again = view_run(env, actions, 7), view_run(env, actions, 7)
    assert same(tuple(first), tuple(again))
    assert not same(tuple(first), tuple(view_run(env, actions, 8)))


def test_check_env_passes_for_every_rule_and_space() -> None:
    for rule in ARRIVAL_RULES:
        for kind in ("discrete", "box"):
            env = stack(kind, (Uniform(0, 3), None), (Constant(1), None), rule, length=1000)
            check_env(DelayAwareObservation(env), skip_render_check=True)


def test_flatten_observation_gives_one_box() -> None:
    env = DelayAwareObservation(
        wrap_delays(
            gym.make("CartPole-v1"), observation_delay=Uniform(0, 2), action_delay=Constant(0)
        )
    )
    flat = gym.wrappers.FlattenObservation(env)
    assert isinstance(flat.observation_space, spaces.Box)
    assert flat.observation_space.shape == (2 * 2 + 3 + 4,)  # one-hot actions and age
    obs, _ = flat.reset(seed=0)
    for _ in range(5):
        assert flat.observation_space.contains(obs)
        obs = flat.step(1)[0]


# --------------------------------------------------------------------------- gym.make, specs
def trajectory(env: gym.Env, seed: int, n: int = 100) -> tuple:
    """The observations, rewards and received observations of ``n`` seeded random steps."""
    obs, info = env.reset(seed=seed)
    env.action_space.seed(seed)
    rows = [(obs, info["arrived_observations"])]
    for _ in range(n):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        rows.append((obs, reward, info["arrived_observations"]))
        if terminated or truncated:
            rows.append(env.reset()[0])
    return tuple(rows)


MAKE = {
    "max_steps": 30,
    "action_delay": Uniform(0, 2),
    "observation_delay": Constant(1),
    "observation_arrival": "network",
    "reward_delay": 2,
}


def test_gym_make_builds_the_view_inside_the_reward_delay() -> None:
    env = gym.make("delayed_rl/GridWorld-5x5-v0", **MAKE, delay_aware=True)
    assert layers(env) == [
        "PoissonRewardDelay",
        "DelayAwareObservation",
        "ObservationDelay",
        "ActionDelay",
    ]
    assert env.get_wrapper_attr("arrival") == "network"
    assert env.observation_space["actions"] == spaces.MultiDiscrete([4] * 3)
    obs, info = env.reset(seed=0)
    *_, info = env.step(0)
    assert {"arrived_observations", "drawn_reward_delay", "executed_action"} <= set(info)
    unbounded = gym.make(
        "delayed_rl/Roulette-v0", action_delay=2.0, delay_aware=True, action_history=5
    )
    assert unbounded.observation_space["actions"].shape == (5,)
    assert layers(gym.make("delayed_rl/GridWorld-3x3-v0", delay_aware=True)) == [
        "DelayAwareObservation"
    ]


@pytest.mark.parametrize("through_json", [False, True])
def test_the_view_round_trips_through_the_spec(through_json: bool) -> None:
    made = gym.make("delayed_rl/GridWorld-5x5-v0", **MAKE, delay_aware=True, action_history=4)
    by_hand = DelayAwareObservation(
        gym.make("delayed_rl/GridWorld-5x5-v0", observation_delay=Uniform(0, 3), max_steps=30)
    )
    for env in (made, by_hand, DiscreteDelayAwareObservation(made)):
        spec = env.spec
        if through_json:
            spec = gym.envs.registration.EnvSpec.from_json(spec.to_json())
        rebuilt = gym.make(spec)
        assert layers(rebuilt) == layers(env)
        assert rebuilt.observation_space == env.observation_space
        if not isinstance(env, DiscreteDelayAwareObservation):
            assert same(trajectory(env, 3), trajectory(rebuilt, 3))


@pytest.mark.parametrize(
    ("kwargs", "exc", "match"),
    [
        ({"delay_aware": 1}, TypeError, "^delay_aware must be a bool"),
        ({"delay_aware": True, "action_history": "3"}, TypeError, "^action_history must be"),
        ({"delay_aware": True, "action_history": 0}, ValueError, "^action_history must be"),
        ({"action_history": 3}, ValueError, "^action_history is DelayAwareObservation's"),
        ({"observation_arrival": "late"}, ValueError, "^observation_arrival must be one of"),
        ({"delay_aware": True, "action_delay": 2.0}, ValueError, "needs action_history"),
    ],
)
def test_gym_make_refuses_bad_arguments_naming_them(kwargs, exc, match) -> None:
    with pytest.raises(exc, match=match):
        gym.make("delayed_rl/GridWorld-3x3-v0", **kwargs)


@pytest.mark.parametrize(
    ("build", "exc", "match"),
    [
        (lambda: DelayAwareObservation(Walk(), action_history=True), TypeError, "^action_history"),
        (lambda: DelayAwareObservation(Walk(), action_history=2.0), TypeError, "^action_history"),
        (lambda: DelayAwareObservation(Walk(), action_history=-1), ValueError, "^action_history"),
        (
            lambda: DelayAwareObservation(Walk(), action_history=MAX_ACTION_HISTORY + 1),
            ValueError,
            r"^action_history must be None or an integer in \[1, 65536\], got 65537",
        ),
        (
            lambda: DelayAwareObservation(ObservationDelay(Walk(), Poisson(2.0))),
            ValueError,
            r"needs action_history .* ObservationDelay of unbounded delay Poisson",
        ),
        (
            lambda: DelayAwareObservation(ActionDelay(Walk(), Geometric(0.5))),
            ValueError,
            r"needs action_history .* ActionDelay of unbounded delay Geometric",
        ),
        (
            lambda: DelayAwareObservation(ObservationDelay(Walk(), Uniform(0, 10**6))),
            ValueError,
            "would observe 1000000 actions .* MAX_ACTION_HISTORY = 65536",
        ),
        (
            lambda: DelayAwareObservation(ObservationDelay(ObservationDelay(Walk(), 0), 0)),
            ValueError,
            "^env must hold at most one ObservationDelay",
        ),
        (
            lambda: DelayAwareObservation(Sensor(spaces.Tuple([spaces.Discrete(2)]))),
            TypeError,
            "action_space is Discrete, Box, MultiDiscrete or MultiBinary",
        ),
    ],
)
def test_bad_arguments_are_refused_naming_them(build, exc, match) -> None:
    with pytest.raises(exc, match=match):
        build()


def test_an_action_outside_the_space_is_refused_before_the_stack_steps() -> None:
    env = DelayAwareObservation(Walk())
    env.reset(seed=0)
    with pytest.raises(ValueError, match="^action must be an action of Discrete"):
        env.step(3)
    assert env.unwrapped.t == 0


# --------------------------------------------------------------------------- vector envs
@pytest.mark.parametrize("rule", ARRIVAL_RULES)
def test_a_vector_env_of_views_is_one_view_per_sub_env(rule: str) -> None:
    def make():
        env = stack("discrete", (Uniform(0, 3), None), (Constant(1), None), rule, length=1000)
        return DelayAwareObservation(env)

    vector = gym.vector.SyncVectorEnv([make, make])
    singles = [make(), make()]
    actions = np.random.default_rng(0).integers(0, 3, (30, 2))
    views, _ = vector.reset(seed=10)
    expected = [env.reset(seed=10 + i)[0] for i, env in enumerate(singles)]
    for row in actions:
        for i, single in enumerate(expected):
            assert same({key: value[i] for key, value in views.items()}, single)
        views = vector.step(row)[0]
        expected = [env.step(a)[0] for env, a in zip(singles, row, strict=True)]
    made = gym.make_vec(
        "delayed_rl/GridWorld-3x3-v0", num_envs=2, vectorization_mode="sync",
        observation_delay=Uniform(0, 2), observation_arrival=rule, delay_aware=True,
    )  # fmt: skip
    assert made.single_observation_space["age"] == spaces.Discrete(3)
    _, info = made.reset(seed=0)
    assert info["_arrived_observations"].all()


# --------------------------------------------------------------------------- the Discrete index
def discrete_view(rule: str = "stale") -> DiscreteDelayAwareObservation:
    """The index over a Walk with Uniform(0, 2) observation delays and Constant(1) action delays."""
    env = stack("discrete", (Uniform(0, 2), None), (Constant(1), None), rule, length=1000)
    return DiscreteDelayAwareObservation(DelayAwareObservation(env))


def test_the_index_numbers_every_view_once_and_decodes_back() -> None:
    env = discrete_view()  # N observations, ages 0..2, K = 3 actions of 3
    assert env.observation_space == spaces.Discrete(N * 3 * 3**3)
    space = env.env.observation_space
    for index in range(env.observation_space.n):
        view = env.decode(index)
        assert space.contains(view) and env.observation(view) == index
        parts = (view["observation"], view["age"], *view["actions"])
        assert index == np.ravel_multi_index(parts, (N, 3, 3, 3, 3))  # the first part leads
    with pytest.raises(ValueError, match="^index must be in"):
        env.decode(env.observation_space.n)
    with pytest.raises(TypeError, match="^index must be an integer"):
        env.decode(1.0)


@pytest.mark.parametrize("rule", ARRIVAL_RULES)
def test_the_index_is_the_view_a_step_at_a_time(rule: str) -> None:
    env, twin = discrete_view(rule=rule), discrete_view(rule=rule).env
    actions = actions_for("discrete", 2, 50)
    indices = [env.reset(seed=5)[0]] + [env.step(a)[0] for a in actions]
    views = [twin.reset(seed=5)[0]] + [twin.step(a)[0] for a in actions]
    assert all(same(env.decode(i), v) for i, v in zip(indices, views, strict=True))
    assert len(set(indices)) > 20
    check_env(env, skip_render_check=True)


def test_multi_binary_actions_are_numbered_entry_by_entry() -> None:
    view = DelayAwareObservation(ActionDelay(DiscreteSensor(spaces.MultiBinary(2)), Constant(1)))
    env = DiscreteDelayAwareObservation(view)
    assert env.observation_space == spaces.Discrete(4 * 1 * 2**2)  # ages 0..0, K = 1
    index, _ = env.reset(seed=0)
    index = env.step(np.array([1, 0], dtype=np.int8))[0]
    assert env.decode(index)["actions"].tolist() == [[1, 0]]


def test_too_many_states_are_refused_with_the_count_and_the_limit() -> None:
    view = DelayAwareObservation(stack("discrete", (Constant(2), None)), action_history=14)
    states = N * 3 * 3**14
    assert states > MAX_DISCRETE_STATES
    with pytest.raises(ValueError, match=f"would number {states} states .* = {2**24}"):
        DiscreteDelayAwareObservation(view)
    fits = DelayAwareObservation(stack("discrete", (Constant(2), None)), action_history=11)
    assert DiscreteDelayAwareObservation(fits).observation_space.n == N * 3 * 3**11
    assert math.prod([N, 3, 3**11]) <= MAX_DISCRETE_STATES


@pytest.mark.parametrize(
    "env",
    [
        Walk(),
        DelayAwareObservation(Sensor(spaces.Discrete(2))),
        DelayAwareObservation(DiscreteSensor(spaces.Box(-1.0, 1.0, (1,)))),
    ],
    ids=["not a view", "box observations", "box actions"],
)
def test_the_index_needs_a_view_of_discrete_parts(env) -> None:
    with pytest.raises(TypeError, match="^DiscreteDelayAwareObservation needs an env whose"):
        DiscreteDelayAwareObservation(env)


# --------------------------------------------------------------------------- stable-baselines3
@pytest.mark.sb3
def test_stable_baselines3_takes_the_view() -> None:
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_checker import check_env as sb3_check_env
    from stable_baselines3.common.env_util import make_vec_env

    for base in ("CartPole-v1", "Pendulum-v1"):
        stacked = wrap_delays(
            gym.make(base), observation_delay=Uniform(0, 2), action_delay=Constant(1)
        )
        sb3_check_env(DelayAwareObservation(stacked))  # Pendulum: warns of its 2-D actions Box
    kwargs = {"observation_delay": Uniform(0, 2), "observation_arrival": "network"}
    venv = make_vec_env(
        "CartPole-v1", n_envs=2, seed=0, wrapper_class=wrap_delays,
        wrapper_kwargs={**kwargs, "delay_aware": True},
    )  # fmt: skip
    model = PPO("MultiInputPolicy", venv, n_steps=16, batch_size=16, n_epochs=1, seed=0)
    model.learn(32)
    flat = make_vec_env(
        "delayed_rl/GridWorld-3x3-v0", n_envs=2, seed=0,
        env_kwargs={**kwargs, "render_mode": None, "delay_aware": True},
        wrapper_class=gym.wrappers.FlattenObservation,
    )  # fmt: skip
    assert flat.observation_space.shape == (2 * 4 + 3 + 9,)  # K = 2 actions, ages 0..2
    PPO("MlpPolicy", flat, n_steps=16, batch_size=16, n_epochs=1, seed=0).learn(32)


def test_a_numpy_action_history_is_written_to_the_spec_as_an_int():
    import delayed_rl  # noqa: F401  (registers the ids)

    env = gym.make(
        "delayed_rl/GridWorld-5x5-v0",
        observation_delay=Constant(1),
        delay_aware=True,
        action_history=np.int64(3),
    )
    spec = gym.envs.registration.EnvSpec.from_json(env.spec.to_json())
    assert spec.kwargs["action_history"] == 3 and type(spec.kwargs["action_history"]) is int
    assert gym.make(spec).observation_space == env.observation_space
