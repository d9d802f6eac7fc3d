"""``mmq-gridworld`` (thesis Figs. 5.9–5.15, Table 5.1): MMQ vs Q-learning on 9×9, λ = 13."""

from __future__ import annotations

import numpy as np

from delayed_rl._validation import check_probability
from delayed_rl.agents.mmq import greedy_actions
from delayed_rl.experiments import plotting
from delayed_rl.experiments.common import claim, mean_ci_n
from delayed_rl.experiments.runner import Config, Curve, Experiment, Summary, running_average
from delayed_rl.experiments.training import EPSILON, greedy_average_reward, grid_env, train

SIZE, LAM, LAMBDA_MAX = 9, 13, 50
LOOP_FRACTION = 0.95
"""A greedy average this close to 10/17 means the optimal 17-step loop: over 1000 steps that loop
scores 58 rewards (0.580, 0.986 of 10/17), the next shortest, 19 steps, 0.895 of it."""


def tasks(config: Config) -> list[dict]:
    """Per seed: MMQ (Λ = {0..50}) and Q-learning under Poisson(13) delays, and undelayed Q.

    1M steps a run (100k with ``config.quick``).
    """
    steps = config.steps or (100_000 if config.quick else 1_000_000)
    lags = {"MMQ": list(range(LAMBDA_MAX + 1)), "Q": [0], "Q undelayed": [0]}
    return [
        {
            "agent": agent,
            "lags": lags[agent],
            "lam": 0 if agent == "Q undelayed" else LAM,
            "steps": steps,
            "seed": config.base_seed + i,
        }
        for i in range(config.seeds)
        for agent in lags
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
    return np.einsum("sm,sma->sa", p_model, p_action)


def run_task(task: dict) -> dict:
    """Train one agent, then read off its curve, greedy score, visits, policies and Table 5.1 rows.

    Returns:
        ``steps`` and ``curve`` (the running average reward), ``average`` (over the run),
        ``greedy`` (the greedy policy's average reward over 1000 steps), ``visits`` (per cell),
        ``policy`` (greedy action per cell), ``route_table`` (per state of the greedy route:
        state, action, mean and variance over λ̂ of its Q-value), ``behaviour`` (the ε-greedy
        P(a | s) per action and cell) and ``model_share`` (how often each λ̂ acted).
    """
    agent = train(grid_env(SIZE, task["lam"]), task["lags"], task["steps"], task["seed"])
    log, q = agent.training_log, agent.q_table
    steps, curve = running_average(log["undelayed_reward"])
    policy = greedy_actions(q)
    table = [
        (s, int(policy[s]), float(q[s, :, policy[s]].mean()), float(q[s, :, policy[s]].var()))
        for s in _greedy_route(policy)
    ]
    return {
        "steps": steps,
        "curve": curve,
        "average": float(log["undelayed_reward"].mean()),
        "greedy": greedy_average_reward(agent, SIZE, 1000),
        "visits": np.bincount(log["obs"], minlength=SIZE * SIZE).reshape(SIZE, SIZE),
        "policy": policy.reshape(SIZE, SIZE),
        "route_table": table,
        "behaviour": behaviour_policy(q).T.reshape(4, SIZE, SIZE),
        "model_share": agent.acting_delay_share,
    }


def summarize(task_list: list[dict], results: list[dict], config: Config) -> Summary:
    """Fig. 5.9's and Table 5.1's claims: MMQ's greedy policy near-optimal, Q's near zero."""
    by_agent: dict[str, list[dict]] = {}
    for task, result in zip(task_list, results, strict=True):
        by_agent.setdefault(task["agent"], []).append(result)
    curves = [
        Curve(t["agent"], t["seed"], r["steps"], r["curve"])
        for t, r in zip(task_list, results, strict=True)
    ]
    stat = {
        agent: {key: mean_ci_n([r[key] for r in runs]) for key in ("average", "greedy")}
        for agent, runs in by_agent.items()
    }
    mmq = by_agent["MMQ"]
    optimal = 10 / (2 * (SIZE - 1) + 1)
    loops = sum(r["greedy"] >= LOOP_FRACTION * optimal for r in mmq)
    route_means = [np.mean([row[2] for row in r["route_table"]]) for r in mmq]
    route_spread = [
        np.mean([np.sqrt(row[3]) / abs(row[2]) for row in r["route_table"]]) for r in mmq
    ]
    claims = [
        claim(
            "MMQ greedy average reward (1000 steps)",
            "0.59 (near-optimal; optimum 0.588)",
            stat["MMQ"]["greedy"],
            ok=stat["MMQ"]["greedy"][0] >= 0.9 * optimal,
            note=f"{loops} of {len(mmq)} seeds' greedy policies walk the optimal 17-step loop",
        ),
        claim(
            "Q greedy average reward (1000 steps)",
            "0.00 (loops in the centre)",
            stat["Q"]["greedy"],
            ok=stat["Q"]["greedy"][0] <= 0.1,
        ),
        claim(
            "MMQ average reward during learning",
            "near-optimal, above Q (Fig. 5.9)",
            stat["MMQ"]["average"],
            ok=stat["MMQ"]["average"][0] > stat["Q"]["average"][0],
        ),
        claim(
            "Q average reward during learning",
            "≈ 0 (Fig. 5.9)",
            stat["Q"]["average"],
            ok=stat["Q"]["average"][0] <= 0.1,
        ),
        claim(
            "undelayed Q average reward during learning",
            "reference",
            stat["Q undelayed"]["average"],
            ok=True,
        ),
        claim(
            "Table 5.1: mean over λ̂ of Q along the greedy route",
            "≈ 21.4 (inflated above the true ≈ 2.2 by the max over models)",
            mean_ci_n(route_means),
            ok=float(np.mean(route_means)) > 2 * 2.2,
            note="agrees when well above the true value, as in the thesis; its size follows "
            "q_init and the delay",
        ),
        claim(
            "Table 5.1: spread across λ̂ (std / mean) along the route",
            "≈ 0.04 (√0.75 / 21.4: the models agree, Eq. 5.5)",
            mean_ci_n(route_spread),
            ok=float(np.mean(route_spread)) < 0.1,
        ),
    ]
    table51 = [
        {"state": s + 1, "action": a + 1, "mean_q": m, "var_q": v}
        for s, a, m, v in mmq[0]["route_table"]
    ]
    share = np.mean([r["model_share"] for r in mmq], axis=0)
    extra = {
        "table_5_1_first_seed": table51,
        "mmq_model_share": share,
        "most_used_estimate": int(np.argmax(share)),
    }
    return Summary(claims, curves, _figures(by_agent), extra)


def _figures(by_agent: dict[str, list[dict]]) -> dict:
    """Figs. 5.9–5.15: learning curves, visits, greedy and ε-greedy policies of each agent."""
    groups = {a: [(r["steps"], r["curve"]) for r in runs] for a, runs in by_agent.items()}
    visits = {a: np.mean([r["visits"] for r in runs], axis=0) for a, runs in by_agent.items()}
    first = {a: runs[0] for a, runs in by_agent.items()}
    figures = {
        "fig5_9_mmq_vs_q": plotting.figure(
            plotting.learning_curves,
            groups,
            "9×9, λ = 13: MMQ vs Q-learning (Fig. 5.9)",
            "average reward",
        ),
        "fig5_10_visits": plotting.figure(
            plotting.grid_heatmap, visits, "State visits during learning (Fig. 5.10)"
        ),
        "fig5_11_policies": plotting.figure(
            plotting.grid_heatmap,
            {a: r["visits"] for a, r in first.items()},
            "Deterministic greedy policies, first seed (Fig. 5.11)",
            arrows={a: r["policy"] for a, r in first.items()},
        ),
    }
    directions = ("P(up)", "P(right)", "P(down)", "P(left)")
    for agent, result in first.items():
        panels = dict(zip(directions, result["behaviour"], strict=True))
        title = f"{agent}: probabilistic (ε-greedy) policy, first seed (Figs. 5.12, 5.15)"
        figures[f"fig5_12_15_probabilistic_policy_{agent.replace(' ', '_')}"] = plotting.figure(
            plotting.grid_heatmap, panels, title
        )
    return figures


EXPERIMENT = Experiment(
    name="mmq-gridworld",
    thesis="Figs. 5.9–5.15, Table 5.1",
    description="Multiple Model Q-learning (Λ = {0..50}) against Q-learning on the 9×9 grid world "
    "with Poisson(13) reward delays, 1M steps; greedy evaluation over 1000 steps; Table 5.1's mean "
    "and variance of Q across λ̂ along the greedy route (summary.json).",
    tasks=tasks,
    run_task=run_task,
    summarize=summarize,
    default_seeds=5,
)
