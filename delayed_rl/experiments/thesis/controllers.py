"""``controllers`` (thesis Fig. 5.19): the proportional controller against Q-learning and MMQ.

Four line followers run on the racetrack under Poisson reward delays, from the same pose for a
given seed: the thesis's proportional controller, seeing the camera undelayed and behind an
observation delay, and Q-learning and MMQ trained first under the reward delay. The numbers are
the constants ``EXPERIMENT.description`` is formatted from (:data:`RUN_STEPS`,
:data:`TRAIN_STEPS`, :data:`K_P`, :data:`THESIS`); the contestants are in :func:`tasks`, the
claims in :func:`summarize`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.claims import band_claim, direction_claim, mean_ci_n, paired
from delayed_rl.experiments.framework.experiment import (
    Config,
    Curve,
    Experiment,
    SharedRun,
    Summary,
    step_count,
)
from delayed_rl.experiments.framework.line_following import (
    LAM,
    LAMBDA_MAX,
    line_env,
    line_statistics,
    only_readout,
    pooled_training,
    run_metrics,
    training_cost,
)
from delayed_rl.experiments.framework.results import pivot
from delayed_rl.experiments.framework.task import Task

#: The steps of every controller's run (Fig. 5.19), and of a quick run.
RUN_STEPS, QUICK_RUN_STEPS = 1700, 300
#: The learners' training steps before their run (``--steps``), and a quick run's.
TRAIN_STEPS, QUICK_TRAIN_STEPS = 300_000, 2_000
#: The proportional controller's gain k_p (the thesis's Eqs. 5.8–5.9).
K_P = 6
#: Thesis Fig. 5.19's final average rewards, in the thesis's order of performance.
THESIS = {"P undelayed": 0.9, "MMQ": 0.6, "Q": 0.3, "P delayed observations": -0.6}
#: The proportional controllers among them, by whether their observations are delayed (the
#: others are learners).
PROPORTIONAL = {"P undelayed": False, "P delayed observations": True}
#: The band of each controller's final average reward: the thesis's value ± this.
TOLERANCE = 0.2


@dataclasses.dataclass(frozen=True, kw_only=True)
class ControllerTask(Task):
    """A controller's run of ``controllers``.

    Attributes:
        controller: the contestant, a key of :data:`THESIS`.
        train_steps: a learner's training steps before its run (a proportional controller
            ignores them).
        run_steps: the steps of the run.
    """

    controller: str
    train_steps: int
    run_steps: int

    @property
    def learner(self) -> bool:
        """Whether the contestant learns (else it is one of the :data:`PROPORTIONAL`)."""
        return self.controller not in PROPORTIONAL

    def cost(self) -> float:
        """The run's estimated core-seconds, for scheduling: a learner's training and its run."""
        steps = self.run_steps + (self.train_steps if self.learner else 0)
        return training_cost(self.controller, steps)


def tasks(config: Config) -> list[ControllerTask]:
    """Per seed, one run of each of the four controllers (:data:`THESIS`), all from one pose.

    - **P undelayed**: the thesis's proportional controller (Eqs. 5.8–5.9, gain :data:`K_P`) on
      continuous wheel speeds, seeing the camera undelayed. Its rewards still pass through the
      reward delay, as in the thesis; the controller ignores rewards and the metric uses the
      undelayed stream, so this changes nothing.
    - **P delayed observations**: the same controller behind
      :class:`~delayed_rl.wrappers.ObservationDelay` with Poisson delays of the same mean: at
      step t it sees the camera of step t − d_t.
    - **Q** and **MMQ** (λ̂max as in Figs. 5.20–5.23): first "thoroughly trained" under the
      reward delay for :data:`TRAIN_STEPS` (twice the training of Figs. 5.20–5.23; the learning
      curves are flat by then), then their Q-tables start the run on a fresh env, where they
      keep learning with ε = 0.1 as the thesis's did. The training is
      :func:`~.line_following.training_run`'s: its first steps are ``linefollow``'s run of the
      same learner and seed, and ``real-robot`` continues it, so run together they train once.

    Every run lasts :data:`RUN_STEPS`; ``config.quick`` takes :data:`QUICK_TRAIN_STEPS` and
    :data:`QUICK_RUN_STEPS`.
    """
    train_steps = config.run_steps(TRAIN_STEPS, QUICK_TRAIN_STEPS)
    run_steps = QUICK_RUN_STEPS if config.quick else RUN_STEPS
    return [
        ControllerTask(
            controller=name, train_steps=train_steps, run_steps=run_steps, seed=config.base_seed + i
        )
        for i in range(config.seeds)
        for name in THESIS
    ]


def _run_proportional(delayed: bool, steps: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The P controller's undelayed rewards and true centroids over ``steps`` steps."""
    from delayed_rl.agents.proportional import ProportionalController
    from delayed_rl.delays import Poisson
    from delayed_rl.wrappers import ObservationDelay

    env = line_env(action_mode="continuous")
    if delayed:
        env = ObservationDelay(env, Poisson(LAM))
    controller = ProportionalController(env=env, k_p=K_P)
    obs, info = env.reset(seed=seed)
    rewards, centroids = np.zeros(steps), np.zeros(steps, dtype=np.int64)
    state = None
    for t in range(steps):
        centroids[t] = info["centroid"]  # the camera now, whatever the controller is shown
        action, state = controller.predict(obs, state)
        obs, _, _, _, info = env.step(action)
        rewards[t] = info["undelayed_reward"]
    env.close()
    return rewards, centroids


