"""``HindsightSAC``: what it stores, when, and that it trains as SAC does.

The env is a counter whose observation is its step index (so a stored observation names the
step it was made at) and whose reward is a known function of the step and the executed action.
A recorder inside the stack keeps what the env really did; the learner's replay buffer is read
back and checked against it:

- every stored transition starts at an observation the view had received when it was stored
  (nothing reaches the learner early), and spans the steps to the next received one, with their
  discounted rewards and ``γ`` to the power of their number;
- under a constant observation delay every observation arrives, each step waits exactly the
  delay, and only a truncated episode's tail is dropped; under the network rule with random
  delays every step is stored with one step's discount, but the tail;
- a terminated episode's last steps are stored as ends (nothing to bootstrap);
- the same seed gives the same bits; bad envs and settings are refused by name.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from support import torch_on_one_thread  # noqa: F401  (the fixture)

from delayed_rl.delays import Constant, Uniform
from delayed_rl.wrappers import ActionDelay, DelayAwareObservation, ObservationDelay

pytestmark = [pytest.mark.sb3, pytest.mark.usefixtures("torch_on_one_thread")]

GAMMA = 0.9


class Counter(gym.Env):
    """Observes its step index; reward ``step + action``; ends at ``length`` (truncated or not)."""

    observation_space = spaces.Box(0.0, 1000.0, (1,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, length=12, terminate=False):
        self.length, self.terminate = length, terminate

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.array([0.0], np.float32), {}

    def step(self, action):
        reward = float(self.t) + float(np.asarray(action).reshape(-1)[0])
        self.t += 1
        end = self.t >= self.length
        obs = np.array([float(self.t)], np.float32)
        return obs, reward, end and self.terminate, end and not self.terminate, {}


class Record(gym.Wrapper):
    """What the env really did: each episode's rewards."""

    def __init__(self, env):
        super().__init__(env)
        self.episodes = []

    def reset(self, **kwargs):
        self.episodes.append([])
        return self.env.reset(**kwargs)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.episodes[-1].append(float(reward))
        return obs, reward, terminated, truncated, info


def view(observation_delay, action_delay=None, arrival="stale", **counter):
    action_delay = Constant(1) if action_delay is None else action_delay
    record = Record(Counter(**counter))
    stack = ObservationDelay(ActionDelay(record, action_delay), observation_delay, arrival=arrival)
    return DelayAwareObservation(stack), record


def learner(env, **kwargs):
    from delayed_rl.deep import HindsightSAC

    settings = {
        "critic_input": "made",  # the tests below the newest-input section are of "made"
        "learning_starts": 20,
        "batch_size": 8,
        "gamma": GAMMA,
        "policy_kwargs": {"net_arch": [8]},
        "seed": 0,
        "device": "cpu",
    }
    return HindsightSAC("MultiInputPolicy", env, **{**settings, **kwargs})


class Watch:
    """Wraps the buffer's ``add_transition``: each transition with what the view had received."""

    def __init__(self, agent):
        self.agent, self.stored = agent, []
        original = agent.replay_buffer.add_transition

        def add(obs, next_obs, action, reward, done, discount):
            episode = agent._episodes[0]
            self.stored.append(
                {
                    "start": int(obs["hindsight"][0]),
                    "end": int(next_obs["hindsight"][0]),
                    "reward": reward,
                    "done": done,
                    "discount": discount,
                    "view_step": episode.steps,
                    "received": set(episode.received) | {int(obs["hindsight"][0])},
                }
            )
            original(obs, next_obs, action, reward, done, discount)

        agent.replay_buffer.add_transition = add


