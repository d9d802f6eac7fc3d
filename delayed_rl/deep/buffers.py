"""SB3 buffers that keep what they receive for a reward model and hand the algorithm ``R̂``.

Each is SB3's own buffer with a reward model beside it: :class:`RelabelingReplayBuffer`,
:class:`RelabelingNStepReplayBuffer` and :class:`RelabelingDictReplayBuffer` (off-policy: the
sampled batches are relabelled), :class:`RelabelingRolloutBuffer` and
:class:`RelabelingDictRolloutBuffer` (on-policy, with
:class:`~delayed_rl.deep.callbacks.RewardModelCallback`: the rollout is relabelled). Pass one as
``replay_buffer_class`` / ``rollout_buffer_class`` with ``{"reward_model": model}`` in its
kwargs. What each path hands the model, when it relabels and what is refused at construction:
the docs' deep RL page (``docs/deep_rl.md``, "The buffers, in full").
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.buffers import (
    DictReplayBuffer,
    DictRolloutBuffer,
    NStepReplayBuffer,
    ReplayBuffer,
    RolloutBuffer,
)

from delayed_rl._validation import check_int, check_probability
from delayed_rl.deep.binding import (
    adopt,
    bind,
    calling_algorithm,
    env_was_reset,
    remember_episode_starts,
)
from delayed_rl.deep.files import make_reward_model
from delayed_rl.deep.reward_model import RewardModel

__all__ = [
    "RelabelingDictReplayBuffer",
    "RelabelingDictRolloutBuffer",
    "RelabelingNStepReplayBuffer",
    "RelabelingReplayBuffer",
    "RelabelingRolloutBuffer",
]

HER_SETTINGS = frozenset({"env", "n_sampled_goal", "goal_selection_strategy", "copy_info_dict"})
"""``HerReplayBuffer``'s own keyword arguments."""


def _refuse_unknown(cls: type, settings: dict[str, Any]) -> None:
    """Refuse keyword arguments a relabelling buffer does not take, HER's by name."""
    if not settings:
        return
    if HER_SETTINGS & set(settings):
        raise TypeError(
            f"{cls.__name__} does not take HerReplayBuffer's settings "
            f"{sorted(HER_SETTINGS & set(settings))}: HER recomputes rewards itself from the env's "
            "compute_reward, which a reward model cannot relabel; use HerReplayBuffer without a "
            "reward model"
        )
    raise TypeError(f"{cls.__name__} got unexpected keyword arguments {sorted(settings)}")


def _check_dict_space(buffer: Any, observation_space: Any) -> None:
    """Refuse a ``Dict`` space in a non-``Dict`` buffer and the reverse, naming the counterpart."""
    if isinstance(observation_space, spaces.Dict) != buffer.takes_dict:
        wanted = "a Dict" if buffer.takes_dict else "a non-Dict"
        raise TypeError(
            f"{type(buffer).__name__} takes {wanted} observation_space, got "
            f"{observation_space!r}: use {buffer.counterpart}"
        )


class _Relabeling:
    """What every relabelling buffer shares: its reward model's checks and its binding."""

    takes_dict = False

    def _checked_model(
        self,
        reward_model: RewardModel | dict[str, Any],
        observation_space: Any,
        action_space: Any,
        settings: dict[str, Any],
    ) -> RewardModel:
        """The buffer's reward model (made for its spaces from a mapping), after its checks.

        Refuses the unknown ``settings`` and an observation space of the other kind (``Dict``
        or not) before the model is made.
        """
        _refuse_unknown(type(self), settings)
        _check_dict_space(self, observation_space)
        return make_reward_model(reward_model, observation_space, action_space)

    def _bind_to_caller(self) -> None:
        """Start unwatched; bind to the algorithm building the buffer, if one is, once checked.

        The algorithm is the one whose ``_setup_model`` is running; :meth:`_check_algorithm`
        refuses one the buffer cannot serve.
        """
        self.watched = False
        algorithm = calling_algorithm("_setup_model")
        if algorithm is not None:
            self._check_algorithm(algorithm)
            bind(self, algorithm)
            remember_episode_starts(self, algorithm)

    def _check_algorithm(self, algorithm: Any) -> None:
        """Refuse an algorithm whose settings the buffer cannot serve (none here)."""


