"""What an agent counts while it trains, and the metrics it logs from those counts."""

from __future__ import annotations

import time
from collections import deque
from typing import Any

import numpy as np

__all__ = ["TrainingStatistics"]


class TrainingStatistics:
    """Episode returns and lengths, how often each model acted, and the logging clock.

    Episode returns are sums of the *undelayed* reward (``info["undelayed_reward"]``), so pending
    rewards never distort them.

    Args:
        n_models: how many delay models the agent acts from (|Λ|).
        num_timesteps: the agent's step count now (the logging clock starts there).

    Attributes:
        acting_counts: per model, how many training steps it was the acting model.
        episode_rewards: the last 100 episodes' undelayed returns.
        episode_lengths: their lengths.
        episodes: how many episodes ended.
        episode_reward: the undelayed return of the episode in progress so far.
        episode_length: its length so far.
    """

    def __init__(self, n_models: int, num_timesteps: int):
        self.acting_counts = [0] * n_models
        self.episode_rewards: deque[float] = deque(maxlen=100)
        self.episode_lengths: deque[int] = deque(maxlen=100)
        self.episodes = 0
        self.episode_reward = 0.0
        self.episode_length = 0
        self.restart_clock(num_timesteps)
        self.logged_counts = list(self.acting_counts)

    def restart_clock(self, num_timesteps: int) -> None:
        """Measure the next log's steps per second from now and ``num_timesteps``."""
        self.log_start = (time.perf_counter(), num_timesteps)

    def start_episode(self) -> None:
        """A new episode begins."""
        self.episode_reward, self.episode_length = 0.0, 0

    def end_episode(self, reward: float, length: int) -> None:
        """An episode with undelayed return ``reward`` and ``length`` steps ended."""
        self.episode_rewards.append(reward)
        self.episode_lengths.append(length)
        self.episodes += 1

    def add_chunk(self, acting: np.ndarray, undelayed: np.ndarray, episode_end: np.ndarray) -> None:
        """Count a block of steps: acting model indices, undelayed rewards, episode-end flags."""
        counts = np.bincount(acting, minlength=len(self.acting_counts))
        self.acting_counts = [a + int(b) for a, b in zip(self.acting_counts, counts, strict=True)]
        previous = 0
        for end in np.flatnonzero(episode_end).tolist():
            chunk = float(undelayed[previous : end + 1].sum())
            self.end_episode(self.episode_reward + chunk, self.episode_length + end + 1 - previous)
            self.start_episode()
            previous = end + 1
        self.episode_reward += float(undelayed[previous:].sum())
        self.episode_length += undelayed.size - previous

    def acting_counts_since_log(self) -> np.ndarray:
        """Per model, the acting steps since the last call (the first call: since the start)."""
        counts = np.asarray(self.acting_counts) - np.asarray(self.logged_counts)
        self.logged_counts = list(self.acting_counts)
        return counts

    def record(self, logger: Any, agent: Any, reward_total: float, undelayed_total: float) -> None:
        """Record SB3's ``time/``, ``rollout/`` and ``train/`` metrics of the steps since the last log.

        Args:
            logger: where to record.
            agent: the agent (its step count, ε and α).
            reward_total: the sum of the rewards received since the last log.
            undelayed_total: the sum of the undelayed rewards since the last log.
        """
        start_time, start_steps = self.log_start
        now = time.perf_counter()
        steps = agent.num_timesteps - start_steps
        logger.record("time/total_timesteps", agent.num_timesteps, exclude="tensorboard")
        logger.record("time/episodes", self.episodes)
        logger.record("time/fps", int(steps / max(now - start_time, 1e-9)))
        if steps:
            logger.record("rollout/reward_per_step", reward_total / steps)
            logger.record("rollout/undelayed_reward_per_step", undelayed_total / steps)
        if self.episode_rewards:
            logger.record("rollout/ep_rew_mean", float(np.mean(self.episode_rewards)))
            logger.record("rollout/ep_len_mean", float(np.mean(self.episode_lengths)))
        logger.record("rollout/exploration_rate", agent.exploration_rate)
        logger.record("train/learning_rate", agent.current_learning_rate)
        self.log_start = (now, agent.num_timesteps)
