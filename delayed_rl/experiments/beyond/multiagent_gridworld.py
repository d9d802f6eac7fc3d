"""``multiagent-gridworld`` (beyond the thesis): independent learners, a shared delayed reward.

The game is :class:`~delayed_rl.multiagent.CooperativeGridWorldEnv`, the thesis's grid world
walked by two agents paid together; each agent's rewards are delayed by its own Poisson draws
(:class:`~delayed_rl.multiagent.ParallelRewardDelay`), and each agent is an independent tabular
learner (:data:`LEARNERS`). The numbers are the constants ``EXPERIMENT.description`` is
formatted from; the score is :func:`train_and_score`'s, the claims, fixed before the runs,
:func:`summarize`'s. Runs are kept as they finish, so an interrupted run resumes. It needs the
``multiagent`` extra (PettingZoo).
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._validation import check_choice
from delayed_rl.agents import TabularAgent
from delayed_rl.agents.registry import agent_class
from delayed_rl.delays import Poisson
from delayed_rl.experiments.framework import delay_settings, plotting
from delayed_rl.experiments.framework.claims import (
    direction_claim,
    mean_ci_n,
    paired,
    reference_row,
    seed_rule_claim,
)
from delayed_rl.experiments.framework.delay_estimates import mean_delay_claim
from delayed_rl.experiments.framework.delay_settings import learner_arguments
from delayed_rl.experiments.framework.experiment import (
    Claim,
    Config,
    Curve,
    Experiment,
    SharedRun,
    Summary,
    running_average,
    seed_tasks,
    step_count,
)
from delayed_rl.experiments.framework.results import curve_groups, pivot
from delayed_rl.experiments.framework.task import Task, optional
from delayed_rl.experiments.framework.training import hyperparameter_text, thesis_hyperparameters
from delayed_rl.multiagent.gridworld import MEETING_REWARD

LEARNERS = ("Q", "DeconvQ known", "DeconvQ learned", "Q undelayed")
"""The learners, in the tables' order; one agent object per PettingZoo agent, stepping the
wrapped env through ``predict`` (ε-greedy) and ``update``, with the thesis's hyper-parameters:

- ``Q``: Q-learning on the delayed reward as it arrives;
- ``DeconvQ known``: :class:`~delayed_rl.agents.DeconvolutionQLearning` given Poisson(λ)
  (modelled on at most :data:`LAMBDA_MAX` lags);
- ``DeconvQ learned``: the same learning the delay on 0..:data:`LAMBDA_MAX`;
- ``Q undelayed``: Q-learning without any delay, the oracle (one run per seed, shared by both
  delays: :func:`shared_run`).
"""
#: The grid's side (each agent sees its own cell, ``Discrete(SIZE²)``) and the episodes' steps.
SIZE, EPISODE_STEPS = 5, 100
#: The mean delays λ of the full run, and of ``--quick``.
LAMS, QUICK_LAM = (5, 10), 10
#: The steps of a run, and of a quick run.
STEPS, QUICK_STEPS = 150_000, 10_000
CHECKPOINTS = 30
"""Greedy evaluations a run: the learning curve's points, every ``steps // CHECKPOINTS``."""
LAMBDA_MAX = delay_settings.LAMBDA_MAX
"""The longest delay DeconvQ models (``max_delay_estimate``), as in ``anonymous-delay``."""
OPTIMAL_FRACTION = 0.95
"""A joint policy is optimal when its score is at least this share of the optimum."""
SEED_SHARE = 0.8
"""The claims' seed rule: optimal on at least this share of the seeds (4 of 5)."""
LEARNER_STREAM = 0x1EA52
"""The spawn key of the learners' seeds (:func:`learner_seed`)."""


#: Rough cost of one joint step (µs, both learners and the env), for scheduling only.
STEP_MICROSECONDS = {"Q undelayed": 40.0, "Q": 90.0, "DeconvQ known": 110.0}


