"""The SB3 callback of the relabelling buffers: env rewards for on-policy, logs for both."""

from __future__ import annotations

from stable_baselines3.common.callbacks import BaseCallback

from delayed_rl.deep.buffers import RelabelingReplayBuffer, RelabelingRolloutBuffer

__all__ = ["RewardModelCallback"]


class RewardModelCallback(BaseCallback):
    """Hands the on-policy buffer each step's env rewards, and logs the reward model.

    The rewards go to a :class:`~delayed_rl.deep.buffers.RelabelingRolloutBuffer` at every step;
    the reward model's metrics go to SB3's logger at each rollout's end.

    Pass it to ``learn(callback=...)``: the on-policy buffer needs it (see
    :mod:`delayed_rl.deep.buffers`); with the off-policy buffer it only logs. The keys are
    ``reward_model/loss`` (the mean since the last log), ``reward_model/rmse`` (against
    ``info["undelayed_reward"]``, when the infos have it), ``reward_model/mean_delay`` (the
    deconvolution model's) and ``reward_model/gradient_steps``.

    Raises:
        TypeError: at the start of training, when the algorithm has no relabelling buffer.
    """

    def _buffer(self):
        buffer = getattr(self.model, "rollout_buffer", None) or getattr(
            self.model, "replay_buffer", None
        )
        if not isinstance(buffer, (RelabelingRolloutBuffer, RelabelingReplayBuffer)):
            raise TypeError(
                "RewardModelCallback needs an algorithm with a RelabelingRolloutBuffer or a "
                f"RelabelingReplayBuffer, got a {type(buffer).__name__}"
            )
        return buffer

    def _on_training_start(self) -> None:
        self._buffer()

    def _on_step(self) -> bool:
        buffer = self._buffer()
        if isinstance(buffer, RelabelingRolloutBuffer):
            buffer.receive_env_step(
                self.locals["rewards"], self.locals["dones"], self.locals["infos"]
            )
        return True

    def _on_rollout_end(self) -> None:
        self._buffer().reward_model.record(self.logger)
