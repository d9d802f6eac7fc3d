"""Hostile sweep files and corrupted ``results.csv`` files, generated in code.

Sweep files: what a reader could be made to do (expand aliases, recurse, read a huge file),
keys given twice, sizes beyond the stated limits, and random edits of a valid file. Each is
refused with a ``TypeError`` or ``ValueError`` that names the file or the field, the CLI exits
with 2 and one ``error:`` line, and nothing else ever escapes.

Results files: every corruption of a finished sweep's ``results.csv`` is refused with its line
number, except a last row cut short (the file ends inside it), which is left out and run again.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import socket
import sys
import types
import warnings
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support import examples

from delayed_rl.cli import main
from delayed_rl.sweep import parse_sweep, read_sweep_file, reading, run_sweep, schema
from delayed_rl.sweep.results import RESULTS_FILE, read_results

GRID = "delayed_rl/GridWorld-3x3-v0"
VALID_YAML = f"""\
name: small
agents:
  - q
  - {{name: mmq, kwargs: {{max_delay_estimate: 3, learning_rate: 0.2}}}}
envs:
  - {{id: {GRID}, label: grid, eval_steps: 20}}
delays: [1.5, {{type: Constant, k: 2}}]
seeds: 2
steps: 200
"""


def write(tmp_path: Path, name: str, text: str | bytes) -> Path:
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


def cli_error(path: Path, capsys) -> str:
    """The CLI's ``error:`` line for ``delayed-rl sweep path`` (which must exit with 2)."""
    with pytest.raises(SystemExit) as exit_:
        main(["sweep", str(path), "--out", str(path.parent / "out")])
    assert exit_.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert "Traceback" not in "\n".join(lines)
    return lines[-1]


# --- what a reader could be made to do ---------------------------------------------------------


def laughs(levels: int, fan: int) -> str:
    """A sweep whose kwargs nest ``levels`` anchors, each ``fan`` aliases of the one before."""
    lines = ["agents:", "  - name: q", "    kwargs:", '      a0: &a0 ["lol"]']
    for k in range(1, levels + 1):
        aliases = ", ".join([f"*a{k - 1}"] * fan)
        lines.append(f"      a{k}: &a{k} [{aliases}]")
    return "\n".join([*lines, f"envs: [{GRID}]", "delays: [1]", ""])


@pytest.mark.parametrize(("levels", "fan"), [(9, 9), (5, 20), (30, 2)])
def test_nested_aliases_are_refused_before_anything_is_built(tmp_path, monkeypatch, levels, fan):
    path = write(tmp_path, "laughs.yaml", laughs(levels, fan))
    import yaml

    def never(*args, **kwargs):
        raise AssertionError("a value was constructed before the expansion was checked")

    monkeypatch.setattr(yaml.constructor.BaseConstructor, "construct_document", never)
    with pytest.raises(ValueError, match=r"laughs.yaml stands for more than MAX_VALUES = 100,000"):
        read_sweep_file(path)


def test_a_few_aliases_are_fine(tmp_path):
    text = VALID_YAML.replace(
        "  - q\n",
        "  - {name: q, label: q1, kwargs: &rate {learning_rate: 0.2}}\n"
        "  - {name: q, label: q2, kwargs: *rate}\n",
    )
    sweep = parse_sweep(read_sweep_file(write(tmp_path, "s.yaml", text)))
    assert [a.kwargs for a in sweep.agents[:2]] == [{"learning_rate": 0.2}] * 2


