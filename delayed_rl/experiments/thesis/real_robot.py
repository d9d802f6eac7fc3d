"""``real-robot`` (thesis section 5.3, Figs. 5.24–5.27): simulation-trained agents on a stand-in robot.

The thesis trained MMQ and Q-learning in simulation, then let them learn on with a real e-puck
on a paper print of the racetrack. Here the "real robot" is ``delayed_rl/EPuckLineFollowReal-v0``
(:data:`~delayed_rl.envs.linefollow.env.REAL_ROBOT`, whose class docstring gives every value and
its source), and a control run continues the same agent in the clean simulation. The protocol
is :func:`tasks`', the numbers the constants ``EXPERIMENT.description`` is formatted from
(:data:`PRETRAIN_STEPS`, :data:`RUN_STEPS`, and the framework's); the claims are in
:func:`summarize`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from delayed_rl import figures
from delayed_rl._validation import check_choice
from delayed_rl.envs.linefollow.env import REAL_ROBOT
from delayed_rl.experiments.framework import claims as rules
from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.experiment import (
    Claim,
    Config,
    Experiment,
    SharedRun,
    Summary,
    seed_tasks,
    step_count,
)
from delayed_rl.experiments.framework.line_claims import REWARD_TOLERANCE
from delayed_rl.experiments.framework.line_following import (
    LAM,
    LAMBDA_MAX,
    Q_INIT,
    REAL_ENV_ID,
    TRACK,
    UNSEEN_ERROR,
    line_curves,
    pooled_training,
    training_cost,
)
from delayed_rl.experiments.framework.results import pivot
from delayed_rl.experiments.framework.task import Task
from delayed_rl.experiments.framework.training import hyperparameter_text

#: The learners compared.
LEARNERS = ("MMQ", "Q", "DeconvQ learned")
CONDITIONS = ("real", "control")
#: The env each condition continues on (a key of :data:`~.line_following.SETTINGS`).
SETTING = {"real": "real", "control": "clean"}
#: The steps of the pretraining in simulation (``--steps``), and of a quick run's.
PRETRAIN_STEPS, QUICK_PRETRAIN_STEPS = 500_000, 5_000
#: The steps of each continuation (the thesis's robot runs), and of a quick run's.
RUN_STEPS, QUICK_RUN_STEPS = 1_500, 300
#: Thesis section 5.3: average reward of each agent in each of the two robot runs.
THESIS_RUNS = {"run 1": {"MMQ": 0.2, "Q": -0.2}, "run 2": {"MMQ": 0.2, "Q": -0.3}}
#: The mean of the two runs, the target of the average-reward claims.
THESIS_REAL = {"MMQ": 0.2, "Q": -0.25}
#: Thesis Fig. 5.19: pretrained agents' average reward over 1,700 steps in simulation.
THESIS_SIM = {"MMQ": 0.6, "Q": 0.3}
#: The average-reward targets by condition: the robot runs' mean, and the simulation's.
THESIS_REWARDS = {"real": THESIS_REAL, "control": THESIS_SIM}
#: Thesis section 5.3: Q's accumulated error over MMQ's in run 1 and run 2.
THESIS_ERROR_RATIOS = {"run 1": 1.7, "run 2": 1.55}
#: The error-ratio claim's band: the thesis's range [1.55, 1.7] widened by this on each side.
ERROR_RATIO_TOLERANCE = 0.25
_COLOURS = {"MMQ": "C0", "Q": "C1", "DeconvQ learned": "C2"}


@dataclasses.dataclass(frozen=True, kw_only=True)
class RealRobotTask(Task):
    """A learner's run of ``real-robot``: pretraining, then the real and the control runs.

    Attributes:
        agent: the learner, one of :data:`LEARNERS`.
        pretrain_steps: steps of pretraining in the clean simulation.
        steps: steps of each run after it.
    """

    agent: str
    pretrain_steps: int
    steps: int

    def cost(self) -> float:
        """The run's estimated core-seconds, for scheduling: its pretraining and two runs."""
        return training_cost(self.agent, self.pretrain_steps + 2 * self.steps)


