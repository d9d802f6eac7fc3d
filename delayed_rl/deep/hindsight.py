"""SAC for late observations and actions: an actor on what the agent knows, a critic in hindsight.

:class:`HindsightSAC` acts on the delay-aware view (:class:`~delayed_rl.wrappers.DelayAwareObservation`)
and learns its critic on the observation made at each step, once it has arrived, with the
actions then in transit (BPQL's "beta" critic, for random delays); :class:`HindsightReplayBuffer`
stores a step only once the view has received what it needs, and :class:`HindsightPolicy` feeds
the actor and the critic their inputs. The rule, what the learner may read and when, and why
this learner: the docs' deep RL page (``docs/deep_rl.md``, "HindsightSAC").
"""

from __future__ import annotations

import json
import math
import zipfile
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from stable_baselines3 import SAC
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.save_util import open_path
from stable_baselines3.common.torch_layers import CombinedExtractor
from stable_baselines3.sac.policies import Actor, ContinuousCritic, MultiInputPolicy

from delayed_rl._validation import check_choice
from delayed_rl.wrappers.delay_aware import VIEW_KEYS

__all__ = [
    "CRITIC_INPUTS",
    "HINDSIGHT_AGE_KEY",
    "HINDSIGHT_KEY",
    "HindsightPolicy",
    "HindsightReplayBuffer",
    "HindsightSAC",
    "ViewActor",
    "hindsight_space",
]

HINDSIGHT_KEY = "hindsight"
"""The stored observation the critic reads for the transition's step (received later)."""
HINDSIGHT_AGE_KEY = "hindsight_age"
"""With ``critic_input="newest"``: how many steps before the transition's step it was made."""
CRITIC_INPUTS = ("made", "newest")
"""The values of :class:`HindsightSAC`'s ``critic_input``."""


def check_view_space(space: Any, name: str = "observation_space") -> spaces.Dict:
    """``space`` if it is a delay-aware view's ``Dict``.

    Raises:
        TypeError: it is not a ``Dict`` with the view's keys.
    """
    if not isinstance(space, spaces.Dict) or set(space.spaces) != set(VIEW_KEYS):
        raise TypeError(
            f"{name} must be the Dict of delayed_rl.wrappers.DelayAwareObservation (keys "
            f"{list(VIEW_KEYS)}), got {space!r}: wrap the env in DelayAwareObservation, without "
            "FlattenObservation"
        )
    return space


def critic_space(view: spaces.Dict, critic_input: str = "newest") -> spaces.Dict:
    """What the critic reads: the hindsight observation (its age too, for ``"newest"``), actions.

    ``"actions"`` are the view's: the last ``K`` actions sent before the transition's step.
    """
    hindsight = {HINDSIGHT_KEY: view.spaces["observation"], "actions": view["actions"]}
    if critic_input == "newest":
        hindsight[HINDSIGHT_AGE_KEY] = view["age"]
    return spaces.Dict(hindsight)


def hindsight_space(view: spaces.Dict, critic_input: str = "newest") -> spaces.Dict:
    """The replay buffer's space: the view's keys and the critic's hindsight keys."""
    return spaces.Dict({**critic_space(view, critic_input).spaces, **view.spaces})


class ViewActor(Actor):
    """SAC's actor, reading only the view's keys of a ``Dict`` that may hold more."""

    def extract_features(self, obs: Any, features_extractor: Any) -> Any:
        """The features of the view's keys (the buffer's ``"hindsight"`` left out)."""
        view = {key: obs[key] for key in self.observation_space.spaces}
        return super().extract_features(view, features_extractor)


