"""The relabelling buffers and their callback, driven by stable-baselines3's own algorithms.

Off-policy (SAC, DQN): what the model learns from is what the env delivered, sampled rewards are
the model's ``R̂``, and learning is bit-identical with the diagnostic infos stripped. On-policy
(PPO): the model learns the env's rewards, not those SB3 adds ``γ·V`` to at truncations, and the
relabelled rewards keep that bootstrap. With several sub-envs the episodes the model sees are
each sub-env's own (under ``"flush"``, CartPole's episodes deliver their length). SB3's own
files (``save_replay_buffer``, ``save``) keep a working model. torch and SB3 are imported in
the tests' bodies (and a fixture), not at collection.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from support import same_tensors, torch_on_one_thread  # noqa: F401  (the fixture)

from delayed_rl.delays import Poisson
from delayed_rl.wrappers import RewardDelay

pytestmark = [pytest.mark.sb3, pytest.mark.usefixtures("torch_on_one_thread")]

DIAGNOSTIC_KEYS = (
    "undelayed_reward",
    "drawn_reward_delay",
    "pending_reward",
    "flushed_reward",
    "dropped_reward",
    "reward_arrivals",
)
"""What ``RewardDelay`` adds to ``info``."""


class StripInfo(gym.Wrapper):
    """Removes the delay wrapper's diagnostic keys from every ``info``."""

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        return obs, {k: v for k, v in info.items() if k not in DIAGNOSTIC_KEYS}

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        info = {k: v for k, v in info.items() if k not in DIAGNOSTIC_KEYS}
        assert not set(info) & set(DIAGNOSTIC_KEYS)
        return obs, reward, terminated, truncated, info


class Record(gym.Wrapper):
    """Records what the env delivered: rewards, episode ends, undelayed rewards."""

    def __init__(self, env):
        super().__init__(env)
        self.rewards, self.ends, self.undelayed = [], [], []

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.rewards.append(float(reward))
        self.ends.append(bool(terminated or truncated))
        self.undelayed.append(info.get("undelayed_reward"))
        return obs, reward, terminated, truncated, info


def pendulum(steps=50, lam=5.0, strip=False):
    env = RewardDelay(gym.make("Pendulum-v1", max_episode_steps=steps), Poisson(lam))
    return Record(StripInfo(env) if strip else env)


def cartpole(lam=3.0):
    return Record(RewardDelay(gym.make("CartPole-v1"), Poisson(lam)))


def deconvolution(env, **kwargs):
    from delayed_rl.deep import DeconvolutionRewardModel

    settings = {
        "delay": Poisson(3),
        "max_delay_estimate": 10,
        "hidden_sizes": (8,),
        "batch_size": 32,
        "window": 8,
        "warmup_updates": 20,
        "seed": 0,
        **kwargs,
    }
    return DeconvolutionRewardModel(env.observation_space, env.action_space, **settings)


def sac(env, model, n_steps=None):
    """SAC on ``env`` with ``model`` in a relabelling buffer (an n-step one with ``n_steps``)."""
    from stable_baselines3 import SAC

    from delayed_rl.deep import RelabelingNStepReplayBuffer, RelabelingReplayBuffer

    n_step = {} if n_steps is None else {"n_steps": n_steps}
    return SAC(
        "MlpPolicy",
        env,
        learning_starts=50,
        batch_size=32,
        buffer_size=2000,
        policy_kwargs={"net_arch": [16]},
        replay_buffer_class=RelabelingReplayBuffer
        if n_steps is None
        else RelabelingNStepReplayBuffer,
        replay_buffer_kwargs={"reward_model": model, **n_step},
        seed=0,
        device="cpu",
    )


