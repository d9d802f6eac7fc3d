"""Deconvolution Q-learning: regress the received rewards on the past, then Q-learn on the estimate.

Under rewards delayed independently by ``d ~ p`` (:class:`~delayed_rl.wrappers.RewardDelay`),
the reward received at step ``t`` has expectation ``Σ_k p(k) · R(s_{t−k}, a_{t−k})``: a
convolution of the delay pmf with the mean rewards ``R`` of the (state, action) pairs visited.
:class:`DeconvolutionQLearning` undoes it:

1. it keeps the sufficient statistics of that regression (:mod:`delayed_rl.agents._regression`:
   ``O(K)`` per step, never the history) and, after 1000, 2000, 4000, ... steps and then every
   ``solve_interval`` steps (the gaps double until they reach it), solves the least
   squares for ``R̂`` — with the delay pmf known (``delay=``), or estimated with it (``delay=None``:
   ``p`` on ``0..max_delay`` and ``R`` alternate, ``p`` kept a distribution);
2. it runs Q-learning on the observed, undelayed transitions ``(s, a, s′)`` with reward
   ``R̂(s, a)``: ``Q(s, a) += α (R̂(s, a) + γ (1 − terminated) max_a′ Q(s′, a′) − Q(s, a))``.

It is anonymous: it reads only the reward delivered at each step, the observations, actions and
episode ends — never ``info["undelayed_reward"]``, ``reward_delay`` or ``reward_arrivals``.

**Sizes.** The statistics take ``(K + 1)·P²`` 4-byte counts for ``P`` (state, action) pairs
while that fits 64 MiB (the grid worlds); above (Taxi's 3000 pairs), a hashed table holds only
the couples of pairs that occurred within ``K`` steps of each other, so memory follows what the
agent has seen (:mod:`delayed_rl.agents._regression`). Both paths run either layout; a
compiled step costs about 1.4 MMQ(|Λ| = 51) steps and the solves bring a 1M-step run on
GridWorld-9x9 to about 2.6 times MMQ's time, a known delay's to about MMQ's
(``benchmarks/deconvolution_cost.py``).

**When it helps.** Deconvolution removes the delay's bias at the price of variance: the
estimate of a pair's mean reward improves as ``1/√visits``, and the noise of the delivered
stream (every reward's arrival time is random) is amplified in the directions the agent's
behaviour hardly excites. Where rewards are sparse (the grid worlds) it reaches the optimal
policy in a few hundred thousand steps; where every step is rewarded and a policy's value
hangs on small differences (Taxi, CliffWalking at γ = 0.9) it needs many visits per pair, and
with too few steps it can do worse than plain Q-learning (``benchmarks/REPORT.md``).
"""

from __future__ import annotations

import numbers
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._validation import check_choice, check_int, check_real
from delayed_rl.agents._fused import CompiledTables
from delayed_rl.agents._regression import RewardRegression
from delayed_rl.agents.expected_credit import credit_weights
from delayed_rl.agents.hyperparameters import shares_hyperparameters
from delayed_rl.agents.qlearning import QLearning
from delayed_rl.delays import Delay, Empirical
from delayed_rl.fast.kernel import RewardModel
from delayed_rl.wrappers.reward_delay import find_reward_delay

__all__ = ["DeconvQ", "DeconvolutionQLearning"]

EPISODE_END_MODES = ("flush", "drop", "carry")
DEFAULT_MAX_DELAY = 50  # as MMQ's λ̂max: the thesis's grid-world cut-off
_CHUNK = 4096  # compiled steps between two looks at the statistics' room for segment ends
_HASHED_CHUNK = 256  # the same with hashed statistics: each step may claim K + 1 new rows
_FIRST_SOLVE = 1_000  # steps before the first solve; the gaps then double to solve_interval
_OWN_NAMES = {  # this class's own constructor arguments, and their defaults
    "delay": None,
    "max_delay": None,
    "solve_interval": 20_000,
    "ridge": 1.0,
    "delay_iterations": 2,
    "on_episode_end": None,
}


