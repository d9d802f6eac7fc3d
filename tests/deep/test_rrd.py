"""RRD against the authors' formulas: the biased and unbiased losses, the draws, the preset.

The expected values are computed here by hand from the authors' code
(Stilwell-Git/Randomized-Return-Decomposition: ``rrd_buffer.py``'s draws and ``rrd.py``'s
loss), replaying the model's generator to know which steps it drew.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from gymnasium import spaces

pytestmark = pytest.mark.sb3

OBS, ACT = spaces.Discrete(6), spaces.Discrete(2)


def _model(**settings):
    from delayed_rl.deep import ReturnDecompositionRewardModel

    return ReturnDecompositionRewardModel(OBS, ACT, hidden_sizes=(8,), seed=3, **settings)


def _two_episodes(model):
    """Episodes of 4 steps (return 8) and 2 steps (return −1), then an open one."""
    steps = [(0, 1.0, False), (1, 2.0, False), (2, 0.0, False), (3, 5.0, True)]
    steps += [(4, -3.0, False), (5, 2.0, True), (0, 50.0, False)]
    for obs, reward, end in steps:
        model.add([obs], [obs % 2], [reward], [end])
    assert list(model.history.episodes) == [(0, 0, 4, 8.0), (0, 4, 2, -1.0)]


def _expected_terms(model, n, episodes_drawn):
    """Per drawn episode: R̂ over its subset, and its target G / T, replaying the model's rng."""
    rng = copy.deepcopy(model.rng)
    ends = np.array([4, 6])  # the episodes' cumulative lengths: a step's episode is drawn
    picks = np.searchsorted(ends, rng.integers(0, 6, size=episodes_drawn), side="right")
    firsts, lengths, returns = [0, 4], [4, 2], [8.0, -1.0]
    terms = []
    for pick in picks:
        length = lengths[pick]
        offsets = rng.choice(length, size=n, replace=n > length)  # the authors' rrd_sample
        obs = firsts[pick] + offsets
        predicted = model.predict(obs, obs % 2).astype(np.float64)
        terms.append((predicted, returns[pick] / length, length))
    return terms


@pytest.mark.parametrize(("batch_size", "n", "count"), [(5, 2, 2), (8, 2, 4), (3, 4, 1)])
def test_a_batch_is_the_authors_floor_of_episodes_and_at_least_one(
    monkeypatch, batch_size, n, count
):
    from delayed_rl.deep import return_decomposition

    asked = []
    real = return_decomposition.sample_episodes

    def recorded(model, episodes, draw):
        asked.append(episodes)
        return real(model, episodes, draw)

    monkeypatch.setattr(return_decomposition, "sample_episodes", recorded)
    model = _model(subset_size=n, batch_size=batch_size)
    _two_episodes(model)
    model.loss()
    assert asked == [count]


@pytest.mark.parametrize("n", [2, 3])  # 3 > the 2-step episode: drawn with replacement there
def test_the_biased_loss_is_the_subsets_mean_squared_error(n):
    model = _model(subset_size=n, batch_size=2 * n)
    _two_episodes(model)
    terms = _expected_terms(model, n, 2)
    expected = np.mean([(np.mean(r) - target) ** 2 for r, target, _ in terms])
    assert float(model.loss().detach()) == pytest.approx(expected, rel=1e-5, abs=1e-7)


@pytest.mark.parametrize("n", [2, 3])
def test_the_unbiased_loss_subtracts_the_subsets_variance_estimate(n):
    model = _model(subset_size=n, batch_size=3 * n, unbiased=True)
    _two_episodes(model)
    terms = _expected_terms(model, n, 3)
    biased = np.mean([(np.mean(r) - target) ** 2 for r, target, _ in terms])
    # rrd.py: r_var = mean(var_{n-1}(R̂_I) · coef / n), coef = 1 − n/T if n ≤ T (and T > 1) else 1
    coefficients = [1 - n / length if n <= length else 1.0 for _, _, length in terms]
    variance = np.mean(
        [np.var(r, ddof=1) * c / n for (r, _, _), c in zip(terms, coefficients, strict=True)]
    )
    assert variance > 0  # the correction is really exercised
    assert float(model.loss().detach()) == pytest.approx(biased - variance, rel=1e-5, abs=1e-7)


def test_a_one_step_episode_has_no_variance_term():
    from delayed_rl.deep.return_decomposition import ReturnDecompositionRewardModel

    factor = ReturnDecompositionRewardModel.variance_factor
    assert factor(4, 1) == 0.0 and factor(4, 2) == 1.0 and factor(4, 8) == 0.5 and factor(4, 4) == 0


def test_episodes_are_drawn_in_proportion_to_their_lengths():
    from delayed_rl.deep.return_decomposition import sample_episodes

    model = _model()
    for end in [True] + [False] * 8 + [True]:  # a 1-step and a 9-step episode
        model.add([0], [0], [0.0], [end])
    draws = 40_000
    drawn = sample_episodes(model, draws, "length")
    share = sum(length == 9 for _, _, length, _ in drawn) / draws
    sigma = math.sqrt(0.9 * 0.1 / draws)  # binomial standard error at the expected 0.9
    assert abs(share - 0.9) < 5 * sigma
    uniform = sample_episodes(model, draws, "uniform")
    share = sum(length == 9 for _, _, length, _ in uniform) / draws
    assert abs(share - 0.5) < 5 * math.sqrt(0.25 / draws)


