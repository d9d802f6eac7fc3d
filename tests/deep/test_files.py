"""Reward model files, pickles, mappings and imports: what round-trips, and what is refused.

A saved model loads with the same predictions, counters, generator and history, owes the same
updates, and trains on to the same bits as the one kept in memory (every class, ``p`` known and
learned, and every kind of space: ``Dict`` observations of a ``Box``, a ``Discrete`` and a
``MultiBinary``, ``MultiDiscrete`` actions, a small image read flat and one read by the CNN); a
pickle does too. Each check of :func:`~delayed_rl.deep.load_reward_model` has a file crafted to
fail it, refused with a ``ValueError`` that says what is wrong (never garbage loaded silently).
:func:`~delayed_rl.deep.make_reward_model` refuses a setting the class does not take, by name.
``import delayed_rl.deep`` imports no torch, and without torch a name's first use says to
install the ``sb3`` extra.
"""

from __future__ import annotations

import io
import json
import os
import pickle
import re
import subprocess
import sys
import textwrap
import zipfile
from collections import OrderedDict

import numpy as np
import pytest
from gymnasium import spaces
from support import torch_on_one_thread  # noqa: F401  (the fixture)

from delayed_rl.delays import Constant, Geometric

pytestmark = [pytest.mark.sb3, pytest.mark.usefixtures("torch_on_one_thread")]


OBS = spaces.Box(-1.0, 1.0, (3,), np.float32)
ACT = spaces.Discrete(3)

KINDS = {
    "known": (
        "DeconvolutionRewardModel",
        {"delay": Geometric(0.5), "max_delay_estimate": 4, "window": 4},
    ),
    "learned": ("DeconvolutionRewardModel", {"delay": None, "max_delay_estimate": 4, "window": 4}),
    "carry": (
        "DeconvolutionRewardModel",
        {"delay": Constant(2), "on_episode_end": "carry", "window": 3},
    ),
    "rrd": ("ReturnDecompositionRewardModel", {"subset_size": 4}),
    "ircr": ("ReturnRegressionRewardModel", {}),
}


def build(name="learned", capacity=64, observation_space=OBS, action_space=ACT, **kwargs):
    import delayed_rl.deep as deep

    kind, settings = KINDS[name]
    settings = {
        "hidden_sizes": (8,),
        "batch_size": 16,
        "warmup_updates": 5,
        "capacity": capacity,
        "seed": 2,
        **settings,
        **kwargs,
    }
    return getattr(deep, kind)(observation_space, action_space, **settings)


def steps(count, seed, n_envs=2):
    """``count`` random steps of ``n_envs`` sub-envs: (obs, actions, rewards, ends, infos, next obs)."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield (
            rng.uniform(-1, 1, (n_envs, 3)).astype(np.float32),
            rng.integers(0, 3, n_envs),
            rng.normal(size=n_envs),
            rng.random(n_envs) < 0.15,
            [{"undelayed_reward": float(r)} for r in rng.normal(size=n_envs)],
            rng.uniform(-1, 1, (n_envs, 3)).astype(np.float32),
        )


def feed(model, count, seed, train=True):
    """Add ``count`` steps, taking the updates the schedule owes after each (``train``)."""
    for step in steps(count, seed):
        model.add(*step)
        if train:
            model.train_on_schedule()


_PROBE_RNG = np.random.default_rng(1)
PROBE = (
    _PROBE_RNG.uniform(-1, 1, (20, 3)).astype(np.float32),
    np.arange(20) % 3,
    _PROBE_RNG.uniform(-1, 1, (20, 3)).astype(np.float32),
)
"""Observations, actions and next observations that models are compared on."""


def assert_same_model(a, b, probe=PROBE):
    """``a`` and ``b`` hold the same bits: weights, Adam, generator, counters and history."""
    import torch

    assert type(a) is type(b)
    assert a.settings() == b.settings()
    assert a.observations.to_dict() == b.observations.to_dict()
    assert a.actions.to_dict() == b.actions.to_dict()
    for x, y in zip(a.network.parameters(), b.network.parameters(), strict=True):
        assert torch.equal(x, y)
    assert a._extra_state().keys() == b._extra_state().keys()
    for name, value in a._extra_state().items():
        assert torch.equal(value, b._extra_state()[name])
    adam_a, adam_b = a.optimizer.state_dict(), b.optimizer.state_dict()
    assert adam_a["param_groups"] == adam_b["param_groups"]
    assert adam_a["state"].keys() == adam_b["state"].keys()
    for index, state in adam_a["state"].items():
        for name, value in state.items():
            assert torch.equal(value, adam_b["state"][index][name])
    assert a.rng.bit_generator.state == b.rng.bit_generator.state
    if probe is not None:
        np.testing.assert_array_equal(a.predict(*probe), b.predict(*probe))
    assert a.updates_taken == b.updates_taken
    assert a.updates_due == b.updates_due
    assert a.ready == b.ready
    assert a.history.steps_added == b.history.steps_added
    assert a.history.n_envs == b.history.n_envs
    assert list(a.history.episodes) == list(b.history.episodes)
    arrays_a, arrays_b = history_arrays(a), history_arrays(b)
    assert arrays_a.keys() == arrays_b.keys()
    for name, value in arrays_a.items():
        assert value.dtype == arrays_b[name].dtype, name
        np.testing.assert_array_equal(value, arrays_b[name], err_msg=name)


def history_arrays(model):
    """The history's arrays by their file names (``obs.0``, ``obs.1``... for a ``Dict``)."""
    history = model.history
    return {
        **model.observations.arrays(history.obs, "obs"),
        **model.actions.arrays(history.action, "action"),
        **{
            name: getattr(history, name)
            for name in ("reward", "episode_end", "episode_cut", "undelayed")
        },
    }


