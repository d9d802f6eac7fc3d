"""Deconvolution Q-learning: regress the received rewards on the past, then Q-learn on the estimate.

:class:`DeconvolutionQLearning` estimates each (state, action) pair's mean reward ``R̂`` by
deconvolving the delayed reward stream (:mod:`delayed_rl.agents.deconvolution.regression`),
with the delay known or learned, and runs Q-learning on the observed transitions with ``R̂``.
It is anonymous: it reads only the rewards delivered. The rule, its sizes and when it helps are
on the docs' agents page (``docs/agents.md``).
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._validation import Limit, check_choice, check_int, check_real
from delayed_rl.agents.common.compiled_loop import CompiledTables
from delayed_rl.agents.common.delay_estimate import (
    DEFAULT_MAX_DELAY_ESTIMATE,
    check_max_delay_estimate,
)
from delayed_rl.agents.common.hyperparameters import (
    MAX_ABS_VALUE,
    check_limit,
    shares_hyperparameters,
)
from delayed_rl.agents.common.persistence import check_state_array
from delayed_rl.agents.common.python_loop import MAX_TIMESTEPS
from delayed_rl.agents.common.q_agent import QAgent
from delayed_rl.agents.common.q_table import MAX_TABLE_BYTES, table_bytes
from delayed_rl.agents.deconvolution.regression import (
    STATISTICS_LIMIT,
    RewardRegression,
    statistics_bytes,
)
from delayed_rl.agents.expected_credit import credit_weights
from delayed_rl.compiled.state import RewardEstimates
from delayed_rl.delays import Delay, Empirical
from delayed_rl.wrappers.reward_delay import EPISODE_END_MODES, find_reward_delay

__all__ = [
    "MAX_DELAY_ITERATIONS",
    "MAX_SOLVE_INTERVAL",
    "PMF_TOLERANCE",
    "DeconvolutionQLearning",
]

MAX_DELAY_ITERATIONS = Limit(100, "MAX_DELAY_ITERATIONS", __name__, "100")
"""The most ``delay_iterations`` (alternations of the ``R`` and ``p`` solves at each solve).

