"""The reward models of ``delayed_rl.deep``: losses, schedule, seeds, learning, diagnostics, arguments.

The deconvolution loss is checked against a plain-Python sum over the same windows (drawn from a
copy of the model's generator) for each episode-end mode and for a learned ``p``. The schedule:
``add()`` never trains (the weights and the generator stay the same bits), ``train_on_schedule``
takes ``floor(steps · updates_per_step) + warmup_updates`` updates in all, the warm-up at once
when the loss first can be computed (a window for the deconvolution, a finished episode for RRD
and IRCR). Seeds: equal seeds give equal bits, ``reseed`` is a model made with that seed, and no
global generator is drawn from. Learning is checked on a synthetic stream delayed by the real
``RewardDelay`` wrapper, whose reward has a standard deviation known in closed form, trained on
the schedule after every step as an algorithm's buffer does; anonymity is bit-identical weights
with and without the diagnostic ``infos``. The watched diagnostics (RMSE, correlation) are
checked against numpy's over the same pairs. torch is imported in the tests' bodies (and a
fixture), not at collection.
"""

from __future__ import annotations

import copy
import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from support import torch_on_one_thread  # noqa: F401  (the fixture)

from delayed_rl.delays import Constant, Empirical, Poisson
from delayed_rl.wrappers import RewardDelay

pytestmark = [pytest.mark.sb3, pytest.mark.usefixtures("torch_on_one_thread")]


def reward_fn(obs, action):
    """The synthetic env's reward: ``sin(2·x₀) + x₁·a`` (smooth, mean 0)."""
    return math.sin(2.0 * float(obs[0])) + float(obs[1]) * float(action[0])


# Var[sin(2x)] for x ~ U[-1, 1] is E[sin²(2x)] = 1/2 − sin(4)/8 (its mean is 0); Var[x₁·a] for
# independent x₁, a ~ U[-1, 1] is 1/3 · 1/3; the two terms are uncorrelated.
REWARD_STD = math.sqrt(0.5 - math.sin(4.0) / 8.0 + 1.0 / 9.0)


class Synthetic(gym.Env):
    """Uniform random observations in [-1, 1]², ``reward_fn`` rewards, truncated at ``length``."""

    observation_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, length=50):
        self.length = length

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        self.obs = self.np_random.uniform(-1.0, 1.0, 2).astype(np.float32)
        return self.obs, {}

    def step(self, action):
        reward = reward_fn(self.obs, action)
        self.t += 1
        self.obs = self.np_random.uniform(-1.0, 1.0, 2).astype(np.float32)
        return self.obs, reward, False, self.t >= self.length, {}


def feed(model, env, steps, seed, strip=False):
    """Random actions on ``env`` for ``steps`` steps, each added to ``model``, which then trains.

    The model takes the updates its schedule owes after each step (``train_on_schedule``), as a
    relabelling buffer has it do. ``strip``: pass ``infos=None`` in place of the wrapper's infos.
    """
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        action = rng.uniform(-1.0, 1.0, 1).astype(np.float32)
        next_obs, reward, terminated, truncated, info = env.step(action)
        model.add(
            obs[None],
            action[None],
            [reward],
            [terminated or truncated],
            None if strip else [info],
            next_observations=next_obs[None],
        )
        model.train_on_schedule()
        obs = next_obs
        if terminated or truncated:
            obs, _ = env.reset()


# ---------------------------------------------------------------------- the loss, summed by hand
class Stream:
    """Hand-made episodes of ``n_envs`` sub-envs, added to a model and kept here as lists."""

    def __init__(self, model, observation_space, action_space, n_envs, steps, seed, cuts=0.0):
        rng = np.random.default_rng(seed)
        observation_space.seed(seed)
        action_space.seed(seed + 1)
        self.obs, self.action, self.reward, self.end = [], [], [], []
        self.cut = []  # [t][env]: sub-env env's open episode was cut after step t (a reset)
        for _ in range(steps):
            obs = np.stack([observation_space.sample() for _ in range(n_envs)])
            action = np.stack([action_space.sample() for _ in range(n_envs)])
            reward = rng.normal(size=n_envs)
            end = rng.random(n_envs) < 0.2  # episodes of 1 step to a dozen or more
            reset = rng.random(n_envs) < cuts
            if self.end:
                self.cut[-1] = reset & ~self.end[-1]  # an episode just ended has nothing to cut
            model.add(obs, action, reward, end, episode_starts=reset)
            self.cut.append(np.zeros(n_envs, bool))
            self.obs.append(obs)
            self.action.append(action)
            self.reward.append(reward)
            self.end.append(end)


def direct_loss(model, stream, starts, envs, pmf, mode):
    """The deconvolution loss over the windows at ``starts`` (sub-envs ``envs``), by a plain loop.

    ``y_t`` is predicted as ``Σ_k w_t(k)·R̂(s_{t−k}, a_{t−k})`` with ``w_t(k) = p(k)``, or
    ``P(D ≥ k)`` at an episode's last step under ``"flush"`` (not at the last step of an episode
    cut by a reset, which flushes nothing); a lag that crosses an episode's start, a cut's
    included (``"flush"``, ``"drop"``), or reaches before the stream counts 0.
    """
    K = pmf.size - 1
    errors = []
    for start, env in zip(starts, envs, strict=True):
        for t in range(int(start), int(start) + model.window):
            predicted = 0.0
            for k in range(K + 1):
                s = t - k
                if s < 0:
                    continue
                assert s >= model.history.oldest, "a window reaches overwritten steps"
                if mode != "carry" and any(
                    stream.end[j][env] or stream.cut[j][env] for j in range(s, t)
                ):
                    continue
                weight = pmf[k:].sum() if mode == "flush" and stream.end[t][env] else pmf[k]
                r_hat = model.predict(stream.obs[s][env][None], stream.action[s][env][None])[0]
                predicted += weight * float(r_hat)
            errors.append((predicted - stream.reward[t][env]) ** 2)
    return float(np.mean(errors))


def drawn_windows(model):
    """The windows the next ``loss()`` draws: replayed from a copy of the model's generator."""
    history = model.history
    K, length = model.support, model.window
    rng = copy.deepcopy(model.rng)
    lowest = history.oldest + K if history.oldest > 0 else 0
    count = math.ceil(model.batch_size / length)
    starts = rng.integers(lowest, history.steps_added - length + 1, size=count)
    envs = rng.integers(0, history.n_envs, size=count)
    return starts, envs