# ---------------------------------------------------------------------- round trips
@pytest.mark.parametrize("name", sorted(KINDS))
@pytest.mark.parametrize("count", [40, 150])  # the ring (64 steps) not wrapped / wrapped
def test_a_saved_model_loads_and_trains_on_to_the_same_bits(tmp_path, name, count):
    from delayed_rl.deep import load_reward_model

    model = build(name)
    feed(model, count, seed=0)
    assert model.updates_taken == count + 5 and model.ready
    feed(model, 3, seed=5, train=False)  # saved with updates owed
    loaded = load_reward_model(model.save(tmp_path / "model.zip"))
    assert not loaded.takes_algorithm_seed
    assert_same_model(model, loaded)
    assert np.isclose(loaded.rmse(), model.rmse())
    assert loaded.train_on_schedule() == model.train_on_schedule() == 3
    assert_same_model(model, loaded)
    feed(model, 60, seed=1)
    feed(loaded, 60, seed=1)
    assert_same_model(model, loaded)
    if name == "learned":
        assert loaded.mean_delay == model.mean_delay != 2.0  # p moved, the same way


def test_the_episode_index_is_rebuilt_at_any_step(tmp_path):
    from delayed_rl.deep import ReturnRegressionRewardModel, load_reward_model

    # a ring of 6 steps, episodes of 1 to 4 steps ending at various offsets of the two sub-envs:
    # a save at every step meets every position of an episode's start against the oldest step
    model = ReturnRegressionRewardModel(OBS, ACT, hidden_sizes=(4,), capacity=6, seed=0)
    ends = [[0, 0, 1, 0, 1, 0, 0, 0, 1, 1, 0, 0, 1, 0, 0, 1, 0, 1, 1, 0, 0, 0, 1, 0, 1, 0],
            [1, 0, 0, 0, 1, 0, 1, 1, 0, 0, 0, 1, 0, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 0, 0]]  # fmt: skip
    resets = {4: [0, 1], 7: [1], 14: [0], 20: [0, 1]}  # episodes cut short before these steps
    for step, end in enumerate(zip(*ends, strict=True)):
        starts = np.isin([0, 1], resets.get(step, []))
        model.add(np.zeros((2, 3)), [0, 1], [step, -step], list(end), episode_starts=starts)
        loaded = load_reward_model(model.save(tmp_path / "model.zip"))
        assert list(loaded.history.episodes) == list(model.history.episodes), step
        held = model.history.rows(model.history.oldest, step + 1)
        assert np.array_equal(loaded.history.episode_cut[held], model.history.episode_cut[held])
        assert np.array_equal(loaded.history._episode_first, model.history._episode_first) or (
            model.history.oldest > 0
        )
        for env in range(2):  # and both go on alike
            assert loaded.history.episode_ids(env, model.history.oldest, step + 1).tolist() == (
                model.history.episode_ids(env, model.history.oldest, step + 1).tolist()
            )


@pytest.mark.parametrize("name", sorted(KINDS))
def test_a_pickled_model_trains_on_to_the_same_bits(name):
    model = build(name)
    feed(model, 70, seed=0)
    feed(model, 2, seed=4, train=False)  # pickled with updates owed
    copy = pickle.loads(pickle.dumps(model))
    assert_same_model(model, copy)
    assert copy.train_on_schedule() == model.train_on_schedule() == 2
    feed(model, 30, seed=3)
    feed(copy, 30, seed=3)
    assert_same_model(model, copy)