def tasks(config: Config) -> list[RealRobotTask]:
    """Per seed, one task per agent: pretraining, then the real and the control runs.

    1. pretraining: ``linefollow``'s setting
       (:mod:`~delayed_rl.experiments.framework.line_following`) in the clean simulation, for
       :data:`PRETRAIN_STEPS`;
    2. the **real** run: a copy of the pretrained agent (``copy.deepcopy``) moved to the real
       configuration (``set_env``), same reward delay, learning on for :data:`RUN_STEPS`
       (``learn(RUN_STEPS, reset_num_timesteps=False)``);
    3. the **control** run: another copy of the same pretrained agent, as many steps on a fresh
       clean simulation: the same protocol with no reality gap (the thesis's Fig. 5.19 runs
       pretrained agents this way in simulation). Control minus real is what the gap costs;
       the control against ``linefollow`` is what the delay costs.

    Both continuations start from the same agent state and the same env seed (the first reset
    after ``set_env`` uses the agent's seed), so their difference is paired by seed. (The control
    runs on the compiled path; the stand-in's command latency keeps the real run on the Python
    path, so their agents' random draws differ.) Agents: :data:`LEARNERS`, ``DeconvQ learned``
    beyond the thesis (learning the delay on 0..λ̂max, as in ``linefollow-deconv``). The
    default 4 seeds: the thesis's two runs are seeds ``base_seed`` and ``base_seed + 1``, drawn
    alone in the figures' first panels; all four give the 95 % CIs, with 3 degrees of freedom, a
    choice made when a seed cost minutes of pretraining. ``config.quick`` takes
    :data:`QUICK_PRETRAIN_STEPS` and :data:`QUICK_RUN_STEPS`.

    Cost: pretraining dominates; it runs on the compiled path, the continuations on the real
    configuration on the Python path; ``benchmarks/SPEED.md`` has their cost, ``summary.json``
    each pretraining's wall time (``pretrain_seconds``). The pretraining is
    :func:`~.line_following.training_run`'s, whose first steps are ``linefollow``'s,
    ``linefollow-deconv``'s and ``controllers``' training of the same learner and seed: run
    together (``delayed-rl bench all``), each trains once.
    """
    pretrain = config.run_steps(PRETRAIN_STEPS, QUICK_PRETRAIN_STEPS)
    run = QUICK_RUN_STEPS if config.quick else RUN_STEPS
    return seed_tasks(config, LEARNERS, RealRobotTask, pretrain_steps=pretrain, steps=run)


def run_task(task: RealRobotTask) -> dict:
    """Pretrain one agent in the clean simulation, then continue a copy on each condition.

    Returns:
        ``{"real": ..., "control": ...}`` (:func:`~.line_following.run_metrics`' metrics) and
        ``pretrain_seconds``, the wall time of the pretraining.
    """
    return shared_run(task).alone()


def shared_run(task: RealRobotTask) -> SharedRun:
    """The task's training run, pooled with the other line-following experiments'.

    Its first steps are ``linefollow``'s (or ``linefollow-deconv``'s) and ``controllers``' runs
    of the same learner and seed (:func:`~.line_following.training_run`): run together, each learner
    and seed trains once.
    """
    check_choice("agent", task.agent, LEARNERS)
    continuations = [
        ["continue", task.pretrain_steps, SETTING[condition], task.steps]
        for condition in CONDITIONS
    ]
    return pooled_training(task.agent, task.seed, continuations, _by_condition)


def _by_condition(result: dict) -> dict:
    """:func:`run_task`'s result from the training run's readouts (one per condition)."""
    readouts = result["readouts"]
    out: dict[str, Any] = {"pretrain_seconds": readouts[0]["pretrain_seconds"]}
    for condition, readout in zip(CONDITIONS, readouts, strict=True):
        out[condition] = {key: value for key, value in readout.items() if key != "pretrain_seconds"}
    return out