def ppo(env, model, n_steps):
    from stable_baselines3 import PPO

    from delayed_rl.deep import RelabelingRolloutBuffer

    return PPO(
        "MlpPolicy",
        env,
        n_steps=n_steps,
        batch_size=n_steps,
        n_epochs=1,
        policy_kwargs={"net_arch": [8]},
        rollout_buffer_class=RelabelingRolloutBuffer,
        rollout_buffer_kwargs={"reward_model": model},
        seed=0,
        device="cpu",
    )


def params(module):
    return [p.detach().clone() for p in module.parameters()]


# ---------------------------------------------------------------------- off-policy
def test_sac_learns_the_same_bits_without_the_diagnostic_infos():
    from delayed_rl.deep import RewardModelCallback

    runs = []
    for strip in (False, True):
        env = pendulum(strip=strip)
        # the box action space as SAC stores it: squashed to [-1, 1]
        model = deconvolution(env, delay=None, max_delay_estimate=12)
        agent = sac(env, model)
        agent.learn(250, callback=RewardModelCallback())
        runs.append((env, model, agent))
    (env, model, agent), (stripped_env, stripped_model, stripped_agent) = runs
    assert model.updates_taken == stripped_model.updates_taken > 100
    assert same_tensors(params(model.network), params(stripped_model.network))
    assert same_tensors([model.delay_logits], [stripped_model.delay_logits])
    assert same_tensors(params(agent.policy), params(stripped_agent.policy))
    assert env.rewards == stripped_env.rewards
    assert np.isfinite(model.rmse()) and np.isnan(stripped_model.rmse())
    # what the model learned from is what the env delivered, as the buffer also keeps it
    delivered = np.float32(env.rewards)
    np.testing.assert_array_equal(model.history.reward[:250, 0], delivered)
    np.testing.assert_array_equal(agent.replay_buffer.delivered_rewards[:250, 0], delivered)
    np.testing.assert_array_equal(model.history.episode_end[:250, 0], env.ends)


def test_dqn_samples_are_relabelled_with_the_model():
    import torch
    from stable_baselines3 import DQN

    from delayed_rl.deep import RelabelingReplayBuffer

    env = cartpole()
    model = deconvolution(env)
    assert isinstance(model.actions.space, gym.spaces.Discrete)
    agent = DQN(
        "MlpPolicy",
        env,
        learning_starts=50,
        train_freq=4,
        batch_size=32,
        buffer_size=1000,
        policy_kwargs={"net_arch": [8]},
        replay_buffer_class=RelabelingReplayBuffer,
        replay_buffer_kwargs={"reward_model": model},
        seed=0,
        device="cpu",
    )
    agent.learn(300)
    buffer = agent.replay_buffer
    assert model.updates_taken > 200
    np.testing.assert_array_equal(buffer.delivered_rewards[:300, 0], np.float32(env.rewards))
    np.testing.assert_array_equal(model.history.reward[:300, 0], np.float32(env.rewards))
    np.testing.assert_array_equal(model.history.action[:300, 0], buffer.actions[:300, 0])
    batch = buffer.sample(64)
    obs, actions = batch.observations.numpy(), batch.actions.numpy()
    assert actions.dtype.kind == "i" and set(np.unique(actions)) <= {0, 1}
    predicted = model.predict(obs, actions)
    sampled = batch.rewards.numpy().ravel()
    np.testing.assert_allclose(sampled, predicted, rtol=1e-6, atol=1e-6)
    # the delivered rewards of the same rows are not what was sampled
    rows = zip(buffer.observations[:300, 0], buffer.delivered_rewards[:300, 0], strict=True)
    delivered = {tuple(o): r for o, r in rows}
    assert not np.allclose(sampled, [delivered[tuple(o)] for o in obs])
    with torch.no_grad():
        assert torch.isfinite(agent.q_net(batch.observations)).all()