def test_a_model_without_steps_round_trips(tmp_path):
    from delayed_rl.deep import load_reward_model

    model = build("known")
    path = model.save(tmp_path / "fresh.zip")
    with zipfile.ZipFile(path) as archive:
        assert sorted(archive.namelist()) == ["reward_model.json", "weights.pt"]
    loaded = load_reward_model(path)
    assert loaded.history is None
    assert loaded.updates_taken == loaded.updates_due == 0
    np.testing.assert_array_equal(loaded.predict(*PROBE), model.predict(*PROBE))
    np.testing.assert_allclose(loaded.delay_pmf, model.delay_pmf)
    feed(model, 20, seed=0)
    feed(loaded, 20, seed=0)
    assert model.updates_taken == 20 + 5
    assert_same_model(model, loaded)


def test_an_unseeded_model_saves_the_seed_it_drew(tmp_path):
    from delayed_rl.deep import load_reward_model

    model = build("rrd", seed=None)
    assert model.takes_algorithm_seed
    loaded = load_reward_model(model.save(tmp_path / "unseeded.zip"))
    # the file holds the seed drawn: the loaded model is that model, not one to seed again
    assert loaded.seed == model.seed and not loaded.takes_algorithm_seed
    np.testing.assert_array_equal(loaded.predict(*PROBE), model.predict(*PROBE))
    feed(model, 30, seed=0)
    feed(loaded, 30, seed=0)
    assert_same_model(model, loaded)


def test_a_users_delay_is_saved_as_its_clipped_pmf(tmp_path):
    from delayed_rl.deep import load_reward_model
    from delayed_rl.delays import Delay

    class Twos(Delay):
        """A delay of 2 always, which ``to_dict`` cannot describe."""

        def sample(self, rng, size=None):
            return self._finish(np.full(() if size is None else size, 2), size)

        def pmf(self, k):
            return np.where(np.asarray(k) == 2, 1.0, 0.0)

        @property
        def mean(self):
            return 2.0

        @property
        def support_max(self):
            return 2

    model = build("known", delay=Twos(), max_delay_estimate=None)
    loaded = load_reward_model(model.save(tmp_path / "twos.zip"))
    assert loaded.settings()["delay"]["type"] == "Empirical"
    np.testing.assert_array_equal(loaded.delay_pmf, [0.0, 0.0, 1.0])


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize(
    ("observation_space", "action_space"),
    [
        (spaces.Box(-1.0, 1.0, (2, 3), np.float32), spaces.Box(-2.0, 2.0, (2,), np.float32)),
        (
            spaces.Box(np.array([-np.inf, 0.0]), np.array([np.inf, 5.0]), dtype=np.float64),
            spaces.Discrete(4, start=-1),
        ),
        (spaces.Box(0, 255, (4,), np.uint8), spaces.Box(0, 2**62, (1,), np.int64)),
        (spaces.Discrete(5, start=3), spaces.Discrete(2)),
    ],
)
def test_spaces_round_trip_exactly_and_quietly(tmp_path, observation_space, action_space):
    from delayed_rl.deep import ReturnRegressionRewardModel, load_reward_model

    model = ReturnRegressionRewardModel(observation_space, action_space, hidden_sizes=(4,), seed=0)
    observation_space.seed(0)
    action_space.seed(0)
    for end in (False, True, False):
        model.add(observation_space.sample()[None], action_space.sample()[None], [1.0], [end])
    loaded = load_reward_model(model.save(tmp_path / "spaces.zip"))
    assert loaded.observations.space == observation_space
    assert loaded.actions.space == action_space
    assert loaded.observations.space.dtype == observation_space.dtype
    assert_same_model(model, loaded, probe=None)


# Dict observations (in an order that is not sorted), integer spaces that do not start at 0,
# images read flat (under 36 pixels a side) and by SB3's NatureCNN
DICT_OBS = spaces.Dict(
    OrderedDict(
        [
            ("position", spaces.Box(-1.0, 1.0, (2,), np.float32)),
            ("room", spaces.Discrete(4, start=-1)),
            ("bits", spaces.MultiBinary([2, 3])),
        ]
    )
)
MULTI_ACT = spaces.MultiDiscrete([[3, 2], [2, 4]], start=[[1, 0], [-1, 2]])
SPACE_PAIRS = {
    "dict-multidiscrete": (DICT_OBS, MULTI_ACT),
    "small-image": (spaces.Box(0, 255, (8, 8, 3), np.uint8), spaces.Box(-1.0, 1.0, (2,))),
    "cnn-image": (spaces.Box(0, 255, (36, 36, 1), np.uint8), spaces.MultiBinary(2)),
}
STORED = {  # the history arrays a file holds, and their dtypes
    "dict-multidiscrete": {
        "obs.0": np.float32,
        "obs.1": np.int64,
        "obs.2": np.int8,
        "action": np.int64,
    },
    "small-image": {"obs": np.uint8, "action": np.float32},
    "cnn-image": {"obs": np.uint8, "action": np.int8},
}


