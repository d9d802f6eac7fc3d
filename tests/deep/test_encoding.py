"""How a reward model stores, describes and reads the values of a space, and what it refuses.

:class:`~delayed_rl.deep.encoding.SpaceEncoding` is fuzzed on random ``Dict`` spaces (random
string keys, in drawn order, mapping to random ``Box``, ``Discrete``, ``MultiDiscrete`` and
``MultiBinary`` spaces, images among the boxes): a batch of sampled values is stored exactly, in
the stored dtype, and comes back out of ``put``/``take``, ``flat`` and ``arrays``/``from_arrays``
unchanged; the JSON description (``to_dict``, through ``json``) makes the same space and
encoding again; and the reward network gives one finite reward a value. What the network reads
of each space (:class:`~delayed_rl.deep.network.SpaceFeatures`: one-hots from ``start``, bits,
an image divided by 255, flat or through SB3's ``NatureCNN`` with channels-last images
transposed) is checked against numpy and the CNN itself. Spaces SB3's policies do not take
(``Tuple``, ``Text``, ``Graph``, ``Sequence``, a nested ``Dict``, a ``Dict`` with a key that is not
a string) are refused with a ``TypeError`` naming the argument and the space, and values outside
a space with a ``ValueError``, before anything is stored.
"""

from __future__ import annotations

import json
import re
from collections import OrderedDict

import numpy as np
import pytest
from gymnasium import spaces
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support import examples, torch_on_one_thread  # noqa: F401  (the fixture)

pytestmark = [pytest.mark.sb3, pytest.mark.usefixtures("torch_on_one_thread")]

