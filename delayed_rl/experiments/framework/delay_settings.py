"""The grid worlds under anonymous delays, which ``anonymous-delay`` and ``future-work`` share.

The worlds are :data:`SETTINGS`, each under the delays :data:`DELAYS` (:func:`make_delay`);
:func:`setting_tasks` makes one task per (setting, agent, seed). The learners
(:data:`LEARNERS`, :func:`make_agent`) have the thesis's hyper-parameters (:mod:`.training`) and
model delays up to :data:`LAMBDA_MAX`. :func:`run_agent` trains one and measures it: it is the
run both experiments name when they share one (``future-work``'s thesis rule is
``anonymous-delay``'s MMQ run).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from delayed_rl._validation import check_choice, check_int
from delayed_rl.delays import Delay, Empirical, Geometric, Poisson
from delayed_rl.experiments.framework.experiment import Config, step_count
from delayed_rl.experiments.framework.snapshot_runs import measure, warm_up
from delayed_rl.experiments.framework.task import Task
from delayed_rl.experiments.framework.training import thesis_hyperparameters

#: (side, mean delay λ, steps a run) of the two worlds.
SETTINGS = ((9, 13, 1_000_000), (7, 8, 300_000))
#: The quick setting: its side, mean delay and steps, under Poisson delays only.
QUICK_SIZE, QUICK_LAM, QUICK_STEPS = 7, 8, 30_000
#: The three delay distributions of each world, all of mean λ (:func:`make_delay`): Poisson(λ)
#: (the thesis's), geometric (``Geometric(p)`` with ``p = 1 / (λ + 1)``, mean
#: ``(1 − p) / p = λ``) and a bimodal one (mass ½ at 0 and ½ at 2λ, an ``Empirical`` pmf).
DELAYS = ("Poisson", "geometric", "bimodal")
LAMBDA_MAX = 50
"""The longest delay any learner models, their ``max_delay_estimate`` (MMQ's λ̂max)."""
#: Where :func:`make_agent` puts the run's true delay among a learner's arguments.
_TRUE_DELAY = object()
#: Each learner: its agent in :data:`~delayed_rl.agents.registry.REGISTRY`, and its arguments
#: beyond the thesis's hyper-parameters (:func:`make_agent`).
_LEARNER_AGENTS: dict[str, tuple[str, dict[str, Any]]] = {
    "Q": ("q", {}),
    "MMQ": ("mmq", {"max_delay_estimate": LAMBDA_MAX}),
    "expected credit": (
        "expected-credit",
        {"delay": _TRUE_DELAY, "max_delay_estimate": LAMBDA_MAX},
    ),
    "DeconvQ known": ("deconv", {"delay": _TRUE_DELAY, "max_delay_estimate": LAMBDA_MAX}),
    "DeconvQ learned": ("deconv", {"delay": None, "max_delay_estimate": LAMBDA_MAX}),
    "oracle": ("oracle", {}),
    "Q undelayed": ("q", {}),
}
#: The seven learners, in the tables' order (:func:`make_agent`).
LEARNERS = tuple(_LEARNER_AGENTS)


def world_texts() -> list[tuple[str, str]]:
    """Each world of :data:`SETTINGS` as the descriptions write it: ``("9×9", "(λ = 13, 1M steps)")``."""
    return [(f"{n}×{n}", f"(λ = {lam}, {step_count(steps)} steps)") for n, lam, steps in SETTINGS]


WINDOW_DIVISOR = 10
"""MMQ's runs keep a greedy window of ``steps // WINDOW_DIVISOR`` steps (100k of 1M): the
averaged table ``future-work``'s greedy-window variant reads (:func:`make_agent`)."""


def make_delay(kind: str, lam: float) -> Delay:
    """The delay of mean ``lam``: ``"Poisson"``, ``"geometric"`` or ``"bimodal"`` (½ at 0, ½ at 2λ).

    Raises:
        TypeError: ``kind`` is not a string, or ``lam`` (bimodal) not an integer.
        ValueError: ``kind`` is not one of :data:`DELAYS`, or ``lam`` is out of range.
    """
    check_choice("kind", kind, DELAYS)
    if kind == "Poisson":
        return Poisson(lam)
    if kind == "geometric":
        return Geometric(1.0 / (lam + 1.0))  # mean (1 − p) / p = λ
    lam = check_int("lam", lam, 1)
    pmf = np.zeros(2 * lam + 1)
    pmf[0] = pmf[-1] = 0.5
    return Empirical(pmf)


def setting_label(size: int, kind: str, lam: float) -> str:
    """A setting's name in the tables and figures, e.g. ``"7×7 Poisson(8)"``."""
    names = {
        "Poisson": f"Poisson({lam:g})",
        "geometric": f"geometric (mean {lam:g})",
        "bimodal": f"bimodal {{0, {2 * lam:g}}}",
    }
    return f"{size}×{size} {names[kind]}"


@dataclasses.dataclass(frozen=True, kw_only=True)
class SettingTask(Task):
    """An agent's run in a grid world under an anonymous delay (:func:`setting_tasks`).

    Attributes:
        setting: the setting's label (:func:`setting_label`).
        size: the grid's side.
        lam: the delay's mean λ.
        delay: the delay's kind, one of :data:`DELAYS`.
        agent: the learner.
        steps: training steps.
    """

    setting: str
    size: int
    lam: int
    delay: str
    agent: str
    steps: int

    def cost(self) -> float:
        """The run's estimated core-seconds (its steps at :data:`STEP_MICROSECONDS`, else 0.7 µs)."""
        return 1e-6 * self.steps * STEP_MICROSECONDS.get(self.agent, 0.7)


#: Compiled training cost per step (µs) of the learners on these grids, for scheduling only.
STEP_MICROSECONDS = {"DeconvQ learned": 1.8, "DeconvQ known": 0.9, "MMQ": 0.8}


def setting_tasks(
    config: Config, agents: Sequence[str], task_type: type[SettingTask] = SettingTask
) -> list[SettingTask]:
    """One task per (setting, agent, seed): :data:`SETTINGS` × :data:`DELAYS`, or the quick one.

    ``config.steps`` replaces every setting's own step count; ``task_type`` is
    :class:`SettingTask` or an experiment's subclass of it (one that costs its runs otherwise).

    Raises:
        TypeError: ``task_type`` is not :class:`SettingTask` or a subclass of it.
    """
    if not (isinstance(task_type, type) and issubclass(task_type, SettingTask)):
        raise TypeError(f"task_type must be SettingTask or a subclass of it, got {task_type!r}")
    if config.quick:
        worlds, kinds = [(QUICK_SIZE, QUICK_LAM, QUICK_STEPS)], ("Poisson",)
    else:
        worlds, kinds = SETTINGS, DELAYS
    return [
        task_type(
            setting=setting_label(size, kind, lam),
            size=size,
            lam=lam,
            delay=kind,
            agent=agent,
            steps=config.steps or steps,
            seed=config.base_seed + i,
        )
        for size, lam, steps in worlds
        for kind in kinds
        for agent in agents
        for i in range(config.seeds)
    ]


def grid(size: int, delay: Delay | None = None, record_arrivals: bool = False) -> gym.Env:
    """``delayed_rl/GridWorld-v0`` of side ``size``, its reward delayed by ``delay`` (if any).

    Args:
        size: the grid's side.
        delay: the reward delay (``None``: undelayed).
        record_arrivals: report ``info["reward_arrivals"]`` (what the oracle reads); the
            :class:`~delayed_rl.wrappers.RewardDelay` is then put on top of ``gym.make``'s env.
    """
    import delayed_rl  # noqa: F401  (registers the ids)

    if record_arrivals:
        from delayed_rl.wrappers import RewardDelay

        return RewardDelay(
            gym.make("delayed_rl/GridWorld-v0", size=size), delay, record_arrivals=True
        )
    return gym.make("delayed_rl/GridWorld-v0", size=size, reward_delay=delay)


def learner_arguments(agent: str, delay: Delay) -> tuple[str, dict[str, Any]]:
    """The learner ``agent`` (one of :data:`LEARNERS`): its registry name and its arguments.

    A learner told the true delay (``expected credit``, ``DeconvQ known``) is told ``delay``.

    Raises:
        TypeError: ``agent`` is not a string.
        ValueError: ``agent`` is not one of :data:`LEARNERS`.
    """
    check_choice("agent", agent, LEARNERS)
    registered, extra = _LEARNER_AGENTS[agent]
    return registered, {
        key: delay if value is _TRUE_DELAY else value for key, value in extra.items()
    }


def make_agent(name: str, size: int, delay: Delay, seed: int, steps: int | None = None) -> Any:
    """One of :data:`LEARNERS` on its own ``size`` grid under ``delay``, built from the registry.

    ``Q`` is Q-learning on the delayed reward, ``MMQ`` Multiple Model Q-learning with
    Λ = {0, ..., ``LAMBDA_MAX``}, ``expected credit`` and ``DeconvQ known`` are told the true
    delay, ``DeconvQ learned`` learns it on 0..``LAMBDA_MAX``, the ``oracle`` is told which
    transition each reward came from, and ``Q undelayed`` learns without any delay. Given the
    run's ``steps``, MMQ also keeps the averaged table of a greedy window of
    ``steps // WINDOW_DIVISOR`` steps (``greedy_window``), which changes nothing of how it learns
    or acts: :func:`~.snapshot_runs.measure` reads both greedy policies off the one run.

    Raises:
        TypeError: ``name`` is not a string, or ``steps`` not an integer.
        ValueError: ``name`` is not one of :data:`LEARNERS`, or ``steps`` < 1.
    """
    from delayed_rl.agents.registry import REGISTRY, agent_class

    steps = check_int("steps", steps, 1, optional=True)
    agent, options = learner_arguments(name, delay)
    if name == "MMQ":
        options["greedy_window"] = None if steps is None else max(1, steps // WINDOW_DIVISOR)
    if name == "Q undelayed":
        env = grid(size)
    else:
        env = grid(size, delay, record_arrivals=REGISTRY[agent].needs_arrivals)
    return agent_class(agent)(env, **options, **thesis_hyperparameters(seed))


def run_agent(task: SettingTask) -> dict:
    """Train one agent of :data:`LEARNERS` in its setting (a task of :func:`setting_tasks`), measured.

    A throw-away agent is trained first, untimed (:func:`~.snapshot_runs.warm_up`); the run's
    result is :func:`~.snapshot_runs.measure`'s.
    """
    delay = make_delay(task.delay, task.lam)
    size, seed, steps = task.size, task.seed, task.steps
    warm_up(lambda: make_agent(task.agent, size, delay, seed + 1, steps), steps, task.agent)
    return measure(make_agent(task.agent, size, delay, seed, steps), steps, size)