def stack(space, values):
    """One value a sub-env, as a batch (a dict of batches for a ``Dict``)."""
    if isinstance(space, spaces.Dict):
        return {key: np.stack([value[key] for value in values]) for key in space.spaces}
    return np.stack(values)


def space_steps(observation_space, action_space, count, seed, n_envs=2):
    """Like ``steps``, with values sampled from the spaces."""
    observation_space.seed(seed)
    action_space.seed(seed + 1)
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield (
            stack(observation_space, [observation_space.sample() for _ in range(n_envs)]),
            stack(action_space, [action_space.sample() for _ in range(n_envs)]),
            rng.normal(size=n_envs),
            rng.random(n_envs) < 0.15,
            [{"undelayed_reward": float(r)} for r in rng.normal(size=n_envs)],
        )


def feed_spaces(model, count, seed, train=True):
    for step in space_steps(model.observations.space, model.actions.space, count, seed):
        model.add(*step)
        if train:
            model.train_on_schedule()


@pytest.mark.parametrize("name", ["learned", "rrd"])
@pytest.mark.parametrize("pair", sorted(SPACE_PAIRS))
def test_every_space_round_trips_and_trains_on_to_the_same_bits(tmp_path, name, pair):
    from delayed_rl.deep import load_reward_model

    observation_space, action_space = SPACE_PAIRS[pair]
    model = build(
        name,
        capacity=24,
        observation_space=observation_space,
        action_space=action_space,
        batch_size=8,
        warmup_updates=3,
    )
    assert (model.network.observation_features.cnn is not None) == (pair == "cnn-image")
    feed_spaces(model, 30, seed=0)  # the ring wraps
    assert model.ready
    feed_spaces(model, 2, seed=5, train=False)  # saved with updates owed
    path = model.save(tmp_path / f"{pair}.zip")
    with zipfile.ZipFile(path) as archive, np.load(io.BytesIO(archive.read("history.npz"))) as data:
        stored = {name: data[name].dtype for name in data.files}
    expected = {
        **STORED[pair],
        "reward": np.float64,
        "episode_end": bool,
        "episode_cut": bool,
        "undelayed": np.float64,
    }
    assert stored == {name: np.dtype(dtype) for name, dtype in expected.items()}
    loaded = load_reward_model(path)
    assert loaded.observations.space == observation_space
    assert list(loaded.observations.to_dict().get("keys", [])) == list(
        getattr(observation_space, "spaces", {})
    )  # a Dict's key order is kept (not sorted)
    assert loaded.actions.space == action_space
    obs, action, *_ = next(space_steps(observation_space, action_space, 1, seed=9))
    assert_same_model(model, loaded, probe=(obs, action))
    assert loaded.train_on_schedule() == model.train_on_schedule() == 2
    feed_spaces(model, 12, seed=1)
    feed_spaces(loaded, 12, seed=1)
    assert_same_model(model, loaded, probe=(obs, action))


# ---------------------------------------------------------------------- mappings
def test_a_mapping_makes_its_model_and_refuses_settings_the_class_does_not_take():
    from delayed_rl.deep import ReturnDecompositionRewardModel, make_reward_model

    spec = {"type": "ReturnDecompositionRewardModel", "subset_size": 4, "warmup_updates": 3}
    model = make_reward_model(spec, OBS, ACT)
    assert isinstance(model, ReturnDecompositionRewardModel)
    assert model.subset_size == 4 and model.warmup_updates == 3
    assert model.takes_algorithm_seed  # no seed: the algorithm's buffer gives it one
    seeded = make_reward_model({**spec, "seed": 9}, OBS, ACT)
    assert seeded.seed == 9 and not seeded.takes_algorithm_seed
    assert spec == {"type": "ReturnDecompositionRewardModel", "subset_size": 4, "warmup_updates": 3}
    assert make_reward_model(seeded, OBS, ACT) is seeded
    with pytest.raises(ValueError, match="reward_model was made for the observation_space"):
        make_reward_model(seeded, spaces.Box(-1.0, 1.0, (4,), np.float32), ACT)
    for kind, unknown in [
        ("ReturnDecompositionRewardModel", ["gradient_steps", "learning_starts"]),  # the old ones
        ("DeconvolutionRewardModel", ["subset_size"]),  # another class's
        ("ReturnRegressionRewardModel", ["window"]),
    ]:
        settings = dict.fromkeys(unknown, 1)
        # (a TypeError, as for a keyword the constructor does not take)
        match = re.escape(f"settings {unknown!r} are not {kind}'s: it takes")
        with pytest.raises(TypeError, match=match) as error:
            make_reward_model({"type": kind, **settings, "seed": 0}, OBS, ACT)
        message = str(error.value)
        allowed = message.split("it takes")[1]
        for name in ("hidden_sizes", "updates_per_step", "warmup_updates", "seed", "capacity"):
            assert repr(name) in allowed
        for name in unknown:
            assert repr(name) not in allowed


