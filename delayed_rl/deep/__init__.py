"""Deep RL under delays: reward models for SB3, and SAC for late observations and actions.

- reward models, ``R̂(s, a)`` learned from the delivered rewards alone:
  :class:`DeconvolutionRewardModel`, :class:`ReturnDecompositionRewardModel` (RRD),
  :class:`ReturnRegressionRewardModel`; :func:`load_reward_model`, :func:`make_reward_model`;
- buffers that hand SB3's algorithms ``R̂``: :class:`RelabelingReplayBuffer`,
  :class:`RelabelingNStepReplayBuffer`, :class:`RelabelingDictReplayBuffer` (off-policy),
  :class:`RelabelingRolloutBuffer`, :class:`RelabelingDictRolloutBuffer` (on-policy, with
  :class:`RewardModelCallback`), and :class:`IRCRReplayBuffer` (IRCR as published);
- :class:`HindsightSAC`: SAC for late observations and actions.

Everything here needs the ``sb3`` extra (torch and stable-baselines3), imported when a name is
first used. ``docs/deep_rl.md`` has the wiring, the schedule and the measurements.
"""

from __future__ import annotations

from delayed_rl._lazy import lazy_attributes

__all__ = [
    "GUIDANCE_BUFFERS",
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

GUIDANCE_BUFFERS = ("IRCRReplayBuffer",)
"""The replay buffers that compute the rewards they hand out themselves, with no reward model."""

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