class DeconvolutionQLearning(QLearning):
    """Q-learning on mean rewards estimated by deconvolving the delayed reward stream.

    See the module docstring for the rule. The reward model ``R̂`` is 0 until the first solve, so
    an optimistic ``q_init`` explores meanwhile, as for the other agents.

    **Episode ends.** How a reward-delay wrapper treats pending rewards at an episode's end
    changes what the last step delivers, and the model follows it (``on_episode_end``):
    ``"flush"`` (the last step carries every pending reward: the pair ``k`` steps back weighs
    ``P(D ≥ k)``), ``"drop"`` (those rewards never come), ``"carry"`` (they come in the next
    episode: the regression runs over the whole stream). ``None`` reads the mode of the
    :class:`~delayed_rl.wrappers.RewardDelay` in the env's stack, else assumes ``"flush"`` (the
    wrapper's default).

    Args:
        env: the training env (``Discrete`` spaces) or an env id.
        delay: the delay distribution when it is known (a :class:`~delayed_rl.delays.Delay`, or a
            number read as a Poisson mean), modelled on ``0..K`` with ``K`` its largest value (or,
            for an unbounded one, where less than 1e-6 of its mass is left, at most
            ``max_delay``); ``None`` (default) learns it on ``0..max_delay``.
        max_delay: ``K`` for a learned delay, the longest delay modelled (the designer's cut-off,
            like MMQ's λ̂max; default 50); with a known delay, a cap on its support.
        solve_interval: the longest gap between two least-squares solves (default 20,000); the
            first solve comes after 1000 steps (or ``solve_interval``, if shorter) and the gaps
            double up to it, so early estimates come fast and long runs pay little for them.
        ridge: the weight of a prior that each pair's mean reward is the mean reward received
            per step so far (default 1.0, in units of the normal equations, where one visit
            weighs about ``Σ_k p(k)²``, 0.08 for Poisson(13)): a pair never visited gets that
            mean, a rarely visited one is pulled towards it, and a well-visited one keeps its
            estimate. Deconvolution amplifies noise in the directions the agent's behaviour
            hardly excites; the prior keeps those estimates near the typical reward rather than
            at a spuriously attractive value (on envs with a reward at every step, such as Taxi
            and CliffWalking, a prior at 0 makes unvisited pairs look better than every visited
            one).
        delay_iterations: with a learned delay, the alternations of the ``R`` and ``p`` solves
            at each solve (warm-started from the last estimate; default 2).
        on_episode_end: ``"flush"``, ``"drop"``, ``"carry"`` or ``None`` (see above).
        **hyperparameters: the hyper-parameters every agent shares, by keyword: see
            :class:`~delayed_rl.agents.base.TabularAgent`.

    Example:
        >>> import gymnasium as gym
        >>> import delayed_rl
        >>> from delayed_rl.agents import DeconvQ
        >>> env = gym.make("delayed_rl/GridWorld-3x3-v0", reward_delay=2)
        >>> agent = DeconvQ(env, max_delay=8, q_init=10.0, seed=0).learn(20_000)
        >>> agent.predict(8, deterministic=True)[0] in (0, 3)  # from the start: up or left
        True
        >>> agent.delay_pmf.shape  # the learned pmf on 0..max_delay
        (9,)
    """

    _hyperparameter_names = (*QLearning._hyperparameter_names, *_OWN_NAMES)

    @shares_hyperparameters
    def __init__(
        self,
        env: gym.Env | str,
        delay: Delay | float | None = None,
        max_delay: int | None = None,
        solve_interval: int = 20_000,
        ridge: float = 1.0,
        delay_iterations: int = 2,
        on_episode_end: str | None = None,
        **hyperparameters: Any,
    ):
        self._set_deconvolution(
            delay, max_delay, solve_interval, ridge, delay_iterations, on_episode_end
        )
        super().__init__(env, **hyperparameters)

    # ------------------------------------------------------------------ construction
    def _set_deconvolution(
        self,
        delay: Any,
        max_delay: Any,
        solve_interval: Any,
        ridge: Any,
        delay_iterations: Any,
        on_episode_end: Any,
    ) -> None:
        self.delay = _as_known_delay(delay)
        self.max_delay = check_int("max_delay", max_delay, 0, optional=True)
        self.solve_interval = check_int("solve_interval", solve_interval, 1)
        self.ridge = check_real("ridge", ridge, 0.0, low_open=True)
        self.delay_iterations = check_int("delay_iterations", delay_iterations, 1)
        if on_episode_end is not None:
            check_choice("on_episode_end", on_episode_end, EPISODE_END_MODES)
        self.on_episode_end = on_episode_end

    def _set_hyperparameters(self, **hyperparameters: Any) -> None:
        if any(name in hyperparameters for name in _OWN_NAMES):  # loading: they come along
            own = {name: hyperparameters.pop(name, default) for name, default in _OWN_NAMES.items()}
            self._set_deconvolution(**own)
        super()._set_hyperparameters(**hyperparameters)

    def _get_hyperparameters(self) -> dict[str, Any]:
        params = super()._get_hyperparameters()
        if self.delay is not None:  # a known delay is saved as the pmf it is modelled by
            params["delay"] = self._pmf.tolist()
        return params

    def _setup_model(self) -> None:
        super()._setup_model()
        if self.delay is None:
            self._support = DEFAULT_MAX_DELAY if self.max_delay is None else self.max_delay
            self._pmf = np.full(self._support + 1, 1.0 / (self._support + 1))
        else:  # expected credit's weights: the pmf of min(d, K), K as the class docstring says
            weights = credit_weights(self.delay, self.max_delay)
            self._pmf, self._support = weights / weights.sum(), weights.size - 1
        self._reward_model = np.zeros(self.n_states * self.n_actions)
        self._regression = self._new_regression(self.on_episode_end or "flush")
        self._since_solve = 0
        self._solve_after = min(self.solve_interval, _FIRST_SOLVE)

    def _new_regression(self, mode: str) -> RewardRegression:
        self.assumed_episode_end = mode
        return RewardRegression(
            self.n_states * self.n_actions, self._support, mode == "flush", mode == "carry"
        )

    def set_env(self, env: gym.Env | str) -> None:
        """Train on ``env`` from now on (see ``TabularAgent.set_env``); reads its episode-end mode.

        Raises:
            ValueError: the env's reward-delay wrapper treats episode ends otherwise than the
                data the reward model holds (pass ``on_episode_end`` to say which applies).
        """
        super().set_env(env)
        if self.on_episode_end is not None:
            return
        wrapper = find_reward_delay(self.env)
        mode = "flush" if wrapper is None else wrapper.on_episode_end
        if mode == self.assumed_episode_end:
            return
        if self._regression.steps:
            raise ValueError(
                f"the reward model holds {self._regression.steps} steps under "
                f"on_episode_end={self.assumed_episode_end!r} but this env's RewardDelay uses "
                f"{mode!r}: pass on_episode_end= to say which applies"
            )
        self._regression = self._new_regression(mode)

    def compiled_tables(self) -> CompiledTables:
        """Q-learning's tables with the reward model: the compiled loop feeds the statistics.

        A chunk runs up to the next solve; the solve itself runs between chunks, as in
        :meth:`solve`, so both paths learn the same from the same steps.
        """
        chunk = _CHUNK if self._regression.layout == "direct" else _HASHED_CHUNK
        until_solve = min(self._solve_after - self._since_solve, chunk)
        self._regression.reserve(until_solve)  # room for what every step may add
        model = RewardModel(self._reward_model, self._regression.stats)
        tables = super().compiled_tables()
        return tables._replace(
            reward_model=model, chunk_limit=until_solve, after_chunk=self._after_chunk
        )

    def _after_chunk(self, steps: int) -> None:
        self._since_solve += steps
        if self._since_solve >= self._solve_after:
            self.solve()

    # ------------------------------------------------------------------ learning
    def _learn_transition(
        self, s: int, a: int, r: float, s2: int, terminated: bool, truncated: bool
    ) -> None:
        pair = s * self.n_actions + a
        super()._learn_transition(s, a, float(self._reward_model[pair]), s2, terminated, truncated)
        self._regression.observe(pair, r, terminated or truncated)
        self._since_solve += 1
        if self._since_solve >= self._solve_after:
            self.solve()

    def solve(self) -> None:
        """Re-estimate ``R̂`` (and, for a learned delay, the pmf) from everything seen so far."""
        self._since_solve = 0
        self._solve_after = min(self.solve_interval, max(_FIRST_SOLVE, self._regression.steps))
        if self.delay is not None:
            self._reward_model[:] = self._solve_rewards()
            return
        for _ in range(self.delay_iterations):
            self._reward_model[:] = self._solve_rewards()
            self._pmf = self._regression.solve_delay(self._reward_model, self._pmf)

    def _solve_rewards(self) -> np.ndarray:
        regression = self._regression
        return regression.solve_rewards(self._pmf, self.ridge, regression.mean_reward)

    # ------------------------------------------------------------------ persistence
    def _get_state_arrays(self) -> dict[str, np.ndarray]:
        arrays = super()._get_state_arrays()
        regression = self._regression
        arrays.update(
            reward_model=self._reward_model.copy(),
            delay_pmf=self._pmf.copy(),
            solve_clock=np.array([self._since_solve, self._solve_after]),
            assumed_episode_end=np.array(EPISODE_END_MODES.index(self.assumed_episode_end)),
            **{f"regression_{name}": value for name, value in regression.state().items()},
        )
        return arrays

    def _set_state_arrays(self, arrays: dict[str, np.ndarray], where: str) -> None:
        super()._set_state_arrays(arrays, where)
        try:
            mode = EPISODE_END_MODES[int(arrays["assumed_episode_end"])]
            self._regression = self._new_regression(mode)
            self._regression.restore(
                {
                    name[len("regression_") :]: value
                    for name, value in arrays.items()
                    if name.startswith("regression_")
                }
            )
            reward_model, pmf = arrays["reward_model"], arrays["delay_pmf"]
            if reward_model.shape != self._reward_model.shape or pmf.shape != self._pmf.shape:
                raise ValueError("reward_model or delay_pmf has the wrong shape")
            if not (np.all(np.isfinite(reward_model)) and np.all(np.isfinite(pmf))):
                raise ValueError("reward_model or delay_pmf holds non-finite values")
            self._reward_model = reward_model.astype(np.float64)
            self._pmf = pmf.astype(np.float64)
            since, after = (int(v) for v in arrays["solve_clock"])
            self._since_solve = check_int("solve_clock[0]", since, 0)
            self._solve_after = check_int("solve_clock[1]", after, 1)
        except (KeyError, IndexError, TypeError, ValueError) as error:
            raise ValueError(f"{where}: malformed deconvolution state: {error}") from None

    # ------------------------------------------------------------------ diagnostics
    @property
    def delay_pmf(self) -> np.ndarray:
        """The delay pmf on ``0..K`` the agent uses: the known one, or its current estimate."""
        return self._pmf.copy()

    @property
    def mean_delay(self) -> float:
        """The mean of :attr:`delay_pmf`."""
        return float(np.sum(self._pmf * np.arange(self._pmf.size)))

    @property
    def reward_model(self) -> np.ndarray:
        """``R̂``, the estimated mean reward of each (state, action), shape ``(|S|, |A|)``."""
        return self._reward_model.reshape(self.n_states, self.n_actions).copy()

    def _record_model_metrics(self, logger: Any) -> None:
        logger.record("deconv/mean_delay", self.mean_delay)
        logger.record("deconv/reward_model_max", float(self._reward_model.max()))


DeconvQ = DeconvolutionQLearning
"""Short alias of :class:`DeconvolutionQLearning`."""


def _as_known_delay(delay: Any) -> Delay | None:
    """``None``, a :class:`Delay`, a Poisson mean, or a saved pmf (a list), as a ``Delay``."""
    if delay is None or isinstance(delay, Delay):
        return delay
    if isinstance(delay, list):
        return Empirical(delay)
    if isinstance(delay, numbers.Real) and not isinstance(delay, bool):
        from delayed_rl.delays import as_delay

        return as_delay(delay, "delay")
    raise TypeError(
        "delay must be None (learn it), a delayed_rl.delays.Delay or a number read as a Poisson "
        f"mean, got {delay!r} ({type(delay).__name__})"
    )