def _check_next_observations_kept(model: RewardModel, optimize_memory_usage: bool) -> None:
    """Refuse a model that reads ``s′`` in a buffer that keeps no next observations.

    With ``optimize_memory_usage`` SB3 reads a row's next observation from the next row, which at
    an episode's end holds the next episode's first observation.
    """
    if optimize_memory_usage and model.reads_next_observation:
        raise ValueError(
            f"optimize_memory_usage=True with a {type(model).__name__} that reads s′ "
            "(RRD's state_change=True): the buffer would read an episode's last s′ from the "
            "next episode's first observation; use optimize_memory_usage=False, or a model "
            "that reads no s′ (state_change=False)"
        )


class _RelabelingOffPolicy(_Relabeling):
    """What the off-policy relabelling buffers share (a mixin before SB3's buffer class)."""

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
        **settings: Any,
    ):
        own = {key: settings.pop(key) for key in ("n_steps", "gamma") if key in settings}
        model = self._checked_model(reward_model, observation_space, action_space, settings)
        _check_next_observations_kept(model, optimize_memory_usage)
        super().__init__(
            buffer_size,
            observation_space,
            action_space,
            device,
            n_envs=n_envs,
            optimize_memory_usage=optimize_memory_usage,
            handle_timeout_termination=handle_timeout_termination,
            **self._own_settings(own),
        )
        self.reward_model = model
        self.delivered_rewards = np.zeros_like(self.rewards)
        self.undelayed_rewards = np.full_like(self.rewards, np.nan)
        self._bind_to_caller()

    def _own_settings(self, settings: dict[str, Any]) -> dict[str, Any]:
        """The settings this class's SB3 parent takes beside the common ones (n-step's)."""
        if settings:
            raise TypeError(
                f"{type(self).__name__} takes no {' or '.join(sorted(settings))}: for n-step "
                "returns use RelabelingNStepReplayBuffer (replay_buffer_kwargs n_steps, gamma)"
            )
        return {}

    def _check_algorithm(self, algorithm: Any) -> None:
        from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

        n_steps = getattr(algorithm, "n_steps", 1)
        if isinstance(algorithm, OffPolicyAlgorithm) and n_steps > 1:
            raise ValueError(
                f"{type(algorithm).__name__}(n_steps={n_steps}) with {type(self).__name__}: SB3 "
                "ignores n_steps with a custom replay buffer; for n-step returns on R̂ use "
                "replay_buffer_class=RelabelingNStepReplayBuffer with replay_buffer_kwargs "
                f"n_steps={n_steps} and gamma (Box or Discrete observations), or n_steps=1"
            )

    def __setstate__(self, state: dict[str, Any]) -> None:
        _check_next_observations_kept(state["reward_model"], state["optimize_memory_usage"])
        self.__dict__.update(state)
        algorithm = calling_algorithm("load_replay_buffer")
        if algorithm is not None:
            adopt(self, algorithm)
            remember_episode_starts(self, algorithm)

    def add(self, obs, next_obs, action, reward, done, infos) -> None:  # noqa: D417
        """Store the transition as SB3 does, and hand it to the reward model.

        When the algorithm reset its env since the last step (:func:`~.binding.env_was_reset`),
        the episodes it left open are cut first: in the model's history (``episode_starts`` of
        :meth:`~.reward_model.RewardModel.add`), and in the buffer, whose last row of each
        becomes a truncation (so that an n-step return stops there and bootstraps from that
        row's next observation; a one-step target reads no truncation but a terminal one's).
        """
        starts = None
        if env_was_reset(self):
            starts = np.ones(self.n_envs, dtype=bool)
            self._truncate_open_episodes()
        self.delivered_rewards[self.pos] = np.asarray(reward).reshape(self.n_envs)
        self.undelayed_rewards[self.pos] = [
            info.get("undelayed_reward", np.nan) if isinstance(info, dict) else np.nan
            for info in infos
        ]
        self.reward_model.add(
            obs, action, reward, done, infos, next_observations=next_obs, episode_starts=starts
        )
        super().add(obs, next_obs, action, reward, done, infos)

    def _truncate_open_episodes(self) -> None:
        """Mark the last row of each sub-env whose episode it did not end as a time-limit one."""
        if self.pos == 0 and not self.full:
            return
        last = (self.pos - 1) % self.buffer_size
        self.timeouts[last] = np.logical_or(self.timeouts[last], ~self.dones[last].astype(bool))

    def sample(self, batch_size: int, env: Any = None) -> Any:
        """SB3's sample, after the reward model takes the updates its schedule owes."""
        self.reward_model.train_on_schedule()
        return super().sample(batch_size, env=env)

    def _rows_read(self, batch_inds: np.ndarray) -> np.ndarray:
        """The rows a batch's rewards are read from."""
        return np.unique(batch_inds)

    def _get_samples(self, batch_inds: np.ndarray, env: Any = None) -> Any:
        """SB3's samples, their rewards ``R̂`` of the rows read (every sub-env's) once ready."""
        model = self.reward_model
        if model.ready:
            rows = self._rows_read(batch_inds)
            # SB3 stores what add() handed the model, which checked it: no second check here
            encoding = model.observations
            obs = encoding.flat(encoding.take(self.observations, rows))
            actions = self.actions[rows].reshape(-1, *model.actions.shape)
            inputs = [obs, actions]
            if model.reads_next_observation:  # a Box, never with optimize_memory_usage
                inputs.append(encoding.flat(self.next_observations[rows]))
            relabelled = model.reward_tensor(*inputs).numpy()
            self.rewards[rows] = relabelled.reshape(rows.size, self.n_envs)
            if self.watched:
                model.watch(relabelled, self.undelayed_rewards[rows].ravel())
        return super()._get_samples(batch_inds, env)