# ---------------------------------------------------------------------- on-policy
def test_ppo_learns_env_rewards_and_keeps_the_truncation_bootstrap():
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    from delayed_rl.deep import RewardModelCallback

    class Check(BaseCallback):
        """At each rollout's end, what SB3 added at truncations, by the unchanged policy."""

        def _on_rollout_start(self):
            self.steps = []

        def _on_step(self):
            done, info = bool(self.locals["dones"][0]), self.locals["infos"][0]
            self.steps.append(
                (done, info.get("TimeLimit.truncated", False), info.get("terminal_observation"))
            )
            return True

        def _on_rollout_end(self):
            buffer = self.model.rollout_buffer
            history = buffer.reward_model.history
            rows = history.rows(history.steps_added - 32, history.steps_added)
            # R̂ of what the env saw and did: the actions as executed, clipped to [-2, 2]
            np.testing.assert_array_equal(
                history.action[rows, 0], np.clip(buffer.actions[:, 0], -2.0, 2.0)
            )
            relabelled = buffer.reward_model.predict(history.obs[rows, 0], history.action[rows, 0])
            added = buffer.rewards[:, 0] - relabelled
            truncations = 0
            for i, (done, truncated, terminal) in enumerate(self.steps):
                if done and truncated:
                    truncations += 1
                    obs = self.model.policy.obs_to_tensor(terminal)[0]
                    with torch.no_grad():
                        value = float(self.model.policy.predict_values(obs)[0, 0])
                    bootstrap = self.model.gamma * value
                    assert bootstrap != 0.0
                    assert buffer.bootstraps[i, 0] == pytest.approx(bootstrap, rel=1e-5, abs=1e-6)
                    assert added[i] == pytest.approx(bootstrap, rel=1e-4, abs=1e-5)
                else:
                    assert buffer.bootstraps[i, 0] == 0.0
                    assert added[i] == 0.0
            assert truncations == 3  # episodes of 10 steps in a rollout of 32
            self.model.checked = getattr(self.model, "checked", 0) + 1

    env = pendulum(steps=10, lam=2.0)
    model = deconvolution(env, max_delay_estimate=6, window=4, warmup_updates=16)
    agent = ppo(env, model, n_steps=32)
    agent.learn(96, callback=[RewardModelCallback(), Check()])
    assert agent.checked == 3
    assert model.updates_taken > 0
    # the model learned from the env's rewards (with the bootstrap, SB3's rewards differ)
    assert model.history.steps_added == 96 == len(env.rewards)
    np.testing.assert_array_equal(model.history.reward[:96, 0], np.float32(env.rewards))
    np.testing.assert_array_equal(model.history.episode_end[:96, 0], env.ends)
    assert sum(env.ends) == 9
    buffer = agent.rollout_buffer
    np.testing.assert_array_equal(buffer.delivered_rewards[:, 0], np.float32(env.rewards[64:]))


def test_ppo_without_the_callback_refuses_to_add():
    from stable_baselines3 import PPO

    from delayed_rl.deep import RelabelingRolloutBuffer

    env = pendulum(steps=10)
    agent = PPO(
        "MlpPolicy",
        env,
        n_steps=16,
        batch_size=16,
        policy_kwargs={"net_arch": [8]},
        rollout_buffer_class=RelabelingRolloutBuffer,
        rollout_buffer_kwargs={"reward_model": deconvolution(env)},
        device="cpu",
    )
    with pytest.raises(RuntimeError, match="RewardModelCallback"):
        agent.learn(16)


def test_the_callback_needs_a_relabelling_buffer():
    from stable_baselines3 import PPO

    from delayed_rl.deep import RewardModelCallback

    agent = PPO("MlpPolicy", pendulum(), n_steps=16, batch_size=16, device="cpu")
    with pytest.raises(TypeError, match="needs an algorithm with a relabelling buffer"):
        agent.learn(16, callback=RewardModelCallback())


