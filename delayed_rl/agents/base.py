"""The stable-baselines3-like shell shared by the tabular agents.

:class:`TabularAgent` owns everything that is not the learning rule: the env (an instance or an id
string), argument checks, the training loop of :meth:`~TabularAgent.learn` with SB3's callback
protocol, progress bar and logger, :meth:`~TabularAgent.predict`, and saving to / loading from
``.npz`` files. A subclass supplies the learning rule: ``_setup_model`` (allocate the tables),
``_choose`` (one behaviour action), ``_learn_transition`` (one learning step, shared by
:meth:`~TabularAgent.learn` and :meth:`~TabularAgent.update`), ``_greedy_actions``,
``_end_episode`` (forget the episode's history) and ``_get_state_arrays``/``_set_state_arrays``
(what a model file holds).
"""

from __future__ import annotations

import math
import numbers
import sys
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from delayed_rl._validation import check_int
from delayed_rl.agents.callbacks import as_callback
from delayed_rl.agents.logger import Logger
from delayed_rl.agents.schedules import (
    ConstantSchedule,
    LinearSchedule,
    Schedule,
    as_learning_rate_schedule,
    check_fraction,
    check_probability,
    check_schedule_value,
)

__all__ = ["RECORD_KEYS", "TabularAgent"]

RECORD_KEYS = ("obs", "action", "reward", "undelayed_reward", "acting_delay_index", "done")
"""The arrays of ``agent.training_log`` after ``learn(..., record=True)``."""

_PREDICT_STREAM = 0x9E3D  # spawn key separating predict()'s randomness from training's


class UniformStream:
    """Uniform [0, 1) numbers handed out one at a time from blocks of one generator call.

    Args:
        rng: the generator.
        block_size: how many numbers to draw per call.
    """

    __slots__ = ("rng", "block", "i", "block_size")

    def __init__(self, rng: np.random.Generator, block_size: int = 1024):
        self.rng = rng
        self.block: list[float] = []
        self.i = 0
        self.block_size = block_size

    def __call__(self) -> float:
        i = self.i
        if i == len(self.block):
            self.block = self.rng.random(self.block_size).tolist()
            i = 0
        self.i = i + 1
        return self.block[i]

    def get_state(self) -> tuple[dict[str, Any], np.ndarray]:
        """The generator's state and the numbers drawn but not yet handed out."""
        return self.rng.bit_generator.state, np.asarray(self.block[self.i :], dtype=np.float64)

    def set_state(self, state: dict[str, Any], remaining: np.ndarray) -> None:
        """Restore what :meth:`get_state` returned."""
        self.rng.bit_generator.state = state
        self.block, self.i = [float(x) for x in remaining], 0


def _check_discrete(space: Any, name: str) -> spaces.Discrete:
    if isinstance(space, spaces.Discrete):
        return space
    if name == "observation_space":
        hint = (
            "map observations to integers first, e.g. "
            "gymnasium.wrappers.DiscretizeObservation(env, bins=10) for a Box space, or your own "
            "gymnasium.ObservationWrapper whose observation_space is Discrete(n)"
        )
    else:
        hint = (
            "use a discrete action set, e.g. gymnasium.wrappers.DiscretizeAction(env, bins=5) for "
            "a Box space, or your own gymnasium.ActionWrapper whose action_space is Discrete(n)"
        )
    raise TypeError(f"tabular agents need a Discrete {name}, got {space!r}: {hint}")


def make_env(env: Any) -> gym.Env:
    """``env`` itself if it is a ``gymnasium.Env``, ``gym.make(env)`` if it is an id string."""
    if isinstance(env, str):
        return gym.make(env)
    if isinstance(env, gym.Env):
        return env
    if hasattr(env, "num_envs") and hasattr(env, "step_async"):
        raise TypeError(
            "tabular agents step one gymnasium.Env, got a stable-baselines3 VecEnv "
            f"({type(env).__name__}); pass the env itself (for a DummyVecEnv: venv.envs[0])"
        )
    raise TypeError(f"env must be a gymnasium.Env or a registered env id string, got {env!r}")


class SingleEnvVecView:
    """A one-env, SB3-``VecEnv``-shaped view of a ``gymnasium.Env`` (what ``get_env()`` returns
    when stable-baselines3 is not loaded). Batched ``reset``/``step`` with automatic reset, as in
    SB3; the agent itself steps the underlying env directly.

    Args:
        env: the env.
    """

    num_envs = 1

    def __init__(self, env: gym.Env):
        self.envs = [env]
        self.observation_space = env.observation_space
        self.action_space = env.action_space
        self.metadata = env.metadata
        self.render_mode = env.render_mode

    def reset(self) -> np.ndarray:
        obs, _ = self.envs[0].reset()
        return np.array([obs])

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        obs, reward, terminated, truncated, info = self.envs[0].step(np.asarray(actions)[0])
        done = terminated or truncated
        if done:
            info["terminal_observation"] = obs
            info["TimeLimit.truncated"] = truncated and not terminated
            obs, _ = self.envs[0].reset()
        return np.array([obs]), np.array([reward], dtype=np.float32), np.array([done]), [info]

    def get_attr(self, name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.envs[0], name)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        env = self.envs[0]
        while isinstance(env, gym.Wrapper):
            if isinstance(env, wrapper_class):
                return [True]
            env = env.env
        return [False]

    def close(self) -> None:
        self.envs[0].close()