Each is a least-squares solve for ``R`` and 300 projected-gradient steps for ``p``; the default
is 2.
"""
MAX_SOLVE_INTERVAL = Limit(MAX_TIMESTEPS, "MAX_SOLVE_INTERVAL", __name__, MAX_TIMESTEPS.shown)
"""The longest ``solve_interval`` (``MAX_TIMESTEPS`` = 2**40: a longer gap is never reached)."""
PMF_TOLERANCE = 1e-9
"""How far from 1 a model file's ``delay_pmf`` may sum (its entries finite and >= 0); a known
delay's must also be within this of the delay's own pmf, entry by entry."""
_CHUNK = 4096  # compiled steps between two looks at the statistics' room for segment ends
_HASHED_CHUNK = 256  # the same with hashed statistics: each step may claim K + 1 new rows
_FIRST_SOLVE = 1_000  # steps before the first solve; the gaps then double to solve_interval
_OWN_NAMES = {  # this class's own constructor arguments, and their defaults
    "delay": None,
    "max_delay_estimate": None,
    "solve_interval": 20_000,
    "ridge": 1.0,
    "delay_iterations": 2,
    "on_episode_end": None,
}


class DeconvolutionQLearning(QAgent):
    """Q-learning on mean rewards estimated by deconvolving the delayed reward stream.

    ``docs/agents.md`` states the rule. The reward model ``R̂`` is 0 until the first solve, so
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
            ``max_delay_estimate``); ``None`` (default) learns it on ``0..max_delay_estimate``.
        max_delay_estimate: ``K`` for a learned delay, the longest delay modelled (the designer's cut-off,
            like MMQ's λ̂max; default 50); with a known delay, a cap on its support. At most
            :data:`MAX_DELAY_ESTIMATE` (1024), and a known delay must be modelled within it.
        solve_interval: the longest gap between two least-squares solves (default 20,000); the
            first solve comes after 1000 steps (or ``solve_interval``, if shorter) and the gaps
            double up to it, so early estimates come fast and long runs pay little for them.
            At most :data:`MAX_SOLVE_INTERVAL` (2**40).
        ridge: the weight of a prior that each pair's mean reward is the mean reward received
            per step so far (default 1.0, in units of the normal equations, where one visit
            weighs about ``Σ_k p(k)²``, 0.08 for Poisson(13)): a pair never visited gets that
            mean, a rarely visited one is pulled towards it, and a well-visited one keeps its
            estimate. Deconvolution amplifies noise in the directions the agent's behaviour
            hardly excites; the prior keeps those estimates near the typical reward rather than
            at a spuriously attractive value (on envs with a reward at every step, such as Taxi
            and CliffWalking, a prior at 0 makes unvisited pairs look better than every visited
            one). At most ``MAX_ABS_VALUE`` (2**200); a ridge so small that a solve's mean
            rewards pass ``MAX_ABS_VALUE`` makes that solve raise ``ValueError``.
        delay_iterations: with a learned delay, the alternations of the ``R`` and ``p`` solves
            at each solve (warm-started from the last estimate; default 2; at most
            :data:`MAX_DELAY_ITERATIONS`, 100).
        on_episode_end: ``"flush"``, ``"drop"``, ``"carry"`` or ``None`` (see above).
        **hyperparameters: the hyper-parameters every agent shares, by keyword: see
            :class:`~delayed_rl.agents.common.base.TabularAgent`.

    The tables (Q-table, reward model, statistics and the solves' workspace) must fit
    ``delayed_rl.agents.common.q_table.MAX_TABLE_BYTES``, checked before anything is allocated. A model
    file is checked as the constructor checks its arguments, and its arrays as
    :meth:`_set_state_arrays` says.

    Example:
        >>> import gymnasium as gym
        >>> import delayed_rl
        >>> from delayed_rl.agents import DeconvolutionQLearning
        >>> env = gym.make("delayed_rl/GridWorld-3x3-v0", reward_delay=2)
        >>> agent = DeconvolutionQLearning(env, max_delay_estimate=8, q_init=10.0, seed=0).learn(20_000)
        >>> agent.predict(8, deterministic=True)[0] in (0, 3)  # from the start: up or left
        True
        >>> agent.delay_pmf.shape  # the learned pmf on 0..max_delay_estimate
        (9,)
    """

    _hyperparameter_names = (*QAgent._hyperparameter_names, *_OWN_NAMES)

    @shares_hyperparameters
    def __init__(
        self,
        env: gym.Env | str,
        delay: Delay | float | None = None,
        max_delay_estimate: int | None = None,
        solve_interval: int = 20_000,
        ridge: float = 1.0,
        delay_iterations: int = 2,
        on_episode_end: str | None = None,
        **hyperparameters: Any,
    ):
        self._set_deconvolution(
            delay, max_delay_estimate, solve_interval, ridge, delay_iterations, on_episode_end
        )
        super().__init__(env, **hyperparameters)

    # ------------------------------------------------------------------ construction
    def _set_deconvolution(
        self,
        delay: Any,
        max_delay_estimate: Any,
        solve_interval: Any,
        ridge: Any,
        delay_iterations: Any,
        on_episode_end: Any,
    ) -> None:
        """Check and set this class's own arguments; the pmf's support ``K`` (nothing allocated).

        The checks are the constructor's and a model file's alike (the limits are
        :data:`MAX_DELAY_ESTIMATE`, :data:`MAX_SOLVE_INTERVAL`, :data:`MAX_DELAY_ITERATIONS`,
        and ``MAX_ABS_VALUE`` for ``ridge``).

        Raises:
            TypeError: an argument of the wrong type (the message names it).
            ValueError: an argument out of range, or a known delay that reaches beyond
                :data:`MAX_DELAY_ESTIMATE` steps (give a ``max_delay_estimate`` to clip it).
        """
        self.max_delay_estimate = check_max_delay_estimate(max_delay_estimate)
        self.delay = _as_known_delay(delay)
        self.solve_interval = check_limit(
            "solve_interval",
            check_int("solve_interval", solve_interval, 1),
            MAX_SOLVE_INTERVAL,
        )
        self.ridge = check_limit(
            "ridge",
            check_real("ridge", ridge, 0.0, low_open=True),
            MAX_ABS_VALUE,
        )
        self.delay_iterations = check_limit(
            "delay_iterations",
            check_int("delay_iterations", delay_iterations, 1),
            MAX_DELAY_ITERATIONS,
        )
        if on_episode_end is not None:
            check_choice("on_episode_end", on_episode_end, EPISODE_END_MODES)
        self.on_episode_end = on_episode_end
        if self.delay is None:
            self._known_pmf = None
            self._support = (
                DEFAULT_MAX_DELAY_ESTIMATE
                if self.max_delay_estimate is None
                else self.max_delay_estimate
            )
            return
        # expected credit's weights: the pmf of min(d, K), K as the class docstring says
        weights = credit_weights(self.delay, self.max_delay_estimate)
        self._known_pmf = weights / weights.sum()
        self._support = weights.size - 1

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
        self._check_table_size()
        super()._setup_model()
        if self._known_pmf is None:
            self._pmf = np.full(self._support + 1, 1.0 / (self._support + 1))
        else:
            self._pmf = self._known_pmf.copy()
        self._reward_model = np.zeros(self.n_states * self.n_actions)
        self._regression = self._new_regression(self.on_episode_end or "flush")
        self._since_solve = 0
        self._solve_after = min(self.solve_interval, _FIRST_SOLVE)

    def _check_table_size(self) -> None:
        """Refuse tables above ``MAX_TABLE_BYTES``, before any is allocated.

        The Q-table and its cache, the reward model and the regression's statistics and solves
        (:func:`~delayed_rl.agents.deconvolution.regression.statistics_bytes`) together.

        Raises:
            ValueError: the message names ``max_delay_estimate``, the env's size and the memory needed.
        """
        pairs = self.n_states * self.n_actions
        size = (
            table_bytes(self.n_states, self.n_actions, 1, 0)
            + 8 * pairs
            + 8 * (self._support + 1)
            + statistics_bytes(pairs, self._support)
        )
        if size > MAX_TABLE_BYTES:
            raise ValueError(
                f"{type(self).__name__}(max_delay_estimate={self.max_delay_estimate}) on an env of {self.n_states} "
                f"states and {self.n_actions} actions needs {size / 2**30:.3g} GiB of tables "
                f"(delays modelled up to {self._support} steps: {self._support + 1} reward sums "
                f"per (state, action) pair), over MAX_TABLE_BYTES = "
                f"{MAX_TABLE_BYTES / 2**30:g} GiB (delayed_rl.agents.common.q_table.MAX_TABLE_BYTES): use a "
                "shorter max_delay_estimate or a smaller state space"
            )

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
        model = RewardEstimates(self._reward_model, self._regression.stats)
        tables = self._q_tables()
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
        self._q_learning_update(s, a, float(self._reward_model[pair]), s2, terminated)
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
        """``R̂`` for the current pmf, refused if a mean reward is not within ±MAX_ABS_VALUE.

        Raises:
            ValueError: the solve gave a NaN, infinite or larger value (rewards so large or a
                ridge so small that the regression cannot be solved in float64), which would
                make the Q-table overflow.
        """
        regression = self._regression
        rewards = regression.solve_rewards(self._pmf, self.ridge, regression.mean_reward)
        within = np.abs(rewards) <= MAX_ABS_VALUE  # False for NaN
        if not within.all():
            worst = float(rewards[int(np.argmin(within))])
            raise ValueError(
                f"the reward model's solve gave a mean reward of {worst!r}, beyond "
                f"{MAX_ABS_VALUE.text}: the received rewards "
                f"(mean {regression.mean_reward!r}) are too large for ridge={self.ridge!r}"
            )
        return rewards

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

    def _state_array_specs(self) -> dict[str, tuple[tuple[int, ...], Any]]:
        pairs, k1 = self.n_states * self.n_actions, self._support + 1
        return {
            **super()._state_array_specs(),
            "reward_model": ((pairs,), np.float64),
            "delay_pmf": ((k1,), np.float64),
            "solve_clock": ((2,), np.int64),
            "assumed_episode_end": ((), np.int64),
            "regression_by_lag": ((k1, pairs), np.float64),
            "regression_window": ((k1,), np.int64),
        }

    def _check_state_headers(self, headers: dict[str, Any]) -> None:
        """The co-occurrence counts' size, from their headers, before anything is read.

        Their rows depend on what the agent saw (the hashed layout) or on the file's version
        (``cooc[m, i, j]``), so their shape is checked when they are restored; their bytes must
        not pass ``STATISTICS_LIMIT`` (the limit the statistics keep while training).

        Raises:
            ValueError: the counts and keys would take more than ``STATISTICS_LIMIT`` bytes.
        """
        nbytes = sum(
            math.prod(headers[name].shape) * headers[name].dtype.itemsize
            for name in ("regression_cooc", "regression_keys")
            if name in headers
        )
        if nbytes > STATISTICS_LIMIT:
            raise ValueError(
                f"regression_cooc and regression_keys declare {nbytes / 2**20:,.0f} MiB, more "
                f"than the limit of STATISTICS_LIMIT = {STATISTICS_LIMIT / 2**20:.0f} MiB "
                "(delayed_rl.agents.deconvolution.regression.STATISTICS_LIMIT)"
            )

    def _set_state_arrays(self, arrays: dict[str, np.ndarray], where: str) -> None:
        """Check the deconvolution state against this agent, then set it.

        Beyond Q-learning's arrays: ``assumed_episode_end`` an index of
        :data:`~delayed_rl.wrappers.EPISODE_END_MODES` (the ``on_episode_end`` given, if one was); the statistics as
        :meth:`~delayed_rl.agents.deconvolution.regression.RewardRegression.restore` checks them;
        ``reward_model`` one mean reward per pair within ±``MAX_ABS_VALUE``; ``delay_pmf`` on
        the simplex (finite, ``>= 0``, summing to 1 within :data:`PMF_TOLERANCE`) and, for a
        known delay, that delay's pmf; ``solve_clock`` ``[steps since the last solve, the
        gap]`` with ``0 <= since < gap <= MAX_SOLVE_INTERVAL`` and ``since`` at most the steps
        the statistics hold. A ``solve_interval`` given to ``load`` (``custom_objects``) below
        the saved gap shortens it to ``solve_interval`` (and ``since`` to at most one step
        less): the next solve then comes within the new interval. Last, the statistics are
        solved once, as the next solve will: statistics that are not the counts of any stream
        of steps (normal equations that are not positive definite, a window couple never
        counted) or whose mean rewards pass ``MAX_ABS_VALUE`` are refused.

        Raises:
            ValueError: an array is missing or wrong (the message names the file and it).
        """
        super()._set_state_arrays(arrays, where)
        try:
            self._set_deconvolution_arrays(arrays)
        except (KeyError, IndexError, TypeError, ValueError) as error:
            raise ValueError(f"{where}: malformed deconvolution state: {error}") from None

    def _set_deconvolution_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        pairs, k1 = self.n_states * self.n_actions, self._support + 1
        mode_index = int(
            check_state_array(
                "assumed_episode_end",
                arrays.get("assumed_episode_end"),
                (),
                np.int64,
                0,
                len(EPISODE_END_MODES) - 1,
                note=f" (an index of {EPISODE_END_MODES})",
            )
        )
        mode = EPISODE_END_MODES[mode_index]
        if self.on_episode_end is not None and mode != self.on_episode_end:
            raise ValueError(
                f"assumed_episode_end must be {EPISODE_END_MODES.index(self.on_episode_end)} "
                f"(on_episode_end={self.on_episode_end!r}), got {mode_index} ({mode!r})"
            )
        regression = self._new_regression(mode)
        regression.restore(
            {
                name[len("regression_") :]: value
                for name, value in arrays.items()
                if name.startswith("regression_")
            },
            prefix="regression_",
        )
        reward_model = check_state_array(
            "reward_model",
            arrays.get("reward_model"),
            (pairs,),
            np.float64,
            -MAX_ABS_VALUE,
            MAX_ABS_VALUE,
            note=f" ({MAX_ABS_VALUE.text})",
        )
        pmf = _check_pmf(arrays.get("delay_pmf"), k1, self._known_pmf)
        since, after = (
            int(v)
            for v in check_state_array(
                "solve_clock", arrays.get("solve_clock"), (2,), np.int64, 0, MAX_SOLVE_INTERVAL
            )
        )
        if not 0 <= since < after or since > regression.steps:
            raise ValueError(
                f"solve_clock must be [steps since the last solve, the gap to the next] with "
                f"0 <= since < gap and since at most the {regression.steps} steps the "
                f"statistics hold, got {[since, after]}"
            )
        if after > self.solve_interval:  # a shorter solve_interval given to load()
            after, since = self.solve_interval, min(since, self.solve_interval - 1)
        self._regression, self.assumed_episode_end = regression, mode
        self._reward_model = reward_model.copy()
        self._pmf = pmf.copy()
        self._since_solve, self._solve_after = since, after
        if regression.steps:
            self._check_solvable()

    def _check_solvable(self) -> None:
        """Solve the reward model once as the next solve will, keeping nothing of it.

        Statistics that are the counts of a stream of steps always solve (their normal
        equations plus the ridge are positive definite); others (corrupt counts, a window
        couple never counted) usually do not.

        Raises:
            ValueError: the statistics cannot be solved, or give mean rewards beyond
                ``MAX_ABS_VALUE``.
        """
        regression = self._regression
        warm_start = regression._last_rewards
        try:
            self._solve_rewards()
        except ValueError as error:
            raise ValueError(
                f"the regression_* statistics cannot be solved (with ridge={self.ridge!r}) as "
                f"the next solve will solve them: {error}"
            ) from None
        finally:
            regression._last_rewards = warm_start

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


def _check_pmf(pmf: Any, size: int, known: np.ndarray | None) -> np.ndarray:
    """A model file's ``delay_pmf``, checked: on the simplex, and the known delay's if given.

    Raises:
        ValueError: it is not a float64 array of ``size`` finite entries in [0, 1] summing to 1
            within :data:`PMF_TOLERANCE`, or differs from ``known`` by more than that.
    """
    pmf = check_state_array(
        "delay_pmf",
        pmf,
        (size,),
        np.float64,
        0.0,
        1.0,
        note=" (a delay pmf on 0..max_delay_estimate)",
    )
    total = math.fsum(pmf.tolist())
    if abs(total - 1.0) > PMF_TOLERANCE:
        raise ValueError(
            f"delay_pmf must sum to 1 (within PMF_TOLERANCE = {PMF_TOLERANCE:g}), got a sum of "
            f"{total!r}"
        )
    if known is not None and np.max(np.abs(pmf - known)) > PMF_TOLERANCE:
        raise ValueError(
            f"delay_pmf must be the known delay's pmf (within PMF_TOLERANCE = "
            f"{PMF_TOLERANCE:g}): it differs by up to {float(np.max(np.abs(pmf - known)))!r}"
        )
    return pmf


def _as_known_delay(delay: Any) -> Delay | None:
    """``None``, a :class:`Delay`, a Poisson mean, or a saved pmf (a list), as a ``Delay``.

    Raises:
        TypeError: ``delay`` is none of these (the message names ``delay``).
        ValueError: a number that is not a Poisson mean, or a list that is not a pmf.
    """
    if delay is None or isinstance(delay, Delay):
        return delay
    if isinstance(delay, list):
        try:
            return Empirical(delay)
        except (TypeError, ValueError) as error:
            raise type(error)(f"delay (a saved pmf): {error}") from None
    if isinstance(delay, numbers.Real) and not isinstance(delay, bool):
        from delayed_rl.delays import as_delay

        return as_delay(delay, "delay")
    raise TypeError(
        "delay must be None (learn it), a delayed_rl.delays.Delay or a number read as a Poisson "
        f"mean, got {delay!r} ({type(delay).__name__})"
    )