@pytest.mark.parametrize("kind", ["RelabelingReplayBuffer", "RelabelingRolloutBuffer"])
def test_buffers_refuse_what_is_not_a_reward_model(kind):
    import delayed_rl.deep as deep

    env = pendulum()
    with pytest.raises(TypeError, match="reward_model must be a delayed_rl.deep reward model"):
        getattr(deep, kind)(16, env.observation_space, env.action_space, reward_model="model")


# ---------------------------------------------------------------------- several sub-envs
@pytest.mark.parametrize("algorithm", ["PPO", "DQN"])
def test_each_sub_envs_episodes_are_its_own(algorithm):
    from stable_baselines3 import DQN, PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env

    from delayed_rl.deep import (
        RelabelingReplayBuffer,
        RelabelingRolloutBuffer,
        RewardModelCallback,
    )

    class Dones(BaseCallback):
        def _init_callback(self):
            self.dones = []

        def _on_step(self):
            self.dones.append(np.array(self.locals["dones"], dtype=bool))
            return True

    n_envs = 3
    vec = make_vec_env(cartpole, n_envs=n_envs, seed=0)
    model = deconvolution(vec, updates_per_step=0, warmup_updates=0)  # the stream only
    common = {"policy_kwargs": {"net_arch": [8]}, "seed": 0, "device": "cpu"}
    if algorithm == "PPO":
        agent = PPO(
            "MlpPolicy",
            vec,
            n_steps=64,
            batch_size=64,
            n_epochs=1,
            rollout_buffer_class=RelabelingRolloutBuffer,
            rollout_buffer_kwargs={"reward_model": model},
            **common,
        )
    else:
        agent = DQN(
            "MlpPolicy",
            vec,
            learning_starts=64,
            buffer_size=1000,
            replay_buffer_class=RelabelingReplayBuffer,
            replay_buffer_kwargs={"reward_model": model},
            **common,
        )
    recorder = Dones()
    agent.learn(64 * n_envs, callback=[RewardModelCallback(), recorder])
    history = model.history
    steps = history.steps_added
    assert history.n_envs == n_envs and steps == 64
    dones = np.stack(recorder.dones)
    np.testing.assert_array_equal(history.episode_end[:steps], dones)
    records = [vec.envs[i].env for i in range(n_envs)]  # Monitor(Record(...))
    for i, record in enumerate(records):
        assert isinstance(record, Record)
        np.testing.assert_array_equal(history.reward[:steps, i], np.float32(record.rewards))
        np.testing.assert_array_equal(dones[:, i], record.ends)
    # the finished episodes, by sub-env, from the dones: under "flush" each delivered its return,
    # CartPole's length (a reward of 1 a step), and so the boundaries are the wrapper's
    expected = []
    for i in range(n_envs):
        first = 0
        for end in np.flatnonzero(dones[:, i]):
            expected.append((i, first, int(end) + 1 - first))
            first = int(end) + 1
    found = sorted((env, first, length) for env, first, length, _ in history.episodes)
    assert found == sorted(expected)
    assert len(found) >= 2 * n_envs
    for _, _, length, total in history.episodes:
        assert total == float(length)
    for i in range(n_envs):
        ids = history.episode_ids(i, 0, steps)
        np.testing.assert_array_equal(ids, np.concatenate(([0], np.cumsum(dones[:-1, i]))))


# ---------------------------------------------------------------------- SB3's files
# ---------------------------------------------------------------------- learn() again
def episode_sums(env, bounds):
    """The sums of what ``env`` delivered over the ``(first, length)`` step ranges."""
    return [pytest.approx(sum(env.rewards[first : first + length])) for first, length in bounds]


