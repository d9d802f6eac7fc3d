"""Delay distributions: interface, validation and goodness of fit of the sampled delays.

Poisson delays by table look-up (the alias table and the Poisson table) are checked the same
way; the streams the wrappers and the compiled run draw from them, in
``tests/wrappers/test_delay_draws.py`` and ``tests/compiled/test_randomness.py``.

Statistical tests use fixed seeds and a significance level of ``support.ALPHA`` (1e-3): a
correct sampler fails a given check with probability 1e-3, and since the seeds are fixed the
outcome is deterministic. Chi-square bins are merged until every expected count is at least 5
(the usual validity condition); means are checked to within ``support.N_SE`` (4) standard
errors.
"""

from __future__ import annotations

import numpy as np
import pytest
from support import ALPHA, POISSON_MEANS, assert_mean_close, binned_chisquare

from delayed_rl.delays import (
    AliasTable,
    Constant,
    Delay,
    Empirical,
    Geometric,
    Poisson,
    Uniform,
    as_delay,
)

N_DRAWS = 20_000


class SciPyReference:
    """``scipy.stats.<name>(*args, **kwargs)``, frozen when called (by the test).

    Not at collection: scipy.stats takes half a second to import.
    """

    def __init__(self, name: str, *args, **kwargs):
        self.name, self.args, self.kwargs = name, args, kwargs

    def __call__(self):
        from scipy import stats

        return getattr(stats, self.name)(*self.args, **self.kwargs)


# (distribution, its scipy frozen distribution on {0, 1, ...} or None)
LAMS = POISSON_MEANS
CASES = [(Poisson(lam), SciPyReference("poisson", lam)) for lam in LAMS] + [
    (Geometric(0.3), SciPyReference("geom", 0.3, loc=-1)),
    (Geometric(0.05), SciPyReference("geom", 0.05, loc=-1)),
    (Uniform(2, 9), SciPyReference("randint", 2, 10)),
    (Empirical([0.1, 0.0, 0.45, 0.25, 0.2]), None),
]


@pytest.mark.parametrize(("dist", "ref"), CASES, ids=[repr(c[0]) for c in CASES])
def test_sample_goodness_of_fit(dist: Delay, ref) -> None:
    draws = dist.sample(np.random.default_rng(20240601), N_DRAWS)
    assert draws.dtype == np.int64 and draws.shape == (N_DRAWS,)
    assert draws.min() >= 0
    if dist.support_max is not None:
        assert draws.max() <= dist.support_max
    if draws.max() > 0:
        assert binned_chisquare(draws, dist.pmf) > ALPHA
    var = (
        ref().var()
        if ref is not None
        else float(dist.pmf(np.arange(5)) @ (np.arange(5) - dist.mean) ** 2)
    )
    assert_mean_close(draws, dist.mean, var)


@pytest.mark.parametrize(("dist", "ref"), [c for c in CASES if c[1] is not None])
def test_pmf_and_mean_match_scipy(dist: Delay, ref) -> None:
    ref = ref()
    ks = np.arange(0, int(ref.ppf(1 - 1e-12)) + 2)
    np.testing.assert_allclose(dist.pmf(ks), ref.pmf(ks), rtol=1e-9, atol=1e-300)
    assert dist.pmf(np.array([-1, -5])).tolist() == [0.0, 0.0]
    assert isinstance(dist.pmf(1), float)
    assert dist.mean == pytest.approx(ref.mean(), rel=1e-12)
    assert float(dist.pmf(ks).sum()) == pytest.approx(1.0, abs=1e-9)


def test_chisquare_rejects_a_wrong_distribution() -> None:
    """The test machinery has power: Poisson(5.5) draws are rejected as Poisson(5)."""
    draws = Poisson(5.5).sample(np.random.default_rng(1), N_DRAWS)
    assert binned_chisquare(draws, Poisson(5).pmf) < ALPHA


def test_empirical_pmf_mean_support() -> None:
    dist = Empirical([0.1, 0.0, 0.45, 0.25, 0.2, 0.0])
    assert dist.pmf(np.arange(-1, 8)).tolist() == [0.0, 0.1, 0.0, 0.45, 0.25, 0.2, 0.0, 0.0, 0.0]
    assert dist.mean == pytest.approx(0.9 + 0.75 + 0.8)
    assert dist.support_max == 4  # trailing zeros do not count
    draws = dist.sample(np.random.default_rng(3), 5000)
    assert set(np.unique(draws).tolist()) == {0, 2, 3, 4}


