"""``deep-rl`` (beyond the thesis): SB3's SAC and PPO on delayed rewards, with reward models.

Each setting is an env, an algorithm with SB3's defaults and a reward delay flushed at each
episode's end (:data:`SETTINGS`):

- ``pendulum-poisson5``, ``pendulum-poisson20``: SAC on Pendulum-v1 (200-step episodes) under
  Poisson(5) and Poisson(20) delays, 10k steps;
- ``pendulum-episodic``: SAC on Pendulum-v1 with a constant delay of 200 steps, so all of an
  episode's reward arrives at its last step;
- ``pendulum1000-poisson20``: SAC on Pendulum-v1 with 1000-step episodes under Poisson(20), the
  setting that separates the reward models: 10k steps are 10 episodes, so a model fitted to
  episode sums alone (RRD, IRCR) has 10 numbers to learn from, while the deconvolution fits each
  step's arrival;
- ``cartpole-poisson20``: PPO on CartPole-v1 with 4 sub-envs under Poisson(20), 100k steps; the
  flush pays out at the pole's fall, so raw PPO is paid for falling.

Every method of :mod:`~delayed_rl.experiments.framework.deep_training` runs 5 seeds in each
setting; the oracle (the undelayed env) is one run per seed for the three Pendulum settings of
200-step episodes, and a random policy is scored on the same evaluation episodes. A score is the
mean return of 10 deterministic episodes of the undelayed env; its *gain* is
``(score − random) / (oracle − random)``, the random policy's and the oracle's mean scores of the
setting, so 1 is the oracle's level.

The claims, against the targets set for this experiment:

- Pendulum, Poisson(20): deconvolution, with ``p`` known and learned, is within 10 % of the
  oracle's gain (gain ≥ 0.9) on ≥ 80 % of the seeds (4 of 5; a rule on the seeds themselves);
  raw stays below half the gain (its mean gain's 95 % CI below 0.5);
- episodic rewards: RRD and deconvolution with ``p`` learned reach ≥ 80 % of the gain (the
  mean gain's CI above 0.8);
- PPO on CartPole: deconvolution is not below raw (the gain difference paired by seed: its CI
  above −0.1, the margin the Pendulum target allows);
- the separating setting: deconvolution with ``p`` known above RRD and above IRCR (the gain
  difference paired by seed).

Every (setting, method) also has a reference row of its gain. ``summary.json``'s ``table`` holds
the scores, gains, the reward models' RMSE against the true reward and the learned mean delays.
``--quick``: ``pendulum-poisson20`` for 1000 steps and ``cartpole-poisson20`` for one PPO rollout
(8192 steps), 2 seeds. Runs are kept as they finish (:attr:`~.runner.Experiment.resumable`), so
an interrupted run resumes. It needs the ``sb3`` extra.
"""

from __future__ import annotations

import math
from typing import Any

from delayed_rl.delays import Constant, Poisson
from delayed_rl.experiments.framework import claims as rules
from delayed_rl.experiments.framework.deep_training import (
    METHODS,
    random_score,
    require_sb3,
    train_and_score,
)
from delayed_rl.experiments.framework.gain_settings import (
    gain_tasks,
    group_results,
    learning_curves,
    method_gains,
)
from delayed_rl.experiments.framework.runner import (
    AGREES,
    DIFFERS,
    Claim,
    Config,
    Experiment,
    SharedRun,
    Summary,
)


def _pendulum(delay: Any, max_delay: int, episode_steps: int = 200) -> dict[str, Any]:
    """SAC on Pendulum-v1 for 10k steps, scored every 1000 steps (2500 for long episodes)."""
    return {"env_id": "Pendulum-v1", "algorithm": "SAC", "n_envs": 1,
            "episode_steps": episode_steps, "delay": delay.to_dict(), "max_delay": max_delay,
            "steps": 10_000, "eval_every": 1000 if episode_steps <= 200 else 2500}  # fmt: skip


