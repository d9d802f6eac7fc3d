"""What every reward model shares: its network, its history, its schedule, files and diagnostics.

:class:`RewardModel` learns ``R̂(s, a)`` from the rewards an env *delivered*, and nothing else:
:meth:`RewardModel.add` keeps a step, :meth:`RewardModel.train_on_schedule` takes the updates
its schedule owes (``updates_per_step``, ``warmup_updates``), :meth:`RewardModel.predict` gives
``R̂``; each subclass states its loss. Its schedule, seeds, diagnostics and files: the docs' deep
RL page (``docs/deep_rl.md``, "What every reward model shares").
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch

from delayed_rl._validation import Limit, check_int, check_real
from delayed_rl._version import __version__
from delayed_rl.deep.encoding import SpaceEncoding
from delayed_rl.deep.history import TransitionHistory
from delayed_rl.deep.network import RewardNetwork, as_tensors, check_hidden_sizes

__all__ = ["DIAGNOSTIC_PAIRS", "FORMAT", "RewardModel"]

FORMAT = "delayed-rl reward model 3"
"""The ``format`` a reward model file declares."""

MAX_MEMBER_BYTES = Limit(2**34, "MAX_MEMBER_BYTES", __name__, "2**34")
"""The largest member of a reward model file that is read."""

DIAGNOSTIC_PAIRS = 4096
"""The relabelled rewards a logged RMSE and correlation are computed over (at least)."""

HISTORY_ARRAYS = ("reward", "episode_end", "episode_cut", "undelayed")
"""The history's arrays a file holds beside its observations and actions."""


def _pair(name: str, value: Any, count: int) -> np.ndarray:
    """``value`` as ``count`` floats (rewards) or bools (episode ends), checked."""
    array = np.asarray(value)
    if array.dtype.kind not in "biuf":
        raise TypeError(f"{name} must be numbers, got {array.dtype} values")
    if array.size != count:
        raise ValueError(f"{name} must hold {count} values (one a sub-env), got {array.shape}")
    return array.reshape(count)


def _count(encoding: SpaceEncoding, values: Any) -> int:
    """How many values of the space ``values`` holds (read off its first key for a ``Dict``).

    Raises:
        TypeError: a ``Dict`` space's values that are not a dict.
        ValueError: a ``Dict`` space's values without its first key.
    """
    if encoding.parts is not None:
        key = next(iter(encoding.parts))
        if not isinstance(values, dict):
            raise TypeError(
                f"{encoding.name} values must be a dict with keys {list(encoding.parts)}, got "
                f"{type(values).__name__}"
            )
        if key not in values:
            raise ValueError(f"{encoding.name} values must have the key {key!r}")
        return _count(encoding.parts[key], values[key])
    return np.asarray(values).size // int(np.prod(encoding.shape, dtype=np.int64))