def test_the_defaults_are_the_authors_and_xavier_initialises_the_layers():
    from torch import nn

    from delayed_rl.deep import ReturnDecompositionRewardModel

    model = ReturnDecompositionRewardModel(spaces.Box(-1, 1, (5,)), spaces.Box(-1, 1, (2,)))
    # common.py's rrd_args for MuJoCo and rrd.py's mlp_rrd
    assert model.hidden_sizes == (256, 256) and model.learning_rate == 3e-4
    assert model.batch_size // model.subset_size == 4 and model.subset_size == 64
    assert model.episode_draw == "length" and model.unbiased is False
    layers = [m for m in model.network.modules() if isinstance(m, nn.Linear)]
    assert [layer.out_features for layer in layers] == [256, 256, 1]
    for layer in layers:
        bound = math.sqrt(6 / (layer.in_features + layer.out_features))  # Glorot uniform
        assert float(layer.weight.detach().abs().max()) <= bound
        assert (
            float(layer.weight.detach().abs().max()) > 0.9 * bound
        )  # the full range, not PyTorch's
        assert float(layer.bias.detach().abs().max()) == 0.0
    pytorch = ReturnDecompositionRewardModel(
        spaces.Box(-1, 1, (5,)), spaces.Box(-1, 1, (2,)), initialisation="pytorch", seed=0
    )
    assert float(next(iter(pytorch.network.layers)).bias.detach().abs().max()) > 0


def test_the_paper_settings_make_a_model_from_a_mapping():
    from delayed_rl.deep import make_reward_model
    from delayed_rl.deep.return_decomposition import PAPER_SETTINGS

    box = spaces.Box(-1, 1, (3,))
    model = make_reward_model(
        {"type": "ReturnDecompositionRewardModel", **PAPER_SETTINGS, "unbiased": True}, box, box
    )
    assert model.unbiased and model.hidden_sizes == tuple(PAPER_SETTINGS["hidden_sizes"])
    assert model.reads_next_observation
    with pytest.raises(ValueError, match="state_change=True needs a Box"):
        make_reward_model({"type": "ReturnDecompositionRewardModel", **PAPER_SETTINGS}, OBS, ACT)


def test_a_saved_model_keeps_its_settings(tmp_path):
    from delayed_rl.deep import load_reward_model

    model = _model(subset_size=3, episode_draw="uniform", initialisation="pytorch", unbiased=True)
    _two_episodes(model)
    model.train(2)
    loaded = load_reward_model(model.save(tmp_path / "rrd.zip"))
    assert loaded.settings() == model.settings()
    assert float(loaded.loss().detach()) == float(model.loss().detach())


@pytest.mark.parametrize(
    ("settings", "error", "match"),
    [
        ({"episode_draw": "random"}, ValueError, "episode_draw"),
        ({"initialisation": "zeros"}, ValueError, "initialisation"),
        ({"unbiased": 1}, TypeError, "unbiased"),
        ({"unbiased": True, "subset_size": 1}, ValueError, "subset_size"),
        ({"subset_size": 0}, ValueError, "subset_size"),
    ],
)
def test_bad_settings_are_refused_by_name(settings, error, match):
    with pytest.raises(error, match=match):
        _model(**settings)


def test_the_network_reads_the_state_its_action_and_the_change():
    import torch

    from delayed_rl.deep import ReturnDecompositionRewardModel

    box = spaces.Box(-5, 5, (2,))
    model = ReturnDecompositionRewardModel(box, spaces.Box(-1, 1, (1,)), hidden_sizes=(), seed=0)
    (layer,) = [m for m in model.network.modules() if isinstance(m, torch.nn.Linear)]
    weights = [1.0, 10.0, 100.0, 1000.0, 10_000.0]  # s₁, s₂, a, (s − s′)₁, (s − s′)₂
    with torch.no_grad():
        layer.weight.copy_(torch.tensor([weights]))
        layer.bias.fill_(0.5)
    s, a, s_next = np.array([[1.0, 2.0]]), np.array([[3.0]]), np.array([[0.5, 4.0]])
    expected = 1.0 + 20.0 + 300.0 + 1000.0 * 0.5 + 10_000.0 * (2.0 - 4.0) + 0.5
    assert model.predict(s, a, s_next)[0] == pytest.approx(expected)
    with pytest.raises(ValueError, match="next_observations"):
        model.predict(s, a)
    plain = ReturnDecompositionRewardModel(box, box, state_change=False, seed=0)
    assert not plain.reads_next_observation and plain.predict(s, s).shape == (1,)


def test_the_on_policy_history_keeps_each_steps_next_observation():
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    from delayed_rl.deep import RelabelingRolloutBuffer, RewardModelCallback

    model_spec = {"type": "ReturnDecompositionRewardModel", "hidden_sizes": (8,), "seed": 0}
    env = make_vec_env("Pendulum-v1", n_envs=2, seed=0, env_kwargs={"max_episode_steps": 10})
    agent = PPO(
        "MlpPolicy",
        env,
        n_steps=16,
        batch_size=16,
        n_epochs=1,
        rollout_buffer_class=RelabelingRolloutBuffer,
        rollout_buffer_kwargs={"reward_model": model_spec},
        seed=0,
    )
    agent.learn(32, callback=RewardModelCallback())
    history = agent.rollout_buffer.reward_model.history
    steps = history.steps_added
    assert steps == 16  # 32 steps: 16 of each of the two sub-envs
    obs, following, ends = history.obs[:steps], history.next_obs[:steps], history.episode_end
    inside = ~ends[: steps - 1]  # within an episode, s′ is the next step's s
    np.testing.assert_array_equal(following[: steps - 1][inside], obs[1:steps][inside])
    ended = ends[: steps - 1]  # at an episode's end s′ is its terminal observation, not o_0
    assert ended.sum() == 2
    assert not np.isclose(following[: steps - 1][ended], obs[1:steps][ended]).all(axis=-1).any()