@pytest.mark.parametrize("reset", [True, False])
def test_learning_again_cuts_the_episode_the_reset_left_open(reset):
    from delayed_rl.deep import RewardModelCallback

    env = pendulum()  # episodes of 50 steps: the first learn() ends 25 steps into the second
    model = deconvolution(env)
    agent = sac(env, model)
    agent.learn(75, callback=RewardModelCallback())
    agent.learn(75, callback=RewardModelCallback(), reset_num_timesteps=reset)
    history = model.history
    assert history.steps_added == 150 == len(env.rewards)
    # a reset (SB3's default) ends the open episode at step 74, cut; without one it goes on
    assert np.flatnonzero(history.episode_cut[:150, 0]).tolist() == ([74] if reset else [])
    bounds = [(0, 50), (75, 50)] if reset else [(0, 50), (50, 50), (100, 50)]
    assert [(first, length) for _, first, length, _ in history.episodes] == bounds
    assert [total for *_, total in history.episodes] == episode_sums(env, bounds)
    assert history.episode_ids(0, 0, 150).tolist() == (
        [0] * 50 + [1] * 25 + [2] * 50 + [3] * 25 if reset else [0] * 50 + [1] * 50 + [2] * 50
    )


def test_ppo_learning_again_cuts_the_episode_the_reset_left_open():

    from delayed_rl.deep import RewardModelCallback

    env = pendulum(steps=10)  # rollouts of 32 steps: each learn() leaves 2 steps open
    model = deconvolution(env, max_delay_estimate=6, window=4, warmup_updates=16)
    agent = ppo(env, model, n_steps=32)
    agent.learn(32, callback=RewardModelCallback())
    agent.learn(32, callback=RewardModelCallback())
    history = model.history
    assert np.flatnonzero(history.episode_cut[:64, 0]).tolist() == [31]
    bounds = [(0, 10), (10, 10), (20, 10), (32, 10), (42, 10), (52, 10)]
    assert [(first, length) for _, first, length, _ in history.episodes] == bounds
    assert [total for *_, total in history.episodes] == episode_sums(env, bounds)


def test_a_loaded_replay_buffer_cuts_the_episode_its_new_env_does_not_go_on_with(tmp_path):
    env = pendulum()
    agent = sac(env, deconvolution(env))
    agent.learn(75)
    agent.save_replay_buffer(tmp_path / "buffer.pkl")
    fresh_env = pendulum()
    fresh = sac(fresh_env, deconvolution(fresh_env, seed=9))
    fresh.load_replay_buffer(tmp_path / "buffer.pkl")
    fresh.learn(50, reset_num_timesteps=False)  # a new algorithm resets its env all the same
    history = fresh.replay_buffer.reward_model.history
    assert np.flatnonzero(history.episode_cut[:125, 0]).tolist() == [74]
    bounds = [(first, length) for _, first, length, _ in history.episodes]
    assert bounds == [(0, 50), (75, 50)]


def test_a_buffer_reloaded_into_its_own_algorithm_goes_on_without_a_cut(tmp_path):
    env = pendulum()
    agent = sac(env, deconvolution(env))
    agent.learn(75)
    agent.save_replay_buffer(tmp_path / "buffer.pkl")
    agent.load_replay_buffer(tmp_path / "buffer.pkl")
    agent.learn(50, reset_num_timesteps=False)  # no reset: the episode of steps 50-99 goes on
    history = agent.replay_buffer.reward_model.history
    assert not history.episode_cut[:125].any()
    assert [(first, length) for _, first, length, _ in history.episodes] == [(0, 50), (50, 50)]


def test_sub_envs_are_cut_together_and_an_n_step_sum_stops_at_the_cut():
    from stable_baselines3.common.vec_env import DummyVecEnv

    envs = [pendulum(steps=50), pendulum(steps=30)]
    venv = DummyVecEnv([lambda env=env: env for env in envs])
    model = deconvolution(envs[0])
    agent = sac(venv, model, n_steps=3)
    agent.learn(2 * 40)  # 40 steps of each: sub-env 1's first episode ends at its step 29
    agent.learn(2 * 10)
    history, buffer = model.history, agent.replay_buffer
    assert np.flatnonzero(history.episode_cut[:50, 0]).tolist() == [39]
    assert np.flatnonzero(history.episode_cut[:50, 1]).tolist() == [39]
    # the cut rows become truncations (their next observations are bootstrapped from), and
    # nothing else does: sub-env 1's row 29 ended its episode by SB3's time limit already
    assert np.flatnonzero(buffer.timeouts[:50, 0]).tolist() == [39]
    assert np.flatnonzero(buffer.timeouts[:50, 1]).tolist() == [29, 39]
    assert not buffer.dones[39].any()


