"""``IRCRReplayBuffer`` against the authors' formulas (tgangwani/GuidanceRewards, IRCR).

The buffer is filled through ``add`` with tiny spaces: an observation is ``(episode, step)``, its
next observation ``(episode, step + 1)`` and its action ``100·episode + step``, so every sampled
row is traced back to its episode. The expected guidance rewards are worked out by hand from the
episodes' rewards: ``(c − c_min) / (c_max − c_min)`` over the credits (mean reward per step, or
return) of the episodes still in the ring and in the heap (``compute_rg``); the heap keeps the
episodes with the highest returns, replacing its lowest when a new return is at least that one
(``heapq`` of ``[priority, slot]``: ties to the earliest slot); half of a batch comes from it.
torch and SB3 are imported in the tests' bodies (and a fixture), not at collection.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from support import torch_on_one_thread  # noqa: F401  (the fixture)

from delayed_rl.wrappers import RewardDelay

pytestmark = [pytest.mark.sb3, pytest.mark.usefixtures("torch_on_one_thread")]

OBSERVATIONS = spaces.Box(-1000, 1000, (2,))
"""``(episode, step)``."""
ACTIONS = spaces.Box(-1000, 1000, (1,))
"""``100·episode + step``."""
OPEN = 100.0
"""The reward of every step of an open episode: it would stand out in any credit or guidance."""


def make(buffer_size=100, n_envs=1, **kwargs):
    from delayed_rl.deep import IRCRReplayBuffer

    return IRCRReplayBuffer(
        buffer_size, OBSERVATIONS, ACTIONS, device="cpu", n_envs=n_envs, **kwargs
    )


def add(buffer, *transitions):
    """One ``add``: a transition ``(episode, step, reward, done[, truncated])`` per sub-env."""
    obs = np.array([[t[0], t[1]] for t in transitions], dtype=np.float32)
    actions = np.array([[100 * t[0] + t[1]] for t in transitions], dtype=np.float32)
    rewards = np.array([t[2] for t in transitions], dtype=np.float32)
    dones = np.array([t[3] for t in transitions])
    infos = [{"TimeLimit.truncated": True} if t[4:] and t[4] else {} for t in transitions]
    buffer.add(obs, obs + [0, 1], actions, rewards, dones, infos)


def transitions(episodes, *, first=0, open_steps=0, truncated=()):
    """The transitions of ``episodes`` (lists of rewards), then ``open_steps`` of an open one.

    The i-th episode is numbered ``first + i``; ``truncated``: those that end on a time limit.
    """
    steps = []
    for episode, rewards in enumerate(episodes, first):
        for step, reward in enumerate(rewards):
            last = step == len(rewards) - 1
            steps.append((episode, step, reward, last, last and episode in truncated))
    steps += [(first + len(episodes), step, OPEN, False) for step in range(open_steps)]
    return steps


def fill(buffer, episodes, **kwargs):
    for transition in transitions(episodes, **kwargs):
        add(buffer, transition)


def rows(batch, batch_size):
    """``(episodes, steps, rewards, dones)`` of a batch, after checking each row is one transition."""
    obs = batch.observations.numpy()
    next_obs = batch.next_observations.numpy()
    actions = batch.actions.numpy()
    rewards, dones = batch.rewards.numpy(), batch.dones.numpy()
    assert obs.shape == next_obs.shape == (batch_size, 2)
    assert actions.shape == rewards.shape == dones.shape == (batch_size, 1)
    assert rewards.dtype == np.float32
    episodes, steps = obs[:, 0].astype(int), obs[:, 1].astype(int)
    np.testing.assert_array_equal(obs, np.stack([episodes, steps], axis=1))
    np.testing.assert_array_equal(next_obs, obs + [0, 1])
    np.testing.assert_array_equal(actions[:, 0], 100 * episodes + steps)
    return episodes, steps, rewards[:, 0], dones[:, 0]


def draws(buffer, batch_size, count, seed=0):
    """``count`` batches' rows as ``(episodes, steps, rewards, dones)``, each ``(count, size)``."""
    np.random.seed(seed)  # noqa: NPY002  (the buffer draws from NumPy's global generator)
    drawn = [rows(buffer.sample(batch_size), batch_size) for _ in range(count)]
    return tuple(np.stack(part) for part in zip(*drawn, strict=True))


