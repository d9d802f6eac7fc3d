"""The SB3 callback of the relabelling buffers: what the env did for on-policy, logs for both."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.callbacks import BaseCallback

from delayed_rl.deep.buffers import _RelabelingOffPolicy, _RelabelingOnPolicy

__all__ = ["RewardModelCallback"]


class RewardModelCallback(BaseCallback):
    """Hands the on-policy buffer each step of the env, and logs the reward model.

    Pass it to ``learn(callback=...)``. The on-policy buffers need it: at every step it hands
    them the env's own rewards, the observations and rewards before any ``VecNormalize`` and the
    executed (clipped) actions (see :mod:`delayed_rl.deep.buffers`). With the off-policy buffers
    it only watches and logs.

    While it runs, the buffer hands the model each relabelled batch for its diagnostics, a few
    sums a batch (:meth:`~delayed_rl.deep.reward_model.RewardModel.watch`), and at each
    rollout's end the callback writes to SB3's logger ``reward_model/loss`` (the mean since the
    last write), ``reward_model/rmse`` and ``reward_model/correlation`` (of ``R̂`` against
    ``info["undelayed_reward"]``, when the infos have it, over the last block of
    :data:`~delayed_rl.deep.reward_model.DIAGNOSTIC_PAIRS` relabelled rewards),
    ``reward_model/mean_delay`` (the deconvolution model's) and ``reward_model/updates``.
    ``benchmarks/deep_reward_model_cost.py`` measures what watching costs a SAC step.

    Raises:
        TypeError: at the start of training, when the algorithm has no relabelling buffer
            (with ``HerReplayBuffer``, saying why it cannot have one).

    Example:
        >>> import gymnasium as gym
        >>> from stable_baselines3 import PPO
        >>> from delayed_rl.deep import RelabelingRolloutBuffer
        >>> from delayed_rl.wrappers import RewardDelay
        >>> spec = {"type": "ReturnRegressionRewardModel", "warmup_updates": 10,
        ...         "updates_per_step": 0}  # 10 updates once an episode has finished
        >>> agent = PPO("MlpPolicy", RewardDelay(gym.make("CartPole-v1"), 20), n_steps=64, seed=0,
        ...             n_epochs=1, rollout_buffer_class=RelabelingRolloutBuffer,
        ...             rollout_buffer_kwargs={"reward_model": spec})
        >>> model = agent.learn(64, callback=RewardModelCallback()).rollout_buffer.reward_model
        >>> model.history.steps_added, model.ready  # every step handed over; the rollout relabelled
        (64, True)
    """

    def _buffer(self):
        buffer = getattr(self.model, "rollout_buffer", None) or getattr(
            self.model, "replay_buffer", None
        )
        if isinstance(buffer, (_RelabelingOnPolicy, _RelabelingOffPolicy)):
            return buffer
        if type(buffer).__name__ == "HerReplayBuffer":
            raise TypeError(
                "RewardModelCallback cannot watch a HerReplayBuffer: HER recomputes rewards "
                "itself from the env's compute_reward, which a reward model cannot relabel"
            )
        raise TypeError(
            "RewardModelCallback needs an algorithm with a relabelling buffer "
            "(delayed_rl.deep.RelabelingReplayBuffer, RelabelingRolloutBuffer or their Dict and "
            f"n-step counterparts), got a {type(buffer).__name__}"
        )

    def _on_training_start(self) -> None:
        buffer = self._buffer()
        buffer.watched = True
        self._normalizer = self.model.get_vec_normalize_env()
        if isinstance(buffer, RolloutBuffer):
            buffer.vec_normalize = self._normalizer
            self._observations = self._original_observations(self.model._last_obs)

    def _original_observations(self, observations):
        """A copy of ``observations`` before any ``VecNormalize`` (its own copy when there is one).

        ``observations`` are the latest the env returned (after autoreset, the next episode's).
        """
        if self._normalizer is not None:
            return copy.deepcopy(self._normalizer.get_original_obs())
        return copy.deepcopy(observations)

    def _terminal_observations(self, following: Any, dones: Any, infos: list) -> Any:
        """``following`` with each ended episode's terminal observation in its sub-env's row.

        Under ``VecNormalize`` the infos hold it normalised: it is un-normalised (exact up to
        rounding, unless ``VecNormalize`` clipped it). Box observations (the only ones a model
        reading ``s′`` takes).
        """
        following = np.array(following, copy=True)
        for env in np.flatnonzero(dones):
            terminal = infos[env].get("terminal_observation")
            if terminal is None:
                continue
            if self._normalizer is not None:
                terminal = self._normalizer.unnormalize_obs(terminal)
            following[env] = terminal
        return following

    def _on_step(self) -> bool:
        buffer = self._buffer()
        if isinstance(buffer, RolloutBuffer):
            rewards = self.locals["rewards"]
            original = (
                rewards if self._normalizer is None else self._normalizer.get_original_reward()
            )
            dones, infos = self.locals["dones"], self.locals["infos"]
            following = self._original_observations(self.locals["new_obs"])
            buffer.receive_env_step(
                self._observations,
                self.locals["clipped_actions"],
                rewards,
                original,
                dones,
                infos,
                self._terminal_observations(following, dones, infos)
                if buffer.reward_model.reads_next_observation
                else None,
            )
            self._observations = following
        return True

    def _on_rollout_end(self) -> None:
        self._buffer().reward_model.record(self.logger)

    def _on_training_end(self) -> None:
        self._buffer().watched = False