def test_a_value_that_contains_itself_is_refused(tmp_path):
    text = VALID_YAML.replace("seeds: 2", "seeds: &s [0, *s]")
    with pytest.raises(ValueError, match=r"holds a value that contains itself .* line"):
        read_sweep_file(write(tmp_path, "s.yaml", text))


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
@pytest.mark.parametrize("depth", [33, 1000, 100_000])
def test_deep_nesting_is_a_value_error_at_any_depth(tmp_path, capsys, suffix, depth):
    body = "[" * depth + "]" * depth
    text = f'{{"agents": ["q"], "envs": ["{GRID}"], "delays": {body}}}'
    path = write(tmp_path, "deep" + suffix, text)
    with pytest.raises(ValueError, match=r"nested deeper than MAX_DEPTH = 32"):
        read_sweep_file(path)
    assert "MAX_DEPTH = 32" in cli_error(path, capsys)


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_unclosed_brackets_are_a_value_error(tmp_path, capsys, suffix):
    path = write(tmp_path, "open" + suffix, "[" * 100_000)
    with pytest.raises(
        ValueError, match=r"open\.(yaml|json)(, line 1: values| is) nested deeper than MAX_DEPTH"
    ):
        read_sweep_file(path)
    assert cli_error(path, capsys).startswith("delayed-rl sweep: error: ")


def test_nesting_within_the_limit_reads(tmp_path):
    body = "[" * 30 + "1" + "]" * 30
    path = write(tmp_path, "s.json", f'{{"agents": ["q"], "x": {body}}}')
    assert read_sweep_file(path)["x"][0][0][0]


def test_a_file_over_the_size_limit_is_refused_without_reading_it_all(tmp_path, monkeypatch):
    monkeypatch.setattr(reading, "MAX_SWEEP_FILE_BYTES", 1000)
    path = write(tmp_path, "big.yaml", VALID_YAML + "#" * 2000 + "\n")
    with pytest.raises(
        ValueError, match=r"big.yaml is larger than MAX_SWEEP_FILE_BYTES = 1,000 bytes"
    ):
        read_sweep_file(path)


def test_the_real_size_limit_holds_for_a_padded_valid_file(tmp_path):
    path = write(tmp_path, "big.json", json.dumps({"agents": ["q"], "pad": "x" * 1_000_001}))
    with pytest.raises(ValueError, match=r"larger than MAX_SWEEP_FILE_BYTES = 1,000,000 bytes"):
        read_sweep_file(path)


def test_many_values_in_json_are_refused(tmp_path):
    path = write(tmp_path, "many.json", json.dumps({"agents": ["q"], "x": [0] * 200_000}))
    with pytest.raises(ValueError, match=r"more than MAX_VALUES = 100,000 values"):
        read_sweep_file(path)


def test_text_that_is_not_utf8_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match=r"s.yaml is not UTF-8 text"):
        read_sweep_file(write(tmp_path, "s.yaml", b"agents: [\xff\xfe]\n"))


@pytest.mark.parametrize(
    "text", ["!!python/object/apply:os.system ['echo hi']\n", "agents: !!python/name:os.system\n"]
)
def test_python_tags_are_refused(tmp_path, text):
    with pytest.raises(ValueError, match="is not valid YAML"):
        read_sweep_file(write(tmp_path, "s.yaml", text))


# --- keys given twice ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "key", "line"),
    [
        (VALID_YAML + "steps: 300\n", "steps", 10),
        (VALID_YAML.replace("label: grid,", "label: grid, label: other,"), "label", 6),
        (
            VALID_YAML.replace("learning_rate: 0.2", "learning_rate: 0.2, learning_rate: 1"),
            "learning_rate",
            4,
        ),
        (VALID_YAML + "? steps\n: 1\n", "steps", 10),
    ],
    ids=["top level", "in an env", "in kwargs", "complex key form"],
)
def test_a_yaml_key_given_twice_is_refused_naming_it_and_its_line(tmp_path, text, key, line):
    message = rf"s.yaml, line {line}: the key '{key}' is given a second time in one mapping"
    with pytest.raises(ValueError, match=message):
        read_sweep_file(write(tmp_path, "s.yaml", text))


def test_a_json_key_given_twice_is_refused_naming_it(tmp_path):
    text = f'{{"agents": ["q"], "envs": ["{GRID}"], "delays": [1], "steps": 5, "steps": 300}}'
    with pytest.raises(ValueError, match=r"gives the key 'steps' twice"):
        read_sweep_file(write(tmp_path, "s.json", text))


