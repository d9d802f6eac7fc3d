"""Malformed model files: every one is refused with one ``ValueError``, quickly and cheaply.

The corpus is generated here from a good file (no binary files are committed): truncations, bit
flips, wrong dtypes and shapes, huge declared shapes, zip bombs, non-finite tables, out-of-range
fields, missing and extra keys, JSON that is not an object, and pickled object arrays. Each must
raise ``ValueError`` naming the file (``FileNotFoundError`` for a missing one), never another
exception, never run code, and stay far below the decompression cap in memory.
"""

from __future__ import annotations

import io
import json
import struct
import tracemalloc
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numpy.lib import format as npy
from support import examples

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl.agents import (
    DeconvolutionQLearning,
    MultipleModelQLearning,
    QLearning,
    load_agent,
)
from delayed_rl.agents.common import persistence, save_util
from delayed_rl.agents.common.q_table import MAX_TABLE_BYTES
from delayed_rl.agents.deconvolution import regression as regression_module
from delayed_rl.agents.registry import REGISTRY, agent_class
from delayed_rl.delays import Poisson
from delayed_rl.envs.gridworld import GridWorldEnv
from delayed_rl.wrappers import RewardDelay

GRID3 = "delayed_rl/GridWorld-3x3-v0"
MEMORY_BOUND = 32 * 2**20
"""The most a refused file may make the loader allocate (the cap is 1 GiB: far below it)."""
MARKER = Path(__file__).with_name("pickle-ran-code.marker")


class RunsCode:
    """Unpickling this creates :data:`MARKER`: a pickle that runs code when loaded."""

    def __reduce__(self):
        return (open, (str(MARKER), "w"))


@dataclass
class Base:
    """The good model file the corpus is derived from."""

    data: bytes
    metadata: dict[str, Any]
    arrays: dict[str, np.ndarray]


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Base:
    env = gym.make(GRID3, reward_delay=1)
    path = (
        QLearning(env, q_init=5.0, seed=0)
        .learn(300, compiled=False)
        .save(tmp_path_factory.mktemp("good") / "good")
    )
    with np.load(path) as data:
        arrays = {key: data[key] for key in data.files}
    metadata = json.loads(str(arrays.pop("metadata")))
    return Base(path.read_bytes(), metadata, arrays)


# ---------------------------------------------------------------------- building files
def npz(arrays: dict[str, Any], metadata: Any, compress: bool = True) -> bytes:
    """An ``.npz`` archive of ``arrays`` plus ``metadata`` (JSON-encoded unless an array)."""
    if not isinstance(metadata, np.ndarray):
        metadata = np.array(json.dumps(metadata))
    buffer = io.BytesIO()
    (np.savez_compressed if compress else np.savez)(buffer, **arrays, metadata=metadata)
    return buffer.getvalue()


DROP = object()
"""A metadata value for :func:`changed`: remove the field."""


def changed(base: Base, metadata: dict | None = None, drop: tuple = (), **arrays: Any) -> bytes:
    """The base file with metadata fields (``"a.b"``: nested) set or dropped, arrays replaced."""
    meta = json.loads(json.dumps(base.metadata))
    for key, value in (metadata or {}).items():
        target, _, field = key.rpartition(".")
        holder = meta[target] if target else meta
        if value is DROP:
            holder.pop(field)
        else:
            holder[field] = value
    merged = {k: v for k, v in {**base.arrays, **arrays}.items() if k not in drop}
    return npz(merged, meta)


def npy_member(header: dict[str, Any], data: bytes = b"", version=(1, 0)) -> bytes:
    """A ``.npy`` member: a (possibly lying) header followed by ``data``."""
    buffer = io.BytesIO()
    if version == (1, 0):
        npy.write_array_header_1_0(buffer, header)
    else:
        npy.write_array_header_2_0(buffer, header)
    return buffer.getvalue() + data