# ---------------------------------------------------------------------- crafted files
@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """The members of a saved model file (learned ``p``, two sub-envs, a wrapped ring)."""
    model = build("learned", capacity=32)
    feed(model, 50, seed=0)
    path = model.save(tmp_path_factory.mktemp("saved") / "model.zip")
    with zipfile.ZipFile(path) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def write(path, members):
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in members.items():
            if data is not None:
                archive.writestr(name, data)
    return path


def with_header(saved, change):
    header = json.loads(saved["reward_model.json"])
    change(header)
    return {**saved, "reward_model.json": json.dumps(header)}


def with_tensors(saved, change):
    import torch

    tensors = torch.load(io.BytesIO(saved["weights.pt"]), weights_only=True)
    change(tensors)
    data = io.BytesIO()
    torch.save(tensors, data)
    return {**saved, "weights.pt": data.getvalue()}


def with_arrays(saved, change):
    with np.load(io.BytesIO(saved["history.npz"])) as data:
        arrays = {name: data[name] for name in data.files}
    change(arrays)
    data = io.BytesIO()
    np.savez(data, **arrays)
    return {**saved, "history.npz": data.getvalue()}


def refused(tmp_path, members, match):
    from delayed_rl.deep import load_reward_model

    path = write(tmp_path / "crafted.zip", members)
    with pytest.raises(ValueError, match=match):
        load_reward_model(path)


def test_the_unchanged_members_load(tmp_path, saved):
    from delayed_rl.deep import load_reward_model

    model = load_reward_model(write(tmp_path / "same.zip", saved))
    assert model.history.steps_added == 50 and model.history.oldest == 18


