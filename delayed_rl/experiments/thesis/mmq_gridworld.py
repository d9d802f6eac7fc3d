"""``mmq-gridworld`` (thesis Figs. 5.9–5.15, Table 5.1): MMQ against Q-learning on a grid world.

MMQ and Q-learning under Poisson reward delays, and undelayed Q-learning, with the thesis's
hyper-parameters (:mod:`~delayed_rl.experiments.framework.training`); each run records at
snapshots whether its greedy policy is optimal. The numbers are the constants
``EXPERIMENT.description`` is formatted from (:data:`SIZE`, :data:`LAM`, :data:`STEPS`, ...);
what each run records is :func:`run_task`'s, the claims :func:`summarize`'s.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np

from delayed_rl._validation import check_probability
from delayed_rl.agents import MultipleModelQLearning
from delayed_rl.agents.common.q_table import greedy_actions
from delayed_rl.experiments.framework import plotting
from delayed_rl.experiments.framework.claims import (
    band_claim,
    count_claim,
    direction_claim,
    mean_ci_n,
    paired,
    range_claim,
    reference_row,
)
from delayed_rl.experiments.framework.experiment import (
    Claim,
    Config,
    Experiment,
    Summary,
    running_average,
    step_count,
)
from delayed_rl.experiments.framework.results import pivot
from delayed_rl.experiments.framework.snapshot_runs import (
    LOOP_FRACTION,
    SNAPSHOTS,
    WALK_STEPS,
    optimal_average,
    second_half_share,
    snapshot_curves,
    train_with_snapshots,
)
from delayed_rl.experiments.framework.task import Task
from delayed_rl.experiments.framework.training import (
    EPSILON,
    greedy_average_reward,
    grid_env,
    thesis_hyperparameters,
)

#: The grid world's side, the Poisson mean delay λ and MMQ's λ̂max (its ``max_delay_estimate``).
SIZE, LAM, LAMBDA_MAX = 9, 13, 50
#: The steps of a run, and of a quick run.
STEPS, QUICK_STEPS = 1_000_000, 100_000
#: The steps of the optimal loop: to the reward cell and back, +1.
LOOP_STEPS = 2 * (SIZE - 1) + 1
#: The bands of the claims: MMQ's greedy reward 0.59 ± this, "≈ 0" rewards 0 ± ``NEAR_ZERO``.
GREEDY_TOLERANCE, NEAR_ZERO = 0.06, 0.1
#: The true value of Q along the route (V* ≈ 2.2 on 9×9) and the spread Table 5.1 shows.
TRUE_ROUTE_Q, SPREAD_LIMIT = 2.2, 0.1
#: The thesis's greedy average rewards over 1000 steps (section 5.1.1: 0.59 and 0.00).
THESIS_GREEDY = {"MMQ": 0.59, "Q": 0.0}
#: The thesis's Table 5.1: the mean over λ̂ of Q along the greedy route, ≈ 21.4 in every row.
THESIS_ROUTE_Q = 21.4


@dataclasses.dataclass(frozen=True, kw_only=True)
class MMQGridTask(Task):
    """An agent's run of ``mmq-gridworld``.

    Attributes:
        agent: ``"MMQ"``, ``"Q"`` or ``"Q undelayed"``.
        delay_estimates: the delay estimates Λ it models (``(0,)``: Q-learning).
        lam: the Poisson mean delay λ (0: undelayed).
        steps: training steps.
    """

    agent: str
    delay_estimates: tuple[int, ...]
    lam: int
    steps: int


def tasks(config: Config) -> list[MMQGridTask]:
    """Per seed: MMQ (Λ = {0..λ̂max}) and Q-learning under Poisson(λ) delays, and undelayed Q.

    :data:`STEPS` a run (:data:`QUICK_STEPS` with ``config.quick``).
    """
    steps = config.run_steps(STEPS, QUICK_STEPS)
    estimates = {"MMQ": tuple(range(LAMBDA_MAX + 1)), "Q": (0,), "Q undelayed": (0,)}
    return [
        MMQGridTask(
            agent=agent,
            delay_estimates=estimates[agent],
            lam=0 if agent == "Q undelayed" else LAM,
            steps=steps,
            seed=config.base_seed + i,
        )
        for i in range(config.seeds)
        for agent in estimates
    ]


def _greedy_route(policy: np.ndarray) -> list[int]:
    """States the greedy ``policy`` visits from the start until the reward cell (≤ 2 size²)."""
    env = grid_env(SIZE, 0).unwrapped
    route, state = [], env.start_state
    for _ in range(2 * SIZE * SIZE):
        route.append(state)
        if state == 0:
            break
        state = int(env.next_state[state, policy[state]])
    return route


def behaviour_policy(q: np.ndarray, epsilon: float = EPSILON) -> np.ndarray:
    """P(a | s) of the two-level ε-greedy acting rule (thesis Figs. 5.12 and 5.15), shape (S, A).

    A greedy model (uniform among those holding the state's max) with probability 1 − ε, else a
    uniform model; then that model's greedy action (uniform among ties) with probability 1 − ε,
    else a uniform action.

    Args:
        q: the Q-table, shape ``(|S|, |Λ|, |A|)``.
        epsilon: the exploration rate ε of both levels, in [0, 1].
    """
    epsilon = check_probability("epsilon", epsilon)
    n_states, n_models, n_actions = q.shape
    model_best = q.max(axis=2)  # (S, Λ)
    holds_max = model_best == model_best.max(axis=1, keepdims=True)
    p_model = (1 - epsilon) * holds_max / holds_max.sum(axis=1, keepdims=True)
    p_model = p_model + epsilon / n_models if n_models > 1 else np.ones((n_states, 1))
    greedy = q == model_best[..., None]  # (S, Λ, A)
    p_action = (1 - epsilon) * greedy / greedy.sum(axis=2, keepdims=True) + epsilon / n_actions
    return (p_model[:, :, None] * p_action).sum(axis=1)  # Σ over models, in a fixed order


def run_task(task: MMQGridTask) -> dict:
    """Train one agent, then read off its curve, greedy score, visits, policies and Table 5.1 rows.

    The agent learns in :data:`~.snapshot_runs.SNAPSHOTS` pieces
    (:func:`~.snapshot_runs.train_with_snapshots`, which trains exactly as one ``learn`` call)
    and after each piece records whether the greedy policy is optimal (its walk scores
    :data:`~.snapshot_runs.LOOP_FRACTION` of the optimal loop). The greedy policy of a learner
    under delays can keep flipping between the optimal loop and another route, so the final
    greedy policy is one draw of that: the report gives both the count of seeds whose final
    greedy policy is optimal (k of n) and, per seed, the share of second-half snapshots that
    are optimal.

    Returns:
        ``steps`` and ``curve`` (the running average reward), ``average`` (over the run),
        ``greedy`` (the final greedy policy's average reward over :data:`WALK_STEPS` steps), ``optimal``
        (whether that is the optimal loop), ``snapshot_steps`` and ``snapshot_optimal`` (per
        snapshot), ``second_half_optimal`` (the share of snapshots after half the steps that
        are optimal), ``visits`` (per cell), ``policy`` (greedy action per cell),
        ``route_table`` (per state of the greedy route: state, action, mean and variance over
        λ̂ of its Q-value), ``behaviour`` (the ε-greedy P(a | s) per action and cell) and
        ``model_share`` (how often each λ̂ acted).
    """
    agent = MultipleModelQLearning(
        grid_env(SIZE, task.lam),
        delay_estimates=list(task.delay_estimates),
        **thesis_hyperparameters(task.seed),
    )
    run = train_with_snapshots(agent, task.steps, SIZE, keep_obs=True)
    q = agent.q_table
    steps, curve = running_average(run["rewards"])
    policy = greedy_actions(q)
    table = [
        (s, int(policy[s]), float(q[s, :, policy[s]].mean()), float(q[s, :, policy[s]].var()))
        for s in _greedy_route(policy)
    ]
    greedy = greedy_average_reward(agent, SIZE, WALK_STEPS)
    return {
        "steps": steps,
        "curve": curve,
        "average": float(run["rewards"].mean()),
        "greedy": greedy,
        "optimal": bool(run["snapshot_optimal"][-1]),
        "snapshot_steps": run["snapshot_steps"],
        "snapshot_optimal": run["snapshot_optimal"],
        "second_half_optimal": second_half_share(
            run["snapshot_steps"], run["snapshot_optimal"], task.steps
        ),
        "visits": np.bincount(run["obs"], minlength=SIZE * SIZE).reshape(SIZE, SIZE),
        "policy": policy.reshape(SIZE, SIZE),
        "route_table": table,
        "behaviour": behaviour_policy(q).T.reshape(4, SIZE, SIZE),
        "model_share": agent.acting_delay_share,
    }


#: The quantity of the second-half snapshot rows, and the note of the seed-count rows.
_LATE = "share of second-half greedy snapshots optimal"
_LOOP = f"optimal: a {WALK_STEPS}-step greedy walk ≥ {LOOP_FRACTION} of the {LOOP_STEPS}-step loop"
#: The note of the second-half snapshot rows.
_PER_SEED = "per seed, the share of its snapshots after half the steps"


def summarize(task_list: list[MMQGridTask], results: list[dict], config: Config) -> Summary:
    """Fig. 5.9's and Table 5.1's claims, curves and figures.

    The claims (verdicts by :mod:`~.framework.claims`' rules; each row's ``criterion`` states
    its own):

    - MMQ's greedy average reward against the thesis's (:data:`THESIS_GREEDY`)
      ± :data:`GREEDY_TOLERANCE`; Q's against 0 ± :data:`NEAR_ZERO`;
    - MMQ's seeds whose final greedy policy is optimal, and MMQ's second-half snapshot share:
      more than half ([0.5, 1]; the thesis's "near-optimal"); Q's: less than half ([0, 0.5]);
    - MMQ minus Q average reward during learning, paired by seed: above 0 (Fig. 5.9); Q's
      average reward during learning against 0 ± :data:`NEAR_ZERO`;
    - Table 5.1: the mean over λ̂ of Q along the greedy route above twice the true value
      (:data:`TRUE_ROUTE_Q`; the thesis's :data:`THESIS_ROUTE_Q` is inflated by the max over
      models; its size follows ``q_init``), and the spread across λ̂ (std / mean) below
      :data:`SPREAD_LIMIT` (the thesis's ≈ 0.04: the models agree);
    - ``reference`` rows: MMQ's average reward during learning, and undelayed Q-learning's
      greedy and training rewards and snapshot share.
    """
    by_agent = {
        agent: list(runs.values())
        for agent, runs in pivot(task_list, results, by=("agent",)).items()
    }
    training = pivot(task_list, results, by=("agent",), value="average")
    curves = [
        curve
        for task, result in zip(task_list, results, strict=True)
        for curve in snapshot_curves(task.agent, task.seed, result)
    ]
    keys = ("average", "greedy", "second_half_optimal")
    stat = {
        agent: {key: mean_ci_n([r[key] for r in runs]) for key in keys}
        for agent, runs in by_agent.items()
    }
    optimal_seeds = {a: sum(r["optimal"] for r in runs) for a, runs in by_agent.items()}
    claims = [
        *_greedy_claims(stat, optimal_seeds, {a: len(runs) for a, runs in by_agent.items()}),
        *_training_claims(stat, training),
        *_undelayed_rows(stat, optimal_seeds, len(by_agent["Q undelayed"])),
        *_route_claims(by_agent["MMQ"]),
    ]
    extra = _statistics(by_agent, optimal_seeds)
    return Summary(claims, curves, _figures(by_agent, stat), extra)


def _greedy_claims(stat: dict, optimal_seeds: dict, seeds: dict[str, int]) -> list[Claim]:
    """MMQ's and Q's final greedy rewards, seeds optimal at the end, and second-half snapshots.

    Args:
        stat: each agent's ``(mean, ci, n)`` of each claim key.
        optimal_seeds: each agent's count of seeds whose final greedy policy is optimal.
        seeds: each agent's count of seeds.
    """
    return [
        band_claim(
            f"MMQ greedy average reward ({WALK_STEPS} steps)",
            "0.59 (near-optimal; optimum 0.588)",
            stat["MMQ"]["greedy"],
            THESIS_GREEDY["MMQ"],
            GREEDY_TOLERANCE,
        ),
        count_claim(
            "MMQ seeds whose final greedy policy is optimal",
            "near-optimal: most seeds",
            optimal_seeds["MMQ"],
            seeds["MMQ"],
            0.5,
            note=_LOOP,
        ),
        range_claim(
            f"MMQ {_LATE}",
            "near-optimal: most of the time",
            stat["MMQ"]["second_half_optimal"],
            0.5,
            1.0,
            note=_PER_SEED,
        ),
        band_claim(
            f"Q greedy average reward ({WALK_STEPS} steps)",
            "0.00 (loops in the centre)",
            stat["Q"]["greedy"],
            THESIS_GREEDY["Q"],
            NEAR_ZERO,
        ),
        count_claim(
            "Q seeds whose final greedy policy is optimal",
            "≈ 0: few seeds",
            optimal_seeds["Q"],
            seeds["Q"],
            0.0,
            0.5,
            note=_LOOP,
        ),
        range_claim(
            f"Q {_LATE}", "≈ 0: rarely", stat["Q"]["second_half_optimal"], 0.0, 0.5, note=_PER_SEED
        ),
    ]


def _training_claims(stat: dict, training: dict[str, dict[int, float]]) -> list[Claim]:
    """Fig. 5.9 during learning: MMQ's reward (a reference), MMQ above Q by seed, Q's ≈ 0."""
    return [
        reference_row(
            "MMQ average reward during learning",
            stat["MMQ"]["average"],
            "near-optimal, above Q (Fig. 5.9; tested in the next row)",
        ),
        direction_claim(
            "MMQ minus Q average reward during learning (paired by seed)",
            "MMQ above Q (Fig. 5.9)",
            mean_ci_n(paired(training["MMQ"], training["Q"])),
            "above",
        ),
        band_claim(
            "Q average reward during learning",
            "≈ 0 (Fig. 5.9)",
            stat["Q"]["average"],
            0.0,
            NEAR_ZERO,
        ),
    ]


def _undelayed_rows(stat: dict, optimal_seeds: dict, seeds: int) -> list[Claim]:
    """Undelayed Q-learning's training and greedy rewards and snapshots, as reference rows."""
    undelayed = stat["Q undelayed"]
    return [
        reference_row("undelayed Q average reward during learning", undelayed["average"]),
        reference_row(
            f"undelayed Q greedy average reward ({WALK_STEPS} steps)",
            undelayed["greedy"],
            note=f"{optimal_seeds['Q undelayed']} of {seeds} seeds optimal at the end",
        ),
        reference_row(f"undelayed Q {_LATE}", undelayed["second_half_optimal"]),
    ]


def _route_claims(mmq: list[dict]) -> list[Claim]:
    """Table 5.1 over MMQ's seeds: Q along the greedy route (mean over λ̂), and its spread."""
    route_means = [np.mean([row[2] for row in r["route_table"]]) for r in mmq]
    route_spread = [
        np.mean([np.sqrt(row[3]) / abs(row[2]) for row in r["route_table"]]) for r in mmq
    ]
    return [
        direction_claim(
            "Table 5.1: mean over λ̂ of Q along the greedy route",
            f"≈ {THESIS_ROUTE_Q} (inflated above the true ≈ {TRUE_ROUTE_Q} by the max over models)",
            mean_ci_n(route_means),
            "above",
            2 * TRUE_ROUTE_Q,
            note="the test: well above (twice) the true value, as in the thesis; its size "
            "follows q_init and the delay",
        ),
        direction_claim(
            "Table 5.1: spread across λ̂ (std / mean) along the route",
            f"≈ 0.04 (√0.75 / {THESIS_ROUTE_Q}: the models agree, Eq. 5.5)",
            mean_ci_n(route_spread),
            "below",
            SPREAD_LIMIT,
        ),
    ]


def _statistics(by_agent: dict[str, list[dict]], optimal_seeds: dict) -> dict:
    """``summary.json``'s extra: Table 5.1 of the first seed, MMQ's model share, optimal seeds."""
    mmq = by_agent["MMQ"]
    table51 = [
        {"state": s + 1, "action": a + 1, "mean_q": m, "var_q": v}
        for s, a, m, v in mmq[0]["route_table"]
    ]
    share = np.mean([r["model_share"] for r in mmq], axis=0)
    return {
        "table_5_1_first_seed": table51,
        "mmq_model_share": share,
        "most_used_estimate": int(np.argmax(share)),
        "optimal_seeds": {a: [int(k), len(by_agent[a])] for a, k in optimal_seeds.items()},
        "snapshots": SNAPSHOTS,
        "loop_fraction": LOOP_FRACTION,
    }


#: Every figure's setting, in its title.
_SETTING = f"{SIZE}×{SIZE}, Poisson delays of mean λ = {LAM}, MMQ with Λ = {{0..{LAMBDA_MAX}}}"


def _figures(by_agent: dict[str, list[dict]], stat: dict[str, dict]) -> dict:
    """Figs. 5.9–5.15 and Table 5.1: curves, greedy rewards, route Q, visits and policies.

    Args:
        by_agent: each agent's run results.
        stat: each agent's ``(mean, ci, n)`` of ``"greedy"`` (and the other claim keys).
    """
    groups = {a: [(r["steps"], r["curve"]) for r in runs] for a, runs in by_agent.items()}
    first = {a: runs[0] for a, runs in by_agent.items()}
    optimum = optimal_average(SIZE)
    return {
        "fig5_9_mmq_vs_q": plotting.figure(
            plotting.learning_curves,
            groups,
            f"{_SETTING}: average reward during learning (Fig. 5.9)\n"
            "thesis: MMQ near-optimal (below the loop only by ε's exploration), Q ≈ 0",
            "average reward",
            [
                (optimum, f"thesis: MMQ near-optimal; optimal loop 10/17 = {optimum:.3f}", "MMQ"),
                (THESIS_GREEDY["Q"], "thesis Q ≈ 0 (Fig. 5.9)", "Q"),
            ],
        ),
        "greedy_average_reward": plotting.figure(
            plotting.value_bars,
            {a: stat[a]["greedy"] for a in by_agent},
            f"{_SETTING}: the final greedy policy's average reward over {WALK_STEPS} steps",
            "greedy average reward",
            {a: (v, f"thesis {a} {v:.2f} (section 5.1.1)") for a, v in THESIS_GREEDY.items()},
        ),
        "table5_1_route_q": _route_figure(first["MMQ"]["route_table"]),
        **_visit_figures(by_agent),
        "greedy_optimal_snapshots": plotting.figure(
            plotting.band_plot,
            {
                a: [(r["snapshot_steps"], r["snapshot_optimal"]) for r in runs]
                for a, runs in by_agent.items()
            },
            f"{_SETTING}: share of seeds whose greedy policy is optimal\n"
            "thesis: MMQ's greedy policy near-optimal (most seeds), Q's ≈ 0 (loops in the centre)",
            "time step",
            "share of seeds optimal",
            (-0.05, 1.05),
        ),
        **_policy_figures(first),
    }


def _route_figure(route: list[tuple]) -> Callable[[Path], None]:
    """Table 5.1: Q(s, a*, λ̂) along MMQ's greedy route (first seed), mean ± std over λ̂."""
    return plotting.figure(
        plotting.errorbar_curve,
        np.arange(len(route)),
        [row[2] for row in route],
        [np.sqrt(row[3]) for row in route],
        f"{_SETTING}: Q(s, a*, λ̂) along MMQ's greedy route, first seed (Table 5.1)",
        "state along the greedy route (thesis numbering; a* its greedy action)",
        "Q(s, a*, λ̂)",
        thesis=[
            (None, THESIS_ROUTE_Q, f"thesis ≈ {THESIS_ROUTE_Q} in every row (Table 5.1)"),
            (None, TRUE_ROUTE_Q, f"true value ≈ {TRUE_ROUTE_Q} (V* of the route)"),
        ],
        label="measured: mean ± std over λ̂",
        xticklabels=[str(row[0] + 1) for row in route],
    )


def _visit_figures(by_agent: dict[str, list[dict]]) -> dict:
    """Figs. 5.10–5.11: state visits (mean over seeds), and the first seed's greedy policies."""
    visits = {a: np.mean([r["visits"] for r in runs], axis=0) for a, runs in by_agent.items()}
    first = {a: runs[0] for a, runs in by_agent.items()}
    n = len(by_agent["MMQ"])
    return {
        "fig5_10_visits": plotting.figure(
            plotting.grid_heatmap,
            visits,
            f"{_SETTING}: state visits during learning, mean over {n} seeds (Fig. 5.10)",
            "visits per cell (mean over seeds)",
        ),
        "fig5_11_policies": plotting.figure(
            plotting.grid_heatmap,
            {a: r["visits"] for a, r in first.items()},
            f"{_SETTING}: deterministic greedy policies (arrows), first seed (Fig. 5.11)",
            "visits per cell during learning (first seed)",
            arrows={a: r["policy"] for a, r in first.items()},
        ),
    }


def _policy_figures(first: dict[str, dict]) -> dict:
    """Figs. 5.12 and 5.15: each agent's ε-greedy P(a | s) per direction, first seed."""
    directions = ("P(up)", "P(right)", "P(down)", "P(left)")
    figures = {}
    for agent, result in first.items():
        panels = dict(zip(directions, result["behaviour"], strict=True))
        title = f"{agent}: probabilistic (ε-greedy) policy, first seed (Figs. 5.12, 5.15)\n{_setting_of(agent)}"
        figures[f"fig5_12_15_probabilistic_policy_{agent.replace(' ', '_')}"] = plotting.figure(
            plotting.grid_heatmap,
            panels,
            title,
            f"P(a | s) of the ε-greedy rule, ε = {EPSILON}",
            vmin=0.0,
            vmax=1.0,
            columns=2,
        )
    return figures


def _setting_of(agent: str) -> str:
    """One agent's setting in a title: ``"9×9, Poisson delays of mean λ = 13, Λ = {0..50}"``."""
    delay = "no reward delay" if agent == "Q undelayed" else f"Poisson delays of mean λ = {LAM}"
    models = f", Λ = {{0..{LAMBDA_MAX}}}" if agent == "MMQ" else ""
    return f"{SIZE}×{SIZE}, {delay}{models}"


EXPERIMENT = Experiment(
    name="mmq-gridworld",
    thesis="Figs. 5.9–5.15, Table 5.1",
    description=f"Multiple Model Q-learning (Λ = {{0..{LAMBDA_MAX}}}) against Q-learning on the "
    f"{SIZE}×{SIZE} grid world with Poisson({LAM}) reward delays (and undelayed Q-learning), "
    f"{step_count(STEPS)} steps; greedy evaluation over {WALK_STEPS} steps, at the end and at "
    f"{SNAPSHOTS} snapshots during learning (optimal: ≥ {LOOP_FRACTION} of the {LOOP_STEPS}-step "
    "loop); Table 5.1's mean and variance of Q across λ̂ along the greedy route (summary.json).",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=20,
)
