"""Randomized return decomposition (RRD, Ren et al. 2022): ``R̂`` from episode sums alone.

An episode's delivered rewards sum to its return ``G`` (under ``"flush"``, whatever the delays:
that is what makes it delay-agnostic). RRD draws random subsets ``I`` of an episode's steps and
regresses the per-step share ``G / T`` on the mean of ``R̂`` over ``I``. It needs no model of
the delay, but it uses only the sums: it cannot tell which steps earned a reward beyond what
the episodes' sums reveal. Only finished episodes wholly in the history are used; under
``"carry"`` or ``"drop"`` episode sums are not the returns, and RRD learns the wrong scale.

The defaults are the authors' (Stilwell-Git/Randomized-Return-Decomposition, MuJoCo):
:data:`PAPER_SETTINGS`. Where this model still differs from their code, the class docstring
says so.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from torch import nn

from delayed_rl._validation import check_choice, check_int
from delayed_rl.deep.encoding import is_image
from delayed_rl.deep.reward_model import RewardModel

__all__ = [
    "EPISODE_DRAWS",
    "INITIALISATIONS",
    "PAPER_SETTINGS",
    "ReturnDecompositionRewardModel",
    "sample_episodes",
]

EPISODE_DRAWS = ("length", "uniform")
"""The values of ``episode_draw``: in proportion to the episodes' lengths, or uniformly."""
INITIALISATIONS = ("xavier", "pytorch")
"""The values of ``initialisation``: Glorot-uniform weights and zero biases, or PyTorch's."""
PAPER_SETTINGS = {
    "hidden_sizes": (256, 256),
    "learning_rate": 3e-4,
    "batch_size": 256,
    "subset_size": 64,
    "episode_draw": "length",
    "initialisation": "xavier",
    "unbiased": False,
    "state_change": True,
}
"""The authors' settings for MuJoCo (their ``rrd_args`` and ``mlp_rrd``: a 256×256 ReLU MLP on
``(s, a, s − s′)`` with TensorFlow's Xavier initialiser, Adam at 3e-4, 256 steps a batch as 4
subsets of 64, episodes drawn in proportion to their lengths, the biased loss unless
``--rrd_bias_correction``): the defaults (``state_change`` where the observations are a ``Box``
of measurements)."""


def sample_episodes(
    model: RewardModel, count: int, draw: str = "uniform"
) -> list[tuple[int, int, int, float]] | None:
    """``count`` finished episodes of ``model``'s history, drawn with replacement.

    ``draw="uniform"`` gives each episode the same chance; ``"length"`` a chance in proportion
    to its length (a uniformly drawn step's episode, as the authors' buffer draws). ``None``
    when no episode has finished yet.
    """
    episodes = model.history.episodes
    if not episodes:
        return None
    if draw == "uniform":
        picks = model.rng.integers(0, len(episodes), size=count)
    else:
        ends = np.cumsum([length for _, _, length, _ in episodes])
        picks = np.searchsorted(ends, model.rng.integers(0, ends[-1], size=count), side="right")
    return [episodes[i] for i in picks]


def _state_change(state_change: bool | None, observation_space: Any) -> bool:
    """``state_change`` resolved for ``observation_space`` (see the class docstring).

    Raises:
        TypeError: it is neither a bool nor None.
        ValueError: it is True for observations that are not a ``Box`` of measurements.
    """
    measured = isinstance(observation_space, spaces.Box) and not is_image(observation_space)
    if state_change is None:
        return measured
    if not isinstance(state_change, bool):
        raise TypeError(f"state_change must be a bool or None, got {state_change!r}")
    if state_change and not measured:
        raise ValueError(
            "state_change=True needs a Box observation space that is not an image (s − s′ of "
            f"measurements), got {observation_space!r}"
        )
    return state_change


