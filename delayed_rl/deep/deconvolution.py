"""The deconvolution reward model: ``R̂(s, a)`` fitted so that ``p ∗ R̂`` explains what arrived.

:class:`DeconvolutionRewardModel` states the fit, its episode-end modes and its batches.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from numpy.lib.stride_tricks import sliding_window_view

from delayed_rl._validation import check_choice, check_int, check_real
from delayed_rl.agents.common.delay_estimate import check_max_delay_estimate
from delayed_rl.agents.expected_credit import credit_weights
from delayed_rl.deep.network import as_tensors
from delayed_rl.deep.reward_model import RewardModel
from delayed_rl.delays import Delay, Empirical, as_delay
from delayed_rl.wrappers import EPISODE_END_MODES

__all__ = ["DeconvolutionRewardModel"]


class DeconvolutionRewardModel(RewardModel):
    """``R̂(s, a)`` learned by deconvolving the delivered rewards, with ``p`` known or learned.

    With i.i.d. delays ``d ~ p``, the reward delivered at step ``t`` has the mean
    ``E[y_t] = Σ_k p(k)·R(s_{t−k}, a_{t−k})``. :class:`DeconvolutionRewardModel` fits ``R̂`` by least
    squares on that sum, over windows of the history, with the weights of the wrapper's episode-end
    mode (``on_episode_end``, as :class:`~delayed_rl.wrappers.RewardDelay` takes it):

    - ``"flush"`` (the default): lags stay inside an episode, and the last step of an episode
      collects the survival ``P(D ≥ k)`` of each earlier step's reward (all that was pending);
    - ``"drop"``: lags stay inside an episode and the tail is lost;
    - ``"carry"``: lags cross episode boundaries (pending rewards arrive in the next episode).

    An episode cut short by a reset (:meth:`~delayed_rl.deep.history.TransitionHistory.cut`) ends
    there under ``"flush"`` and ``"drop"`` with no tail collected: the reset discarded what was
    pending.

    ``delay``: a known distribution (its pmf clipped to ``0..K``, the last lag holding the tail, as
    :func:`~delayed_rl.agents.expected_credit.credit_weights` makes it), or ``None`` to learn ``p``
    jointly, as a softmax over ``0..max_delay_estimate`` started uniform (``delay_pmf``, ``mean_delay``).
    A batch is ``ceil(batch_size / window)`` windows of ``window`` consecutive targets of one
    sub-env, drawn uniformly, each with the ``K`` steps before it: ``R̂`` is evaluated once a step and
    passed through the causal convolution with ``p``.

    Args:
        observation_space: the env's observation space (any the base class takes).
        action_space: its action space (likewise).
        delay: the delay distribution (a :class:`~delayed_rl.delays.Delay`, a number read as a
            Poisson mean, or a ``to_dict()`` description), or ``None`` to learn it.
        max_delay_estimate: ``K``, the longest delay modelled: required with ``delay=None``; with a known
            delay, a clip (``None``: where the pmf's tail falls below ``1e-12``).
        on_episode_end: the wrapper's episode-end mode: ``"flush"``, ``"drop"`` or ``"carry"``.
        window: targets per window of a batch.
        delay_learning_rate: Adam's step size for ``p``'s logits (with ``delay=None``).
        **kwargs: the :class:`~delayed_rl.deep.reward_model.RewardModel` settings
            (``hidden_sizes``, ``learning_rate``, ``batch_size``, ``seed``...).

    Raises:
        TypeError, ValueError: a bad argument (the message names it); ``delay=None`` without a
            ``max_delay_estimate``; a ``K`` above
            :data:`~delayed_rl.agents.common.delay_estimate.MAX_DELAY_ESTIMATE` (1024).

    Example:
        >>> import gymnasium as gym
        >>> env = gym.make("Pendulum-v1")
        >>> model = DeconvolutionRewardModel(
        ...     env.observation_space, env.action_space, delay=None, max_delay_estimate=60, seed=0
        ... )
        >>> round(model.mean_delay, 1)  # p starts uniform on 0..60
        30.0
    """

    own_settings = (
        "delay",
        "max_delay_estimate",
        "on_episode_end",
        "window",
        "delay_learning_rate",
    )

    def __init__(
        self,
        observation_space: Any,
        action_space: Any,
        delay: Delay | float | dict | None = None,
        max_delay_estimate: int | None = None,
        *,
        on_episode_end: str = "flush",
        window: int = 64,
        delay_learning_rate: float = 1e-2,
        **kwargs: Any,
    ):
        self.max_delay_estimate = check_max_delay_estimate(max_delay_estimate)
        self.delay = None if delay is None else as_delay(delay)
        self.on_episode_end = check_choice("on_episode_end", on_episode_end, EPISODE_END_MODES)
        self.window = check_int("window", window, 1, 2**16)
        self.delay_learning_rate = check_real(
            "delay_learning_rate", delay_learning_rate, 0.0, 1e6, low_open=True
        )
        if self.delay is None:
            if self.max_delay_estimate is None:
                raise ValueError(
                    "max_delay_estimate must be given (an integer >= 0) when delay is None"
                )
            self._known_pmf = None
            self.support = self.max_delay_estimate
        else:
            weights = credit_weights(self.delay, self.max_delay_estimate)
            self._known_pmf = torch.as_tensor(weights / weights.sum(), dtype=torch.float32)
            self.support = weights.size - 1
        super().__init__(observation_space, action_space, **kwargs)
        if self.capacity < self.window + self.support:
            raise ValueError(
                f"capacity must be at least window + K = {self.window} + {self.support} (a "
                f"window and the K steps before it), got {self.capacity}: a full history that "
                "holds less never trains"
            )

    def _make_parameters(self) -> None:
        self.delay_logits = None
        if self._known_pmf is None:
            self.delay_logits = torch.nn.Parameter(torch.zeros(self.support + 1))

    def _make_optimizer(self) -> torch.optim.Optimizer:
        groups: list[dict[str, Any]] = [{"params": list(self.network.parameters())}]
        if self.delay_logits is not None:
            groups.append({"params": [self.delay_logits], "lr": self.delay_learning_rate})
        return torch.optim.Adam(groups, lr=self.learning_rate, foreach=True)

    def _extra_state(self) -> dict[str, torch.Tensor]:
        return {} if self.delay_logits is None else {"delay_logits": self.delay_logits.detach()}

    def _load_extra_state(self, tensors: dict[str, torch.Tensor]) -> None:
        if self.delay_logits is not None:
            with torch.no_grad():
                self.delay_logits.copy_(tensors["delay_logits"])

    def _settings(self) -> dict[str, Any]:
        settings = super()._settings()
        if self.delay is not None:
            try:
                settings["delay"] = self.delay.to_dict()
            except NotImplementedError:  # a user's distribution: its clipped pmf
                settings["delay"] = Empirical(self._known_pmf.double().numpy()).to_dict()
        return settings

    # ------------------------------------------------------------------ the delay
    def _pmf(self) -> torch.Tensor:
        """``p`` on ``0..K`` (learned: the softmax of the logits, with gradients)."""
        if self.delay_logits is None:
            return self._known_pmf
        return torch.softmax(self.delay_logits, dim=0)

    @property
    def delay_pmf(self) -> np.ndarray:
        """``p(k)`` for ``k = 0..K``, known or as learned so far (``float64``)."""
        with torch.no_grad():
            return self._pmf().double().numpy().copy()

    @property
    def mean_delay(self) -> float:
        """The mean of :attr:`delay_pmf`."""
        pmf = self.delay_pmf
        return float(np.arange(pmf.size) @ pmf)

    def metrics(self) -> dict[str, float]:
        """The learned (or known) mean delay (computed once after each update)."""
        computed = getattr(self, "_mean_delay_at", None)
        if computed is None or computed[0] != self.updates_taken:
            self._mean_delay_at = (self.updates_taken, self.mean_delay)
        return {"mean_delay": self._mean_delay_at[1]}

    # ------------------------------------------------------------------ the loss
    def loss(self) -> torch.Tensor | None:
        """The mean squared error of ``Σ_k w_t(k)·R̂(s_{t−k}, a_{t−k})`` against ``y_t``.

        ``w_t(k)`` is ``p(k)`` (``P(D ≥ k)`` at an episode's last step under ``"flush"``), and 0
        for a step of another episode (under ``"flush"`` and ``"drop"``) or before the stream.
        """
        history = self.history
        k, length = self.support, self.window
        lowest = history.oldest + k if history.oldest > 0 else 0
        if history.steps_added - length < lowest:
            return None
        count = math.ceil(self.batch_size / length)
        starts = self.rng.integers(lowest, history.steps_added - length + 1, size=count)
        envs = self.rng.integers(0, history.n_envs, size=count)
        steps = starts[:, None] + np.arange(-k, length)  # (windows, K + window)
        valid = steps >= 0
        # a lag before the stream reads step 0 (masked below): the ring's unfilled rows hold
        # zeros, which are outside a space that starts above 0 (a one-hot could not take them)
        rows = np.where(valid, steps, 0) % history.capacity
        columns = envs[:, None]
        ends = history.episode_end[rows, columns] & valid
        cuts = history.episode_cut[rows, columns] & valid  # reset mid-episode: nothing flushed
        obs = history.observations_at(rows, columns)
        action = history.actions_at(rows, columns)
        rewards = self.network(as_tensors(obs), as_tensors(action))
        lagged = rewards.reshape(count, k + length).unfold(1, k + 1, 1)
        # [w, i, j] = R̂ of step i + j of window w: lag K − j of its target i + K
        allowed = sliding_window_view(valid, k + 1, axis=1)
        if self.on_episode_end != "carry":
            episode = np.concatenate(
                (np.zeros((count, 1), np.int64), np.cumsum(ends | cuts, 1)[:, :-1]), 1
            )
            allowed = allowed & (
                sliding_window_view(episode, k + 1, axis=1) == episode[:, k:, None]
            )
        weights = self._pmf().flip(0)  # [j] = p(K − j)
        if self.on_episode_end == "flush":
            survival = weights.cumsum(0)  # [j] = P(D >= K − j)
            weights = torch.where(torch.as_tensor(ends[:, k:, None]), survival, weights)
        allowed = torch.as_tensor(np.ascontiguousarray(allowed))
        predicted = (lagged * (weights * allowed)).sum(-1)
        delivered = torch.as_tensor(history.reward[rows[:, k:], columns], dtype=torch.float32)
        return torch.mean((predicted - delivered) ** 2)