class RelabelingReplayBuffer(_RelabelingOffPolicy, ReplayBuffer):
    """SB3's ``ReplayBuffer`` whose sampled rewards are a reward model's ``R̂(s, a)``.

    Args:
        buffer_size, observation_space, action_space, device, n_envs: as SB3's ``ReplayBuffer``.
        optimize_memory_usage, handle_timeout_termination: as SB3's ``ReplayBuffer``.
        reward_model: the model to train and relabel with (its spaces must be the buffer's),
            or a mapping ``{"type": <class name>, <setting>: <value>, ...}`` that the buffer
            makes it from, for its spaces (:func:`~delayed_rl.deep.files.make_reward_model`;
            a hyperparameter file's form).

    Attributes:
        reward_model: the model.
        delivered_rewards: the rewards ``add()`` received (``rewards`` holds the last relabelling).
        undelayed_rewards: ``info["undelayed_reward"]`` of each stored step (NaN where absent),
            for the diagnostics only.
        watched: whether relabelled batches go to the model's diagnostics (set by
            :class:`~delayed_rl.deep.callbacks.RewardModelCallback`).

    Raises:
        TypeError, ValueError: see ``docs/deep_rl.md`` ("Refused at construction").

    Example:
        >>> import gymnasium as gym
        >>> from stable_baselines3 import SAC
        >>> from delayed_rl.wrappers import RewardDelay
        >>> env = RewardDelay(gym.make("Pendulum-v1"), 20)  # Poisson(20) delays, flushed
        >>> spec = {"type": "DeconvolutionRewardModel", "delay": 20}  # made for env's spaces
        >>> agent = SAC("MlpPolicy", env, replay_buffer_class=RelabelingReplayBuffer,
        ...             replay_buffer_kwargs={"reward_model": spec}, buffer_size=10_000, seed=0)
        >>> round(agent.replay_buffer.reward_model.mean_delay)  # the known delay's mean
        20
    """

    counterpart = "RelabelingDictReplayBuffer"