def test_replay_buffer_and_algorithm_files_keep_a_working_model(tmp_path):
    from stable_baselines3 import SAC

    from delayed_rl.deep import RewardModel, RewardModelCallback

    env = pendulum()
    model = deconvolution(env, delay=None, max_delay_estimate=12)
    agent = sac(env, model)
    agent.learn(120, callback=RewardModelCallback())
    probe_obs = np.random.default_rng(0).uniform(-1, 1, (16, 3)).astype(np.float32)
    probe_actions = np.linspace(-1, 1, 16, dtype=np.float32)[:, None]
    expected = model.predict(probe_obs, probe_actions)
    taken = model.updates_taken

    agent.save_replay_buffer(tmp_path / "buffer.pkl")
    fresh = sac(pendulum(), deconvolution(env, delay=None, max_delay_estimate=12, seed=9))
    fresh.load_replay_buffer(tmp_path / "buffer.pkl")
    loaded = fresh.replay_buffer.reward_model
    assert isinstance(loaded, RewardModel) and loaded is not model
    np.testing.assert_array_equal(loaded.predict(probe_obs, probe_actions), expected)
    assert loaded.history.steps_added == 120
    np.testing.assert_array_equal(loaded.delay_pmf, model.delay_pmf)
    fresh.learn(60, reset_num_timesteps=False)
    assert loaded.updates_taken == taken + 60

    agent.save(tmp_path / "sac.zip")
    restored = SAC.load(tmp_path / "sac.zip", env=pendulum(), device="cpu")
    restored_model = restored.replay_buffer.reward_model
    assert isinstance(restored_model, RewardModel) and restored_model is not model
    np.testing.assert_array_equal(restored_model.predict(probe_obs, probe_actions), expected)
    restored.learn(60, reset_num_timesteps=False, callback=RewardModelCallback())
    assert restored_model.updates_taken == taken + 60
    assert restored_model.history.steps_added == 180
    batch = restored.replay_buffer.sample(8)
    np.testing.assert_allclose(
        batch.rewards.numpy().ravel(),
        restored_model.predict(batch.observations.numpy(), batch.actions.numpy()),
        rtol=1e-6,
        atol=1e-6,
    )


def test_ppo_file_keeps_its_rollout_model(tmp_path):
    from stable_baselines3 import PPO

    from delayed_rl.deep import RewardModelCallback

    env = pendulum(steps=10)
    model = deconvolution(env, warmup_updates=8)
    agent = ppo(env, model, n_steps=16)
    agent.learn(32, callback=RewardModelCallback())
    agent.save(tmp_path / "ppo.zip")
    restored = PPO.load(tmp_path / "ppo.zip", env=pendulum(steps=10), device="cpu")
    restored_model = restored.rollout_buffer.reward_model
    obs, actions = np.zeros((4, 3), np.float32), np.zeros((4, 1), np.float32)
    np.testing.assert_array_equal(restored_model.predict(obs, actions), model.predict(obs, actions))
    taken = restored_model.updates_taken
    restored.learn(16, reset_num_timesteps=False, callback=RewardModelCallback())
    assert restored_model.updates_taken == taken + 16