FUZZ = settings(
    max_examples=examples(100),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
SUPPORTED = "Box, Discrete, MultiDiscrete, MultiBinary, or a Dict of those"


def stack(space, values):
    """Sampled values (one a row) as a batch: a dict of arrays for a ``Dict``."""
    if isinstance(space, spaces.Dict):
        return {key: np.stack([np.asarray(v[key]) for v in values]) for key in space.spaces}
    return np.stack([np.asarray(v) for v in values])


def leaves(encoding, store):
    """``(encoding, array)`` for each leaf of a store, in key order."""
    if encoding.parts is None:
        return [(encoding, store)]
    return [(encoding.parts[key], store[key]) for key in encoding.parts]


def assert_same_store(encoding, a, b):
    for (part, x), (_, y) in zip(leaves(encoding, a), leaves(encoding, b), strict=True):
        assert x.dtype == y.dtype == part.dtype
        np.testing.assert_array_equal(x, y)


# ---------------------------------------------------------------------- fuzzing
def _box(shape, low, width, dtype):
    high = low + width
    if np.dtype(dtype).kind == "i":
        return spaces.Box(int(low), int(high), shape, dtype)
    return spaces.Box(float(low), float(high), shape, dtype)


shapes = st.lists(st.integers(1, 3), min_size=0, max_size=3).map(tuple)
boxes = st.one_of(
    st.builds(
        _box,
        shapes,
        st.integers(-10, 0),
        st.integers(0, 10),
        st.sampled_from([np.float32, np.float64, np.int64]),
    ),
    st.builds(lambda shape: spaces.Box(-np.inf, np.inf, shape, np.float32), shapes),
    # images: flat below 36 pixels a side, through the CNN from 36 on; channels last or first
    st.builds(
        lambda side, channels, last: spaces.Box(
            0, 255, (side, side, channels) if last else (channels, side, side), np.uint8
        ),
        st.sampled_from([2, 5, 36]),
        st.integers(1, 3),
        st.booleans(),
    ),
    st.builds(lambda n: spaces.Box(0, 255, (n,), np.uint8), st.integers(1, 4)),  # not an image
)
discretes = st.builds(
    lambda n, start: spaces.Discrete(n, start=start), st.integers(1, 6), st.integers(-5, 5)
)
multi_discretes = st.builds(
    lambda nvec, start: spaces.MultiDiscrete(nvec, start=np.resize(start, nvec.shape)),
    st.one_of(
        st.lists(st.integers(1, 4), min_size=1, max_size=3).map(np.array),
        st.lists(st.integers(1, 3), min_size=4, max_size=4).map(lambda v: np.reshape(v, (2, 2))),
    ),
    st.lists(st.integers(-3, 3), min_size=1, max_size=4),
)
multi_binaries = st.one_of(
    st.integers(1, 4).map(spaces.MultiBinary),
    st.lists(st.integers(1, 3), min_size=2, max_size=2).map(spaces.MultiBinary),
)
leaf_spaces = st.one_of(boxes, discretes, multi_discretes, multi_binaries)
dict_spaces = st.lists(
    st.tuples(st.text(min_size=1, max_size=6), leaf_spaces),
    min_size=1,
    max_size=4,
    unique_by=lambda item: item[0],
).map(lambda items: spaces.Dict(OrderedDict(items)))


@FUZZ
@given(
    dict_spaces,
    st.one_of(leaf_spaces, dict_spaces),
    st.integers(1, 5),
    st.integers(0, 2**32 - 1),
)
def test_dict_spaces_store_describe_and_read_their_values(
    observation_space, action_space, count, seed
):
    import torch

    from delayed_rl.deep.encoding import SpaceEncoding
    from delayed_rl.deep.network import IMAGE_FEATURES, RewardNetwork, as_tensors

    encoding = SpaceEncoding("observation_space", observation_space)
    assert list(encoding.parts) == list(observation_space.spaces)  # the drawn order, not sorted
    observation_space.seed(seed)
    values = stack(observation_space, [observation_space.sample() for _ in range(count)])

    # batch: every key, count values of its stored shape and dtype, the values themselves
    batch = encoding.batch(values, count)
    assert list(batch) == list(observation_space.spaces)
    for key, part in encoding.parts.items():
        assert batch[key].shape == (count, *part.shape) and batch[key].dtype == part.dtype
        # a stored value is the sampled one (floats to float32; an image keeps uint8)
        np.testing.assert_array_equal(
            batch[key], np.asarray(values[key]).reshape(count, *part.shape).astype(part.dtype)
        )
        assert part.image == (
            isinstance(part.space, spaces.Box) and part.dtype == np.uint8
        )  # only an image keeps uint8

    # put and take: one row of a ring of 4 steps of `count` sub-envs, the others left zero
    store = encoding.empty(4, count)
    for part, array in leaves(encoding, store):
        assert array.shape == (4, count, *part.shape) and not array.any()
    encoding.put(store, 2, batch)
    assert_same_store(encoding, encoding.take(store, 2), batch)
    for _, array in leaves(encoding, store):
        assert not array[[0, 1, 3]].any()

    # flat: fancy-indexed rows and sub-envs, merged into one batch in order
    rows, envs = np.full((2, count), 2), np.tile(np.arange(count), (2, 1))
    flat = encoding.flat(encoding.take(store, (rows, envs)))
    assert_same_store(
        encoding, flat, {key: np.tile(v, (2,) + (1,) * (v.ndim - 1)) for key, v in batch.items()}
    )

    # arrays and from_arrays: the file's names, one array a key in key order
    arrays = encoding.arrays(store, "obs")
    assert list(arrays) == [f"obs.{i}" for i in range(len(encoding.parts))]
    for name, (_, array) in zip(arrays, leaves(encoding, store), strict=True):
        assert arrays[name] is array
    assert_same_store(encoding, encoding.from_arrays(arrays, "obs"), store)
    with pytest.raises(KeyError):
        encoding.from_arrays({name: a for name, a in arrays.items() if name != "obs.0"}, "obs")

    # to_dict and from_dict, through JSON: the same space, key order, dtypes and features
    described = json.loads(json.dumps(encoding.to_dict()))
    again = SpaceEncoding.from_dict("observation_space", described)
    assert again.space == observation_space
    assert list(again.parts) == list(encoding.parts)
    assert again.to_dict() == described
    assert again.n_features == encoding.n_features and again.value_bytes == encoding.value_bytes
    for key, part in encoding.parts.items():
        assert again.parts[key].dtype == part.dtype and again.parts[key].shape == part.shape
        assert again.parts[key].space.dtype == part.space.dtype
    assert_same_store(again, again.batch(values, count), batch)

    # the network: one finite reward a value, from the features of every key
    actions = SpaceEncoding("action_space", action_space)
    action_space.seed(seed + 1)
    action_batch = actions.batch(
        stack(action_space, [action_space.sample() for _ in range(count)]), count
    )
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        network = RewardNetwork(encoding, actions, (4,))
    features = network.observation_features(as_tensors(batch))
    # an image 36 pixels a side (the strategy's only size from 36 on) makes the CNN's features
    widths = [
        IMAGE_FEATURES if part.image and max(part.shape) >= 36 else part.n_features
        for part in encoding.parts.values()
    ]
    assert features.shape == (count, sum(widths))
    with torch.no_grad():
        rewards = network(as_tensors(batch), as_tensors(action_batch))
    assert rewards.shape == (count,) and rewards.dtype == torch.float32
    assert torch.isfinite(rewards).all()


# ---------------------------------------------------------------------- what is read
def test_features_are_one_hots_from_start_bits_and_scaled_pixels():
    import torch

    from delayed_rl.deep.encoding import SpaceEncoding
    from delayed_rl.deep.network import SpaceFeatures

    space = spaces.Dict(
        OrderedDict(
            [
                ("room", spaces.Discrete(3, start=-1)),
                ("dials", spaces.MultiDiscrete([2, 3], start=[1, -2])),
                ("bits", spaces.MultiBinary([2, 2])),
                ("image", spaces.Box(0, 255, (2, 2, 3), np.uint8)),  # under 36 px: flat
                ("position", spaces.Box(-1.0, 1.0, (2,), np.float32)),
            ]
        )
    )
    encoding = SpaceEncoding("observation_space", space)
    space.seed(3)
    samples = [space.sample() for _ in range(6)]
    batch = encoding.batch(stack(space, samples), 6)
    features = SpaceFeatures(encoding)(
        {key: torch.as_tensor(value) for key, value in batch.items()}
    )
    expected = []
    for sample in samples:
        row = [np.eye(3)[sample["room"] + 1]]
        row += [np.eye(2)[sample["dials"][0] - 1], np.eye(3)[sample["dials"][1] + 2]]
        row += [sample["bits"].ravel(), sample["image"].ravel() / 255.0, sample["position"]]
        expected.append(np.concatenate(row))
    assert features.shape == (6, 3 + 5 + 4 + 12 + 2)
    np.testing.assert_allclose(features.numpy(), np.array(expected), rtol=1e-6)


@pytest.mark.parametrize("shape", [(36, 40, 3), (3, 36, 40)])
def test_an_image_from_36_pixels_goes_through_natures_cnn(shape):
    import torch

    from delayed_rl.deep.encoding import SpaceEncoding
    from delayed_rl.deep.network import IMAGE_FEATURES, SpaceFeatures

    space = spaces.Box(0, 255, shape, np.uint8)
    encoding = SpaceEncoding("observation_space", space)
    assert encoding.image and encoding.dtype == np.uint8
    reader = SpaceFeatures(encoding)
    assert reader.cnn is not None and reader.n_out == IMAGE_FEATURES
    space.seed(0)
    images = np.stack([space.sample() for _ in range(3)])
    with torch.no_grad():
        features = reader(torch.as_tensor(images))
        first = torch.as_tensor(images).float() / 255.0
        if shape[-1] == 3:  # channels last: moved first, as SB3's VecTransposeImage does
            first = first.permute(0, 3, 1, 2)
        np.testing.assert_array_equal(features.numpy(), reader.cnn(first).numpy())
    assert features.shape == (3, IMAGE_FEATURES)
    # one pixel changed changes the features (the image is read, not dropped)
    images[0].flat[0] = 255 - images[0].flat[0]
    with torch.no_grad():
        assert not torch.equal(reader(torch.as_tensor(images))[0], features[0])


def test_a_small_image_is_read_flat_and_a_non_image_box_is_not_scaled():
    import torch

    from delayed_rl.deep.encoding import SpaceEncoding
    from delayed_rl.deep.network import SpaceFeatures

    image = SpaceEncoding("observation_space", spaces.Box(0, 255, (35, 36, 1), np.uint8))
    assert image.image and SpaceFeatures(image).cnn is None  # 35 < 36 pixels a side
    pixels = np.full((1, 35, 36, 1), 51, np.uint8)
    np.testing.assert_allclose(SpaceFeatures(image)(torch.as_tensor(pixels)).numpy(), 0.2)
    counts = SpaceEncoding("observation_space", spaces.Box(0, 255, (4,), np.uint8))
    assert not counts.image and counts.dtype == np.float32  # 1-d: not an image
    stored = counts.batch([[0, 1, 2, 255]], 1)
    np.testing.assert_array_equal(SpaceFeatures(counts)(torch.as_tensor(stored)), stored)


def test_the_history_reads_dict_values_at_rows_and_sub_envs():
    from delayed_rl.deep import ReturnRegressionRewardModel

    space = spaces.Dict({"a": spaces.Discrete(4), "b": spaces.Box(-1.0, 1.0, (2,), np.float32)})
    model = ReturnRegressionRewardModel(space, spaces.MultiDiscrete([3, 2]), capacity=5, seed=0)
    space.seed(0)
    added = []
    for step in range(8):  # the ring of 5 wraps
        obs = stack(space, [space.sample() for _ in range(2)])
        action = np.array([[step % 3, 0], [0, step % 2]])
        model.add(obs, action, [0.0, 0.0], [False, False])
        added.append((obs, action))
    steps, envs = np.array([3, 7, 5, 7]), np.array([1, 0, 1, 1])
    rows = model.history.rows(3, 8)[steps - 3]
    read = model.history.observations_at(rows, envs)
    actions = model.history.actions_at(rows, envs)
    for i, (step, env) in enumerate(zip(steps, envs, strict=True)):
        obs, action = added[step]
        assert read["a"][i, 0] == obs["a"][env]
        np.testing.assert_array_equal(read["b"][i], obs["b"][env])
        np.testing.assert_array_equal(actions[i], action[env])


# ---------------------------------------------------------------------- what is refused
TUPLE = spaces.Tuple([spaces.Discrete(2), spaces.Discrete(3)])
UNSUPPORTED = [  # a space, and what the message says of it
    (TUPLE, f"{TUPLE!r} (Tuple)"),
    (spaces.Text(5), f"{spaces.Text(5)!r} (Text)"),
    (spaces.Sequence(spaces.Discrete(2)), "(Sequence)"),
    (spaces.Graph(spaces.Box(0.0, 1.0, (2,)), None), "(Graph)"),
    (
        spaces.Dict({"inner": spaces.Dict({"x": spaces.Discrete(2)})}),
        "a nested Dict at key 'inner'",
    ),
    (spaces.Dict({"pair": TUPLE}), f"['pair'] must be a gymnasium {SUPPORTED} (the spaces SB3's"),
]


@pytest.mark.parametrize(("space", "said"), UNSUPPORTED)
@pytest.mark.parametrize("argument", ["observation_space", "action_space"])
def test_a_space_sb3_does_not_take_is_refused_by_name(space, said, argument):
    from delayed_rl.deep import ReturnRegressionRewardModel, make_reward_model

    given_spaces = {"observation_space": spaces.Discrete(2), "action_space": spaces.Discrete(2)}
    given_spaces[argument] = space
    for make in (
        lambda: ReturnRegressionRewardModel(**given_spaces, seed=0),
        lambda: make_reward_model({"type": "ReturnRegressionRewardModel"}, *given_spaces.values()),
    ):
        with pytest.raises(TypeError) as error:
            make()
        message = str(error.value)
        assert message.startswith(argument)
        assert said in message and SUPPORTED in message


def test_a_dict_with_a_key_that_is_not_a_string_is_refused():
    from delayed_rl.deep import ReturnRegressionRewardModel

    space = spaces.Dict(OrderedDict([("a", spaces.Discrete(2)), (1, spaces.Discrete(2))]))
    with pytest.raises(TypeError, match=r"observation_space must have string keys.* 1 \(int\)"):
        ReturnRegressionRewardModel(space, spaces.Discrete(2))


@pytest.mark.parametrize(
    ("space", "bad", "match"),
    [
        (spaces.MultiDiscrete([2, 3]), [[2, 0]], r"values must be in \[0, 0\]..\[1, 2\]"),
        (spaces.MultiDiscrete([2, 3]), [[0, 3]], "values must be in"),
        (
            spaces.MultiDiscrete([2, 3], start=[1, -1]),
            [[0, 0]],
            r"values must be in \[1, -1\]..\[2, 1\]",
        ),
        (spaces.MultiDiscrete([3, 3]), [[-1, 0]], r"values must be in 0..2, got"),
        (spaces.MultiDiscrete([3, 3]), [[0.5, 0]], "values must be integers"),
        (spaces.MultiBinary(3), [[0, 2, 1]], "values must be in 0..1"),
        (spaces.MultiBinary(3), [[0, -1, 1]], "values must be in 0..1"),
        (spaces.MultiBinary([2, 2]), [[[0, 1], [1, 0.5]]], "values must be integers"),
        # an image's bounds are told as one range, not a list a pixel
        (
            spaces.Box(0, 255, (40, 40, 3), np.uint8),
            np.full((1, 40, 40, 3), 256),
            r"values must be in 0..255, got",
        ),
    ],
)
@pytest.mark.parametrize("argument", ["observation_space", "action_space"])
def test_values_outside_the_space_are_refused_before_anything_is_stored(
    space, bad, match, argument
):
    from delayed_rl.deep import ReturnRegressionRewardModel

    other = spaces.Discrete(2)
    model = (
        ReturnRegressionRewardModel(space, other, seed=0)
        if argument == "observation_space"
        else ReturnRegressionRewardModel(other, space, seed=0)
    )
    space.seed(0)
    good = np.asarray(space.sample())[None]
    steps = {"observation_space": (bad, [0]), "action_space": ([0], bad)}[argument]
    with pytest.raises(ValueError, match=re.escape(argument) + " " + match):
        model.add(*steps, [1.0], [False])
    assert model.history is None
    with pytest.raises(ValueError, match=re.escape(argument) + " " + match):
        model.predict(*steps)
    model.add(
        *({"observation_space": (good, [0]), "action_space": ([0], good)}[argument]), [1.0], [False]
    )
    with pytest.raises(ValueError, match=match):
        model.add(*steps, [1.0], [False])
    assert model.history.steps_added == 1
    assert len(str(pytest.raises(ValueError, model.predict, *steps).value)) < 300


def test_dict_values_must_be_a_dict_with_the_spaces_keys():
    from delayed_rl.deep import ReturnRegressionRewardModel

    space = spaces.Dict({"a": spaces.Discrete(2), "b": spaces.MultiBinary(2)})
    model = ReturnRegressionRewardModel(space, spaces.Discrete(2), seed=0)
    good = {"a": [1], "b": [[0, 1]]}
    for bad, error, match in [
        ([1, 0, 1], TypeError, r"observation_space values must be a dict with keys \['a', 'b'\]"),
        ({"a": [1]}, ValueError, r"must have the keys \['a', 'b'\], got \['a'\]"),
        ({**good, "c": [0]}, ValueError, r"must have the keys \['a', 'b'\]"),
        ({**good, "b": [[0, 3]]}, ValueError, r"observation_space\['b'\] values must be in 0..1"),
    ]:
        with pytest.raises(error, match=match):
            model.add(bad, [0], [0.0], [False])
    assert model.history is None
    model.add(good, [0], [0.0], [False])
    np.testing.assert_array_equal(model.history.obs["b"][0, 0], [0, 1])
    assert model.history.obs["b"].dtype == np.int8