class RelabelingDictReplayBuffer(_RelabelingOffPolicy, DictReplayBuffer):
    """SB3's ``DictReplayBuffer`` whose sampled rewards are ``R̂(s, a)``, for ``MultiInputPolicy``.

    Takes what :class:`RelabelingReplayBuffer` takes, for a ``Dict`` observation space (n-step
    returns are refused, as SB3 has no ``Dict`` n-step buffer).

    Example:
        >>> import gymnasium as gym
        >>> from stable_baselines3 import SAC
        >>> from delayed_rl.delays import Constant
        >>> from delayed_rl.wrappers import wrap_delays
        >>> env = wrap_delays(gym.make("Pendulum-v1"), observation_delay=Constant(2),
        ...                   delay_aware=True, reward_delay=20)  # a Dict view, rewards late
        >>> spec = {"type": "ReturnRegressionRewardModel"}  # made for the view's Dict
        >>> agent = SAC("MultiInputPolicy", env, replay_buffer_class=RelabelingDictReplayBuffer,
        ...             replay_buffer_kwargs={"reward_model": spec}, buffer_size=10_000, seed=0)
        >>> sorted(agent.replay_buffer.observations)  # the view's keys, stored and read by R̂
        ['actions', 'age', 'observation']
    """

    takes_dict = True
    counterpart = "RelabelingReplayBuffer"

    def _check_algorithm(self, algorithm: Any) -> None:
        n_steps = getattr(algorithm, "n_steps", 1)
        if n_steps > 1:
            raise ValueError(
                f"{type(algorithm).__name__}(n_steps={n_steps}) with Dict observations: n-step "
                "returns are not supported for Dict observation spaces (SB3 has no Dict n-step "
                "buffer); use n_steps=1"
            )


class RelabelingNStepReplayBuffer(_RelabelingOffPolicy, NStepReplayBuffer):
    """SB3's ``NStepReplayBuffer`` whose n-step sums add up ``R̂`` of each step.

    Takes what :class:`RelabelingReplayBuffer` takes, and SB3's ``n_steps`` (default 3) and
    ``gamma`` (default 0.99). With an algorithm built with ``n_steps > 1`` they must agree.

    Example:
        >>> import gymnasium as gym
        >>> from stable_baselines3 import SAC
        >>> from delayed_rl.wrappers import RewardDelay
        >>> env = RewardDelay(gym.make("Pendulum-v1"), 20)  # Poisson(20) delays, flushed
        >>> kwargs = {"reward_model": {"type": "ReturnRegressionRewardModel"}, "n_steps": 5}
        >>> agent = SAC("MlpPolicy", env, replay_buffer_class=RelabelingNStepReplayBuffer,
        ...             replay_buffer_kwargs=kwargs, buffer_size=10_000, seed=0)
        >>> agent.replay_buffer.n_steps, agent.replay_buffer.gamma  # gamma: the default
        (5, 0.99)
    """

    counterpart = "RelabelingDictReplayBuffer (without n-step returns)"

    def _own_settings(self, settings: dict[str, Any]) -> dict[str, Any]:
        return {
            "n_steps": check_int("n_steps", settings.get("n_steps", 3), 1, 2**20),
            "gamma": check_probability("gamma", settings.get("gamma", 0.99)),
        }

    def _check_algorithm(self, algorithm: Any) -> None:
        n_steps = getattr(algorithm, "n_steps", 1)
        if n_steps > 1 and n_steps != self.n_steps:
            raise ValueError(
                f"replay_buffer_kwargs n_steps={self.n_steps} differs from "
                f"{type(algorithm).__name__}(n_steps={n_steps}): give one value"
            )

    def _rows_read(self, batch_inds: np.ndarray) -> np.ndarray:
        steps = np.arange(self.n_steps)
        return np.unique((batch_inds[:, None] + steps) % self.buffer_size)