SPACES = {
    "box-discrete": (spaces.Box(-2.0, 2.0, (2,), np.float32), spaces.Discrete(3)),
    "discrete-box": (spaces.Discrete(4, start=1), spaces.Box(-1.0, 1.0, (2,), np.float32)),
    # a MultiDiscrete that starts above 0 (the ring's unfilled rows hold zeros, outside it)
    "multidiscrete-multibinary": (
        spaces.MultiDiscrete([3, 2], start=[1, 2]),
        spaces.MultiBinary(3),
    ),
}


@pytest.mark.parametrize("mode", ["flush", "drop", "carry"])
@pytest.mark.parametrize("spaces_name", sorted(SPACES))
@pytest.mark.parametrize("capacity", [1000, 40])  # the ring not wrapped / wrapped
def test_known_delay_loss_is_the_direct_sum(mode, spaces_name, capacity):
    from delayed_rl.deep import DeconvolutionRewardModel

    observation_space, action_space = SPACES[spaces_name]
    delay = Empirical([0.4, 0.3, 0.2, 0.1])
    model = DeconvolutionRewardModel(
        observation_space,
        action_space,
        delay=delay,
        max_delay_estimate=3,
        on_episode_end=mode,
        window=4,
        hidden_sizes=(8,),
        batch_size=64,  # 16 windows
        capacity=capacity,
        seed=3,
    )
    assert model.support == 3
    np.testing.assert_allclose(model.delay_pmf, [0.4, 0.3, 0.2, 0.1], rtol=1e-6)
    stream = Stream(model, observation_space, action_space, n_envs=2, steps=100, seed=7)
    assert (model.history.oldest > 0) == (capacity < 100)
    starts, envs = drawn_windows(model)
    expected = direct_loss(model, stream, starts, envs, model.delay_pmf, mode)
    loss = float(model.loss().detach())
    assert loss == pytest.approx(expected, rel=1e-5)
    # the modes differ on this stream (so the weights of each one are what is checked)
    others = {
        other: direct_loss(model, stream, starts, envs, model.delay_pmf, other)
        for other in ("flush", "drop", "carry")
        if other != mode
    }
    for other, value in others.items():
        assert value != pytest.approx(expected, rel=1e-3), other


@pytest.mark.parametrize("mode", ["flush", "drop", "carry"])
@pytest.mark.parametrize("capacity", [1000, 40])
def test_an_episode_cut_by_a_reset_ends_there_and_flushes_nothing(mode, capacity):
    from delayed_rl.deep import DeconvolutionRewardModel

    observation_space, action_space = SPACES["box-discrete"]
    model = DeconvolutionRewardModel(
        observation_space,
        action_space,
        delay=Empirical([0.4, 0.3, 0.2, 0.1]),
        max_delay_estimate=3,
        on_episode_end=mode,
        window=4,
        hidden_sizes=(8,),
        batch_size=64,
        capacity=capacity,
        seed=3,
    )
    stream = Stream(model, observation_space, action_space, n_envs=2, steps=100, seed=7, cuts=0.1)
    assert sum(map(np.sum, stream.cut)) >= 10  # the stream has cuts (a seeded count)
    starts, envs = drawn_windows(model)
    expected = direct_loss(model, stream, starts, envs, model.delay_pmf, mode)
    assert float(model.loss().detach()) == pytest.approx(expected, rel=1e-5)
    if mode != "carry":  # reading a cut as no boundary, or as an end that flushes, differs
        as_ends = copy.copy(stream)
        as_ends.end = [e | c for e, c in zip(stream.end, stream.cut, strict=True)]
        as_ends.cut = [np.zeros_like(c) for c in stream.cut]
        ignored = copy.copy(stream)
        ignored.cut = as_ends.cut
        for wrong in (as_ends, ignored) if mode == "flush" else (ignored,):
            value = direct_loss(model, wrong, starts, envs, model.delay_pmf, mode)
            assert value != pytest.approx(expected, rel=1e-3)


def test_an_episode_reset_midway_is_cut_and_left_out_of_the_finished_ones():
    from delayed_rl.deep import ReturnRegressionRewardModel

    model = ReturnRegressionRewardModel(spaces.Discrete(2), spaces.Discrete(2), capacity=100)
    ends = [[0, 0, 1, 0, 0, 0, 0, 1], [0, 1, 0, 0, 0, 1, 0, 1]]
    for step, end in enumerate(zip(*ends, strict=True)):
        # starts at steps 0 (the first: nothing to cut), 3 (after ends: nothing), 4 (a reset
        # after step 3: sub-env 0's episode 3..3 and sub-env 1's 2..3 are cut)
        starts = [1, 1] if step in (0, 4) else [1, 0] if step == 3 else [0, 0]
        model.add([0, 0], [1, 1], [10.0**step, -(10.0**step)], list(end), episode_starts=starts)
    history = model.history
    assert history.episode_cut[:8].tolist() == [[0, 0]] * 3 + [[1, 1]] + [[0, 0]] * 4
    assert sorted(history.episodes) == [
        (0, 0, 3, 111.0),
        (0, 4, 4, 11110000.0),
        (1, 0, 2, -11.0),
        (1, 4, 2, -110000.0),
        (1, 6, 2, -11000000.0),
    ]
    assert history.episode_ids(0, 0, 8).tolist() == [0, 0, 0, 1, 2, 2, 2, 2]
    model.add([0, 0], [1, 1], [0.0, 0.0], [0, 0], episode_starts=[True, False])
    assert not history.episode_cut[7].any()  # an episode that just ended has nothing to cut
    with pytest.raises(TypeError, match="episode_starts must be numbers"):
        model.add([0, 0], [1, 1], [0.0, 0.0], [0, 0], episode_starts=["yes", "no"])
    with pytest.raises(ValueError, match="episode_starts must hold 2 values"):
        model.add([0, 0], [1, 1], [0.0, 0.0], [0, 0], episode_starts=[True])