@dataclasses.dataclass(frozen=True, kw_only=True)
class MultiagentGridTask(Task):
    """A learner's run of ``multiagent-gridworld``.

    Attributes:
        agent: the learners' kind, one of :data:`LEARNERS`.
        size: the grid's side.
        episode_steps: the steps of an episode.
        steps: training steps.
        lam: the Poisson mean delay λ of each agent's rewards (optional: ``None``, left out of
            the task's JSON, in the run ``Q undelayed``'s tasks share, :func:`shared_run`).
    """

    agent: str
    size: int
    episode_steps: int
    steps: int
    lam: int | None = optional()

    def cost(self) -> float:
        """The run's estimated core-seconds (its steps at :data:`STEP_MICROSECONDS`, else 140 µs)."""
        return 1e-6 * self.steps * STEP_MICROSECONDS.get(self.agent, 140.0)


def tasks(config: Config) -> list[MultiagentGridTask]:
    """Per delay λ of :data:`LAMS` (``--quick``: :data:`QUICK_LAM`), seed and learner, one task."""
    steps = config.run_steps(STEPS, QUICK_STEPS)
    lams = (QUICK_LAM,) if config.quick else LAMS
    fields = {"size": SIZE, "episode_steps": EPISODE_STEPS, "steps": steps}
    return [
        task
        for lam in lams
        for task in seed_tasks(config, LEARNERS, MultiagentGridTask, lam=lam, **fields)
    ]


def shared_run(task: MultiagentGridTask) -> SharedRun:
    """The run behind a task: Q undelayed's has no λ, so both delays share it."""
    check_choice("agent", task.agent, LEARNERS)
    if task.agent == "Q undelayed":
        return SharedRun(train_and_score, dataclasses.replace(task, lam=None))
    return SharedRun(train_and_score, task)


class AgentSpaces(gym.Env):
    """A stand-in env that only carries one PettingZoo agent's spaces, to build a learner on.

    The tabular agents read their spaces from the env they are given; a learner driven by
    ``predict`` and ``update`` never steps it (``learn()`` would fail: it has no ``step``).
    """

    def __init__(self, env: Any, agent: Any):
        self.observation_space = env.observation_space(agent)
        self.action_space = env.action_space(agent)


def learner_seed(seed: int, index: int) -> int:
    """The seed of agent ``index``'s learner in the run of ``seed`` (63 bits of a SeedSequence)."""
    state = np.random.SeedSequence(seed, spawn_key=(LEARNER_STREAM, index)).generate_state(
        1, np.uint64
    )
    return int(state[0] >> np.uint64(1))


def make_game(task: MultiagentGridTask) -> Any:
    """The task's game, with each agent's Poisson(λ) reward delay (flushed) unless undelayed."""
    from delayed_rl.multiagent import CooperativeGridWorldEnv, ParallelRewardDelay

    env = CooperativeGridWorldEnv(task.size, max_steps=task.episode_steps)
    if task.agent == "Q undelayed":
        return env
    return ParallelRewardDelay(env, Poisson(task.lam), on_episode_end="flush")


def make_learner(task: MultiagentGridTask, env: gym.Env, seed: int) -> TabularAgent:
    """One independent learner of ``task.agent``'s kind, on ``env``'s spaces.

    Built as ``anonymous-delay`` builds the learner of that name
    (:func:`~.delay_settings.learner_arguments`, the known delay Poisson(λ)); a learner that
    models the delay is told the episodes' ends flush (the stand-in env has no reward delay to
    read it from).
    """
    delay = None if task.lam is None else Poisson(task.lam)
    agent, options = learner_arguments(task.agent, delay)
    cls = agent_class(agent)
    if "on_episode_end" in inspect.signature(cls).parameters:
        options["on_episode_end"] = "flush"
    return cls(env, **options, **thesis_hyperparameters(seed))


