"""Each learning rule of :mod:`delayed_rl.agents`, written plainly: no caches, no rings, no numba.

These classes are the rules as their agents' docstrings state them, for reading and for tests:
both training paths of every agent (the Python loop and the compiled one) are tested against
them bit for bit, on random transitions (``tests/agents/test_reference.py``). They learn only;
acting is the agents' (ε-greedy with random ties, :class:`~delayed_rl.agents.common.q_table.QTable`).

- :class:`ReferenceMMQ`: Multiple Model Q-learning with its credit options; with Λ = {0} it is
  Q-learning, with Λ = {k} fixed-delay Q-learning, and fed a reward model's ``R̂(s, a)``
  instead of the received reward it is deconvolution Q-learning's rule;
- :class:`ReferenceExpectedCredit`: expected-credit Q-learning;
- :class:`ReferenceOracle`: oracle Q-learning.

Every update is ``Q ← Q + rate · (target − Q)`` (or ``Q + rate · δ``) with the operations in the
agents' order, so that floating point gives the same bits; the maxima are taken over whole rows.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from delayed_rl.compiled.state import credit_kernel

__all__ = ["ReferenceExpectedCredit", "ReferenceMMQ", "ReferenceOracle"]


class _Table:
    """Q-values ``q[s, λ̂, a]`` and the max over a state's whole row."""

    def __init__(self, n_states: int, n_models: int, n_actions: int, q_init: float):
        self.q = np.full((n_states, n_models, n_actions), float(q_init))

    def best(self, s: int) -> float:
        """``max_{λ̂, a} Q(s, a, λ̂)``."""
        return max(self.q[s].ravel().tolist())


class ReferenceMMQ(_Table):
    """MMQ's rule (thesis Eq. 3.7), with the reward kernel and the delay trace.

    At episode step ``t`` with received reward ``r_t``: for every λ̂ ∈ Λ with ``t − λ̂ >= 0``,
    with ``(s, a, s′, done)`` the transition of step ``t − λ̂``, the target is
    ``w_t(λ̂) r_t + γ (1 − done) max Q(s′)``; all targets of a step come before any write.
    ``w_t(λ̂) = 1`` by default; with the options it is the kernel's weight of ``|λ̂ − λ̂*_t|``
    times the trace ``e_t(λ̂)`` (``e ← β e``, then ``e(λ̂*_t) ← 1``), ``λ̂*_t`` the acting model.

    Args:
        n_states, n_actions: the env's sizes.
        delay_estimates: Λ, sorted.
        q_init, alpha, gamma: the initial value, α and γ.
        reward_kernel, delay_trace: σ and β, or ``None`` (off).
    """

    def __init__(
        self,
        n_states: int,
        n_actions: int,
        delay_estimates: Sequence[int],
        q_init: float,
        alpha: float,
        gamma: float,
        reward_kernel: float | None = None,
        delay_trace: float | None = None,
    ):
        super().__init__(n_states, len(delay_estimates), n_actions, q_init)
        self.delays = [int(d) for d in delay_estimates]
        self.alpha, self.gamma = alpha, gamma
        self.kernel = (
            None if reward_kernel is None else credit_kernel(np.array(self.delays), reward_kernel)
        )
        self.decay = delay_trace
        self.trace = [0.0] * len(self.delays)
        self.history: list[tuple[int, int, int, bool]] = []  # this episode's (s, a, s′, done)

    def weights(self, acting: int) -> list[float]:
        """``w_t(λ̂)`` for every model when model ``acting`` acted (advances the trace)."""
        if self.decay is not None:
            self.trace = [e * self.decay for e in self.trace]
            self.trace[acting] = 1.0
        weights = []
        for j, delay in enumerate(self.delays):
            w = 1.0
            if self.kernel is not None:
                w = float(self.kernel[abs(delay - self.delays[acting])])
                if self.decay is not None:
                    w = w * self.trace[j]
            elif self.decay is not None:
                w = self.trace[j]
            weights.append(w)
        return weights

    def greedy_model(self, s: int) -> int:
        """The lowest-index model whose table holds ``s``'s max (the acting model of ``update``)."""
        return int(np.argmax(self.q[s].ravel())) // self.q.shape[2]

    def update(
        self, s: int, a: int, r: float, s2: int, terminated: bool, truncated: bool,
        acting: int | None = None,
    ) -> None:  # fmt: skip
        """Learn from step ``(s, a, r, s2)``; ``acting``: its acting model (``None``: greedy)."""
        options = self.kernel is not None or self.decay is not None
        weights = (
            self.weights(self.greedy_model(s) if acting is None else acting) if options else None
        )
        self.history.append((s, a, s2, terminated))
        t = len(self.history) - 1
        targets = []
        for j, delay in enumerate(self.delays):
            if t - delay < 0:
                continue
            hs, ha, hs2, done = self.history[t - delay]
            credit = r if weights is None else r * weights[j]
            targets.append((hs, j, ha, credit + self.gamma * (0.0 if done else self.best(hs2))))
        for hs, j, ha, target in targets:
            old = float(self.q[hs, j, ha])
            self.q[hs, j, ha] = old + self.alpha * (target - old)
        if terminated or truncated:
            self.history.clear()