def test_a_history_pickled_before_cuts_were_kept_unpickles_with_none():
    import pickle

    from delayed_rl.deep import ReturnRegressionRewardModel

    model = ReturnRegressionRewardModel(spaces.Discrete(2), spaces.Discrete(2), capacity=10)
    for step in range(4):
        model.add([0], [1], [float(step)], [step == 1])
    del model.history.episode_cut  # the state an earlier version pickled
    loaded = pickle.loads(pickle.dumps(model))
    assert loaded.history.episode_cut.shape == (10, 1) and not loaded.history.episode_cut.any()
    loaded.add([0], [1], [1.0], [False], episode_starts=[True])
    assert np.flatnonzero(loaded.history.episode_cut[:, 0]).tolist() == [3]


def test_clipped_poisson_pmf_is_credit_weights():
    from delayed_rl.deep import DeconvolutionRewardModel

    model = DeconvolutionRewardModel(
        spaces.Discrete(2), spaces.Discrete(2), delay=Poisson(1.5), max_delay_estimate=3, seed=0
    )
    pmf = [math.exp(-1.5) * 1.5**k / math.factorial(k) for k in range(3)]
    expected = [*pmf, 1.0 - sum(pmf)]  # the last lag holds the tail
    np.testing.assert_allclose(model.delay_pmf, expected, rtol=1e-6)
    assert model.mean_delay == pytest.approx(float(np.arange(4) @ np.array(expected)), rel=1e-6)


def test_learned_delay_starts_uniform_and_its_loss_is_the_direct_sum():
    import torch

    from delayed_rl.deep import DeconvolutionRewardModel

    observation_space, action_space = SPACES["box-discrete"]
    model = DeconvolutionRewardModel(
        observation_space,
        action_space,
        delay=None,
        max_delay_estimate=3,
        window=4,
        hidden_sizes=(8,),
        batch_size=32,
        delay_learning_rate=0.2,
        seed=5,
    )
    np.testing.assert_array_equal(model.delay_pmf, np.full(4, 0.25))
    assert model.mean_delay == pytest.approx(1.5)
    assert model.metrics() == {"mean_delay": pytest.approx(1.5)}
    stream = Stream(model, observation_space, action_space, n_envs=1, steps=80, seed=11)
    assert model.train(20) == 20
    assert model.updates_taken == 20
    pmf = model.delay_pmf
    assert pmf.sum() == pytest.approx(1.0, abs=1e-6)
    assert np.all(pmf > 0)
    assert np.ptp(pmf) > 1e-3, "the learned pmf did not move from uniform"
    assert model.mean_delay == pytest.approx(float(np.arange(4) @ pmf))
    np.testing.assert_allclose(
        pmf, torch.softmax(model.delay_logits.detach(), 0).double().numpy(), rtol=1e-6
    )
    starts, envs = drawn_windows(model)
    expected = direct_loss(model, stream, starts, envs, pmf, "flush")
    loss = model.loss()
    assert float(loss.detach()) == pytest.approx(expected, rel=1e-5)
    loss.backward()  # the gradient reaches p's logits
    assert model.delay_logits.grad is not None and model.delay_logits.grad.abs().sum() > 0


def test_loss_waits_for_a_window_and_the_delay_before_it():
    from delayed_rl.deep import DeconvolutionRewardModel

    model = DeconvolutionRewardModel(
        spaces.Discrete(2),
        spaces.Discrete(2),
        delay=Constant(2),
        window=5,
        capacity=7,  # the least that holds a window and the K = 2 steps before it
        seed=0,
    )
    for step in range(5):
        if step:
            assert model.loss() is None  # fewer than a window of steps
        model.add([0], [1], [1.0], [False])
    assert model.loss() is not None  # steps 0..4: a window, its lags before the stream masked
    for _ in range(20):
        model.add([0], [1], [1.0], [False])
        # once the ring is full, the one window whose lags are all held: the last 5 steps
        assert model.loss() is not None
        if model.history.oldest > 0:
            starts, _ = drawn_windows(model)
            assert set(starts.tolist()) == {model.history.steps_added - 5}


def test_lags_before_the_stream_are_masked_in_spaces_that_start_above_zero():
    from delayed_rl.deep import DeconvolutionRewardModel

    # the first window begins at step 0, so its K = 2 lags reach before the stream: they count
    # 0, and must not read the ring's unfilled rows (zeros, which Discrete(3, start=5) and the
    # MultiDiscrete do not hold: a one-hot of them fails)
    for observation_space, action_space in [
        (spaces.Discrete(3, start=5), spaces.Discrete(2)),
        (spaces.Box(-1.0, 1.0, (2,), np.float32), spaces.MultiDiscrete([2, 2], start=[3, -4])),
    ]:
        model = DeconvolutionRewardModel(
            observation_space, action_space, delay=Constant(2), window=4, batch_size=8, seed=0
        )
        stream = Stream(model, observation_space, action_space, n_envs=1, steps=4, seed=0)
        starts, envs = drawn_windows(model)
        assert set(starts.tolist()) == {0}
        expected = direct_loss(model, stream, starts, envs, model.delay_pmf, "flush")
        assert float(model.loss().detach()) == pytest.approx(expected, rel=1e-5)
        assert model.train(3) == 3


def test_a_history_too_short_for_a_window_is_refused():
    from delayed_rl.deep import DeconvolutionRewardModel

    # a full ring of 6 steps never holds a window of 5 and its 2 lags: it would never train
    with pytest.raises(ValueError, match="capacity"):
        DeconvolutionRewardModel(
            spaces.Discrete(2), spaces.Discrete(2), delay=Constant(2), window=5, capacity=6
        )
    with pytest.raises(ValueError, match="capacity"):
        DeconvolutionRewardModel(
            spaces.Discrete(2), spaces.Discrete(2), max_delay_estimate=10, window=64, capacity=73
        )