def test_a_buffer_makes_its_reward_model_from_a_mapping_for_its_spaces():
    from delayed_rl.deep import DeconvolutionRewardModel, RelabelingReplayBuffer

    env = gym.make("Pendulum-v1")
    spec = {"type": "DeconvolutionRewardModel", "delay": None, "max_delay_estimate": 7, "seed": 3}
    buffer = RelabelingReplayBuffer(100, env.observation_space, env.action_space, reward_model=spec)
    model = buffer.reward_model
    assert isinstance(model, DeconvolutionRewardModel)
    assert (model.max_delay_estimate, model.seed, model.delay) == (7, 3, None)
    assert spec == {
        "type": "DeconvolutionRewardModel",
        "delay": None,
        "max_delay_estimate": 7,
        "seed": 3,
    }


@pytest.mark.parametrize(
    ("spec", "error", "message"),
    [
        ([1, 2], TypeError, "reward_model must be a delayed_rl.deep reward model or a mapping"),
        ({"delay": 3}, TypeError, "reward_model's 'type' must be a class name"),
        (
            {"type": "Sequential"},
            ValueError,
            "must be one of .*'ReturnRegressionRewardModel'.*got 'Sequential'",
        ),
        ({"type": "ReturnRegressionRewardModel", "hidden_sizes": (0,)}, ValueError, "hidden_sizes"),
        ({"type": "ReturnRegressionRewardModel", "window": 3}, TypeError, "window"),
    ],
)
def test_a_bad_reward_model_mapping_is_refused_naming_what_is_wrong(spec, error, message):
    from delayed_rl.deep import RelabelingReplayBuffer

    env = gym.make("Pendulum-v1")
    with pytest.raises(error, match=message):
        RelabelingReplayBuffer(100, env.observation_space, env.action_space, reward_model=spec)


def test_a_reward_model_made_for_other_spaces_is_refused():
    from delayed_rl.deep import RelabelingRolloutBuffer, ReturnRegressionRewardModel

    cartpole, pendulum = gym.make("CartPole-v1"), gym.make("Pendulum-v1")
    model = ReturnRegressionRewardModel(cartpole.observation_space, cartpole.action_space, seed=0)
    with pytest.raises(ValueError, match="reward_model was made for the observation_space"):
        RelabelingRolloutBuffer(
            8, pendulum.observation_space, pendulum.action_space, reward_model=model
        )


def test_a_model_reading_the_next_observation_is_refused_with_optimize_memory_usage():
    """SB3 then keeps no next observations: an episode's last s′ would be the next one's first."""
    from delayed_rl.deep import RelabelingReplayBuffer

    env = gym.make("Pendulum-v1")
    spaces = (env.observation_space, env.action_space)
    shared = {"optimize_memory_usage": True, "handle_timeout_termination": False}
    with pytest.raises(ValueError, match=r"optimize_memory_usage=True with .*state_change=True"):
        RelabelingReplayBuffer(
            100, *spaces, reward_model={"type": "ReturnDecompositionRewardModel"}, **shared
        )
    spec = {"type": "ReturnDecompositionRewardModel", "state_change": False}
    buffer = RelabelingReplayBuffer(100, *spaces, reward_model=spec, **shared)
    assert buffer.optimize_memory_usage and not buffer.reward_model.reads_next_observation


def test_a_saved_buffer_whose_model_reads_the_next_observation_is_refused_on_load():
    """A file from before the refusal: loading it would read s′ that SB3 did not keep."""
    import pickle

    from delayed_rl.deep import RelabelingReplayBuffer

    env = gym.make("Pendulum-v1")
    spec = {"type": "ReturnDecompositionRewardModel", "state_change": False}
    buffer = RelabelingReplayBuffer(
        100,
        env.observation_space,
        env.action_space,
        reward_model=spec,
        optimize_memory_usage=True,
        handle_timeout_termination=False,
    )
    assert pickle.loads(pickle.dumps(buffer)).optimize_memory_usage  # allowed: reads no s′
    buffer.reward_model.state_change = True  # as the earlier code let it be
    with pytest.raises(ValueError, match=r"optimize_memory_usage=True with .*state_change=True"):
        pickle.loads(pickle.dumps(buffer))