def test_yaml_merge_keys_keep_their_meaning(tmp_path):
    text = VALID_YAML.replace(
        "  - q\n",
        "  - &base {name: q, label: base, kwargs: {learning_rate: 0.2}}\n"
        "  - {<<: *base, label: other}\n",
    )
    sweep = parse_sweep(read_sweep_file(write(tmp_path, "s.yaml", text)))
    assert [(a.name, a.label) for a in sweep.agents[:2]] == [("q", "base"), ("q", "other")]


# --- sizes beyond the stated limits --------------------------------------------------------------


def plan(**changes) -> dict:
    data = {"agents": ["q"], "envs": [{"id": GRID, "eval_steps": 20}], "delays": [1], "steps": 50}
    data.update(changes)
    return data


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"steps": 10**21}, r"^steps must be at most MAX_TIMESTEPS = 2\*\*40"),
        ({"steps": 2**40 + 1}, r"^steps must be at most MAX_TIMESTEPS"),
        ({"eval_steps": 10**14}, r"^eval_steps must be at most MAX_EVAL_STEPS = 10\*\*9"),
        ({"eval_episodes": 10**7}, r"^eval_episodes must be at most MAX_EVAL_EPISODES = 10\*\*6"),
        (
            {"seeds": 10**6},
            r"^seeds must be at most MAX_SEED_COUNT = 10,000 \(delayed_rl.parallel.pools\)",
        ),
        ({"seeds": 10**30}, r"^seeds must be at most MAX_SEED_COUNT"),
        ({"seeds": [0, 2**40]}, r"^seeds\[1\] must be at most MAX_SWEEP_SEED_VALUE = 2\*\*32 - 1"),
        (
            {"seeds": list(range(10_001))},
            r"^seeds must list at most MAX_SEED_COUNT = 10,000 \(.*\), got 10,001 seeds",
        ),
        ({"agents": [{"name": "q", "steps": 10**21}]}, r"^agents\[0\]\.steps must be at most"),
        (
            {"envs": [{"id": GRID, "eval_steps": 10**10}]},
            r"^envs\[0\]\.eval_steps must be at most MAX_EVAL_STEPS",
        ),
        ({"envs": [{"id": GRID, "steps": 10**13}]}, r"^envs\[0\]\.steps must be at most"),
    ],
    ids=lambda value: repr(value)[:60],
)
def test_sizes_beyond_the_limits_are_refused_naming_the_limit(changes, message):
    with pytest.raises(ValueError, match=message):
        parse_sweep(plan(**changes))


def test_too_many_runs_are_refused_before_the_runs_are_listed(monkeypatch):
    agents = [{"name": "q", "label": f"q{i}"} for i in range(100)]
    delays = [float(k) for k in range(100)]

    def never(self):
        raise AssertionError("the runs were listed")

    monkeypatch.setattr(schema.Sweep, "runs", never)
    with pytest.raises(ValueError, match=r"1,000,000 runs .*more than MAX_RUNS = 100,000"):
        parse_sweep(plan(agents=agents, delays=delays, seeds=100))


def test_the_limits_are_inclusive():
    sweep = parse_sweep(plan(steps=2**40, eval_steps=10**9, seeds=[0, 2**32 - 1]))
    assert (sweep.steps, sweep.evaluation.count, sweep.seeds) == (2**40, 10**9, (0, 2**32 - 1))


def test_the_cli_refuses_a_huge_step_count_with_exit_2(tmp_path, capsys):
    path = write(
        tmp_path, "s.yaml", VALID_YAML.replace("steps: 200", "steps: 1000000000000000000000")
    )
    assert "steps must be at most MAX_TIMESTEPS" in cli_error(path, capsys)


# --- backends that cannot start --------------------------------------------------------------