class TabularAgent:
    """Shell of the tabular agents: stable-baselines3's names and semantics on a Q-table.

    Args:
        env: the training env (a ``gymnasium.Env`` with ``Discrete`` observation and action
            spaces) or a registered env id, which is made with ``gym.make``.
        learning_rate: the step size α, a number in (0, 1] or a schedule
            ``fn(progress_remaining) -> α`` as in SB3 (progress remaining falls from 1 to 0 over
            each ``learn()`` call).
        gamma: the discount factor γ in [0, 1].
        exploration_initial_eps: ε at the start of ``learn()``.
        exploration_final_eps: ε after a fraction ``exploration_fraction`` of ``learn()``.
            Equal to ``exploration_initial_eps`` (the default, 0.1) gives a constant ε.
        exploration_fraction: the fraction of training over which ε moves, in (0, 1].
        q_init: the initial value of every Q-table entry (optimistic when above the values).
        seed: seeds the agent's random choices and the env's first reset after it is set.
        verbose: 0 silent, 1 prints the logged metrics at every dump.

    Attributes:
        env: the ``gymnasium.Env`` the agent trains on (``None`` after ``load`` without env).
        num_timesteps: learning steps taken (by ``learn()`` and ``update()``).
        exploration_rate: the current ε.
        training_log: after ``learn(..., record=True)``, one array per step for each key of
            :data:`RECORD_KEYS`.
        last_learn_path: ``"fused"`` or ``"python"``: the loop the last ``learn()`` ran on.
    """

    _hyperparameter_names: ClassVar[tuple[str, ...]] = (
        "learning_rate",
        "gamma",
        "exploration_initial_eps",
        "exploration_final_eps",
        "exploration_fraction",
        "q_init",
        "seed",
        "verbose",
    )

    def __init__(
        self,
        env: gym.Env | str,
        learning_rate: float | Schedule = 0.1,
        gamma: float = 0.9,
        exploration_initial_eps: float = 0.1,
        exploration_final_eps: float = 0.1,
        exploration_fraction: float = 0.1,
        q_init: float = 0.0,
        seed: int | None = None,
        verbose: int = 0,
    ):
        self._set_hyperparameters(
            learning_rate=learning_rate,
            gamma=gamma,
            exploration_initial_eps=exploration_initial_eps,
            exploration_final_eps=exploration_final_eps,
            exploration_fraction=exploration_fraction,
            q_init=q_init,
            seed=seed,
            verbose=verbose,
        )
        env = make_env(env)
        self._set_spaces(env.observation_space, env.action_space)
        self._setup_model()
        self._reset_statistics()
        self.set_env(env)

    # ------------------------------------------------------------------ construction
    def _set_hyperparameters(
        self,
        learning_rate: float | Schedule,
        gamma: float,
        exploration_initial_eps: float,
        exploration_final_eps: float,
        exploration_fraction: float,
        q_init: float,
        seed: int | None,
        verbose: int,
    ) -> None:
        self.lr_schedule = as_learning_rate_schedule(learning_rate)
        self.learning_rate = learning_rate
        self.gamma = check_probability("gamma", gamma)
        self.exploration_initial_eps = check_probability(
            "exploration_initial_eps", exploration_initial_eps
        )
        self.exploration_final_eps = check_probability(
            "exploration_final_eps", exploration_final_eps
        )
        self.exploration_fraction = check_fraction("exploration_fraction", exploration_fraction)
        self.exploration_schedule = LinearSchedule(
            self.exploration_initial_eps, self.exploration_final_eps, self.exploration_fraction
        )
        if (
            isinstance(q_init, bool)
            or not isinstance(q_init, numbers.Real)
            or not math.isfinite(q_init)
        ):
            raise ValueError(f"q_init must be a finite real number, got {q_init!r}")
        self.q_init = float(q_init)
        self.seed = check_int("seed", seed, 0, optional=True)
        self.verbose = check_int("verbose", verbose, 0, note=" (0 silent, 1 info)")
        self._progress_remaining = 1.0
        self._alpha = self._current_learning_rate()
        self.exploration_rate = self.exploration_schedule(1.0)
        self.num_timesteps = 0
        self._logger: Any = None
        self.training_log: dict[str, np.ndarray] = {}
        self._uniform = UniformStream(np.random.default_rng(self.seed))
        self._predict_uniform = UniformStream(
            np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(_PREDICT_STREAM,)))
        )

    def _set_spaces(self, observation_space: Any, action_space: Any) -> None:
        self.observation_space = _check_discrete(observation_space, "observation_space")
        self.action_space = _check_discrete(action_space, "action_space")
        self.n_states = int(self.observation_space.n)
        self.n_actions = int(self.action_space.n)
        self._obs_start = int(self.observation_space.start)
        self._action_start = int(self.action_space.start)

    def _setup_model(self) -> None:
        """Allocate the tables (subclasses)."""
        raise NotImplementedError

    def _get_hyperparameters(self) -> dict[str, Any]:
        """The constructor arguments, JSON-ready (the learning rate as a schedule description)."""
        from delayed_rl.agents.schedules import schedule_to_json

        params = {name: getattr(self, name) for name in self._hyperparameter_names}
        params["learning_rate"] = schedule_to_json(self.lr_schedule, self._alpha)
        return params

    # ------------------------------------------------------------------ env
    def get_env(self) -> Any:
        """The training env as a one-env SB3 ``VecEnv`` (as SB3's ``get_env()``), or ``None``.

        A stable-baselines3 ``DummyVecEnv`` around :attr:`env` when stable-baselines3 is loaded
        (so SB3's callbacks see the type they expect), else a :class:`SingleEnvVecView`. The agent
        steps :attr:`env` itself; do not step this view during ``learn()``.
        """
        if self.env is None:
            return None
        if self._vec_env is None:
            if sys.modules.get("stable_baselines3") is not None:
                from stable_baselines3.common.vec_env import DummyVecEnv

                env = self.env
                self._vec_env = DummyVecEnv([lambda: env])
            else:
                self._vec_env = SingleEnvVecView(self.env)
        return self._vec_env

    def get_vec_normalize_env(self) -> None:
        """``None``: tabular agents never normalise (SB3 parity, used by ``EvalCallback``)."""
        return None

    def set_env(self, env: gym.Env | str) -> None:
        """Train on ``env`` from now on; its spaces must equal the agent's.

        The next ``learn()`` resets it (the first reset after ``set_env`` uses the agent's seed).

        Raises:
            TypeError: ``env`` is not an env, or its spaces are not ``Discrete``.
            ValueError: its spaces differ from the agent's.
        """
        env = make_env(env)
        for name in ("observation_space", "action_space"):
            theirs = _check_discrete(getattr(env, name), name)
            ours = getattr(self, name)
            if theirs != ours:
                raise ValueError(
                    f"the env's {name} is {theirs!r} but the agent was built for {ours!r}"
                )
        self.env = env
        self._vec_env = None
        self._env_seeded = False
        self._episode_open = False
        self._end_episode()

    def _reset_env(self) -> int:
        seed = None if self._env_seeded else self.seed
        self._env_seeded = True
        obs, _ = self.env.reset(seed=seed)
        self._end_episode()
        self._episode_open = True
        self._episode_reward = 0.0
        self._episode_length = 0
        return self._obs_index(obs, "the env's reset() observation")

    def _end_episode(self) -> None:
        """Forget the current episode's history (subclasses)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ logging
    @property
    def logger(self) -> Any:
        """Where metrics are recorded: set with :meth:`set_logger`, else a :class:`Logger`."""
        if self._logger is None:
            self._logger = Logger(self.verbose)
        return self._logger

    def set_logger(self, logger: Any) -> None:
        """Record metrics with ``logger`` (e.g. SB3's ``configure(folder, ["csv"])``)."""
        if not (
            callable(getattr(logger, "record", None)) and callable(getattr(logger, "dump", None))
        ):
            raise TypeError(f"logger must have record() and dump() methods, got {logger!r}")
        self._logger = logger

    def dump_logs(self) -> None:
        """Write the recorded metrics at the current step (SB3 parity)."""
        self.logger.dump(self.num_timesteps)

    # ------------------------------------------------------------------ schedules
    def _current_learning_rate(self) -> float:
        return check_schedule_value(
            "learning_rate",
            self.lr_schedule(self._progress_remaining),
            self._progress_remaining,
            allow_zero=False,
        )

    @property
    def current_learning_rate(self) -> float:
        """The α of the next learning step."""
        return self._alpha

    # ------------------------------------------------------------------ conversions
    def _obs_index(self, obs: Any, what: str = "observation") -> int:
        if isinstance(obs, (bool, np.bool_)) or not isinstance(obs, (numbers.Integral, np.ndarray)):
            raise ValueError(f"{what} must be an integer in {self.observation_space}, got {obs!r}")
        index = int(obs) - self._obs_start
        if not 0 <= index < self.n_states:
            raise ValueError(f"{what} must be an integer in {self.observation_space}, got {obs!r}")
        return index

    def _obs_indices(self, observation: Any, name: str = "observation") -> tuple[np.ndarray, bool]:
        """Observations as 0-based indices, and whether a single (unbatched) one was given."""
        obs = np.asarray(observation)
        if obs.dtype == np.bool_ or not np.issubdtype(obs.dtype, np.integer):
            if obs.size and np.issubdtype(obs.dtype, np.floating) and np.all(obs == np.round(obs)):
                obs = obs.astype(np.int64)
            else:
                raise ValueError(
                    f"{name} must be an integer (or a 1-D batch of integers) in "
                    f"{self.observation_space}, got {observation!r}"
                )
        if obs.ndim > 1:
            raise ValueError(
                f"{name} must be one integer or a 1-D batch for {self.observation_space}, "
                f"got shape {obs.shape}"
            )
        index = obs.astype(np.int64) - self._obs_start
        if index.size and (index.min() < 0 or index.max() >= self.n_states):
            raise ValueError(f"{name} must lie in {self.observation_space}, got {observation!r}")
        return index, obs.ndim == 0

    # ------------------------------------------------------------------ acting
    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = False,
    ) -> tuple[Any, None]:
        """The action for ``observation`` (SB3's signature).

        Args:
            observation: one observation (an integer) or a 1-D batch of them.
            state: ignored (no recurrent state), returned as ``None``.
            episode_start: ignored.
            deterministic: the greedy action (ties go to the lowest index) when ``True``;
                otherwise the behaviour policy (ε-greedy at the current ``exploration_rate``,
                random tie-breaks), drawn from a random stream separate from training's.

        Returns:
            ``(action, None)``: an ``int`` for one observation, an ``int64`` array for a batch.
        """
        index, single = self._obs_indices(observation)
        flat = index.reshape(-1)
        if deterministic:
            actions = self._greedy_actions(flat)
        else:
            actions = np.fromiter(
                (
                    self._choose(int(s), self.exploration_rate, self._predict_uniform)[1]
                    for s in flat
                ),
                dtype=np.int64,
                count=flat.size,
            )
        actions = actions + self._action_start
        if single:
            return int(actions[0]), None
        return actions, None

    def _choose(self, s: int, eps: float, uniform: Callable[[], float]) -> tuple[int, int]:
        """Behaviour choice in state index ``s``: ``(model index, action index)`` (subclasses)."""
        raise NotImplementedError

    def _greedy_actions(self, states: np.ndarray) -> np.ndarray:
        """Greedy action indices for state indices (subclasses)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ learning
    def update(
        self,
        obs: Any,
        action: Any,
        reward: float,
        next_obs: Any,
        terminated: bool = False,
        truncated: bool = False,
    ) -> None:
        """One learning step from a transition you drove yourself (custom loops, robots).

        Transitions must come in the order they happened: the agent keeps the current episode's
        history to credit delayed rewards. ``terminated`` or ``truncated`` ends the episode (the
        history is cleared after this update); ``terminated`` also stops bootstrapping from
        ``next_obs``. ``learn()`` runs every step through the same code.

        Args:
            obs: the observation the action was taken in.
            action: the action taken.
            reward: the reward received at this step (delayed: whatever arrived now).
            next_obs: the observation after the action.
            terminated: the episode ended in a terminal state.
            truncated: the episode was cut short (e.g. a time limit).

        Raises:
            ValueError: an argument is outside its space, or the reward is not finite.
        """
        s = self._obs_index(obs, "obs")
        s2 = self._obs_index(next_obs, "next_obs")
        if isinstance(action, (bool, np.bool_)) or not isinstance(
            action, (numbers.Integral, np.ndarray)
        ):
            raise ValueError(f"action must be an integer in {self.action_space}, got {action!r}")
        a = int(action) - self._action_start
        if not 0 <= a < self.n_actions:
            raise ValueError(f"action must be an integer in {self.action_space}, got {action!r}")
        if isinstance(reward, (bool, np.bool_)) or not isinstance(
            reward, (numbers.Real, np.ndarray)
        ):
            raise ValueError(f"reward must be a finite real number, got {reward!r}")
        r = float(reward)
        if not math.isfinite(r):
            raise ValueError(f"reward must be a finite real number, got {reward!r}")
        for name, flag in (("terminated", terminated), ("truncated", truncated)):
            if not isinstance(flag, (bool, np.bool_)):
                raise ValueError(f"{name} must be a bool, got {flag!r}")
        self._learn_transition(s, a, r, s2, bool(terminated), bool(truncated))

    def _learn_transition(
        self, s: int, a: int, r: float, s2: int, terminated: bool, truncated: bool
    ) -> None:
        """Learn from one transition and advance ``num_timesteps`` (subclasses)."""
        raise NotImplementedError

    def learn(
        self,
        total_timesteps: int,
        callback: Any = None,
        log_interval: int | None = 10_000,
        tb_log_name: str = "run",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
        record: bool = False,
        fused: bool | None = None,
    ) -> TabularAgent:
        """Train for ``total_timesteps`` steps of the env (SB3's signature and semantics).

        Works on continuing envs (which never end an episode): each step acts, steps the env and
        learns at once. When an episode ends (terminated or truncated) the env is reset and the
        episode's history is cleared. With ``reset_num_timesteps=True`` (the default)
        ``num_timesteps`` restarts at 0 and the env is reset first; with ``False`` the step
        count, the exploration and learning-rate schedules' clock and the current episode
        continue where the previous ``learn()`` stopped (after ``load`` or ``set_env``, the env is
        reset).

        Args:
            total_timesteps: how many env steps to take (``reset_num_timesteps=False``: more).
            callback: ``None``, a stable-baselines3 callback (``EvalCallback``,
                ``CheckpointCallback``, ``StopTrainingOnMaxEpisodes``, ``CallbackList``, ...), a
                :mod:`delayed_rl.agents.callbacks` callback, a callable
                ``fn(locals_, globals_) -> bool`` (``False`` stops training), or a list of these.
            log_interval: record and dump metrics every this many *steps* (episodes may never
                end in a continuing task); ``None`` logs only at the end.
            tb_log_name: the run's name, passed to callbacks as SB3 does (unused otherwise).
            reset_num_timesteps: see above.
            progress_bar: show a progress bar (tqdm's when installed, else a text bar).
            record: fill :attr:`training_log` with one entry per step: ``obs``, ``action``,
                ``reward`` (as received, delayed), ``undelayed_reward`` (``info
                ["undelayed_reward"]`` of a reward-delay wrapper, else the reward),
                ``acting_delay_index`` (the index into ``delay_estimates`` of the acting model)
                and ``done`` (the episode ended at that step) — what experiments need to
                compute average rewards from the undelayed stream.
            fused: run the whole loop compiled (:mod:`delayed_rl.fast`): ``None`` (default)
                does when it can — the env stack compiles (a tabular env exposing its tables,
                under at most one :class:`~delayed_rl.wrappers.RewardDelay`, see
                :mod:`delayed_rl.fast.tabular`), the learning rate is constant and no
                ``callback`` is given (``progress_bar`` is fine) — and runs the Python loop
                otherwise; ``False`` never does; ``True`` must (raises
                :class:`~delayed_rl.fast.NotCompilable` with the reason otherwise). Both paths
                apply the same update rule; their random streams differ, so seeded runs agree
                in distribution, not step by step. On the compiled path the env object is not
                stepped (the next Python-path ``learn()`` resets it). Callbacks still get one
                ``on_step()`` per step, with that step's ``locals`` (``info`` holds only
                ``undelayed_reward``), but they run after each compiled chunk of
                :attr:`fused_chunk` steps: the model they see (an ``EvalCallback``'s
                evaluation, a ``CheckpointCallback``'s file) is the one at the chunk's end, and
                a callback's ``False`` stops training at the end of its chunk.

        Returns:
            The agent itself.

        Raises:
            ValueError: a bad argument, or the agent has no env.
        """
        total_timesteps = check_int("total_timesteps", total_timesteps, 0)
        log_interval = check_int("log_interval", log_interval, 1, optional=True)
        for name, flag in (
            ("reset_num_timesteps", reset_num_timesteps),
            ("progress_bar", progress_bar),
            ("record", record),
        ):
            if not isinstance(flag, bool):
                raise ValueError(f"{name} must be a bool, got {flag!r}")
        if self.env is None:
            raise ValueError(
                "the agent has no env to learn from: pass env= to load() or call set_env(env)"
            )
        per_step_callbacks = callback is not None
        callback = as_callback(callback, progress_bar)
        if reset_num_timesteps:
            self.num_timesteps = 0
            self._reset_statistics()
            self._episode_open = False
        start_timesteps = self.num_timesteps
        total_timesteps = int(total_timesteps) + start_timesteps  # SB3: the absolute end
        n_steps = total_timesteps - start_timesteps
        if not self._episode_open:
            self._obs = self._reset_env()
        log = (
            {key: np.zeros(n_steps, dtype=_RECORD_DTYPES[key]) for key in RECORD_KEYS}
            if record
            else {}
        )

        env = self.env
        obs_start, action_start = self._obs_start, self._action_start
        eps_constant = self.exploration_initial_eps == self.exploration_final_eps
        lr_constant = isinstance(self.lr_schedule, ConstantSchedule)
        eps = self.exploration_rate
        uniform = self._uniform
        choose, learn_transition = self._choose, self._learn_transition
        acting_counts = self._acting_counts
        locals_: dict[str, Any] = {
            "self": self,
            "total_timesteps": total_timesteps,
            "tb_log_name": tb_log_name,
        }
        if callback is not None:
            callback.init_callback(self)
            callback.on_training_start(locals_, globals())
            callback.on_rollout_start()
        self._log_start = (time.perf_counter(), self.num_timesteps)
        next_log = n_steps + 1 if log_interval is None else log_interval
        if fused is None and per_step_callbacks:
            fused = False  # callbacks see the exact per-step model on the Python path
        fused_run = self._fused_run(fused, lr_constant, reset_num_timesteps)
        self.last_learn_path = "python" if fused_run is None else "fused"
        if fused_run is not None:
            steps_done, reward_total, undelayed_total = self._learn_fused(
                fused_run, n_steps, start_timesteps, total_timesteps, callback, locals_,
                log_interval, log,
            )  # fmt: skip
            return self._finish_learn(
                steps_done, reward_total, undelayed_total, total_timesteps, record, log, callback
            )
        s = self._obs
        episode_reward, episode_length = self._episode_reward, self._episode_length
        reward_total = undelayed_total = 0.0
        steps_done = 0
        for step in range(n_steps):
            if not (eps_constant and lr_constant):
                self._progress_remaining = 1.0 - (start_timesteps + step) / total_timesteps
                if not eps_constant:
                    eps = self.exploration_rate = self.exploration_schedule(
                        self._progress_remaining
                    )
                if not lr_constant:
                    self._alpha = self._current_learning_rate()
            model, a = choose(s, eps, uniform)
            acting_counts[model] += 1
            obs, reward, terminated, truncated, info = env.step(a + action_start)
            s2 = int(obs) - obs_start
            reward = float(reward)
            undelayed = info.get("undelayed_reward", reward)
            learn_transition(s, a, reward, s2, terminated, truncated)
            done = terminated or truncated
            steps_done = step + 1
            reward_total += reward
            undelayed_total += undelayed
            episode_reward += undelayed
            episode_length += 1
            if record:
                log["obs"][step] = s + obs_start
                log["action"][step] = a + action_start
                log["reward"][step] = reward
                log["undelayed_reward"][step] = undelayed
                log["acting_delay_index"][step] = model
                log["done"][step] = done
            if callback is not None:
                locals_.update(
                    obs=s + obs_start,
                    action=a + action_start,
                    reward=reward,
                    undelayed_reward=undelayed,
                    terminated=terminated,
                    truncated=truncated,
                    info=info,
                    acting_delay_index=model,
                    new_obs=np.array([obs]),
                    actions=np.array([a + action_start]),
                    rewards=np.array([reward]),
                    dones=np.array([done]),
                    infos=[info],
                )
                callback.update_locals(locals_)
            if done:
                self._episode_rewards.append(episode_reward)
                self._episode_lengths.append(episode_length)
                self._episodes += 1
                s = self._reset_env()
                episode_reward, episode_length = 0.0, 0
            else:
                s = s2
            if callback is not None:
                self._obs = s
                if not callback.on_step():
                    break
            if steps_done == next_log:
                next_log += log_interval
                self._log_metrics(reward_total, undelayed_total)
                reward_total = undelayed_total = 0.0
        self._obs = s
        self._episode_reward, self._episode_length = episode_reward, episode_length
        return self._finish_learn(
            steps_done, reward_total, undelayed_total, total_timesteps, record, log, callback
        )

    def _finish_learn(
        self,
        steps_done: int,
        reward_total: float,
        undelayed_total: float,
        total_timesteps: int,
        record: bool,
        log: dict[str, np.ndarray],
        callback: Any,
    ) -> TabularAgent:
        """What ends every ``learn()``: the record, the last metrics, the callbacks' ends."""
        self._progress_remaining = 1.0 - self.num_timesteps / max(total_timesteps, 1)
        if record:
            self.training_log = {key: value[:steps_done] for key, value in log.items()}
        if self.num_timesteps > self._log_start[1]:
            self._log_metrics(reward_total, undelayed_total)
        if callback is not None:
            callback.on_rollout_end()
            callback.on_training_end()
        return self

    # ------------------------------------------------------------------ the compiled path
    fused_chunk: int = 1_000
    """Steps per compiled call when callbacks are attached (they are called between calls)."""

    def _fused_run(self, fused: bool | None, lr_constant: bool, restart: bool) -> Any:
        """The compiled run to train with, or ``None`` for the Python loop (see ``learn``).

        A run continues (same episode, history and pending rewards) across ``learn()`` calls
        with ``reset_num_timesteps=False`` on the same env; otherwise a new one starts, seeded
        from the agent's own generator (so seeded agents are reproducible).
        """
        if fused is not None and not isinstance(fused, bool):
            raise ValueError(f"fused must be None (automatic), True or False, got {fused!r}")
        if fused is False:
            self._fused = None
            return None
        from delayed_rl.fast import FusedRun, NotCompilable

        try:
            if not lr_constant:
                raise NotCompilable("the learning rate is a schedule (only a constant compiles)")
            if not hasattr(self, "_q"):
                raise NotCompilable(f"{type(self).__name__} has no compiled learning rule")
            cached = getattr(self, "_fused", None)
            if cached is None or cached[0] is not self.env or restart:
                seed = int(self._uniform.rng.integers(2**63))
                self._fused = (self.env, FusedRun(self.env, self._delays, seed))
            return self._fused[1]
        except NotCompilable:
            self._fused = None
            if fused:
                raise
            return None

    def _learn_fused(
        self,
        run: Any,
        n_steps: int,
        start_timesteps: int,
        total_timesteps: int,
        callback: Any,
        locals_: dict[str, Any],
        log_interval: int | None,
        log: dict[str, np.ndarray],
    ) -> tuple[int, float, float]:
        """Train ``n_steps`` on the compiled path; return (steps done, reward sums since the log)."""
        eps_steps = max(1, round(self.exploration_fraction * total_timesteps))
        if self.exploration_initial_eps == self.exploration_final_eps:
            eps_steps = 1
        chunk = self.fused_chunk if callback is not None else n_steps
        if log_interval is not None:
            chunk = min(chunk, log_interval)
        next_log = n_steps + 1 if log_interval is None else log_interval
        steps_done, reward_total, undelayed_total = 0, 0.0, 0.0
        while steps_done < n_steps:
            length = min(chunk, n_steps - steps_done, next_log - steps_done)
            out = run.run(
                self._q, self._v_max, self._v_cell, length, start_timesteps + steps_done,
                self._alpha, self.gamma, self.exploration_initial_eps,
                self.exploration_final_eps, eps_steps,
            )  # fmt: skip
            self.num_timesteps += length
            self._record_fused_chunk(out, log, steps_done)
            steps_done += length
            reward_total += float(out["reward"].sum())
            undelayed_total += float(out["undelayed_reward"].sum())
            # ε as the Python loop leaves it: the value used at the chunk's last step
            self._progress_remaining = 1.0 - (self.num_timesteps - 1) / total_timesteps
            self.exploration_rate = self.exploration_schedule(self._progress_remaining)
            if callback is not None and not self._replay_callback(
                callback, locals_, out, run.state[0], self.num_timesteps - length
            ):
                break
            if steps_done == next_log:
                next_log += log_interval
                self._log_metrics(reward_total, undelayed_total)
                reward_total = undelayed_total = 0.0
        self._episode_open = False  # the env object was not stepped: reset it next time
        return steps_done, reward_total, undelayed_total

    def _replay_callback(
        self, callback: Any, locals_: dict[str, Any], out: dict, last_obs: int, start: int
    ) -> bool:
        """Call ``callback.on_step()`` once per step of a compiled chunk, with that step's locals.

        The chunk has already been learned: a callback sees the Q-table of the chunk's end, and
        a ``False`` from it stops training at the chunk's end.
        """
        o0, a0 = self._obs_start, self._action_start
        obs = (out["obs"] + o0).tolist()
        next_obs = [*obs[1:], int(last_obs) + o0]
        actions = (out["action"] + a0).tolist()
        rewards, undelayed = out["reward"].tolist(), out["undelayed_reward"].tolist()
        ends, terminals = out["episode_end"].tolist(), out["terminated"].tolist()
        models = out["model"].tolist()
        end = self.num_timesteps
        keep_going = True
        for i, action in enumerate(actions):
            self.num_timesteps = start + i + 1
            info: dict[str, Any] = {"undelayed_reward": undelayed[i]}
            locals_.update(
                obs=obs[i], action=action, reward=rewards[i], undelayed_reward=undelayed[i],
                terminated=terminals[i], truncated=ends[i] and not terminals[i], info=info,
                acting_delay_index=models[i], new_obs=np.array([next_obs[i]]),
                actions=np.array([action]), rewards=np.array([rewards[i]]),
                dones=np.array([ends[i]]), infos=[info],
            )  # fmt: skip
            callback.update_locals(locals_)
            if not callback.on_step():
                keep_going = False
                break
        self.num_timesteps = end
        return keep_going

    def _record_fused_chunk(self, out: dict, log: dict[str, np.ndarray], offset: int) -> None:
        """Book-keep a compiled chunk: acting counts, episode statistics, the optional record."""
        counts = np.bincount(out["model"], minlength=len(self._acting_counts))
        self._acting_counts = [a + int(b) for a, b in zip(self._acting_counts, counts, strict=True)]
        ends = np.flatnonzero(out["episode_end"])
        rewards = out["undelayed_reward"]
        previous = 0
        for end in ends.tolist():
            self._episode_rewards.append(
                self._episode_reward + float(rewards[previous : end + 1].sum())
            )
            self._episode_lengths.append(self._episode_length + end + 1 - previous)
            self._episode_reward, self._episode_length = 0.0, 0
            self._episodes += 1
            previous = end + 1
        self._episode_reward += float(rewards[previous:].sum())
        self._episode_length += rewards.size - previous
        if log:
            stop = offset + rewards.size
            log["obs"][offset:stop] = out["obs"] + self._obs_start
            log["action"][offset:stop] = out["action"] + self._action_start
            log["reward"][offset:stop] = out["reward"]
            log["undelayed_reward"][offset:stop] = rewards
            log["acting_delay_index"][offset:stop] = out["model"]
            log["done"][offset:stop] = out["episode_end"]

    def _reset_statistics(self) -> None:
        self._acting_counts = [0] * self._n_models_for_stats()
        self._episode_rewards: deque[float] = deque(maxlen=100)
        self._episode_lengths: deque[int] = deque(maxlen=100)
        self._episodes = 0
        self._log_start = (time.perf_counter(), self.num_timesteps)
        self._log_counts = list(self._acting_counts)

    def _n_models_for_stats(self) -> int:
        return 1

    def _log_metrics(self, reward_total: float, undelayed_total: float) -> None:
        """Record the metrics of the steps since the last log, then dump."""
        start_time, start_steps = self._log_start
        now = time.perf_counter()
        steps = self.num_timesteps - start_steps
        logger = self.logger
        logger.record("time/total_timesteps", self.num_timesteps, exclude="tensorboard")
        logger.record("time/episodes", self._episodes)
        logger.record("time/fps", int(steps / max(now - start_time, 1e-9)))
        if steps:
            logger.record("rollout/reward_per_step", reward_total / steps)
            logger.record("rollout/undelayed_reward_per_step", undelayed_total / steps)
        if self._episode_rewards:
            logger.record("rollout/ep_rew_mean", float(np.mean(self._episode_rewards)))
            logger.record("rollout/ep_len_mean", float(np.mean(self._episode_lengths)))
        logger.record("rollout/exploration_rate", self.exploration_rate)
        logger.record("train/learning_rate", self._alpha)
        self._record_model_metrics(logger)
        logger.dump(self.num_timesteps)
        self._log_start = (now, self.num_timesteps)

    def _record_model_metrics(self, logger: Any) -> None:
        """Record algorithm-specific metrics (subclasses)."""

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | Path) -> Path:
        """Save the agent to a ``.npz`` file (arrays plus JSON metadata, no pickles).

        ``path`` is used as given when it has a suffix (SB3's ``CheckpointCallback`` passes
        ``.zip`` names: the file is still an ``.npz`` archive); otherwise ``.npz`` is appended.

        Returns:
            The path written.
        """
        from delayed_rl.agents.serialization import save_agent

        return save_agent(self, path)

    @classmethod
    def load(
        cls,
        path: str | Path,
        env: gym.Env | str | None = None,
        custom_objects: dict[str, Any] | None = None,
    ) -> Any:
        """Load an agent that :meth:`save` wrote.

        Args:
            path: the file (``.npz`` is tried when the path as given does not exist).
            env: the env to train on next (its spaces must match the saved ones); ``None``
                gives an agent that can predict and be given an env later with ``set_env``.
            custom_objects: constructor arguments to override, e.g. a ``learning_rate``
                schedule (a saved callable schedule comes back as a constant at its saved value).

        Raises:
            FileNotFoundError: there is no such file.
            ValueError: the file is corrupt, not a delayed-rl agent, holds another class, or
                ``env``'s spaces do not match (the message says which).
        """
        from delayed_rl.agents.serialization import load_agent

        return load_agent(path, env=env, custom_objects=custom_objects, expected_cls=cls)

    def _get_state_arrays(self) -> dict[str, np.ndarray]:
        """The learned arrays to save (subclasses)."""
        raise NotImplementedError

    def _set_state_arrays(self, arrays: dict[str, np.ndarray], where: str) -> None:
        """Restore the learned arrays (subclasses); ``where`` names the file for errors."""
        raise NotImplementedError


_RECORD_DTYPES = {
    "obs": np.int64,
    "action": np.int64,
    "reward": np.float64,
    "undelayed_reward": np.float64,
    "acting_delay_index": np.int64,
    "done": np.bool_,
}
