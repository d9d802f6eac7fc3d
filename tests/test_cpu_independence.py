"""Seeded results have the same bits on every x86-64 CPU, whatever its SIMD level.

Three kinds of code round differently by CPU: numpy's SIMD loops (``np.exp``, ``np.log``,
``np.arctan2``, ``np.power``, complex products and absolute values, chosen at import among
AVX2 and AVX-512 versions), BLAS and LAPACK (``@``, ``np.dot``, ``np.linalg``, whose kernels
are chosen for the CPU) and the C library's ``exp``, ``log``, ``sin``, ``cos``, ``atan2`` and
``lgamma`` (which x86-64 glibc picks among FMA and plain variants). numba adds a fourth: it
compiles for the host CPU.

The proof runs on whatever machine runs the tests: short seeded runs (``tests/cpu_probe.py``:
the e-puck in every observation and action mode, every agent on both training paths, the
experiments' quick reproduction) are hashed in this process and in a subprocess where numpy
dispatches to none of the SIMD levels this CPU has (``NPY_DISABLE_CPU_FEATURES``), numba
compiles for a generic x86-64 (``NUMBA_CPU_NAME=generic``, with a fresh cache) and glibc
uses its plain variants (``GLIBC_TUNABLES``); the hashes must be equal. The other tests here
check :mod:`delayed_rl._portable_math` against the C library, and that the library's
bit-relevant modules call none of the CPU-dependent functions.
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from delayed_rl import _portable_math as portable_math

TESTS = Path(__file__).parent
PACKAGE = TESTS.parent / "delayed_rl"
#: glibc's x86-64 CPU features whose variants of the math functions round differently.
GLIBC_PLAIN = "glibc.cpu.hwcaps=-AVX2,-FMA,-FMA4,-AVX,-AVX512F,-AVX512DQ"


def numpy_dispatch_levels() -> list[str]:
    """The SIMD levels numpy dispatches to that this CPU has (what a plainer CPU would lack)."""
    try:
        from numpy._core import _multiarray_umath as umath
    except ImportError:  # numpy 1.x
        from numpy.core import _multiarray_umath as umath
    return [name for name in umath.__cpu_dispatch__ if umath.__cpu_features__.get(name)]


def plainer_cpu_environment(cache: Path) -> dict[str, str]:
    """The environment of a subprocess that computes as a plainer CPU would."""
    env = dict(os.environ)
    env.update(
        NPY_DISABLE_CPU_FEATURES=" ".join(numpy_dispatch_levels()),
        NUMBA_CPU_NAME="generic",
        NUMBA_CACHE_DIR=str(cache),
        GLIBC_TUNABLES=GLIBC_PLAIN,
    )
    return env


@pytest.mark.cold_cache
def test_seeded_runs_hash_the_same_on_a_plainer_cpu(tmp_path):
    sys.path.insert(0, str(TESTS))
    try:
        import cpu_probe
    finally:
        sys.path.remove(str(TESTS))
    here = cpu_probe.hashes()
    env = plainer_cpu_environment(tmp_path / "numba-cache")
    check = "import numpy as np; from numpy._core import _multiarray_umath as u; "
    check += "print(sorted(k for k, v in u.__cpu_features__.items() if v))"
    features = subprocess.run(
        [sys.executable, "-c", check], env=env, capture_output=True, text=True, check=True
    )
    for level in numpy_dispatch_levels():  # the subprocess really runs without them
        assert f"'{level}'" not in features.stdout
    probe = subprocess.run(
        [sys.executable, str(TESTS / "cpu_probe.py")],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert probe.returncode == 0, probe.stderr[-3000:]
    there = json.loads(probe.stdout)
    assert set(there) == set(here)
    differing = sorted(name for name in here if here[name] != there[name])
    assert not differing, f"these runs depend on the CPU: {differing}"


# ---------------------------------------------------------------------- the portable functions
def _ulps(ours: np.ndarray, reference: np.ndarray) -> np.ndarray:
    return np.abs(ours - reference) / np.spacing(np.abs(reference))


ARGUMENTS = np.concatenate(
    [
        np.random.default_rng(0).uniform(-10.0, 10.0, 4000),
        np.random.default_rng(1).uniform(-2000.0, 2000.0, 1000),
        np.random.default_rng(2).normal(0.0, 1e-3, 500),
        [0.0, -0.0, 1e-300, math.pi / 4, math.pi / 2, math.pi, 3 * math.pi / 2, 1e5],
    ]
)


@pytest.mark.parametrize(
    ("ours", "reference", "arguments"),
    [
        (portable_math.sin, math.sin, ARGUMENTS),
        (portable_math.cos, math.cos, ARGUMENTS),
        (portable_math.exp, math.exp, ARGUMENTS[np.abs(ARGUMENTS) < 700]),
        (portable_math.log, math.log, np.abs(ARGUMENTS[ARGUMENTS != 0]) * 7.3),
    ],
    ids=["sin", "cos", "exp", "log"],
)
def test_the_portable_functions_are_within_one_ulp_of_the_c_library(ours, reference, arguments):
    got = np.array([ours(float(v)) for v in arguments])
    want = np.array([reference(float(v)) for v in arguments])
    assert _ulps(got, want).max() <= 1.0  # both are within half an ulp and a bit of the truth


def test_atan2_is_within_one_ulp_and_has_the_c_functions_signs():
    rng = np.random.default_rng(3)
    y, x = rng.uniform(-5.0, 5.0, 3000), rng.uniform(-5.0, 5.0, 3000)
    got = np.array([portable_math.atan2(float(a), float(b)) for a, b in zip(y, x, strict=True)])
    want = np.array([math.atan2(float(a), float(b)) for a, b in zip(y, x, strict=True)])
    assert _ulps(got, want).max() <= 1.0
    for a, b in [(0.0, 1.0), (-0.0, 1.0), (0.0, -1.0), (-0.0, -1.0), (1.0, 0.0), (-1.0, 0.0)]:
        assert repr(portable_math.atan2(a, b)) == repr(math.atan2(a, b))
    assert portable_math.atan2_array([1.0, -1.0], -1.0).tolist() == [
        portable_math.atan2(1.0, -1.0),
        portable_math.atan2(-1.0, -1.0),
    ]


def test_sincos_is_sin_and_cos_and_special_values_follow_ieee():
    for x in ARGUMENTS[:200]:
        assert portable_math.sincos(float(x)) == (
            portable_math.sin(float(x)),
            portable_math.cos(float(x)),
        )
    assert all(math.isnan(v) for v in portable_math.sincos(math.inf))
    assert portable_math.exp(800.0) == math.inf and portable_math.exp(-800.0) == 0.0
    assert portable_math.log(0.0) == -math.inf and math.isnan(portable_math.log(-1.0))
    assert portable_math.log(1.0) == 0.0 and portable_math.exp(0.0) == 1.0
    assert abs(portable_math.sin(1e7) - math.sin(1e7)) < 1e-6  # past the exact reduction


def test_log_factorial_and_integer_power_are_close_to_exact_values():
    k = np.arange(0, 3000)
    want = np.array([math.lgamma(v + 1.0) for v in k])
    got = portable_math.log_factorial(k)
    assert got[0] == got[1] == 0.0
    assert (_ulps(got[2:], want[2:]) <= 8).all()
    n = np.arange(200)
    exact = np.array([0.9 ** int(m) for m in n])  # the C library's pow, within an ulp
    power = portable_math.integer_power(0.9, n)
    assert (_ulps(power, exact) <= n + 1).all()  # squarings double the relative error


@pytest.mark.skipif(not hasattr(portable_math.sin, "py_func"), reason="numba is not installed")
def test_compiled_and_python_calls_give_the_same_bits():
    funcs = [portable_math.sin, portable_math.cos, portable_math.exp, portable_math.log]
    for function in funcs:
        for x in ARGUMENTS[:500]:
            v = abs(float(x)) + 1e-3 if function is portable_math.log else float(x)
            assert repr(function(v)) == repr(function.py_func(v))
    for y, x in zip(ARGUMENTS[:300], ARGUMENTS[300:600], strict=True):
        got = portable_math.atan2(float(y), float(x))
        assert repr(got) == repr(portable_math.atan2.py_func(float(y), float(x)))


# ---------------------------------------------------------------------- the library's code
#: Calls whose bits depend on the CPU: numpy's dispatched transcendental loops, BLAS and
#: LAPACK, complex numbers, and the C library's transcendental functions.
CPU_DEPENDENT = re.compile(
    r"(?<![\w.])np\.(exp|log|log2|log10|log1p|expm1|sin|cos|tan|arctan|arctan2|angle|tanh|power|hypot|"
    r"dot|matmul|einsum|linalg)\b"
    r"|(?<![\w.])math\.(exp|log|log1p|expm1|sin|cos|tan|atan|atan2|hypot|lgamma|pow|erf)\b"
    r"|\w\s@\s\w|\b1j\b"
)
#: Modules whose numbers never reach a seeded result: what they compute is drawn or printed.
NOT_BIT_RELEVANT = {
    "experiments/framework/plotting.py",  # figures
    "experiments/thesis/delay_sweep.py",  # a log-scale axis of a figure
    "envs/linefollow/render.py",  # pixels of a picture
    "cli.py",
}


def test_the_bit_relevant_modules_call_nothing_that_rounds_by_cpu():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        name = path.relative_to(PACKAGE).as_posix()
        if name in NOT_BIT_RELEVANT or name == "_portable_math.py":
            continue
        code = re.sub(r'"""[\s\S]*?"""', "", path.read_text())  # docstrings may name them
        for line in code.splitlines():
            statement = line.split("#")[0]
            if CPU_DEPENDENT.search(statement):
                found.append(f"{name}: {statement.strip()}")
    assert not found, "\n".join(found)


def test_the_check_finds_what_it_looks_for():
    for statement in ("y = np.exp(x)", "a @ b", "math.lgamma(k)", "z = 1j * w", "np.linalg.norm"):
        assert CPU_DEPENDENT.search(statement), statement
    for statement in ("portable_math.exp(x)", "@_jit", "np.sqrt(x)", "math.floor(x)"):
        assert not CPU_DEPENDENT.search(statement), statement