def _by_seed(runs: dict, agent: str, condition: str, key: str) -> dict[int, float]:
    """``{seed: result[condition][key]}`` of one agent's runs (``runs``: a pivot by agent)."""
    return {seed: result[condition][key] for seed, result in runs[agent].items()}


def summarize(task_list: list[RealRobotTask], results: list[dict], config: Config) -> Summary:
    """The claims, statistics in ``extra``, and the figures.

    The metrics of each continuation come from its own ``training_log``
    (:func:`~.line_following.run_metrics`): the average reward (Figs. 5.24, 5.26) and the
    accumulated error Σ|Δ| (Figs. 5.25, 5.27). The claims, verdicts from the 95 % CIs over seeds
    (:mod:`~.framework.claims`' rules):

    - on the real configuration, MMQ's and Q's average rewards against the thesis's
      (:data:`THESIS_REAL`, the mean of :data:`THESIS_RUNS`), each
      ± :data:`~.line_claims.REWARD_TOLERANCE`; MMQ above Q (paired by seed);
    - Q's accumulated error over MMQ's (paired by seed) against the thesis's range
      (:data:`THESIS_ERROR_RATIOS`), widened by :data:`ERROR_RATIO_TOLERANCE`;
    - the control runs' average rewards against Fig. 5.19's pretrained agents in simulation
      (:data:`THESIS_SIM`), ± the same tolerance;
    - the gap's cost, control minus real average reward (paired by seed), above 0 for MMQ and
      for Q (the thesis: both "performed worse in experiment than they did in simulation");
    - DeconvQ learned minus Q on the real configuration, above 0 (an extension), and DeconvQ's
      average reward there as a reference row.
    """
    by_agent = pivot(task_list, results, by=("agent",))
    runs = {agent: by_agent.get(agent, {}) for agent in LEARNERS}
    curves = [
        curve
        for task, result in zip(task_list, results, strict=True)
        for condition in CONDITIONS
        for curve in line_curves(f"{task.agent} {condition}", task.seed, result[condition])
    ]
    claims = [*_real_claims(runs), *_control_claims(runs), *_deconv_claims(runs)]
    seeds = sorted(runs["MMQ"])
    extra = {**_statistics(runs, seeds), "protocol": _protocol(task_list)}
    return Summary(claims, curves, _figures(runs, seeds), extra)


def _stats(
    runs: dict, agent: str, condition: str, key: str = "average"
) -> tuple[float, float, int]:
    """(mean, CI, n) over the seeds of one agent's ``key`` in one condition."""
    return rules.mean_ci_n(list(_by_seed(runs, agent, condition, key).values()))


def _gap(runs: dict, agent: str) -> tuple[float, float, int]:
    """(mean, CI, n) of what the gap costs ``agent``: control minus real average reward, by seed."""
    control = _by_seed(runs, agent, "control", "average")
    return rules.mean_ci_n(rules.paired(control, _by_seed(runs, agent, "real", "average")))


def _reward_claims(runs: dict, condition: str, where: str, thesis: dict) -> list[Claim]:
    """MMQ's and Q's average rewards in ``condition`` (named ``where``), each against the thesis.

    The targets are :data:`THESIS_REAL` on the real robot and :data:`THESIS_SIM` in the control,
    ± :data:`~.line_claims.REWARD_TOLERANCE`; ``thesis`` gives each agent's thesis statement.
    """
    targets = THESIS_REWARDS[condition]
    return [
        rules.band_claim(
            f"{agent} average reward{where}",
            thesis[agent],
            _stats(runs, agent, condition),
            targets[agent],
            REWARD_TOLERANCE,
        )
        for agent in ("MMQ", "Q")
    ]