def heap_episodes(buffer):
    """``[(return, episode)]`` of the heap's slots, after checking each holds a whole episode."""
    held = []
    for entry in buffer.heap:
        episode = int(entry.observations[0, 0])
        np.testing.assert_array_equal(entry.observations[:, 0], episode)
        np.testing.assert_array_equal(entry.observations[:, 1], np.arange(len(entry.dones)))
        held.append((entry.priority, episode))
    return held


# ---------------------------------------------------------------------- guidance
# returns [-3, 5, 1] over lengths [2, 4, 3]; an open episode of reward OPEN after them
KNOWN = [[-1.0, -2.0], [1.0, 2.0, 0.0, 2.0], [0.0, 0.0, 1.0]]
# means -3/2, 5/4, 1/3: over [-3/2, 5/4] (width 11/4), 1/3 is (11/6) / (11/4) = 2/3 of the way
# returns -3, 5, 1: over [-3, 5] (width 8), 1 is 4/8 = 1/2 of the way
GUIDANCE = {"mean": {0: 0.0, 1: 1.0, 2: 2 / 3}, "return": {0: 0.0, 1: 1.0, 2: 1 / 2}}


@pytest.mark.parametrize("credit", ["mean", "return"])
def test_every_sampled_reward_is_its_episodes_normalised_credit(credit):
    buffer = make(credit=credit)
    fill(buffer, KNOWN, open_steps=3)
    episodes, steps, rewards, _ = draws(buffer, 16, 40)
    expected = np.vectorize(GUIDANCE[credit].get)(episodes)
    np.testing.assert_allclose(rewards, expected, rtol=1e-6, atol=1e-7)
    # both halves of the batches saw every finished transition, and none of the open episode
    for half in (slice(0, 8), slice(8, 16)):
        seen = set(zip(episodes[:, half].ravel(), steps[:, half].ravel(), strict=True))
        assert seen == {(e, s) for e, rewards in enumerate(KNOWN) for s in range(len(rewards))}


# ---------------------------------------------------------------------- the heap's share
# buffer_size 10, heap of 2: episodes 0 and 1 (returns 10 and 9) have the highest returns and
# have left the ring (steps 0-6 overwritten by steps 10-16), so a row of theirs came from the heap
# and any other from the ring: the ring holds episodes 3-5 (8 transitions) and the open 6
SHARE = [[5.0, 5.0], [3.0, 3.0, 3.0], [0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0], [0.0, 1.0, 2.0]]


@pytest.mark.parametrize("batch_size", [8, 7])
def test_the_last_half_of_a_batch_comes_from_the_heap_of_the_best_episodes(batch_size):
    buffer = make(buffer_size=10, heap_episodes=2)
    fill(buffer, SHARE, open_steps=2)
    episodes, steps, _, _ = draws(buffer, batch_size, 60)
    heap = batch_size // 2
    ring = batch_size - heap
    from_heap = np.isin(episodes, [0, 1])
    assert not from_heap[:, :ring].any()
    assert from_heap[:, ring:].all()
    # the ring's part: every finished transition still in the ring, never the open episode's
    ring_seen = set(zip(episodes[:, :ring].ravel(), steps[:, :ring].ravel(), strict=True))
    assert ring_seen == {(e, s) for e in (3, 4, 5) for s in range(len(SHARE[e]))}
    heap_seen = set(zip(episodes[:, ring:].ravel(), steps[:, ring:].ravel(), strict=True))
    assert heap_seen == {(0, 0), (0, 1), (1, 0), (1, 1), (1, 2)}
    # the heap holds 5 transitions, enough for its part: drawn without replacement
    codes = 10 * episodes[:, ring:] + steps[:, ring:]
    assert all(len(set(batch)) == heap for batch in codes.tolist())