@pytest.mark.parametrize("capacity", [1000, 20])
def test_history_keeps_the_episodes_its_ring_shows_whole(capacity):
    from delayed_rl.deep import ReturnRegressionRewardModel

    model = ReturnRegressionRewardModel(spaces.Discrete(2), spaces.Discrete(2), capacity=capacity)
    rng = np.random.default_rng(0)
    n_envs, finished, first = 3, [], [0, 0, 0]
    sums = np.zeros(n_envs)
    # sub-env 0's episodes are long, sub-env 2's short: they end out of the order they began
    chance = np.array([0.03, 0.2, 0.6])
    for step in range(200):
        reward, end = rng.normal(size=n_envs), rng.random(n_envs) < chance
        model.add(np.zeros(n_envs, int), np.ones(n_envs, int), reward, end)
        sums += reward
        for env in np.flatnonzero(end):
            finished.append((int(env), first[env], step + 1 - first[env], float(sums[env])))
            first[env], sums[env] = step + 1, 0.0
        history = model.history
        # whole: begun after the oldest step held (whose episode may have begun before it)
        cut = history.oldest + 1 if history.oldest > 0 else 0
        expected = [e for e in finished if e[1] >= cut]
        held = list(history.episodes)
        assert sorted(held) == sorted(expected)
        assert [e[1] for e in held] == sorted(e[1] for e in held)  # in order of first step
        for env, begin, length, total in held:
            rows = history.rows(begin, begin + length)
            assert history.reward[rows, env].sum() == pytest.approx(total)
            assert history.episode_end[rows, env].tolist() == [False] * (length - 1) + [True]
    assert len(finished) > 40 and (capacity > 200 or len(held) < len(finished))


# ---------------------------------------------------------------------- learning
def test_known_delay_learns_the_reward():
    from delayed_rl.deep import DeconvolutionRewardModel

    env = RewardDelay(Synthetic(), Poisson(3), on_episode_end="flush")
    model = DeconvolutionRewardModel(
        env.observation_space,
        env.action_space,
        delay=Poisson(3),
        max_delay_estimate=10,
        hidden_sizes=(16,),
        batch_size=128,
        window=16,
        # one update a step from the first window on, as the old schedule's one a step from
        # step 200 (the warm-up is not what this test is about)
        updates_per_step=1.0,
        warmup_updates=1,
        seed=0,
    )
    assert math.isnan(model.rmse())
    feed(model, env, 2000, seed=0)
    truth = model.history.undelayed[: model.history.steps_added, 0]
    assert np.isfinite(truth).all()
    assert np.std(truth) == pytest.approx(REWARD_STD, rel=0.1)  # the closed form holds
    # a constant predictor's RMSE is the reward's standard deviation
    assert model.rmse() < 0.5 * REWARD_STD
    assert model.updates_taken == model.updates_due == 2000 + 1


def test_learned_delay_finds_the_mean():
    from delayed_rl.deep import DeconvolutionRewardModel

    env = RewardDelay(Synthetic(), Poisson(5), on_episode_end="flush")
    model = DeconvolutionRewardModel(
        env.observation_space,
        env.action_space,
        delay=None,
        max_delay_estimate=15,
        hidden_sizes=(16,),
        batch_size=128,
        window=16,
        updates_per_step=1.0,  # as in test_known_delay_learns_the_reward
        warmup_updates=1,
        delay_learning_rate=3e-2,
        seed=1,
    )
    assert model.mean_delay == pytest.approx(7.5)  # uniform on 0..15
    feed(model, env, 3000, seed=1)
    # The truth is the mean of min(D, 15) for D ~ Poisson(5): 5 less a tail of ~1e-4. The start
    # is 7.5; a tolerance of 1 step (0.45 of Poisson(5)'s standard deviation, and under half of
    # the way from the start) fails a model that did not learn p, while the mean of a pmf
    # learned from 3000 updates on a reward of known scale lands well inside it.
    assert model.delay_pmf.sum() == pytest.approx(1.0, abs=1e-6)
    assert abs(model.mean_delay - 5.0) < 1.0
    assert model.rmse() < 0.5 * REWARD_STD


@pytest.mark.parametrize("kind", ["ReturnDecompositionRewardModel", "ReturnRegressionRewardModel"])
def test_episode_sum_baselines_train(kind):
    import delayed_rl.deep as deep

    env = RewardDelay(Synthetic(length=10), Poisson(3), on_episode_end="flush")
    model = getattr(deep, kind)(
        env.observation_space,
        env.action_space,
        hidden_sizes=(8,),
        batch_size=32,
        updates_per_step=1.0,
        warmup_updates=1,
        seed=0,
    )
    probe = (np.zeros((1, 2)), np.zeros((1, 1)), np.ones((1, 2)))  # s, a and s′
    before = model.predict(*probe)
    model.add(*probe[:2], [1.0], [False], next_observations=probe[2])
    assert model.updates_due == 2
    assert model.train_on_schedule() == 0  # no finished episode yet: loss() is None
    assert model.updates_taken == 0
    feed(model, env, 300, seed=0)
    assert model.updates_taken == model.updates_due == 301 + 1
    assert len(model.history.episodes) == 30
    assert not np.array_equal(before, model.predict(*probe))


def test_rrd_loss_is_the_episode_sum_regression():
    from delayed_rl.deep import ReturnDecompositionRewardModel

    model = ReturnDecompositionRewardModel(
        spaces.Discrete(3), spaces.Discrete(2), subset_size=2, batch_size=2
    )
    # one episode of 3 steps whose delivered rewards sum to 6: every subset's mean targets 2
    for obs, reward, end in [(0, 5.0, False), (1, 0.0, False), (2, 1.0, True)]:
        model.add([obs], [0], [reward], [end])
    model.add([0], [1], [100.0], [False])  # an open episode: not used
    assert list(model.history.episodes) == [(0, 0, 3, 6.0)]
    rng = copy.deepcopy(model.rng)
    rng.integers(0, 3, size=1)  # the episode drawn (a step of the only episode's 3)
    subset = rng.choice(3, size=2, replace=False)
    expected = (np.mean(model.predict(subset, [0, 0])) - 2.0) ** 2
    assert float(model.loss().detach()) == pytest.approx(float(expected), rel=1e-5)


def test_return_regression_targets_are_normalised_returns():
    from delayed_rl.deep import ReturnRegressionRewardModel

    model = ReturnRegressionRewardModel(spaces.Discrete(2), spaces.Discrete(2), batch_size=4)
    model.add([0], [0], [1.0], [True])  # return 1
    model.add([1], [1], [3.0], [True])  # return 3
    rng = copy.deepcopy(model.rng)
    picks = rng.integers(0, 2, size=4)
    targets = np.where(picks == 0, 0.0, 1.0)  # (G − 1) / (3 − 1)
    predicted = model.predict(picks, picks)  # each episode is one step: obs = action = index
    assert float(model.loss().detach()) == pytest.approx(
        float(np.mean((predicted - targets) ** 2)), rel=1e-5
    )


