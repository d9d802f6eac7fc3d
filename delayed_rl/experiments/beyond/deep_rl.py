"""``deep-rl`` (beyond the thesis): SB3's SAC and PPO on delayed rewards, with reward models.

Each setting (:data:`SETTINGS`) is an env, an algorithm with SB3's defaults and a reward delay
flushed at each episode's end, with its own number of seeds; the methods are
:mod:`~delayed_rl.experiments.framework.deep_training`'s. The numbers are the constants
``EXPERIMENT.description`` is formatted from; the claims, fixed before the runs, are in
:func:`summarize`. Runs are kept as they finish (:attr:`~.experiment.Experiment.resumable`), so
an interrupted run resumes. It needs the ``sb3`` extra.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from delayed_rl.delays import Constant, Poisson
from delayed_rl.experiments.framework import claims as rules
from delayed_rl.experiments.framework.deep_training import (
    METHODS,
    WARMUP_EPISODES,
    random_score,
    train_and_score,
)
from delayed_rl.experiments.framework.experiment import (
    Claim,
    Config,
    Experiment,
    SharedRun,
    Summary,
)
from delayed_rl.experiments.framework.gain_settings import (
    RewardDelayTask,
    curve_means,
    delay_fields,
    gain_rows,
    gain_summary,
    gain_tasks,
    method_gains,
)
from delayed_rl.experiments.framework.results import pivot
from delayed_rl.experiments.framework.task import optional

#: The Poisson means of the short and the long delays, and the long episodes' steps.
SHORT_LAM, LAM, LONG_EPISODE_STEPS = 5, 20, 1000
#: CartPole's sub-envs.
CARTPOLE_ENVS = 4


def _pendulum(
    delay: Any, max_delay_estimate: int, seeds: int, episode_steps: int = 200, **fields: Any
) -> dict[str, Any]:
    """SAC on Pendulum-v1 for 10k steps, scored every 1000 steps (2500 for long episodes)."""
    return {"env_id": "Pendulum-v1", "algorithm": "SAC", "n_envs": 1,
            "episode_steps": episode_steps, "delay": delay.to_dict(), "max_delay_estimate": max_delay_estimate,
            "steps": 10_000, "eval_every": 1000 if episode_steps <= 200 else 2500,
            "warmup_episodes": WARMUP_EPISODES, "seeds": seeds, **fields}  # fmt: skip


SETTINGS: dict[str, dict[str, Any]] = {
    "pendulum-poisson5": _pendulum(Poisson(SHORT_LAM), 20, 5),
    "pendulum-poisson20": _pendulum(Poisson(LAM), 60, 5),
    "pendulum-episodic": _pendulum(Constant(200), 200, 5),
    "pendulum1000-poisson20": _pendulum(Poisson(LAM), 60, 15, episode_steps=LONG_EPISODE_STEPS),
    "pendulum1000-upright": _pendulum(
        Poisson(LAM), 60, 10, episode_steps=LONG_EPISODE_STEPS, reward="upright"
    ),
    "cartpole-poisson20": {"env_id": "CartPole-v1", "algorithm": "PPO", "n_envs": CARTPOLE_ENVS,
                           "episode_steps": 500, "delay": Poisson(LAM).to_dict(),
                           "max_delay_estimate": 60, "steps": 100_000, "eval_every": 10_000,
                           "seeds": 5},
}  # fmt: skip
"""Each setting's run fields; ``max_delay_estimate`` bounds a learned ``p``; ``seeds`` is the
setting's number of seeds (``--seeds`` caps it).

- ``pendulum-poisson5``, ``pendulum-poisson20``: SAC on Pendulum-v1 (200-step episodes) under
  Poisson(5) and Poisson(20) delays, 10k steps, 5 seeds;
- ``pendulum-episodic``: SAC on Pendulum-v1 with a constant delay of 200 steps, so all of an
  episode's reward arrives at its last step, 5 seeds;