def test_a_constant_delay_stores_each_step_once_it_arrives():
    env, record = view(Constant(2))
    agent = learner(env)
    watch = Watch(agent)
    agent.learn(36)  # three episodes of 12
    episodes = 3
    assert agent.transitions_stored == episodes * 10 and agent.transitions_dropped == episodes * 2
    for transition in watch.stored[:10]:
        start = transition["start"]
        # stored at the view's step start + 1 + 2: the next observation arrived 2 steps late
        assert transition["end"] == start + 1 and transition["view_step"] == start + 3
        assert transition["discount"] == pytest.approx(GAMMA)
        assert transition["reward"] == pytest.approx(record.episodes[0][start])
        assert not transition["done"]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stale_arrivals_bridge_the_observations_never_shown(seed):
    env, record = view(Uniform(0, 3), Uniform(1, 2), length=30)
    agent = learner(env, seed=seed)
    watch = Watch(agent)
    agent.learn(60)
    assert agent.transitions_stored == len(watch.stored) > 20
    assert agent.transitions_dropped > 0  # the stale sensor skips some observations
    by_episode, episode, last = [[]], 0, -1
    for transition in watch.stored:
        if transition["start"] <= last:
            by_episode.append([])
            episode += 1
        by_episode[-1].append(transition)
        last = transition["start"]
    for episode, transitions in enumerate(by_episode):
        rewards = record.episodes[episode]
        for transition in transitions:
            start, end = transition["start"], transition["end"]
            # its observations had arrived, and none between them could still arrive (the one
            # made at m arrives by the view's step m + 3), unless the episode had ended
            assert {start, end} <= transition["received"]
            ended = transition["view_step"] == 30
            assert ended or end == start + 1 or end - 1 <= transition["view_step"] - 3
            expected = sum(GAMMA**k * rewards[start + k] for k in range(end - start))
            assert transition["reward"] == pytest.approx(expected)
            assert transition["discount"] == pytest.approx(GAMMA ** (end - start))
        starts = [t["start"] for t in transitions]
        assert starts == sorted(set(starts))


def test_the_network_rule_delivers_every_step_but_the_tail():
    env, _ = view(Uniform(0, 3), Uniform(0, 2), arrival="network", length=20)
    agent = learner(env)
    watch = Watch(agent)
    agent.learn(40)
    # mid-episode, every observation arrives; at the end, those in flight never do
    assert all(t["end"] == t["start"] + 1 for t in watch.stored if t["view_step"] < 20)
    # per episode, the steps after the last observation that arrived before the end are lost
    assert agent.transitions_stored + agent.transitions_dropped == 40
    assert agent.transitions_dropped <= 2 * 4


def test_a_terminated_episode_stores_its_last_steps_as_ends():
    env, record = view(Constant(3), terminate=True, length=10)
    agent = learner(env)
    watch = Watch(agent)
    agent.learn(10)
    # observations 8, 9 and 10 are in flight at the end: step 7's is the last received, and
    # it ends the episode with the rewards of steps 7 to 9; steps 8 and 9 start nothing
    ends = [t for t in watch.stored if t["done"]]
    assert [t["start"] for t in ends] == [7]
    expected = sum(GAMMA ** (k - 7) * record.episodes[0][k] for k in range(7, 10))
    assert ends[0]["reward"] == pytest.approx(expected)
    assert agent.transitions_stored == 8 and agent.transitions_dropped == 2


def test_the_same_seed_gives_the_same_bits_and_it_learns_through_sacs_train():
    import torch

    runs = []
    for _ in range(2):
        env, _ = view(Uniform(0, 2), Uniform(0, 1), length=15)
        agent = learner(env, seed=3)
        agent.learn(90)
        runs.append(agent)
    first, second = runs
    assert first.replay_buffer.size() == second.replay_buffer.size() > 40
    for a, b in zip(
        first.policy.state_dict().values(), second.policy.state_dict().values(), strict=True
    ):
        assert torch.equal(a, b)
    assert first._n_updates > 0
    critic_space = first.policy.critic.features_extractor.extractors
    assert set(critic_space) == {"hindsight", "actions"}
    assert set(first.policy.actor.features_extractor.extractors) == {
        "observation",
        "age",
        "actions",
    }


def test_what_is_not_a_view_or_sacs_own_buffer_is_refused():
    from stable_baselines3.common.buffers import ReplayBuffer

    from delayed_rl.deep import HindsightSAC

    with pytest.raises(TypeError, match="DelayAwareObservation"):
        HindsightSAC("MultiInputPolicy", gym.make("Pendulum-v1"), device="cpu")
    env, _ = view(Constant(1))
    with pytest.raises(TypeError, match="replay_buffer_class"):
        HindsightSAC("MultiInputPolicy", env, replay_buffer_class=ReplayBuffer)
    with pytest.raises(ValueError, match="n_steps"):
        HindsightSAC("MultiInputPolicy", env, n_steps=3)
    with pytest.raises(ValueError, match="optimize_memory_usage"):
        HindsightSAC("MultiInputPolicy", env, optimize_memory_usage=True)
    with pytest.raises(ValueError, match="policy must be 'MultiInputPolicy'.*got 'MlpPolicy'"):
        HindsightSAC("MlpPolicy", env, device="cpu")


