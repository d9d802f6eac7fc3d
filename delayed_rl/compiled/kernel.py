"""The compiled training loop: env step, reward-delay ring, ε-greedy MMQ choice and update.

One function, :func:`run_chunk`, advances a whole training run by a chunk of steps. All state
(Q-table, cached maxima, history ring, delay ring, clocks) lives in arrays owned by the caller,
so a run proceeds chunk by chunk, with callbacks and the progress bar between chunks. Its
arguments come in named groups (:mod:`delayed_rl.compiled.state`: ``QCache``, ``Rule``, the
env's :class:`~delayed_rl.compiled.tabular.TabularModel`, ``DelayLine``, ``History``,
``StepLog``, ``Script``), which numba compiles as tuples.

The update rule is the one of :mod:`delayed_rl.agents.mmq` (``docs/agents.md`` states it
exactly), options included (the reward kernel and the delay trace, :class:`~delayed_rl.compiled.state.Rule`); the exactness
tests drive both on scripted transitions.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from delayed_rl._numba import HAVE_NUMBA  # noqa: F401  (re-exported: delayed_rl.compiled)
from delayed_rl._numba import jit as _jit
from delayed_rl.compiled.arrivals import end_pending, take_due
from delayed_rl.compiled.arrivals import record as record_arrival
from delayed_rl.compiled.deconvolution_statistics import observe
from delayed_rl.compiled.robot import robot_reset, robot_step
from delayed_rl.compiled.state import (
    CARRY,
    FLUSH,
    DelayLine,
    History,
    QCache,
    RewardEstimates,
    Rule,
    Script,
    StepLog,
    credit_kernel,
)

_MULTIPLIER_5, _MULTIPLIER_9 = np.uint64(5), np.uint64(9)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2**-53: 53 random bits as a float in [0, 1)


@_jit
def _rotl(x, k):
    return (x << np.uint64(k)) | (x >> np.uint64(64 - k))


@_jit
def next_uniform(rng):
    """The next number in [0, 1) of a run's own generator, xoshiro256** (Blackman and Vigna).

    ``rng`` is the generator's state, four ``uint64`` words (not all zero), advanced in place: a
    run owns its generator, so no other run, thread or copy changes what it draws, and copying or
    saving the four words copies or saves the stream.
    """
    s0, s1, s2, s3 = rng[0], rng[1], rng[2], rng[3]
    result = _rotl(s1 * _MULTIPLIER_5, 7) * _MULTIPLIER_9
    t = s1 << np.uint64(17)
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = _rotl(s3, 45)
    rng[0], rng[1], rng[2], rng[3] = s0, s1, s2, s3
    return (result >> np.uint64(11)) * _TO_UNIT


@_jit
def _below(rng, n):
    """A uniform integer in ``0..n−1`` (``int(u·n)``, as the Python path draws)."""
    return int(next_uniform(rng) * n)


def generator_state(seed_sequence: np.random.SeedSequence) -> np.ndarray:
    """A fresh xoshiro256** state (four ``uint64`` words, not all zero) from ``seed_sequence``."""
    state = seed_sequence.generate_state(4, dtype=np.uint64)
    if not state.any():  # the one state the generator cannot leave (probability 2**-256)
        state[0] = 1
    return state


@_jit
def _scan_max(qf, base, size):
    """``(max, first index of the max, number of entries equal to it)`` of ``qf[base:base+size]``.

    One scalar pass: cheaper here than a vectorised max followed by a search for its position.
    """
    best = qf[base]
    first = base
    ties = 1
    for i in range(base + 1, base + size):
        value = qf[i]
        if value > best:
            best = value
            first = i
            ties = 1
        elif value == best:
            ties += 1
    return best, first, ties


@_jit
def _nth_equal(qf, base, size, best, k):
    """The index of the ``k``-th (from 0) entry of ``qf[base:base+size]`` equal to ``best``."""
    for i in range(base, base + size):
        if qf[i] == best:
            if k == 0:
                return i
            k -= 1
    return base


@_jit
def _pick_model(qf, base, n_models, n_actions, best, rng):
    """A uniformly random model among those holding ``best`` somewhere in their row.

    ``qf[base:]`` is the state's rows, model after model (one draw from ``rng``).
    """
    holders = 0
    for m in range(n_models):
        row = base + m * n_actions
        for i in range(row, row + n_actions):
            if qf[i] == best:
                holders += 1
                break
    k = _below(rng, holders)
    for m in range(n_models):
        row = base + m * n_actions
        for i in range(row, row + n_actions):
            if qf[i] == best:
                if k == 0:
                    return m
                k -= 1
                break
    return 0


LANES_FROM = 16
"""Rows at least this long are rescanned in four lanes (:func:`_rescan_lanes`); shorter rows in
one scalar pass (:func:`_rescan_scalar`), which costs less than setting the lanes up."""


@_jit
def _rescan(qf, base, size):
    """``(max, first index of it, entries equal to it, max of the others)`` of a state's row.

    "The others" are every entry but the first holding the max (so with ties, the max itself;
    ``-inf`` for a row of one entry). A max and a count are exact in any order, so both passes
    give the same four numbers (up to the sign of a zero max); a row with NaNs still gets an
    index inside it.
    """
    if size < LANES_FROM:
        return _rescan_scalar(qf, base, size)
    return _rescan_lanes(qf, base, size)


@_jit
def _rescan_scalar(qf, base, size):
    """:func:`_rescan` in one pass that branches on each entry (for short rows)."""
    best = qf[base]
    first = base
    ties = 1
    others = -np.inf
    for k in range(1, size):
        i = base + k
        value = qf[i]
        if value > best:  # the old max becomes one of the others
            others = max(others, best)
            best, first, ties = value, i, 1
        elif value == best:
            ties += 1
            others = value
        else:
            others = max(others, value)
    return best, first, ties, others


@_jit
def _rescan_lanes(qf, base, size):
    """:func:`_rescan` in one branch-free pass in four lanes (for long rows).

    Entry ``i`` goes to lane ``i mod 4`` (the last ``size mod 4`` to lane 0); each lane keeps
    its max, the index of its first holder, how many of its entries equal it and the max of its
    other entries, and the lanes then combine. The row is read through a view with ``range``
    indices, which spares the compiled loop numba's negative-index handling (half the cost of a
    pass).
    """
    row = qf[base : base + size]
    whole = size - size % 4
    b0 = b1 = b2 = b3 = -np.inf  # each lane's max
    o0 = o1 = o2 = o3 = -np.inf  # the max of the lane's entries but its first holder
    i0 = i1 = i2 = i3 = 0  # the lane's first holder
    t0 = t1 = t2 = t3 = 0  # the lane's entries equal to its max
    for i in range(0, whole, 4):
        v0, v1, v2, v3 = row[i], row[i + 1], row[i + 2], row[i + 3]
        o0 = max(o0, min(v0, b0))  # a new max makes the old one an "other"; else v is one
        o1 = max(o1, min(v1, b1))
        o2 = max(o2, min(v2, b2))
        o3 = max(o3, min(v3, b3))
        g0, g1, g2, g3 = v0 > b0, v1 > b1, v2 > b2, v3 > b3
        t0 = 1 if g0 else t0 + (v0 == b0)
        t1 = 1 if g1 else t1 + (v1 == b1)
        t2 = 1 if g2 else t2 + (v2 == b2)
        t3 = 1 if g3 else t3 + (v3 == b3)
        i0 = i if g0 else i0
        i1 = i + 1 if g1 else i1
        i2 = i + 2 if g2 else i2
        i3 = i + 3 if g3 else i3
        b0 = v0 if g0 else b0
        b1 = v1 if g1 else b1
        b2 = v2 if g2 else b2
        b3 = v3 if g3 else b3
    for i in range(whole, size):
        v0 = row[i]
        o0 = max(o0, min(v0, b0))
        g0 = v0 > b0
        t0 = 1 if g0 else t0 + (v0 == b0)
        i0 = i if g0 else i0
        b0 = v0 if g0 else b0
    best = max(max(b0, b1), max(b2, b3))
    first = size  # the first holder: the lowest first index of the lanes holding the max
    lane = 0  # its lane (the tail's entries are lane 0's)
    ties = 0
    if b0 == best:
        first, ties = i0, t0
    if b1 == best:
        ties += t1
        if i1 < first:
            first, lane = i1, 1
    if b2 == best:
        ties += t2
        if i2 < first:
            first, lane = i2, 2
    if b3 == best:
        ties += t3
        if i3 < first:
            first, lane = i3, 3
    if first == size:  # no lane holds it (NaNs): the row's first entry
        first, ties = 0, 1
    if ties > 1:
        return best, base + first, ties, best
    # the holder's lane contributes its others, every other lane its max
    if lane == 0:
        others = max(max(o0, b1), max(b2, b3))
    elif lane == 1:
        others = max(max(b0, o1), max(b2, b3))
    elif lane == 2:
        others = max(max(b0, b1), max(o2, b3))
    else:
        others = max(max(b0, b1), max(b2, o3))
    return best, base + first, 1, others


@_jit
def _prime_cache(qf, v_max, v_cell, row_size, ties, second):
    """Count each state's ties to its cached max and bound the rest (the start of a call).

    ``ties[s]``: how many entries of state ``s``'s row equal ``v_max[s]``; ``second[s]``: the
    max of the row's entries other than ``v_cell[s]``.
    """
    for s in range(v_max.shape[0]):
        ties[s] = 0
        second[s] = -np.inf
        for i in range(s * row_size, (s + 1) * row_size):
            ties[s] += qf[i] == v_max[s]
            if i != v_cell[s] and qf[i] > second[s]:
                second[s] = qf[i]


@_jit
def _write(qf, v_max, v_cell, v_ties, v_second, s, cell, new, row_size):
    """Set ``qf[cell]``, an entry of state ``s``'s row, to ``new``, keeping the cache exact.

    The cache of a state: its max ``v_max``, the flat index ``v_cell`` of an entry holding it, how
    many entries hold it (``v_ties``) and ``v_second``, an upper bound of the other entries (every
    one but ``v_cell``'s; exact after a rescan, raised by each write to them). The row is
    rescanned only when the cached arg-max entry decreases to or below that bound, or while
    tied.
    """
    old = qf[cell]
    qf[cell] = new
    best = v_max[s]
    if new > best:  # a new unique max (a former holder elsewhere joins the others)
        if v_cell[s] != cell and best > v_second[s]:
            v_second[s] = best
        v_max[s] = new
        v_cell[s] = cell
        v_ties[s] = 1
    elif v_cell[s] != cell:  # one of the others
        if new == best:
            v_ties[s] += old != new
        elif old == best:  # an entry holding the max fell
            v_ties[s] -= 1
        if new > v_second[s]:
            v_second[s] = new
    elif new < best:  # the cached arg-max fell: still above the others, else rescan
        if v_ties[s] == 1 and new > v_second[s]:
            v_max[s] = new
        else:
            v_max[s], v_cell[s], v_ties[s], v_second[s] = _rescan(qf, s * row_size, row_size)


def run_chunk(
    cache, rule, env, line, history, log, script, start_step, rng, model, arrivals, average, robot
):
    """Advance training by ``line.delays.shape[0]`` steps.

    One loop, written out: splitting its step into compiled helpers (choose, env step, delay,
    learn) measured slower, even inlined (``benchmarks/SPEED.md``), so the phases are marked by
    comments.

    The MMQ update: at each step, for every model ``j`` whose step ``t − Λ[j]`` is in this
    episode's history, with (s, a, s′, terminated) that step's transition,
    ``target = r_t + γ (1 − terminated) max Q[s′]``, the max over every (λ̂, a′) of ``s′``; all
    TD errors ``target − Q`` of a step are computed before its writes (a parallel update), then
    each entry moves by ``rate · error``, lag after lag. With a Q-table of one model for several
    lags (expected credit, :attr:`~delayed_rl.compiled.state.Rule.lag_rates`) the lags' increments to one entry add up.

    The oracle (``arrivals`` given): instead, the loop records who emitted each reward
    (:mod:`delayed_rl.compiled.arrivals`) and, for every transition whose reward arrives at the step
    (oldest first; all pending ones at a flushing episode end), makes the Q-learning update of
    that transition with its own reward, one after the other, if it is among the
    ``arrivals.held`` most recent.

    The cache (:class:`~delayed_rl.compiled.state.QCache`) is kept exact: a state's row is rescanned only when the cached
    arg-max entry decreases to or below an upper bound of the row's other entries (kept for the
    call, see :func:`_write`), or while it is tied; the acting model is read off ``v_cell``
    unless the max is tied, where choosing costs a scan. Random draws happen exactly where the
    Python path draws: ε tests, uniform choices, and a tie-break only when there is a tie.

    With a ``script`` the steps replay its transitions and received rewards instead of acting in
    the env: :func:`replay` uses it so that tests drive this very loop.

    The optional parts (``script``, ``model``, ``arrivals``, ``average``, ``robot`` and the
    rule's credit options) are ``None`` when absent, and numba compiles the loop once for each
    combination of the parts present, leaving the code of the absent ones out (:func:`_loop`).
    That is faster than one loop testing for each part at every step (``benchmarks/SPEED.md``);
    the price is a first compile (cached on disk as all compiled code here) for each
    combination a machine meets: about one per kind of agent.

    MMQ's credit options (:class:`~delayed_rl.compiled.state.Rule`): the delay trace is decayed and the acting model's entry
    set to 1 at every step, before the step's update; the per-model weight of the reward is
    computed only when an option is on, so the thesis's rule pays nothing for them.

    Args:
        cache: the Q-table, its cache and the delay trace (:class:`~delayed_rl.compiled.state.QCache`), updated in place.
        rule: Λ, α, γ, the ε schedule and the credit options (:class:`~delayed_rl.compiled.state.Rule`).
        env: the env's outcome tables (:class:`~delayed_rl.compiled.tabular.TabularModel`).
        line: the reward delay (:class:`~delayed_rl.compiled.state.DelayLine`).
        history: the episode's transitions and the clocks (:class:`~delayed_rl.compiled.state.History`), updated in place.
        log: receives one entry per step (:class:`~delayed_rl.compiled.state.StepLog`).
        script: transitions to replay (:class:`~delayed_rl.compiled.state.Script`), or ``None``: act in the env.
        start_step: the training step of the chunk's first step (for the ε schedule).
        rng: the run's generator state (:func:`next_uniform`), advanced in place.
        model: a reward model (:class:`~delayed_rl.compiled.state.RewardEstimates`; Λ must then be {0}), or ``None``: learn
            from the delivered rewards.
        arrivals: the oracle's record (:class:`~delayed_rl.compiled.arrivals.Arrivals`, Λ = {0},
            not with a script), or ``None``.
        average: a moving average of the Q-table to keep (:class:`~delayed_rl.compiled.state.TableAverage`), or ``None``.
        robot: the e-puck env to step instead of ``env``'s tables
            (:class:`~delayed_rl.compiled.robot.Robot`, not with a script), or ``None``.

    Indices into the Q-table and its cache are cast to unsigned integers, which spares the
    compiled code numba's negative-index handling in the innermost loops (about 5%).
    """
    _loop(
        cache, rule, env, line, history, log, script, start_step, rng, model, arrivals, average,
        robot, rule.credit_kernel, rule.trace_decay, rule.lag_rates,
    )  # fmt: skip


@_jit
def _loop(
    cache, rule, env, line, history, log, script, start_step, rng, model, arrivals, average,
    robot, kernel_weights, decay, lag_rates,
):  # fmt: skip
    """:func:`run_chunk`'s loop, with the rule's optional parts as arguments of their own.

    numba leaves out the code of an absent part (``None``) only when it is an argument: its
    dead-branch pruning does not see into tuples such as :class:`~delayed_rl.compiled.state.Rule`. :func:`run_chunk` is
    plain Python, called once a chunk: a compiled one would link a copy of each version of the
    loop into its own, doubling what numba compiles and caches.
    """
    estimates = rule.delay_estimates
    alpha, gamma = rule.learning_rate, rule.gamma
    eps_initial, eps_final, eps_steps = rule.eps_initial, rule.eps_final, rule.eps_steps
    q, v_max, v_cell, v_ties, trace = cache.q, cache.v_max, cache.v_cell, cache.ties, cache.trace
    has_kernel = kernel_weights is not None
    has_trace = decay is not None
    weighted = has_kernel or has_trace
    has_rates = lag_rates is not None
    out_cdf, out_next, out_reward = env.out_cdf, env.out_next, env.out_reward
    out_term = env.out_term
    init_cdf, max_steps, cut_steps = env.init_cdf, env.max_steps, env.cut_steps
    delays, ring, episode_end_mode = line.delays, line.ring, line.episode_end_mode
    hist_s, hist_a, hist_s2, hist_term, state = history
    n_lags = estimates.shape[0]
    n_models = q.shape[1]  # one table per lag (MMQ), or one for every lag (expected credit)
    per_lag = n_models == n_lags
    n_actions = q.shape[2]
    row_size = n_models * n_actions
    qf = q.reshape(q.size)  # the Q-table, flat: entry (s, j, a) is qf[(s·|Λ| + j)·|A| + a]
    v_second = np.empty(v_max.shape[0])  # the others' bound (see _write), made afresh each call
    _prime_cache(qf, v_max, v_cell, row_size, v_ties, v_second)
    hmask = hist_s.shape[0] - 1
    bmask = ring.shape[0] - 1
    targets = np.zeros(n_lags)
    states = np.zeros(n_lags, dtype=np.uint64)
    cells = np.zeros(n_lags, dtype=np.uint64)
    s = state[0]
    hist_count = state[1]
    episode_steps = state[2]
    clock = state[3]
    scripted = script is not None
    has_model = model is not None
    oracle = arrivals is not None
    pmask = 0
    if oracle:
        pmask = arrivals.due.shape[0] - 1
    n_arrived = 0
    for t in range(delays.shape[0]):
        if scripted:
            s = script.transitions[t, 0]
            action = script.transitions[t, 1]
            s2 = script.transitions[t, 2]
            terminated = script.terminated[t]
            delivered = script.rewards[t]
            reward = delivered
            acting = 0
            if script.acting.shape[0] > 0:
                acting = script.acting[t]
            elif weighted:  # the greedy model: the lowest index holding the state's max
                first = _scan_max(qf, s * row_size, row_size)[1]
                acting = (first - s * row_size) // n_actions
            ended = terminated
            cut = False
        else:
            step = start_step + t
            if step >= eps_steps:
                eps = eps_final
            else:
                eps = eps_initial + (eps_final - eps_initial) * (step / eps_steps)
            # the acting model, then the action (two ε-greedy levels, random tie-breaks)
            if n_models == 1:
                acting = 0
            elif next_uniform(rng) < eps:
                acting = _below(rng, n_models)
            elif v_ties[s] == 1:  # the one model holding the state's max
                acting = (v_cell[s] // n_actions) % n_models
            else:  # a uniformly random model among those holding it
                acting = _pick_model(qf, s * row_size, n_models, n_actions, v_max[s], rng)
            if next_uniform(rng) < eps:
                action = _below(rng, n_actions)
            else:  # a uniformly random action among the model's best
                row = s * row_size + acting * n_actions
                best, first, ties = _scan_max(qf, row, n_actions)
                if ties > 1:
                    first = _nth_equal(qf, row, n_actions, best, _below(rng, ties))
                action = first - row
            # the env: the robot, or the tables (no draw where the first outcome is certain)
            if robot is not None:  # (pruned when compiling for None: tables only)
                s2, reward, terminated, env_truncated = robot_step(robot, action)
            else:
                k = 0
                if out_cdf[s, action, 0] < 1.0:
                    u = next_uniform(rng)
                    while k < out_cdf.shape[2] - 1 and out_cdf[s, action, k] <= u:
                        k += 1
                s2 = out_next[s, action, k]
                reward = out_reward[s, action, k]
                terminated = out_term[s, action, k]
                env_truncated = False
            episode_steps += 1
            ended = terminated or env_truncated or (max_steps > 0 and episode_steps >= max_steps)
            cut = not ended and cut_steps > 0 and episode_steps >= cut_steps  # unseen by the delay
            # the reward delay: the rule of wrappers.reference.ReferenceRewardDelay, inlined
            due = clock + delays[t]
            ring[due & bmask] += reward
            delivered = ring[clock & bmask]
            ring[clock & bmask] = 0.0
            if oracle:  # record who emitted the reward; collect this step's arrivals
                record_arrival(arrivals, clock, due, s, action, s2, terminated, reward)
                if not (ended and episode_end_mode == FLUSH):
                    n_arrived = take_due(arrivals, clock)
            if (ended or cut) and episode_end_mode != CARRY:
                flush = ended and episode_end_mode == FLUSH
                total = 0.0
                for i in range(ring.shape[0]):
                    total += ring[i]
                    ring[i] = 0.0
                if flush:
                    delivered += total
                elif cut:  # the reset after a cut discards it, as RewardDelay.reset does
                    line.discarded[0] += total
                if oracle:  # flushed: every pending transition arrives now; dropped: none
                    flushed = end_pending(arrivals, clock, flush)
                    if flush:
                        n_arrived = flushed
            ended = ended or cut
            clock += 1
        # record, remember
        log.undelayed_reward[t] = reward
        log.reward[t] = delivered
        log.obs[t] = s
        log.action[t] = action
        log.acting_delay_index[t] = acting
        log.episode_end[t] = ended
        log.terminated[t] = terminated
        pos = hist_count & hmask
        hist_s[pos] = s
        hist_a[pos] = action
        hist_s2[pos] = s2
        hist_term[pos] = terminated
        hist_count += 1
        if has_trace:  # the delay trace: decay every model's, mark the acting model's
            for j in range(n_models):
                trace[j] *= decay
            trace[acting] = 1.0
        if oracle:  # each arriving reward's own transition, oldest first, one by one
            for i in range(n_arrived):
                e = arrivals.order[i]
                if clock - 1 - e >= arrivals.held:
                    continue  # a transition the oracle does not hold
                p = e & pmask
                cell = np.uint64(arrivals.s[p] * row_size + arrivals.a[p])
                bootstrap = 0.0 if arrivals.terminated[p] else gamma * v_max[arrivals.s2[p]]
                old = qf[cell]
                new = old + alpha * (arrivals.value[p] + bootstrap - old)
                sp = np.uint64(arrivals.s[p])
                _write(qf, v_max, v_cell, v_ties, v_second, sp, cell, new, row_size)
            n_lags_now = 0  # (the lags below do not learn)
        else:
            n_lags_now = n_lags
        # learn: every TD error first (each reads the cached max of its next state) ...
        count = n_lags_now  # the lags whose step t − λ̂ is in this episode: a prefix (sorted Λ)
        for j in range(n_lags_now):
            estimate = estimates[j]
            if estimate >= hist_count:
                count = j
                break
            pos = np.uint64((hist_count - 1 - estimate) & hmask)
            bootstrap = 0.0 if hist_term[pos] else gamma * v_max[np.uint64(hist_s2[pos])]
            credited = delivered
            if has_model:  # the estimated mean reward of the pair (Λ = {0}: this step's)
                credited = model.rewards[hist_s[pos] * n_actions + hist_a[pos]]
            elif weighted:  # r_t · kernel(|λ̂ − λ̂*|) · e(λ̂), the options that are on
                weight = 1.0
                if has_kernel:
                    weight = kernel_weights[abs(estimate - estimates[acting])]
                if has_trace:
                    weight *= trace[j]
                credited = delivered * weight
            states[j] = hist_s[pos]
            cells[j] = hist_s[pos] * row_size + (j if per_lag else 0) * n_actions + hist_a[pos]
            targets[j] = credited + bootstrap
            if not per_lag:  # one table: the TD error now, before any write of the step
                targets[j] -= qf[cells[j]]
        # ... then the writes, lag after lag (several lags' increments to one entry add up).
        # This is _write, inlined: the call measured slower in this loop (benchmarks/SPEED.md).
        for j in range(count):
            sj = states[j]
            cell = cells[j]
            old = qf[cell]
            rate = lag_rates[j] if has_rates else alpha
            # one entry per lag: its TD error is the one it had before the step; one table:
            # the error computed before the step's writes
            new = old + rate * (targets[j] - old if per_lag else targets[j])
            qf[cell] = new
            best = v_max[sj]
            if new > best:  # a new unique max (a former holder elsewhere joins the others)
                if v_cell[sj] != cell and best > v_second[sj]:
                    v_second[sj] = best
                v_max[sj] = new
                v_cell[sj] = cell
                v_ties[sj] = 1
            elif v_cell[sj] != cell:  # one of the others
                if new == best:
                    v_ties[sj] += old != new
                elif old == best:  # an entry holding the max fell
                    v_ties[sj] -= 1
                if new > v_second[sj]:
                    v_second[sj] = new
            elif new < best:  # the cached arg-max fell: still above the others, else rescan
                if v_ties[sj] == 1 and new > v_second[sj]:
                    v_max[sj] = new
                else:
                    v_max[sj], v_cell[sj], v_ties[sj], v_second[sj] = _rescan(
                        qf, sj * row_size, row_size
                    )
        if has_model:  # after the update, as the Python path: this step informs the next solve
            observe(model.stats, s * n_actions + action, delivered, ended)
        if average is not None:  # the Q-table's moving average, after the step's update
            average.clock[0] += 1
            if average.clock[0] >= average.every:
                averaged = average.table.reshape(average.table.size)
                if average.clock[1] > 0:  # the expression of the Python path's numpy update
                    for i in range(qf.shape[0]):
                        averaged[i] += average.rate * (qf[i] - averaged[i])
                else:
                    averaged[:] = qf
                average.clock[0] = 0
                average.clock[1] += 1
        if ended:
            if robot is not None:  # the env's own reset
                s = robot_reset(robot)
            elif not scripted:  # the next episode's start (no draw for a certain one)
                s = 0
                if init_cdf[0] < 1.0:
                    u = next_uniform(rng)
                    while s < init_cdf.shape[0] - 1 and init_cdf[s] <= u:
                        s += 1
            hist_count = 0
            episode_steps = 0
        elif not scripted:
            s = s2
    state[0] = s
    state[1] = hist_count
    state[2] = episode_steps
    state[3] = clock


def replay(
    q: np.ndarray,
    delay_estimates: np.ndarray,
    transitions: np.ndarray,
    terminated: np.ndarray,
    rewards: np.ndarray,
    learning_rate: float,
    gamma: float,
    model: RewardEstimates | None = None,
    *,
    reward_kernel: float | None = None,
    delay_trace: float | None = None,
    trace: np.ndarray | None = None,
    acting: np.ndarray | None = None,
) -> None:
    """Apply the MMQ update of :func:`run_chunk` to scripted transitions, in place on ``q``.

    By default, the thesis's rule (every model credited the reward). MMQ's credit options apply
    as the agent's ``reward_kernel`` and ``delay_trace`` do; the acting model of each step is
    ``acting``'s, or else the greedy model of the step's state, as MMQ's ``update()`` takes it.

    Args:
        q: the Q-table, shape (|S|, |Λ|, |A|), updated in place.
        delay_estimates: Λ, sorted ascending.
        transitions: rows ``(s, a, s′)`` in the order they happened (one episode or several:
            a ``terminated`` row ends its episode and clears the history).
        terminated: one flag per row.
        rewards: the reward received at each row's step.
        learning_rate: α.
        gamma: γ.
        model: a reward model whose statistics are fed (and whose rewards are credited), or
            ``None``.
        reward_kernel: σ of the reward kernel (``None``: off).
        delay_trace: β of the delay trace (``None``: off).
        trace: the delay trace to start from, one float64 per model, updated in place
            (``None``: zeros; only read with ``delay_trace``).
        acting: the acting model's index into Λ at each row (``None``: the greedy model).
    """
    from delayed_rl.compiled.tabular import TabularModel

    n = transitions.shape[0]
    estimates = np.asarray(delay_estimates, dtype=np.int64)
    flat = q.reshape(q.shape[0], -1)
    trace, acting = _replay_options(n, estimates.shape[0], delay_trace, trace, acting)
    cache = QCache(
        q,
        flat.max(axis=1),
        np.arange(q.shape[0]) * flat.shape[1] + flat.argmax(axis=1),
        np.zeros(q.shape[0], np.int64),
        None if delay_trace is None else trace,
    )
    rule = Rule(
        estimates,
        float(learning_rate),
        float(gamma),
        0.0,
        0.0,
        1,
        None if reward_kernel is None else credit_kernel(estimates, reward_kernel),
        None if delay_trace is None else float(delay_trace),
    )
    line = DelayLine(np.zeros(n, np.int64), np.zeros(1), FLUSH)
    script = Script(
        np.asarray(transitions, np.int64),
        np.asarray(terminated, np.bool_),
        np.asarray(rewards, np.float64),
        np.zeros(0, np.int64) if acting is None else acting,
    )
    history = History.empty(int(estimates.max()))
    no_draws = np.ones(4, np.uint64)  # a script draws nothing
    run_chunk(
        cache, rule, TabularModel.empty(), line, history, StepLog.empty(n), script, 0, no_draws,
        model, None, None, None,
    )  # fmt: skip


def _replay_options(
    n: int, n_models: int, delay_trace: float | None, trace: Any, acting: Any
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """:func:`replay`'s delay trace (zeros by default) and acting models, checked.

    Raises:
        ValueError: ``trace`` is not float64 of one value per model, or ``acting`` not one
            model index per row.
    """
    if delay_trace is not None and trace is None:
        trace = np.zeros(n_models)
    if trace is not None and (trace.dtype != np.float64 or trace.shape != (n_models,)):
        raise ValueError(f"trace must be a float64 array of shape ({n_models},)")
    if acting is not None:
        acting = np.asarray(acting, np.int64)
        if acting.shape != (n,) or (n and not 0 <= acting.min() <= acting.max() < n_models):
            raise ValueError(f"acting must hold one model index in 0..{n_models - 1} per row")
    return trace, acting