def test_ray_that_cannot_start_is_one_error_line(tmp_path, capsys, monkeypatch):
    fake = types.ModuleType("ray")
    fake.is_initialized = lambda: False

    def init(address=None):
        raise Exception("The current node timed out during startup")  # as Ray raises it

    fake.init = init
    monkeypatch.setitem(sys.modules, "ray", fake)
    path = write(tmp_path, "s.yaml", VALID_YAML)
    code = main(["sweep", str(path), "--out", str(tmp_path / "out"), "--backend", "ray"])
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err
    assert err.strip().splitlines()[-1] == (
        "error: backend 'ray' could not start on a local cluster: Exception: The current node "
        "timed out during startup"
    )


def test_dask_that_cannot_reach_its_scheduler_is_one_error_line(tmp_path, capsys, monkeypatch):
    fake = types.ModuleType("dask.distributed")

    def client(*args, **kwargs):
        raise OSError("Timed out trying to connect to tcp://10.0.0.1:8786 after 30 s")

    fake.Client = client
    monkeypatch.setitem(sys.modules, "dask.distributed", fake)
    path = write(tmp_path, "s.yaml", VALID_YAML)
    argv = ["sweep", str(path), "--out", str(tmp_path / "o"), "--backend", "dask"]
    code = main([*argv, "--address", "tcp://10.0.0.1:8786"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and err[-1].startswith(
        "error: backend 'dask' could not start on the cluster at 'tcp://10.0.0.1:8786': OSError"
    )


# --- random edits of a valid file ----------------------------------------------------------------

EDITS = settings(
    max_examples=examples(300),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
yaml_bits = st.sampled_from(
    [
        "&a ",
        "*a",
        "[",
        "]",
        "{",
        "}",
        ": ",
        "- ",
        "\n",
        "  ",
        "<<: ",
        "!!str ",
        "!!binary ",
        "!!python/tuple ",
        "~",
        "1e999",
        "-1",
        "10000000000000000000000",
        ".nan",
        "? ",
        "'",
        '"',
        "#",
        "%YAML 1.1\n",
        "---\n",
        "...\n",
        "\t",
        "\x00",
        "é",
        "steps: 3\n",
    ]
)


@EDITS
@given(edits=st.lists(st.tuples(st.integers(0, len(VALID_YAML)), yaml_bits), max_size=6))
def test_any_edit_of_a_valid_yaml_file_is_read_or_refused_clearly(tmp_path, edits):
    text = VALID_YAML
    for where, bit in edits:
        text = text[:where] + bit + text[where:]
    path = write(tmp_path, "s.yaml", text)
    with contextlib.suppress(TypeError, ValueError):  # refused: the other tests check messages
        parse_sweep(read_sweep_file(path))


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner, max_size=4)
    ),
    max_leaves=20,
)
FIELDS = ["agents", "envs", "delays", "seeds", "steps", "eval_episodes", "eval_steps", "name"]


@EDITS
@given(field=st.sampled_from(FIELDS), value=json_values, inner=st.booleans())
def test_any_json_value_in_any_field_is_taken_or_refused_clearly(field, value, inner):
    data = plan()
    if inner and field in ("agents", "envs", "delays"):
        data[field] = [value]
    else:
        data[field] = value
    with contextlib.suppress(TypeError, ValueError):
        parse_sweep(data)


# --- corrupted results files ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> Path:
    """A finished sweep of 4 runs (q and mmq × 1 delay × 2 seeds): its output folder."""
    out = tmp_path_factory.mktemp("finished")
    data = plan(agents=["q", {"name": "mmq", "kwargs": {"max_delay_estimate": 3}}], seeds=2)
    run_sweep(parse_sweep(data), out)
    return out


def corrupt(finished: Path, tmp_path: Path, change) -> tuple[Path, list[str]]:
    """A copy of ``finished``'s results.csv with its lines passed through ``change``."""
    lines = (finished / RESULTS_FILE).read_text(encoding="utf-8").splitlines(keepends=True)
    path = tmp_path / RESULTS_FILE
    path.write_text("".join(change(list(lines))), encoding="utf-8")
    return path, lines