- ``pendulum1000-poisson20``: SAC on Pendulum-v1 with 1000-step episodes under Poisson(20), the
  setting that separates the reward models: 10k steps are 10 episodes, so a model fitted to
  episode sums alone (RRD, IRCR) has 10 numbers to learn from, while the deconvolution fits each
  step's arrival. 15 seeds: the earlier implementation's paired differences (sd ≈ 0.5 of the
  gain over 5 seeds) needed about 12 to resolve a difference of 0.3;
- ``pendulum1000-upright``: the same, with a sparse reward: 1 at each step the pendulum is within
  about 26° of upright (``cos θ ≥ 0.9``), else 0: reaching a region, a reward episode sums
  carry only as a count while arrival times place it. 10 seeds;
- ``cartpole-poisson20``: PPO on CartPole-v1 with 4 sub-envs under Poisson(20), 100k steps, 5
  seeds; the flush pays out at the pole's fall, so raw PPO is paid for falling.

``--quick`` (:data:`QUICK`): ``pendulum-poisson20`` for 1000 steps and ``cartpole-poisson20``
for one PPO rollout (8192 steps), 2 seeds.
"""
#: Each setting's number of seeds.
_SEEDS = [setting["seeds"] for setting in SETTINGS.values()]
LONG_EPISODES = ("pendulum1000-poisson20", "pendulum1000-upright")
"""The separating settings: there the return regression runs too."""


def _methods(name: str) -> tuple[str, ...]:
    """A setting's methods: IRCR off-policy only, the return regression where it separates."""
    off_policy = SETTINGS[name]["algorithm"] == "SAC"
    return tuple(
        method
        for method in (*METHODS, "random")
        if (method != "ircr" or off_policy)
        and (method != "return-regression" or name in LONG_EPISODES)
    )