class _RelabelingOnPolicy(_Relabeling):
    """What the on-policy relabelling buffers share (a mixin before SB3's buffer class)."""

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
        **settings: Any,
    ):
        model = self._checked_model(reward_model, observation_space, action_space, settings)
        if model.capacity < buffer_size:
            raise ValueError(
                f"reward_model's capacity ({model.capacity} steps) must hold a rollout of "
                f"{buffer_size} steps (the algorithm's n_steps): the rollout is relabelled "
                "from the model's history"
            )
        self.reward_model = model
        self.vec_normalize = None
        self._env_step: tuple | None = None
        super().__init__(
            buffer_size,
            observation_space,
            action_space,
            device,
            gae_lambda=gae_lambda,
            gamma=gamma,
            n_envs=n_envs,
        )
        self._bind_to_caller()

    def reset(self) -> None:
        """SB3's reset, and the per-step records emptied."""
        super().reset()
        self.delivered_rewards = np.zeros((self.buffer_size, self.n_envs), dtype=np.float32)
        self.bootstraps = np.zeros((self.buffer_size, self.n_envs), dtype=np.float32)

    def receive_env_step(
        self,
        observations: Any,
        actions: Any,
        rewards: Any,
        env_rewards: Any,
        dones: Any,
        infos: list,
        next_observations: Any = None,
    ) -> None:
        """Take what the env did at this step, before SB3 adds a bootstrap and stores it.

        :class:`~delayed_rl.deep.callbacks.RewardModelCallback` calls it at every step.

        Args:
            observations: the observations the actions were chosen at, before any
                ``VecNormalize``.
            actions: the actions the env executed (clipped to the action space).
            rewards: the rewards as the algorithm received them (normalised under
                ``VecNormalize``), before any bootstrap.
            env_rewards: the rewards the env delivered, before any ``VecNormalize``.
            dones: the sub-envs' episode ends.
            infos: the step's ``infos``.
            next_observations: the observations the step led to (the terminal one where an
                episode ended), before any ``VecNormalize``: for a model that
                :attr:`~delayed_rl.deep.reward_model.RewardModel.reads_next_observation`.
        """
        self._env_step = (
            observations,
            np.array(actions),
            np.array(rewards, dtype=np.float32),
            np.array(env_rewards, dtype=np.float64),
            np.array(dones, dtype=bool),
            infos,
            next_observations,
        )

    def add(self, obs, action, reward, episode_start, value, log_prob) -> None:  # noqa: D417
        """Store the step as SB3 does; hand the model what the env did; keep the bootstrap.

        A sub-env whose ``episode_start`` is set while its episode in the model's history is
        open was reset by the algorithm (SB3's ``learn()`` does when it starts again): that
        episode is cut first (``episode_starts`` of :meth:`~.reward_model.RewardModel.add`).

        Raises:
            RuntimeError: the callback did not hand over this step.
        """
        if self._env_step is None:
            raise RuntimeError(
                f"{type(self).__name__} needs delayed_rl.deep.RewardModelCallback in "
                "learn(callback=...): SB3's on-policy loop adds gamma * V(terminal observation) to "
                "the reward of a truncated step before add(), and only the callback sees the "
                "env's own reward, observations and executed actions"
            )
        observations, actions, delivered, env_rewards, dones, infos, following = self._env_step
        self._env_step = None
        self.delivered_rewards[self.pos] = delivered.reshape(self.n_envs)
        reward = np.asarray(reward, dtype=np.float32).reshape(self.n_envs)
        self.bootstraps[self.pos] = reward - self.delivered_rewards[self.pos]
        self.reward_model.add(
            observations,
            actions,
            env_rewards,
            dones,
            infos,
            next_observations=following,
            episode_starts=episode_start,
        )
        super().add(obs, action, reward, episode_start, value, log_prob)

    def compute_returns_and_advantage(self, last_values: torch.Tensor, dones: np.ndarray) -> None:
        """Train the model as owed; once ready, relabel with ``R̂ + bootstrap``; then SB3's."""
        model = self.reward_model
        model.train_on_schedule()
        steps = self.buffer_size if self.full else self.pos
        if model.ready and steps:
            history = model.history
            rows = history.rows(history.steps_added - steps, history.steps_added)[:, None]
            envs = np.arange(self.n_envs)[None, :]
            with torch.no_grad():
                relabelled = model.network(*model.inputs_at(rows, envs)).numpy()
            if self.watched:
                model.watch(relabelled, history.undelayed[rows, envs].ravel())
            scaled = relabelled.reshape(steps, self.n_envs)
            if self.vec_normalize is not None:
                scaled = self.vec_normalize.normalize_reward(scaled)
            self.rewards[:steps] = scaled + self.bootstraps[:steps]
        super().compute_returns_and_advantage(last_values, dones)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["vec_normalize"] = None
        return state