def set_cell(lines: list[str], line: int, column: str, value: str) -> list[str]:
    header = next(csv.reader([lines[0]]))
    row = next(csv.reader([lines[line - 1]]))
    row[header.index(column)] = value
    buffer = io.StringIO()
    csv.writer(buffer).writerow(row)
    lines[line - 1] = buffer.getvalue()
    return lines


@pytest.mark.parametrize(
    ("line", "column", "value", "message"),
    [
        (
            2,
            "eval_reward",
            "nan",
            r"line 2: eval_reward must be a decimal number of magnitude at most MAX_ABS_VALUE = 2\*\*200 \(delayed_rl\.agents\.common\.hyperparameters\), got 'nan'",
        ),
        (
            3,
            "train_reward",
            "inf",
            r"line 3: train_reward must be a decimal number of magnitude at most MAX_ABS_VALUE = 2\*\*200 \(delayed_rl\.agents\.common\.hyperparameters\)",
        ),
        (
            4,
            "eval_reward",
            "abc",
            r"line 4: eval_reward must be a decimal number of magnitude at most MAX_ABS_VALUE = 2\*\*200 \(delayed_rl\.agents\.common\.hyperparameters\), got 'abc'",
        ),
        (2, "wall_s", "-1", r"line 2: wall_s must be a number >= 0"),
        (3, "seed", "-1", r"line 3: seed must be an integer in \[0, 4294967295\], got '-1'"),
        (3, "seed", "1.5", r"line 3: seed must be an integer"),
        (2, "steps", "0", r"line 2: steps must be an integer in \[1, "),
        (5, "eval_unit", "epoch", r"line 5: eval_unit must be 'episode' or 'step'"),
        (2, "run_id", "3f2a", r"line 2: run_id must be 16 hexadecimal digits, got '3f2a'"),
        (4, "agent", "", r"line 4: agent must be a non-empty label"),
        (3, "eval_reward", "1" * 5000, r"line 3: eval_reward must be a decimal number"),
        (2, "eval_reward", "1e308", r"line 2: eval_reward must be a decimal number"),
        (3, "train_reward", "1_000", r"line 3: train_reward must be a decimal number"),
        (4, "eval_reward", " 0.5 ", r"line 4: eval_reward must be a decimal number"),
    ],
)
def test_a_bad_value_is_refused_with_its_line_and_column(
    finished, tmp_path, line, column, value, message
):
    path, _ = corrupt(finished, tmp_path, lambda lines: set_cell(lines, line, column, value))
    with pytest.raises(ValueError, match=rf"results.csv, {message}"):
        read_results(path)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            lambda lines: lines[:2] + [lines[2].rstrip("\r\n") + ",extra\r\n"] + lines[3:],
            "line 3: the row has 11 values, the header 10",
        ),
        (
            lambda lines: lines[:3] + [lines[3].split(",", 4)[0] + "\r\n"] + lines[4:],
            "line 4: the row has 1 values",
        ),
        (lambda lines: lines[:1] + ['"unclosed,' + lines[1]] + lines[2:], "line"),
    ],
    ids=["an extra value", "a row cut short in the middle", "an unclosed quote"],
)
def test_a_row_of_the_wrong_shape_is_refused_with_its_line(finished, tmp_path, change, message):
    path, _ = corrupt(finished, tmp_path, change)
    with pytest.raises(ValueError, match=rf"results.csv, {message}"):
        read_results(path)


def test_a_last_row_cut_at_any_point_is_left_out_and_the_rest_kept(finished, tmp_path):
    lines = (finished / RESULTS_FILE).read_text(encoding="utf-8").splitlines(keepends=True)
    whole = read_results(finished / RESULTS_FILE)
    last = lines[-1]
    for cut in range(1, len(last) - 1):  # the row's first characters, up to its last but "\r\n"
        path = tmp_path / RESULTS_FILE
        path.write_text("".join(lines[:-1]) + last[:cut], encoding="utf-8")
        with pytest.warns(UserWarning, match=rf"line {len(lines)}: a row cut short"):
            assert read_results(path) == whole[:-1]


