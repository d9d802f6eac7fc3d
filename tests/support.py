"""Test helpers shared by several test modules."""

from __future__ import annotations

import math
import tracemalloc
from typing import TYPE_CHECKING

import gymnasium as gym
import numpy as np
import pytest

from delayed_rl.delays import Delay

if TYPE_CHECKING:
    from delayed_rl.experiments.framework.delay_settings import SettingTask


def examples(ci_count: int) -> int:
    """A test's own ``max_examples``: ``ci_count`` under the ``ci`` profile, scaled to the active one.

    A test's ``@settings(max_examples=...)`` overrides the profile (``tests/conftest.py``), so a
    test that needs more (or fewer) examples than the default states its ``ci`` count through
    this: the ``dev`` profile's 10 examples in place of 100 give a tenth of it (at least one).
    """
    from hypothesis import settings

    scale = settings().max_examples / settings.get_profile("ci").max_examples
    return max(1, round(ci_count * scale))


class ScriptedDelay(Delay):
    """Delays read from a script, in order (``then`` once it runs out); ignores the generator."""

    def __init__(self, script, then: int = 0, mean: float = 1.0):
        self.script, self.then, self._mean, self.used = list(script), then, mean, 0

    def sample(self, rng, size=None):
        n = 1 if size is None else int(np.prod(size))
        out = [
            self.script[i] if i < len(self.script) else self.then
            for i in range(self.used, self.used + n)
        ]
        self.used += n
        return self._finish(np.reshape(out, () if size is None else size), size)

    def pmf(self, k):
        return 0.0

    @property
    def mean(self):
        return self._mean


ALPHA = 1e-3
"""The statistical tests' significance level: a correct sampler fails a check with this
probability (the seeds are fixed, so the outcome is deterministic)."""
N_SE = 4.0
"""How many standard errors a sample mean or count may be from its expectation."""
POISSON_MEANS = [0.5, 5, 13.7, 90, 150]
"""The Poisson means the samplers are checked at: small, the thesis's, and its line follower's."""


def assert_mean_close(draws: np.ndarray, mean: float, var: float) -> None:
    """``draws``' mean is within :data:`N_SE` standard errors of ``mean`` (variance ``var``)."""
    se = math.sqrt(var / draws.size) if var > 0 else 0.0
    assert abs(draws.mean() - mean) <= N_SE * se + 1e-12, (draws.mean(), mean, se)


def binned_chisquare(draws: np.ndarray, pmf) -> float:
    """p-value of a chi-square goodness-of-fit test of integer ``draws`` against ``pmf``.

    Bins are consecutive integers merged left to right until each expected count is >= 5; all
    probability mass beyond the largest draw goes to the last bin, so the bins cover the support.
    """
    draws = np.asarray(draws, dtype=np.int64)
    assert draws.min() >= 0
    n = draws.size
    kmax = int(draws.max())
    probs = np.asarray(pmf(np.arange(kmax + 1)), dtype=float)
    probs[-1] += max(0.0, 1.0 - probs.sum())  # the tail P(d > kmax)
    observed = np.bincount(draws, minlength=kmax + 1).astype(float)
    obs_bins, exp_bins = [], []
    acc_o = acc_e = 0.0
    for o, p in zip(observed, probs, strict=True):
        acc_o += o
        acc_e += n * p
        if acc_e >= 5.0:
            obs_bins.append(acc_o)
            exp_bins.append(acc_e)
            acc_o = acc_e = 0.0
    if acc_e > 0.0 or acc_o > 0.0:
        obs_bins[-1] += acc_o
        exp_bins[-1] += acc_e
    assert len(obs_bins) >= 2, "too few bins for a chi-square test"
    exp_arr = np.asarray(exp_bins)
    exp_arr *= n / exp_arr.sum()
    from scipy import stats  # (imported here: scipy.stats takes half a second to import)

    return float(stats.chisquare(np.asarray(obs_bins), exp_arr).pvalue)


class NeverEndingEnv(gym.Env):
    """Pays ``reward`` (whatever it is: non-finite, numpy-typed, not a number) every step, never ends.

    The cheapest env to drive a delay wrapper; by default it pays 1.0.
    """

    observation_space = gym.spaces.Discrete(1)
    action_space = gym.spaces.Discrete(1)

    def __init__(self, reward=1.0):
        self.reward = reward

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return 0, {}

    def step(self, action):
        return 0, self.reward, False, False, {}


def layers(env: gym.Env) -> list[str]:
    """The wrapper classes from the outside in, without Gymnasium's bookkeeping."""
    names = []
    while isinstance(env, gym.Wrapper):
        if not isinstance(env, gym.wrappers.OrderEnforcing | gym.wrappers.PassiveEnvChecker):
            names.append(type(env).__name__)
        env = env.env
    return names