def test_constant_and_degenerate_supports() -> None:
    c = Constant(7)
    assert c.sample(np.random.default_rng(0), 10).tolist() == [7] * 10
    assert c.sample(np.random.default_rng(0)) == 7 and isinstance(
        c.sample(np.random.default_rng(0)), int
    )
    assert c.pmf(np.array([6, 7, 8])).tolist() == [0.0, 1.0, 0.0]
    assert (c.mean, c.support_max) == (7.0, 7)
    zero = Poisson(0)
    assert zero.sample(np.random.default_rng(0), 100).tolist() == [0] * 100
    assert zero.pmf(np.array([0, 1])).tolist() == [1.0, 0.0]
    assert zero.support_max is None and Poisson(3).support_max is None
    assert Geometric(1.0).support_max == 0 and Geometric(0.5).support_max is None
    assert Geometric(1.0).sample(np.random.default_rng(0), 50).tolist() == [0] * 50
    assert Uniform(3, 6).support_max == 6 and Uniform(3, 6).mean == 4.5
    assert Uniform(4, 4).sample(np.random.default_rng(0), 20).tolist() == [4] * 20


@pytest.mark.parametrize(
    "dist", [Poisson(2.5), Constant(2), Geometric(0.4), Uniform(1, 4), Empirical([0.5, 0.5])]
)
def test_sample_shapes_and_seed_reproducibility(dist: Delay) -> None:
    one = dist.sample(np.random.default_rng(5))
    assert isinstance(one, int)
    block = dist.sample(np.random.default_rng(5), (7, 3))
    assert block.shape == (7, 3) and block.dtype == np.int64
    a = dist.sample(np.random.default_rng(11), 200)
    b = dist.sample(np.random.default_rng(11), 200)
    np.testing.assert_array_equal(a, b)


def test_equality_and_hash() -> None:
    assert Poisson(5) == Poisson(5.0) and hash(Poisson(5)) == hash(Poisson(5.0))
    assert Poisson(5) != Poisson(6) and Poisson(1) != Constant(1)
    assert Empirical([0.5, 0.5]) == Empirical(np.array([0.5, 0.5]))


def test_as_delay() -> None:
    d = Geometric(0.2)
    assert as_delay(d) is d
    assert as_delay(3.5) == Poisson(3.5)
    assert as_delay(np.float64(2.0)) == Poisson(2.0)
    with pytest.raises(TypeError, match="delay"):
        as_delay("5")
    with pytest.raises(TypeError, match="delay"):
        as_delay(True)
    with pytest.raises(TypeError, match="my_name"):
        as_delay(None, name="my_name")


@pytest.mark.parametrize(
    ("factory", "exc", "name"),
    [
        (lambda: Poisson(-1), ValueError, "lam"),
        (lambda: Poisson(-1e-9), ValueError, "lam"),
        (lambda: Poisson(float("nan")), ValueError, "lam"),
        (lambda: Poisson(float("inf")), ValueError, "lam"),
        (lambda: Poisson(True), TypeError, "lam"),
        (lambda: Poisson("5"), TypeError, "lam"),
        (lambda: Poisson(None), TypeError, "lam"),
        (lambda: Constant(-1), ValueError, "k"),
        (lambda: Constant(1.5), TypeError, "k"),
        (lambda: Constant(2.0), TypeError, "k"),
        (lambda: Constant(True), TypeError, "k"),
        (lambda: Geometric(0), ValueError, r"\bp\b"),
        (lambda: Geometric(1.5), ValueError, r"\bp\b"),
        (lambda: Geometric(-0.1), ValueError, r"\bp\b"),
        (lambda: Geometric(float("nan")), ValueError, r"\bp\b"),
        (lambda: Geometric("0.5"), TypeError, r"\bp\b"),
        (lambda: Uniform(5, 2), ValueError, "high"),
        (lambda: Uniform(-1, 2), ValueError, "low"),
        (lambda: Uniform(0.5, 2), TypeError, "low"),
        (lambda: Uniform(0, 2.5), TypeError, "high"),
        (lambda: Empirical([0.5, 0.4]), ValueError, "sum to 1"),
        (lambda: Empirical([0.6, 0.6]), ValueError, "sum to 1"),
        (lambda: Empirical([-0.1, 1.1]), ValueError, "pmf"),
        (lambda: Empirical([float("nan"), 1.0]), ValueError, "pmf"),
        (lambda: Empirical([]), ValueError, "pmf"),
        (lambda: Empirical([[0.5, 0.5]]), ValueError, "pmf"),
        (lambda: Empirical([[0.5], [0.3, 0.2]]), ValueError, "pmf"),
        (lambda: Empirical(["a", "b"]), TypeError, "pmf"),
        (lambda: Empirical([0.5, None]), TypeError, "pmf"),
        (lambda: Empirical([True, False]), TypeError, "pmf"),
    ],
)
def test_invalid_arguments_raise_naming_them(factory, exc, name) -> None:
    with pytest.raises(exc, match=name):
        factory()


