"""``multiagent-pursuit`` (beyond the thesis): PPO with parameter sharing under delayed team rewards.

The game is SISL's ``pursuit_v5`` made small enough to learn in minutes on a CPU (:data:`SETTINGS`),
each pursuer's rewards delayed by its own Poisson draws
(:class:`~delayed_rl.multiagent.ParallelRewardDelay`); one SB3 PPO policy acts for every
pursuer (:mod:`~delayed_rl.experiments.framework.multiagent_training`). The numbers are the
constants ``EXPERIMENT.description`` is formatted from; the claims, fixed before the runs, are
in :func:`summarize`. Runs are kept as they finish, so an interrupted run resumes. It needs the
``sb3`` and ``multiagent`` extras.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from delayed_rl.delays import Poisson
from delayed_rl.experiments.framework import claims as rules
from delayed_rl.experiments.framework import gain_settings
from delayed_rl.experiments.framework.delay_estimates import mean_delay_claim
from delayed_rl.experiments.framework.experiment import Config, Experiment, SharedRun, Summary
from delayed_rl.experiments.framework.multiagent_training import (
    METHODS,
    random_score,
    train_and_score,
)
from delayed_rl.experiments.framework.results import pivot

#: The Poisson mean of every pursuer's reward delay.
LAM = 30
#: The seeds of a full run.
SEEDS = 5
SETTING = f"pursuit-poisson{LAM}"
SETTINGS: dict[str, dict[str, Any]] = {
    SETTING: {
        "env": "pursuit",
        "env_kwargs": {
            "max_cycles": 200,
            "x_size": 8,
            "y_size": 8,
            "n_pursuers": 4,
            "n_evaders": 6,
            "surround": False,
            "n_catch": 2,
        },
        "delay": Poisson(LAM).to_dict(),
        "max_delay_estimate": 3 * LAM,
        "ppo": {"n_steps": 512, "batch_size": 256},
        "steps": 300_000,
        "eval_every": 30_000,
    }
}
"""The setting's run fields.