def greedy_score(learners: dict[Any, TabularAgent], size: int, episode_steps: int) -> float:
    """The greedy joint policy's mean reward per step over an undelayed episode from the start."""
    from delayed_rl.multiagent import CooperativeGridWorldEnv

    env = CooperativeGridWorldEnv(size, max_steps=episode_steps)
    cells = np.arange(env.n_states)
    policy = {a: learner.predict(cells, deterministic=True)[0] for a, learner in learners.items()}
    observations, _ = env.reset(seed=0)
    total = 0.0
    while env.agents:
        actions = {agent: int(policy[agent][observations[agent]]) for agent in env.agents}
        observations, rewards, *_ = env.step(actions)
        total += rewards[env.possible_agents[0]]  # shared: every agent's is the same
    return total / episode_steps


def train_and_score(task: MultiagentGridTask) -> dict:
    """Train one independent learner per agent on the task's game; score the greedy policy.

    The greedy joint policy is scored :data:`CHECKPOINTS` times a run (the learning curve) over
    an episode of the undelayed game; the game and the greedy policies are deterministic, so one
    episode is every episode.

    Returns:
        ``steps`` and ``greedy`` (the checkpoints and the greedy score at each), ``score`` (the
        last), ``curve_steps`` and ``curve`` (the running mean of the undelayed shared reward),
        ``average`` (its mean over the run) and, for DeconvQ learned, ``mean_delay`` (the
        agents' mean) and ``estimates`` (each agent's ``delay_pmf``); JSON-ready lists.
    """
    env = make_game(task)
    learners = {
        agent: make_learner(task, AgentSpaces(env, agent), learner_seed(task.seed, i))
        for i, agent in enumerate(env.possible_agents)
    }
    steps, every = task.steps, max(1, task.steps // CHECKPOINTS)
    undelayed = np.empty(steps)
    checkpoints, scores = [], []
    observations, _ = env.reset(seed=task.seed)
    for step in range(steps):
        actions = {agent: learners[agent].predict(observations[agent])[0] for agent in env.agents}
        following, rewards, terminated, truncated, infos = env.step(actions)
        for agent, action in actions.items():
            learners[agent].update(
                observations[agent],
                action,
                rewards[agent],
                following[agent],
                terminated[agent],
                truncated[agent],
            )
        first = env.possible_agents[0]
        undelayed[step] = infos[first].get("undelayed_reward", rewards[first])
        observations = following if env.agents else env.reset()[0]
        if (step + 1) % every == 0 or step + 1 == steps:
            checkpoints.append(step + 1)
            scores.append(greedy_score(learners, task.size, task.episode_steps))
    curve_steps, curve = running_average(undelayed)
    result = {
        "steps": checkpoints,
        "greedy": scores,
        "score": scores[-1],
        "curve_steps": curve_steps.tolist(),
        "curve": curve.tolist(),
        "average": float(undelayed.mean()),
    }
    if task.agent == "DeconvQ learned":
        result["mean_delay"] = float(np.mean([agent.mean_delay for agent in learners.values()]))
        result["estimates"] = [agent.delay_pmf.tolist() for agent in learners.values()]
    return result


def optimum(size: int = SIZE, episode_steps: int = EPISODE_STEPS) -> float:
    """The best score: the meeting's reward every ``2(size − 1) + 1`` steps, per step."""
    return MEETING_REWARD * (episode_steps // (2 * (size - 1) + 1)) / episode_steps


def setting_label(lam: float) -> str:
    """A delay setting's name in the tables and figures: ``"Poisson(10)"``."""
    return f"Poisson({lam:g})"


def _score(result: dict) -> float:
    """A run's score, as a float."""
    return float(result["score"])


def _optimal_claim(quantity: str, thesis: str, scores: dict[int, float]) -> Claim:
    """The seeds whose final greedy policy is optimal, against :data:`SEED_SHARE` of them."""
    values = [score / optimum() for score in scores.values()]
    at_least = math.ceil(SEED_SHARE * len(values))
    return seed_rule_claim(quantity, thesis, values, OPTIMAL_FRACTION, at_least)


def _setting_claims(
    lam: float, by_agent: dict[str, dict[int, dict]], scores: dict[str, dict[int, float]]
) -> list[Claim]:
    """The claims of one delay (see :func:`summarize`), then every learner's score.

    Args:
        lam: the delay's mean.
        by_agent: its results, ``{agent: {seed: result}}``.
        scores: their scores, ``{agent: {seed: score}}``.
    """
    label = setting_label(lam)
    claims = []
    for name in ("DeconvQ known", "DeconvQ learned"):
        claims.append(
            direction_claim(
                f"{label}: {name} minus Q score",
                f"extension: {name} above Q",
                mean_ci_n(paired(scores[name], scores["Q"])),
                "above",
                note="paired by seed",
            )
        )
        claims.append(
            _optimal_claim(
                f"{label}: {name}, score / optimum (seeds ≥ {OPTIMAL_FRACTION:g})",
                f"extension: optimal on ≥ {SEED_SHARE * 100:g} % of the seeds",
                scores[name],
            )
        )
    claims.append(
        direction_claim(
            f"{label}: Q minus Q undelayed score",
            "extension: the delay costs Q-learning (below 0)",
            mean_ci_n(paired(scores["Q"], scores["Q undelayed"])),
            "below",
            note="paired by seed",
        )
    )
    delays = [r["mean_delay"] for r in by_agent["DeconvQ learned"].values()]
    claims.append(mean_delay_claim(f"{label}: DeconvQ learned mean delay", mean_ci_n(delays), lam))
    claims += [
        reference_row(f"{label}: {agent} score", mean_ci_n(list(scores[agent].values())))
        for agent in LEARNERS
        if agent in scores
    ]
    return claims


def _mean_ci(values: list[float]) -> dict[str, float]:
    mean, ci, _ = mean_ci_n(values)
    return {"mean": mean, "ci95": ci}


def _table(groups: dict[float, dict[str, dict]]) -> dict:
    """``summary.json``'s table: per delay and learner, the scores and training rewards."""
    table: dict[str, dict] = {}
    for lam, by_agent in groups.items():
        rows = table.setdefault(setting_label(lam), {})
        for agent, runs in by_agent.items():
            seeds = sorted(runs)
            scores = [runs[seed]["score"] for seed in seeds]
            rows[agent] = {
                "seeds": seeds,
                "scores": scores,
                "score": _mean_ci(scores),
                "average_reward": _mean_ci([runs[seed]["average"] for seed in seeds]),
                "optimal_seeds": sum(score >= OPTIMAL_FRACTION * optimum() for score in scores),
            }
            if agent == "DeconvQ learned":
                rows[agent]["mean_delay"] = [runs[seed]["mean_delay"] for seed in seeds]
    return table


def _curves(groups: dict[float, dict[str, dict]]) -> list[Curve]:
    """Every run's greedy-score and training curves, for ``curves.csv``."""
    curves = []
    for lam, by_agent in groups.items():
        for agent, runs in by_agent.items():
            condition = f"{setting_label(lam)} | {agent}"
            for seed, r in runs.items():
                curves.append(
                    Curve(
                        condition,
                        seed,
                        np.asarray(r["steps"]),
                        np.asarray(r["greedy"]),
                        "greedy_score",
                    )
                )
                curves.append(
                    Curve(condition, seed, np.asarray(r["curve_steps"]), np.asarray(r["curve"]))
                )
    return curves


def _figures(groups: dict[float, dict[str, dict]]) -> dict:
    """Per delay: the greedy scores' learning curves, and DeconvQ learned's delay estimates."""
    figures = {}
    for lam, by_agent in groups.items():
        label = setting_label(lam)
        title = f"two independent learners, {SIZE}×{SIZE} cooperative grid world, {label} delays"
        figures[f"greedy_score_poisson{lam:g}"] = plotting.figure(
            plotting.learning_curves,
            curve_groups(by_agent, y="greedy"),
            f"{title}: greedy joint policy",
            "greedy score (reward per step)",
            levels=[(optimum(), f"optimum {optimum():.2f}")],
        )
        learned = by_agent.get("DeconvQ learned", {})
        pmfs = [np.mean(np.asarray(r["estimates"]), axis=0) for r in learned.values()]
        estimates = [(np.arange(pmf.size), pmf) for pmf in pmfs]  # per seed, the agents' mean
        if estimates:
            figures[f"delay_estimate_poisson{lam:g}"] = plotting.figure(
                plotting.estimate_plot,
                {"DeconvQ learned pmf (the two agents' mean)": estimates},
                np.asarray(Poisson(lam).pmf(np.arange(LAMBDA_MAX + 1))),
                f"{title}: DeconvQ learned's delay estimate",
            )
    return figures


def summarize(task_list: list[MultiagentGridTask], results: list[dict], config: Config) -> Summary:
    """The claims, the table (``extra["table"]``) and the figures.

    A score is the mean (undelayed) reward per step of the greedy joint policy (each learner's
    ``predict(obs, deterministic=True)``) over an evaluation episode of the undelayed game from
    the start (:func:`train_and_score`); a joint policy is *optimal* when it scores at least
    :data:`OPTIMAL_FRACTION` of the optimum (:func:`optimum`). The claims, fixed before the
    runs, per delay, with verdicts by :mod:`~delayed_rl.experiments.framework.claims`' rules:

    - DeconvQ known minus Q score, and DeconvQ learned minus Q, paired by seed: above 0;
    - DeconvQ known, and DeconvQ learned: optimal on at least :data:`SEED_SHARE` of the seeds
      (a rule on these seeds, the share's Wilson interval beside it);
    - Q minus Q undelayed score, paired by seed: below 0 (the delay costs Q-learning);
    - DeconvQ learned's mean delay (both agents' estimates averaged, per seed): λ ± 10 %;

    and once, the setting's check: Q undelayed optimal on at least :data:`SEED_SHARE` of the
    seeds. Every learner's score also has a reference row.
    """
    groups = pivot(task_list, results, by=("lam", "agent"), nested=True)
    scores = pivot(task_list, results, by=("lam", "agent"), value=_score, nested=True)
    undelayed = next(iter(scores.values()))["Q undelayed"]
    claims = [
        _optimal_claim(
            f"Q undelayed, score / optimum (seeds ≥ {OPTIMAL_FRACTION:g})",
            f"the setting's check: optimal on ≥ {SEED_SHARE * 100:g} % of the seeds",
            undelayed,
        )
    ]
    claims += [
        claim
        for lam, by_agent in groups.items()
        for claim in _setting_claims(lam, by_agent, scores[lam])
    ]
    extra = {
        "table": _table(groups),
        "optimum": optimum(),
        "rules": {"optimal_fraction": OPTIMAL_FRACTION, "seed_share": SEED_SHARE},
    }
    return Summary(claims, _curves(groups), _figures(groups), extra)


EXPERIMENT = Experiment(
    name="multiagent-gridworld",
    thesis="beyond the thesis (multi-agent, shared delayed reward)",
    description="Two independent tabular learners (one per PettingZoo agent, through predict and "
    f"update) on a cooperative two-agent {SIZE}×{SIZE} grid world (the thesis's world, "
    f"+{MEETING_REWARD:g} to both only when both stand on the reward cell; each sees its own cell; "
    f"{EPISODE_STEPS}-step episodes) under each agent's Poisson(λ) reward delays, "
    f"λ = {' and '.join(map(str, LAMS))}, flushed at the episode's end: Q-learning, "
    f"deconvolution Q-learning (delay known, or learned on 0..{LAMBDA_MAX}) and undelayed "
    f"Q-learning, {step_count(STEPS)} steps a run; {hyperparameter_text()}. Scored by the greedy "
    f"joint policy's reward per step over an undelayed episode (optimum {optimum():g}), paired "
    "by seed.",
    tasks=tasks,
    summarize=summarize,
    default_seeds=5,
    shared_run=shared_run,
    resumable=True,
    extras=("multiagent",),
)