def _real_claims(runs: dict) -> list[Claim]:
    """On the real robot: MMQ's and Q's average rewards, MMQ above Q, Q's error over MMQ's."""
    mmq_over_q = rules.mean_ci_n(
        rules.paired(
            _by_seed(runs, "MMQ", "real", "average"), _by_seed(runs, "Q", "real", "average")
        )
    )
    error_ratio = rules.mean_ci_n(
        rules.paired(
            _by_seed(runs, "Q", "real", "total_error"),
            _by_seed(runs, "MMQ", "real", "total_error"),
            "ratio",
        )
    )
    low = min(THESIS_ERROR_RATIOS.values()) - ERROR_RATIO_TOLERANCE
    high = max(THESIS_ERROR_RATIOS.values()) + ERROR_RATIO_TOLERANCE
    thesis = {
        "MMQ": "≈ 0.2 (run 1 just over, run 2 just under; Figs. 5.24, 5.26)",
        "Q": "≈ −0.25 (run 1 −0.2, run 2 just under −0.3; Figs. 5.24, 5.26)",
    }
    return [
        *_reward_claims(runs, "real", " on the real robot", thesis),
        rules.direction_claim(
            "MMQ minus Q average reward on the real robot (paired by seed)",
            "> 0: MMQ above Q in both runs (≈ +0.4, +0.5)",
            mmq_over_q,
            "above",
        ),
        rules.range_claim(
            "Q accumulated error / MMQ accumulated error on the real robot",
            "1.7 (run 1), 1.55 (run 2) (Figs. 5.25, 5.27)",
            error_ratio,
            low,
            high,
            note=f"paired by seed; the thesis's range [1.55, 1.7] ± {ERROR_RATIO_TOLERANCE}; "
            f"an unseen line counts |Δ| = {UNSEEN_ERROR}",
        ),
    ]


def _control_claims(runs: dict) -> list[Claim]:
    """In the clean simulation: MMQ's and Q's average rewards, and what the gap costs each."""
    thesis = {
        "MMQ": "just over 0.6 (Fig. 5.19, pretrained MMQ in simulation, 1,700 steps)",
        "Q": "≈ 0.3 (Fig. 5.19, pretrained Q in simulation, 1,700 steps)",
    }
    return [
        *_reward_claims(runs, "control", ", control (clean simulation)", thesis),
        rules.direction_claim(
            "MMQ gap cost: control minus real average reward (paired by seed)",
            "> 0: worse on the robot than in simulation (section 5.3; ≈ 0.6 − 0.2)",
            _gap(runs, "MMQ"),
            "above",
        ),
        rules.direction_claim(
            "Q gap cost: control minus real average reward (paired by seed)",
            "> 0: worse on the robot than in simulation (section 5.3; ≈ 0.3 + 0.25)",
            _gap(runs, "Q"),
            "above",
        ),
    ]


def _deconv_claims(runs: dict) -> list[Claim]:
    """The extension: DeconvQ learned above Q on the real robot, and its reward as a reference."""
    deconv_over_q = rules.mean_ci_n(
        rules.paired(
            _by_seed(runs, "DeconvQ learned", "real", "average"),
            _by_seed(runs, "Q", "real", "average"),
        )
    )
    return [
        rules.direction_claim(
            "DeconvQ learned minus Q average reward on the real robot (paired by seed)",
            "extension: DeconvQ above Q",
            deconv_over_q,
            "above",
        ),
        rules.reference_row(
            "DeconvQ learned average reward on the real robot",
            _stats(runs, "DeconvQ learned", "real"),
            note=f"control: {_stats(runs, 'DeconvQ learned', 'control')[0]:.3f}",
        ),
    ]