# ---------------------------------------------------------------------- anonymity
def test_learning_is_the_same_bits_without_the_infos():
    import torch

    from delayed_rl.deep import DeconvolutionRewardModel

    models = []
    for strip in (False, True):
        env = RewardDelay(Synthetic(length=20), Poisson(3), record_arrivals=True)
        model = DeconvolutionRewardModel(
            env.observation_space,
            env.action_space,
            delay=None,
            max_delay_estimate=8,
            hidden_sizes=(8,),
            batch_size=32,
            window=8,
            warmup_updates=50,
            seed=4,
        )
        feed(model, env, 300, seed=4, strip=strip)
        models.append(model)
    with_infos, without = models
    assert with_infos.updates_taken == without.updates_taken == 300 + 50
    for a, b in zip(with_infos.network.parameters(), without.network.parameters(), strict=True):
        assert torch.equal(a, b)
    assert torch.equal(with_infos.delay_logits, without.delay_logits)
    # the infos did reach the diagnostics
    assert np.isfinite(with_infos.rmse()) and math.isnan(without.rmse())


def test_add_reads_nothing_but_the_undelayed_reward_from_infos():
    import torch

    from delayed_rl.deep import DeconvolutionRewardModel

    def run(infos_at):
        model = DeconvolutionRewardModel(
            spaces.Discrete(3),
            spaces.Discrete(2),
            delay=Constant(1),
            window=4,
            hidden_sizes=(8,),
            batch_size=8,
            warmup_updates=8,
            seed=0,
        )
        rng = np.random.default_rng(0)
        for step in range(40):
            model.add([step % 3], [step % 2], [rng.normal()], [step % 7 == 6], infos_at(step))
            model.train_on_schedule()
        assert model.updates_taken == 40 + 8
        return model

    plain = run(lambda step: None)

    def noisy_infos(step):
        return [
            {
                "undelayed_reward": float(step),
                "drawn_reward_delay": step,
                "pending_reward": 9.0,
                "reward_arrivals": [(step, 1.0)],
                "flushed_reward": -3.0,
            }
        ]

    noisy = run(noisy_infos)
    odd = run(lambda step: ["not a dict"])  # anything but a dict is ignored
    for other in (noisy, odd):
        for a, b in zip(plain.network.parameters(), other.network.parameters(), strict=True):
            assert torch.equal(a, b)
    assert noisy.history.undelayed[39, 0] == 39.0
    assert np.isnan(odd.history.undelayed).all()


# ---------------------------------------------------------------------- the schedule
def snapshot(model):
    """Copies of everything a model learns or draws from: weights, extras, Adam, generator."""
    return {
        "network": copy.deepcopy(model.network.state_dict()),
        "extra": copy.deepcopy(model._extra_state()),
        "optimizer": copy.deepcopy(model.optimizer.state_dict()),
        "rng": copy.deepcopy(model.rng.bit_generator.state),
    }


def assert_same_bits(a, b):
    """Two snapshots (or models) hold the same bits."""
    import torch

    a = a if isinstance(a, dict) else snapshot(a)
    b = b if isinstance(b, dict) else snapshot(b)
    assert a["rng"] == b["rng"]
    for part in ("network", "extra"):
        assert a[part].keys() == b[part].keys()
        for name in a[part]:
            assert torch.equal(a[part][name], b[part][name]), name
    assert a["optimizer"]["param_groups"] == b["optimizer"]["param_groups"]
    assert a["optimizer"]["state"].keys() == b["optimizer"]["state"].keys()
    for index, state in a["optimizer"]["state"].items():
        for name, value in state.items():
            assert torch.equal(value, b["optimizer"]["state"][index][name]), (index, name)


def changed(before, model):
    """Whether any weight differs from the snapshot's."""
    import torch

    now = model.network.state_dict()
    return any(not torch.equal(before["network"][name], now[name]) for name in now)


