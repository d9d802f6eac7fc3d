"""``roulette`` (thesis section 3.2, Tables 3.2–3.5): MMQ's credit assignment traced by hand.

A demonstration rather than a statistical experiment: the three rounds of the thesis's worked
example (:data:`ROUNDS`) are fed to :class:`~delayed_rl.agents.MultipleModelQLearning` through
its public ``update()``, and the Q-table after each round is compared with the thesis's tables
(:data:`THESIS_TABLES`); the rule of the verdicts is :func:`summarize`'s.
"""

from __future__ import annotations

import numpy as np

from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.claims import band_claim
from delayed_rl.experiments.framework.experiment import Config, Curve, Experiment, Summary
from delayed_rl.experiments.framework.task import Task
from delayed_rl.experiments.framework.training import ALPHA, GAMMA

EVEN, THIRTEEN = 0, 1
#: The worked example's MMQ: its optimistic initial value and λ̂max (its ``max_delay_estimate``)
#: (α and γ are the thesis's, :mod:`~delayed_rl.experiments.framework.training`).
Q_INIT, LAMBDA_MAX = 50.0, 2
ROUNDING = 0.005
"""Half the last decimal the thesis prints: the band of each Q-value."""
#: The wagers: (action, name in the report).
WAGERS = ((EVEN, "even"), (THIRTEEN, "13"))
#: (wager, payout received that round): round 1 bets even (its loss arrives 2 rounds later), round
#: 2 bets 13 and wins 35 at once, round 3 bets even and receives round 1's −1.
ROUNDS = ((EVEN, 0.0), (THIRTEEN, 35.0), (EVEN, -1.0))
#: Thesis Tables 3.3–3.5, as Q[λ̂][a] with a = (even, 13).
THESIS_TABLES = (
    ((49.50, 50.00), (50.00, 50.00), (50.00, 50.00)),
    ((49.50, 53.00), (53.00, 50.00), (50.00, 50.00)),
    ((49.22, 53.00), (53.00, 49.67), (49.67, 50.00)),
)


def tasks(config: Config) -> list[Task]:
    """One task: the walk-through is deterministic, so one seed (``config.base_seed``) is enough."""
    return [Task(seed=config.base_seed)]


def run_task(task: Task) -> dict:
    """Feed the three rounds to MMQ's ``update()``; return its Q-table after each round.

    Returns:
        ``tables``: shape (3 rounds, 3 estimates λ̂, 2 wagers).
    """
    from delayed_rl.agents import MultipleModelQLearning

    agent = MultipleModelQLearning(
        "delayed_rl/Roulette-v0",
        learning_rate=ALPHA,
        gamma=GAMMA,
        q_init=Q_INIT,
        max_delay_estimate=LAMBDA_MAX,
        seed=task.seed,
    )
    tables = []
    for wager, payout in ROUNDS:
        agent.update(0, wager, payout, 0)
        tables.append(agent.q_table[0].copy())
    return {"tables": np.array(tables)}


def summarize(task_list: list[Task], results: list[dict], config: Config) -> Summary:
    """One claim per Q-value of Tables 3.3–3.5: the thesis's value ± :data:`ROUNDING`.

    The walk-through is deterministic (no random draw enters ``update()``), so each Q-value is one
    exact number: its CI is 0 with n = 1, and the verdict is the band rule on the thesis's printed
    value ± :data:`ROUNDING` (half its last decimal): ``agrees`` when the value rounds to the
    thesis's, ``differs`` otherwise, never ``inconclusive``.
    """
    measured = results[0]["tables"]
    entries = [(lam_hat, action, name) for lam_hat in range(3) for action, name in WAGERS]
    claims = [
        band_claim(
            f"round {round_index + 1}: Q(bet {name}, λ̂ = {lam_hat})",
            f"{thesis[lam_hat][action]:.2f} (Table 3.{round_index + 3})",
            (float(table[lam_hat, action]), 0.0, 1),
            thesis[lam_hat][action],
            ROUNDING,
        )
        for round_index, (thesis, table) in enumerate(zip(THESIS_TABLES, measured, strict=True))
        for lam_hat, action, name in entries
    ]
    rounds = np.arange(1, len(ROUNDS) + 1)
    curves = [
        Curve(
            f"Q(bet {name}, lambda_hat={lam_hat})",
            config.base_seed,
            rounds,
            measured[:, lam_hat, action],
            "q_value",
        )
        for lam_hat, action, name in entries
    ]
    panels = {f"after round {i + 1} (Table 3.{i + 3})": table for i, table in enumerate(measured)}
    figures = {
        "tables_3_3_to_3_5": plotting.figure(
            plotting.value_tables,
            panels,
            "Roulette walk-through: MMQ's Q(s, a, λ̂) after each round, measured and thesis",
            "Q(s, a, λ̂)",
            [f"λ̂ = {lam_hat}" for lam_hat in range(3)],
            [f"bet {name}" for _, name in WAGERS],
            thesis=dict(zip(panels, THESIS_TABLES, strict=True)),
        )
    }
    return Summary(claims, curves, figures, {"tables": measured})


EXPERIMENT = Experiment(
    name="roulette",
    thesis="Tables 3.2–3.5",
    description="The thesis's Roulette walk-through: three wagers with delayed, overlapping "
    f"payouts, credited by MMQ (q_init = {Q_INIT:g}, α = {ALPHA}, γ = {GAMMA}, "
    f"λ̂max = {LAMBDA_MAX}) through update(). Deterministic: each Q-value is one exact number "
    f"(CI 0, n = 1), tested against the thesis's printed value ± {ROUNDING}.",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=1,
    quick_seeds=1,
)
