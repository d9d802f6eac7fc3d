"""The ``delayed-rl`` commands: the train/evaluate round trip, exit codes and messages.

``bench`` runs are tested with the experiments (``tests/experiments/``), their
progress bar here.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tracemalloc
import zipfile
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest

from delayed_rl.agents import (
    DeconvolutionQLearning,
    ExpectedCreditQLearning,
    MultipleModelQLearning,
    QLearning,
    load_agent,
)
from delayed_rl.agents.registry import REGISTRY
from delayed_rl.cli import main

GRID = "delayed_rl/GridWorld-3x3-v0"


def _train(tmp_path, *extra: str) -> list[str]:
    """Train on the 3×3 grid under a Poisson(3) reward delay and save to ``tmp_path/agent``."""
    options = f"--env {GRID} --reward-delay 3 --steps 30000 --seed 0 --no-progress"
    return ["train", *options.split(), "--save", str(tmp_path / "agent"), *extra]


#: A ``train`` command line to append one bad option to (it never gets to train).
TRAIN = f"train --env {GRID} --agent q --save x "


def _average(text: str, unit: str) -> float:
    match = re.search(rf"(-?\d+\.\d+) per {unit}", text)
    assert match, text
    return float(match.group(1))


def test_train_saves_an_agent_that_evaluate_runs_greedily(tmp_path, capsys):
    assert main(_train(tmp_path, "--agent", "q")) == 0
    out = capsys.readouterr().out
    assert "trained QLearning on delayed_rl/GridWorld-3x3-v0" in out and "λ = 3" in out
    assert str(tmp_path / "agent.npz") in out
    training_average = _average(out, "step")
    assert 0.5 < training_average <= 2.0  # learned something; 2.0 = +10 every 5 steps (optimal)
    agent = load_agent(tmp_path / "agent.npz")
    assert isinstance(agent, QLearning) and agent.num_timesteps == 30_000
    assert agent.gamma == 0.9 and agent.exploration_rate == 0.1

    options = f"--env {GRID} --reward-delay 3 --steps 500 --seed 1"
    argv = ["evaluate", str(tmp_path / "agent.npz"), *options.split()]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "for 500 steps" in out and "no episode ended" in out
    # evaluate reports the greedy policy's own average: replay it here, on the same seed.
    env = gym.make(GRID, reward_delay=3)
    obs, _ = env.reset(seed=1)
    total = 0.0
    for _ in range(500):
        obs, _, terminated, truncated, info = env.step(agent.predict(obs, deterministic=True)[0])
        total += info["undelayed_reward"]
        assert not (terminated or truncated)
    assert _average(out, "step") == pytest.approx(total / 500, abs=5e-5)


def test_train_passes_the_agent_options(tmp_path, capsys):
    options = "--agent mmq --max-delay-estimate 6 --learning-rate 0.2 --gamma 0.8 --epsilon 0.05"
    assert main(_train(tmp_path, *options.split(), "--q-init", "10")) == 0
    agent = load_agent(tmp_path / "agent.npz")
    assert isinstance(agent, MultipleModelQLearning)
    assert agent.delay_estimates == list(range(7))
    assert (agent.current_learning_rate, agent.gamma, agent.exploration_rate) == (0.2, 0.8, 0.05)
    assert agent.q_init == 10.0
    capsys.readouterr()
    assert main(_train(tmp_path, "--agent", "fixed", "--delay-estimate", "3")) == 0
    assert load_agent(tmp_path / "agent.npz").delay_estimates == [3]


def test_evaluate_counts_episodes_on_an_episodic_env(tmp_path, capsys):
    env = "delayed_rl/EPuckLineFollow-v0"
    options = f"--env {env} --agent q --steps 500 --seed 0 --no-progress"
    argv = ["train", *options.split(), "--save", str(tmp_path / "line")]
    assert main(argv) == 0
    capsys.readouterr()
    assert main(["evaluate", str(tmp_path / "line.npz"), "--env", env, "--episodes", "2"]) == 0
    out = capsys.readouterr().out
    assert "over 2 episode(s)" in out
    per_step, per_episode = _average(out, "step"), _average(out, "episode")
    steps = int(re.search(r"for (\d+) steps", out).group(1))
    # both are printed to 4 decimals: the per-step mean's rounding grows with the steps
    assert per_episode == pytest.approx(per_step * steps / 2, abs=1e-4 * (steps / 2 + 1))
    assert -1.0 <= per_step <= 1.0  # Eq. 5.7 rewards


def test_evaluate_with_episodes_on_a_continuing_env_fails_clearly(tmp_path, capsys):
    assert main(_train(tmp_path, "--agent", "q", "--steps", "100")) == 0
    capsys.readouterr()
    argv = [
        "evaluate",
        str(tmp_path / "agent.npz"),
        "--env",
        GRID,
        "--max-eval-episode-steps",
        "50",
    ]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: no episode") and "--steps" in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("command", "message"),
    [
        ("frobnicate", "invalid choice: 'frobnicate'"),
        (
            "train --env delayed_rl/GridWorld-3x3 --agent q --save x",
            "unknown env id 'delayed_rl/GridWorld-3x3'; did you mean delayed_rl/GridWorld-3x3-v0",
        ),
        (f"train --env {GRID} --agent no-such-agent --save x", "invalid choice: 'no-such-agent'"),
        (f"train --env {GRID} --agent q", "the following arguments are required: --save"),
        # a value of the wrong type (the checks' TypeError) and one out of range (ValueError)
        (TRAIN + "--steps abc", "argument --steps: must be an integer >= 1, got 'abc' (str)"),
        (TRAIN + "--steps 2.5", "argument --steps: must be an integer >= 1, got '2.5' (str)"),
        (TRAIN + "--steps 0", "argument --steps: must be an integer >= 1, got 0"),
        (TRAIN + "--gamma high", "argument --gamma: must be a number in [0, 1], got 'high' (str)"),
        (TRAIN + "--gamma 1.5", "argument --gamma: must be a number in [0, 1], got 1.5"),
        (TRAIN + "--learning-rate 0", "--learning-rate: must be a number in (0, 1], got 0.0"),
        (TRAIN + "--reward-delay -2", "argument --reward-delay: must be a number in [0, "),
        (TRAIN + "--reward-delay 1e300", "argument --reward-delay: must be a number in [0, "),
        (f"evaluate m.npz --env {GRID} --reward-delay 1e20", "--reward-delay: must be a number in"),
        (TRAIN + "--q-init nan", "argument --q-init: must be a finite number, got nan"),
        (TRAIN + "--q-init 1e300", "argument --q-init: must be within ±MAX_ABS_VALUE = 2**200"),
        (TRAIN + "--seed -1", "argument --seed: must be an integer >= 0, got -1"),
        (f"train --env {GRID} --agent fixed --save x", "--agent fixed needs --delay-estimate"),
        (TRAIN + "--delay-estimate 2", "--delay-estimate is for --agent fixed, not --agent q"),
        (TRAIN + "--delay 2", "--delay-estimate is for --agent fixed, not --agent q"),  # a prefix
        (TRAIN + "--max-delay-estimate 9", "--max-delay-estimate is for --agent mmq or deconv"),
        ("evaluate m.npz --env Nope-v9", "unknown env id 'Nope-v9'"),
        (f"evaluate m.npz --env {GRID} --steps 5 --episodes 2", "not allowed with argument"),
        (f"evaluate m.npz --env {GRID} --episodes 0", "--episodes: must be an integer >= 1, got 0"),
        ("bench nope", "argument NAME: invalid choice: 'nope'"),
        ("bench delay-sweep --seeds 0", "argument --seeds: must be an integer >= 1, got 0"),
        ("bench delay-sweep --workers 0", "argument --workers: must be an integer >= 1, got 0"),
        ("bench delay-sweep --workers two", "--workers: must be an integer >= 1, got 'two' (str)"),
        ("bench delay-sweep --backend spark", "argument --backend: invalid choice: 'spark'"),
        ("bench all --base-seed -3", "argument --base-seed: must be an integer >= 0, got -3"),
        (
            "bench delay-sweep --base-seed -5",
            "argument --base-seed: must be an integer >= 0, got -5",
        ),
        # sizes beyond the stated limits, refused before anything starts
        (
            "bench mmq-gridworld --seeds 10001",
            "argument --seeds: must be at most MAX_SEED_COUNT = 10,000",
        ),
        (
            "bench mmq-gridworld --steps 1099511627777",
            "--steps: must be at most MAX_TIMESTEPS = 2**40",
        ),
        ("bench all --steps 100000000000000000000", "--steps: must be at most MAX_TIMESTEPS"),
        (
            "bench roulette --base-seed 9223372036854775808",
            "--base-seed: must be at most MAX_SEED_VALUE = 2**63 - 1",
        ),
        ("bench roulette --workers 1025", "--workers: must be at most MAX_WORKERS = 1024"),
        (
            TRAIN + "--steps 1099511627777",
            "argument --steps: must be at most MAX_TIMESTEPS = 2**40",
        ),
        (TRAIN + "--seed 9223372036854775808", "argument --seed: must be at most MAX_SEED_VALUE"),
        (
            f"evaluate m.npz --env {GRID} --steps 1000000001",
            "--steps: must be at most MAX_EVAL_STEPS",
        ),
        (f"evaluate m.npz --env {GRID} --episodes 1000001", "must be at most MAX_EVAL_EPISODES"),
        (
            f"evaluate m.npz --env {GRID} --max-eval-episode-steps 10000000000",
            "at most MAX_EVAL_STEPS",
        ),
        ("sweep s.yaml --workers 5000", "argument --workers: must be at most MAX_WORKERS = 1024"),
        (
            "bench --base-seed -5 delay-sweep",
            "argument --base-seed: must be an integer >= 0, got -5",
        ),
    ],
)
def test_bad_usage_exits_with_code_2(command, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(command.split())
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "usage: delayed-rl" in err and "Traceback" not in err
    errors = [line for line in err.splitlines() if "error:" in line]
    assert len(errors) == 1 and message in errors[0], err


def test_list_names_the_envs_agents_and_experiments(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "delayed_rl/GridWorld-9x9-v0" in out and "mmq-gridworld" in out
    assert "  fixed: FixedDelayQLearning" in out
    assert "(train: --agent fixed, --delay-estimate required)" in out
    assert "  mmq: MultipleModelQLearning" in out and "--agent mmq, --max-delay-estimate)" in out
    assert "oracle: OracleQLearning, " in out and "(sweeps and Python; not train)" in out


def test_every_command_has_help(capsys):
    for command in ("list", "train", "evaluate", "bench"):
        with pytest.raises(SystemExit) as exit_info:
            main([command, "--help"])
        assert exit_info.value.code == 0
        assert f"usage: delayed-rl {command}" in capsys.readouterr().out


def test_runtime_failures_exit_with_code_1_and_one_line(tmp_path, capsys):
    missing = ["evaluate", str(tmp_path / "missing"), "--env", GRID, "--steps", "5"]
    assert main(missing) == 1
    err = capsys.readouterr().err
    assert err == f"error: no model file at {tmp_path / 'missing'} (nor missing.npz, missing.zip)\n"

    assert main(_train(tmp_path, "--agent", "q", "--steps", "50")) == 0
    capsys.readouterr()
    model = str(tmp_path / "agent.npz")
    assert main(["evaluate", model, "--env", "delayed_rl/GridWorld-5x5-v0", "--steps", "5"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: cannot load") and "Discrete(25)" in err and "Discrete(9)" in err
    assert err.count("\n") == 1

    np.savez(tmp_path / "junk.npz", x=np.arange(3))  # an archive, but no delayed-rl model
    assert main(["evaluate", str(tmp_path / "junk.npz"), "--env", GRID, "--steps", "5"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "junk.npz" in err and err.count("\n") == 1

    cart = str(tmp_path / "cart")
    continuous = ["train", "--env", "CartPole-v1", "--agent", "q", "--steps", "10", "--save", cart]
    assert main(continuous) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: cannot train QLearning on CartPole-v1") and "Discrete" in err
    assert not (tmp_path / "cart.npz").exists()


def test_train_fails_before_training_when_it_cannot_save(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    argv = _train(tmp_path, "--agent", "q")
    argv[argv.index("--save") + 1] = str(blocker / "agent")
    assert main(argv) == 1
    assert capsys.readouterr().err.startswith("error: cannot create the folder of --save")


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    return err


def _corrupt(path, target):
    """``path`` with garbage in the middle of its deflated q_table (zlib cannot inflate it)."""
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as archive:
        info = archive.getinfo("q_table.npy")
    start = info.header_offset + 30 + len(info.filename) + len(info.extra)
    data[start + 2 : start + 60] = b"\xff" * 58
    target.write_bytes(bytes(data))
    return target


def test_a_corrupt_model_file_exits_1_with_one_line(tmp_path, capsys):
    assert main(_train(tmp_path, "--agent", "q", "--steps", "50")) == 0
    capsys.readouterr()
    bad = _corrupt(tmp_path / "agent.npz", tmp_path / "bad.npz")
    assert main(["evaluate", str(bad), "--env", GRID, "--steps", "5"]) == 1
    assert str(bad) in _one_error_line(capsys)


@pytest.mark.parametrize(
    "agent", [k for k, e in REGISTRY.items() if "max_delay_estimate" in (e.train_options or ())]
)
def test_max_delay_estimate_has_one_limit_whatever_the_agent(tmp_path, capsys, agent):
    code = main(_train(tmp_path, "--agent", agent, "--max-delay-estimate", "1025"))
    limit = "max_delay_estimate must be at most MAX_DELAY_ESTIMATE = 1024"
    assert code == 1 and limit in _one_error_line(capsys)
    assert not (tmp_path / "agent.npz").exists()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ("--agent fixed --delay-estimate 1000000000", "delay_estimate must keep the tables"),
    ],
)
def test_tables_too_large_are_refused_before_allocating(tmp_path, capsys, options, message):
    tracemalloc.start()
    try:
        code = main(_train(tmp_path, *options.split()))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert code == 1 and peak < 64 * 2**20
    err = _one_error_line(capsys)
    assert message in err and "MAX_TABLE_BYTES" in err and "GiB" in err
    assert not (tmp_path / "agent.npz").exists()


@pytest.mark.parametrize(
    "error",
    [
        MemoryError("Unable to allocate 7.28 TiB for an array\nwith shape (10**12,)"),
        MemoryError(),
        OverflowError("Python int too large to convert to C long"),
        RecursionError("maximum recursion depth exceeded"),
    ],
    ids=["memory", "memory-no-message", "overflow", "recursion"],
)
def test_any_failure_while_running_exits_1_with_one_line(tmp_path, capsys, monkeypatch, error):
    def fail(*args, **kwargs):
        raise error

    monkeypatch.setattr(QLearning, "learn", fail)
    assert main(_train(tmp_path, "--agent", "q")) == 1
    err = _one_error_line(capsys)
    if isinstance(error, MemoryError):
        assert err.startswith("error: out of memory")


def test_train_deconvolution_learns_the_delay_and_saves_an_agent_that_loads(tmp_path, capsys):
    """``--agent deconv``: the delay learned on 0..--max-delay-estimate, saved and loaded back."""
    from delayed_rl.agents import DeconvolutionQLearning, load_agent

    save = tmp_path / "deconv"
    argv = (
        "train --env delayed_rl/GridWorld-3x3-v0 --agent deconv --reward-delay 2 "
        f"--max-delay-estimate 8 --q-init 10 --steps 6000 --seed 0 --save {save}"
    ).split()
    assert main(argv) == 0
    assert "trained DeconvolutionQLearning" in capsys.readouterr().out
    agent = load_agent(save.with_suffix(".npz"))
    assert type(agent) is DeconvolutionQLearning and agent.delay_pmf.shape == (9,)


# ---------------------------------------------------------------------- Ctrl-C
def test_the_command_exits_130_on_ctrl_c_and_a_second_one_quits(monkeypatch, capsys):
    import signal

    from delayed_rl import cli

    seen = []

    def interrupted_main() -> int:
        seen.append(signal.getsignal(signal.SIGINT))
        signal.raise_signal(signal.SIGINT)  # Ctrl-C, delivered to this process's handler
        return 0  # (not reached)

    monkeypatch.setattr(cli, "main", interrupted_main)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        assert cli.console() == 130
        assert seen == [cli._interrupt]  # the command's handler ran the command
        assert signal.getsignal(signal.SIGINT) is cli._quit_now  # the next Ctrl-C quits
    finally:
        signal.signal(signal.SIGINT, previous)
    assert "interrupted" in capsys.readouterr().err


def test_the_command_leaves_an_ignored_ctrl_c_ignored(monkeypatch):
    import signal

    from delayed_rl import cli

    monkeypatch.setattr(cli, "main", lambda: 0)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        assert cli.console() == 0
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_the_command_puts_the_handler_back_when_it_ends_without_ctrl_c(monkeypatch):
    import signal

    from delayed_rl import cli

    during = []
    monkeypatch.setattr(cli, "main", lambda: during.append(signal.getsignal(signal.SIGINT)) or 3)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        assert cli.console() == 3
        assert during == [cli._interrupt]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, previous)


def _marked_processes(mark: str) -> list[int]:
    """The pids of the processes whose environment holds ``mark`` (Linux's /proc)."""
    from pathlib import Path

    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if mark.encode() in (entry / "environ").read_bytes():
                    found.append(int(entry.name))
            except OSError:  # gone, or not ours to read
                continue
    return found


@pytest.mark.experiment
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc (Linux)")
@pytest.mark.parametrize("gap", [0.05, 0.5])
def test_two_ctrl_c_during_a_parallel_run_exit_at_once_leaving_no_worker(tmp_path, gap):
    import contextlib
    import os
    import signal
    import subprocess
    import time
    import uuid

    mark = f"DELAYED_RL_CTRL_C_TEST={uuid.uuid4().hex}"
    command = (  # Ctrl-C as a terminal has it (a test runner may start us with it ignored)
        "import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
        "from delayed_rl.cli import console; "
        f"sys.argv = ['delayed-rl', 'bench', 'all', '--quick', '--workers', '2', '--out', "
        f"{str(tmp_path)!r}]; sys.exit(console())"
    )
    env = {**os.environ, mark.split("=")[0]: mark.split("=")[1]}
    process = subprocess.Popen(
        [sys.executable, "-c", command], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    try:
        deadline = time.monotonic() + 60
        while not (tmp_path / "delay-sweep").exists() and time.monotonic() < deadline:
            time.sleep(0.05)  # until the workers are busy (the first experiment written)
        assert process.poll() is None, process.stderr.read().decode()
        process.send_signal(signal.SIGINT)
        time.sleep(gap)
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
        assert process.wait(timeout=30) in (130, -signal.SIGINT)
        deadline = time.monotonic() + 10
        while _marked_processes(mark.split("=")[1]) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _marked_processes(mark.split("=")[1]) == []  # no worker left behind
    finally:  # (a hung run must not outlive the test)
        if process.poll() is None:
            process.kill()
        for pid in _marked_processes(mark.split("=")[1]):
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        process.stderr.close()


# ---------------------------------------------------------------------- bench's progress
#: The quickest ``bench``: the delay sweep scaled down to one seed of 2000 steps.
BENCH = "bench delay-sweep --quick --seeds 1 --steps 2000"


def _scheduled_runs() -> int:
    """How many distinct runs :data:`BENCH` schedules (as the scheduler counts them)."""
    from delayed_rl.experiments import Config, get_experiment
    from delayed_rl.experiments.framework.pool import pool_key

    experiment = get_experiment("delay-sweep")
    tasks = experiment.tasks(Config(quick=True, seeds=1, steps=2000))
    return len({pool_key(experiment.run_of(task)) for task in tasks})


def _bench(tmp_path, capsys, *options: str) -> tuple[str, str]:
    """Run :data:`BENCH` with ``options`` into ``tmp_path``; return its stdout and stderr."""
    assert main([*BENCH.split(), "--out", str(tmp_path), *options]) == 0
    captured = capsys.readouterr()
    assert "verdict" in captured.out  # the report, whatever the progress
    return captured.out, captured.err


@pytest.mark.parametrize("default", [False, True], ids=["--progress", "default-on-a-terminal"])
def test_bench_progress_bar_counts_the_scheduled_runs(tmp_path, capsys, monkeypatch, default):
    runs = _scheduled_runs()
    assert runs > 1
    if default:
        monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    out, err = _bench(tmp_path, capsys, *([] if default else ["--progress"]))
    assert "delay-sweep: 100%" in err and f"| {runs}/{runs} [" in err  # tqdm's bar
    assert re.search(r"\[\d\d:\d\d<\d\d:\d\d", err)  # the time elapsed < the time left
    assert f"[delay-sweep] {runs} runs ({runs} tasks) on 1 worker(s)..." in out


@pytest.mark.parametrize("option", ["--no-progress", None], ids=["--no-progress", "not-a-tty"])
def test_bench_shows_no_progress_when_off_or_stderr_is_not_a_terminal(tmp_path, capsys, option):
    assert not sys.stderr.isatty()  # (capsys's)
    runs = _scheduled_runs()
    out, err = _bench(tmp_path, capsys, *([option] if option else []))
    assert f"/{runs}" not in err and "run/s" not in err
    assert "worker(s)..." not in out


def test_bench_without_tqdm_counts_in_lines_when_asked_and_stays_silent_by_default(
    tmp_path, capsys, monkeypatch
):
    monkeypatch.setitem(sys.modules, "tqdm.auto", None)  # as if tqdm were not installed
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    runs = _scheduled_runs()
    _, err = _bench(tmp_path / "asked", capsys, "--progress")
    assert err.splitlines() == [
        f"[delay-sweep] {done}/{runs} runs done" for done in range(1, runs + 1)
    ]
    _, err = _bench(tmp_path / "default", capsys)
    assert err == ""


def test_bench_takes_progress_flags(capsys):
    with pytest.raises(SystemExit):
        main(["bench", "--help"])
    assert "--progress, --no-progress" in capsys.readouterr().out


def test_bench_names_several_experiments_once_each_and_long_needs_all(chosen, capsys):
    with pytest.raises(_Stop):
        main(["bench", "roulette", "delay-sweep", "roulette"])
    assert chosen == ["roulette", "delay-sweep"]
    with pytest.raises(SystemExit) as exit_info:
        main(["bench", "roulette", "--long"])
    assert exit_info.value.code == 2
    assert "--long adds the long experiments to 'all'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["bench", "reproduce"])
    assert "invalid choice: 'reproduce'" in capsys.readouterr().err


def _edited_copy(path, target, arrays=None, **hyperparameters):
    """``path``'s model file with arrays replaced and hyper-parameters set, written to ``target``."""
    import json

    with np.load(path) as data:
        contents = {key: data[key] for key in data.files}
    metadata = json.loads(str(contents.pop("metadata")))
    metadata["hyperparameters"].update(hyperparameters)
    contents.update(arrays or {})
    np.savez(target, **contents, metadata=np.array(json.dumps(metadata)))
    return target


@pytest.mark.parametrize("path", [".", ""])
def test_evaluate_of_a_path_without_a_file_name_exits_1_naming_it(path, capsys):
    assert main(["evaluate", path, "--env", GRID, "--steps", "5"]) == 1
    assert "path must name a model file" in _one_error_line(capsys)


@pytest.mark.parametrize(
    ("make", "edit", "fragment"),
    [
        (
            lambda env: ExpectedCreditQLearning(env, 2.0),
            {"delay": None},
            "delay must be",
        ),
        (
            lambda env: DeconvolutionQLearning(env, max_delay_estimate=4),
            {"max_delay_estimate": 10**9},
            "max_delay_estimate must be at most MAX_DELAY_ESTIMATE",
        ),
        (
            lambda env: DeconvolutionQLearning(env, max_delay_estimate=4),
            {"arrays": {"delay_pmf": np.array([2.0, -1.0, 0.0, 0.0, 0.0])}},
            "delay_pmf must hold numbers in [0, 1]",
        ),
    ],
    ids=[
        "expected credit with delay null",
        "DeconvQ max_delay_estimate 1e9",
        "DeconvQ pmf off simplex",
    ],
)
def test_evaluate_on_a_bad_agent_file_exits_1_with_one_line(tmp_path, capsys, make, edit, fragment):
    good = make(gym.make(GRID)).learn(20).save(tmp_path / "good")
    bad = _edited_copy(good, tmp_path / "bad.npz", **edit)
    assert main(["evaluate", str(bad), "--env", GRID, "--steps", "5"]) == 1
    err = _one_error_line(capsys)
    assert str(bad) in err and fragment in err, err


def test_train_refuses_a_save_path_without_a_file_name(tmp_path, capsys):
    """Bad usage, exit 2, before training (``--steps`` beyond its limit: the bad-usage table)."""
    argv = _train(tmp_path, "--agent", "q")
    argv[argv.index("--save") + 1] = ""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    assert "argument --save: must name a model file" in capsys.readouterr().err
    assert not (tmp_path / "agent.npz").exists()


class _Stop(Exception):
    """Raised by a stand-in for ``run_experiments`` once it has seen what it was given."""


@pytest.fixture
def chosen(monkeypatch):
    """The names of the experiments ``main`` hands to ``run_experiments``, which then stops."""
    import delayed_rl.experiments as experiments

    seen = []

    def record(chosen, *args, **kwargs):
        seen.extend(experiment.name for experiment in chosen)
        raise _Stop

    monkeypatch.setattr(experiments, "get_experiment", lambda name: SimpleNamespace(name=name))
    monkeypatch.setattr(experiments, "run_experiments", record)
    return seen


def test_bench_of_several_experiments_writes_their_index(monkeypatch, tmp_path, capsys):
    import delayed_rl.experiments as experiments
    from delayed_rl.experiments.framework.experiment import Claim, Summary

    def summaries(chosen, config, out, progress, on_done):
        costs = {"runs": 1, "shared_runs": 0, "run_seconds": 1.0}
        return [Summary([Claim("q", "t", 0.0, 0.1, 2, "agrees")], [], extra=costs) for _ in chosen]

    monkeypatch.setattr(experiments, "run_experiments", summaries)
    assert main(["bench", "roulette", "delay-sweep", "--out", str(tmp_path)]) == 0
    index = (tmp_path / "index.md").read_text()
    assert "`roulette`" in index and "`delay-sweep`" in index
    assert f"[bench] wrote {tmp_path / 'index.md'}" in capsys.readouterr().out
    assert main(["bench", "roulette", "--out", str(tmp_path / "one")]) == 0
    assert not (tmp_path / "one" / "index.md").exists()  # one experiment: no index


@pytest.mark.parametrize(
    ("argv", "has_long"), [(["bench", "all"], False), (["bench", "all", "--long"], True)]
)
def test_bench_all_leaves_the_long_experiments_to_long(chosen, argv, has_long):
    import delayed_rl.experiments as experiments

    with pytest.raises(_Stop):
        main(argv)
    assert set(chosen) == set(experiments.NAMES if has_long else experiments.DEFAULT_NAMES)
    assert ("deep-rl" in chosen) is has_long


@pytest.mark.cold_cache
def test_deep_rl_without_torch_is_an_error_naming_the_extra(tmp_path):
    blocker = (
        "import sys\n"
        "class Block:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] in ('torch', 'stable_baselines3'):\n"
        "            raise ImportError(f'No module named {name!r}')\n"
        "sys.meta_path.insert(0, Block())\n"
        "from delayed_rl.cli import main\n"
        f"sys.exit(main(['bench', 'deep-rl', '--quick', '--out', {str(tmp_path)!r}]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", blocker], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 1, done.stderr
    needs = 'needs torch and stable-baselines3: pip install "delayed-rl[sb3]"'
    assert f"error: the deep-rl experiment {needs}" in done.stderr
    assert not any(tmp_path.iterdir())


def test_the_train_options_default_to_the_agents_defaults():
    from delayed_rl.agents import DEFAULTS
    from delayed_rl.cli import build_parser

    args = build_parser().parse_args(["train", "--env", GRID, "--agent", "q", "--save", "x"])
    assert (args.learning_rate, args.gamma, args.q_init) == (
        DEFAULTS.learning_rate,
        DEFAULTS.gamma,
        DEFAULTS.q_init,
    )
    assert args.epsilon == DEFAULTS.exploration_initial_eps == DEFAULTS.exploration_final_eps


@pytest.mark.parametrize(
    ("option", "name"),
    [
        ("--learning-rate", "learning_rate"),
        ("--gamma", "gamma"),
        ("--epsilon", "exploration_final_eps"),
        ("--q-init", "q_init"),
    ],
)
@pytest.mark.parametrize("text", ["0", "1", "0.5", "1.5", "-0.25", "nan", "inf", "1e300", "x"])
def test_a_hyperparameter_option_refuses_what_the_agent_refuses(option, name, text, capsys):
    from delayed_rl.agents import QLearning
    from delayed_rl.cli import build_parser

    try:
        value = float(text)
    except ValueError:
        value = text
    try:
        QLearning(GRID, **{name: value})
        agent_takes = True
    except (TypeError, ValueError):
        agent_takes = False
    command = ["train", "--env", GRID, "--agent", "q", "--save", "x", option, text]
    try:
        build_parser().parse_args(command)
        parser_takes = True
    except SystemExit:
        parser_takes = False
    assert parser_takes == agent_takes, capsys.readouterr().err