#: Each setting's run fields (see the module docstring); ``max_delay`` bounds a learned ``p``.
SETTINGS: dict[str, dict[str, Any]] = {
    "pendulum-poisson5": _pendulum(Poisson(5), 20),
    "pendulum-poisson20": _pendulum(Poisson(20), 60),
    "pendulum-episodic": _pendulum(Constant(200), 200),
    "pendulum1000-poisson20": _pendulum(Poisson(20), 60, episode_steps=1000),
    "cartpole-poisson20": {"env_id": "CartPole-v1", "algorithm": "PPO", "n_envs": 4,
                           "episode_steps": 500, "delay": Poisson(20).to_dict(),
                           "max_delay": 60, "steps": 100_000, "eval_every": 10_000},
}  # fmt: skip
#: Each setting's methods: IRCR's batches replay the best episodes, so it is off-policy only.
SETTING_METHODS = {
    name: tuple(m for m in (*METHODS, "random") if m != "ircr" or setting["algorithm"] == "SAC")
    for name, setting in SETTINGS.items()
}
QUICK = {"pendulum-poisson20": (1000, 500), "cartpole-poisson20": (8192, 4096)}
"""The quick run's settings: their (steps, eval_every)."""
EVAL_EPISODES = 10
RANDOM_EPISODES = 100
"""Episodes that score the random policy (its mean is the gain's zero)."""
NOT_BELOW_MARGIN = 0.1
"""How far below a baseline's gain "not below" allows (CartPole's claims)."""
LABELS = {
    "raw": "raw",
    "oracle": "oracle (undelayed)",
    "rrd": "RRD",
    "ircr": "IRCR",
    "return-regression": "return regression",
    "deconv-known": "deconvolution, p known",
    "deconv-learned": "deconvolution, p learned",
}
_RUN_FIELDS = ("env_id", "algorithm", "n_envs", "episode_steps", "steps", "eval_every")


def tasks(config: Config) -> list[dict]:
    """Every (setting, method, seed), and a ``random`` task per (setting, seed).

    Raises:
        ImportError: torch or stable-baselines3 is missing (the ``sb3`` extra).
    """
    require_sb3()
    return gain_tasks(config, SETTINGS, QUICK, SETTING_METHODS)


def shared_run(task: dict) -> SharedRun:
    """The run behind a task, without what it does not depend on.

    The oracle's run has no delay (the 200-step Pendulum settings share it); the random policy's
    depends only on the env and the seed.
    """
    if task["method"] == "random":
        fields = {key: task[key] for key in ("env_id", "episode_steps", "seed")}
        return SharedRun(random_score, {**fields, "eval_episodes": RANDOM_EPISODES})
    run = {key: task[key] for key in (*_RUN_FIELDS, "method", "seed")}
    run["eval_episodes"] = EVAL_EPISODES
    if task["method"] != "oracle":
        run["delay"] = task["delay"]
    if task["method"] == "deconv-learned":
        run["max_delay"] = task["max_delay"]
    return SharedRun(train_and_score, run)


def run_task(task: dict) -> dict:
    """A task's result, run on its own (:func:`shared_run`)."""
    return shared_run(task).alone()


def cost(task: dict) -> float:
    """Estimated core-seconds: SAC about 20 ms a step, PPO 1.5 ms (for scheduling only)."""
    if task["method"] == "random":
        return 1.0
    per_step = 0.02 if task["algorithm"] == "SAC" else 0.0015
    return per_step * task["steps"]


def _within_gain_claim(setting: str, method: str, gains: dict[int, float]) -> Claim:
    """Gain ≥ 0.9 on at least 80 % of the seeds: a rule on the seeds themselves."""
    k, n = sum(g >= 0.9 for g in gains.values()), len(gains)
    verdict = AGREES if n and k >= 0.8 * n else DIFFERS
    return Claim(
        f"{setting}: {LABELS[method]}, seeds with gain ≥ 0.9",
        "target: within 10 % of the oracle's gain on ≥ 4 of 5 seeds",
        k / n if n else math.nan,
        0.0,
        n,
        verdict,
        "agrees if the share of seeds with gain ≥ 0.9 is at least 0.8 (a rule on these seeds, "
        "not an interval)",
        "gains " + ", ".join(f"{g:.2f}" for g in gains.values()),
    )


def _paired_claim(setting: str, ours: str, theirs: str, values: dict, what: str) -> Claim:
    """``ours − theirs`` of ``values`` paired by seed, above 0."""
    stats = rules.mean_ci_n(rules.paired(values[ours], values[theirs]))
    return rules.direction_claim(
        f"{setting}: {LABELS[ours]} − {LABELS[theirs]} {what}",
        f"target: {LABELS[ours]} ≥ {LABELS[theirs]}",
        stats,
        "above",
    )