def npy_of(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    npy.write_array(buffer, array, allow_pickle=True)
    return buffer.getvalue()


@dataclass
class Member:
    """One member of a hand-made zip: its name, stored bytes, method and declared size/CRC."""

    name: str
    raw: bytes
    method: int = 0
    size: int | None = None
    crc: int | None = None


def deflated(name: str, content: bytes) -> Member:
    compressor = zlib.compressobj(9, zlib.DEFLATED, -15)
    raw = compressor.compress(content) + compressor.flush()
    return Member(name, raw, 8, len(content), zlib.crc32(content))


def zero_bomb(name: str, head: bytes, mib: int, declared: int | None = None) -> Member:
    """``head`` then ``mib`` MiB of zeros, deflated in ~1 KiB per MiB (repeated flushed blocks)."""
    compressor = zlib.compressobj(9, zlib.DEFLATED, -15)
    start = compressor.compress(head) + compressor.flush(zlib.Z_FULL_FLUSH)
    block = compressor.compress(bytes(2**20)) + compressor.flush(zlib.Z_FULL_FLUSH)
    raw = start + block * mib + compressor.flush()
    size = len(head) + mib * 2**20 if declared is None else declared
    return Member(name, raw, 8, size, 0)  # the CRC is wrong: it must never be reached


def hand_zip(members: list[Member]) -> bytes:
    """A zip archive written field by field, so that sizes and CRCs can lie."""
    out, directory = io.BytesIO(), io.BytesIO()
    for member in members:
        name = member.name.encode()
        size = len(member.raw) if member.size is None else member.size
        crc = zlib.crc32(member.raw) if member.crc is None else member.crc
        fields = (20, 0, member.method, 0, 33, crc, len(member.raw), size, len(name))
        offset = out.tell()
        out.write(b"PK\x03\x04" + struct.pack("<HHHHHIIIHH", *fields, 0) + name + member.raw)
        central = struct.pack("<HHHHHHIIIHHHHHII", 20, *fields, 0, 0, 0, 0, 0, offset)
        directory.write(b"PK\x01\x02" + central + name)
    start, cd = out.tell(), directory.getvalue()
    count = len(members)
    out.write(cd + b"PK\x05\x06" + struct.pack("<HHHHIIH", 0, 0, count, count, len(cd), start, 0))
    return out.getvalue()


def good_members(base: Base, **replaced: bytes) -> list[Member]:
    """The base file's members, stored, with some replaced by raw ``.npy`` bytes."""
    contents = {name: npy_of(value) for name, value in base.arrays.items()}
    contents["metadata"] = npy_of(np.array(json.dumps(base.metadata)))
    contents.update(replaced)
    return [Member(f"{name}.npy", content) for name, content in contents.items()]


def with_states(base: Base, n: int) -> dict[str, Any]:
    """Metadata fields declaring ``n`` states."""
    return {"observation_space": {"type": "Discrete", "n": n, "start": 0}}


# ---------------------------------------------------------------------- the corpus
Case = tuple[str, Callable[[Base], bytes], str]
"""(id, build the file from the base, a fragment the message must contain)."""

F8 = "<f8"
HUGE = 5 * 10**7


def _bomb_file(base: Base, states: int, mib: int) -> bytes:
    """A q_table bomb declaring ``states`` × 1 × 4 values, ``mib`` MiB of deflated zeros."""
    head = npy_member({"descr": F8, "fortran_order": False, "shape": (states, 1, 4)})
    meta = json.loads(json.dumps(base.metadata))
    meta["observation_space"]["n"] = states
    members = [m for m in good_members(base) if m.name not in ("q_table.npy", "metadata.npy")]
    members.append(Member("metadata.npy", npy_of(np.array(json.dumps(meta)))))
    members.append(zero_bomb("q_table.npy", head, mib))
    return hand_zip(members)


def _lying_bomb(base: Base) -> bytes:
    """A q_table declaring its true 288 bytes whose deflated stream inflates to 200 MiB."""
    head = npy_member({"descr": F8, "fortran_order": False, "shape": (9, 1, 4)})
    bomb = zero_bomb("q_table.npy", head, 200, declared=len(head) + 288)
    return hand_zip([m for m in good_members(base) if m.name != "q_table.npy"] + [bomb])


def _metadata_bomb(base: Base) -> bytes:
    """A metadata string of 20 MB (over MAX_METADATA_BYTES) from 20 KB of deflated zeros."""
    head = npy_member({"descr": "<U5000000", "fortran_order": False, "shape": ()})
    bomb = zero_bomb("metadata.npy", head, 20, declared=len(head) + 20_000_000)
    return hand_zip([m for m in good_members(base) if m.name != "metadata.npy"] + [bomb])


STRUCTURE: list[Case] = [
    ("empty", lambda b: b"", "not a readable"),
    ("text", lambda b: b"not a model at all", "not a readable"),
    ("npy", lambda b: npy_of(np.arange(3)), "single .npy array"),
    ("pickle", lambda b: __import__("pickle").dumps(RunsCode()), "not a readable"),
    ("zip of nothing", lambda b: hand_zip([]), "no metadata string"),
    ("not npy members", lambda b: hand_zip([Member("x.txt", b"hello")]), "member 'x.txt'"),
    (
        "duplicate members",
        lambda b: hand_zip([*good_members(b), Member("q_table.npy", npy_of(np.zeros(3)))]),
        "distinct NAME.npy",
    ),
    (
        "bzip2 member",
        lambda b: hand_zip([Member("q_table.npy", b"BZh9", method=12)]),
        "compression method 12",
    ),
    (
        "member not npy",
        lambda b: hand_zip(good_members(b, q_table=b"garbage" * 10)),
        "array 'q_table'",
    ),
    (
        "npy version 3",
        lambda b: hand_zip(good_members(b, q_table=b"\x93NUMPY\x03\x00" + bytes(20))),
        "unsupported .npy format version",
    ),
    (
        "npy header of 1 GB",
        lambda b: hand_zip(
            good_members(b, q_table=b"\x93NUMPY\x02\x00" + struct.pack("<I", 2**30))
        ),
        "a .npy header of",
    ),
    (
        "npy header not a dict",
        lambda b: hand_zip(
            good_members(b, q_table=b"\x93NUMPY\x01\x00" + struct.pack("<H", 6) + b"[1, 2]")
        ),
        "array 'q_table'",
    ),
    (
        "directory of 3000 members",
        lambda b: hand_zip([Member(f"a{i}.npy", b"") for i in range(3_000)]),
        "archive directory",
    ),
    (
        "data shorter than the header says",
        lambda b: hand_zip(
            good_members(
                b,
                q_table=npy_member({"descr": F8, "fortran_order": False, "shape": (9, 1, 4)})
                + bytes(100),
            )
        ),
        "declares shape (9, 1, 4)",
    ),
    (
        "huge declared shape, tiny data",
        lambda b: hand_zip(
            good_members(
                b,
                q_table=npy_member({"descr": F8, "fortran_order": False, "shape": (HUGE, 1, 4)})
                + bytes(288),
            )
        ),
        "declares shape (50000000, 1, 4)",
    ),
    (
        "huge declared space (10 KB file, 5e7 states)",
        lambda b: changed(b, with_states(b, HUGE)),
        "q_table must be a float64 array of shape (50000000, 1, 4)",
    ),
    (
        "zip bomb past the cap (2 MB inflating to 2.1 GB)",
        lambda b: _bomb_file(b, (2100 * 2**20) // 32, 2100),
        "refused before decompressing",
    ),
    (
        "zip bomb under the cap, tables over the limit",
        lambda b: _bomb_file(b, (960 * 2**20) // 32, 960),
        "MAX_TABLE_BYTES",
    ),
    ("zip bomb lying about its size", lambda b: _lying_bomb(b), "not a readable"),
    ("metadata bomb", lambda b: _metadata_bomb(b), "MAX_METADATA_BYTES"),
    (
        "metadata of 100k nested lists",
        lambda b: npz(b.arrays, np.array("[" * 100_000 + "]" * 100_000)),
        "not valid JSON",
    ),
    ("metadata not JSON", lambda b: npz(b.arrays, np.array("{oops")), "not valid JSON"),
    ("metadata bytes", lambda b: npz(b.arrays, np.array(b"{}")), "plain numbers and text"),
    ("metadata 2-D", lambda b: npz(b.arrays, np.array([["{}"]])), "no metadata string"),
    ("no metadata", lambda b: hand_zip(good_members(b)[:-1]), "no metadata string"),
]
for _kind in ("[]", '"a string"', "3", "null", "true"):
    STRUCTURE.append(
        (f"JSON {_kind}", lambda b, k=_kind: npz(b.arrays, np.array(k)), "lacks format")
    )

PICKLES: list[Case] = [
    (
        "object q_table",
        lambda b: npz({**b.arrays, "q_table": np.array([RunsCode()], dtype=object)}, b.metadata),
        "allow_pickle=False",
    ),
    (
        "object metadata",
        lambda b: npz(b.arrays, np.array([RunsCode(), json.dumps(b.metadata)], dtype=object)),
        "allow_pickle=False",
    ),
    (
        "object extra array",
        lambda b: npz({**b.arrays, "payload": np.array([RunsCode()], dtype=object)}, b.metadata),
        "allow_pickle=False",
    ),
    (
        "structured q_table",
        lambda b: npz({**b.arrays, "q_table": np.zeros(36, dtype=[("a", "<f8")])}, b.metadata),
        "plain numbers and text",
    ),
]

ARRAYS: list[Case] = [
    ("q_table float32", lambda b: changed(b, q_table=np.zeros((9, 1, 4), np.float32)), "q_table"),
    ("q_table int64", lambda b: changed(b, q_table=np.zeros((9, 1, 4), np.int64)), "q_table"),
    ("q_table transposed", lambda b: changed(b, q_table=np.zeros((4, 1, 9))), "q_table"),
    ("q_table 4-D", lambda b: changed(b, q_table=np.zeros((9, 1, 4, 1))), "q_table"),
    ("q_table text", lambda b: changed(b, q_table=np.array("zeros")), "q_table"),
    ("delay_estimates float", lambda b: changed(b, delay_estimates=np.zeros(1)), "delay_estimates"),
    ("delay_estimates wrong", lambda b: changed(b, delay_estimates=np.ones(1, np.int64)), "match"),
    ("acting_counts float", lambda b: changed(b, acting_counts=np.zeros(1)), "acting_counts"),
    ("acting_counts 2", lambda b: changed(b, acting_counts=np.zeros(2, np.int64)), "acting_counts"),
    (
        "acting_counts < 0",
        lambda b: changed(b, acting_counts=-np.ones(1, np.int64)),
        "acting_counts",
    ),
    ("rng_block 2-D", lambda b: changed(b, rng_block=np.zeros((2, 2))), "rng_block"),
    ("rng_block int", lambda b: changed(b, rng_block=np.zeros(3, np.int64)), "rng_block"),
    ("rng_block long", lambda b: changed(b, rng_block=np.zeros(5_000)), "rng_block"),
    ("rng_block 7.0", lambda b: changed(b, rng_block=np.full(3, 7.0)), "rng_block"),
    ("rng_block 1.0", lambda b: changed(b, rng_block=np.ones(3)), "rng_block"),
    ("rng_block < 0", lambda b: changed(b, rng_block=np.full(3, -0.5)), "rng_block"),
    ("rng_block nan", lambda b: changed(b, rng_block=np.full(3, np.nan)), "rng_block"),
    ("predict block 28", lambda b: changed(b, predict_rng_block=np.full(9, 7.0)), "predict_rng"),
]
for _value in (np.nan, np.inf, -np.inf):
    ARRAYS.append(
        (
            f"q_table {_value}",
            lambda b, v=_value: changed(b, q_table=np.full((9, 1, 4), v)),
            "non-finite",
        )
    )
for _name in ("q_table", "delay_estimates", "rng_block", "predict_rng_block", "acting_counts"):
    ARRAYS.append((f"no {_name}", lambda b, n=_name: changed(b, drop=(n,)), _name))
ARRAYS.append(
    ("extra array", lambda b: changed(b, extra=np.zeros(3)), "unexpected arrays ['extra']")
)

_PCG = {"bit_generator": "PCG64", "state": {"state": 5, "inc": 7}, "has_uint32": 0, "uinteger": 0}
FIELDS: dict[str, list[Any]] = {
    "exploration_rate": [5, -0.1, "0.1", True, None, [0.1], 1e400],
    "progress_remaining": [2.0, -1, "1", float("nan")],
    "num_timesteps": [-1, 1.5, True, "10", 10**400],
    "class": [3, None, "PPO", ["QLearning"]],
    "format_version": [99, 0, True, "1", 1.0],
    "library_version": [3],
    "hyperparameters": [[], "x", None, 3],
    "hyperparameters.gamma": [5.0, -1, "0.9", True, None],
    "hyperparameters.learning_rate": [
        0.1,
        {"type": "constant"},
        {"type": "constant", "value": "0.1"},
        {"type": "constant", "value": 0.0},
        {"type": "constant", "value": 1e400},
        {"type": "linear", "start": 0.5},
        {"type": "linear", "start": 0.5, "end": 2.0, "end_fraction": 0.5},
        {"type": "callable", "value": 0.1, "repr": 3},
        {"type": "nope", "value": 0.1},
        {"type": "constant", "value": 0.1, "extra": 1},
    ],
    "hyperparameters.seed": [-1, 1.5, "0"],
    "hyperparameters.verbose": [-1, "x"],
    "hyperparameters.q_init": [float("inf"), "5"],
    "hyperparameters.exploration_fraction": [0.0, 2.0],
    "hyperparameters.delay_estimates": [[0, 1], [10**9], [10**30], "0", [-1], [0.5], None],
    "hyperparameters.policy": ["MlpPolicy"],
    "observation_space": [
        {"type": "Box"},
        {"type": "Discrete", "n": 0, "start": 0},
        {"type": "Discrete", "n": True, "start": 0},
        {"type": "Discrete", "n": 9.0, "start": 0},
        {"type": "Discrete", "n": 10**30, "start": 0},
        {"type": "Discrete", "n": 9, "start": 2**70},
        {"type": "Discrete", "n": 9, "start": 0, "extra": 1},
        [9],
        None,
    ],
    "action_space": ["Discrete(4)", {"type": "Discrete", "n": 4}],
    "rng_state": [
        None,
        "PCG64",
        [1, 2],
        {**_PCG, "bit_generator": "MT19937"},
        {**_PCG, "state": {"state": 5}},
        {**_PCG, "state": {"state": 5, "inc": 8}},
        {**_PCG, "state": {"state": -5, "inc": 7}},
        {**_PCG, "state": {"state": 2**130, "inc": 7}},
        {**_PCG, "state": {"state": "5", "inc": 7}},
        {**_PCG, "state": [5, 7]},
        {**_PCG, "has_uint32": 2},
        {**_PCG, "uinteger": -1},
        {**_PCG, "uinteger": 2**40},
        {**_PCG, "extra": 0},
    ],
    "predict_rng_state": [{**_PCG, "bit_generator": None}],
    "unexpected_field": [1],
}
_FRAGMENTS = {
    "format_version": "format version",
    "hyperparameters": "hyper-parameters",
    "hyperparameters.policy": "unknown",
}
METADATA: list[Case] = [
    (
        f"{field}={value!r}"[:60],
        lambda b, f=field, v=value: changed(b, {f: v}),
        _FRAGMENTS.get(field, field.rpartition(".")[2]),
    )
    for field, values in FIELDS.items()
    for value in values
]
METADATA.append(
    (
        "action_space of 28 actions",
        lambda b: changed(b, {"action_space": {"type": "Discrete", "n": 28, "start": 0}}),
        "q_table must be a float64 array of shape (9, 1, 28)",
    )
)
MISSING: list[Case] = [
    (f"no {field}", lambda b, f=field: changed(b, {f: DROP}), "")
    for field in (
        *sorted(persistence._METADATA_KEYS - {"library_version"}),  # all but the optional one
        "hyperparameters.gamma",
        "hyperparameters.learning_rate",
        "hyperparameters.delay_estimates",
    )
]

CORPUS = STRUCTURE + PICKLES + ARRAYS + METADATA + MISSING


# ---------------------------------------------------------------------- the tests
def refused(path: Path, cls: type = QLearning) -> ValueError:
    """The ``ValueError`` loading ``path`` raises, within :data:`MEMORY_BOUND`."""
    tracemalloc.start()
    try:
        with pytest.raises(ValueError) as info:
            cls.load(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < MEMORY_BOUND, f"{peak / 2**20:.1f} MiB"
    assert not MARKER.exists(), "loading ran code from the file"
    return info.value


@pytest.mark.parametrize(("build", "fragment"), [c[1:] for c in CORPUS], ids=[c[0] for c in CORPUS])
def test_a_malformed_file_is_refused_with_one_clear_error(base, tmp_path, build, fragment):
    path = tmp_path / "bad.npz"
    path.write_bytes(build(base))
    error = refused(path)
    message = str(error)
    assert str(path) in message and fragment in message, message
    assert "\n" not in message


def test_the_corpus_starts_from_a_good_file(base, tmp_path):
    path = tmp_path / "good.npz"
    path.write_bytes(base.data)
    assert QLearning.load(path).num_timesteps == 300
    # the generators themselves write loadable files when nothing is changed
    for data in (
        changed(base),
        npz(base.arrays, base.metadata, False),
        hand_zip(good_members(base)),
    ):
        path.write_bytes(data)
        np.testing.assert_array_equal(QLearning.load(path).q_table, base.arrays["q_table"])


@pytest.mark.parametrize("compress", [True, False], ids=["deflated", "stored"])
def test_truncated_files_are_refused(base, tmp_path, compress):
    data = base.data if compress else npz(base.arrays, base.metadata, False)
    rng = np.random.default_rng(1)
    cuts = {0, 1, 5, 21, 22, 100, len(data) // 2, len(data) - 23, len(data) - 22, len(data) - 1}
    cuts |= set(rng.integers(0, len(data), 40).tolist())
    for cut in sorted(cuts):
        path = tmp_path / f"cut{cut}.npz"
        path.write_bytes(data[:cut])
        assert str(path) in str(refused(path))


@pytest.mark.parametrize("compress", [True, False], ids=["deflated", "stored"])
@pytest.mark.statistical
def test_bit_flips_are_refused_or_harmless(base, tmp_path, compress):
    """A flipped bit gives a ``ValueError`` or, in a field nothing reads, the same agent.

    A timestamp, say; never another exception, another agent, or a large allocation.
    """
    data = base.data if compress else npz(base.arrays, base.metadata, False)
    rng = np.random.default_rng(2)
    refusals = 0
    for position in rng.integers(0, len(data) * 8, 250).tolist():
        flipped = bytearray(data)
        flipped[position // 8] ^= 1 << (position % 8)
        path = tmp_path / "flipped.npz"
        path.write_bytes(bytes(flipped))
        tracemalloc.start()
        try:
            agent = QLearning.load(path)
        except ValueError as error:
            refusals += 1
            assert str(path) in str(error)
        else:
            np.testing.assert_array_equal(agent.q_table, base.arrays["q_table"])
            assert agent.num_timesteps == 300
            assert agent._uniform.get_state()[0] == base.metadata["rng_state"]
        finally:
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
        assert peak < MEMORY_BOUND
    assert refusals > 150  # most bits matter


@pytest.mark.parametrize(
    "delays",
    [
        [10**9],
        [0, 10**30],
        pytest.param(list(range(0, 10**8, 1_000)), marks=pytest.mark.large),  # 100,000 delays
    ],
)
def test_a_refused_table_names_its_size_before_allocating(tmp_path, delays):
    """The tables a file declares are checked against MAX_TABLE_BYTES before allocation."""
    good = MultipleModelQLearning(GRID3, max_delay_estimate=2, seed=0).save(tmp_path / "mmq")
    with np.load(good) as data:
        arrays = {key: data[key] for key in data.files}
    metadata = json.loads(str(arrays.pop("metadata")))
    metadata["hyperparameters"]["delay_estimates"] = delays
    path = tmp_path / "big.npz"
    path.write_bytes(npz(arrays, metadata))
    message = str(refused(path, MultipleModelQLearning))
    assert "delay_estimates must keep the tables within MAX_TABLE_BYTES = 1 GiB" in message
    assert "GiB" in message and MAX_TABLE_BYTES == 2**30


def test_every_library_agent_round_trips_through_the_checks(tmp_path):
    """The checks accept what ``save`` writes, whatever the class and its state."""
    env = gym.make("delayed_rl/GridWorld-5x5-v0", reward_delay=2)
    agent = MultipleModelQLearning(env, max_delay_estimate=6, q_init=5.0, seed=3).learn(2_000)
    agent.predict(np.arange(25))  # the predict stream has a partial block
    loaded = load_agent(agent.save(tmp_path / "m"))
    np.testing.assert_array_equal(loaded.q_table, agent.q_table)
    np.testing.assert_array_equal(loaded.predict(np.arange(25))[0], agent.predict(np.arange(25))[0])


def test_save_refuses_what_load_would_refuse(tmp_path, monkeypatch):
    monkeypatch.setattr(save_util, "MAX_MODEL_BYTES", 1_000)
    with pytest.raises(ValueError, match="cannot save .* over MAX_MODEL_BYTES"):
        QLearning(GRID3).save(tmp_path / "m")
    assert not (tmp_path / "m.npz").exists()


def test_a_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match="no model file"):
        QLearning.load(tmp_path / "absent")
    (tmp_path / "folder.npz").mkdir()
    with pytest.raises(ValueError, match="not a readable"):
        QLearning.load(tmp_path / "folder.npz")


def test_sb3_callback_names_find_the_file(tmp_path):
    """EvalCallback saves ``best_model`` (written ``best_model.npz``); users load ``.zip``."""
    agent = QLearning(GRID3, seed=0).learn(10)
    assert agent.save(tmp_path / "best_model") == tmp_path / "best_model.npz"
    for name in ("best_model", "best_model.zip", "best_model.npz"):
        assert QLearning.load(tmp_path / name).num_timesteps == 10
    assert agent.save(tmp_path / "rl_model_10_steps.zip").name == "rl_model_10_steps.zip"
    for name in ("rl_model_10_steps", "rl_model_10_steps.zip", "rl_model_10_steps.npz"):
        assert QLearning.load(tmp_path / name).num_timesteps == 10


# ---------------------------------------------------------------------- every agent class
# Files of every agent class, each of their state arrays and metadata fields mutated in turn:
# each must be refused with one ValueError/TypeError that names the file and the field, or load
# to an agent that learns 300 steps with finite tables (and, for DeconvQ, a pmf on the simplex).
def _grid_env() -> gym.Env:
    return gym.make(GRID3, reward_delay=2)


def _oracle_env() -> gym.Env:
    return RewardDelay(gym.make(GRID3), Poisson(2.0), record_arrivals=True)


def _episodic_env(mode: str = "flush") -> gym.Env:
    """Episodes of 15 steps: DeconvQ's statistics then hold ended windows (and flushed rewards)."""
    return RewardDelay(GridWorldEnv(size=3, max_steps=15), Poisson(2.0), on_episode_end=mode)


@dataclass(frozen=True)
class Kind:
    """An agent class as the corpus builds it: its constructor, its env, its layout."""

    make: Callable[[gym.Env], Any]
    env: Callable[[], gym.Env]
    hashed: bool = False  # DeconvQ's statistics in the hashed layout


SPECIAL_KINDS = {
    "MMQ with options": Kind(
        lambda e: MultipleModelQLearning(
            e,
            max_delay_estimate=3,
            reward_kernel=1.0,
            delay_trace=0.5,
            greedy_window=200,
            q_init=5.0,
            seed=0,
        ),
        _grid_env,
    ),
    "DeconvQ known delay": Kind(
        lambda e: DeconvolutionQLearning(
            e, delay=Poisson(2.0), max_delay_estimate=6, q_init=5.0, seed=0
        ),
        _episodic_env,
    ),
    "DeconvQ learned delay": Kind(
        lambda e: DeconvolutionQLearning(e, max_delay_estimate=5, q_init=5.0, seed=0),
        lambda: _episodic_env("drop"),
    ),
    "DeconvQ hashed statistics": Kind(
        lambda e: DeconvolutionQLearning(e, max_delay_estimate=5, q_init=5.0, seed=0),
        _episodic_env,
        hashed=True,
    ),
}
"""Kinds with what a registered agent's example leaves off: MMQ's options, DeconvQ's layouts."""


def _registered_kind(name: str) -> Kind:
    """A registered agent built from its registry entry's ``example_arguments``, on the grid."""
    entry = REGISTRY[name]
    return Kind(
        lambda e: agent_class(name)(e, **entry.example_arguments, q_init=5.0, seed=0),
        _oracle_env if entry.needs_arrivals else _grid_env,
    )


KINDS = {
    **{entry.class_name: _registered_kind(name) for name, entry in REGISTRY.items()},
    **SPECIAL_KINDS,
}
"""The corpus's kinds: every registered agent as its entry builds it, and the special kinds."""


def test_the_corpus_has_a_file_of_every_registered_agent():
    for name, entry in REGISTRY.items():
        kind = KINDS[entry.class_name]
        assert type(kind.make(kind.env())) is agent_class(name), name


TRAINED = 900
"""Steps before saving: DeconvQ's first solve (at 1000) comes 100 steps into the 300 after."""
FIELD_VALUES: list[Any] = [None, "x", [1], {"a": 1}, True, -1, 0, 10**12, 10**30, 1.5, 1e308]
FIELD_VALUES += [float("nan"), DROP]
"""What each metadata field is set to in turn (JSON's NaN included; DROP: removed)."""


@pytest.fixture(scope="module")
def bases(tmp_path_factory) -> dict[str, Base]:
    """One good file of each :data:`KINDS`, trained :data:`TRAINED` steps."""
    folder = tmp_path_factory.mktemp("agents")
    out = {}
    for name, kind in KINDS.items():
        with pytest.MonkeyPatch.context() as patch:
            if kind.hashed:
                patch.setattr(regression_module, "DIRECT_LIMIT", 0)
            agent = kind.make(kind.env()).learn(TRAINED)
        if kind.hashed:
            assert agent._regression.layout == "hashed"
        path = agent.save(folder / name.replace(" ", "_"))
        with np.load(path) as data:
            arrays = {key: data[key] for key in data.files}
        out[name] = Base(path.read_bytes(), json.loads(str(arrays.pop("metadata"))), arrays)
    return out


def array_mutations(value: np.ndarray) -> list[tuple[str, Any]]:
    """``(label, replacement)`` for one state array: dtypes, shapes, values; ``DROP``: missing."""
    kind = value.dtype.kind
    out: list[tuple[str, Any]] = [
        ("float32", value.astype(np.float32)),
        ("int64" if kind == "f" else "float64", value.astype(np.int64 if kind == "f" else float)),
        ("int32", value.astype(np.int32)),
        ("bool", value.astype(bool)),
        ("text", np.array("x")),
        ("0-d", np.array(value.flat[0]) if value.size else np.zeros((), value.dtype)),
        ("extra axis", value[..., None]),
        ("missing", DROP),
    ]
    if value.ndim:
        longer = (
            np.concatenate([value, value[:1]]) if len(value) else np.zeros((1, *value.shape[1:]))
        )
        out.append(("longer", longer.astype(value.dtype)))
        if len(value):
            out.append(("shorter", value[:-1]))
    if not value.size:
        return out
    if kind == "f":
        specials: list[Any] = [np.nan, np.inf, -np.inf, 1e308, -1e308, 1e200, -1.0, 2.0, 0.5]
    elif kind in "iu":
        specials = [-1, 7, 2**31 - 1, 2**62, -(2**62)]
    else:
        specials = [True, False]
    for special in specials:
        if kind in "iu" and not np.iinfo(value.dtype).min <= special <= np.iinfo(value.dtype).max:
            continue
        for where in ("first", "all"):
            mutated = value.copy()
            if where == "first":
                mutated.flat[0] = special
            else:
                mutated[...] = special
            out.append((f"{where}={special!r}", mutated))
    return out


AgentCase = tuple[str, Callable[[Base], bytes], tuple[str, ...]]
"""(id, build the file from the kind's base, fragments one of which the message must contain)."""


def agent_corpus(base: Base) -> list[AgentCase]:
    """Every mutation of ``base``: each state array's, each metadata field's, extra ones."""
    cases: list[AgentCase] = []
    state = tuple(name for name in base.arrays)
    for name, value in base.arrays.items():
        for label, replacement in array_mutations(value):
            drop = (name,) if replacement is DROP else ()
            extra = {} if replacement is DROP else {name: replacement}
            fragments = (name, "regression_") if name.startswith("regression_") else (name,)
            cases.append(
                (f"{name} {label}", lambda b, d=drop, e=extra: changed(b, drop=d, **e), fragments)
            )
    cases.append(("extra array", lambda b: changed(b, extra=np.zeros(2)), ("extra",)))
    fields = [f for f in base.metadata if f not in ("format", "format_version", "class")]
    fields += [f"hyperparameters.{name}" for name in base.metadata["hyperparameters"]]
    for field in fields:
        for value in FIELD_VALUES:
            # a valid value that no longer fits the arrays is refused naming the array
            names = (field.rpartition(".")[2], "hyper-parameters", *state)
            cases.append(
                (f"{field}={value!r}"[:60], lambda b, f=field, v=value: changed(b, {f: v}), names)
            )
    cases.append(
        ("extra hyper-parameter", lambda b: changed(b, {"hyperparameters.extra": 1}), ("extra",))
    )
    return cases


def _sound_tables(agent: Any) -> list[np.ndarray]:
    tables = [agent.q_table]
    if isinstance(agent, MultipleModelQLearning):
        tables.append(agent.greedy_table)
    if isinstance(agent, DeconvolutionQLearning):
        tables += [agent.reward_model, agent.delay_pmf]
        pmf = agent.delay_pmf
        assert pmf.min() >= 0.0 and abs(pmf.sum() - 1.0) < 1e-6, pmf
    return tables


def refused_or_sound(kind: str, path: Path, fragments: tuple[str, ...]) -> str:
    """``"refused"`` (one clear error, little memory) or ``"loaded"`` (it then learns soundly)."""
    tracemalloc.start()
    try:
        agent = load_agent(path, KINDS[kind].env())
    except (ValueError, TypeError) as error:
        message = str(error)
        assert str(path) in message and "\n" not in message, message
        assert any(fragment in message for fragment in fragments), (fragments, message)
        return "refused"
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert peak < MEMORY_BOUND, f"{peak / 2**20:.1f} MiB"
    agent.learn(300)
    assert all(np.all(np.isfinite(table)) for table in _sound_tables(agent))
    return "loaded"


def _modified(base: Base, arrays: dict[str, Any] | None = None, **fields: Any) -> bytes:
    """The base with arrays replaced and metadata fields (``hyperparameters__x``: nested) set."""
    metadata = {key.replace("__", "."): value for key, value in fields.items()}
    return changed(base, metadata, **(arrays or {}))


def _free_row_counted(base: Base) -> np.ndarray:
    """The hashed counts with a lag-1 count in a row no couple holds (the lag-0 sums still right)."""
    cooc = base.arrays["regression_cooc"].copy()
    cooc[int(np.flatnonzero(base.arrays["regression_keys"] == -1)[0]), 1] = 1
    return cooc


_DECONV = ("DeconvQ known delay", "DeconvQ learned delay", "DeconvQ hashed statistics")
#: (kind, id, build, fragment): files the loader used to accept (or crash on) that it refuses.
REFUSED: list[tuple[str, str, Callable[[Base], bytes], str]] = [
    # the files
    *[
        (
            "DeconvQ learned delay",
            f"delay_pmf {pmf}",
            lambda b, p=pmf: _modified(b, {"delay_pmf": np.array(p, dtype=float)}),
            "delay_pmf",
        )
        for pmf in ([2, -1, 0, 0, 0, 0], [0] * 6, [7] * 6, [0.5, 0.5, 0.5, 0, 0, 0])
    ],
    (
        "DeconvQ learned delay",
        "reward_model 1e308",
        lambda b: _modified(b, {"reward_model": np.full(36, 1e308)}),
        "reward_model",
    ),
    (
        "DeconvQ learned delay",
        "solve_clock 2**62",
        lambda b: _modified(b, {"solve_clock": np.array([2**62, 2**62])}),
        "solve_clock",
    ),
    (
        "DeconvQ learned delay",
        "delay_iterations 10**12",
        lambda b: _modified(b, hyperparameters__delay_iterations=10**12),
        "MAX_DELAY_ITERATIONS",
    ),
    (
        "DeconvQ learned delay",
        "max_delay_estimate 10**9",
        lambda b: _modified(b, hyperparameters__max_delay_estimate=10**9),
        "MAX_DELAY_ESTIMATE",
    ),
    (
        "ExpectedCreditQLearning",
        "delay null",
        lambda b: _modified(b, hyperparameters__delay=None),
        "delay must be",
    ),
    # clocks and counters out of their ranges
    (
        "DeconvQ known delay",
        "solve_clock since >= gap",
        lambda b: _modified(b, {"solve_clock": np.array([5, 5])}),
        "solve_clock",
    ),
    (
        "DeconvQ known delay",
        "delay_pmf not the known delay's",
        lambda b: _modified(b, {"delay_pmf": np.full(7, 1 / 7)}),
        "known delay's pmf",
    ),
    (
        "DeconvQ known delay",
        "solve_interval 10**30",
        lambda b: _modified(b, hyperparameters__solve_interval=10**30),
        "MAX_SOLVE_INTERVAL",
    ),
    (
        "DeconvQ known delay",
        "ridge 1e300",
        lambda b: _modified(b, hyperparameters__ridge=1e300),
        "ridge must be at most",
    ),
    (
        "DeconvQ hashed statistics",
        "a free row holding counts",
        lambda b: _modified(b, {"regression_cooc": _free_row_counted(b)}),
        "a free row of the hashed table holds counts",
    ),
    (
        "DeconvQ learned delay",
        "by_lag 1e308",
        lambda b: _modified(
            b, {"regression_by_lag": np.full_like(b.arrays["regression_by_lag"], 1e308)}
        ),
        "regression_by_lag",
    ),
    (
        "MMQ with options",
        "greedy_clock past its interval",
        lambda b: _modified(b, {"greedy_clock": np.array([10**6, 1])}),
        "greedy_clock[0]",
    ),
    (
        "MMQ with options",
        "greedy_window 10**30",
        lambda b: _modified(b, hyperparameters__greedy_window=10**30),
        "MAX_TIMESTEPS",
    ),
    (
        "MMQ with options",
        "greedy_table 1e300",
        lambda b: _modified(b, {"greedy_table": np.full((9, 4, 4), 1e300)}),
        "greedy_table",
    ),
    *[
        (
            kind,
            "q_table 1e300",
            lambda b: _modified(b, {"q_table": np.full_like(b.arrays["q_table"], 1e300)}),
            "q_table",
        )
        for kind in KINDS
    ],
    *[
        (kind, f"{field}={value}", lambda b, f=field, v=value: _modified(b, **{f: v}), fragment)
        for kind in ("QLearning", "OracleQLearning", "DeconvQ learned delay")
        for field, value, fragment in (
            ("num_timesteps", 2**62, "MAX_TIMESTEPS"),
            ("hyperparameters__seed", 2**64, "MAX_SEED_VALUE"),
            ("hyperparameters__q_init", 1e300, "MAX_ABS_VALUE"),
        )
    ],
    *[
        (
            kind,
            "acting_counts 2**62",
            lambda b: _modified(
                b, {"acting_counts": np.full_like(b.arrays["acting_counts"], 2**62)}
            ),
            "acting_counts",
        )
        for kind in ("FixedDelayQLearning", "ExpectedCreditQLearning", _DECONV[0])
    ],
]


@pytest.mark.parametrize(
    ("kind", "build", "fragment"),
    [(c[0], *c[2:]) for c in REFUSED],
    ids=[f"{c[0]}: {c[1]}" for c in REFUSED],
)
def test_every_agent_class_refuses_out_of_range_state(bases, tmp_path, kind, build, fragment):
    path = tmp_path / "bad.npz"
    path.write_bytes(build(bases[kind]))
    tracemalloc.start()
    try:
        with pytest.raises(ValueError) as error:  # (not learning: some used to hang it)
            load_agent(path, KINDS[kind].env())
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    message = str(error.value)
    assert str(path) in message and fragment in message and "\n" not in message, message
    assert peak < MEMORY_BOUND, f"{peak / 2**20:.1f} MiB"


@given(data=st.data())
@settings(
    max_examples=examples(200),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
def test_a_mutated_file_of_any_class_is_refused_or_learns_soundly(bases, tmp_path, data):
    kind = data.draw(st.sampled_from(sorted(KINDS)), label="kind")
    name, build, fragments = data.draw(st.sampled_from(agent_corpus(bases[kind])), label="case")
    path = tmp_path / "case.npz"
    path.write_bytes(build(bases[kind]))
    refused_or_sound(kind, path, fragments)


@pytest.mark.statistical
@pytest.mark.parametrize("kind", sorted(KINDS))
def test_every_mutation_of_every_class_is_refused_or_learns_soundly(bases, tmp_path, kind, capsys):
    """The whole corpus of a class (about 300 to 650 files), each one in turn.

    The good file itself loads and learns on: the checks accept what ``save`` writes.
    """
    good = tmp_path / "good.npz"
    good.write_bytes(bases[kind].data)
    assert refused_or_sound(kind, good, ()) == "loaded"
    outcomes = []
    for name, build, fragments in agent_corpus(bases[kind]):
        path = tmp_path / "case.npz"
        path.write_bytes(build(bases[kind]))
        try:
            outcomes.append(refused_or_sound(kind, path, fragments))
        except AssertionError as error:
            raise AssertionError(f"{kind}, {name}: {error}") from None
        capsys.readouterr()  # a file with verbose=10**12 logs as it learns
    assert outcomes.count("refused") > 0.8 * len(outcomes)
    assert outcomes.count("loaded") > 0