class RewardModel(ABC):
    """A learned ``R̂(s, a)``, fitted to the delivered rewards by a subclass's :meth:`loss`.

    Args:
        observation_space: the env's observation space (``Box``, ``Discrete``,
            ``MultiDiscrete``, ``MultiBinary`` or a ``Dict`` of those; see
            :mod:`delayed_rl.deep.network` for how each is read).
        action_space: its action space, likewise, as the algorithm stores actions (SAC and TD3
            store them squashed to [-1, 1]: a buffer trains and queries the model with what it
            stores; the on-policy buffer, with the actions the env executed).
        hidden_sizes: the MLP's hidden layers.
        learning_rate: Adam's step size.
        batch_size: how many targets an update fits (a subclass says what a target is).
        updates_per_step: Adam updates owed for each step added (see ``docs/deep_rl.md``).
        warmup_updates: updates owed on top of those, taken at once when the loss first can be
            computed; the model is :attr:`ready` after them (and after at least one update:
            with ``updates_per_step=0`` and ``warmup_updates=0`` it only keeps the stream).
        capacity: steps of every sub-env the history keeps (its memory: ``capacity`` · n_envs
            transitions).
        seed: seeds the initial weights and the batches (``None``: fresh entropy, or the seed a
            seeded algorithm's buffer derives for it; see ``docs/deep_rl.md``).

    Attributes:
        network: the :class:`~delayed_rl.deep.network.RewardNetwork`.
        history: the :class:`~delayed_rl.deep.history.TransitionHistory` (made at the first
            :meth:`add`, which fixes the number of sub-envs).
        updates_taken: how many Adam updates it took.
        seed: the seed its randomness came from.
        takes_algorithm_seed: whether a seeded algorithm's buffer will seed it (it was made
            with ``seed=None`` and has seen no step).

    Example:
        >>> import gymnasium as gym
        >>> from delayed_rl.deep import DeconvolutionRewardModel  # a concrete RewardModel
        >>> env = gym.make("CartPole-v1")
        >>> model = DeconvolutionRewardModel(
        ...     env.observation_space, env.action_space, delay=2, updates_per_step=0.05,
        ...     warmup_updates=5, seed=0,
        ... )
        >>> obs, _ = env.reset(seed=0)
        >>> for _ in range(100):  # what a buffer hands it at each step (one sub-env here)
        ...     model.add([obs], [0], [1.0], [False])
        >>> model.train_on_schedule(), model.ready  # 100 steps × 0.05 updates, + 5 warm-up ones
        (10, True)
        >>> model.predict([obs, obs], [0, 1]).shape  # R̂ of a batch of (s, a)
        (2,)
    """

    #: The settings a subclass adds, in its constructor's order (saved in files).
    own_settings: ClassVar[tuple[str, ...]] = ()

    def __init__(
        self,
        observation_space: Any,
        action_space: Any,
        *,
        hidden_sizes: Sequence[int] = (64, 64),
        learning_rate: float = 1e-3,
        batch_size: int = 256,
        updates_per_step: float = 1.0,
        warmup_updates: int = 1000,
        capacity: int = 100_000,
        seed: int | None = None,
    ):
        self.observations = SpaceEncoding("observation_space", observation_space)
        self.actions = SpaceEncoding("action_space", action_space)
        self.hidden_sizes = check_hidden_sizes(hidden_sizes)
        self.learning_rate = check_real("learning_rate", learning_rate, 0.0, 1e6, low_open=True)
        self.batch_size = check_int("batch_size", batch_size, 1, 2**20)
        self.updates_per_step = check_real("updates_per_step", updates_per_step, 0.0, 2**20)
        self.warmup_updates = check_int("warmup_updates", warmup_updates, 0, 2**31)
        self.capacity = check_int("capacity", capacity, 1)
        seed = check_int("seed", seed, 0, 2**63 - 1, optional=True)
        self.takes_algorithm_seed = seed is None
        self.history: TransitionHistory | None = None
        self.updates_taken = 0
        self._loss_sum, self._loss_count = 0.0, 0  # since the last record()
        self._watched: list[tuple[np.ndarray, np.ndarray]] = []  # the block being filled
        self._diagnostics: dict[str, float] = {}
        self._initialise(int(np.random.SeedSequence().entropy % 2**63) if seed is None else seed)

    def _initialise(self, seed: int) -> None:
        """Make the generator, the network, the subclass's parameters and Adam from ``seed``."""
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            self.network = RewardNetwork(
                self.observations,
                self.actions,
                self.hidden_sizes,
                state_change=self.reads_next_observation,
            )
            self._make_parameters()
        self.optimizer = self._make_optimizer()

    def reseed(self, seed: int) -> None:
        """Start afresh from ``seed``: weights, parameters, Adam and generator (before any step).

        Raises:
            TypeError, ValueError: ``seed`` is not an integer in ``0..2**63 − 1``.
            RuntimeError: the model has seen a step.
        """
        seed = check_int("seed", seed, 0, 2**63 - 1)
        if self.history is not None:
            raise RuntimeError("a reward model that has seen a step cannot be seeded again")
        self._initialise(seed)
        self.takes_algorithm_seed = False

    # ------------------------------------------------------------------ what a subclass adds
    def _make_parameters(self) -> None:  # noqa: B027 (a hook: most models add nothing)
        """Make the parameters learned beside the network (called under the model's seed)."""

    def _make_optimizer(self) -> torch.optim.Optimizer:
        """Adam over the network's parameters (a subclass adds its own)."""
        return torch.optim.Adam(self.network.parameters(), lr=self.learning_rate, foreach=True)

    def _extra_state(self) -> dict[str, torch.Tensor]:
        """The subclass's learned tensors, by name (saved beside the network's)."""
        return {}

    def _load_extra_state(self, tensors: dict[str, torch.Tensor]) -> None:  # noqa: B027
        """Set the subclass's learned tensors from a file's (checked by the caller for names)."""

    def _settings(self) -> dict[str, Any]:
        """The subclass's own constructor arguments, JSON-able (see :attr:`own_settings`)."""
        return {name: getattr(self, name) for name in self.own_settings}

    @property
    def reads_next_observation(self) -> bool:
        """Whether ``R̂`` also reads the next observation ``s′`` (RRD's ``state_change``)."""
        return False

    @abstractmethod
    def loss(self) -> torch.Tensor | None:
        """One batch's loss, sampled from the history with ``rng`` (``None``: too little data)."""

    def metrics(self) -> dict[str, float]:
        """What the model logs beside its loss and diagnostics (the learned mean delay...)."""
        return {}

    # ------------------------------------------------------------------ the stream
    def add(
        self,
        observations: Any,
        actions: Any,
        rewards: Any,
        episode_ends: Any,
        infos: Sequence[dict] | None = None,
        next_observations: Any = None,
        episode_starts: Any = None,
    ) -> None:
        """Keep one step of every sub-env (it trains only when asked: :meth:`train_on_schedule`).

        Args:
            observations: one observation a sub-env, as the algorithm stores them (a dict of
                arrays for a ``Dict`` space).
            actions: the actions taken, likewise.
            rewards: the rewards the env delivered at this step.
            episode_ends: whether each sub-env's episode ended at this step (terminated or
                truncated; the observation after it is the next episode's).
            infos: the step's ``infos``, read only for the diagnostic ``undelayed_reward``.
            next_observations: the observations each sub-env's step led to (at an episode's
                end, its terminal observation), needed by a model that
                :attr:`reads_next_observation` and ignored by the others.
            episode_starts: whether each sub-env starts an episode at this step (``None``: as the
                last step's ``episode_ends`` say). A sub-env that starts one though its last step
                ended none was reset in the middle of an episode (SB3's ``learn()`` resets its
                env when it starts with ``reset_num_timesteps=True``, the default): that episode
                is cut at its last step (:meth:`~delayed_rl.deep.history.TransitionHistory.cut`),
                and is not a finished episode.

        Raises:
            TypeError, ValueError: an argument that does not hold one value a sub-env of the
                right space, or a number of sub-envs other than the first call's.
        """
        count = np.asarray(rewards).size
        if self.history is None:
            check_int("the number of sub-envs (rewards' length)", count, 1)
        elif count != self.history.n_envs:
            raise ValueError(
                f"rewards must hold one reward for each of the {self.history.n_envs} sub-envs "
                f"the model has seen, got {count}"
            )
        reward = _pair("rewards", rewards, count).astype(np.float64)
        if not np.all(np.isfinite(reward)):
            raise ValueError(f"rewards must be finite, got {reward}")
        ends = _pair("episode_ends", episode_ends, count).astype(bool)
        starts = None if episode_starts is None else _pair("episode_starts", episode_starts, count)
        obs = self.observations.batch(observations, count)
        next_obs = self._next_batch("add()", next_observations, count)
        action = self.actions.batch(actions, count)
        undelayed = np.full(count, np.nan)
        if infos is not None:
            for i, info in enumerate(infos):
                value = info.get("undelayed_reward") if isinstance(info, dict) else None
                if isinstance(value, (int, float, np.number)):
                    undelayed[i] = float(value)
        if self.history is None:  # made once the first step is checked (it fixes n_envs)
            self.history = TransitionHistory(
                self.observations,
                self.actions,
                count,
                self.capacity,
                keep_next=self.reads_next_observation,
            )
            self.takes_algorithm_seed = False
        if starts is not None:
            self.history.cut(np.flatnonzero(starts))
        self.history.add(obs, action, reward, ends, undelayed, next_obs)

    @property
    def updates_due(self) -> int:
        """The updates the schedule asks for by now (the warm-up's included)."""
        steps = 0 if self.history is None else self.history.steps_added
        return math.floor(steps * self.updates_per_step) + self.warmup_updates if steps else 0

    @property
    def ready(self) -> bool:
        """Whether the warm-up is done (and one update at least taken): buffers relabel only then."""
        return self.updates_taken >= max(1, self.warmup_updates)

    def train_on_schedule(self) -> int:
        """Take the updates the schedule owes (none while the loss cannot be computed).

        Returns:
            The number of updates taken.
        """
        return self.train(max(0, self.updates_due - self.updates_taken))

    def train(self, updates: int) -> int:
        """Take up to ``updates`` Adam updates on batches from the history.

        Returns:
            The number taken (fewer when the loss cannot be computed yet).
        """
        taken = 0
        for _ in range(check_int("updates", updates, 0)):
            if self.history is None:
                break
            loss = self.loss()
            if loss is None:
                break
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.optimizer.step()
            self.updates_taken += 1
            taken += 1
            self._loss_sum += float(loss.detach())
            self._loss_count += 1
        return taken

    # ------------------------------------------------------------------ predictions
    def inputs_at(self, rows: np.ndarray, envs: np.ndarray) -> list[Any]:
        """The network's inputs for the history's steps at ``[rows, envs]``, as tensors."""
        history = self.history
        inputs = [history.observations_at(rows, envs), history.actions_at(rows, envs)]
        if self.reads_next_observation:
            inputs.append(history.next_observations_at(rows, envs))
        return [as_tensors(values) for values in inputs]

    def reward_tensor(
        self, observations: Any, actions: Any, next_observations: Any = None
    ) -> torch.Tensor:
        """``R̂`` of stored values (as the history keeps them, flattened), without gradients.

        ``next_observations`` is read by a model that :attr:`reads_next_observation` only.
        """
        inputs = [as_tensors(observations), as_tensors(actions)]
        if self.reads_next_observation:
            inputs.append(as_tensors(next_observations))
        with torch.no_grad():
            return self.network(*inputs)

    def predict(self, observations: Any, actions: Any, next_observations: Any = None) -> np.ndarray:
        """``R̂(s, a)`` (or ``R̂(s, a, s′)``) for a batch: ``float32``, one value a pair.

        Raises:
            TypeError, ValueError: the batches do not hold values of the spaces, or differ in
                length; ``next_observations`` is missing for a model that
                :attr:`reads_next_observation`.
        """
        count = _count(self.actions, actions)
        inputs = [self.observations.batch(observations, count), self.actions.batch(actions, count)]
        following = self._next_batch("predict()", next_observations, count)
        if following is not None:
            inputs.append(following)
        return self.reward_tensor(*inputs).numpy().astype(np.float32)

    def _next_batch(self, caller: str, next_observations: Any, count: int) -> Any:
        """The batch of ``next_observations`` for a model that reads them (else ``None``).

        Raises:
            ValueError: the model reads them and ``caller`` was given none.
        """
        if not self.reads_next_observation:
            return None
        if next_observations is None:
            raise ValueError(
                f"{type(self).__name__} reads the next observation (state_change=True): "
                f"{caller} needs next_observations, got None"
            )
        return self.observations.batch(next_observations, count)

    # ------------------------------------------------------------------ diagnostics
    def rmse(self, last: int = 10_000) -> float:
        """The RMSE of ``R̂`` against ``info["undelayed_reward"]`` over the last ``last`` steps.

        A diagnostic for the end of a run (it evaluates ``R̂`` on up to ``last`` · n_envs
        steps), over the steps whose info had the key (NaN when none had).
        """
        history = self.history
        if history is None:
            return math.nan
        first = max(history.oldest, history.steps_added - check_int("last", last, 1))
        rows = history.rows(first, history.steps_added)
        truth = history.undelayed[rows]
        held = np.isfinite(truth)
        if not held.any():
            return math.nan
        envs = np.broadcast_to(np.arange(history.n_envs), truth.shape)
        row_index = np.broadcast_to(rows[:, None], truth.shape)
        with torch.no_grad():
            predicted = self.network(*self.inputs_at(row_index[held], envs[held]))
        error = predicted.numpy().astype(np.float64) - truth[held]
        return float(np.sqrt(np.mean(error**2)))

    def watch(self, predicted: np.ndarray, undelayed: np.ndarray) -> None:
        """Add relabelled rewards and their undelayed rewards (NaN: unknown) to the diagnostics.

        Pairs are kept until a block holds :data:`DIAGNOSTIC_PAIRS`; the block's RMSE and
        correlation (computed on centred values, in float64) then replace the last ones.
        """
        held = np.isfinite(undelayed)
        if not held.any():
            return
        block = self._watched
        block.append(
            (np.asarray(predicted, np.float64)[held], np.asarray(undelayed, np.float64)[held])
        )
        if sum(x.size for x, _ in block) < DIAGNOSTIC_PAIRS:
            return
        x = np.concatenate([x for x, _ in block])
        y = np.concatenate([y for _, y in block])
        block.clear()
        error = x - y
        self._diagnostics = {"rmse": float(np.sqrt(np.mean(error * error)))}
        if np.ptp(x) > 0 and np.ptp(y) > 0:  # a constant side has no correlation
            dx, dy = x - np.mean(x), y - np.mean(y)
            spread = np.sqrt(np.sum(dx * dx) * np.sum(dy * dy))
            self._diagnostics["correlation"] = float(np.clip(np.sum(dx * dy) / spread, -1, 1))

    def diagnostics(self) -> dict[str, float]:
        """The RMSE and correlation of ``R̂`` with the undelayed reward over the last full block.

        Empty until :data:`DIAGNOSTIC_PAIRS` watched pairs had an undelayed reward; no
        ``correlation`` when either side was constant.
        """
        return dict(self._diagnostics)

    def record(self, logger: Any, prefix: str = "reward_model") -> None:
        """Write the loss (mean since the last call), diagnostics and :meth:`metrics` to ``logger``.

        ``logger`` is SB3's, or anything with ``record(key, value)``.
        """
        if self._loss_count:
            logger.record(f"{prefix}/loss", self._loss_sum / self._loss_count)
            self._loss_sum, self._loss_count = 0.0, 0
        for key, value in (*self._diagnostics.items(), *self.metrics().items()):
            logger.record(f"{prefix}/{key}", value)
        logger.record(f"{prefix}/updates", self.updates_taken)

    # ------------------------------------------------------------------ files
    def settings(self) -> dict[str, Any]:
        """The constructor's arguments but the spaces, JSON-able."""
        return {
            "hidden_sizes": list(self.hidden_sizes),
            "learning_rate": self.learning_rate,
            "batch_size": self.batch_size,
            "updates_per_step": self.updates_per_step,
            "warmup_updates": self.warmup_updates,
            "capacity": self.capacity,
            "seed": self.seed,
            **self._settings(),
        }

    def save(self, path: str | Path) -> Path:
        """Write the model (settings, weights, optimizer, history, counters) to a zip file."""
        path = Path(path)
        tensors = {
            "network": self.network.state_dict(),
            "extra": self._extra_state(),
            "optimizer": self.optimizer.state_dict(),
        }
        weights = io.BytesIO()
        torch.save(tensors, weights)
        header = {
            "format": FORMAT,
            "class": type(self).__name__,
            "version": __version__,
            "observation_space": self.observations.to_dict(),
            "action_space": self.actions.to_dict(),
            "settings": self.settings(),
            "rng": self.rng.bit_generator.state,
            "counters": {
                "updates_taken": self.updates_taken,
                "steps_added": 0 if self.history is None else self.history.steps_added,
                "n_envs": 0 if self.history is None else self.history.n_envs,
            },
        }
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.writestr("reward_model.json", json.dumps(header))
            archive.writestr("weights.pt", weights.getvalue())
            if self.history is not None:
                history = self.history
                arrays = {
                    **self.observations.arrays(history.obs, "obs"),
                    **(
                        {}
                        if history.next_obs is None
                        else self.observations.arrays(history.next_obs, "next_obs")
                    ),
                    **self.actions.arrays(history.action, "action"),
                    **{name: getattr(history, name) for name in HISTORY_ARRAYS},
                }
                stream = io.BytesIO()
                np.savez(stream, **arrays)
                archive.writestr("history.npz", stream.getvalue())
        return path

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_loss_sum"], state["_loss_count"], state["_watched"] = 0.0, 0, []
        return state