def random_steps(count, seed, n_envs=1, end_chance=0.2):
    """``count`` steps on ``Discrete(3)`` × ``Discrete(2)`` (``make``'s spaces)."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield (
            rng.integers(0, 3, n_envs),
            rng.integers(0, 2, n_envs),
            rng.normal(size=n_envs),
            rng.random(n_envs) < end_chance,
        )


@pytest.mark.parametrize(
    ("kind", "kwargs"),
    [
        ("DeconvolutionRewardModel", {"delay": None, "max_delay_estimate": 3, "window": 4}),
        ("ReturnDecompositionRewardModel", {"subset_size": 4}),
        ("ReturnRegressionRewardModel", {}),
    ],
)
def test_add_alone_never_trains(kind, kwargs):
    model = make(kind, hidden_sizes=(8,), batch_size=8, warmup_updates=3, seed=0, **kwargs)
    before = snapshot(model)
    assert model.updates_due == 0 and not model.ready
    for step in random_steps(60, seed=0, n_envs=2):
        model.add(*step)
    assert model.loss() is not None  # it could have trained: a window and finished episodes
    model.rng.bit_generator.state = before["rng"]  # loss() drew a batch; add() draws nothing
    assert_same_bits(before, model)
    assert model.updates_taken == 0 and not model.ready
    assert model.updates_due == 60 + 3
    assert model.train_on_schedule() == 63
    assert model.updates_taken == 63 and model.ready
    assert changed(before, model)
    assert model.train_on_schedule() == 0  # nothing more is owed


@pytest.mark.parametrize("updates_per_step", [0.0, 0.37, 1.0, 2.5])
def test_updates_due_is_the_steps_times_the_rate_plus_the_warmup(updates_per_step):
    model = make(
        "ReturnRegressionRewardModel",
        hidden_sizes=(4,),
        batch_size=4,
        updates_per_step=updates_per_step,
        warmup_updates=5,
        seed=0,
    )
    assert model.train_on_schedule() == 0  # no step: nothing owed, nothing to train on
    assert model.train(3) == 0
    model.add([0], [0], [1.0], [True])  # a finished episode: the loss can be computed
    for added in range(1, 40):
        due = math.floor(added * updates_per_step) + 5
        assert model.updates_due == due
        owed = due - model.updates_taken
        assert model.train_on_schedule() == owed
        assert model.updates_taken == due
        model.add([added % 3], [added % 2], [1.0], [added % 4 == 0])
    # train(n) takes n more, beyond the schedule: then nothing is owed until it catches up
    assert model.train(7) == 7
    taken = model.updates_taken
    for _ in range(3):
        model.add([0], [0], [1.0], [False])
    assert model.train_on_schedule() == max(0, model.updates_due - taken)
    assert model.updates_taken == max(taken, model.updates_due)


@pytest.mark.parametrize("kind", ["ReturnDecompositionRewardModel", "ReturnRegressionRewardModel"])
def test_the_warmup_is_taken_at_once_when_the_first_episode_ends(kind):
    model = make(kind, hidden_sizes=(4,), batch_size=4, warmup_updates=7, seed=0)
    for step in range(5):  # an open episode: the loss cannot be computed yet
        model.add([step % 3], [0], [1.0], [False])
        assert model.updates_due == step + 1 + 7
        assert model.train_on_schedule() == 0
        assert model.train(2) == 0
        assert model.updates_taken == 0 and not model.ready
    before = snapshot(model)
    model.add([0], [1], [2.0], [True])  # the first episode ends
    assert not changed(before, model)
    assert model.train_on_schedule() == 6 + 7  # the warm-up and the owed ones, at once
    assert model.ready and changed(before, model)
    model.add([1], [1], [0.0], [False])
    assert model.train_on_schedule() == 1


def test_the_deconvolution_warmup_waits_for_a_window():
    model = make(delay=Constant(2), window=4, hidden_sizes=(4,), batch_size=4, warmup_updates=9)
    for step in range(3):
        model.add([0], [step % 2], [1.0], [False])
        assert model.train_on_schedule() == 0 and not model.ready
    model.add([0], [1], [1.0], [False])  # steps 0..3: a window (its lags before the stream)
    assert model.train_on_schedule() == 4 + 9
    assert model.ready


def test_ready_once_the_warmup_updates_are_taken():
    model = make(
        "ReturnRegressionRewardModel", hidden_sizes=(4,), batch_size=4, warmup_updates=5, seed=0
    )
    model.add([0], [0], [1.0], [True])
    assert model.train(4) == 4 and not model.ready
    assert model.train(1) == 1 and model.ready
    assert model.train_on_schedule() == 1  # 1 step + 5 warm-up owed, 5 taken


def test_without_a_warmup_ready_needs_one_update():
    model = make(
        "ReturnRegressionRewardModel",
        hidden_sizes=(4,),
        batch_size=4,
        warmup_updates=0,
        updates_per_step=0.5,
    )
    assert model.updates_due == 0 and not model.ready
    model.add([0], [0], [1.0], [True])
    assert model.updates_due == 0 and model.train_on_schedule() == 0 and not model.ready
    model.add([1], [0], [1.0], [True])
    assert model.updates_due == 1 and model.train_on_schedule() == 1 and model.ready


# ---------------------------------------------------------------------- seeds
KINDS = [
    ("DeconvolutionRewardModel", {"delay": None, "max_delay_estimate": 3, "window": 4}),
    ("DeconvolutionRewardModel", {"delay": Constant(1), "window": 4}),
    ("ReturnDecompositionRewardModel", {"subset_size": 4}),
    ("ReturnRegressionRewardModel", {}),
]
SMALL = {"hidden_sizes": (8,), "batch_size": 8, "warmup_updates": 4}


def train_on(model, count=30, seed=0):
    """Add ``count`` steps of two sub-envs, training on the schedule after each."""
    for step in random_steps(count, seed, n_envs=2):
        model.add(*step)
        model.train_on_schedule()
    assert model.ready


@pytest.mark.parametrize(("kind", "kwargs"), KINDS)
def test_equal_seeds_give_equal_bits_and_other_seeds_other_weights(kind, kwargs):
    a, b = (make(kind, seed=123, **SMALL, **kwargs) for _ in range(2))
    other = make(kind, seed=124, **SMALL, **kwargs)
    assert a.seed == b.seed == 123 and a.settings()["seed"] == 123
    assert not a.takes_algorithm_seed
    assert_same_bits(a, b)
    assert changed(snapshot(a), other)
    train_on(a)
    train_on(b)
    assert a.updates_taken == b.updates_taken > 0
    assert_same_bits(a, b)
    np.testing.assert_array_equal(a.predict([0, 1, 2], [1, 0, 1]), b.predict([0, 1, 2], [1, 0, 1]))


@pytest.mark.parametrize(("kind", "kwargs"), KINDS)
def test_reseed_is_a_model_made_with_that_seed(kind, kwargs):
    model = make(kind, seed=None, **SMALL, **kwargs)
    assert model.takes_algorithm_seed
    assert 0 <= model.seed < 2**63
    model.reseed(2**63 - 1)
    assert not model.takes_algorithm_seed and model.seed == 2**63 - 1
    assert model.settings()["seed"] == 2**63 - 1
    seeded = make(kind, seed=2**63 - 1, **SMALL, **kwargs)
    assert_same_bits(model, seeded)
    train_on(model)
    train_on(seeded)
    assert_same_bits(model, seeded)
    with pytest.raises(RuntimeError, match="seen a step"):
        model.reseed(1)


def test_unseeded_models_draw_fresh_entropy_until_their_first_step():
    a, b = make(seed=None), make(seed=None)
    assert a.takes_algorithm_seed and b.takes_algorithm_seed
    assert a.seed != b.seed  # 2**-63 of a chance to be equal
    assert changed(snapshot(a), b)
    a.add([0], [0], [0.0], [False])  # its first step: no algorithm can seed it any more
    assert not a.takes_algorithm_seed
    with pytest.raises(RuntimeError, match="seen a step"):
        a.reseed(0)
    for bad, error in [(-1, ValueError), (2**63, ValueError), (1.0, TypeError), (None, TypeError)]:
        with pytest.raises(error, match="seed"):
            b.reseed(bad)
    assert b.takes_algorithm_seed  # a refused seed changes nothing


def test_models_draw_nothing_from_the_global_generators():
    import torch

    def global_states():  # what an algorithm draws from (SB3 uses both)
        return np.random.get_state(legacy=False), torch.get_rng_state()  # noqa: NPY002

    torch.manual_seed(0)
    np.random.seed(0)  # noqa: NPY002
    numpy_before, torch_before = global_states()
    for kind, kwargs in KINDS:
        for seed in (None, 5):
            model = make(kind, seed=seed, **SMALL, **kwargs)
            if seed is None:
                model.reseed(6)
            train_on(model)
            model.predict([0, 1], [1, 1])
    numpy_after, torch_after = global_states()
    assert torch.equal(torch_after, torch_before)
    assert numpy_after["state"]["pos"] == numpy_before["state"]["pos"]
    np.testing.assert_array_equal(numpy_after["state"]["key"], numpy_before["state"]["key"])


# ---------------------------------------------------------------------- diagnostics
def test_watch_reports_rmse_and_correlation_over_each_block():
    from delayed_rl.deep.reward_model import DIAGNOSTIC_PAIRS

    model = make(seed=0)
    rng = np.random.default_rng(42)
    batch = 1000  # 5 batches make the first block of >= DIAGNOSTIC_PAIRS pairs with a truth
    kept_x, kept_y = [], []

    def watch_one():
        predicted = rng.normal(0.3, 1.2, batch).astype(np.float32)
        undelayed = 0.6 * predicted + rng.normal(-0.1, 0.8, batch)
        undelayed[rng.random(batch) < 0.1] = np.nan  # steps whose info had no truth
        model.watch(predicted, undelayed)
        held = np.isfinite(undelayed)
        kept_x.append(predicted[held].astype(np.float64))
        kept_y.append(undelayed[held])

    def by_hand():
        x, y = np.concatenate(kept_x), np.concatenate(kept_y)
        kept_x.clear()
        kept_y.clear()
        return x.size, math.sqrt(np.mean((x - y) ** 2)), np.corrcoef(x, y)[0, 1]

    for _ in range(4):  # 3600 pairs with a truth: nothing yet
        watch_one()
        assert model.diagnostics() == {}
    model.watch(np.ones(500), np.full(500, np.nan))  # no truth: ignored
    assert sum(x.size for x in kept_x) < DIAGNOSTIC_PAIRS
    watch_one()
    count, rmse, correlation = by_hand()
    assert count >= DIAGNOSTIC_PAIRS
    assert model.diagnostics() == {
        "rmse": pytest.approx(rmse, rel=1e-9),
        "correlation": pytest.approx(correlation, rel=1e-9),
    }
    first = model.diagnostics()
    for _ in range(4):  # the next block: the last full block's values meanwhile
        watch_one()
        assert model.diagnostics() == first
    watch_one()
    count, rmse, correlation = by_hand()
    assert count >= DIAGNOSTIC_PAIRS
    assert model.diagnostics()["rmse"] == pytest.approx(rmse, rel=1e-9)
    assert model.diagnostics()["correlation"] == pytest.approx(correlation, rel=1e-9)
    assert model.diagnostics()["rmse"] != pytest.approx(first["rmse"], rel=1e-6)


def test_watch_leaves_out_the_correlation_of_a_constant_side():
    from delayed_rl.deep.reward_model import DIAGNOSTIC_PAIRS

    model = make(seed=0)
    truth = np.random.default_rng(0).normal(size=DIAGNOSTIC_PAIRS)
    model.watch(np.full(DIAGNOSTIC_PAIRS, 0.5, np.float32), truth)  # an untrained R̂: constant
    assert model.diagnostics() == {"rmse": pytest.approx(math.sqrt(np.mean((0.5 - truth) ** 2)))}
    model.watch(truth.astype(np.float32), np.full(DIAGNOSTIC_PAIRS, 2.0))  # a constant truth
    assert set(model.diagnostics()) == {"rmse"}


class Logger:
    """Keeps what ``record`` writes, as SB3's logger would."""

    def __init__(self):
        self.values = {}

    def record(self, key, value):
        self.values[key] = value