class ReferenceExpectedCredit(_Table):
    """Expected-credit Q-learning's rule: each received reward shared over lags by ``w(k)``.

    At episode step ``t``, for every lag ``k`` with ``w(k) > 0`` and ``t − k >= 0``, with
    ``(s, a, s′, done)`` the transition of step ``t − k``:
    ``δ_k = r_t + γ (1 − done) max Q(s′) − Q(s, a)``, all δ first; then
    ``Q(s, a) += (α w(k)) δ_k`` in lag order.

    Args:
        n_states, n_actions: the env's sizes.
        weights: ``w(k)`` for ``k = 0..K`` (the agent's ``credit_weights``).
        q_init, alpha, gamma: the initial value, α and γ.
    """

    def __init__(
        self, n_states: int, n_actions: int, weights: Sequence[float], q_init: float,
        alpha: float, gamma: float,
    ):  # fmt: skip
        super().__init__(n_states, 1, n_actions, q_init)
        self.lags = [(k, float(w)) for k, w in enumerate(weights) if w > 0.0]
        self.alpha, self.gamma = alpha, gamma
        self.history: list[tuple[int, int, int, bool]] = []

    def update(self, s: int, a: int, r: float, s2: int, terminated: bool, truncated: bool) -> None:
        """Learn from step ``(s, a, r, s2)``."""
        self.history.append((s, a, s2, terminated))
        t = len(self.history) - 1
        steps = []
        for k, w in self.lags:
            if t - k < 0:
                continue
            hs, ha, hs2, done = self.history[t - k]
            delta = r + self.gamma * (0.0 if done else self.best(hs2)) - float(self.q[hs, 0, ha])
            steps.append((hs, ha, self.alpha * w, delta))
        for hs, ha, rate, delta in steps:
            self.q[hs, 0, ha] = float(self.q[hs, 0, ha]) + rate * delta
        if terminated or truncated:
            self.history.clear()


class ReferenceOracle(_Table):
    """Oracle Q-learning's rule: each transition updated once, with its own reward, on arrival.

    At every step the transition is stored; then for each arrival ``(e, r_e)`` of the step, in
    the order of the emission steps, transition ``e`` (on the episode's clock; negative: an
    earlier episode's) gets ``Q(s_e, a_e) += α (r_e + γ (1 − done_e) max Q(s′_e) − Q(s_e, a_e))``,
    if it is one of the last ``held`` transitions and was not updated yet.

    Args:
        n_states, n_actions: the env's sizes.
        held: how many recent transitions are held (the agent's ``history_length``).
        q_init, alpha, gamma: the initial value, α and γ.
    """

    def __init__(
        self, n_states: int, n_actions: int, held: int, q_init: float, alpha: float, gamma: float
    ):
        super().__init__(n_states, 1, n_actions, q_init)
        self.held, self.alpha, self.gamma = held, alpha, gamma
        self.past: dict[int, tuple[int, int, int, bool]] = {}  # clock → (s, a, s′, done)
        self.clock = 0
        self.episode_start = 0

    def update(
        self, s: int, a: int, s2: int, terminated: bool, truncated: bool,
        arrivals: Sequence[tuple[int, float]],
    ) -> None:  # fmt: skip
        """Store step ``(s, a, s2)``; credit the step's ``arrivals`` ``(emission_step, value)``."""
        self.past[self.clock] = (s, a, s2, terminated)
        self.past.pop(self.clock - self.held, None)
        for emitted, value in sorted(arrivals):
            transition = self.past.pop(self.episode_start + emitted, None)
            if transition is None:
                continue  # not held, or already updated
            hs, ha, hs2, done = transition
            target = value + self.gamma * (0.0 if done else self.best(hs2))
            old = float(self.q[hs, 0, ha])
            self.q[hs, 0, ha] = old + self.alpha * (target - old)
        self.clock += 1
        if terminated or truncated:
            self.episode_start = self.clock