def _not_below_claim(setting: str, ours: str, theirs: str, gains: dict) -> Claim:
    """``ours`` not below ``theirs``: their gain difference, paired by seed, at least −0.1.

    The margin is the 10 % of the oracle's gain that the Pendulum target allows.
    """
    stats = rules.mean_ci_n(rules.paired(gains[ours], gains[theirs]))
    return rules.range_claim(
        f"{setting}: {LABELS[ours]} − {LABELS[theirs]} gain",
        f"target: {LABELS[ours]} ≥ {LABELS[theirs]}",
        stats,
        -NOT_BELOW_MARGIN,
        math.inf,
        f"differs if the 95 % CI lies wholly below −{NOT_BELOW_MARGIN} (10 % of the oracle's "
        "gain); agrees if it lies wholly above",
    )


def _setting_claims(setting: str, gains: dict) -> list[Claim]:
    """The target claims of ``setting`` (see the module docstring)."""
    out = []
    if setting == "pendulum-poisson20":
        out += [
            _within_gain_claim(setting, m, gains[m]) for m in ("deconv-known", "deconv-learned")
        ]
        out.append(
            rules.direction_claim(
                f"{setting}: raw gain",
                "target: raw below half the oracle's gain",
                rules.mean_ci_n(list(gains["raw"].values())),
                "below",
                0.5,
            )
        )
    elif setting == "pendulum-episodic":
        for method in ("rrd", "deconv-learned"):
            out.append(
                rules.direction_claim(
                    f"{setting}: {LABELS[method]} gain",
                    "target: ≥ 80 % of the oracle's gain",
                    rules.mean_ci_n(list(gains[method].values())),
                    "above",
                    0.8,
                )
            )
    elif setting == "cartpole-poisson20":
        for method in ("deconv-known", "deconv-learned"):
            out.append(_not_below_claim(setting, method, "raw", gains))
    elif setting == "pendulum1000-poisson20":
        for baseline in ("rrd", "ircr"):
            out.append(_paired_claim(setting, "deconv-known", baseline, gains, "gain"))
    return out


def _table_row(method: str, runs: dict[int, dict], gains: dict[int, float]) -> dict:
    """One (setting, method) row of ``summary.json``'s table: means, CIs and per-seed values."""
    row: dict[str, Any] = {"seeds": sorted(runs)}
    for key in ("score", "rmse", "mean_delay", "train_seconds"):
        values = [r[key] for r in runs.values() if key in r]
        if values:
            mean, ci, _ = rules.mean_ci_n(values)
            row[key] = {"mean": mean, "ci95": ci, "values": values}
    if method in gains:
        mean, ci, _ = rules.mean_ci_n(list(gains[method].values()))
        row["gain"] = {"mean": mean, "ci95": ci, "values": list(gains[method].values())}
    return row


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """The claims, reference rows of every gain, the table and a learning-curve figure a setting."""
    grouped = group_results(task_list, results)
    claims, curves, figures, table = [], [], {}, {}
    for setting, by_method in grouped.items():
        gains, low, high = method_gains(by_method)
        claims += _setting_claims(setting, gains)
        methods = [method for method in METHODS if method in by_method]
        for method in methods:
            stats = rules.mean_ci_n(list(gains[method].values()))
            claims.append(rules.reference_row(f"{setting}: {LABELS[method]} gain", stats))
        table[setting] = {m: _table_row(m, runs, gains) for m, runs in by_method.items()}
        labels = {method: LABELS[method] for method in methods}
        runs_curves, figures[f"curves_{setting}"] = learning_curves(
            setting, by_method, labels, low, "the undelayed env"
        )
        curves += runs_curves
    return Summary(claims, curves, figures, {"table": table, "settings": SETTINGS})


EXPERIMENT = Experiment(
    name="deep-rl",
    thesis="beyond the thesis (deep RL)",
    description="SB3's SAC on Pendulum-v1 (Poisson(5), Poisson(20), episodic and 1000-step "
    "episodes) and PPO on CartPole-v1 (4 sub-envs, Poisson(20)), delayed rewards flushed at "
    "episode ends: raw, the undelayed oracle, RRD, IRCR and the deconvolution reward model with "
    "p known and learned, 5 seeds; scores of 10 greedy episodes of the undelayed env, gains "
    "against a random policy and the oracle. The full table is summary.json's `table`.",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=5,
    shared_run=shared_run,
    cost=cost,
    resumable=True,
)