# ---------------------------------------------------------------------- critic_input="newest"
@pytest.mark.parametrize("arrival", ["stale", "network"])
@pytest.mark.parametrize("terminate", [False, True])
def test_newest_inputs_make_every_step_a_one_step_transition(arrival, terminate):
    env, record = view(Uniform(0, 3), Uniform(1, 2), arrival, length=20, terminate=terminate)
    agent = learner(env, critic_input="newest")
    stored, original = [], agent.replay_buffer.add_transition

    def add(obs, next_obs, action, reward, done, discount):
        episode = agent._episodes[0]
        made, age = int(obs["hindsight"][0]), int(obs["hindsight_age"])
        then, later = int(next_obs["hindsight"][0]), int(next_obs["hindsight_age"])
        stored.append((made + age, made, then + later, reward, done, discount))
        # nothing newer made by the step can still arrive, and none arrived: it is the newest
        assert episode.steps >= made + age + 1 + agent._max_age or episode.ended
        assert not [m for m in episode.received if made < m <= made + age]
        original(obs, next_obs, action, reward, done, discount)

    agent.replay_buffer.add_transition = add
    agent.learn(40)  # two episodes of 20 steps
    assert agent.transitions_stored == 40 and agent.transitions_dropped == 0
    assert [step for step, *_ in stored] == [*range(20), *range(20)]
    for index, (step, made, following, reward, done, discount) in enumerate(stored):
        assert 0 <= step - made <= agent._max_age and following == step + 1
        assert reward == pytest.approx(record.episodes[index // 20][step])
        assert discount == pytest.approx(GAMMA)
        assert done == (terminate and step == 19)
    if arrival == "stale":  # some steps' own observations never arrive: an older one stands in
        assert any(step != made for step, made, *_ in stored)
    critic = agent.policy.critic.features_extractor.extractors
    assert set(critic) == {"hindsight", "hindsight_age", "actions"}


def test_critic_input_is_checked_and_kept_in_files(tmp_path):
    from delayed_rl.deep import HindsightSAC

    env, _ = view(Constant(1))
    with pytest.raises(ValueError, match="critic_input"):
        HindsightSAC("MultiInputPolicy", env, critic_input="oldest")
    with pytest.raises(TypeError, match="critic_input"):
        HindsightSAC("MultiInputPolicy", env, critic_input=1)
    agent = learner(env, critic_input="newest")
    agent.learn(30)
    agent.save(tmp_path / "newest.zip")
    loaded = HindsightSAC.load(tmp_path / "newest.zip", env=view(Constant(1))[0], device="cpu")
    assert loaded.critic_input == loaded.policy.critic_input == "newest"
    assert set(loaded.replay_buffer.observation_space.spaces) >= {"hindsight_age"}


def test_newest_is_the_default_and_a_file_from_before_critic_input_loads_as_made(tmp_path):
    import json
    import zipfile

    from delayed_rl.deep import HindsightSAC

    env, _ = view(Constant(1))
    assert HindsightSAC("MultiInputPolicy", env, device="cpu").critic_input == "newest"
    agent = learner(env, critic_input="made")
    agent.learn(30)
    agent.save(tmp_path / "made.zip")
    # the same file as the code before critic_input wrote it: no attribute, no policy argument
    with zipfile.ZipFile(tmp_path / "made.zip") as saved:
        members = {name: saved.read(name) for name in saved.namelist()}
    data = json.loads(members["data"])
    del data["critic_input"]
    del data["policy_kwargs"]["critic_input"]
    members["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(tmp_path / "old.zip", "w") as old:
        for name, content in members.items():
            old.writestr(name, content)
    loaded = HindsightSAC.load(tmp_path / "old.zip", env=view(Constant(1))[0], device="cpu")
    assert loaded.critic_input == loaded.policy.critic_input == "made"
    obs = {key: np.asarray(value)[None] for key, value in env.observation_space.sample().items()}
    np.testing.assert_array_equal(
        loaded.predict(obs, deterministic=True)[0], agent.predict(obs, deterministic=True)[0]
    )
    newest = HindsightSAC.load(tmp_path / "made.zip", env=view(Constant(1))[0], device="cpu")
    assert newest.critic_input == "made"  # a file that says its input keeps it
    import io

    stream = io.BytesIO((tmp_path / "old.zip").read_bytes())  # a file object, read twice
    assert HindsightSAC.load(stream, env=view(Constant(1))[0], device="cpu").critic_input == "made"
    deferred = HindsightSAC("MultiInputPolicy", env, critic_input="newest", _init_setup_model=False)
    deferred._setup_model()  # set up later, as SB3 allows: the input given is kept
    assert deferred.critic_input == deferred.policy.critic_input == "newest"