def test_what_is_not_a_zip_is_refused(tmp_path, saved):
    from delayed_rl.deep import load_reward_model

    whole = write(tmp_path / "whole.zip", saved).read_bytes()
    for name, data in [("garbage", b"not a zip at all"), ("truncated", whole[: len(whole) // 2])]:
        path = tmp_path / name
        path.write_bytes(data)
        with pytest.raises(ValueError, match="is not a reward model file"):
            load_reward_model(path)
    with pytest.raises(ValueError, match="is not a reward model file"):
        load_reward_model(tmp_path / "missing.zip")
    with pytest.raises(ValueError, match="is not a reward model file"):
        load_reward_model(tmp_path)  # a folder


@pytest.mark.parametrize("member", ["reward_model.json", "weights.pt"])
def test_a_missing_member_is_refused(tmp_path, saved, member):
    refused(tmp_path, {**saved, member: None}, "reward_model.json or weights.pt missing")


def test_a_member_over_the_size_limit_is_refused(tmp_path, saved, monkeypatch):
    import delayed_rl.deep.files as files
    from delayed_rl._validation import Limit

    limit = Limit(len(saved["weights.pt"]) - 1, "MAX_MEMBER_BYTES", files.MAX_MEMBER_BYTES.home)
    monkeypatch.setattr(files, "MAX_MEMBER_BYTES", limit)
    refused(tmp_path, saved, r"weights.pt is .* bytes, over MAX_MEMBER_BYTES = [\d,]+ \(delayed_rl")


@pytest.mark.parametrize(
    ("header", "match"),
    [
        (b"\xff\xfe not utf-8", "reward_model.json is not JSON"),
        (b"{not json", "reward_model.json is not JSON"),
        (b"[1, 2]", "does not declare format"),
        (b'"delayed-rl reward model 1"', "does not declare format"),
    ],
)
def test_a_header_that_is_not_a_json_object_is_refused(tmp_path, saved, header, match):
    refused(tmp_path, {**saved, "reward_model.json": header}, match)


def _set(*keys, value):
    def change(header):
        target = header
        for key in keys[:-1]:
            target = target[key]
        target[keys[-1]] = value

    return change


def _drop(*keys):
    def change(header):
        target = header
        for key in keys[:-1]:
            target = target[key]
        del target[keys[-1]]

    return change


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (
            _set("format", value="delayed-rl reward model 2"),
            r"does not declare format 'delayed-rl reward model 3', got 'delayed-rl reward model 2'",
        ),
        (_set("format", value="delayed-rl reward model 4"), "does not declare format"),
        (_drop("format"), "does not declare format"),
        (_set("class", value="RewardModel"), "unknown reward model class 'RewardModel'"),
        (_set("class", value="os.system"), "unknown reward model class"),
        (_set("class", value=["DeconvolutionRewardModel"]), "unknown reward model class"),
        (_drop("class"), "unknown reward model class None"),
        (_set("observation_space", value={"type": "Dict"}), "observation_space must describe"),
        (_set("observation_space", "low", value="x"), "observation_space must describe"),
        (_set("observation_space", "low", value=[0.0]), "observation_space must describe"),
        (_set("observation_space", "dtype", value="object"), "observation_space must describe"),
        (_set("observation_space", "dtype", value="nope"), "observation_space must describe"),
        (_set("observation_space", value={"type": "Box", "dtype": "float32"}), "must describe"),
        (_set("observation_space", value="Box"), "observation_space must describe"),
        (_drop("action_space"), "action_space must describe"),
        (_set("action_space", "n", value=0), "action_space"),
        (_set("settings", value=[1]), "settings must be a JSON object"),
        (_set("settings", "hidden_sizes", value=[0]), r"bad settings: hidden_sizes\[0\]"),
        (_set("settings", "on_episode_end", value="x"), "bad settings: on_episode_end"),
        (_set("settings", "learning_rate", value=float("nan")), "bad settings: learning_rate"),
        (_set("settings", "extra", value=1), "bad settings: .*extra"),
        (_drop("settings", "learning_rate"), "learning_rate"),
        (_drop("settings", "seed"), "seed"),
        (_set("settings", "hidden_sizes", value=[16]), "weights.pt does not fit the model"),
        (_set("settings", "delay", value={"type": "Constant", "k": 1}), "weights.pt does not fit"),
        (_drop("counters"), "bad counters"),
        (_drop("counters", "steps_added"), "bad counters"),
        (_drop("counters", "updates_taken"), "bad counters"),
        (_set("counters", "updates_taken", value="x"), "bad counters"),
        (_set("counters", "updates_taken", value=-1), "negative counters"),
        (_set("counters", "steps_added", value=-1), "negative counters"),
        (_set("counters", "n_envs", value=3), "history array obs must be"),
        (_set("counters", "n_envs", value=0), "history.npz must be there exactly when n_envs > 0"),
        (_set("rng", value={"bit_generator": "MT19937"}), "generator state"),
        (_drop("rng"), "generator state"),
    ],
)
def test_a_bad_header_is_refused(tmp_path, saved, change, match):
    refused(tmp_path, with_header(saved, change), match)


def _scale_first(factor):
    def change(tensors):
        name = next(iter(tensors["network"]))
        tensors["network"][name] = tensors["network"][name] * factor

    return change


def _first_weight_shape(tensors):
    name = next(iter(tensors["network"]))
    tensors["network"][name] = tensors["network"][name][:, :-1]


def _optimizer_state(key, change):
    def edit(tensors):
        state = tensors["optimizer"]["state"]
        state[0][key] = change(state[0][key])

    return edit


def _optimizer_group(key, value):
    def edit(tensors):
        tensors["optimizer"]["param_groups"][0][key] = value

    return edit


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (_scale_first(float("nan")), "tensor .* is not a finite tensor"),
        (_scale_first(float("inf")), "tensor .* is not a finite tensor"),
        (_first_weight_shape, "weights.pt does not fit the model"),
        (lambda t: t["network"].pop(next(iter(t["network"]))), "weights.pt does not fit"),
        (
            lambda t: t["network"].update(extra=t["extra"]["delay_logits"]),
            "weights.pt does not fit",
        ),
        (lambda t: t.pop("extra"), "weights.pt does not fit"),
        (lambda t: t.pop("optimizer"), "weights.pt does not fit"),
        (lambda t: t["extra"].clear(), "the learned delay's tensors do not match"),
        (lambda t: t["extra"].update(delay_logits=t["extra"]["delay_logits"][:-1]), "do not match"),
        (lambda t: t["extra"].update(delay_logits=t["extra"]["delay_logits"] / 0), "not a finite"),
        (lambda t: t["extra"].update(delay_logits=[0.0] * 5), "not a finite tensor"),
        (_optimizer_state("exp_avg", lambda v: v[:1]), "weights.pt does not fit the model"),
        (_optimizer_state("exp_avg_sq", lambda v: v * float("nan")), "weights.pt does not fit"),
        (_optimizer_group("lr", float("nan")), "weights.pt does not fit the model"),
        (_optimizer_group("lr", 5.0), "weights.pt does not fit the model"),
        (lambda t: t["optimizer"]["param_groups"].pop(), "weights.pt does not fit the model"),
    ],
)
def test_bad_tensors_are_refused(tmp_path, saved, change, match):
    refused(tmp_path, with_tensors(saved, change), match)


