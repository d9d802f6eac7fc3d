"""Return regression: a network fitted to IRCR's guidance target, the normalised episode return.

:class:`ReturnRegressionRewardModel` regresses ``R̂(s, a)`` on the min–max normalised return of
the finished episode each sampled step belongs to, so it averages over the episodes that pass
through (or near) ``(s, a)``. It is IRCR's target learned by a network, not IRCR: IRCR as its
authors wrote it (no network, a heap of the best episodes supplying half of each batch) is
:class:`~delayed_rl.deep.IRCRReplayBuffer`. Like RRD it is delay-agnostic and reads only episode
sums; its rewards are on another scale than the env's (0 to 1), which the RL algorithm does not
mind but a comparison of ``R̂`` with the true reward does.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from delayed_rl.deep.return_decomposition import sample_episodes
from delayed_rl.deep.reward_model import RewardModel

__all__ = ["ReturnRegressionRewardModel"]


class ReturnRegressionRewardModel(RewardModel):
    """``R̂(s, a)`` regressed on the normalised return of the episode holding each step.

    Args:
        observation_space: the env's observation space (any the base class takes).
        action_space: its action space (likewise).
        **kwargs: the :class:`~delayed_rl.deep.reward_model.RewardModel` settings; a batch is
            ``batch_size`` steps, each from an episode drawn uniformly among the finished ones.

    The normalisation uses the returns of the finished episodes in the history (a single
    return, or all equal: every step's target is 1).

    Example:
        >>> import gymnasium as gym
        >>> env = gym.make("CartPole-v1")
        >>> model = ReturnRegressionRewardModel(env.observation_space, env.action_space, seed=0)
        >>> obs, _ = env.reset(seed=0)
        >>> model.add([obs], [0], [0.0], [False])  # one step of one sub-env, its episode open
        >>> model.train(10)  # no finished episode: no target yet
        0
        >>> model.add([obs], [1], [3.0], [True])  # the episode ends, its return 3
        >>> model.train(10)
        10
    """

    def loss(self) -> torch.Tensor | None:
        """The mean squared error of ``R̂`` against the steps' normalised episode returns."""
        history = self.history
        episodes = sample_episodes(self, self.batch_size)
        if episodes is None:
            return None
        returns = np.array([total for _, _, _, total in history.episodes])
        low, high = returns.min(), returns.max()
        env, first, length, total = (np.array(column) for column in zip(*episodes, strict=True))
        steps = first + np.floor(self.rng.random(len(episodes)) * length).astype(np.int64)
        rows = steps % history.capacity
        scale = high - low
        target = (
            np.ones(len(episodes)) if scale == 0 or math.isnan(scale) else (total - low) / scale
        )
        rewards = self.network(*self.inputs_at(rows, env))
        return torch.mean((rewards - torch.as_tensor(target, dtype=torch.float32)) ** 2)