def _statistics(runs: dict, seeds: list[int]) -> dict[str, Any]:
    """``summary.json``'s statistics: per agent and condition, and the thesis's two runs."""
    both = [(a, c) for a in LEARNERS for c in CONDITIONS]
    return {
        "average_reward": {f"{a} {c}": _stats(runs, a, c)[:2] for a, c in both},
        "accumulated_error": {f"{a} {c}": _stats(runs, a, c, "total_error")[:2] for a, c in both},
        "line_visible_fraction": {f"{a} {c}": _stats(runs, a, c, "visible")[:2] for a, c in both},
        "gap_cost": {a: _gap(runs, a)[:2] for a in LEARNERS},
        "thesis_runs": {
            name: {
                "seed": seed,
                **{a: runs[a][seed]["real"]["average"] for a in LEARNERS},
                "error_ratio_Q_over_MMQ": runs["Q"][seed]["real"]["total_error"]
                / runs["MMQ"][seed]["real"]["total_error"],
            }
            for name, seed in zip(THESIS_RUNS, seeds, strict=False)
        },
        "pretrain_seconds": {
            a: rules.mean_ci_n([r["pretrain_seconds"] for r in runs[a].values()])[:2]
            for a in LEARNERS
        },
    }


def _protocol(task_list: list[RealRobotTask]) -> dict[str, Any]:
    """``summary.json``'s protocol: the steps, the delays and the real configuration."""
    return {
        "pretrain_steps": task_list[0].pretrain_steps,
        "run_steps": task_list[0].steps,
        "lambda": LAM,
        "max_delay_estimate": LAMBDA_MAX,
        "real_env": REAL_ENV_ID,
        "real_config": _real_config(),
    }


def _real_config() -> dict[str, float]:
    """The real configuration's arguments (``REAL_ROBOT``), for ``summary.json``."""
    from delayed_rl.envs.linefollow.env import REAL_ROBOT

    return dict(REAL_ROBOT)


def _figures(runs: dict, seeds: list[int]) -> dict:
    """Figs. 5.24–5.27: average reward and accumulated error, runs 1–2 and every seed."""
    panels: dict[str, list] = {"reward": [], "error": []}
    for (name, thesis), seed in zip(THESIS_RUNS.items(), seeds, strict=False):
        ratio = THESIS_ERROR_RATIOS[name]
        for metric, key in (("reward", "curve"), ("error", "error")):
            groups = {
                a: [(runs[a][seed]["real"]["steps"], runs[a][seed]["real"][key])] for a in LEARNERS
            }
            lines = (
                [(a, thesis[a], f"thesis {a} ≈ {thesis[a]:+g} ({name})") for a in thesis]
                if metric == "reward"
                else [("Q", ratio, f"thesis Q = {ratio}× MMQ ({name})")]
            )
            panels[metric].append((f"{name} (seed {seed}), real robot", groups, lines))
    n = len(seeds)
    for condition in CONDITIONS:
        for metric, key in (("reward", "curve"), ("error", "error")):
            groups = {
                a: [(r[condition]["steps"], r[condition][key]) for r in runs[a].values()]
                for a in LEARNERS
            }
            if metric == "reward":
                values = THESIS_REWARDS[condition]
                source = "runs 1–2 mean" if condition == "real" else "Fig. 5.19, simulation"
                lines = [(a, values[a], f"thesis {a} ≈ {values[a]:+g} ({source})") for a in values]
            else:
                mean = float(np.mean(list(THESIS_ERROR_RATIOS.values())))
                lines = [("Q", mean, f"thesis Q = {mean:g}× MMQ")] if condition == "real" else []
            label = "real robot" if condition == "real" else "control: clean simulation"
            if not lines:
                label += " (no thesis value)"
            panels[metric].append((f"{n} seeds, {label}", groups, lines))
    title = (
        f"Poisson delays of mean λ = {LAM}, MMQ with λ̂max = {LAMBDA_MAX}: "
        "pretrained in simulation, then learning on the"
    )
    return {
        "fig5_24_26_average_reward": plotting.figure(
            thesis_panels,
            panels["reward"],
            f"{title} stand-in robot: average reward",
            "average reward",
            "level",
        ),
        "fig5_25_27_accumulated_error": plotting.figure(
            thesis_panels,
            panels["error"],
            f"{title} stand-in robot: accumulated error",
            "accumulated error Σ|Δ| (pixels)",
            "ratio",
        ),
    }