@pytest.mark.filterwarnings("ignore:Detected pickle protocol:UserWarning")  # the pickle's own
def test_weights_that_are_not_tensors_are_refused(tmp_path, saved):
    import torch

    class Payload:
        def __reduce__(self):
            return (os.getcwd, ())

    for data in (b"not a torch file", pickle.dumps({"network": Payload()})):
        refused(tmp_path, {**saved, "weights.pt": data}, "weights.pt does not fit the model")
    buffer = io.BytesIO()
    torch.save([1, 2, 3], buffer)
    refused(tmp_path, {**saved, "weights.pt": buffer.getvalue()}, "weights.pt does not fit")


def _array(name, change):
    def edit(arrays):
        arrays[name] = change(arrays[name])

    return edit


def _held(value):
    """Set one held step's entry (step 49, row 49 % 32) of sub-env 0."""

    def change(array):
        array = array.copy()
        array[49 % 32, 0] = value
        return array

    return change


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (_array("obs", lambda a: a[:, :1]), "history array obs must be float32 of shape"),
        (_array("obs", lambda a: a.astype(np.float64)), "history array obs must be float32"),
        (_array("action", lambda a: a.astype(np.int32)), "history array action must be int64"),
        (_array("reward", lambda a: a[:-1]), "history array reward must be float64"),
        (
            _array("episode_end", lambda a: a.astype(np.int8)),
            "history array episode_end must be bool",
        ),
        (
            _array("episode_cut", lambda a: a.astype(np.int8)),
            "history array episode_cut must be bool",
        ),
        (lambda a: a.pop("episode_cut"), r"history.npz misses arrays \['episode_cut'\]"),
        (_array("undelayed", lambda a: a.ravel()), "history array undelayed must be"),
        (lambda a: a.pop("reward"), "history.npz misses arrays"),
        (lambda a: a.update(extra=np.zeros(3)), r"history.npz holds unknown arrays \['extra'\]"),
        (lambda a: a.update({"obs.0": a["obs"]}), r"unknown arrays \['obs.0'\]"),
        (_array("obs", _held(np.nan)), "observation_space values must be finite"),
        (_array("action", _held(3)), "action_space values must be in 0..2"),
        (_array("action", _held(-1)), "action_space values must be in 0..2"),
        (_array("reward", _held(np.inf)), "history rewards must be finite"),
    ],
)
def test_bad_history_arrays_are_refused(tmp_path, saved, change, match):
    refused(tmp_path, with_arrays(saved, change), match)


@pytest.fixture(scope="module")
def saved_dict(tmp_path_factory):
    """The members of a saved model of ``Dict`` observations and ``MultiDiscrete`` actions."""
    model = build("learned", capacity=16, observation_space=DICT_OBS, action_space=MULTI_ACT)
    feed_spaces(model, 30, seed=0)  # steps 14..29 held: every row
    path = model.save(tmp_path_factory.mktemp("saved_dict") / "model.zip")
    with zipfile.ZipFile(path) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def _held_entry(value, row=29 % 16):
    """Set the first entry of one held step of sub-env 0."""

    def change(array):
        array = array.copy()
        array[(row, 0, *([0] * (array.ndim - 2)))] = value
        return array

    return change


NESTED = '{"type": "Dict", "keys": ["x"], "spaces": [{"type": "Discrete", "n": 2, "start": 0}]}'


def test_the_unchanged_dict_members_load(tmp_path, saved_dict):
    from delayed_rl.deep import load_reward_model

    model = load_reward_model(write(tmp_path / "same.zip", saved_dict))
    assert list(model.history.obs) == ["position", "room", "bits"]
    assert model.history.steps_added == 30 and model.history.oldest == 14


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda a: a.pop("obs.1"), r"history.npz misses arrays \['obs.1'\]"),
        (lambda a: a.update({"obs.3": a["obs.0"]}), r"unknown arrays \['obs.3'\]"),
        (lambda a: a.update(obs=a.pop("obs.0")), r"unknown arrays \['obs'\]"),
        (_array("obs.0", lambda a: a.astype(np.float64)), "history array obs.0 must be float32"),
        (_array("obs.2", lambda a: a[..., :2]), "history array obs.2 must be int8 of shape"),
        (
            _array("obs.0", _held_entry(np.nan)),
            r"observation_space\['position'\] values must be fin",
        ),
        (_array("obs.1", _held_entry(3)), r"observation_space\['room'\] values must be in -1..2"),
        (_array("obs.1", _held_entry(-2)), r"observation_space\['room'\] values must be in"),
        (_array("obs.2", _held_entry(2)), r"observation_space\['bits'\] values must be in 0..1"),
        (_array("obs.2", _held_entry(-1)), r"observation_space\['bits'\] values must be in 0..1"),
        (_array("action", _held_entry(4)), "action_space values must be in"),
        (_array("action", _held_entry(0)), "action_space values must be in"),  # starts at 1
    ],
)
def test_bad_dict_history_arrays_are_refused(tmp_path, saved_dict, change, match):
    refused(tmp_path, with_arrays(saved_dict, change), match)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (_set("observation_space", "keys", value=["position", "room"]), "must describe"),
        (_set("observation_space", "keys", value=["a", "a", "b"]), "distinct strings"),
        (_set("observation_space", "keys", value=[1, 2, 3]), "distinct strings"),
        (_set("observation_space", "spaces", 1, "type", value="Tuple"), "unknown space type"),
        (_set("observation_space", "spaces", 0, value=json.loads(NESTED)), "a nested Dict"),
        (_set("observation_space", "spaces", value=[]), "must describe"),
        (_set("observation_space", value={"type": "Dict", "keys": [], "spaces": []}), "one key"),
        (_set("action_space", "start", value=[1, 0]), "action_space must describe"),
        (_set("action_space", "nvec", value=[[3, 0], [2, 4]]), "action_space must describe"),
    ],
)
def test_a_bad_dict_header_is_refused(tmp_path, saved_dict, change, match):
    refused(tmp_path, with_header(saved_dict, change), match)


