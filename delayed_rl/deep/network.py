"""The default reward network: an MLP on an observation's and an action's features.

:class:`SpaceFeatures` reads a stored value as SB3's default policies do; :class:`RewardNetwork`
concatenates the two and applies the MLP.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

from delayed_rl._validation import check_int
from delayed_rl.deep.encoding import SpaceEncoding

__all__ = [
    "IMAGE_FEATURES",
    "MAX_HIDDEN",
    "MIN_CNN_SIDE",
    "RewardNetwork",
    "SpaceFeatures",
    "as_tensors",
    "check_hidden_sizes",
]

MAX_HIDDEN = 2**16
"""The widest hidden layer allowed, and the most layers."""
IMAGE_FEATURES = 256
"""The features SB3's ``NatureCNN`` makes of an image (``CombinedExtractor``'s default)."""
MIN_CNN_SIDE = 36
"""The smallest image side ``NatureCNN``'s three convolutions take."""


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


def _channels_last(shape: tuple[int, ...]) -> bool:
    """SB3's heuristic: an image's channel axis is its smallest (last: channels-last)."""
    return int(np.argmin(shape)) == 2


def _uses_cnn(encoding: SpaceEncoding) -> bool:
    if not encoding.image:
        return False
    shape = encoding.shape
    height, width = (shape[0], shape[1]) if _channels_last(shape) else (shape[1], shape[2])
    return min(height, width) >= MIN_CNN_SIDE


class SpaceFeatures(nn.Module):
    """The float features of a batch of stored values of one space.

    It reads a stored value as SB3's default policies do:

    - a non-image ``Box``: its entries, flattened, as floats;
    - an image (SB3's ``is_image_space``: a 3-d ``uint8`` ``Box`` on 0..255): divided by 255 and
      passed through SB3's ``NatureCNN`` (``features_dim`` :data:`IMAGE_FEATURES`), as ``CnnPolicy``
      and ``MultiInputPolicy`` do; channels-last images (the smallest axis last) are transposed
      first. An image smaller than the CNN takes (:data:`MIN_CNN_SIDE` pixels a side) is flattened
      like any ``Box``;
    - ``Discrete``: one-hot (from its ``start``); ``MultiDiscrete``: one one-hot an entry,
      concatenated; ``MultiBinary``: its bits as floats;
    - ``Dict``: each key's features, concatenated in the space's key order (SB3's
      ``CombinedExtractor``).

    Args:
        encoding: the space's encoding.

    Attributes:
        n_out: the number of features a value gives.
    """

    def __init__(self, encoding: SpaceEncoding):
        super().__init__()
        self.encoding = encoding
        self.parts = None
        self.cnn = None
        if encoding.parts is not None:
            self.parts = nn.ModuleDict(
                {str(i): SpaceFeatures(part) for i, part in enumerate(encoding.parts.values())}
            )
            self.n_out = sum(part.n_out for part in self.parts.values())
        elif _uses_cnn(encoding):
            from gymnasium import spaces
            from stable_baselines3.common.torch_layers import NatureCNN

            shape = encoding.shape
            self.transpose = _channels_last(shape)
            first = (shape[2], shape[0], shape[1]) if self.transpose else shape
            image = spaces.Box(0, 255, first, np.uint8)
            self.cnn = NatureCNN(image, features_dim=IMAGE_FEATURES)
            self.n_out = IMAGE_FEATURES
        else:
            self.n_out = encoding.n_features

    def forward(self, values) -> torch.Tensor:
        """Features of shape ``(n, n_out)`` from stored values (tensors, a dict for a ``Dict``)."""
        encoding = self.encoding
        if self.parts is not None:
            return torch.cat(
                [self.parts[str(i)](values[key]) for i, key in enumerate(encoding.parts)], dim=1
            )
        space = encoding.space
        if self.cnn is not None:
            images = values.float() / 255.0
            if self.transpose:
                images = images.permute(0, 3, 1, 2)
            return self.cnn(images)
        kind = type(space).__name__
        if kind == "Discrete":
            index = values.reshape(-1).long() - int(space.start)
            return nn.functional.one_hot(index, encoding.n_features).float()
        if kind == "MultiDiscrete":
            flat_values = values.reshape(values.shape[0], -1).long()
            starts = torch.as_tensor(np.ravel(space.start), dtype=torch.long)
            sizes = np.ravel(space.nvec).tolist()
            return torch.cat(
                [
                    nn.functional.one_hot(flat_values[:, i] - starts[i], int(size)).float()
                    for i, size in enumerate(sizes)
                ],
                dim=1,
            )
        features = values.reshape(values.shape[0], -1).float()
        return features / 255.0 if encoding.image else features


class RewardNetwork(nn.Module):
    """``R̂(s, a)``: the features of ``s`` and ``a``, concatenated, through an MLP.

    With ``state_change`` it reads ``(s, a, s − s′)`` instead (RRD's authors' input), the change
    of the observation's features over the step (meaningful for a ``Box`` of measurements).

    Args:
        observations: the observation space's encoding.
        actions: the action space's encoding.
        hidden_sizes: the hidden layers' widths.
        state_change: also read ``s − s′``.
    """

    def __init__(
        self,
        observations: SpaceEncoding,
        actions: SpaceEncoding,
        hidden_sizes: Sequence[int],
        state_change: bool = False,
    ):
        super().__init__()
        self.observation_features = SpaceFeatures(observations)
        self.action_features = SpaceFeatures(actions)
        self.state_change = state_change
        layers: list[nn.Module] = []
        width = self.observation_features.n_out * (2 if state_change else 1)
        width += self.action_features.n_out
        for size in hidden_sizes:
            layers += [nn.Linear(width, size), nn.ReLU()]
            width = size
        layers.append(nn.Linear(width, 1))
        self.layers = nn.Sequential(*layers)

    def forward(self, obs, action, next_obs=None) -> torch.Tensor:
        """The rewards of a batch of stored observations and actions (tensors): shape ``(n,)``.

        ``next_obs`` (the next observations) is read with ``state_change`` only.
        """
        observed = self.observation_features(obs)
        parts = [observed, self.action_features(action)]
        if self.state_change:
            parts.append(observed - self.observation_features(next_obs))
        return self.layers(torch.cat(parts, 1)).squeeze(1)


def as_tensors(values):
    """Stored values (an array, or a dict of them) as tensors sharing their memory."""
    if isinstance(values, dict):
        return {key: torch.as_tensor(value) for key, value in values.items()}
    return torch.as_tensor(values)
