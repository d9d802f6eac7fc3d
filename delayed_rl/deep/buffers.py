"""SB3 buffers that train a reward model on what they receive and hand the algorithm ``R̂``.

Both plug into stable-baselines3 through its own extension points, for any algorithm:

- off-policy (SAC, TD3, DQN): ``replay_buffer_class=RelabelingReplayBuffer,
  replay_buffer_kwargs={"reward_model": model}``. ``add()`` passes each step to the model (which
  trains on its schedule); a sampled batch's rewards are ``R̂(s, a)`` of its transitions, by the
  model as it is when sampled (scaled by a ``VecNormalize``'s reward normalisation, as SB3 scales
  rewards). The delivered rewards stay in ``delivered_rewards``.
- on-policy (PPO, A2C): ``rollout_buffer_class=RelabelingRolloutBuffer,
  rollout_buffer_kwargs={"reward_model": model}``, with
  :class:`~delayed_rl.deep.callbacks.RewardModelCallback` passed to ``learn(callback=...)``.
  Before returns and advantages are computed, the rollout's rewards become ``R̂(s, a)``. The model
  keeps its history from one rollout to the next.

**The on-policy bootstrap.** At a truncation, SB3's on-policy loop adds ``γ·V(terminal
observation)`` to the reward before ``add()``. The model must learn from the env's reward, and
the relabelled reward must keep that bootstrap. ``add()`` cannot tell the two apart, so the
callback hands the buffer each step's rewards as the env delivered them (it runs before the
bootstrap is added); the buffer trains the model on those, keeps ``bootstrap = reward − env
reward`` per step and relabels with ``R̂ + bootstrap``. Without the callback ``add()`` raises.

Episode boundaries are the ``dones`` of SB3's vector envs (terminated or truncated; autoreset
makes the next observation the next episode's), for any number of sub-envs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from stable_baselines3.common.buffers import ReplayBuffer, RolloutBuffer

from delayed_rl.deep.files import make_reward_model
from delayed_rl.deep.reward_model import RewardModel

__all__ = ["RelabelingReplayBuffer", "RelabelingRolloutBuffer"]


class RelabelingReplayBuffer(ReplayBuffer):
    """SB3's ``ReplayBuffer`` whose sampled rewards are a reward model's ``R̂(s, a)``.

    Args:
        buffer_size, observation_space, action_space, device, n_envs: as SB3's ``ReplayBuffer``.
        optimize_memory_usage, handle_timeout_termination: as SB3's ``ReplayBuffer``.
        reward_model: the model to train and relabel with (its spaces must be the buffer's),
            or a mapping ``{"type": <class name>, <setting>: <value>, ...}`` that the buffer
            makes it from, for its spaces (:func:`~delayed_rl.deep.files.make_reward_model`;
            a hyperparameter file's form). A model made so lives in the buffer: SB3's
            ``save_replay_buffer`` keeps it, ``model.save`` keeps only the mapping.

    Attributes:
        delivered_rewards: the rewards ``add()`` received (``rewards`` holds the last relabelling).
    """

    def __init__(
        self,
        buffer_size: int,
        observation_space: Any,
        action_space: Any,
        device: torch.device | str = "auto",
        n_envs: int = 1,
        optimize_memory_usage: bool = False,
        handle_timeout_termination: bool = True,
        *,
        reward_model: RewardModel | dict[str, Any],
    ):
        super().__init__(
            buffer_size,
            observation_space,
            action_space,
            device,
            n_envs=n_envs,
            optimize_memory_usage=optimize_memory_usage,
            handle_timeout_termination=handle_timeout_termination,
        )
        self.reward_model = make_reward_model(reward_model, observation_space, action_space)
        self.delivered_rewards = np.zeros_like(self.rewards)

    def add(
        self,
        obs: np.ndarray,
        next_obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        """Store the transition as SB3 does, and pass it to the reward model."""
        self.delivered_rewards[self.pos] = np.asarray(reward).reshape(self.n_envs)
        self.reward_model.add(obs, action, reward, done, infos)
        super().add(obs, next_obs, action, reward, done, infos)

    def _get_samples(self, batch_inds: np.ndarray, env: Any = None) -> Any:
        """SB3's samples, their rewards ``R̂`` of the rows drawn (every sub-env's)."""
        rows = np.unique(batch_inds)
        obs = self.observations[rows].reshape(-1, *self.obs_shape)
        actions = self.actions[rows].reshape(-1, self.action_dim)
        relabelled = self.reward_model.predict(obs, actions)
        self.rewards[rows] = relabelled.reshape(rows.size, self.n_envs)
        return super()._get_samples(batch_inds, env)


class RelabelingRolloutBuffer(RolloutBuffer):
    """SB3's ``RolloutBuffer`` whose rewards become ``R̂(s, a)`` (plus any bootstrap).

    The relabelling happens before returns and advantages are computed.

    Args:
        buffer_size, observation_space, action_space, device: as SB3's ``RolloutBuffer``.
        gae_lambda, gamma, n_envs: as SB3's ``RolloutBuffer``.
        reward_model: the model to train and relabel with, or a mapping that the buffer makes
            it from, as :class:`RelabelingReplayBuffer` takes it (``model.save`` keeps a model
            given as an object; one made from a mapping starts afresh on load).

    Attributes:
        delivered_rewards: per step, the rewards the env delivered (from the callback).
        bootstraps: per step, what SB3 added to them (``γ·V(terminal observation)`` at a
            truncation, else 0).
    """

    def __init__(
        self,
        buffer_size: int,
        observation_space: Any,
        action_space: Any,
        device: torch.device | str = "auto",
        gae_lambda: float = 1,
        gamma: float = 0.99,
        n_envs: int = 1,
        *,
        reward_model: RewardModel | dict[str, Any],
    ):
        self.reward_model = make_reward_model(reward_model, observation_space, action_space)
        self._env_step: tuple[np.ndarray, np.ndarray, list] | None = None
        super().__init__(
            buffer_size,
            observation_space,
            action_space,
            device,
            gae_lambda=gae_lambda,
            gamma=gamma,
            n_envs=n_envs,
        )

    def reset(self) -> None:
        """SB3's reset, and the per-step records emptied."""
        super().reset()
        self.delivered_rewards = np.zeros((self.buffer_size, self.n_envs), dtype=np.float32)
        self.bootstraps = np.zeros((self.buffer_size, self.n_envs), dtype=np.float32)

    def receive_env_step(self, rewards: np.ndarray, dones: np.ndarray, infos: list) -> None:
        """Take the step's env rewards, ``dones`` and ``infos``, before SB3 adds a bootstrap.

        :class:`~delayed_rl.deep.callbacks.RewardModelCallback` calls it at every step.
        """
        self._env_step = (np.array(rewards, dtype=np.float32), np.array(dones, dtype=bool), infos)

    def add(self, obs, action, reward, episode_start, value, log_prob) -> None:  # noqa: D417
        """Store the step as SB3 does; train the model on the env's reward, keep the bootstrap.

        Raises:
            RuntimeError: the callback did not hand over this step's env rewards.
        """
        if self._env_step is None:
            raise RuntimeError(
                "RelabelingRolloutBuffer needs delayed_rl.deep.RewardModelCallback in "
                "learn(callback=...): SB3's on-policy loop adds gamma * V(terminal observation) to "
                "the reward of a truncated step before add(), and only the callback sees the "
                "env's own reward"
            )
        delivered, dones, infos = self._env_step
        self._env_step = None
        self.delivered_rewards[self.pos] = delivered.reshape(self.n_envs)
        reward = np.asarray(reward, dtype=np.float32).reshape(self.n_envs)
        self.bootstraps[self.pos] = reward - self.delivered_rewards[self.pos]
        self.reward_model.add(obs, action, delivered, dones, infos)
        super().add(obs, action, reward, episode_start, value, log_prob)

    def compute_returns_and_advantage(self, last_values: torch.Tensor, dones: np.ndarray) -> None:
        """Relabel the rollout's rewards with ``R̂ + bootstrap``, then SB3's computation."""
        steps = self.buffer_size if self.full else self.pos
        obs = self.observations[:steps].reshape(-1, *self.obs_shape)
        actions = self.actions[:steps].reshape(-1, self.action_dim)
        relabelled = self.reward_model.predict(obs, actions).reshape(steps, self.n_envs)
        self.rewards[:steps] = relabelled + self.bootstraps[:steps]
        super().compute_returns_and_advantage(last_values, dones)
