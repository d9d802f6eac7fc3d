"""The compiled step loop of :meth:`~delayed_rl.agents.common.base.TabularAgent.learn`.

An agent whose learning rule has a compiled twin says so through
:meth:`~delayed_rl.agents.common.base.TabularAgent.compiled_tables`, which returns the arrays the
compiled path trains in place (:class:`CompiledTables`); the shell never reaches into an agent's
internals. :func:`compiled_run` builds (or continues) the :class:`~delayed_rl.compiled.CompiledRun` of
the agent's env, and :func:`compiled_loop` runs a ``learn()`` call's steps on it, chunk by chunk,
replaying each chunk's steps to the callbacks.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from delayed_rl._validation import check_bool
from delayed_rl.agents.common.python_loop import LearnRun, step_locals

__all__ = ["MAX_CHUNK", "CompiledTables", "check_compiled", "compiled_loop", "compiled_run"]

MAX_CHUNK = 1 << 16
"""The most steps one compiled call takes: its step log (42 bytes a step) stays a few MiB
however long ``learn()`` runs. A seeded run does not depend on the chunking."""


class CompiledTables(NamedTuple):
    """What the compiled path needs from an agent: its Q-table, the table's cache and Λ.

    The compiled code updates ``q``, ``v_max`` and ``v_cell`` in place, so they must be the
    agent's own arrays, not copies. :func:`compiled_loop` asks for them again before each chunk.

    Attributes:
        q: the Q-values, a C-contiguous ``float64`` array of shape (|S|, |Λ|, |A|).
        v_max: each state's max over (λ̂, a) of ``q[s]``.
        v_cell: the flat index into ``q`` of an entry holding that max.
        delay_estimates: Λ, sorted ascending (``int64``).
        reward_model: learn from estimated mean rewards, fed the steps
            (:class:`~delayed_rl.compiled.state.RewardEstimates`); ``None``: the delivered rewards.
        chunk_limit: the most steps the next chunk may take (``None``: no limit).
        after_chunk: called with each chunk's length once it has run (``None``: nothing).
        credit_kernel: MMQ's reward kernel, a weight per distance ``|λ̂ − λ̂*|`` in steps
            (:func:`~delayed_rl.compiled.state.credit_kernel`); ``None``: off.
        trace_decay: β of MMQ's delay trace; ``None``: off.
        trace: the delay trace (one float64 per model, the agent's own: updated in place);
            read only with ``trace_decay``.
        lag_rates: the learning rate of each of Λ's lags when they all update one table
            (expected credit); ``None``: one table per lag, each learning at α.
        held_transitions: the oracle's history length: the run credits each transition with
            its own reward (:mod:`delayed_rl.compiled.arrivals`); ``None``: the delivered rewards.
        average: a moving average of ``q`` the run keeps up to date, step by step
            (:class:`~delayed_rl.compiled.state.TableAverage`: MMQ's greedy window); ``None``:
            none.
    """

    q: np.ndarray
    v_max: np.ndarray
    v_cell: np.ndarray
    delay_estimates: np.ndarray
    reward_model: Any = None
    chunk_limit: int | None = None
    after_chunk: Callable[[int], None] | None = None
    credit_kernel: np.ndarray | None = None
    trace_decay: float | None = None
    trace: np.ndarray | None = None
    lag_rates: np.ndarray | None = None
    held_transitions: int | None = None
    average: Any = None


def check_compiled(compiled: Any, callback: Any) -> bool | None:
    """``learn()``'s ``compiled`` checked; ``None`` (automatic) becomes ``False`` with a callback.

    Callbacks see the exact per-step model on the Python path, so the automatic choice takes it.

    Raises:
        TypeError: ``compiled`` is neither ``None`` nor a bool.
    """
    if compiled is not None:
        return check_bool("compiled", compiled)
    return False if callback is not None else None


def compiled_run(agent: Any, compiled: bool | None, restart: bool) -> Any:
    """The compiled run to train with, or ``None`` for the Python loop (see ``learn``).

    A run continues (same episode, history and pending rewards) across ``learn()`` calls
    with ``reset_num_timesteps=False`` on the same env; otherwise a new one starts, seeded
    from the agent's own generator (so seeded agents are reproducible). A run that steps its
    env (the e-puck) also starts anew when the env was reset since (``set_env``), and a new
    one starts from a fresh episode: one the Python loop left open is reset first (its delay
    wrapper then warns of the pending rewards it discards).

    Raises:
        NotCompilable: ``compiled=True`` and the run cannot be compiled (the message says why).
    """
    if compiled is False:
        _leave_compiled_episode(agent)
        return None
    from delayed_rl.compiled import CompiledRun, NotCompilable
    from delayed_rl.compiled.robot import linked

    try:
        if not agent._lr_constant:
            raise NotCompilable("the learning rate is a schedule (only a constant compiles)")
        tables = agent.compiled_tables()
        if tables is None:
            raise NotCompilable(f"{type(agent).__name__} has no compiled learning rule")
        cached = agent._compiled
        stepped = linked(agent.env.unwrapped)  # the run steps the env itself (the e-puck)
        moved = stepped and not agent._compiled_episode  # the env is not where a run left it
        if cached is None or cached[0] is not agent.env or restart or moved:
            if moved and agent.env.unwrapped._steps:  # the Python loop left it mid-episode:
                agent._obs = agent._reset_env()  # its delay wrapper says what the reset discards
            seed = int(agent._uniform.rng.integers(2**63))
            compiled_run = CompiledRun(
                agent.env, tables.delay_estimates, seed, held_transitions=tables.held_transitions
            )
            agent._compiled = (agent.env, compiled_run)
        return agent._compiled[1]
    except NotCompilable:
        if compiled:
            agent._compiled = None
            raise
        _leave_compiled_episode(agent)
        return None


def _leave_compiled_episode(agent: Any) -> None:
    """Go to the Python loop: an episode a compiled run left open on the env starts afresh.

    A compiled run that steps its env (the e-puck) leaves the env mid-episode, but its pending
    rewards are in the run, not in the env's delay wrapper: the Python loop resets the env, as
    it does after a compiled run on a tabular env (whose env object was not stepped at all).
    """
    if agent._compiled_episode:
        agent._obs = agent._reset_env()
    agent._compiled = None


def compiled_loop(agent: Any, compiled_run: Any, run: LearnRun) -> None:
    """Take ``run.n_steps`` steps on the compiled path, in chunks between callbacks and logs.

    Should a chunk or a callback raise (``KeyboardInterrupt`` included), the run is dropped and
    the next ``learn()`` starts a new one on a reset env: a chunk cut short leaves the run's
    state and the agent's tables out of step with each other.
    """
    try:
        _compiled_chunks(agent, compiled_run, run)
    except BaseException:
        agent._compiled = None
        agent._episode_ended = True
        agent._compiled_episode = False
        raise
    if compiled_run.robot is None:
        agent._episode_ended = True  # the env object was not stepped: reset it next time
    else:  # the run stepped the env: a compiled continuation goes on from where it is
        agent._episode_ended = False
        agent._compiled_episode = True
        agent._obs = int(compiled_run.state[0])


def _compiled_chunks(agent: Any, compiled_run: Any, run: LearnRun) -> None:
    eps_steps = max(1, round(agent.exploration_fraction * run.total_timesteps))
    if agent.exploration_initial_eps == agent.exploration_final_eps:
        eps_steps = 1
    chunk = agent.compiled_chunk if run.callback is not None else MAX_CHUNK
    if run.log_interval is not None:
        chunk = min(chunk, run.log_interval)
    while run.steps_done < run.n_steps:
        tables = agent.compiled_tables()
        length = min(chunk, run.n_steps - run.steps_done, run.next_log - run.steps_done)
        if tables.chunk_limit is not None:
            length = min(length, tables.chunk_limit)
        out = compiled_run.run(
            tables.q,
            tables.v_max,
            tables.v_cell,
            length,
            start_step=run.start_timesteps + run.steps_done,
            learning_rate=agent._alpha,
            gamma=agent.gamma,
            eps_initial=agent.exploration_initial_eps,
            eps_final=agent.exploration_final_eps,
            eps_steps=eps_steps,
            reward_model=tables.reward_model,
            credit_kernel=tables.credit_kernel,
            trace_decay=tables.trace_decay,
            trace=tables.trace,
            lag_rates=tables.lag_rates,
            average=tables.average,
        )
        agent.num_timesteps += length
        if tables.after_chunk is not None:
            tables.after_chunk(length)
        _book_chunk(agent, out, run.log, run.steps_done)
        run.steps_done += length
        run.reward_total += float(out.reward.sum())
        run.undelayed_total += float(out.undelayed_reward.sum())
        # ε as the Python loop leaves it: the value used at the chunk's last step
        agent._progress_remaining = 1.0 - (agent.num_timesteps - 1) / run.total_timesteps
        agent.exploration_rate = agent.exploration_schedule(agent._progress_remaining)
        if run.callback is not None and not _replay_to_callback(
            agent, run, out, int(compiled_run.state[0]), agent.num_timesteps - length
        ):
            break
        run.log_if_due(agent)


def _replay_to_callback(agent: Any, run: LearnRun, out: Any, last_obs: int, start: int) -> bool:
    """Call ``callback.on_step()`` once per step of a compiled chunk, with that step's locals.

    The chunk has already been learned: a callback sees the Q-table of the chunk's end, and
    a ``False`` from it stops training at the chunk's end.
    """
    o0, a0 = agent._obs_index.start, agent._action_index.start
    obs = (out.obs + o0).tolist()
    next_obs = [*obs[1:], last_obs + o0]
    actions = (out.action + a0).tolist()
    rewards, undelayed = out.reward.tolist(), out.undelayed_reward.tolist()
    ends, terminals = out.episode_end.tolist(), out.terminated.tolist()
    acting = out.acting_delay_index.tolist()
    end = agent.num_timesteps
    keep_going = True
    for i, action in enumerate(actions):
        agent.num_timesteps = start + i + 1
        info: dict[str, Any] = {"undelayed_reward": undelayed[i]}
        truncated = ends[i] and not terminals[i]
        run.locals_.update(
            step_locals(
                obs[i],
                action,
                rewards[i],
                undelayed[i],
                terminals[i],
                truncated,
                info,
                acting[i],
                next_obs[i],
            )
        )
        run.callback.update_locals(run.locals_)
        if not run.callback.on_step():
            keep_going = False
            break
    agent.num_timesteps = end
    return keep_going


def _book_chunk(agent: Any, out: Any, log: dict[str, np.ndarray], offset: int) -> None:
    """Book-keep a compiled chunk: acting counts, episode statistics, the optional record."""
    agent._statistics.add_chunk(out.acting_delay_index, out.undelayed_reward, out.episode_end)
    if log:
        stop = offset + out.reward.size
        log["obs"][offset:stop] = out.obs + agent._obs_index.start
        log["action"][offset:stop] = out.action + agent._action_index.start
        log["reward"][offset:stop] = out.reward
        log["undelayed_reward"][offset:stop] = out.undelayed_reward
        log["acting_delay_index"][offset:stop] = out.acting_delay_index
        log["episode_end"][offset:stop] = out.episode_end
