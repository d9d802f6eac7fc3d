"""Randomized return decomposition (RRD, Ren et al. 2022): ``R̂`` from episode sums alone.

An episode's delivered rewards sum to its return ``G`` (under ``"flush"``, whatever the delays:
that is what makes it delay-agnostic). RRD draws random subsets ``I`` of an episode's steps and
regresses the per-step share ``G / T`` on the mean of ``R̂`` over ``I``. It needs no model of
the delay, but it uses only the sums: it cannot tell which steps earned a reward beyond what
the episodes' sums reveal. Only finished episodes wholly in the history are used; under
``"carry"`` or ``"drop"`` episode sums are not the returns, and RRD learns the wrong scale.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from delayed_rl._validation import check_int
from delayed_rl.deep.network import as_tensors
from delayed_rl.deep.reward_model import RewardModel

__all__ = ["ReturnDecompositionRewardModel", "sample_episodes"]


def sample_episodes(model: RewardModel, count: int) -> list[tuple[int, int, int, float]] | None:
    """``count`` finished episodes of ``model``'s history, drawn uniformly with replacement.

    ``None`` when no episode has finished yet.
    """
    episodes = model.history.episodes
    if not episodes:
        return None
    picks = model.rng.integers(0, len(episodes), size=count)
    return [episodes[i] for i in picks]


class ReturnDecompositionRewardModel(RewardModel):
    """RRD: ``mean_{i ∈ I} R̂(s_i, a_i) ≈ G / T`` for random subsets ``I`` of episodes.

    Args:
        observation_space: the env's observation space (any the base class takes).
        action_space: its action space (likewise).
        subset_size: the steps drawn (without replacement) from each episode of a batch
            (all of a shorter episode's); a batch is ``ceil(batch_size / subset_size)`` episodes.
        **kwargs: the :class:`~delayed_rl.deep.reward_model.RewardModel` settings.
    """

    own_settings = ("subset_size",)

    def __init__(
        self, observation_space: Any, action_space: Any, *, subset_size: int = 64, **kwargs
    ):
        self.subset_size = check_int("subset_size", subset_size, 1, 2**16)
        super().__init__(observation_space, action_space, **kwargs)

    def loss(self) -> torch.Tensor | None:
        """The mean over a batch's episodes of ``(mean_I R̂ − G / T)²``."""
        history = self.history
        episodes = sample_episodes(self, math.ceil(self.batch_size / self.subset_size))
        if episodes is None:
            return None
        rows, envs, groups, targets = [], [], [], []
        for group, (env, first, length, total) in enumerate(episodes):
            size = min(self.subset_size, length)
            steps = first + self.rng.choice(length, size=size, replace=False)
            rows.append(steps % history.capacity)
            envs.append(np.full(size, env))
            groups.append(np.full(size, group))
            targets.append(total / length)
        rows, envs = np.concatenate(rows), np.concatenate(envs)
        group = torch.as_tensor(np.concatenate(groups))
        rewards = self.network(
            as_tensors(history.observations_at(rows, envs)),
            as_tensors(history.actions_at(rows, envs)),
        )
        sums = torch.zeros(len(episodes)).index_add(0, group, rewards)
        sizes = torch.zeros(len(episodes)).index_add(0, group, torch.ones_like(rewards))
        target = torch.as_tensor(targets, dtype=torch.float32)
        return torch.mean((sums / sizes - target) ** 2)
