"""Reward models inside SB3's algorithms: seeds, resuming, every observation space, the schedule.

- **Same seed, same run**: SAC, TD3, DQN, PPO and sb3-contrib's TQC trained twice with one seed
  give the same bits through the object route (a model made with ``seed=None``) and the mapping
  route; an explicit model seed is kept; an unseeded algorithm leaves the model unseeded; and the
  algorithm's own random draws (numpy's and torch's global generators) are those of a run
  without a reward model.
- **Resume keeps the model**: SB3's flow (``load``, ``load_replay_buffer``, ``learn``, ``save``)
  leaves one live model, whose weights, counters, history and learned ``p`` round-trip exactly.
- **Every space SB3 takes**: ``Dict`` observations on both routes, images (SB3's CNN route),
  n-step returns on ``R̂``; HER and mismatched buffers refused by name.
- **What the env did**: under ``VecNormalize`` the on-policy model learns the original
  observations and rewards; it learns the executed (clipped) actions.
- **The schedule**: no training in ``add()``; before the warm-up the algorithm's batches carry
  the delivered rewards, after it ``R̂``.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from support import same_tensors, torch_on_one_thread  # noqa: F401  (the fixture)

from delayed_rl.wrappers import RewardDelay

pytestmark = [pytest.mark.sb3, pytest.mark.usefixtures("torch_on_one_thread")]

SPEC = {"type": "DeconvolutionRewardModel", "delay": None, "max_delay_estimate": 8, "window": 8}
SMALL = {"batch_size": 32, "hidden_sizes": (16,), "warmup_updates": 20}


def pendulum(steps=40, lam=3.0):
    return RewardDelay(gym.make("Pendulum-v1", max_episode_steps=steps), lam)


def cartpole(lam=3.0):
    return RewardDelay(gym.make("CartPole-v1"), lam)


class Sensors(gym.Env):
    """A Dict-observation env: a position, a mode, bits and a small camera; reward = pos·action."""

    def __init__(self, image_side=36, length=25):
        self.observation_space = spaces.Dict(
            {
                "position": spaces.Box(-1.0, 1.0, (2,), np.float32),
                "mode": spaces.Discrete(3),
                "bits": spaces.MultiBinary(4),
                "camera": spaces.Box(0, 255, (image_side, image_side, 1), np.uint8),
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.length = length

    def _observe(self):
        self.obs = self.observation_space.sample()
        return self.obs

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.observation_space.seed(int(self.np_random.integers(2**31)))
        self.t = 0
        return self._observe(), {}

    def step(self, action):
        reward = float(self.obs["position"] @ np.asarray(action, dtype=np.float32))
        self.t += 1
        return self._observe(), reward, False, self.t >= self.length, {}


class Camera(gym.Env):
    """An image-observation env (36×36 grey, the smallest NatureCNN takes), two actions."""

    observation_space = spaces.Box(0, 255, (36, 36, 1), np.uint8)
    action_space = spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self._frame(), {}

    def _frame(self):
        self.level = int(self.np_random.integers(0, 256))
        return np.full((36, 36, 1), self.level, np.uint8)

    def step(self, action):
        reward = self.level / 255.0 if action == 1 else 0.0
        self.t += 1
        return self._frame(), reward, False, self.t >= 20, {}


def off_policy(name, env, spec, seed, **kwargs):
    import stable_baselines3 as sb3

    from delayed_rl.deep import RelabelingReplayBuffer

    if name == "TQC":
        from sb3_contrib import TQC as algorithm
    else:
        algorithm = getattr(sb3, name)
    return algorithm(
        "MlpPolicy",
        env,
        learning_starts=50,
        batch_size=32,
        buffer_size=1000,
        policy_kwargs={"net_arch": [16]},
        replay_buffer_class=kwargs.pop("replay_buffer_class", RelabelingReplayBuffer),
        replay_buffer_kwargs={"reward_model": spec, **kwargs.pop("buffer_kwargs", {})},
        seed=seed,
        device="cpu",
        **kwargs,
    )


def ppo(env, spec, seed, **kwargs):
    from stable_baselines3 import PPO

    from delayed_rl.deep import RelabelingRolloutBuffer

    return PPO(
        kwargs.pop("policy", "MlpPolicy"),
        env,
        n_steps=32,
        batch_size=32,
        n_epochs=1,
        policy_kwargs=kwargs.pop("policy_kwargs", {"net_arch": [16]}),
        rollout_buffer_class=kwargs.pop("rollout_buffer_class", RelabelingRolloutBuffer),
        rollout_buffer_kwargs={"reward_model": spec},
        seed=seed,
        device="cpu",
        **kwargs,
    )


def tensors(module):
    return [p.detach().clone() for p in module.state_dict().values()]


def model_of(agent):
    buffer = getattr(agent, "replay_buffer", None) or agent.rollout_buffer
    return buffer.reward_model


def train(name, route, seed, steps=150):
    """One short run of ``name`` with a deconvolution model given by ``route``."""
    from delayed_rl.deep import DeconvolutionRewardModel, RewardModelCallback

    env = cartpole() if name in ("DQN", "PPO") else pendulum()
    if route == "object":
        settings = {k: v for k, v in SPEC.items() if k != "type"}
        spec = DeconvolutionRewardModel(
            env.observation_space, env.action_space, **settings, **SMALL
        )
    else:
        spec = {**SPEC, **SMALL}
    agent = ppo(env, spec, seed) if name == "PPO" else off_policy(name, env, spec, seed)
    agent.learn(steps, callback=RewardModelCallback())
    return agent


# ---------------------------------------------------------------------- seeds
@pytest.mark.parametrize("name", ["SAC", "TD3", "DQN", "PPO", "TQC"])
@pytest.mark.parametrize("route", ["object", "mapping"])
def test_the_same_seed_gives_the_same_bits(name, route):
    from delayed_rl.deep.binding import reward_model_seed

    first, second = train(name, route, seed=7), train(name, route, seed=7)
    model, again = model_of(first), model_of(second)
    assert model.seed == again.seed == reward_model_seed(7)
    assert model.ready and model.updates_taken == again.updates_taken
    assert same_tensors(tensors(model.network), tensors(again.network))
    assert same_tensors(tensors(first.policy), tensors(second.policy))
    other = train(name, route, seed=8)
    assert model_of(other).seed == reward_model_seed(8) != model.seed
    assert not same_tensors(tensors(model_of(other).network), tensors(model.network))


def test_an_explicit_model_seed_is_kept_and_an_unseeded_run_stays_unseeded():
    from delayed_rl.deep import RelabelingReplayBuffer

    env = pendulum()
    kept = off_policy("SAC", env, {**SPEC, **SMALL, "seed": 5}, seed=7)
    assert model_of(kept).seed == 5 and not model_of(kept).takes_algorithm_seed
    seeds = {model_of(off_policy("SAC", env, {**SPEC, **SMALL}, seed=None)).seed for _ in "ab"}
    assert len(seeds) == 2
    # a buffer built by hand, outside an algorithm, leaves a mapping's model on fresh entropy
    by_hand = [
        RelabelingReplayBuffer(
            10, env.observation_space, env.action_space, reward_model={**SPEC, **SMALL}
        ).reward_model
        for _ in "ab"
    ]
    assert by_hand[0].seed != by_hand[1].seed and by_hand[0].takes_algorithm_seed


def test_the_algorithms_own_draws_are_those_of_a_run_without_a_model():
    import torch
    from stable_baselines3 import SAC

    def global_states(agent):
        return np.random.get_state()[1].copy(), torch.get_rng_state().clone()  # noqa: NPY002 (SB3 draws from the global generator)

    with_model = train("SAC", "mapping", seed=3)
    assert model_of(with_model).updates_taken > 100
    without = SAC(
        "MlpPolicy",
        pendulum(),
        learning_starts=50,
        batch_size=32,
        buffer_size=1000,
        policy_kwargs={"net_arch": [16]},
        seed=3,
        device="cpu",
    )
    without.learn(150)
    (numpy_with, torch_with), (numpy_without, torch_without) = map(
        global_states, (with_model, without)
    )
    np.testing.assert_array_equal(numpy_with, numpy_without)
    assert torch.equal(torch_with, torch_without)


# ---------------------------------------------------------------------- resume
@pytest.mark.parametrize("route", ["object", "mapping"])
def test_sb3s_resume_flow_keeps_the_live_model(tmp_path, route):
    from stable_baselines3 import SAC

    from delayed_rl.deep import RewardModel

    agent = train("SAC", route, seed=1, steps=120)
    agent.save(tmp_path / "a.zip")
    agent.save_replay_buffer(tmp_path / "a.pkl")

    resumed = SAC.load(tmp_path / "a.zip", env=pendulum(), device="cpu")
    resumed.load_replay_buffer(tmp_path / "a.pkl")
    live = resumed.replay_buffer.reward_model
    assert live is resumed.replay_buffer_kwargs["reward_model"]
    assert same_tensors(tensors(live.network), tensors(model_of(agent).network))
    resumed.learn(80, reset_num_timesteps=False)
    assert live.updates_taken == model_of(agent).updates_taken + 80
    resumed.save(tmp_path / "b.zip")
    resumed.save_replay_buffer(tmp_path / "b.pkl")

    restored = SAC.load(tmp_path / "b.zip", env=pendulum(), device="cpu")
    from_zip = restored.replay_buffer_kwargs["reward_model"]
    restored.load_replay_buffer(tmp_path / "b.pkl")
    from_buffer = restored.replay_buffer.reward_model
    assert from_buffer is from_zip is restored.replay_buffer_kwargs["reward_model"]
    for model in (from_zip, from_buffer):
        assert isinstance(model, RewardModel)
        assert same_tensors(tensors(model.network), tensors(live.network))
        assert same_tensors([model.delay_logits], [live.delay_logits])
        np.testing.assert_array_equal(model.delay_pmf, live.delay_pmf)
        assert (model.updates_taken, model.seed) == (live.updates_taken, live.seed)
        assert model.history.steps_added == live.history.steps_added == 200
        np.testing.assert_array_equal(model.history.reward, live.history.reward)
        assert model.rng.bit_generator.state == live.rng.bit_generator.state
        assert same_tensors(
            [v for s in model.optimizer.state.values() for v in s.values()],
            [v for s in live.optimizer.state.values() for v in s.values()],
        )


def test_a_buffer_loaded_in_the_same_process_trains_the_users_model(tmp_path):
    agent = train("SAC", "object", seed=2, steps=100)
    users = agent.replay_buffer_kwargs["reward_model"]
    agent.save_replay_buffer(tmp_path / "buffer.pkl")
    agent.load_replay_buffer(tmp_path / "buffer.pkl")
    assert agent.replay_buffer.reward_model is users
    taken = users.updates_taken
    agent.learn(30, reset_num_timesteps=False)
    assert users.updates_taken == taken + 30


def test_ppo_saves_its_live_model_from_a_mapping(tmp_path):
    from stable_baselines3 import PPO

    agent = train("PPO", "mapping", seed=4, steps=96)
    live = model_of(agent)
    agent.save(tmp_path / "ppo.zip")
    restored = PPO.load(tmp_path / "ppo.zip", env=cartpole(), device="cpu")
    assert model_of(restored) is restored.rollout_buffer_kwargs["reward_model"]
    assert same_tensors(tensors(model_of(restored).network), tensors(live.network))
    assert model_of(restored).updates_taken == live.updates_taken


# ---------------------------------------------------------------------- spaces
def test_dict_observations_train_and_relabel_off_policy():
    from stable_baselines3 import SAC

    from delayed_rl.deep import RelabelingDictReplayBuffer, RewardModelCallback

    env = RewardDelay(Sensors(), 2.0)
    agent = SAC(
        "MultiInputPolicy",
        env,
        learning_starts=40,
        batch_size=16,
        buffer_size=500,
        policy_kwargs={"net_arch": [16]},
        replay_buffer_class=RelabelingDictReplayBuffer,
        replay_buffer_kwargs={"reward_model": {**SPEC, **SMALL}},
        seed=0,
        device="cpu",
    )
    agent.learn(100, callback=RewardModelCallback())
    buffer = agent.replay_buffer
    model = buffer.reward_model
    assert model.ready and set(model.history.obs) == set(env.observation_space.spaces)
    batch = buffer.sample(16)
    observations = {key: value.numpy() for key, value in batch.observations.items()}
    np.testing.assert_allclose(
        batch.rewards.numpy().ravel(),
        model.predict(observations, batch.actions.numpy()),
        rtol=1e-6,
        atol=1e-6,
    )


def test_dict_observations_train_and_relabel_on_policy():
    from stable_baselines3.common.env_util import make_vec_env

    from delayed_rl.deep import RelabelingDictRolloutBuffer, RewardModelCallback

    envs = make_vec_env(lambda: RewardDelay(Sensors(), 2.0), n_envs=2, seed=0)
    agent = ppo(
        envs,
        {**SPEC, **SMALL},
        0,
        policy="MultiInputPolicy",
        rollout_buffer_class=RelabelingDictRolloutBuffer,
    )
    agent.learn(128, callback=RewardModelCallback())
    buffer, model = agent.rollout_buffer, model_of(agent)
    assert model.ready and model.history.steps_added == 64
    rows = model.history.rows(32, 64)
    for key, values in buffer.observations.items():  # SB3 flattened them env by env to train
        stored = values.reshape(2, 32, *values.shape[1:]).swapaxes(0, 1)
        np.testing.assert_array_equal(model.history.obs[key][rows], stored)
    steps, envs = rows[:, None], np.arange(2)[None, :]
    relabelled = model.reward_tensor(
        model.history.observations_at(steps, envs), model.history.actions_at(steps, envs)
    ).numpy()
    np.testing.assert_allclose(
        buffer.rewards, relabelled.reshape(32, 2) + buffer.bootstraps, rtol=1e-6, atol=1e-6
    )


def test_images_go_through_sb3s_cnn_route():
    from stable_baselines3.common.env_util import make_vec_env

    from delayed_rl.deep import RewardModelCallback

    envs = make_vec_env(lambda: RewardDelay(Camera(), 2.0), n_envs=1, seed=0)
    agent = ppo(envs, {**SPEC, **SMALL}, 0, policy="CnnPolicy", policy_kwargs={})
    agent.learn(64, callback=RewardModelCallback())
    model = model_of(agent)
    # SB3 moved the channel first; the model was made for the algorithm's space
    assert model.observations.space.shape == (1, 36, 36)
    assert model.history.obs.dtype == np.uint8
    assert model.network.observation_features.cnn is not None
    assert model.ready


def test_n_step_returns_sum_r_hat_over_their_steps():
    from delayed_rl.deep import RelabelingNStepReplayBuffer

    gamma, n = 0.9, 3
    agent = off_policy(
        "SAC",
        pendulum(steps=20),
        {**SPEC, **SMALL},
        0,
        replay_buffer_class=RelabelingNStepReplayBuffer,
        buffer_kwargs={"n_steps": n, "gamma": gamma},
    )
    agent.learn(120)
    buffer = agent.replay_buffer
    model = buffer.reward_model
    # SB3 samples from numpy's global generator: seed it, and read its draw back
    np.random.seed(11)  # noqa: NPY002
    batch = buffer.sample(32)
    np.random.seed(11)  # noqa: NPY002
    inds = np.random.randint(0, buffer.pos, size=32)  # noqa: NPY002 (BaseBuffer.sample's draw)
    obs, actions = buffer.observations[:120, 0], buffer.actions[:120, 0]
    rewards = model.predict(obs, actions)
    ends = buffer.dones[:120, 0].astype(bool) | buffer.timeouts[:120, 0].astype(bool)
    expected = []
    for i in inds:
        total, discount = 0.0, 1.0
        for k in range(n):
            total += discount * float(rewards[i + k])
            discount *= gamma
            if ends[i + k] or i + k + 1 >= buffer.pos:
                break
        expected.append(total)
    np.testing.assert_allclose(batch.rewards.numpy().ravel(), expected, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize(
    ("build", "error", "message"),
    [
        (
            lambda: off_policy("SAC", pendulum(), {**SPEC, **SMALL}, 0, n_steps=3),
            ValueError,
            r"SAC\(n_steps=3\) with RelabelingReplayBuffer: SB3 ignores n_steps",
        ),
        (
            lambda: off_policy(
                "SAC",
                pendulum(),
                {**SPEC, **SMALL},
                0,
                n_steps=3,
                replay_buffer_class=__import__(
                    "delayed_rl.deep", fromlist=["x"]
                ).RelabelingNStepReplayBuffer,
                buffer_kwargs={"n_steps": 2},
            ),
            ValueError,
            r"n_steps=2 differs from SAC\(n_steps=3\)",
        ),
        (
            lambda: off_policy(
                "SAC", pendulum(), {**SPEC, **SMALL}, 0, buffer_kwargs={"n_steps": 2}
            ),
            TypeError,
            "RelabelingReplayBuffer takes no n_steps: for n-step returns use "
            "RelabelingNStepReplayBuffer",
        ),
        (
            lambda: off_policy(
                "SAC",
                pendulum(),
                {**SPEC, **SMALL},
                0,
                buffer_kwargs={"goal_selection_strategy": "future", "n_sampled_goal": 4},
            ),
            TypeError,
            "HER recomputes rewards itself",
        ),
        (
            lambda: off_policy("SAC", pendulum(), {**SPEC, **SMALL}, 0, buffer_kwargs={"x": 1}),
            TypeError,
            r"unexpected keyword arguments \['x'\]",
        ),
    ],
)
def test_settings_sb3_would_ignore_or_misuse_are_refused(build, error, message):
    with pytest.raises(error, match=message):
        build()


def test_dict_spaces_and_plain_buffers_point_to_each_other():
    import delayed_rl.deep as deep

    sensors, plain = Sensors(), gym.make("Pendulum-v1")
    with pytest.raises(TypeError, match="use RelabelingDictReplayBuffer"):
        deep.RelabelingReplayBuffer(
            8, sensors.observation_space, sensors.action_space, reward_model={**SPEC}
        )
    with pytest.raises(TypeError, match="use RelabelingRolloutBuffer"):
        deep.RelabelingDictRolloutBuffer(
            8, plain.observation_space, plain.action_space, reward_model={**SPEC}
        )
    tuple_space = spaces.Tuple((spaces.Discrete(2), spaces.Discrete(3)))
    with pytest.raises(TypeError, match=r"observation_space must be a gymnasium Box.*Tuple"):
        deep.RelabelingReplayBuffer(8, tuple_space, plain.action_space, reward_model={**SPEC})


def test_the_callback_refuses_her_saying_why():
    from stable_baselines3 import SAC, HerReplayBuffer

    from delayed_rl.deep import RewardModelCallback

    class Goal(gym.Env):
        observation_space = spaces.Dict(
            {
                key: spaces.Box(-1.0, 1.0, (2,), np.float32)
                for key in ("observation", "achieved_goal", "desired_goal")
            }
        )
        action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            return self.observation_space.sample(), {}

        def step(self, action):
            return self.observation_space.sample(), 0.0, False, False, {}

        def compute_reward(self, achieved, desired, info):
            return -np.linalg.norm(achieved - desired, axis=-1)

    agent = SAC("MultiInputPolicy", Goal(), replay_buffer_class=HerReplayBuffer, device="cpu")
    with pytest.raises(TypeError, match="HER recomputes rewards itself"):
        agent.learn(2, callback=RewardModelCallback())


# ---------------------------------------------------------------------- what the env did
def test_under_vec_normalize_the_model_learns_the_original_stream():
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    from delayed_rl.deep import RewardModelCallback

    class Seen(gym.Wrapper):
        """Records each observation an action is taken at, and each reward, as the env gave them."""

        def reset(self, **kwargs):
            self.seen, self.rewards = [], []
            obs, info = self.env.reset(**kwargs)
            self.obs = obs
            return obs, info

        def step(self, action):
            self.seen.append(self.obs)
            obs, reward, terminated, truncated, info = self.env.step(action)
            self.obs = obs
            self.rewards.append(reward)
            return obs, reward, terminated, truncated, info

    vec = VecNormalize(make_vec_env(lambda: Seen(pendulum(steps=500)), n_envs=1, seed=0))
    agent = ppo(vec, {**SPEC, **SMALL}, 0)
    agent.learn(96, callback=RewardModelCallback())
    model, buffer = model_of(agent), agent.rollout_buffer
    seen = vec.venv.envs[0].env  # Monitor(Seen(...))
    rows = model.history.rows(0, 96)
    np.testing.assert_array_equal(model.history.obs[rows, 0], np.float32(seen.seen))
    # SB3's vector env holds rewards as float32, before VecNormalize as after
    np.testing.assert_array_equal(model.history.reward[rows, 0], np.float32(seen.rewards))
    assert not np.allclose(buffer.observations, model.history.obs[rows[-32:], 0])
    # the relabelled rewards are R̂ normalised as the env's rewards are
    last = rows[-32:]
    predicted = model.reward_tensor(model.history.obs[last], model.history.action[last]).numpy()
    np.testing.assert_allclose(
        buffer.rewards,
        vec.normalize_reward(predicted[:, None]) + buffer.bootstraps,
        rtol=1e-5,
        atol=1e-6,
    )


def test_the_model_learns_the_actions_the_env_executed():
    agent = ppo(pendulum(), {**SPEC, **SMALL}, 0, policy_kwargs={"log_std_init": 1.5})
    from delayed_rl.deep import RewardModelCallback

    agent.learn(64, callback=RewardModelCallback())
    model, buffer = model_of(agent), agent.rollout_buffer
    stored = buffer.actions  # one sub-env: (32, 1)
    assert np.abs(stored).max() > 2.0  # PPO stores actions before clipping them
    rows = model.history.rows(32, 64)
    np.testing.assert_array_equal(model.history.action[rows, 0], np.clip(stored, -2.0, 2.0))


# ---------------------------------------------------------------------- the schedule
def test_before_the_warm_up_batches_carry_the_delivered_rewards_then_r_hat():
    from delayed_rl.deep import ReturnDecompositionRewardModel

    env = pendulum(steps=100)
    model = ReturnDecompositionRewardModel(
        env.observation_space, env.action_space, seed=0, batch_size=32, warmup_updates=30
    )
    agent = off_policy("SAC", env, model, 0)
    agent.learn(80)  # SAC trains from step 50; RRD has no finished episode before step 100
    buffer = agent.replay_buffer
    assert model.updates_taken == 0 and not model.ready
    batch = buffer.sample(32)
    delivered = dict(
        zip(map(bytes, buffer.observations[:80, 0]), buffer.delivered_rewards[:80, 0], strict=True)
    )
    sampled = [delivered[bytes(o)] for o in batch.observations.numpy()]
    np.testing.assert_array_equal(batch.rewards.numpy().ravel(), sampled)
    agent.learn(30, reset_num_timesteps=False)
    assert model.ready and model.updates_taken == 110 + 30  # owed (1 a step) + warm-up, at once
    batch = buffer.sample(32)
    np.testing.assert_allclose(
        batch.rewards.numpy().ravel(),
        model.predict(
            batch.observations.numpy(), batch.actions.numpy(), batch.next_observations.numpy()
        ),
        rtol=1e-6,
        atol=1e-6,
    )


def test_storing_a_transition_never_trains():
    from delayed_rl.deep import RelabelingReplayBuffer

    env = pendulum()
    buffer = RelabelingReplayBuffer(
        100, env.observation_space, env.action_space, reward_model={**SPEC, **SMALL, "seed": 0}
    )
    before = tensors(buffer.reward_model.network)
    rng = np.random.default_rng(0)
    for step in range(60):
        obs = rng.uniform(-1, 1, (1, 3)).astype(np.float32)
        action = rng.uniform(-1, 1, (1, 1)).astype(np.float32)
        buffer.add(obs, obs, action, np.array([1.0]), np.array([step % 20 == 19]), [{}])
    assert buffer.reward_model.updates_taken == 0
    assert same_tensors(before, tensors(buffer.reward_model.network))
    buffer.sample(8)
    assert buffer.reward_model.updates_taken == 60 + 20