class RelabelingRolloutBuffer(_RelabelingOnPolicy, RolloutBuffer):
    """SB3's ``RolloutBuffer`` whose rewards become ``R̂(s, a)`` (plus any bootstrap).

    The relabelling happens before returns and advantages are computed; it needs
    :class:`~delayed_rl.deep.callbacks.RewardModelCallback` (see ``docs/deep_rl.md``).

    Args:
        buffer_size, observation_space, action_space, device: as SB3's ``RolloutBuffer``.
        gae_lambda, gamma, n_envs: as SB3's ``RolloutBuffer``.
        reward_model: the model to train and relabel with, or a mapping that the buffer makes
            it from, as :class:`RelabelingReplayBuffer` takes it.

    Attributes:
        reward_model: the model.
        delivered_rewards: per step, the rewards as the algorithm received them, before any
            bootstrap (from the callback).
        bootstraps: per step, what SB3 added to them (``γ·V(terminal observation)`` at a
            truncation, else 0).
        vec_normalize: the algorithm's ``VecNormalize`` (set by the callback), whose reward
            normalisation the relabelled rewards get.
        watched: whether relabelled rollouts go to the model's diagnostics.

    Raises:
        TypeError, ValueError: see ``docs/deep_rl.md`` ("Refused at construction").

    Example:
        >>> import gymnasium as gym
        >>> from stable_baselines3 import PPO
        >>> from delayed_rl.wrappers import RewardDelay
        >>> kwargs = {"reward_model": {"type": "ReturnRegressionRewardModel"}}  # for env's spaces
        >>> agent = PPO("MlpPolicy", RewardDelay(gym.make("CartPole-v1"), 20), n_steps=64, seed=0,
        ...             rollout_buffer_class=RelabelingRolloutBuffer, rollout_buffer_kwargs=kwargs)
        >>> agent.learn(64)  # learn(64, callback=RewardModelCallback()) trains
        Traceback (most recent call last):
            ...
        RuntimeError: RelabelingRolloutBuffer needs delayed_rl.deep.RewardModelCallback in learn(...
    """

    counterpart = "RelabelingDictRolloutBuffer"


class RelabelingDictRolloutBuffer(_RelabelingOnPolicy, DictRolloutBuffer):
    """SB3's ``DictRolloutBuffer`` whose rewards become ``R̂(s, a)``, for ``MultiInputPolicy``.

    Takes what :class:`RelabelingRolloutBuffer` takes, for a ``Dict`` observation space.

    Example:
        >>> import gymnasium as gym
        >>> import delayed_rl
        >>> from stable_baselines3 import PPO
        >>> env = gym.make("delayed_rl/GridWorld-3x3-v0", observation_delay=1, delay_aware=True,
        ...                action_history=4, reward_delay=2)  # a Dict view, rewards late
        >>> agent = PPO("MultiInputPolicy", env, n_steps=64, seed=0,
        ...             rollout_buffer_class=RelabelingDictRolloutBuffer,
        ...             rollout_buffer_kwargs={"reward_model": {"type": "ReturnRegressionRewardModel"}})
        >>> sorted(agent.rollout_buffer.observations)  # the view's keys, stored and read by R̂
        ['actions', 'age', 'observation']
    """

    takes_dict = True
    counterpart = "RelabelingRolloutBuffer"