#: Each setting's methods (see :func:`summarize`).
SETTING_METHODS = {name: _methods(name) for name in SETTINGS}
QUICK = {"pendulum-poisson20": (1000, 500), "cartpole-poisson20": (8192, 4096)}
"""The quick run's settings: their (steps, eval_every)."""
#: Episodes that score a trained policy (their mean return is its score).
EVAL_EPISODES = 10
RANDOM_EPISODES = 100
"""Episodes that score the random policy (its mean is the gain's zero)."""
LABELS = {
    "raw": "raw",
    "oracle": "oracle (undelayed)",
    "rrd": "RRD",
    "ircr": "IRCR",
    "return-regression": "return regression (IRCR's target, learned)",
    "deconv-known": "deconvolution, p known",
    "deconv-learned": "deconvolution, p learned",
}
_RUN_FIELDS = ("env_id", "algorithm", "n_envs", "episode_steps", "steps", "eval_every")
_OPTIONAL_RUN_FIELDS = ("warmup_episodes", "reward")
"""Run fields only some settings have (a run without them keeps its key)."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class DeepTask(RewardDelayTask):
    """A (setting, method, seed) of ``deep-rl``.

    Attributes:
        env_id: the Gymnasium env.
        algorithm: ``"SAC"`` or ``"PPO"``.
        n_envs: the sub-envs of a run.
        episode_steps: the steps of an episode.
        warmup_episodes: the episodes that warm a reward model up (optional: ``None``, left out
            of the task's JSON, where the setting has none).
        reward: the env's reward, where not its own (optional: ``None``, left out of the task's
            JSON, for the env's own).
    """

    env_id: str
    algorithm: str
    n_envs: int
    episode_steps: int
    warmup_episodes: int | None = optional()
    reward: str | None = optional()

    def cost(self) -> float:
        """Estimated core-seconds: SAC about 20 ms a step, PPO 1.5 ms (for scheduling only)."""
        if self.method == "random":
            return 1.0
        per_step = 0.02 if self.algorithm == "SAC" else 0.0015
        return per_step * self.steps


def tasks(config: Config) -> list[DeepTask]:
    """Every (setting, method, seed), and a ``random`` task per (setting, seed)."""
    return gain_tasks(config, SETTINGS, QUICK, SETTING_METHODS, DeepTask)


def shared_run(task: DeepTask) -> SharedRun:
    """The run behind a task, without what it does not depend on.

    The oracle's run has no delay (the 200-step Pendulum settings share it); the random policy's
    depends only on the env and the seed.
    """
    entries = task.to_json()
    if task.method == "random":
        fields = {key: entries[key] for key in ("env_id", "episode_steps", "seed")}
        fields.update({key: entries[key] for key in ("reward",) if key in entries})
        return SharedRun(random_score, {**fields, "eval_episodes": RANDOM_EPISODES})
    run = {key: entries[key] for key in (*_RUN_FIELDS, "method", "seed")}
    run.update({key: entries[key] for key in _OPTIONAL_RUN_FIELDS if key in entries})
    run["eval_episodes"] = EVAL_EPISODES
    return SharedRun(train_and_score, {**run, **delay_fields(task)})


def _paired_claim(setting: str, ours: str, theirs: str, gains: dict) -> Claim:
    """``ours − theirs`` gain paired by seed, above 0, noting the seeds its spread would need."""
    return rules.paired_direction_claim(
        f"{setting}: {LABELS[ours]} − {LABELS[theirs]} gain",
        f"target: {LABELS[ours]} above {LABELS[theirs]}",
        gains[ours],
        gains[theirs],
    )


def _setting_claims(setting: str, gains: dict, curves: dict) -> list[Claim]:
    """The target claims of ``setting`` (see :func:`summarize`)."""
    out = []
    if setting == "pendulum-poisson20":
        for method in ("deconv-known", "deconv-learned"):
            values = list(gains[method].values())
            out.append(
                rules.seed_rule_claim(
                    f"{setting}: {LABELS[method]}, seeds with gain ≥ 0.9",
                    "target: within 10 % of the oracle's gain on ≥ 4 of 5 seeds",
                    values,
                    0.9,
                    math.ceil(0.8 * len(values)),
                )
            )
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
            differences = rules.paired(curves[method], curves["raw"])
            out.append(
                rules.direction_claim(
                    f"{setting}: {LABELS[method]} − raw, mean score over the learning curve",
                    f"target: {LABELS[method]} learns faster than raw",
                    rules.mean_ci_n(differences),
                    "above",
                )
            )
    elif setting in LONG_EPISODES:
        for baseline in ("rrd", "ircr"):
            out.append(_paired_claim(setting, "deconv-known", baseline, gains))
    return out


def _table_row(method: str, runs: dict[int, dict], gains: dict[int, float]) -> dict:
    """One (setting, method) row of ``summary.json``'s table: means, CIs and per-seed values."""
    row: dict[str, Any] = {"seeds": sorted(runs)}
    for key in ("score", "curve_mean", "rmse", "mean_delay", "train_seconds"):
        values = [r[key] for r in runs.values() if key in r]
        if values:
            mean, ci, _ = rules.mean_ci_n(values)
            row[key] = {"mean": mean, "ci95": ci, "values": values}
    if method in gains:
        mean, ci, _ = rules.mean_ci_n(list(gains[method].values()))
        row["gain"] = {"mean": mean, "ci95": ci, "values": list(gains[method].values())}
    return row


def _zero_width_notes(gains: dict, by_method: dict[str, dict[int, dict]]) -> dict[str, str]:
    """Why a method's gain row has zero width, where it has: all seeds gave the same score."""
    return {
        method: rules.identical_note(list(gains[method].values()))
        and rules.identical_note([r["score"] for r in by_method[method].values()])
        for method in gains
    }


def summarize(task_list: list[DeepTask], results: list[dict], config: Config) -> Summary:
    """The claims, reference rows of every gain, the table and a learning-curve figure a setting.

    The methods (:mod:`~delayed_rl.experiments.framework.deep_training`, one warm-up for all: an
    off-policy algorithm starts learning after two episodes of steps): raw, the undelayed
    oracle, RRD (its authors' settings), IRCR as its authors wrote it (SAC settings only: its
    batches replay the best episodes), the return regression (IRCR's target learned by a
    network; in :data:`LONG_EPISODES`, where it must earn its row), and the deconvolution with
    ``p`` known and learned. The oracle (the undelayed env) is one run per seed for the three
    Pendulum settings of 200-step episodes, and a random policy is scored on the same evaluation
    episodes. A score is the mean return of :data:`EVAL_EPISODES` deterministic episodes of the
    undelayed env; its *gain* is ``(score − random) / (oracle − random)``, the random policy's
    and the oracle's mean scores of the setting, so 1 is the oracle's level.

    The claims, fixed before the run:

    - Pendulum, Poisson(20): deconvolution, with ``p`` known and learned, is within 10 % of the
      oracle's gain (gain ≥ 0.9) on ≥ 4 of 5 seeds (a rule on the seeds, with the share's
      Wilson interval); raw stays below half the gain (its mean gain's 95 % CI below 0.5);
    - episodic rewards: RRD and deconvolution with ``p`` learned reach ≥ 80 % of the gain (the
      mean gain's CI above 0.8);
    - PPO on CartPole: deconvolution (``p`` known and learned) learns faster than raw: its mean
      score over the learning curve's evaluations (the area under the curve over its length)
      minus raw's, paired by seed, has its CI above 0;
    - the two 1000-step settings: deconvolution with ``p`` known above RRD and above IRCR (the
      gain difference paired by seed, CI above 0); each row notes how many seeds its spread
      would need to resolve.

    Every (setting, method) also has a reference row of its gain (a zero-width one says that
    all seeds gave the same value). ``summary.json``'s ``table`` holds the scores, gains, the
    curves' means, the reward models' RMSE against the true reward and the learned mean delays.
    """
    grouped = pivot(task_list, results, by=("setting", "method"), nested=True)
    claims, table = [], {}
    for setting, by_method in grouped.items():
        gains = method_gains(by_method)[0]
        curves_mean = curve_means(by_method)
        for method, runs in by_method.items():
            for seed, run in runs.items():
                if method in curves_mean:
                    run["curve_mean"] = curves_mean[method][seed]
        claims += _setting_claims(setting, gains, curves_mean)
        labels = {method: LABELS[method] for method in METHODS if method in by_method}
        claims += gain_rows(setting, gains, labels, _zero_width_notes(gains, by_method))
        table[setting] = {m: _table_row(m, runs, gains) for m, runs in by_method.items()}
    extra = {"table": table, "settings": SETTINGS}
    return gain_summary(grouped, LABELS, "the undelayed env", claims, extra)


EXPERIMENT = Experiment(
    name="deep-rl",
    thesis="beyond the thesis (deep RL)",
    description=f"SB3's SAC on Pendulum-v1 (Poisson({SHORT_LAM}), Poisson({LAM}), episodic, "
    f"{LONG_EPISODE_STEPS}-step episodes, and {LONG_EPISODE_STEPS}-step episodes with a sparse "
    f"upright reward) and PPO on CartPole-v1 ({CARTPOLE_ENVS} sub-envs, Poisson({LAM})), delayed "
    "rewards flushed at episode ends, one warm-up for every method: raw, the undelayed oracle, "
    "RRD and IRCR as their authors wrote them, the return regression and the deconvolution "
    f"reward model with p known and learned, {min(_SEEDS)} to {max(_SEEDS)} seeds; scores of "
    f"{EVAL_EPISODES} greedy episodes of the undelayed env, gains against a random policy and "
    "the oracle. The full table is summary.json's `table`.",
    tasks=tasks,
    summarize=summarize,
    default_seeds=max(_SEEDS),
    shared_run=shared_run,
    resumable=True,
    extras=("sb3",),
)