@pytest.mark.parametrize(
    ("cls", "name", "wrong_type", "bad_value"),
    [
        (Poisson, "lam", "5", -1.0),
        (Constant, "k", 2.0, -1),
        (Geometric, "p", "0.5", 0.0),
        (lambda low: Uniform(low, 3), "low", 1.5, -1),
        (lambda high: Uniform(2, high), "high", 2.5, 1),
        (Empirical, "pmf", "0.5", [0.5, 0.4]),
        (AliasTable, "pmf", ["x"], [0.0, 0.0]),
    ],
)
def test_each_argument_refuses_a_wrong_type_and_a_bad_value(
    cls, name, wrong_type, bad_value
) -> None:
    """The library's policy: TypeError for the wrong type, ValueError for a bad value."""
    with pytest.raises(TypeError, match=rf"\b{name}\b"):
        cls(wrong_type)
    with pytest.raises(ValueError, match=rf"\b{name}\b"):
        cls(bad_value)


def test_valid_argument_types_are_normalised() -> None:
    assert Poisson(np.float32(2.5)).lam == 2.5 and type(Poisson(3).lam) is float
    assert Constant(np.int64(4)).k == 4 and type(Constant(np.int64(4)).k) is int
    assert Uniform(np.int32(1), 3).low == 1 and Geometric(1).p == 1.0
    assert Empirical(np.array([1, 0])).probs.tolist() == [1.0, 0.0]


# --- delays that fit int64, and JSON descriptions ---------------------------------------------

INT64_MAX = 2**63 - 1


@pytest.mark.parametrize(
    ("factory", "name"),
    [
        (lambda: Constant(2**63), "k"),
        (lambda: Constant(2**70), "k"),
        (lambda: Uniform(0, 2**63), "high"),
        (lambda: Uniform(2**63, 2**64), "low"),
        (lambda: Poisson(1e19), "lam"),
        (lambda: Poisson(1e300), "lam"),
        (lambda: Geometric(1e-19), r"\bp\b"),
        (lambda: Geometric(5e-324), r"\bp\b"),
    ],
)
def test_delays_beyond_int64_are_refused_at_construction(factory, name) -> None:
    with pytest.raises(ValueError, match=name):
        factory()


@pytest.mark.parametrize(
    "dist",
    [Constant(INT64_MAX), Uniform(INT64_MAX - 3, INT64_MAX), Poisson(9e18), Geometric(1e-17)],
    ids=repr,
)
def test_delays_at_the_int64_limit_stay_non_negative(dist) -> None:
    draws = dist.sample(np.random.default_rng(0), 64)
    assert draws.dtype == np.int64 and draws.min() >= 0


DESCRIBED = [
    Poisson(3.5),
    Poisson(0),
    Constant(2),
    Geometric(0.25),
    Uniform(1, 7),
    Empirical([0.1, 0.0, 0.45, 0.25, 0.2]),
    Empirical([1 / 3, 1 / 3, 1 / 3]),
]


@pytest.mark.parametrize("dist", DESCRIBED, ids=repr)
def test_to_dict_is_json_and_as_delay_reads_it_back(dist) -> None:
    import json

    description = dist.to_dict()
    assert description["type"] == type(dist).__name__
    text = json.dumps(description)
    rebuilt = as_delay(json.loads(text))
    assert type(rebuilt) is type(dist) and rebuilt == dist
    rng_a, rng_b = np.random.default_rng(4), np.random.default_rng(4)
    np.testing.assert_array_equal(dist.sample(rng_a, 100), rebuilt.sample(rng_b, 100))