def actions(env, steps, seed):
    """``steps`` random batches of ``env``'s actions."""
    space = env.action_space
    space.seed(seed)
    return [space.sample() for _ in range(steps)]


def flush_trap_warnings(caught) -> list:
    """The flush-trap warnings (``the delay had no effect``) among the ``caught`` ones."""
    return [w for w in caught if "the delay had no effect" in str(w.message)]


MB = 1 << 20
"""A mebibyte, in bytes: the unit of the memory bounds."""


def peak_of(make):
    """``(result, peak bytes)`` of calling ``make`` under tracemalloc."""
    tracemalloc.start()
    try:
        result = make()
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def peak_of_error(make, exc, match):
    """The peak bytes allocated before ``make`` raises ``exc`` matching ``match``."""
    tracemalloc.start()
    try:
        with pytest.raises(exc, match=match):
            make()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def fake_grid_run(
    agent: str,
    seed: int,
    optimal: bool,
    average: float,
    mean_delay: float | None,
    late: float,
) -> tuple[SettingTask, dict]:
    """A ``(task, result)`` pair shaped like ``delay_settings.run_agent``'s, for summaries.

    One 100-step run on the 7×7 grid under Poisson(8): its greedy policy ``optimal`` (or not) at
    the end, ``average`` its training reward, ``late`` the share of second-half snapshots
    optimal; with a delay estimate of mean ``mean_delay`` (``None``: the agent holds none).
    """
    from delayed_rl.experiments.framework.delay_settings import SettingTask

    task = SettingTask(
        setting="7×7 Poisson(8)",
        size=7,
        lam=8,
        delay="Poisson",
        agent=agent,
        steps=100,
        seed=seed,
    )
    greedy = 0.76 if optimal else 0.0
    result = {
        "steps": np.array([50, 100]),
        "curve": np.full(2, average),
        "average": average,
        "greedy": greedy,
        "optimal": optimal,
        "second_half_optimal": late,
        "ns_per_step": 100.0,
        "path": "compiled",
        "snapshot_steps": np.array([50, 100]),
        "snapshot_optimal": np.array([False, optimal]),
        "snapshot_greedy": np.array([0.0, greedy]),
    }
    if mean_delay is not None:
        support = np.arange(51)
        estimate = np.exp(-0.5 * (support - mean_delay) ** 2)
        result |= {
            "estimate_support": support,
            "estimate": estimate / estimate.sum(),
            "mean_delay": mean_delay,
        }
    return task, result


def fake_line_run(average: float, total_error: float, mean_delay: float | None) -> dict:
    """A result shaped like a line-following run's (``line_following.run_metrics``'): a 10-step run, for summaries.

    ``average`` is its training reward, ``total_error`` its accumulated error (half of it by
    step 5), with a flat delay estimate on 0..150 of mean ``mean_delay`` (``None``: none held).
    """
    result = {
        "steps": np.array([5, 10]),
        "curve": np.full(2, average),
        "error": np.array([total_error / 2, total_error]),
        "average": average,
        "total_error": total_error,
        "visible": 1.0,
        "ns_per_step": 1e5,
        "path": "python",
    }
    if mean_delay is not None:
        result |= {
            "estimate_support": np.arange(151),
            "estimate": np.full(151, 1 / 151),
            "mean_delay": mean_delay,
        }
    return result


def same(a, b) -> bool:
    """Whether two space samples are equal, entry by entry (arrays by value)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(map(same, a, b))
    return bool(np.array_equal(a, b))


def same_tensors(a, b) -> bool:
    """Whether two lists of torch tensors are equal, pair by pair, bit for bit (torch imported here)."""
    import torch

    return len(a) == len(b) and all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


def scribble(sample) -> None:
    """Overwrite every array of a space sample in place, and every other entry of its dicts."""
    if isinstance(sample, np.ndarray):
        sample[...] = 1 if sample.dtype.kind in "iub" else 0.5
    elif isinstance(sample, dict):
        for key, value in list(sample.items()):
            scribble(value)
            if not isinstance(value, np.ndarray | dict | tuple):
                sample[key] = "scribbled"
    elif isinstance(sample, tuple):
        for value in sample:
            scribble(value)


@pytest.fixture(scope="module")
def torch_on_one_thread():
    """Runs torch on one thread in a test module, and puts the thread count back afterwards.

    The deep RL tests use it: two runs side by side on a 2-core machine share the cores.
    """
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


class Echo(gym.Env):
    """Records the actions it executes; never ends an episode by itself (or after ``length``)."""

    def __init__(self, n=50, length=None):
        self.action_space = gym.spaces.Discrete(n)
        self.observation_space = gym.spaces.Discrete(1)
        self.length, self.executed = length, []

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return 0, {}

    def step(self, action):
        self.executed.append(int(action))
        self.t += 1
        return 0, 0.0, False, self.length is not None and self.t >= self.length, {}
