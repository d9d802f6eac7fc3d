"""``delayed-rl bench deep-rl``: its tasks, shared runs, claims and files, in a tiny quick run."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from delayed_rl.experiments import Config, get_experiment, run_experiment
from delayed_rl.experiments.beyond import deep_rl
from delayed_rl.experiments.framework.deep_training import METHODS, MODEL_METHODS
from delayed_rl.experiments.framework.experiment import VERDICTS
from delayed_rl.experiments.framework.pool import pool_key

pytestmark = pytest.mark.sb3


def test_the_full_run_has_every_setting_method_and_seed_and_shares_the_oracle():
    experiment = get_experiment("deep-rl")
    tasks = experiment.tasks(Config(seeds=experiment.default_seeds))
    methods, settings = deep_rl.SETTING_METHODS, deep_rl.SETTINGS
    seeds = {name: setting["seeds"] for name, setting in settings.items()}
    assert seeds["pendulum1000-poisson20"] >= 10 and min(seeds.values()) >= 5
    assert len(tasks) == sum(len(methods[name]) * seeds[name] for name in settings)
    assert "ircr" not in methods["cartpole-poisson20"]  # off-policy only
    assert set(methods["pendulum1000-upright"]) == {*METHODS, "random"}
    assert "return-regression" not in methods["pendulum-poisson5"]
    sac = [t for t in tasks if t.algorithm == "SAC" and t.method != "random"]
    assert all(experiment.run_of(t).task["warmup_episodes"] == 2 for t in sac)
    keys = {pool_key(experiment.run_of(task)): task for task in tasks}
    oracles = [t for t in tasks if t.method == "oracle" and t.seed == 0]
    shared = {pool_key(experiment.run_of(t)) for t in oracles}
    # the three 200-step Pendulum settings share one oracle run; the others do not
    assert len(oracles) == len(settings) and len(shared) == len(settings) - 2
    delayed = [t for t in tasks if t.method == "raw" and t.seed == 0]
    assert len({pool_key(experiment.run_of(t)) for t in delayed}) == len(settings)
    trained = sum((len(methods[name]) - 1) * seeds[name] for name in settings)  # but random
    # the 200-step settings share an oracle (5 seeds); random: one per env, reward and seed
    randoms = {
        (s["env_id"], s["episode_steps"], s.get("reward")): s["seeds"] for s in settings.values()
    }
    assert len(keys) == trained - 2 * 5 + sum(randoms.values())
    assert {len(experiment.tasks(Config(seeds=2))) // 2} == {
        sum(len(methods[name]) for name in settings)
    }  # --seeds caps every setting


@pytest.mark.experiment
def test_a_tiny_quick_run_scores_every_method_and_resumes(tmp_path):
    config = Config(quick=True, seeds=1, steps=300, workers=2)
    summary = run_experiment(get_experiment("deep-rl"), config, tmp_path, False)
    methods = deep_rl.SETTING_METHODS
    assert summary.extra["runs"] == sum(len(methods[name]) for name in deep_rl.QUICK)
    assert len(list((tmp_path / "runs").glob("*.json"))) == summary.extra["runs"]
    table = summary.extra["table"]
    assert set(table) == set(deep_rl.QUICK)
    for name, rows in table.items():
        assert set(rows) == set(methods[name])
        assert rows["oracle"]["gain"]["mean"] == pytest.approx(1.0)  # the gain's scale
        for method in (m for m in MODEL_METHODS if m in rows):
            assert np.isfinite(rows[method]["rmse"]["values"]).all()
            assert rows[method]["rmse"]["mean"] > 0
        for method in ("deconv-known", "deconv-learned"):
            assert all(0 <= d <= 60 for d in rows[method]["mean_delay"]["values"])
        known = rows["deconv-known"]["mean_delay"]["values"]
        assert known == pytest.approx([20.0], abs=1e-3)  # Poisson(20)'s mean, clipped at 60
    payload = json.loads((tmp_path / "summary.json").read_text())
    for claim in payload["claims"]:
        assert claim["verdict"] in VERDICTS and claim["criterion"]
        assert math.isfinite(claim["mean"]) or claim["verdict"] == "inconclusive"
    targets = [c for c in summary.claims if c.thesis.startswith("target")]
    assert len(targets) == 5  # Pendulum Poisson(20): three, CartPole: two
    curves = [c for c in summary.curves if c.condition == "pendulum-poisson20/raw"]
    assert [c.steps[0] for c in curves] == [0] and [c.steps[-1] for c in curves] == [300]
    assert sorted(p.name for p in tmp_path.glob("*.png")) == [
        f"curves_{setting}.png" for setting in sorted(deep_rl.QUICK)
    ]
    again = run_experiment(get_experiment("deep-rl"), config, tmp_path, False)
    assert [c.mean for c in again.claims] == [c.mean for c in summary.claims]
    assert again.extra["run_seconds"] == summary.extra["run_seconds"]  # read back, not re-run