# ---------------------------------------------------------------------- before the first batch
def test_open_episodes_are_never_sampled():
    buffer = make(buffer_size=12)
    # 3 finished episodes (steps 0-5), then an open one of 8 steps that wraps the ring over
    # episode 0 (steps 0-1): it is left in the heap alone
    fill(buffer, [[1.0, 1.0], [0.0, 0.0, 0.0], [2.0]], open_steps=8)
    episodes, _, rewards, _ = draws(buffer, 10, 100)
    assert set(episodes[:, :5].ravel().tolist()) == {1, 2}
    assert set(episodes[:, 5:].ravel().tolist()) == {0, 1, 2}
    assert (rewards <= 1).all()


@pytest.mark.parametrize("buffer_size", [100, 12])  # the cut episode whole / partly overwritten
def test_an_episode_cut_by_a_reset_is_never_sampled(buffer_size):
    buffer = make(buffer_size=buffer_size)
    # episodes 0 (steps 0-1) and 1 (2-5), then episode 2 (6-8) open when the env is reset
    fill(buffer, [[1.0, 1.0], [0.0, 0.0, 0.0, 2.0]], open_steps=3)
    buffer._cut_open_episodes()  # what add() does first after the algorithm reset its env
    buffer._cut_open_episodes()  # a second reset with no step between: nothing more to cut
    # episodes 3 (step 9), 4 (10-11) and 5 (12-16), then 2 open steps of episode 6
    fill(buffer, [[2.0], [0.0, 1.0], [0.5] * 5], first=3, open_steps=2)
    assert [(first, stop) for _, first, stop, _ in buffer.episodes] == (
        [(0, 2), (2, 6), (9, 10), (10, 12), (12, 17)]
        if buffer_size == 100
        else [(9, 10), (10, 12), (12, 17)]
    )
    episodes, steps, rewards, _ = draws(buffer, 10, 300)
    # at size 12 the ring holds steps 7..18: the cut episode's steps 7 and 8 are still in it
    later = {(3, 0), (4, 0), (4, 1)} | {(5, step) for step in range(5)}
    earlier = {(0, 0), (0, 1)} | {(1, step) for step in range(4)}
    drawn = set(zip(episodes[:, :5].ravel().tolist(), steps[:, :5].ravel().tolist(), strict=True))
    assert drawn == (earlier | later if buffer_size == 100 else later)  # 1,500 draws of 14 or 8
    assert 2 not in set(episodes[:, 5:].ravel().tolist())
    assert (rewards <= 1).all() and (rewards >= 0).all()


def ircr_sac():
    """SAC with IRCR on a Pendulum of 20-step episodes that never trains (until step 200)."""
    from stable_baselines3 import SAC

    from delayed_rl.deep import IRCRReplayBuffer

    return SAC(
        "MlpPolicy",
        RewardDelay(gym.make("Pendulum-v1", max_episode_steps=20), 3),
        replay_buffer_class=IRCRReplayBuffer,
        learning_starts=200,
        buffer_size=500,
        policy_kwargs={"net_arch": [8]},
        seed=0,
        device="cpu",
    )


def test_sac_learning_again_cuts_the_episode_the_reset_left_open():
    agent = ircr_sac()
    agent.learn(50)  # episodes 0-19 and 20-39, then 40-49 open
    agent.learn(50)  # a reset: episodes 50-69 and 70-89, then 90-99 open
    buffer = agent.replay_buffer
    assert [(first, stop) for _, first, stop, _ in buffer.episodes] == [
        (0, 20),
        (20, 40),
        (50, 70),
        (70, 90),
    ]
    np.random.seed(0)  # noqa: NPY002
    rows, _ = buffer._ring_draw(2000)
    assert set(rows.tolist()) == set(range(40)) | set(range(50, 90))


