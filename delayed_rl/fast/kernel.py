"""The compiled training loop: env step, reward-delay buffer, ε-greedy MMQ choice and update.

One function, :func:`run_chunk`, advances a whole training run by a chunk of steps. All state
(Q-table, cached maxima, history ring, delay ring, clocks) lives in arrays owned by the caller,
so a run proceeds chunk by chunk, with callbacks and the progress bar between chunks.

The update rule is the one of :mod:`delayed_rl.agents.mmq` (DESIGN.md, "Multiple Model
Q-learning, exactly"); the exactness tests drive both on scripted transitions.
"""

# ruff: noqa: NPY002  (numba compiles only the legacy np.random API, one generator per thread)
from __future__ import annotations

import numpy as np

try:
    import numba

    HAVE_NUMBA = True
    _jit = numba.njit(cache=True, nogil=True)
except ImportError:  # pragma: no cover - exercised where numba is absent
    HAVE_NUMBA = False

    def _jit(function):
        return function


# Episode-end modes of the reward buffer, as integers for the compiled code.
FLUSH, DROP, CARRY = 0, 1, 2


@_jit
def seed_kernel(seed):
    """Seed the compiled code's own random generator (numba keeps one per thread)."""
    np.random.seed(seed)


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
def _pick_model(qf, base, n_models, n_actions, best):
    """A uniformly random model among those holding ``best`` somewhere in their row.

    ``qf[base:]`` is the state's rows, model after model (one draw).
    """
    holders = 0
    for m in range(n_models):
        row = base + m * n_actions
        for i in range(row, row + n_actions):
            if qf[i] == best:
                holders += 1
                break
    k = np.random.randint(holders)
    for m in range(n_models):
        row = base + m * n_actions
        for i in range(row, row + n_actions):
            if qf[i] == best:
                if k == 0:
                    return m
                k -= 1
                break
    return 0


@_jit
def _count_ties(qf, qmax, row_size, ties):
    """Set ``ties[s]`` to how many entries of state ``s``'s row equal its cached max."""
    for s in range(qmax.shape[0]):
        ties[s] = 0
        for i in range(s * row_size, (s + 1) * row_size):
            ties[s] += qf[i] == qmax[s]


