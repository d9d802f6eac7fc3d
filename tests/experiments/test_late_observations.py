"""``delayed-rl bench late-observations``: its tasks, shared runs, claims and files, tiny and quick."""

from __future__ import annotations

import json
import math

import pytest

from delayed_rl.experiments import LONG_NAMES, Config, get_experiment, run_experiment
from delayed_rl.experiments.beyond import late_observations
from delayed_rl.experiments.framework.experiment import VERDICTS
from delayed_rl.experiments.framework.late_training import METHODS, make_env
from delayed_rl.experiments.framework.pool import pool_key

pytestmark = pytest.mark.sb3


def test_the_full_run_has_every_setting_method_and_seed_and_shares_the_oracle():
    experiment = get_experiment("late-observations")
    assert "late-observations" in LONG_NAMES  # bench all --long, not the default bench all
    tasks = experiment.tasks(Config(seeds=5))
    settings, methods = late_observations.SETTINGS, late_observations.SETTING_METHODS
    seeds = {name: min(5, setting.get("seeds", 5)) for name, setting in settings.items()}
    assert len(tasks) == sum(len(methods[name]) * seeds[name] for name in settings)
    assert seeds["epuck"] >= 3 and set(methods["epuck"]) >= {*METHODS, "p-delayed"}
    oracles = [t for t in tasks if t.method == "oracle" and t.seed == 0]
    keys = {t.setting: pool_key(experiment.run_of(t)) for t in oracles}
    # one oracle for the 20k Pendulum settings, one for the 50k one, one for the e-puck
    assert keys["pendulum-small"] == keys["pendulum-large"] != keys["pendulum-large-50k"]
    assert len({keys["pendulum-small"], keys["pendulum-large-50k"], keys["epuck"]}) == 3
    delayed = [t for t in tasks if t.method == "hindsight" and t.seed == 0]
    assert len({pool_key(experiment.run_of(t)) for t in delayed}) == len(settings)
    assert {t.steps for t in tasks if t.method != "random"} == {20_000, 50_000}


def test_the_p_controller_is_scored_on_the_learners_delayed_observations():
    from delayed_rl.experiments.framework.late_training import controller_score

    task = {**late_observations.SETTINGS["epuck"], "seed": 0, "eval_episodes": 1}
    task["episode_steps"] = 300
    undelayed = controller_score({**task, "method": "p-undelayed"})["score"]
    delayed = controller_score({**task, "method": "p-delayed"})["score"]
    assert undelayed > 0.5 * 300 > delayed  # the delay costs the controller the line
    view = make_env(task, "hindsight").observation_space
    assert view["actions"].shape == (150, 2) and view["age"].n == 151  # K = D = the clip


def test_each_method_acts_in_its_own_env():
    task = late_observations.SETTINGS["pendulum-large"]
    assert make_env(task, "oracle").observation_space.shape == (3,)
    assert make_env(task, "naive").observation_space.shape == (3,)
    view = make_env(task, "hindsight").observation_space
    assert view["age"].n == 7 and view["actions"].shape == (10, 1)  # D = 6, K = 6 + 4
    assert make_env(task, "augmented").observation_space.shape == (3 + 7 + 10,)


@pytest.mark.experiment
def test_a_tiny_quick_run_scores_every_method_and_resumes(tmp_path):
    config = Config(quick=True, seeds=1, steps=150, workers=2)
    summary = run_experiment(get_experiment("late-observations"), config, tmp_path, False)
    assert summary.extra["runs"] == len(METHODS) + 1
    table = summary.extra["table"]["pendulum-small"]
    assert table["oracle"]["gain"]["mean"] == pytest.approx(1.0)  # the gain's scale
    assert set(table) == {*METHODS, "random"}
    payload = json.loads((tmp_path / "summary.json").read_text())
    for claim in payload["claims"]:
        assert claim["verdict"] in VERDICTS and claim["criterion"]
        assert math.isfinite(claim["mean"]) or claim["verdict"] == "inconclusive"
    targets = [c for c in summary.claims if c.thesis.startswith("target")]
    # the seeds' rule of each delay-specific learner, with its interval
    assert len(targets) == len(late_observations.LEARNERS)
    assert all(target.low is not None for target in targets)
    assert (tmp_path / "curves_pendulum-small.png").exists()
    again = run_experiment(get_experiment("late-observations"), config, tmp_path, False)
    assert [c.mean for c in again.claims] == [c.mean for c in summary.claims]