def test_a_buffer_reloaded_into_its_own_algorithm_goes_on_without_a_cut(tmp_path):
    import pickle

    agent = ircr_sac()
    agent.learn(50)  # episodes 0-19 and 20-39, then 40-49 open
    agent.save_replay_buffer(tmp_path / "buffer.pkl")
    agent.load_replay_buffer(tmp_path / "buffer.pkl")
    agent.learn(30, reset_num_timesteps=False)  # to step 80, with no reset: 40-59 goes on
    buffer = agent.replay_buffer
    bounds = [(first, stop) for _, first, stop, _ in buffer.episodes]
    assert bounds == [(0, 20), (20, 40), (40, 60), (60, 80)]
    assert not any(buffer._cut_spans)
    del buffer._cut_spans  # the state an earlier version pickled: no cuts
    restored = pickle.loads(pickle.dumps(buffer))
    assert [list(spans) for spans in restored._cut_spans] == [[]]


def test_sample_refuses_before_a_finished_episode():
    buffer = make()
    with pytest.raises(RuntimeError, match="learning_starts"):
        buffer.sample(4)
    fill(buffer, [], open_steps=5)
    with pytest.raises(RuntimeError, match="learning_starts"):
        buffer.sample(4)


def test_equal_credits_give_guidance_one_before_any_two_differ():
    """A sparse task's first episodes (all one credit) train on, as if they had all differed."""
    # means 1, 1, 1; returns 2, 1, 3
    episodes = [[1.0, 1.0], [1.0], [1.0, 1.0, 1.0]]
    buffer = make(credit="mean")
    fill(buffer, episodes, open_steps=2)
    _, _, rewards, _ = draws(buffer, 8, 10)
    np.testing.assert_array_equal(rewards, 1.0)
    assert not buffer.distinct_credits_seen
    buffer = make(credit="return")
    fill(buffer, episodes, open_steps=2)
    found, _, rewards, _ = draws(buffer, 8, 10)
    np.testing.assert_allclose(rewards, np.choose(found, [0.5, 0.0, 1.0]), atol=1e-7)


def test_once_credits_have_differed_equal_credits_give_guidance_one():
    buffer = make(buffer_size=4, heap_episodes=1)
    fill(buffer, [[0.0], [2.0]])
    found, _, rewards, _ = draws(buffer, 4, 10)
    np.testing.assert_array_equal(rewards, np.choose(found, [0.0, 1.0]))
    # four more episodes of credit 2: the ring's and the heap's credits are all 2
    fill(buffer, [[2.0]] * 4, first=2)
    found, _, rewards, _ = draws(buffer, 4, 10)
    assert set(found.ravel().tolist()) == {2, 3, 4, 5}
    np.testing.assert_array_equal(rewards, 1.0)


# ---------------------------------------------------------------------- heap replacement
# returns 1, 5, 3, 5, 0, 5; means 1/2, 5, 1, 1/2, 0, 5/2 (a heap by means would differ)
RETURNS = [[0.5, 0.5], [5.0], [1.0, 1.0, 1.0], [0.5] * 10, [0.0], [2.5, 2.5]]
HEAPS = [
    [(1, 0)],
    [(1, 0), (5, 1)],
    [(3, 2), (5, 1)],  # 3 >= 1: replaces episode 0
    [(5, 3), (5, 1)],  # 5 >= 3: replaces episode 2
    [(5, 3), (5, 1)],  # 0 < 5: kept out
    [(5, 5), (5, 1)],  # 5 >= 5: replaces the tie in the earliest slot, episode 3
]


def test_the_heap_keeps_the_highest_returns_replacing_ties_in_the_earliest_slot():
    buffer = make(heap_episodes=2)
    for episode, heap in enumerate(HEAPS):
        for step, reward in enumerate(RETURNS[episode]):
            add(buffer, (episode, step, reward, step == len(RETURNS[episode]) - 1))
        assert heap_episodes(buffer) == heap, f"after episode {episode}"
    episodes, _, _, _ = draws(buffer, 16, 20)
    assert set(episodes[:, 8:].ravel().tolist()) == {1, 5}