def test_constant_to_dict_is_the_plain_dict() -> None:
    assert Constant(2).to_dict() == {"type": "Constant", "k": 2}
    assert as_delay({"type": "Constant", "k": 2}) == Constant(2)


@pytest.mark.parametrize(
    ("description", "exc", "match"),
    [
        ({"k": 2}, ValueError, "type"),
        ({"type": "Lognormal", "mu": 1}, ValueError, "Lognormal"),
        ({"type": 3}, TypeError, "type"),
        ({"type": "Constant"}, ValueError, "k"),
        ({"type": "Constant", "k": 2, "extra": 1}, ValueError, "extra"),
        ({"type": "Constant", "k": -2}, ValueError, r"\bk\b"),
        ({"type": "Constant", "k": "2"}, TypeError, r"\bk\b"),
        ({"type": "Poisson", "lam": -1}, ValueError, "lam"),
    ],
)
def test_as_delay_refuses_bad_descriptions(description, exc, match) -> None:
    with pytest.raises(exc, match=match):
        as_delay(description)


def test_as_delay_names_the_argument_in_a_numbers_error():
    assert as_delay(2.5, "action_delay") == Poisson(2.5)
    assert as_delay({"type": "Constant", "k": 2}, "x") == Constant(2)
    with pytest.raises(ValueError, match=r"action_delay must be .*Poisson mean"):
        as_delay(-1, "action_delay")
    with pytest.raises(TypeError, match="observation_delay"):
        as_delay("5", "observation_delay")


# Poisson delays by table look-up: the alias table, the Poisson table, and the streams using it.


@pytest.mark.parametrize(
    "pmf", [[1.0], [0.5, 0.5], [0.7, 0.0, 0.2, 0.1], [3.0, 1.0, 0.0, 4.0, 2.0]]
)
def test_alias_table_draws_its_distribution(pmf):
    """Draws fit the normalised pmf; a zero-probability value is never drawn."""
    pmf = np.asarray(pmf) / np.sum(pmf)
    draws = AliasTable(pmf).sample(np.random.default_rng(11), 50_000)
    assert draws.dtype == np.int64 and draws.min() >= 0 and draws.max() < pmf.size
    assert not np.isin(draws, np.flatnonzero(pmf == 0)).any()
    if pmf.size > 1:
        assert binned_chisquare(draws, lambda k: pmf[k]) > ALPHA


def test_alias_table_has_power():
    """The check above rejects a table built from a different distribution."""
    draws = AliasTable([0.55, 0.45]).sample(np.random.default_rng(12), 50_000)
    assert binned_chisquare(draws, lambda k: np.array([0.5, 0.5])[k]) < ALPHA


@pytest.mark.parametrize("pmf", [[], [0.5, -0.1], [np.nan, 1.0], [0.0, 0.0], [[0.5, 0.5]]])
def test_alias_table_rejects_bad_pmfs(pmf):
    with pytest.raises(ValueError, match="pmf"):
        AliasTable(pmf)


@pytest.mark.parametrize("lam", [0.0, 0.3, 4.0, 13.0, 250.0])
def test_poisson_table_fits_poisson(lam):
    table = Poisson(lam).table
    assert Poisson(lam).pmf(table.keep.size) < Poisson.TAIL  # the tail left out is negligible
    draws = Poisson(lam).sample(np.random.default_rng(int(lam * 10)), 50_000)
    if lam == 0:
        assert not draws.any()
    else:
        assert binned_chisquare(draws, Poisson(lam).pmf) > ALPHA


def test_poisson_draws_from_numpy_beyond_the_largest_table():
    huge = Poisson(4.0 * Poisson.MAX_TABLE)
    assert huge.table is None
    draws = huge.sample(np.random.default_rng(1), 2000)
    assert abs(draws.mean() - huge.lam) < 4 * np.sqrt(huge.lam / draws.size)


def test_poisson_scalar_and_shaped_draws():
    rng = np.random.default_rng(2)
    assert isinstance(Poisson(3.0).sample(rng), int)
    assert Poisson(3.0).sample(rng, (4, 5)).shape == (4, 5)
