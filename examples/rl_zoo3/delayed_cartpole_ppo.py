"""rl-zoo3 hyperparameters: PPO on CartPole-v1, Poisson(20)-delayed rewards, a reward model.

rl-zoo3 reads a Python hyperparameter file's ``hyperparams`` dict, so the rollout buffer is the
class itself (from YAML, rl-zoo3 would pass its name on as text). Run, from the repository
root::

    python -m rl_zoo3.train --algo ppo --env CartPole-v1 --log-folder runs/zoo \
      --conf-file examples/rl_zoo3/delayed_cartpole_ppo.py

The buffer builds the ``reward_model`` mapping's model for the env's spaces;
``RewardModelCallback`` hands it the env's own rewards (see ``delayed_rl.deep.buffers``). The
model takes its seed from the algorithm's (rl-zoo3's ``--seed``).
"""

from delayed_rl.deep import RelabelingRolloutBuffer

hyperparams = {
    "CartPole-v1": {
        "env_wrapper": [{"delayed_rl.wrappers.RewardDelay": {"delay": 20}}],
        "n_envs": 4,
        "n_timesteps": 100_000,
        "policy": "MlpPolicy",
        "rollout_buffer_class": RelabelingRolloutBuffer,
        "rollout_buffer_kwargs": {
            "reward_model": {"type": "DeconvolutionRewardModel", "delay": 20}
        },
        "callback": "delayed_rl.deep.RewardModelCallback",
    }
}
