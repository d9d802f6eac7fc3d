"""The stable-baselines3-like shell shared by the tabular agents.

:class:`TabularAgent` owns everything that is not the learning rule: the env, argument checks,
:meth:`~TabularAgent.learn` with SB3's callback protocol, logger and progress bar,
:meth:`~TabularAgent.predict`, and model files; :func:`load_agent` loads any agent, whatever its
class. What a subclass supplies (its learning rule, in a few methods) is on the docs' agents
page (``docs/agents.md``, "Writing your own agent").
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from delayed_rl._validation import check_bool
from delayed_rl.agents.common import persistence
from delayed_rl.agents.common.compiled_loop import (
    CompiledTables,
    check_compiled,
    compiled_loop,
    compiled_run,
)
from delayed_rl.agents.common.env_util import (
    SpaceIndex,
    check_discrete,
    check_spaces_match,
    make_env,
    vec_env_view,
)
from delayed_rl.agents.common.hyperparameters import (
    HYPERPARAMETER_NAMES,
    check_hyperparameters,
    check_value,
    shares_hyperparameters,
    with_defaults,
)
from delayed_rl.agents.common.logger import Logger
from delayed_rl.agents.common.python_loop import (
    RECORD_DTYPES,
    finish_learn,
    python_loop,
    setup_learn,
)
from delayed_rl.agents.common.schedules import (
    ConstantSchedule,
    LinearSchedule,
    check_schedule_value,
    schedule_to_json,
)
from delayed_rl.agents.common.statistics import TrainingStatistics
from delayed_rl.agents.common.streams import PREDICT_STREAM, UniformStream

__all__ = ["RECORD_KEYS", "TabularAgent", "load_agent"]

RECORD_KEYS = tuple(RECORD_DTYPES)
"""The arrays of ``agent.training_log`` after ``learn(..., record=True)``."""


class TabularAgent(persistence.CopyProtocol, ABC):
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
        q_init: the initial value of every Q-table entry (optimistic when above the values),
            within ±:data:`~delayed_rl.agents.common.hyperparameters.MAX_ABS_VALUE` (2**200).
        seed: seeds the agent's random choices and the env's first reset after it is set
            (``None``, or an integer in ``[0, MAX_SEED_VALUE]``, ``MAX_SEED_VALUE = 2**63 - 1``).
        verbose: 0 silent, 1 prints the logged metrics at every dump.

    Attributes:
        env: the ``gymnasium.Env`` the agent trains on (``None`` after ``load`` without env).
        num_timesteps: learning steps taken (by ``learn()`` and ``update()``).
        exploration_rate: the current ε.
        training_log: after ``learn(..., record=True)``, one array per step for each key of
            :data:`RECORD_KEYS`.
        last_learn_path: ``"compiled"`` or ``"python"``: the loop the last ``learn()`` ran on.

    ``copy.deepcopy`` and ``pickle`` give an independent agent that resumes exactly (own tables,
    streams, env, compiled run); what cannot be copied is dropped: an env (with a warning: call
    ``set_env``), the compiled run (a new one starts), a logger (a default one replaces it).
    ``copy.copy`` shares everything, tables and env included: train only one of the two.

    Example:
        >>> from delayed_rl.agents import QLearning
        >>> agent = QLearning("delayed_rl/GridWorld-3x3-v0", seed=0)  # a concrete TabularAgent
        >>> agent.learn(total_timesteps=500).num_timesteps
        500
        >>> agent.update(0, 1, 0.0, 1)  # a step of your own loop: obs, action, reward, next obs
        >>> agent.num_timesteps
        501
        >>> actions, _ = agent.predict([0, 4, 8], deterministic=True)  # SB3's predict, on a batch
        >>> actions.shape
        (3,)
    """

    _hyperparameter_names: ClassVar[tuple[str, ...]] = HYPERPARAMETER_NAMES
    _optional_hyperparameter_names: ClassVar[tuple[str, ...]] = ()
    """Those a model file may lack (added since files were first written): their defaults apply."""
    n_models: int = 1
    """How many delay models the agent acts from (|Λ|; 1 for a single Q-table)."""
    compiled_chunk: int = 1_000
    """Steps per compiled call when callbacks are attached (they are called between calls)."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        persistence.AGENT_CLASSES[persistence.class_key(cls)] = cls

    @shares_hyperparameters
    def __init__(self, env: gym.Env | str, **hyperparameters: Any):
        self._set_hyperparameters(**with_defaults(type(self).__name__, hyperparameters))
        env = make_env(env)
        self._set_spaces(env.observation_space, env.action_space)
        self._setup_model()
        self._statistics = TrainingStatistics(self.n_models, self.num_timesteps)
        self.set_env(env)

    # ------------------------------------------------------------------ construction
    def _set_hyperparameters(self, **hyperparameters: Any) -> None:
        """Check and set the constructor's hyper-parameters; reset the clocks and streams."""
        vars(self).update(check_hyperparameters(**hyperparameters))
        self._lr_constant = isinstance(self.lr_schedule, ConstantSchedule)
        self.exploration_schedule = LinearSchedule(
            self.exploration_initial_eps, self.exploration_final_eps, self.exploration_fraction
        )
        self._progress_remaining = 1.0
        self._alpha = self._current_learning_rate()
        self.exploration_rate = self.exploration_schedule(1.0)
        self.num_timesteps = 0
        self._logger: Any = None
        self._compiled: Any = None
        self.training_log: dict[str, np.ndarray] = {}
        self._uniform = UniformStream.from_seed(self.seed)
        self._predict_uniform = UniformStream.from_seed(self.seed, (PREDICT_STREAM,))

    def _set_spaces(self, observation_space: Any, action_space: Any) -> None:
        self.observation_space = check_discrete(observation_space, "observation_space")
        self.action_space = check_discrete(action_space, "action_space")
        self._obs_index = SpaceIndex(self.observation_space)
        self._action_index = SpaceIndex(self.action_space)
        self.n_states = self._obs_index.n
        self.n_actions = self._action_index.n

    def _get_hyperparameters(self) -> dict[str, Any]:
        """The constructor arguments, JSON-ready (the learning rate as a schedule description)."""
        params = {name: getattr(self, name) for name in self._hyperparameter_names}
        params["learning_rate"] = schedule_to_json(self.lr_schedule, self._alpha)
        return params

    # ------------------------------------------------------------------ the learning rule
    @abstractmethod
    def _setup_model(self) -> None: ...
    @abstractmethod
    def _choose(self, s: int, eps: float, uniform: Callable[[], float]) -> tuple[int, int]: ...
    @abstractmethod
    def _learn_transition(
        self, s: int, a: int, r: float, s2: int, terminated: bool, truncated: bool
    ) -> None: ...
    @abstractmethod
    def _greedy_actions(self, states: np.ndarray) -> np.ndarray: ...
    def _end_episode(self) -> None:
        """Forget the rule's own history of the episode that ended (none by default).

        Called when an episode ends: by ``learn()`` as it resets the env, by :meth:`update`
        after a terminated or truncated step, and by :meth:`set_env`.
        """

    def _before_update(self, info: Mapping[str, Any] | None) -> None:
        """Prepare the rule for a transition given to :meth:`update`, with its ``info``.

        Nothing by default: the step's ``info`` is for a rule that learns from it.
        """

    @abstractmethod
    def _get_state_arrays(self) -> dict[str, np.ndarray]: ...
    @abstractmethod
    def _set_state_arrays(self, arrays: dict[str, np.ndarray], where: str) -> None: ...

    def compiled_tables(self) -> CompiledTables | None:
        """The arrays the compiled path trains in place, or ``None`` (no compiled twin).

        An agent whose rule is MMQ's (any Λ) returns its own Q-table, its cache and Λ; the
        compiled loop (:mod:`delayed_rl.compiled`) then runs the same rule on them. The default,
        ``None``, keeps ``learn()`` on the Python path.
        """
        return None

    # ------------------------------------------------------------------ env
    def get_env(self) -> Any:
        """The training env as a one-env SB3 ``VecEnv`` (as SB3's ``get_env()``), or ``None``.

        See :func:`~delayed_rl.agents.common.env_util.vec_env_view`. The agent steps :attr:`env`
        itself; do not step this view during ``learn()``.
        """
        if self.env is not None and self._vec_env is None:
            self._vec_env = vec_env_view(self.env)
        return None if self.env is None else self._vec_env

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
        self.env = check_spaces_match(make_env(env), self.observation_space, self.action_space)
        self._vec_env = None
        self._compiled = None  # a compiled run belongs to the episode it was in
        self._env_seeded = False
        self._episode_ended = True
        #: A compiled run left the env mid-episode (see ``_compiled._leave_compiled_episode``).
        self._compiled_episode = False
        self._episode_step = 0
        self._end_episode()

    def _reset_env(self) -> int:
        seed = None if self._env_seeded else self.seed
        self._env_seeded = True
        obs, _ = self.env.reset(seed=seed)
        self._episode_step = 0
        self._end_episode()
        self._episode_ended = False
        self._compiled_episode = False
        self._statistics.start_episode()
        return self._obs_index.index(obs, "the env's reset() observation")

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

    def _record_model_metrics(self, logger: Any) -> None:
        """Record algorithm-specific metrics (subclasses; none here)."""
        return None

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
        index, single = self._obs_index.indices(observation, "observation")
        flat = index.reshape(-1)
        if deterministic:
            actions = self._greedy_actions(flat)
        else:
            eps, uniform = self.exploration_rate, self._predict_uniform
            actions = np.fromiter(
                (self._choose(int(s), eps, uniform)[1] for s in flat),
                dtype=np.int64,
                count=flat.size,
            )
        actions = actions + self._action_index.start
        return (int(actions[0]), None) if single else (actions, None)

    # ------------------------------------------------------------------ learning
    def update(
        self,
        obs: Any,
        action: Any,
        reward: float,
        next_obs: Any,
        terminated: bool = False,
        truncated: bool = False,
        info: Mapping[str, Any] | None = None,
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
            info: the step's ``info``, as ``env.step`` returned it. A rule that learns from it
                reads it (:class:`~delayed_rl.agents.OracleQLearning` needs its
                ``"reward_arrivals"``); the others ignore it.

        Raises:
            TypeError: an argument has the wrong type (``obs``, ``action`` and ``next_obs``
                must each be one integer, or a 0-d integer array: a batch is refused).
            ValueError: an argument is outside its space, or the reward is not finite or above
                :data:`~delayed_rl.agents.common.hyperparameters.MAX_ABS_VALUE` in magnitude.
                A rule that reads ``info`` may refuse it too (the oracle's class docstring
                says how).
        """
        s = self._obs_index.index(obs, "obs")
        s2 = self._obs_index.index(next_obs, "next_obs")
        a = self._action_index.index(action, "action")
        r = check_value("reward", reward)
        ended = check_bool("terminated", terminated), check_bool("truncated", truncated)
        self._before_update(info)
        self._learn_transition(s, a, r, s2, *ended)
        self.num_timesteps += 1
        if ended[0] or ended[1]:  # as learn() at the env's reset
            self._episode_step = 0
            self._end_episode()
        else:
            self._episode_step += 1

    def learn(
        self,
        total_timesteps: int,
        callback: Any = None,
        log_interval: int | None = 10_000,
        tb_log_name: str = "run",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
        record: bool = False,
        compiled: bool | None = None,
    ) -> TabularAgent:
        """Train for ``total_timesteps`` steps of the env (SB3's signature and semantics).

        Each step acts, steps the env and learns at once, so continuing envs work; an episode's
        end resets the env and clears the history. ``reset_num_timesteps=False`` continues the
        step count, the schedules' clock and the current episode of the previous ``learn()``
        (after ``load`` or ``set_env``, the env is reset).

        Args:
            total_timesteps: how many env steps to take (``reset_num_timesteps=False``: more);
                at most :data:`~delayed_rl.agents.common.python_loop.MAX_TIMESTEPS` (2**40), and with
                ``reset_num_timesteps=False`` the step count may not pass it either; with
                ``record=True``, at most what
                :data:`~delayed_rl.agents.common.python_loop.MAX_RECORD_BYTES` holds (41 bytes a step).
            callback: ``None``, a stable-baselines3 callback (``EvalCallback``,
                ``CheckpointCallback``, ``StopTrainingOnMaxEpisodes``, ``CallbackList``, ...), a
                :mod:`delayed_rl.agents.common.callbacks` callback, a callable
                ``fn(locals_, globals_) -> bool`` (``False`` stops training), or a list of these.
            log_interval: record and dump metrics every this many *steps* (episodes may never
                end in a continuing task); ``None`` logs only at the end.
            tb_log_name: the run's name, passed to callbacks as SB3 does (unused otherwise).
            reset_num_timesteps: see above.
            progress_bar: show a progress bar (tqdm's when installed, else a text bar).
            record: fill :attr:`training_log` with one entry per step: ``obs``, ``action``,
                ``reward`` (received), ``undelayed_reward`` (a reward-delay wrapper's
                ``info["undelayed_reward"]``, else the reward), ``acting_delay_index`` (into
                ``delay_estimates``) and ``episode_end``.
            compiled: run the whole loop compiled (:mod:`delayed_rl.compiled`, which says what
                compiles and how callbacks see a compiled run): ``None`` (default) does when it
                can — the agent has :meth:`compiled_tables`, the env stack compiles, the
                learning rate is constant and no ``callback`` is given (``progress_bar`` is
                fine); ``False`` never does; ``True`` must (raises
                :class:`~delayed_rl.compiled.NotCompilable` with the reason otherwise). Both paths
                apply the same update rule; their random streams differ, so seeded runs agree
                in distribution, not step by step.

        Returns:
            The agent itself.

        Raises:
            TypeError: an argument has the wrong type.
            ValueError: a bad value, or the agent has no env.
        """
        compiled = check_compiled(compiled, callback)
        run = setup_learn(
            self,
            total_timesteps,
            callback,
            log_interval,
            tb_log_name,
            reset_num_timesteps,
            progress_bar,
            record,
        )
        prepared = compiled_run(self, compiled, reset_num_timesteps)
        self.last_learn_path = "python" if prepared is None else "compiled"
        if prepared is None:
            python_loop(self, run)
        else:
            compiled_loop(self, prepared, run)
        finish_learn(self, run)
        return self

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | Path) -> Path:
        """Save the agent to a ``.npz`` file (arrays plus JSON metadata, no pickles).

        ``path`` is used as given when it has a suffix (SB3's ``CheckpointCallback`` passes
        ``.zip`` names: the file is still an ``.npz`` archive); otherwise ``.npz`` is appended
        (``load`` finds it by either name). The file holds the learned arrays, the acting counts,
        both random streams and the training clock, so a loaded agent resumes exactly. Returns
        the path written.

        Raises:
            TypeError: ``path`` is not a ``str`` or ``os.PathLike``.
            ValueError: ``path`` has no file name (``""``, ``"."``), or the file would pass
                ``save_util.MAX_MODEL_BYTES``.
        """
        return persistence.save(self, path)

    @classmethod
    def load(
        cls,
        path: str | Path,
        env: gym.Env | str | None = None,
        custom_objects: dict[str, Any] | None = None,
    ) -> Any:
        """Load an agent that :meth:`save` wrote, as the class that saved it.

        Args:
            path: the file: as given, else with ``.npz`` or ``.zip`` appended, else with its
                ``.zip``/``.npz`` suffix swapped (``load("best_model.zip")`` finds the
                ``best_model.npz`` that SB3's ``EvalCallback`` had this agent write).
            env: the env to train on next (its spaces must match the saved ones); ``None``
                gives an agent that can predict and be given an env later with ``set_env``.
            custom_objects: constructor arguments to override, e.g. a ``learning_rate``
                schedule (a saved callable schedule comes back as a constant at its saved value).

        Every field is checked as the constructor checks it (the hyper-parameters are given
        to the class's own checks, limits included), the arrays' headers against the shapes
        and dtypes the agent's tables have before anything is allocated or read, and each
        array's values against their ranges (tables within ±``MAX_ABS_VALUE``, clocks and
        counters within theirs, pmfs on the simplex): see each class's ``_set_state_arrays``.

        Raises:
            TypeError: ``path`` is not a ``str`` or ``os.PathLike``.
            FileNotFoundError: there is no such file.
            ValueError: ``path`` has no file name (``""``, ``"."``), or the file is corrupt
                (one message names the file and the field), too large (``save_util``'s
                ``MAX_MODEL_BYTES``), holds a class that is not ``cls`` or a subclass of it (or
                is not defined in this process: import its module first), or ``env``'s spaces
                do not match (the message says which).
        """
        return persistence.load_as(cls, path, custom_objects, env)


load_agent = TabularAgent.load
"""Load an agent that ``save`` wrote, whatever its class: ``TabularAgent.load``."""