class ReturnDecompositionRewardModel(RewardModel):
    """RRD: ``mean_{i ∈ I} R̂(s_i, a_i) ≈ G / T`` for random subsets ``I`` of episodes.

    A batch is ``batch_size // subset_size`` finished episodes, at least one (the authors'
    floor; below one they would draw none), drawn as ``episode_draw`` says; from each of ``T``
    steps, ``n = subset_size`` steps are drawn, without replacement
    when ``n ≤ T`` and with replacement otherwise (as the authors draw). The loss is the mean
    over the batch's episodes of ``(mean_I R̂ − G / T)²`` (the *biased* loss: the squared error
    of a subset's mean also holds its sampling variance). With ``unbiased=True`` each episode's
    term loses that variance's estimate, ``(1 − n / T) · s² / n`` with ``s²`` the sample variance
    (``n − 1`` in the denominator) of ``R̂`` over ``I`` (the authors' bias correction; the factor
    is 1 when ``n > T`` and 0 for a one-step episode, as theirs).

    With ``state_change`` the network reads ``(s, a, s − s′)``, as the authors' does (the change
    over the step carries velocity-like information that MuJoCo's rewards depend on); the
    buffers hand the model each step's next observation (the terminal one at an episode's end).
    It needs a ``Box`` observation space that is not an image (the authors' image network, a
    CNN over ``s`` and ``s − s′`` stacked, is not reproduced here).

    Where it still differs from the authors' code: their reward network trains once per critic
    update and their SAC starts after 10k steps; here the model follows the
    :class:`~delayed_rl.deep.reward_model.RewardModel` schedule (``updates_per_step``,
    ``warmup_updates``) and the algorithm its own ``learning_starts``. Their network learns from
    SAC's whole buffer (10⁶ steps); this one from its own history, ``capacity`` steps (10⁵ by
    default: pass ``capacity=1_000_000`` for theirs). Once the history has overwritten steps, an
    episode that began at its oldest step is no longer drawn (its start is not known to be one),
    where theirs keeps whole episodes until they are overwritten: one episode at the boundary.

    Args:
        observation_space: the env's observation space (any the base class takes).
        action_space: its action space (likewise).
        subset_size: ``n``, the steps drawn from each episode of a batch (an integer in
            ``1..2**16``; ``unbiased`` needs at least 2).
        episode_draw: ``"length"`` (the authors') or ``"uniform"``.
        initialisation: ``"xavier"`` (the authors': Glorot-uniform weights, zero biases) or
            ``"pytorch"`` (PyTorch's default).
        unbiased: subtract the subsets' variance estimate from the loss (see above).
        state_change: read ``s − s′`` beside ``(s, a)``; ``None`` (default): for a ``Box``
            observation space that is not an image (the authors' input), not for the others.
        **kwargs: the :class:`~delayed_rl.deep.reward_model.RewardModel` settings; their
            defaults here are :data:`PAPER_SETTINGS`' (a 256×256 MLP, Adam at 3e-4, 256 steps a
            batch).

    Raises:
        TypeError: an argument of the wrong type.
        ValueError: ``subset_size`` out of range, or 1 with ``unbiased``; an unknown
            ``episode_draw`` or ``initialisation``; ``state_change=True`` for observations that
            are not a ``Box`` of measurements.

    Example:
        >>> import gymnasium as gym
        >>> env = gym.make("Pendulum-v1")
        >>> model = ReturnDecompositionRewardModel(env.observation_space, env.action_space, seed=0)
        >>> model.state_change, model.subset_size, model.hidden_sizes  # the authors' settings
        (True, 64, (256, 256))
        >>> lake = gym.make("FrozenLake-v1")  # Discrete observations: no s − s′
        >>> ReturnDecompositionRewardModel(lake.observation_space, lake.action_space).state_change
        False
    """

    own_settings = ("subset_size", "episode_draw", "initialisation", "unbiased", "state_change")

    def __init__(
        self,
        observation_space: Any,
        action_space: Any,
        *,
        subset_size: int = PAPER_SETTINGS["subset_size"],
        episode_draw: str = PAPER_SETTINGS["episode_draw"],
        initialisation: str = PAPER_SETTINGS["initialisation"],
        unbiased: bool = PAPER_SETTINGS["unbiased"],
        state_change: bool | None = None,
        hidden_sizes: Any = PAPER_SETTINGS["hidden_sizes"],
        learning_rate: float = PAPER_SETTINGS["learning_rate"],
        batch_size: int = PAPER_SETTINGS["batch_size"],
        **kwargs: Any,
    ):
        self.subset_size = check_int("subset_size", subset_size, 1, 2**16)
        self.episode_draw = check_choice("episode_draw", episode_draw, EPISODE_DRAWS)
        self.initialisation = check_choice("initialisation", initialisation, INITIALISATIONS)
        if not isinstance(unbiased, bool):
            raise TypeError(f"unbiased must be a bool, got {unbiased!r}")
        if unbiased and self.subset_size < 2:
            raise ValueError(
                f"subset_size must be at least 2 with unbiased=True (a subset's variance needs "
                f"two steps), got {subset_size}"
            )
        self.unbiased = unbiased
        self.state_change = _state_change(state_change, observation_space)
        super().__init__(
            observation_space,
            action_space,
            hidden_sizes=hidden_sizes,
            learning_rate=learning_rate,
            batch_size=batch_size,
            **kwargs,
        )

    @property
    def reads_next_observation(self) -> bool:
        """Whether the network reads ``s − s′`` (``state_change``)."""
        return self.state_change

    def _make_parameters(self) -> None:
        """Re-initialise the network's linear layers as ``initialisation`` says."""
        if self.initialisation == "xavier":
            for layer in self.network.modules():
                if isinstance(layer, nn.Linear):
                    nn.init.xavier_uniform_(layer.weight)
                    nn.init.zeros_(layer.bias)

    def subset_steps(self, length: int) -> np.ndarray:
        """The steps (offsets in an episode of ``length``) one subset draws, with ``rng``."""
        n = self.subset_size
        return self.rng.choice(length, size=n, replace=n > length)

    @staticmethod
    def variance_factor(n: int, length: int) -> float:
        """The unbiased loss's ``1 − n / T`` (1 when ``n > T``, 0 for ``T = 1``), as the authors'."""
        if length <= 1:
            return 0.0
        return 1.0 - n / length if n <= length else 1.0

    def loss(self) -> torch.Tensor | None:
        """The mean over a batch's episodes of ``(mean_I R̂ − G / T)²`` (minus the variance term)."""
        history = self.history
        count = max(1, self.batch_size // self.subset_size)
        episodes = sample_episodes(self, count, self.episode_draw)
        if episodes is None:
            return None
        n = self.subset_size
        steps = np.stack([first + self.subset_steps(length) for _, first, length, _ in episodes])
        envs = np.repeat([env for env, *_ in episodes], n)
        rows = steps.ravel() % history.capacity
        rewards = self.network(*self.inputs_at(rows, envs)).reshape(len(episodes), n)
        target = torch.as_tensor([total / length for *_, length, total in episodes])
        loss = torch.mean((rewards.mean(1) - target.float()) ** 2)
        if not self.unbiased:
            return loss
        factors = torch.as_tensor([self.variance_factor(n, e[2]) for e in episodes])
        return loss - torch.mean(rewards.var(1, unbiased=True) * factors.float() / n)