@_jit
def run_chunk(
    q, lags, qmax, qcell, qties,
    out_cdf, out_next, out_reward, out_term, init_cdf, max_steps,
    delays, buffer, episode_end_mode,
    alpha, gamma, eps_initial, eps_final, eps_steps, start_step,
    hist_s, hist_a, hist_s2, hist_term, state,
    rec_undelayed, rec_delivered, rec_obs, rec_action, rec_model, rec_episode_end,
    rec_terminated, script, script_term, script_reward,
):  # fmt: skip
    """Advance training by ``delays.shape[0]`` steps.

    The MMQ update (DESIGN.md, "Multiple Model Q-learning, exactly"): at each step, for every
    model ``m`` whose step ``t − lags[m]`` is in this episode's history, with (s, a, s′, done) that
    step's transition, ``target = r_t + γ (1 − done) max Q[s′]``; all targets of a step are
    computed before its writes. ``lags`` must be sorted ascending (the agents keep Λ sorted).

    The cache is kept exact: ``qmax[s]``, the max of ``q[s]``, with ``qcell[s]`` the flat index
    in ``q`` (the agents' layout) of an entry holding it, and ``qties[s]`` how many entries hold
    it (counted afresh at the start of each call, then kept up to date). A state's row is
    rescanned only when the cached arg-max entry decreases; the acting model is read off
    ``qcell`` unless the max is tied, so ties cost a scan and nothing else does. Random draws
    happen exactly where the Python path draws: ε tests, uniform choices, and a tie-break only
    when there is a tie.

    With a non-empty ``script`` (rows ``(s, a, s′)``, with ``script_term`` and ``script_reward``)
    the steps replay those transitions and received rewards instead of acting in the env:
    :func:`replay` uses it so that tests drive this very loop with scripted transitions.

    ``state`` is an int64 array ``[s, hist_count, episode_steps, clock]`` carried between chunks.
    ``out_*`` are the env's outcome tables of shape (S, A, K): cumulative probabilities, next
    states, rewards, termination flags. ``init_cdf`` is the cumulative initial-state distribution.
    ``buffer`` is the reward-delay ring (power-of-two length above every delay in ``delays``).
    The ``rec_*`` arrays receive one entry per step.

    Indices into the Q-table and its cache are cast to unsigned integers, which spares the
    compiled code numba's negative-index handling in the innermost loops (about 5%).
    """
    n_models = lags.shape[0]
    n_actions = q.shape[2]
    row_size = n_models * n_actions
    qf = q.reshape(q.size)  # the Q-table, flat: entry (s, m, a) is qf[(s·|Λ| + m)·|A| + a]
    _count_ties(qf, qmax, row_size, qties)
    hmask = hist_s.shape[0] - 1
    bmask = buffer.shape[0] - 1
    targets = np.zeros(n_models)
    states = np.zeros(n_models, dtype=np.uint64)
    cells = np.zeros(n_models, dtype=np.uint64)
    s = state[0]
    hist_count = state[1]
    episode_steps = state[2]
    clock = state[3]
    scripted = script.shape[0] > 0
    for t in range(delays.shape[0]):
        if scripted:
            s = script[t, 0]
            action = script[t, 1]
            s2 = script[t, 2]
            terminated = script_term[t]
            delivered = script_reward[t]
            reward = delivered
            m = 0
            ended = terminated
        else:
            step = start_step + t
            if step >= eps_steps:
                eps = eps_final
            else:
                eps = eps_initial + (eps_final - eps_initial) * (step / eps_steps)
            # the acting model, then the action (two ε-greedy levels, random tie-breaks)
            if n_models == 1:
                m = 0
            elif np.random.random() < eps:
                m = np.random.randint(n_models)
            elif qties[s] == 1:  # the one model holding the state's max
                m = (qcell[s] // n_actions) % n_models
            else:  # a uniformly random model among those holding it
                m = _pick_model(qf, s * row_size, n_models, n_actions, qmax[s])
            if np.random.random() < eps:
                action = np.random.randint(n_actions)
            else:  # a uniformly random action among the model's best
                row = s * row_size + m * n_actions
                best, first, ties = _scan_max(qf, row, n_actions)
                if ties > 1:
                    first = _nth_equal(qf, row, n_actions, best, np.random.randint(ties))
                action = first - row
            # the env
            u = np.random.random()
            k = 0
            while k < out_cdf.shape[2] - 1 and out_cdf[s, action, k] <= u:
                k += 1
            s2 = out_next[s, action, k]
            reward = out_reward[s, action, k]
            terminated = out_term[s, action, k]
            episode_steps += 1
            ended = terminated or (max_steps > 0 and episode_steps >= max_steps)
            # the reward delay
            buffer[(clock + delays[t]) & bmask] += reward
            delivered = buffer[clock & bmask]
            buffer[clock & bmask] = 0.0
            clock += 1
            if ended and episode_end_mode != CARRY:
                total = 0.0
                for i in range(buffer.shape[0]):
                    total += buffer[i]
                    buffer[i] = 0.0
                if episode_end_mode == FLUSH:
                    delivered += total
        # record, remember
        rec_undelayed[t] = reward
        rec_delivered[t] = delivered
        rec_obs[t] = s
        rec_action[t] = action
        rec_model[t] = m
        rec_episode_end[t] = ended
        rec_terminated[t] = terminated
        pos = hist_count & hmask
        hist_s[pos] = s
        hist_a[pos] = action
        hist_s2[pos] = s2
        hist_term[pos] = terminated
        hist_count += 1
        # learn: every target first (each reads the cached max of its next state) ...
        count = 0  # the models whose step t − λ̂ is in this episode: a prefix (sorted lags)
        for j in range(n_models):
            lag = lags[j]
            if lag >= hist_count:
                break
            pos = np.uint64((hist_count - 1 - lag) & hmask)
            bootstrap = 0.0 if hist_term[pos] else gamma * qmax[np.uint64(hist_s2[pos])]
            targets[j] = delivered + bootstrap
            states[j] = hist_s[pos]
            cells[j] = hist_s[pos] * row_size + j * n_actions + hist_a[pos]
            count += 1
        for j in range(count):  # ... then the writes, keeping the cache exact
            sj = states[j]
            cell = cells[j]
            old = qf[cell]
            new = old + alpha * (targets[j] - old)
            qf[cell] = new
            if new > qmax[sj]:
                qmax[sj] = new
                qcell[sj] = cell
                qties[sj] = 1
            elif new == qmax[sj]:
                qties[sj] += old != new
            elif old == qmax[sj]:  # an entry holding the max fell
                if qcell[sj] != cell:
                    qties[sj] -= 1
                else:  # the cached arg-max itself: rescan the state's row
                    qmax[sj], qcell[sj], qties[sj] = _scan_max(qf, sj * row_size, row_size)
        if ended:
            if not scripted:
                u = np.random.random()
                s = 0
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
    q: np.ndarray, lags: np.ndarray, transitions: np.ndarray, terminated: np.ndarray,
    rewards: np.ndarray, alpha: float, gamma: float,
) -> None:  # fmt: skip
    """Apply the MMQ update of :func:`run_chunk` to scripted transitions, in place on ``q``.

    Args:
        q: the Q-table, shape (|S|, |Λ|, |A|), updated in place.
        lags: Λ, sorted ascending.
        transitions: rows ``(s, a, s′)`` in the order they happened (one episode or several:
            a ``terminated`` row ends its episode and clears the history).
        terminated: one flag per row.
        rewards: the reward received at each row's step.
        alpha: the learning rate.
        gamma: the discount factor.
    """
    n = transitions.shape[0]
    lags = np.asarray(lags, dtype=np.int64)
    flat = q.reshape(q.shape[0], -1)
    qmax = flat.max(axis=1)
    qcell = np.arange(q.shape[0]) * flat.shape[1] + flat.argmax(axis=1)
    size = 1 << int(lags.max()).bit_length()
    history = [np.zeros(size, np.int64), np.zeros(size, np.int64), np.zeros(size, np.int64),
               np.zeros(size, np.bool_)]  # fmt: skip
    records = [np.zeros(n), np.zeros(n)] + [np.zeros(n, np.int64) for _ in range(3)]
    records += [np.zeros(n, np.bool_), np.zeros(n, np.bool_)]
    none = np.zeros((1, 1, 1))
    run_chunk(
        q, lags, qmax, qcell, np.zeros(q.shape[0], np.int64),
        none, none.astype(np.int64), none, none.astype(np.bool_), np.ones(1), 0,
        np.zeros(n, np.int64), np.zeros(1), FLUSH, alpha, gamma, 0.0, 0.0, 1, 0,
        *history, np.zeros(4, np.int64), *records,
        np.asarray(transitions, np.int64), np.asarray(terminated, np.bool_),
        np.asarray(rewards, np.float64),
    )  # fmt: skip