# ---------------------------------------------------------------------- eviction
# buffer_size 8, heap of 1, credit "return": returns -5, 20, -1 (steps 0-6), then 4 and 1
EVICTION = [[-5.0, 0.0], [10.0, 10.0], [-1.0, 0.0, 0.0], [2.0, 2.0, 0.0], [1.0, 0.0, 0.0]]


def test_an_episode_gone_from_the_ring_leaves_the_bounds_unless_the_heap_holds_it():
    buffer = make(buffer_size=8, heap_episodes=1, credit="return")
    fill(buffer, EVICTION[:3])
    # all in the ring: over [-5, 20], -1 is 4/25 of the way
    found, _, rewards, _ = draws(buffer, 8, 20)
    assert set(found.ravel().tolist()) == {0, 1, 2}
    np.testing.assert_allclose(rewards, np.choose(found, [0.0, 1.0, 4 / 25]), atol=1e-7)
    fill(buffer, EVICTION[3:], first=3)
    # 13 steps in a ring of 8: steps 0-4 overwritten. Episode 0 (-5) is gone; episode 1 (20) is
    # gone from the ring but in the heap; episode 2 (-1) keeps its steps 1 and 2 in the ring.
    # Over [-1, 20] (width 21): 4 is 5/21 of the way, 1 is 2/21.
    found, steps, rewards, _ = draws(buffer, 8, 40)
    np.testing.assert_allclose(
        rewards, np.choose(found, [np.nan, 1.0, 0.0, 5 / 21, 2 / 21]), rtol=1e-6, atol=1e-7
    )
    ring = set(zip(found[:, :4].ravel(), steps[:, :4].ravel(), strict=True))
    assert ring == {(2, 1), (2, 2)} | {(e, s) for e in (3, 4) for s in range(3)}
    assert set(found[:, 4:].ravel().tolist()) == {1}


# ---------------------------------------------------------------------- two sub-envs
# sub-env 0: episodes 0 = [0, 2] and 2 = [1, 2, 3], then the open 4 (steps 0-1 at adds 5-6);
# sub-env 1: episodes 1 = [-2, 0, -1] and 3 = [0], then the open 5 (adds 4-6)
SUB_ENVS = [
    [(0, 0, 0.0, False), (0, 1, 2.0, True), (2, 0, 1.0, False), (2, 1, 2.0, False)]
    + [(2, 2, 3.0, True), (4, 0, OPEN, False), (4, 1, OPEN, False)],
    [(1, 0, -2.0, False), (1, 1, 0.0, False), (1, 2, -1.0, True), (3, 0, 0.0, True)]
    + [(5, 0, OPEN, False), (5, 1, OPEN, False), (5, 2, OPEN, False)],
]
# means 1, -1, 2, 0 over [-1, 2]: 2/3, 0, 1, 1/3; returns 2, -3, 6, 0 over [-3, 6]: 5/9, 0, 1, 3/9
SUB_ENV_GUIDANCE = {"mean": [2 / 3, 0.0, 1.0, 1 / 3], "return": [5 / 9, 0.0, 1.0, 3 / 9]}


@pytest.mark.parametrize("credit", ["mean", "return"])
def test_each_sub_env_has_its_own_episodes(credit):
    buffer = make(n_envs=2, credit=credit)
    for step in zip(*SUB_ENVS, strict=True):
        add(buffer, *step)
    episodes, steps, rewards, _ = draws(buffer, 2000, 10)
    np.testing.assert_allclose(
        rewards, np.choose(episodes, SUB_ENV_GUIDANCE[credit]), rtol=1e-6, atol=1e-7
    )
    # the ring's half: uniform over the 9 finished transitions (10000 draws: 1111 each on average,
    # with a standard deviation of 31)
    ring = 10 * episodes[:, :1000] + steps[:, :1000]
    codes, counts = np.unique(ring, return_counts=True)
    assert codes.tolist() == [0, 1, 10, 11, 12, 20, 21, 22, 30]
    assert (abs(counts - 10000 / 9) < 150).all(), counts