def test_a_cut_row_runs_again_and_the_file_ends_as_a_whole_one(finished, tmp_path):
    data = plan(agents=["q", {"name": "mmq", "kwargs": {"max_delay_estimate": 3}}], seeds=2)
    lines = (finished / RESULTS_FILE).read_text(encoding="utf-8").splitlines(keepends=True)
    cut_inside_run_id = lines[-1][: lines[-1].rindex(",") + 7]
    (tmp_path / RESULTS_FILE).write_text("".join(lines[:-1]) + cut_inside_run_id, encoding="utf-8")
    with pytest.warns(UserWarning, match="a row cut short"):
        outcome = run_sweep(parse_sweep(data), tmp_path)
    assert (outcome.ran, outcome.skipped) == (1, 3)
    rows = read_results(tmp_path / RESULTS_FILE)
    expected = read_results(finished / RESULTS_FILE)
    assert len(rows) == 4
    assert [{k: v for k, v in r.items() if k != "wall_s"} for r in rows] == [
        {k: v for k, v in r.items() if k != "wall_s"} for r in expected
    ]


def test_a_corrupted_file_stops_the_cli_with_one_error_line(finished, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    corrupt(finished, out, lambda lines: set_cell(lines, 3, "eval_reward", "nan"))
    data = plan(agents=["q", {"name": "mmq", "kwargs": {"max_delay_estimate": 3}}], seeds=2)
    path = write(tmp_path, "s.json", json.dumps(data))
    assert main(["sweep", str(path), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("error: ") and "results.csv, line 3: eval_reward" in err[-1]


CORRUPTIONS = settings(
    max_examples=examples(200),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)


@CORRUPTIONS
@given(
    where=st.integers(0, 10_000),
    bits=st.text(alphabet=st.sampled_from(list(',"\r\n x-.e9aZ\x00')), min_size=1, max_size=4),
    delete=st.integers(0, 3),
)
def test_any_edit_of_a_results_file_is_refused_with_a_line_or_reads_valid_rows(
    finished, tmp_path, where, bits, delete
):
    text = (finished / RESULTS_FILE).read_text(encoding="utf-8")
    where %= len(text)
    path = tmp_path / RESULTS_FILE
    path.write_text(text[:where] + bits + text[where + delete :], encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            rows = read_results(path)
        except ValueError as error:
            assert str(error).startswith(f"{path}") and ", line " in str(error)
            return
    for row in rows:  # what was taken is valid: a real number where a number goes
        assert float(row["eval_reward"]) == float(row["eval_reward"])
        assert len(row["run_id"]) == 16


def test_a_long_string_repeated_by_aliases_is_refused(tmp_path):
    big = "x" * 100_000
    text = VALID_YAML.replace("name: small", f"name: &big {big}") + (
        "envs_extra: [" + ", ".join(["*big"] * 20) + "]\n"
    )
    with pytest.raises(
        ValueError, match=r"MAX_SWEEP_FILE_BYTES = 1,000,000 characters, once its aliases"
    ):
        read_sweep_file(write(tmp_path, "s.yaml", text))


@pytest.mark.parametrize(
    "value", ["1" * 5000, "2026-13-45", "!!binary ###", "!!float abc", "!!int 1.5"], ids=repr
)
def test_scalars_yaml_cannot_build_are_a_value_error_naming_the_file(tmp_path, value):
    path = write(tmp_path, "s.yaml", VALID_YAML.replace("steps: 200", f"steps: {value}"))
    with pytest.raises((TypeError, ValueError)) as error:
        parse_sweep(read_sweep_file(path))
    assert "s.yaml" in str(error.value) or "steps" in str(error.value)


@pytest.mark.parametrize(
    "tag", ["!!set {a, b}", "!!omap [{a: 1}]", "!!pairs [{a: 1}]", "2026-01-01", "!!binary aGk="]
)
def test_yaml_types_that_are_not_json_are_refused_naming_the_field(tmp_path, tag):
    text = VALID_YAML.replace("learning_rate: 0.2", f"learning_rate: {tag}")
    with pytest.raises(TypeError, match=r"^agents\[1\]\.kwargs\.learning_rate"):
        parse_sweep(read_sweep_file(write(tmp_path, "s.yaml", text)))


# --- values that would pass the checks, then break the sweep -------------------------------------


@pytest.mark.parametrize(
    ("changes", "exc", "message"),
    [
        (
            {"name": "x" * 1001},
            ValueError,
            r"^name's length must be at most MAX_LABEL_CHARS = 1000 \(delayed_rl\.sweep\.schema\), "
            r"got 1,001",
        ),
        (
            {"envs": [{"id": GRID, "label": "y" * 900_000, "eval_steps": 20}]},
            ValueError,
            r"^envs\[0\]\.label's length must be at most MAX_LABEL_CHARS",
        ),
        ({"name": "\ud800"}, ValueError, r"^name must be text UTF-8 can write"),
        ({"agents": [{"name": "q", "label": "a\udfffb"}]}, ValueError, r"agents\[0\]\.label"),
    ],
    ids=["long name", "long label", "lone surrogate", "surrogate label"],
)
def test_text_a_results_file_could_not_hold_is_refused(changes, exc, message):
    with pytest.raises(exc, match=message):
        parse_sweep(plan(**changes))


def test_building_an_agent_that_asks_for_too_much_memory_is_a_value_error(monkeypatch):
    from delayed_rl.sweep import check_sweep, runs

    def huge(config, env):
        raise MemoryError("Unable to allocate 745. GiB for an array")

    monkeypatch.setattr(runs, "make_model", huge)
    with pytest.raises(ValueError, match=r"asks? for more memory than this machine has"):
        check_sweep(parse_sweep(plan()))


def test_a_results_file_that_is_not_utf8_names_its_line(finished, tmp_path):
    text = (finished / RESULTS_FILE).read_bytes()
    path = tmp_path / RESULTS_FILE
    path.write_bytes(text + b"\x80\x81\r\n")
    lines = text.count(b"\n") + 1
    with pytest.raises(ValueError, match=rf"results.csv, line {lines}: not UTF-8 text"):
        read_results(path)


def test_a_run_given_twice_is_kept_once_if_it_agrees_and_refused_if_not(finished, tmp_path):
    lines = (finished / RESULTS_FILE).read_text(encoding="utf-8").splitlines(keepends=True)
    again = set_cell(list(lines), 2, "wall_s", "99.5")[1]  # the same run, another time
    path, _ = corrupt(finished, tmp_path, lambda lines: [*lines, again])
    assert read_results(path) == read_results(finished / RESULTS_FILE)
    other = set_cell(list(lines), 2, "eval_reward", "99")[1]
    path, _ = corrupt(finished, tmp_path, lambda lines: [*lines, other])
    message = rf"results.csv, line {len(lines) + 1}: the run of line 2 again, with other results"
    with pytest.raises(ValueError, match=message):
        read_results(path)


def test_ray_at_an_address_nobody_answers_is_one_error_line_at_once(tmp_path, capsys, monkeypatch):
    fake = types.ModuleType("ray")
    fake.is_initialized = lambda: False

    def init(address=None):
        raise AssertionError("ray.init was called: it would wait for minutes")

    fake.init = init
    monkeypatch.setitem(sys.modules, "ray", fake)
    with socket.socket() as probe:  # a port of this machine that nothing listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    path = write(tmp_path, "s.yaml", VALID_YAML)
    argv = ["sweep", str(path), "--out", str(tmp_path / "o"), "--backend", "ray"]
    assert main([*argv, "--address", f"127.0.0.1:{port}"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(
        f"error: backend 'ray' could not start on the cluster at '127.0.0.1:{port}': "
        "ConnectionRefusedError"
    )
