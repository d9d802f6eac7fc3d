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
    _jit_inline = numba.njit(cache=True, nogil=True, inline="always")  # no call overhead
except ImportError:  # pragma: no cover - exercised where numba is absent
    HAVE_NUMBA = False

    def _jit(function):
        return function

    _jit_inline = _jit


# Episode-end modes of the reward buffer, as integers for the compiled code.
FLUSH, DROP, CARRY = 0, 1, 2


@_jit
def seed_kernel(seed):
    """Seed the compiled code's own random generator (numba keeps one per thread)."""
    np.random.seed(seed)


def scratch(n_models: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The scratch arrays :func:`apply_update` needs: targets, states and actions per model."""
    return np.zeros(n_models), np.zeros(n_models, np.int64), np.zeros(n_models, np.int64)


@_jit
def model_maxima(q, mmax, marg):
    """Fill ``mmax[s, m]`` = max_a ``q[s, m, a]`` and ``marg[s, m]`` its first action."""
    for s in range(q.shape[0]):
        for m in range(q.shape[1]):
            _repair_model(q, s, m, mmax, marg)


@_jit_inline
def _repair_model(q, s, m, mmax, marg):
    best = q[s, m, 0]
    arg = 0
    for a in range(1, q.shape[2]):
        value = q[s, m, a]
        higher = value > best
        best = value if higher else best
        arg = a if higher else arg
    mmax[s, m] = best
    marg[s, m] = arg


@_jit_inline
def _repair_state(s, n_actions, mmax, marg, qmax, qcell):
    """Recompute state ``s``'s max from its models' maxima (first position, λ̂-major)."""
    row = mmax[s]
    best = row.max()  # a reduction the compiler vectorises; then the first model holding it
    model = 0
    while row[model] != best:
        model += 1
    qmax[s] = best
    qcell[s] = (s * mmax.shape[1] + model) * n_actions + marg[s, model]


@_jit_inline
def apply_update(
    q, lags, reward, alpha, gamma, hist_s, hist_a, hist_s2, hist_term, hist_count,
    qmax, qcell, mmax, marg, targets, states, actions,
):  # fmt: skip
    """One MMQ learning step from the received ``reward`` (targets first, then the writes).

    ``lags`` must be sorted ascending (the agents keep Λ sorted). ``hist_*`` is the episode's
    history ring (power-of-two length), ``hist_count`` the number of transitions in this episode
    so far, the newest at index ``hist_count - 1``. Two caches are
    kept exact: ``qmax[s]``, the max of ``q[s]``, with ``qcell[s]`` its flat index in ``q`` (the
    agents' layout), and ``mmax[s, m]``, the max of ``q[s, m]``, with ``marg[s, m]`` its action.
    An entry is recomputed only when the cached arg-max entry decreases. ``targets``,
    ``states`` and ``actions`` are scratch arrays of length |Λ|.
    """
    mask = hist_s.shape[0] - 1
    n_models = lags.shape[0]
    n_actions = q.shape[2]
    # targets first (each reads the cached max of its next state), remembering each model's cell
    count = 0  # the models whose step t − λ̂ is in this episode: a prefix, as lags are sorted
    for m in range(n_models):
        lag = lags[m]
        if lag >= hist_count:
            break
        pos = (hist_count - 1 - lag) & mask
        bootstrap = 0.0 if hist_term[pos] else gamma * qmax[hist_s2[pos]]
        targets[m] = reward + bootstrap
        states[m] = hist_s[pos]
        actions[m] = hist_a[pos]
        count += 1
    for m in range(count):  # then the writes, repairing a cache only when its arg-max fell
        s = states[m]
        a = actions[m]
        old = q[s, m, a]
        new = old + alpha * (targets[m] - old)
        q[s, m, a] = new
        _repair_model(q, s, m, mmax, marg)  # |A| compares without branches: cheaper than a
        # data-dependent branch the processor would mispredict half the time
        if new > qmax[s]:
            qmax[s] = new
            qcell[s] = (s * n_models + m) * n_actions + a
        elif new < old and qcell[s] == (s * n_models + m) * n_actions + a:
            _repair_state(s, n_actions, mmax, marg, qmax, qcell)


@_jit
def run_chunk(
    q, lags, qmax, qcell, mmax, marg,
    out_cdf, out_next, out_reward, out_term, init_cdf, max_steps,
    delays, buffer, episode_end_mode,
    alpha, gamma, eps_initial, eps_final, eps_steps, start_step,
    hist_s, hist_a, hist_s2, hist_term, state,
    rec_undelayed, rec_delivered, rec_obs, rec_action, rec_model, rec_episode_end,
    rec_terminated,
):  # fmt: skip
    """Advance training by ``delays.shape[0]`` steps.

    ``state`` is an int64 array ``[s, hist_count, episode_steps, clock]`` carried between chunks.
    ``out_*`` are the env's outcome tables of shape (S, A, K): cumulative probabilities, next
    states, rewards, termination flags. ``init_cdf`` is the cumulative initial-state distribution.
    ``buffer`` is the reward-delay ring (power-of-two length above every delay in ``delays``).
    The ``rec_*`` arrays receive one entry per step.
    """
    n_models = lags.shape[0]
    n_actions = q.shape[2]
    hmask = hist_s.shape[0] - 1
    bmask = buffer.shape[0] - 1
    targets = np.zeros(n_models)
    states = np.zeros(n_models, dtype=np.int64)
    actions = np.zeros(n_models, dtype=np.int64)
    s = state[0]
    hist_count = state[1]
    episode_steps = state[2]
    clock = state[3]
    for t in range(delays.shape[0]):
        step = start_step + t
        if step >= eps_steps:
            eps = eps_final
        else:
            eps = eps_initial + (eps_final - eps_initial) * (step / eps_steps)
        # choose the acting model, then the action (two ε-greedy levels, random tie-breaks)
        if n_models == 1:
            m = 0
        elif np.random.random() < eps:
            m = np.random.randint(n_models)
        else:  # a uniformly random model among those holding the state's max
            best = qmax[s]
            m = 0
            ties = 0
            for j in range(n_models):
                if mmax[s, j] == best:
                    ties += 1
                    if ties == 1 or np.random.random() * ties < 1.0:
                        m = j
        if np.random.random() < eps:
            action = np.random.randint(n_actions)
        else:  # a uniformly random action among the model's best
            best = mmax[s, m]
            action = 0
            ties = 0
            for a in range(n_actions):
                if q[s, m, a] == best:
                    ties += 1
                    if ties == 1 or np.random.random() * ties < 1.0:
                        action = a
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
        # record, remember, learn
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
        apply_update(
            q, lags, delivered, alpha, gamma, hist_s, hist_a, hist_s2, hist_term, hist_count,
            qmax, qcell, mmax, marg, targets, states, actions,
        )  # fmt: skip
        if ended:
            u = np.random.random()
            s = 0
            while s < init_cdf.shape[0] - 1 and init_cdf[s] <= u:
                s += 1
            hist_count = 0
            episode_steps = 0
        else:
            s = s2
    state[0] = s
    state[1] = hist_count
    state[2] = episode_steps
    state[3] = clock