The game: 4 pursuers and 6 evaders on an 8×8 grid, 200-step episodes, an evader caught when 2
pursuers tag it, and the team's reward shared by every pursuer (PettingZoo's default
``shared_reward``): +5 a catch and −0.1 a step; each pursuer's rewards delayed by its own
Poisson(:data:`LAM`) draws, flushed at the episode's end. One SB3 PPO policy acts for every
pursuer (parameter sharing, through SuperSuit's vector conversion), with SB3's defaults but for
rollouts of 512 steps a pursuer (2048 a rollout, SB3's default for one env) and minibatches of
256, 300k pursuer-steps a run. ``--quick`` (:data:`QUICK`): 4000 steps, 2 seeds.
"""
QUICK = {SETTING: (4000, 2000)}
"""The quick run's settings: their (steps, eval_every)."""
#: Episodes that score a trained policy (their mean return is its score).
EVAL_EPISODES = 10
RANDOM_EPISODES = 100
"""Episodes that score the random policy (its mean is the gain's zero)."""
LABELS = {
    "oracle": "PPO undelayed (oracle)",
    "raw": "PPO on delayed rewards",
    "deconv-known": "PPO + deconvolution (known delay)",
    "deconv-learned": "PPO + deconvolution (learned delay)",
}
_RUN_FIELDS = ("env", "env_kwargs", "ppo", "steps", "eval_every", "seed")


@dataclasses.dataclass(frozen=True, kw_only=True)
class PursuitTask(gain_settings.RewardDelayTask):
    """A (setting, method, seed) of ``multiagent-pursuit``.

    Attributes:
        env: the game, a name of :data:`~.multiagent_training.ENVS`.
        env_kwargs: the game's arguments.
        ppo: PPO's arguments beyond SB3's defaults.
    """

    env: str
    env_kwargs: dict[str, Any]
    ppo: dict[str, Any]

    def cost(self) -> float:
        """Estimated core-seconds: about 0.6 ms a pursuer-step (for scheduling only)."""
        return 1.0 if self.method == "random" else 6e-4 * self.steps


def tasks(config: Config) -> list[PursuitTask]:
    """Every (setting, method, seed), and a ``random`` task per (setting, seed)."""
    return gain_settings.gain_tasks(config, SETTINGS, QUICK, (*METHODS, "random"), PursuitTask)


def shared_run(task: PursuitTask) -> SharedRun:
    """The run behind a task: the oracle's and the random policy's do not depend on the delay."""
    entries = task.to_json()
    fields = {key: entries[key] for key in ("env", "env_kwargs", "seed")}
    if task.method == "random":
        return SharedRun(random_score, {**fields, "eval_episodes": RANDOM_EPISODES})
    run = {key: entries[key] for key in _RUN_FIELDS}
    run.update(method=task.method, eval_episodes=EVAL_EPISODES)
    return SharedRun(train_and_score, {**run, **gain_settings.delay_fields(task)})


def _setting_claims(setting: str, scores: dict, by_method: dict) -> list[rules.Claim]:
    """The claims of ``setting`` (see :func:`summarize`)."""
    claims = [
        rules.paired_direction_claim(
            f"{setting}: {LABELS[method]} − {LABELS['raw']}, score",
            "target: above 0 (paired by seed)",
            scores[method],
            scores["raw"],
        )
        for method in ("deconv-known", "deconv-learned")
    ]
    claims.append(
        rules.paired_direction_claim(
            f"{setting}: {LABELS['raw']} − {LABELS['oracle']}, score",
            "check: below 0 (paired by seed: the delay costs PPO)",
            scores["raw"],
            scores["oracle"],
            "below",
        )
    )
    curves = gain_settings.curve_means(by_method)
    claims += [
        rules.reference_row(
            f"{setting}: {LABELS[method]} − {LABELS['raw']}, mean score over the learning curve",
            rules.mean_ci_n(rules.paired(curves[method], curves["raw"])),
            "reference, chosen after the run (not a claim): how early each learns",
        )
        for method in ("deconv-known", "deconv-learned")
    ]
    delays = [r["mean_delay"] for r in by_method["deconv-learned"].values()]
    claims.append(
        mean_delay_claim(
            f"{setting}: deconvolution's learned mean delay", rules.mean_ci_n(delays), LAM
        )
    )
    return claims


def _table_row(method: str, runs: dict[int, dict], scores: dict[int, float], gains: dict) -> dict:
    """One (setting, method) row of ``summary.json``'s table: per-seed scores and gains."""
    row: dict[str, Any] = {
        "seeds": sorted(scores),
        "scores": list(scores.values()),
        "gains": list(gains[method].values()),
    }
    if method.startswith("deconv"):
        for key in ("rmse", "mean_delay"):
            row[key] = [r[key] for r in runs.values()]
    return row


def summarize(task_list: list[PursuitTask], results: list[dict], config: Config) -> Summary:
    """The claims, a reference row of every gain, the table and the learning curves.

    The methods: ``oracle`` (PPO on the undelayed rewards), ``raw`` (on the delayed rewards as
    they arrive), ``deconv-known`` (on ``R̂(s, a)`` of
    :class:`~delayed_rl.deep.DeconvolutionRewardModel` given the delay, through
    :class:`~delayed_rl.deep.RelabelingRolloutBuffer`: the rollout-buffer route, on the stacked
    sub-envs, every pursuer's delivered rewards one stream), ``deconv-learned`` (the same,
    learning the delay on 0..3λ), and a random policy; :data:`SEEDS` seeds. A score is the mean
    per-pursuer return of :data:`EVAL_EPISODES` greedy episodes of the undelayed game; its
    *gain* is ``(score − random) / (oracle − random)``.

    The claims, fixed before the runs:

    - deconvolution (known delay) − raw PPO, score, paired by seed: above 0;
    - deconvolution (learned delay) − raw PPO, the same;
    - raw PPO − oracle, score, paired by seed: below 0 (the delay costs PPO);
    - the learned mean delay, averaged over the seeds: λ ± 10 %;

    and a reference row of every method's gain. Each paired claim's note gives the seeds its
    spread would need to resolve it. Two reference rows, chosen after the first run (not
    claims): the reward models minus raw PPO in mean score over the learning curve (how early
    each learns).
    """
    grouped = pivot(task_list, results, by=("setting", "method"), nested=True)
    all_scores = pivot(task_list, results, by=("setting", "method"), value="score", nested=True)
    claims, table = [], {}
    for setting, by_method in grouped.items():
        gains, low, _ = gain_settings.method_gains(by_method)
        scores = all_scores[setting]
        claims += _setting_claims(setting, scores, by_method)
        claims += gain_settings.gain_rows(setting, gains, LABELS)
        table[setting] = {"random": {"score": low}}
        for method in METHODS:
            table[setting][method] = _table_row(method, by_method[method], scores[method], gains)
    extra = {"table": table, "settings": SETTINGS}
    return gain_settings.gain_summary(
        grouped, LABELS, "the undelayed game (per pursuer)", claims, extra
    )


EXPERIMENT = Experiment(
    name="multiagent-pursuit",
    thesis="beyond the thesis (multi-agent delayed rewards, deep)",
    description=(
        "SB3's PPO with parameter sharing (SuperSuit) on SISL's pursuit ({n_pursuers} pursuers, "
        "{n_evaders} evaders, {x_size}×{y_size}, shared team reward) under Poisson({lam}) "
        "reward delays per pursuer: the undelayed oracle, PPO on the delayed rewards, and PPO "
        "on deconvolution's R̂ (delay known or learned), {seeds} seeds, {steps:,} "
        "pursuer-steps; scores of {episodes} greedy episodes of the undelayed game, gains "
        "against a random policy and the oracle."
    ).format(
        **SETTINGS[SETTING]["env_kwargs"],
        lam=LAM,
        seeds=SEEDS,
        steps=SETTINGS[SETTING]["steps"],
        episodes=EVAL_EPISODES,
    ),
    tasks=tasks,
    summarize=summarize,
    default_seeds=SEEDS,
    shared_run=shared_run,
    resumable=True,
    extras=("sb3", "multiagent"),
)