def test_unreadable_or_pickled_history_arrays_are_refused(tmp_path, saved):
    refused(tmp_path, {**saved, "history.npz": b"not an npz"}, "history.npz is not readable")
    objects = io.BytesIO()
    np.savez(objects, obs=np.array([{"a": 1}], dtype=object))
    refused(tmp_path, {**saved, "history.npz": objects.getvalue()}, "history.npz is not readable")
    refused(tmp_path, {**saved, "history.npz": None}, "history.npz must be there exactly when")


def test_a_step_the_ring_no_longer_holds_is_not_checked(tmp_path, saved):
    from delayed_rl.deep import load_reward_model

    # steps 18..49 are held in a ring of 32 over 50 steps: every row is held, so an empty ring
    # (a model with fewer steps than its capacity) shows the unheld rows instead
    model = build("learned", capacity=32)
    feed(model, 10, seed=0)
    path = model.save(tmp_path / "short.zip")
    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    members = with_arrays(
        members, _array("action", lambda a: np.where(np.arange(32)[:, None, None] >= 10, 7, a))
    )
    loaded = load_reward_model(write(tmp_path / "unheld.zip", members))
    assert loaded.history.steps_added == 10
    assert np.all(loaded.history.action[10:] == 0)  # the unheld rows are not read


# ---------------------------------------------------------------------- imports
def run_python(code):
    result = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": os.getcwd()},
    )
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.strip().splitlines()[-1])


@pytest.mark.cold_cache
def test_importing_the_package_imports_no_torch():
    found = run_python(
        """
        import json, sys
        import delayed_rl.deep as deep
        before = sorted({m.split(".")[0] for m in sys.modules} & {"torch", "stable_baselines3"})
        names = dir(deep)
        try:
            deep.Nothing
        except AttributeError as error:
            missing = str(error)
        deep.load_reward_model
        after = sorted({m.split(".")[0] for m in sys.modules} & {"torch", "stable_baselines3"})
        public = sorted(deep.__all__)
        print(json.dumps({"before": before, "names": names, "public": public, "missing": missing,
                          "after": after}))
        """
    )
    assert found["before"] == []
    assert found["names"] == found["public"]  # dir() lists the public names, lazily
    assert {"DeconvolutionRewardModel", "HindsightSAC", "load_reward_model"} <= set(found["names"])
    assert "has no attribute 'Nothing'" in found["missing"]
    assert "torch" in found["after"]


@pytest.mark.cold_cache
@pytest.mark.parametrize(
    ("blocked", "name"),
    [
        ("torch", "DeconvolutionRewardModel"),
        ("torch", "load_reward_model"),
        ("stable_baselines3", "RelabelingReplayBuffer"),  # torch there, stable-baselines3 not
        ("stable_baselines3", "RewardModelCallback"),
    ],
)
def test_without_torch_a_name_asks_for_the_sb3_extra(blocked, name):
    found = run_python(
        f"""
        import json, sys

        class Block:
            def find_spec(self, fullname, path=None, target=None):
                if fullname.split(".")[0] == {blocked!r}:
                    raise ModuleNotFoundError(f"No module named {{fullname!r}}", name=fullname)
                return None

        sys.meta_path.insert(0, Block())
        import delayed_rl.deep as deep
        try:
            getattr(deep, {name!r})
        except ImportError as error:
            print(json.dumps({{"kind": type(error).__name__, "message": str(error)}}))
        else:
            print(json.dumps({{"kind": None}}))
        """
    )
    assert found["kind"] == "ImportError"
    assert "sb3" in found["message"] and 'pip install "delayed-rl[sb3]"' in found["message"]
    assert blocked in found["message"] and name in found["message"]