def thesis_panels(path: Any, panels: list, title: str, ylabel: str, lines: str) -> None:
    """Panels of mean curves (95 % band over seeds) with the thesis's values dashed.

    Args:
        path: where to save the PNG.
        panels: ``[(panel title, {agent: [(steps, values), ...]}, thesis lines), ...]``; a
            thesis line is ``(agent, value, label)``.
        title: the figure's title.
        ylabel: the y axis label.
        lines: ``"level"``: a thesis line is a horizontal line at ``value``; ``"ratio"``: it
            is MMQ's mean curve of the panel times ``value`` (the thesis gives error ratios).
    """
    plt = figures.pyplot()
    columns = 2
    rows = (len(panels) + columns - 1) // columns
    fig, axes = plt.subplots(
        rows, columns, figsize=(12, 5.4 * rows), squeeze=False, layout="constrained"
    )
    for ax, (panel_title, groups, thesis) in zip(axes.flat, panels, strict=False):
        means = {}
        for agent, agent_runs in groups.items():
            steps = agent_runs[0][0]
            values = np.vstack([v for _, v in agent_runs])
            means[agent] = (steps, values.mean(axis=0))
            colour = _COLOURS[agent]
            if len(agent_runs) > 1:
                half = 1.96 * values.std(axis=0, ddof=1) / np.sqrt(len(agent_runs))
                ax.fill_between(
                    steps, means[agent][1] - half, means[agent][1] + half, color=colour, alpha=0.2
                )
            label = figures.band_label(agent, len(agent_runs))
            ax.plot(steps, means[agent][1], color=colour, label=label)
        for agent, value, label in thesis:
            if lines == "level":
                ax.axhline(value, color=_COLOURS[agent], linestyle="--", linewidth=1.2, label=label)
            else:
                steps, mmq = means["MMQ"]
                ax.plot(
                    steps,
                    value * mmq,
                    color=_COLOURS[agent],
                    linestyle="--",
                    linewidth=1.2,
                    label=label,
                )
        ax.set_title(panel_title, fontsize=10)
        ax.set_xlabel("time step on the robot")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        ax.legend(  # below the panel: it never covers the curves
            fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, frameon=False
        )
    for ax in list(axes.flat)[len(panels) :]:
        ax.set_visible(False)
    fig.suptitle(title)
    fig.savefig(path, dpi=100)
    plt.close(fig)


EXPERIMENT = Experiment(
    name="real-robot",
    thesis="section 5.3, Figs. 5.24–5.27",
    description=f"MMQ (λ̂max = {LAMBDA_MAX}), Q-learning and DeconvQ learned, pretrained in "
    f"the clean e-puck simulation (linefollow's setting: {TRACK}, Poisson({LAM}) reward delays, "
    f"{hyperparameter_text(Q_INIT)}) for {step_count(PRETRAIN_STEPS)} steps (--steps), then "
    f"{step_count(RUN_STEPS)} steps learning on the stand-in real robot (EPuckLineFollowReal-v0: "
    f"{REAL_ROBOT['control_period'] * 1000:g} ms steps, {REAL_ROBOT['command_latency']:g} s "
    "command latency, wheel slip, motor lag, camera noise, grey line) and, as a control, on the "
    "clean simulation; both continuations copy one pretrained agent. Average reward and "
    "accumulated error Σ|Δ| of each continuation, paired by seed. --quick: "
    f"{step_count(QUICK_PRETRAIN_STEPS)} pretraining steps, {QUICK_RUN_STEPS} per continuation; "
    "--steps sets the pretraining steps.",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=4,
    shared_run=shared_run,
)