def run_task(task: ControllerTask) -> dict:
    """One controller's run: its running average reward, accumulated error and line visibility.

    Returns:
        ``steps`` and ``curve`` (the running average reward over the run), ``average`` (its
        final value), ``total_error`` (Σ|Δ| over the run) and ``visible`` (the fraction of
        steps whose camera saw the line).
    """
    if task.learner:
        return shared_run(task).alone()
    delayed = PROPORTIONAL[task.controller]
    rewards, centroids = _run_proportional(delayed, task.run_steps, task.seed)
    return _metrics({"undelayed_reward": rewards, "obs": centroids})


def shared_run(task: ControllerTask) -> SharedRun | None:
    """A learner's run: its training, pooled with the other line-following experiments'.

    Trained for ``train_steps``, a copy of it goes on for ``run_steps`` on a fresh env
    (:func:`~.line_following.training_run`, whose first steps are ``linefollow``'s run of the same
    learner and seed and whose training ``real-robot`` continues); the P controllers' runs are
    their own (``None``).
    """
    if not task.learner:
        return None
    continuation = ["continue", task.train_steps, "clean", task.run_steps]
    return pooled_training(task.controller, task.seed, [continuation], _continuation_metrics)


def _continuation_metrics(result: dict) -> dict:
    """A learner's run's metrics, as :func:`run_task` returns them, from its training run."""
    return _pick(only_readout(result))


def _metrics(log: dict) -> dict:
    """A run's metrics, as :func:`run_task` returns them, from its undelayed rewards and states."""
    return _pick(run_metrics(log))


def _pick(metrics: dict) -> dict:
    """The entries of :func:`~.line_following.run_metrics`' result that a controller's run reports."""
    return {key: metrics[key] for key in ("steps", "curve", "average", "total_error", "visible")}


def summarize(task_list: list[ControllerTask], results: list[dict], config: Config) -> Summary:
    """Fig. 5.19's claims: each controller's final average reward, and their order.

    The metric is the running average of the undelayed reward over the run (Fig. 5.19); a
    claim reads its final value. A controller's row is the band rule on the thesis's value
    ± :data:`TOLERANCE`; the thesis's order P > MMQ > Q > delayed P is three rows, one per
    neighbouring pair, each the pair's difference paired by seed (every seed's four runs start
    from the same pose), the direction rule (above 0).
    """
    by_controller = pivot(task_list, results, by=("controller",))
    runs = {name: by_controller[name] for name in THESIS}
    by_seed = pivot(task_list, results, by=("controller",), value="average")
    curves = [
        Curve(task.controller, task.seed, result["steps"], result["curve"])
        for task, result in zip(task_list, results, strict=True)
    ]
    stat = {name: mean_ci_n([r["average"] for r in rs.values()]) for name, rs in runs.items()}
    run_steps = task_list[0].run_steps
    claims = [
        band_claim(
            f"{name}: average reward after {run_steps} steps",
            f"≈ {value:+.1f} (Fig. 5.19)",
            stat[name],
            value,
            TOLERANCE,
        )
        for name, value in THESIS.items()
    ]
    measured_order = " > ".join(sorted(THESIS, key=lambda name: -stat[name][0]))
    names = list(THESIS)
    for better, worse in zip(names, names[1:], strict=False):
        claims.append(
            direction_claim(
                f"{better} minus {worse} average reward (paired by seed)",
                f"> 0: {better} above {worse} (Fig. 5.19's order)",
                mean_ci_n(paired(by_seed[better], by_seed[worse])),
                "above",
                note=f"measured order of the means: {measured_order}",
            )
        )
    groups = {name: [(r["steps"], r["curve"]) for r in rs.values()] for name, rs in runs.items()}
    figures = {
        "fig5_19_controllers": plotting.figure(
            plotting.learning_curves,
            groups,
            f"line following, Poisson delays of mean λ = {LAM}, λ̂max = {LAMBDA_MAX}: "
            "the controllers' average reward (Fig. 5.19)",
            "average reward (undelayed stream)",
            thesis=[
                (value, f"thesis {name} ≈ {value:+.1f} (Fig. 5.19)", name)
                for name, value in THESIS.items()
            ],
        )
    }
    extra = {
        "train_steps": task_list[0].train_steps,
        "run_steps": run_steps,
        "max_delay_estimate": LAMBDA_MAX,
        **line_statistics(runs),
    }
    return Summary(claims, curves, figures, extra)


EXPERIMENT = Experiment(
    name="controllers",
    thesis="Fig. 5.19",
    description=f"{RUN_STEPS} steps of the racetrack under Poisson({LAM}) delays: the "
    f"proportional controller (k_p = {K_P}) undelayed and with Poisson({LAM})-delayed "
    f"observations, and Q-learning and MMQ (λ̂max = {LAMBDA_MAX}) trained first for --steps "
    f"steps (default {step_count(TRAIN_STEPS)}) under the reward delay and still learning during "
    "the run. Average reward from the undelayed reward stream.",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=5,
    shared_run=shared_run,
)