# ---------------------------------------------------------------------- time limits
# episodes 1 and 3 end on a time limit, 0 and 2 terminate
TIMEOUTS = [[1.0, 0.0], [0.0, 0.0, 3.0], [2.0], [0.0, 1.0]]


@pytest.mark.parametrize("handle_timeout_termination", [True, False])
def test_dones_exclude_time_limits_in_both_halves(handle_timeout_termination):
    buffer = make(heap_episodes=3, handle_timeout_termination=handle_timeout_termination)
    fill(buffer, TIMEOUTS, open_steps=2, truncated=(1, 3))
    episodes, steps, _, dones = draws(buffer, 8, 60)
    last = steps == np.choose(episodes, [1, 2, 0, 1])
    terminal = last & (np.isin(episodes, [0, 2]) | (not handle_timeout_termination))
    np.testing.assert_array_equal(dones, terminal)
    for half in (slice(0, 4), slice(4, 8)):  # both halves saw both kinds of episode end
        assert (last[:, half] & np.isin(episodes[:, half], [0, 2])).any()
        assert (last[:, half] & np.isin(episodes[:, half], [1, 3])).any()


# ---------------------------------------------------------------------- seeds
@pytest.mark.parametrize("batch_size", [8, 32])  # the heap's 7 transitions: 4 drawn, 16
def test_the_global_seed_fixes_the_batches(batch_size):
    buffer = make(heap_episodes=2)
    fill(buffer, KNOWN, open_steps=2)
    first, again = draws(buffer, batch_size, 3), draws(buffer, batch_size, 3)
    other = draws(buffer, batch_size, 3, seed=1)
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(first[0] * 10 + first[1], other[0] * 10 + other[1])


def sac_actor(seed):
    from stable_baselines3 import SAC

    from delayed_rl.deep import IRCRReplayBuffer

    agent = SAC(
        "MlpPolicy",
        RewardDelay(gym.make("Pendulum-v1", max_episode_steps=20), 3),
        replay_buffer_class=IRCRReplayBuffer,
        learning_starts=60,
        batch_size=16,
        buffer_size=500,
        policy_kwargs={"net_arch": [16]},
        seed=seed,
        device="cpu",
    )
    agent.learn(100)
    assert isinstance(agent.replay_buffer, IRCRReplayBuffer)
    assert agent.replay_buffer.distinct_credits_seen and len(agent.replay_buffer.heap) == 5
    return [p.detach().clone() for p in agent.actor.parameters()]


def test_a_seeded_sac_learns_the_same_actor():
    import torch

    def same(a, b):
        return all(torch.equal(x, y) for x, y in zip(a, b, strict=True))

    first, again, other = sac_actor(0), sac_actor(0), sac_actor(1)
    assert same(first, again)
    assert not same(first, other)


# ---------------------------------------------------------------------- bad arguments
@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"observation_space": spaces.Dict({"a": OBSERVATIONS})}, TypeError, "observation_space"),
        ({"optimize_memory_usage": True}, ValueError, "optimize_memory_usage"),
        ({"heap_episodes": 0}, ValueError, "heap_episodes"),
        ({"heap_episodes": "3"}, TypeError, "heap_episodes"),
        ({"heap_episodes": True}, TypeError, "heap_episodes"),
        ({"credit": "median"}, ValueError, "credit"),
        ({"credit": 1}, TypeError, "credit"),
    ],
)
def test_bad_arguments_are_refused_naming_them(kwargs, error, message):
    from delayed_rl.deep import IRCRReplayBuffer

    arguments = {"observation_space": OBSERVATIONS, **kwargs}
    with pytest.raises(error, match=message):
        IRCRReplayBuffer(100, action_space=ACTIONS, device="cpu", **arguments)