def test_record_writes_the_loss_diagnostics_metrics_and_updates():
    from delayed_rl.deep.reward_model import DIAGNOSTIC_PAIRS

    model = make(
        delay=None, max_delay_estimate=3, window=4, **{**SMALL, "warmup_updates": 2}, seed=0
    )
    logger = Logger()
    model.record(logger)
    assert logger.values == {"reward_model/mean_delay": 1.5, "reward_model/updates": 0}
    train_on(model, count=10)
    rng = np.random.default_rng(0)
    x = rng.normal(size=DIAGNOSTIC_PAIRS)
    model.watch(x, x + rng.normal(size=DIAGNOSTIC_PAIRS))
    logger = Logger()
    model.record(logger, prefix="rm")
    assert set(logger.values) == {
        "rm/loss",
        "rm/rmse",
        "rm/correlation",
        "rm/mean_delay",
        "rm/updates",
    }
    assert logger.values["rm/updates"] == model.updates_taken == 10 + 2
    assert math.isfinite(logger.values["rm/loss"]) and logger.values["rm/loss"] >= 0
    assert logger.values["rm/mean_delay"] == pytest.approx(model.mean_delay)
    assert logger.values["rm/rmse"] == model.diagnostics()["rmse"]
    logger = Logger()
    model.record(logger)  # no update since: no loss
    assert "reward_model/loss" not in logger.values
    assert logger.values["reward_model/updates"] == 12


