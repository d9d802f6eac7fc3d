"""The default reward network: an MLP on an observation's and an action's features."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from delayed_rl._validation import check_int
from delayed_rl.deep.encoding import SpaceEncoding

__all__ = ["MAX_HIDDEN", "RewardNetwork", "check_hidden_sizes"]

MAX_HIDDEN = 2**16
"""The widest hidden layer allowed, and the most layers."""


def check_hidden_sizes(hidden_sizes: object) -> tuple[int, ...]:
    """``hidden_sizes`` as a tuple of layer widths in ``1..MAX_HIDDEN`` (empty: linear).

    Raises:
        TypeError: not a sequence of integers.
        ValueError: a width outside ``1..MAX_HIDDEN``, or more than ``MAX_HIDDEN`` layers.
    """
    if isinstance(hidden_sizes, (str, bytes)) or not isinstance(hidden_sizes, Sequence):
        raise TypeError(
            f"hidden_sizes must be a sequence of layer widths, got {hidden_sizes!r} "
            f"({type(hidden_sizes).__name__})"
        )
    if len(hidden_sizes) > MAX_HIDDEN:
        raise ValueError(f"hidden_sizes must have at most {MAX_HIDDEN} layers (MAX_HIDDEN)")
    return tuple(
        check_int(f"hidden_sizes[{i}]", width, 1, MAX_HIDDEN)
        for i, width in enumerate(hidden_sizes)
    )


class RewardNetwork(nn.Module):
    """``R̂(s, a)``: an MLP with ReLU between its layers and one linear output.

    Args:
        observations: the observation space's encoding.
        actions: the action space's encoding.
        hidden_sizes: the hidden layers' widths.
    """

    def __init__(
        self, observations: SpaceEncoding, actions: SpaceEncoding, hidden_sizes: Sequence[int]
    ):
        super().__init__()
        self.observations, self.actions = observations, actions
        layers: list[nn.Module] = []
        width = observations.n_features + actions.n_features
        for size in hidden_sizes:
            layers += [nn.Linear(width, size), nn.ReLU()]
            width = size
        layers.append(nn.Linear(width, 1))
        self.layers = nn.Sequential(*layers)

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """The rewards of a batch of stored observations and actions: shape ``(n,)``."""
        features = torch.cat(
            (self.observations.features(obs), self.actions.features(action)), dim=1
        )
        return self.layers(features).squeeze(1)
