"""What every reward model shares: its network, its history, when it trains, files and logs.

A reward model learns ``R̂(s, a)`` from the rewards an env *delivered*, and nothing else: it is
anonymous. :meth:`RewardModel.add` takes one step of every sub-env (observations, actions,
delivered rewards, episode ends and, optionally, the step's ``infos``), keeps it in a
:class:`~delayed_rl.deep.history.TransitionHistory` and trains the network on its schedule;
:meth:`RewardModel.predict` gives ``R̂`` for a batch. Each subclass states its loss
(:meth:`RewardModel.loss`). The ``infos`` serve diagnostics only (the RMSE of ``R̂`` against
``info["undelayed_reward"]`` where present): learning is the same to the bit without them.

**Schedule.** Counted in calls of :meth:`~RewardModel.add` (steps of the vector env, as SB3's
``train_freq`` counts): once ``learning_starts`` steps are in, every ``train_every`` steps the
model takes ``gradient_steps`` Adam steps. Its randomness (initial weights, the batches it
samples) comes from its own ``seed``: it draws nothing from numpy's or torch's global generators,
so adding a reward model leaves the algorithm's own random draws unchanged.

**Files.** :meth:`~RewardModel.save` writes a zip of JSON (the class, its settings, spaces and
counters), tensors (read back with ``torch.load(weights_only=True)``) and ``.npz`` arrays (read
without pickle); :func:`~delayed_rl.deep.files.load_reward_model` checks every part before use. A reward model also
pickles, which is how SB3's ``save_replay_buffer`` and ``model.save`` (through the buffer's
kwargs) keep it. Results are the same bits on one machine; torch's CPU kernels differ between
CPUs, so across machines runs agree in distribution, not bit for bit.
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

from delayed_rl._validation import check_int, check_real
from delayed_rl._version import __version__
from delayed_rl.deep.encoding import SpaceEncoding
from delayed_rl.deep.history import TransitionHistory
from delayed_rl.deep.network import RewardNetwork, check_hidden_sizes

__all__ = ["FORMAT", "RewardModel"]

FORMAT = "delayed-rl reward model 1"
"""The ``format`` a reward model file declares."""

MAX_FILE_BYTES = 2**34
"""The largest member of a reward model file that is read."""

_ARRAYS = ("obs", "action", "reward", "episode_end", "undelayed")


def _pair(name: str, value: Any, count: int) -> np.ndarray:
    """``value`` as ``count`` floats (rewards) or bools (episode ends), checked."""
    array = np.asarray(value)
    if array.dtype.kind not in "biuf":
        raise TypeError(f"{name} must be numbers, got {array.dtype} values")
    if array.size != count:
        raise ValueError(f"{name} must hold {count} values (one a sub-env), got {array.shape}")
    return array.reshape(count)


class RewardModel(ABC):
    """A learned ``R̂(s, a)``, fitted to the delivered rewards by a subclass's :meth:`loss`.

    Args:
        observation_space: the env's observation space (``Box`` or ``Discrete``).
        action_space: its action space (``Box`` or ``Discrete``), as the algorithm stores actions
            (SAC and TD3 store them squashed to [-1, 1]: a buffer trains and queries the model
            with what it stores).
        hidden_sizes: the MLP's hidden layers.
        learning_rate: Adam's step size.
        batch_size: how many targets a gradient step fits (a subclass says what a target is).
        learning_starts: steps added before the first gradient step.
        train_every: steps between training rounds.
        gradient_steps: gradient steps a round.
        capacity: steps of every sub-env the history keeps (its memory: ``capacity`` · n_envs
            transitions).
        seed: seeds the initial weights and the batches (``None``: fresh entropy).

    Attributes:
        network: the :class:`~delayed_rl.deep.network.RewardNetwork`.
        history: the :class:`~delayed_rl.deep.history.TransitionHistory` (made at the first
            :meth:`add`, which fixes the number of sub-envs).
        gradient_steps_taken: how many gradient steps it took.
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
        learning_starts: int = 256,
        train_every: int = 1,
        gradient_steps: int = 1,
        capacity: int = 100_000,
        seed: int | None = None,
    ):
        self.observations = SpaceEncoding("observation_space", observation_space)
        self.actions = SpaceEncoding("action_space", action_space)
        self.hidden_sizes = check_hidden_sizes(hidden_sizes)
        self.learning_rate = check_real("learning_rate", learning_rate, 0.0, 1e6, low_open=True)
        self.batch_size = check_int("batch_size", batch_size, 1, 2**20)
        self.learning_starts = check_int("learning_starts", learning_starts, 0)
        self.train_every = check_int("train_every", train_every, 1)
        self.gradient_steps = check_int("gradient_steps", gradient_steps, 0, 2**20)
        self.capacity = check_int("capacity", capacity, 1)
        seed = check_int("seed", seed, 0, optional=True)
        self.seed = int(np.random.SeedSequence().entropy % 2**63) if seed is None else seed
        self.rng = np.random.default_rng(self.seed)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(self.seed)
            self.network = RewardNetwork(self.observations, self.actions, self.hidden_sizes)
            self._make_parameters()
        self.optimizer = self._make_optimizer()
        self.history: TransitionHistory | None = None
        self.gradient_steps_taken = 0
        self._since_round = 0
        self._losses: list[float] = []

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

    @abstractmethod
    def loss(self) -> torch.Tensor | None:
        """One batch's loss, sampled from the history with ``rng`` (``None``: too little data)."""

    def metrics(self) -> dict[str, float]:
        """What the model logs beside its loss and RMSE (the learned mean delay...)."""
        return {}

    # ------------------------------------------------------------------ the stream
    def add(
        self,
        observations: Any,
        actions: Any,
        rewards: Any,
        episode_ends: Any,
        infos: Sequence[dict] | None = None,
    ) -> None:
        """Take one step of every sub-env, then train if the schedule says so.

        Args:
            observations: one observation a sub-env, as the algorithm stores them.
            actions: the actions taken, likewise.
            rewards: the rewards the env delivered at this step.
            episode_ends: whether each sub-env's episode ended at this step (terminated or
                truncated; the observation after it is the next episode's).
            infos: the step's ``infos``, read only for the diagnostic ``undelayed_reward``.

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
        obs = self.observations.batch(observations, count)
        action = self.actions.batch(actions, count)
        undelayed = np.full(count, np.nan)
        if infos is not None:
            for i, info in enumerate(infos):
                value = info.get("undelayed_reward") if isinstance(info, dict) else None
                if isinstance(value, (int, float, np.number)):
                    undelayed[i] = float(value)
        if self.history is None:  # made once the first step is checked (it fixes n_envs)
            self.history = TransitionHistory(self.observations, self.actions, count, self.capacity)
        self.history.add(obs, action, reward, ends, undelayed)
        self._since_round += 1
        if self.history.steps_added >= self.learning_starts and (
            self._since_round >= self.train_every
        ):
            self._since_round = 0
            self.train(self.gradient_steps)

    def train(self, gradient_steps: int) -> None:
        """Take up to ``gradient_steps`` Adam steps on batches from the history."""
        for _ in range(check_int("gradient_steps", gradient_steps, 0)):
            if self.history is None:
                return
            loss = self.loss()
            if loss is None:
                return
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.optimizer.step()
            self.gradient_steps_taken += 1
            self._losses.append(float(loss.detach()))

    # ------------------------------------------------------------------ predictions
    def reward_tensor(self, observations: np.ndarray, actions: np.ndarray) -> torch.Tensor:
        """``R̂`` of stored values (arrays as the history keeps them), without gradients."""
        with torch.no_grad():
            return self.network(torch.as_tensor(observations), torch.as_tensor(actions))

    def predict(self, observations: Any, actions: Any) -> np.ndarray:
        """``R̂(s, a)`` for a batch: ``float32``, one value a pair.

        Raises:
            TypeError, ValueError: the batches do not hold values of the spaces, or differ in
                length.
        """
        count = np.asarray(actions).size // int(np.prod(self.actions.shape))
        obs = self.observations.batch(observations, count)
        action = self.actions.batch(actions, count)
        return self.reward_tensor(obs, action).numpy().astype(np.float32)

    def rmse(self, last: int = 10_000) -> float:
        """The RMSE of ``R̂`` against ``info["undelayed_reward"]`` over the last ``last`` steps.

        A diagnostic, over the steps whose info had the key (NaN when none had).
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
        obs, action = history.obs[rows][held], history.action[rows][held]
        error = self.reward_tensor(obs, action).numpy().astype(np.float64) - truth[held]
        return float(np.sqrt(np.mean(error**2)))

    def record(self, logger: Any, prefix: str = "reward_model") -> None:
        """Write the loss (mean since the last call), the RMSE and :meth:`metrics` to ``logger``.

        ``logger`` is SB3's, or anything with ``record(key, value)``.
        """
        if self._losses:
            logger.record(f"{prefix}/loss", float(np.mean(self._losses)))
            self._losses.clear()
        rmse = self.rmse()
        if not math.isnan(rmse):
            logger.record(f"{prefix}/rmse", rmse)
        for key, value in self.metrics().items():
            logger.record(f"{prefix}/{key}", value)
        logger.record(f"{prefix}/gradient_steps", self.gradient_steps_taken)

    # ------------------------------------------------------------------ files
    def settings(self) -> dict[str, Any]:
        """The constructor's arguments but the spaces, JSON-able."""
        return {
            "hidden_sizes": list(self.hidden_sizes),
            "learning_rate": self.learning_rate,
            "batch_size": self.batch_size,
            "learning_starts": self.learning_starts,
            "train_every": self.train_every,
            "gradient_steps": self.gradient_steps,
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
                "gradient_steps_taken": self.gradient_steps_taken,
                "since_round": self._since_round,
                "steps_added": 0 if self.history is None else self.history.steps_added,
                "n_envs": 0 if self.history is None else self.history.n_envs,
            },
        }
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.writestr("reward_model.json", json.dumps(header))
            archive.writestr("weights.pt", weights.getvalue())
            if self.history is not None:
                arrays = io.BytesIO()
                np.savez(arrays, **{name: getattr(self.history, name) for name in _ARRAYS})
                archive.writestr("history.npz", arrays.getvalue())
        return path

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_losses"] = []
        return state