class HindsightPolicy(MultiInputPolicy):
    """SAC's ``MultiInputPolicy`` whose critic reads ``"hindsight"`` and ``"actions"``.

    The actor is SAC's, on the view's ``Dict`` (SB3's ``CombinedExtractor``: each key flattened,
    the age one-hot). The critics (and their targets) are SAC's ``ContinuousCritic`` on the
    hindsight observation of the transition's step (with its age, for ``critic_input=
    "newest"``) and the actions sent before it, through their own ``CombinedExtractor``; they
    are given the buffer's whole ``Dict`` and read those keys (:func:`critic_space`).

    Args:
        *args: SAC's ``MultiInputPolicy``'s positional arguments.
        critic_input: ``"newest"`` or ``"made"``, set by :class:`HindsightSAC` (whose default
            is ``"newest"``); ``"made"`` by default here, what a policy file saved before
            ``critic_input`` existed holds.
        **kwargs: SAC's ``MultiInputPolicy``'s keyword arguments.
    """

    def __init__(self, *args: Any, critic_input: str = "made", **kwargs: Any):
        self.critic_input = check_choice("critic_input", critic_input, CRITIC_INPUTS)
        super().__init__(*args, **kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return {**super()._get_constructor_parameters(), "critic_input": self.critic_input}

    def make_actor(self, features_extractor: Any = None) -> ViewActor:
        """SAC's actor on the view (:class:`ViewActor`)."""
        kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        return ViewActor(**kwargs).to(self.device)

    def make_critic(self, features_extractor: Any = None) -> ContinuousCritic:
        """SAC's critic, on :func:`critic_space` (its own extractor: never the actor's)."""
        space = critic_space(self.observation_space, self.critic_input)
        kwargs = self._update_features_extractor(self.critic_kwargs, CombinedExtractor(space))
        kwargs["observation_space"] = hindsight_space(self.observation_space, self.critic_input)
        return ContinuousCritic(**kwargs).to(self.device)


class HindsightReplayBuffer(DictReplayBuffer):
    """SB3's ``DictReplayBuffer`` (one column) with each transition's own discount.

    A transition may span several steps (from one received observation to the next), so its
    reward is their discounted sum and its discount ``γ`` to the power of their number; SAC's
    ``train()`` reads ``discounts`` as it does from SB3's n-step buffer.
    """

    def __init__(self, buffer_size: int, observation_space: Any, action_space: Any, **kwargs):
        super().__init__(buffer_size, observation_space, action_space, n_envs=1, **kwargs)
        self.discounts = np.zeros((self.buffer_size, 1), dtype=np.float32)

    def add_transition(
        self, obs: dict, next_obs: dict, action: Any, reward: float, done: bool, discount: float
    ) -> None:
        """Store one transition (no timeout: a truncation is stored with ``done=False``)."""
        self.discounts[self.pos] = discount
        self.add(
            {key: np.asarray(value)[None] for key, value in obs.items()},
            {key: np.asarray(value)[None] for key, value in next_obs.items()},
            np.asarray(action)[None],
            np.array([reward]),
            np.array([done]),
            [{}],
        )

    def _get_samples(self, batch_inds: np.ndarray, env: Any = None) -> Any:
        samples = super()._get_samples(batch_inds, env)
        return samples._replace(discounts=self.to_torch(self.discounts[batch_inds]))


class _Episode:
    """One sub-env's current episode: its steps until each is stored or dropped."""

    def __init__(self) -> None:
        self.steps = 0  # n: the view x_n is the current one (x_0 the reset's)
        self.first = 0  # the earliest step not yet stored or dropped
        self.views: dict[int, dict[str, np.ndarray]] = {}
        self.actions: dict[int, np.ndarray] = {}
        self.rewards: dict[int, float] = {}
        self.received: dict[int, np.ndarray] = {}  # made step -> observation
        self.ended = False
        self.terminated = False

    def receive_view(self, view: dict[str, np.ndarray]) -> None:
        """Keep the view ``x_n`` and its newest observation (made ``age`` steps before ``n``)."""
        self.views[self.steps] = view
        age = int(np.asarray(view["age"]).reshape(-1)[0])
        self.receive(self.steps - age, view["observation"])

    def receive(self, made: int, observation: Any) -> None:
        self.received.setdefault(int(made), np.array(observation))


def _saved_critic_input(path: Any) -> bool:
    """Whether the SB3 file at ``path`` records a ``critic_input`` (a file object is rewound).

    Only the file's ``data`` entry (SB3's JSON of the saved attributes) is read, not its tensors.
    """
    file = open_path(path, "r", verbose=0, suffix="zip")  # ``path`` itself when a file object
    start = file.tell()
    try:
        with zipfile.ZipFile(file) as archive:
            return "critic_input" in json.loads(archive.read("data"))
    finally:
        if file is path:
            file.seek(start)
        else:
            file.close()


class HindsightSAC(SAC):
    """SAC with its actor on the delay-aware view and its critic on observations in hindsight.

    Args:
        policy: ``"MultiInputPolicy"`` (:class:`HindsightPolicy`: the view is a ``Dict``), or
            the class.
        env: a :class:`~delayed_rl.wrappers.DelayAwareObservation` env (its ``Dict``, not
            flattened), or a vector env of them.
        critic_input: what the critic reads for a step ``τ`` (beside the actions sent before it):
            ``"newest"`` (the default), the newest observation made at or before ``τ`` that
            arrived by the time nothing newer can, and its age at ``τ`` (``"hindsight_age"``);
            every step is a one-step transition. ``"made"``: the observation made at ``τ``, once
            it has arrived; a step whose observation never arrives starts no transition, and a
            transition spans the steps to the next one whose observation arrived. ``"newest"``
            learned faster in the measurements (``docs/late_observations.md``). A file saved
            before ``critic_input`` existed loads as ``"made"``, the only input then.
        **kwargs: SAC's (``learning_rate``, ``buffer_size``, ``learning_starts``, ``seed``...).

    Attributes:
        transitions_stored: the transitions that entered the replay buffer.
        transitions_dropped: those that never could (an observation they need never arrived;
            none with ``critic_input="newest"``).

    Raises:
        TypeError: an env that is not a view; a ``replay_buffer_class``; a ``critic_input``
            that is not a string.
        ValueError: a policy name but ``"MultiInputPolicy"``, ``optimize_memory_usage``,
            ``n_steps > 1``, an unknown ``critic_input``.

    ``docs/deep_rl.md`` ("HindsightSAC") states the rule, what the learner may read and when.

    Example:
        >>> import gymnasium as gym
        >>> from delayed_rl.delays import Constant
        >>> from delayed_rl.wrappers import wrap_delays
        >>> late = {"observation_delay": Constant(2), "action_delay": Constant(1)}
        >>> env = wrap_delays(gym.make("Pendulum-v1"), **late, delay_aware=True)  # the view
        >>> agent = HindsightSAC("MultiInputPolicy", env, learning_starts=200, seed=0).learn(100)
        >>> agent.transitions_stored  # all but the last 2 steps, whose observations are in transit
        98
    """

    policy_aliases: ClassVar[dict[str, type]] = {
        "MultiInputPolicy": HindsightPolicy,
    }

    def __init__(self, policy: Any, env: Any, critic_input: str = "newest", **kwargs: Any):
        self.critic_input = check_choice("critic_input", critic_input, CRITIC_INPUTS)
        if isinstance(policy, str) and policy not in self.policy_aliases:
            raise ValueError(
                f"policy must be 'MultiInputPolicy' (HindsightPolicy: the view is a Dict) or a "
                f"policy class, got {policy!r}"
            )
        if kwargs.get("replay_buffer_class") is not None:
            raise TypeError(
                "HindsightSAC keeps its own replay buffer (the view with the hindsight "
                f"observation), got replay_buffer_class={kwargs['replay_buffer_class']!r}"
            )
        if kwargs.get("optimize_memory_usage"):
            raise ValueError("HindsightSAC takes optimize_memory_usage=False only")
        if kwargs.get("n_steps", 1) != 1:
            raise ValueError(f"HindsightSAC takes n_steps=1 only, got {kwargs['n_steps']!r}")
        self.transitions_stored = 0
        self.transitions_dropped = 0
        self._episodes: list[_Episode] = []
        super().__init__(policy, env, **kwargs)

    def _setup_model(self) -> None:
        view = check_view_space(self.observation_space)
        self.policy_kwargs = {**self.policy_kwargs, "critic_input": self.critic_input}
        if self.replay_buffer is None:
            self.replay_buffer = HindsightReplayBuffer(
                self.buffer_size,
                hindsight_space(view, self.critic_input),
                self.action_space,
                device=self.device,
                handle_timeout_termination=False,  # the transitions carry their own ends
            )
        self._max_age = int(view["age"].n) - 1
        super()._setup_model()

    @classmethod
    def load(  # noqa: D417 (SB3's arguments)
        cls,
        path: Any,
        env: Any = None,
        device: Any = "auto",
        custom_objects: dict[str, Any] | None = None,
        print_system_info: bool = False,
        force_reset: bool = True,
        **kwargs: Any,
    ) -> HindsightSAC:
        """SAC's ``load``; a file saved before ``critic_input`` existed loads as ``"made"``.

        That file's critic read the observation made at each step, the only input then.
        """
        if "critic_input" not in kwargs and not _saved_critic_input(path):
            kwargs["critic_input"] = "made"
        return super().load(
            path, env, device, custom_objects, print_system_info, force_reset, **kwargs
        )

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_episodes"]

    def _setup_learn(
        self, total_timesteps: int, callback: Any = None, reset_num_timesteps: bool = True, *args
    ) -> Any:
        result = super()._setup_learn(total_timesteps, callback, reset_num_timesteps, *args)
        if reset_num_timesteps or len(self._episodes) != self.n_envs:  # SB3 reset the env
            self._episodes = [_Episode() for _ in range(self.n_envs)]
            for i, episode in enumerate(self._episodes):
                episode.receive_view({k: np.array(v[i]) for k, v in self._last_obs.items()})
        return result

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        """SAC's training, once a transition has entered the replay buffer."""
        if self.replay_buffer.size() > 0:
            super().train(gradient_steps, batch_size)

    def _store_transition(self, replay_buffer, buffer_action, new_obs, reward, dones, infos):
        """Keep each sub-env's step; store what the observations received so far allow."""
        if self._vec_normalize_env is not None:
            raise TypeError("HindsightSAC does not support VecNormalize")
        for i, done in enumerate(dones):
            episode = self._episodes[i]
            step = episode.steps
            episode.actions[step] = np.array(buffer_action[i])
            episode.rewards[step] = float(reward[i])
            episode.steps = step + 1
            terminal = infos[i].get("terminal_observation") if done else None
            source = terminal if terminal is not None else {k: v[i] for k, v in new_obs.items()}
            episode.receive_view({key: np.array(value) for key, value in source.items()})
            for made, observation in infos[i].get("arrived_observations", ()):
                episode.receive(made, observation)
            if done:
                episode.ended = True
                episode.terminated = not infos[i].get("TimeLimit.truncated", False)
            if self.critic_input == "newest":
                self._store_settled_newest(episode)
            else:
                self._store_settled(episode)
            if done:
                self._episodes[i] = _Episode()
                self._episodes[i].receive_view({k: np.array(v[i]) for k, v in new_obs.items()})
        self._last_obs = new_obs

    def _store_settled(self, episode: _Episode) -> None:
        """Store (or drop) each step, in order, once the observations it needs are settled.

        The observation made at step ``m`` can still arrive until the view's step ``m + D``
        (``D`` the age bound); after that, or once the episode ended, it never will.
        """
        settled = math.inf if episode.ended else episode.steps - self._max_age
        received = episode.received
        while episode.first < episode.steps:
            start = episode.first
            if start not in received:
                if start > settled:
                    return  # it may still arrive
                self.transitions_dropped += 1
            else:
                later = [m for m in received if start < m <= episode.steps]
                end = min(later, default=None)
                if end is not None and (end == start + 1 or end - 1 <= settled):
                    self._store(episode, start, end, done=False)
                elif episode.ended and episode.terminated:
                    self._store(episode, start, episode.steps, done=True)
                elif episode.ended:
                    self.transitions_dropped += 1  # truncated: nothing to bootstrap from
                else:
                    return  # a nearer observation may still arrive
            episode.first = start + 1
            for table in (episode.views, episode.actions, episode.rewards):
                table.pop(start, None)
            for made in [m for m in received if m < episode.first]:
                del received[made]

    def _store_settled_newest(self, episode: _Episode) -> None:
        """Store each step, in order, once its critic input and the next step's are settled.

        The input of step ``τ`` is the newest observation made at or before ``τ`` that arrived:
        settled once no observation made by ``τ`` can still arrive (at the view's step
        ``τ + D``), or once the episode ended. The reset's observation always arrives, so every
        step has one.
        """
        settled = math.inf if episode.ended else episode.steps - self._max_age
        received = episode.received
        if episode.first >= episode.steps or episode.first + 1 > settled:
            return
        current = self._newest_before(episode, episode.first)
        while episode.first < episode.steps and episode.first + 1 <= settled:
            start = episode.first
            done = episode.ended and episode.terminated and start + 1 == episode.steps
            following = self._newest_before(episode, start + 1)
            self.replay_buffer.add_transition(
                {**episode.views[start], **current},
                {**episode.views[start + 1], **following},
                episode.actions[start],
                episode.rewards[start],
                done,
                self.gamma,
            )
            self.transitions_stored += 1
            episode.first, current = start + 1, following
            for table in (episode.views, episode.actions, episode.rewards):
                table.pop(start, None)
        kept = max(m for m in received if m <= episode.first)  # the next input's, or newer
        for made in [m for m in received if m < kept]:
            del received[made]

    @staticmethod
    def _newest_before(episode: _Episode, step: int) -> dict[str, Any]:
        """The critic's hindsight keys for ``step``: the newest observation made by then, its age."""
        made = max(m for m in episode.received if m <= step)
        return {HINDSIGHT_KEY: episode.received[made], HINDSIGHT_AGE_KEY: np.int64(step - made)}

    def _store(self, episode: _Episode, start: int, end: int, done: bool) -> None:
        """One transition from ``start`` to ``end``: the discounted rewards between them."""
        reward, discount = 0.0, 1.0
        for step in range(start, end):
            reward += discount * episode.rewards[step]
            discount *= self.gamma
        after = episode.received.get(end, episode.received[start])  # unread when done
        self.replay_buffer.add_transition(
            {**episode.views[start], HINDSIGHT_KEY: episode.received[start]},
            {**episode.views[end], HINDSIGHT_KEY: after},
            episode.actions[start],
            reward,
            done,
            discount,
        )
        self.transitions_stored += 1
