"""Deep RL under delays: reward models for SB3, and SAC for late observations and actions.

A reward model learns ``R̂(s, a)`` from the rewards an env delivered (anonymously: it never
reads when a reward was emitted), and a relabelling buffer hands stable-baselines3's algorithms
``R̂`` in place of the delayed rewards:

- :class:`DeconvolutionRewardModel`: ``R̂`` fitted so that its convolution with the delay's pmf
  ``p`` explains the delivered rewards; ``p`` known or learned;
- :class:`ReturnDecompositionRewardModel` (RRD) and :class:`ReturnRegressionRewardModel`
  (IRCR's target, learned): delay-agnostic baselines that use only episode sums;
- :class:`IRCRReplayBuffer`: IRCR as its authors wrote it, guidance rewards from episode
  returns with no network, half of each batch from the best episodes (SAC, TD3, DQN);
- :class:`RelabelingReplayBuffer` (SAC, TD3, DQN), :class:`RelabelingRolloutBuffer` (PPO, A2C,
  with :class:`RewardModelCallback`), and their counterparts for ``Dict`` observations
  (:class:`RelabelingDictReplayBuffer`, :class:`RelabelingDictRolloutBuffer`) and n-step returns
  (:class:`RelabelingNStepReplayBuffer`);
- :class:`HindsightSAC`: SAC for late observations and actions, its critic learning on
  observations once they have arrived (on :class:`~delayed_rl.wrappers.DelayAwareObservation`);
- :func:`load_reward_model`, and :func:`make_reward_model` (a model from a mapping, as a
  hyperparameter file gives it).

Everything here needs torch and stable-baselines3 (``pip install "delayed-rl[sb3]"``); they are
imported when a name is first used, not by ``import delayed_rl.deep``.

Example:
    >>> import gymnasium as gym
    >>> from stable_baselines3 import SAC
    >>> from delayed_rl.deep import DeconvolutionRewardModel, RelabelingReplayBuffer
    >>> from delayed_rl.wrappers import RewardDelay
    >>> env = RewardDelay(gym.make("Pendulum-v1"), 20)  # Poisson(20) delays, flushed
    >>> model = DeconvolutionRewardModel(env.observation_space, env.action_space, delay=None,
    ...                                  max_delay_estimate=60, seed=0)
    >>> agent = SAC("MlpPolicy", env, replay_buffer_class=RelabelingReplayBuffer,
    ...             replay_buffer_kwargs={"reward_model": model}, seed=0)
"""

from __future__ import annotations

from delayed_rl._lazy import lazy_attributes

__all__ = [
    "REWARD_MODELS",
    "DeconvolutionRewardModel",
    "HindsightSAC",
    "IRCRReplayBuffer",
    "RelabelingDictReplayBuffer",
    "RelabelingDictRolloutBuffer",
    "RelabelingNStepReplayBuffer",
    "RelabelingReplayBuffer",
    "RelabelingRolloutBuffer",
    "ReturnDecompositionRewardModel",
    "ReturnRegressionRewardModel",
    "RewardModel",
    "RewardModelCallback",
    "load_reward_model",
    "make_reward_model",
]

REWARD_MODELS = (
    "DeconvolutionRewardModel",
    "ReturnDecompositionRewardModel",
    "ReturnRegressionRewardModel",
)
"""The reward model classes a mapping's ``type`` names (known without importing torch)."""

_HOMES = {
    "DeconvolutionRewardModel": "deconvolution",
    "HindsightSAC": "hindsight",
    "IRCRReplayBuffer": "ircr",
    "RelabelingDictReplayBuffer": "buffers",
    "RelabelingDictRolloutBuffer": "buffers",
    "RelabelingNStepReplayBuffer": "buffers",
    "RelabelingReplayBuffer": "buffers",
    "RelabelingRolloutBuffer": "buffers",
    "ReturnDecompositionRewardModel": "return_decomposition",
    "ReturnRegressionRewardModel": "return_regression",
    "RewardModel": "reward_model",
    "RewardModelCallback": "callbacks",
    "load_reward_model": "files",
    "make_reward_model": "files",
}


__getattr__ = lazy_attributes(
    __name__,
    _HOMES,
    ("torch", "stable_baselines3"),
    "torch and stable-baselines3",
    "sb3",
    '`pip install "delayed-rl[sb3]"` (torch first, for its CPU build: '
    "`pip install torch --index-url https://download.pytorch.org/whl/cpu`)",
)


def __dir__() -> list[str]:
    return sorted(__all__)