# ---------------------------------------------------------------------- arguments
def make(kind="DeconvolutionRewardModel", observation_space=None, action_space=None, **kwargs):
    import delayed_rl.deep as deep

    if kind == "DeconvolutionRewardModel":
        kwargs.setdefault("delay", Constant(1))
    return getattr(deep, kind)(
        spaces.Discrete(3) if observation_space is None else observation_space,
        spaces.Discrete(2) if action_space is None else action_space,
        **kwargs,
    )


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (
            {"observation_space": spaces.Dict({"a": spaces.Dict({"b": spaces.Discrete(2)})})},
            TypeError,
            "observation_space must be .* a nested Dict at key 'a'",
        ),
        ({"action_space": spaces.Tuple([spaces.Discrete(2)])}, TypeError, r"action_space.*Tuple"),
        ({"observation_space": "Discrete(3)"}, TypeError, "observation_space"),
        ({"observation_space": spaces.Box(0, 1, (0,))}, ValueError, "observation_space"),
        ({"observation_space": spaces.Discrete(2**20 + 1)}, ValueError, "MAX_FEATURES"),
        ({"observation_space": spaces.Dict({})}, ValueError, "observation_space must have"),
        (
            {"observation_space": spaces.Dict({"a": spaces.Box(0, 1, (0,))})},
            ValueError,
            r"observation_space\['a'\]",
        ),
        ({"max_delay_estimate": -1}, ValueError, "max_delay_estimate"),
        ({"max_delay_estimate": 1.5}, TypeError, "max_delay_estimate"),
        (
            {"max_delay_estimate": 1025},
            ValueError,
            "max_delay_estimate must be at most MAX_DELAY_E",
        ),
        ({"delay": None}, ValueError, "max_delay_estimate must be given"),
        ({"delay": "Poisson"}, TypeError, "delay"),
        ({"delay": -2.0}, ValueError, "delay"),
        ({"delay": {"type": "Nope"}}, ValueError, "delay"),
        ({"delay": Poisson(5000.0)}, ValueError, "delay"),
        ({"on_episode_end": "x"}, ValueError, "on_episode_end"),
        ({"on_episode_end": 1}, TypeError, "on_episode_end"),
        ({"window": 0}, ValueError, "window"),
        ({"window": 2.0}, TypeError, "window"),
        ({"delay_learning_rate": 0.0}, ValueError, "delay_learning_rate"),
        ({"hidden_sizes": (0,)}, ValueError, r"hidden_sizes\[0\]"),
        ({"hidden_sizes": (8, -1)}, ValueError, r"hidden_sizes\[1\]"),
        ({"hidden_sizes": (8.0,)}, TypeError, r"hidden_sizes\[0\]"),
        ({"hidden_sizes": "8"}, TypeError, "hidden_sizes"),
        ({"hidden_sizes": 8}, TypeError, "hidden_sizes"),
        ({"learning_rate": 0.0}, ValueError, "learning_rate"),
        ({"learning_rate": float("nan")}, ValueError, "learning_rate"),
        ({"learning_rate": "1e-3"}, TypeError, "learning_rate"),
        ({"batch_size": 0}, ValueError, "batch_size"),
        ({"updates_per_step": -0.5}, ValueError, "updates_per_step"),
        ({"updates_per_step": float("nan")}, ValueError, "updates_per_step"),
        ({"updates_per_step": 2.0**21}, ValueError, "updates_per_step"),
        ({"updates_per_step": "1"}, TypeError, "updates_per_step"),
        ({"warmup_updates": -1}, ValueError, "warmup_updates"),
        ({"warmup_updates": 10.0}, TypeError, "warmup_updates"),
        # the old schedule's settings are gone (not silently ignored)
        ({"learning_starts": 10}, TypeError, "learning_starts"),
        ({"train_every": 1}, TypeError, "train_every"),
        ({"gradient_steps": 1}, TypeError, "gradient_steps"),
        ({"capacity": 0}, ValueError, "capacity"),
        ({"seed": -1}, ValueError, "seed"),
        ({"seed": 2**63}, ValueError, "seed"),
        ({"seed": 1.0}, TypeError, "seed"),
        ({"kind": "ReturnDecompositionRewardModel", "subset_size": 0}, ValueError, "subset_size"),
        (
            {"kind": "ReturnRegressionRewardModel", "hidden_sizes": [2**17]},
            ValueError,
            r"hidden_sizes\[0\]",
        ),
        ({"kind": "ReturnRegressionRewardModel", "window": 4}, TypeError, "window"),
    ],
)
def test_bad_arguments_are_refused_by_name(kwargs, error, match):
    with pytest.raises(error, match=match):
        make(**kwargs)


def test_a_history_beyond_the_memory_limit_is_refused_at_the_first_step():
    model = make(capacity=2**40)  # the history is made when the first step fixes n_envs
    with pytest.raises(
        ValueError,
        match=r"capacity must keep the history's size at most MAX_HISTORY_BYTES = 2\*\*34 \(",
    ):
        model.add([0], [0], [0.0], [False])
    assert model.history is None


def test_bad_steps_and_batches_are_refused_by_name():
    model = make(observation_space=spaces.Box(-1, 1, (2,)), action_space=spaces.Discrete(2))
    with pytest.raises(ValueError, match="observation_space values must be 1 of shape"):
        model.add(np.zeros(3), [0], [0.0], [False])
    with pytest.raises(ValueError, match="action_space values must be in 0..1"):
        model.add(np.zeros(2), [2], [0.0], [False])
    with pytest.raises(ValueError, match="action_space values must be integers"):
        model.add(np.zeros(2), [0.5], [0.0], [False])
    with pytest.raises(ValueError, match="observation_space values must be finite"):
        model.add([np.nan, 0.0], [0], [0.0], [False])
    with pytest.raises(TypeError, match="observation_space values must be numbers"):
        model.add(["a", "b"], [0], [0.0], [False])
    with pytest.raises(ValueError, match="rewards must be finite"):
        model.add(np.zeros(2), [0], [np.inf], [False])
    with pytest.raises(TypeError, match="rewards must be numbers"):
        model.add(np.zeros(2), [0], ["1"], [False])
    with pytest.raises(ValueError, match="episode_ends must hold 1 values"):
        model.add(np.zeros(2), [0], [0.0], [False, True])
    with pytest.raises(ValueError, match="observation_space values must be 2 of shape"):
        model.add(np.zeros(2), [0, 1], [0.0, 0.0], [False, False])  # 2 rewards, 1 observation
    # a refused first step fixes nothing: not even the number of sub-envs
    assert model.history is None
    model.add(np.zeros(2), [0], [0.0], [False])
    with pytest.raises(ValueError, match="rewards must hold one reward for each of the 1 sub-envs"):
        model.add(np.zeros((2, 2)), [0, 1], [0.0, 0.0], [False, False])
    assert model.history.steps_added == 1
    with pytest.raises(ValueError, match="observation_space values must be 2 of shape"):
        model.predict(np.zeros((3, 2)), [0, 1])
    with pytest.raises(ValueError, match="last"):
        model.rmse(last=0)
    with pytest.raises(ValueError, match="updates"):
        model.train(-1)
    with pytest.raises(TypeError, match="updates"):
        model.train(1.0)
