"""exp, log, sin, cos and atan2 that give the same bits on every CPU.

numpy's SIMD loops and the C library's fused multiply-add variants round these functions
differently from one CPU to another. The functions here are fdlibm's algorithms written with the
four basic operations in a fixed order, so a compiled call, a Python call and a call on another
CPU return the same bits, within one unit in the last place. Why, how, and their domains: the
docs' reproducibility page (``docs/reproducibility.md``, "Portable exp, log, sin, cos and atan2").
"""

from __future__ import annotations

import math

import numpy as np

from delayed_rl._numba import jit

__all__ = [
    "atan2",
    "atan2_array",
    "cos",
    "cos_array",
    "exp",
    "exp_array",
    "integer_power",
    "log",
    "log_factorial",
    "sin",
    "sin_array",
    "sincos",
]

# ---------------------------------------------------------------------- exp and log
_LN2_HI = 6.93147180369123816490e-01  # ln 2's upper 32 bits: k · _LN2_HI is exact
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e00
_EXP_P1 = 1.66666666666666019037e-01
_EXP_P2 = -2.77777777770155933842e-03
_EXP_P3 = 6.61375632143793436117e-05
_EXP_P4 = -1.65339022054652515390e-06
_EXP_P5 = 4.13813679705723846039e-08
_EXP_OVERFLOW = 7.09782712893383973096e02
_EXP_UNDERFLOW = -7.45133219101941108420e02

_LG1 = 6.666666666666735130e-01
_LG2 = 3.999999999940941908e-01
_LG3 = 2.857142874366239149e-01
_LG4 = 2.222219843214978396e-01
_LG5 = 1.818357216161805012e-01
_LG6 = 1.531383769920937332e-01
_LG7 = 1.479819860511658591e-01
_SQRT_HALF = 7.07106781186547524401e-01


@jit
def exp(x):
    """e**x, reproducible to the bit (fdlibm's ``e_exp``)."""
    if x != x:
        return x
    if x > _EXP_OVERFLOW:
        return math.inf
    if x < _EXP_UNDERFLOW:
        return 0.0
    if -3.725290298461914e-09 < x < 3.725290298461914e-09:  # |x| < 2**-28: 1 + x
        return 1.0 + x
    k = math.floor(x * _INV_LN2 + 0.5)
    hi = x - k * _LN2_HI
    lo = k * _LN2_LO
    r = hi - lo
    t = r * r
    c = r - t * (_EXP_P1 + t * (_EXP_P2 + t * (_EXP_P3 + t * (_EXP_P4 + t * _EXP_P5))))
    y = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    return math.ldexp(y, int(k))


@jit
def log(x):
    """The natural logarithm, reproducible to the bit (fdlibm's ``e_log``)."""
    if x != x or x < 0.0:
        return math.nan
    if x == 0.0:
        return -math.inf
    if x == math.inf:
        return x
    m, e = math.frexp(x)  # x = m · 2**e, m in [0.5, 1): exact
    if m < _SQRT_HALF:
        m *= 2.0
        e -= 1
    f = m - 1.0  # in [√2/2 − 1, √2 − 1)
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (_LG2 + w * (_LG4 + w * _LG6))
    t2 = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7)))
    big = t2 + t1
    half_f2 = 0.5 * f * f
    k = float(e)
    return k * _LN2_HI - ((half_f2 - (s * (half_f2 + big) + k * _LN2_LO)) - f)


_EXACT_FACTORIALS = 30  # below it, k! is exact in an integer and rounded once to a double
_HALF_LOG_TWO_PI = 9.18938533204672741780e-01


@jit
def _log_factorials(k):
    """``log(k!)`` for each integer-valued ``k >= 0`` of a float array (see ``log_factorial``)."""
    exact = np.empty(_EXACT_FACTORIALS)
    factorial = 1.0  # exact up to 22! (its odd part fits 53 bits), then rounded once a step
    for i in range(_EXACT_FACTORIALS):
        if i > 1:
            factorial *= i
        exact[i] = log(factorial)
    out = np.empty(k.shape[0])
    for i in range(k.shape[0]):
        n = k[i]
        if n < _EXACT_FACTORIALS:
            out[i] = exact[int(n)]
            continue
        x = n + 1.0  # Stirling's series for log Γ(x), truncated after 1/x⁷ (error < 1e-16)
        r = 1.0 / x
        r2 = r * r
        series = r * (1.0 / 12.0 - r2 * (1.0 / 360.0 - r2 * (1.0 / 1260.0 - r2 * (1.0 / 1680.0))))
        out[i] = (x - 0.5) * log(x) - x + _HALF_LOG_TWO_PI + series
    return out


def log_factorial(k) -> np.ndarray:
    """``log(k!)`` of each element of ``k`` (integers ``>= 0``), reproducible to the bit.

    Below 30 from the product of the integers (exact up to 22!, then one rounding a step),
    above from Stirling's series for ``log Γ(k + 1)``: within a few units in the last place of
    ``math.lgamma(k + 1)``, whose C implementation calls the CPU-dependent ``log`` and ``exp``.
    """
    array = np.asarray(k, dtype=np.float64)
    return _log_factorials(np.ascontiguousarray(array.ravel())).reshape(array.shape)


def integer_power(base: float, exponent) -> np.ndarray:
    """``base ** k`` for each integer ``k >= 0`` of ``exponent``, by repeated squaring.

    A fixed sequence of multiplications (about 2·log₂ k of them), reproducible to the bit, where
    ``np.power`` runs a CPU-dependent SIMD loop. Each squaring doubles the relative error of
    the square, so the result is within about ``k`` units in the last place (1e-13 relative at
    ``k = 1000``).
    """
    remaining = np.asarray(exponent, dtype=np.int64).copy()
    result = np.ones(remaining.shape)
    square = np.full(remaining.shape, float(base))
    while np.any(remaining > 0):
        odd = (remaining & 1) == 1
        result = np.where(odd, result * square, result)
        square = square * square
        remaining >>= 1
    return result


# ---------------------------------------------------------------------- sin and cos
_INV_PIO2 = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e00  # π/2's first 33 bits: n · _PIO2_1 is exact
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_2T = 2.02226624879595063154e-21
_REDUCE_LIMIT = 823549.6653753  # 2**19 · π/2
_TWO_PI = 6.283185307179586

_SIN = (
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
)
"""fdlibm's ``__kernel_sin`` coefficients S1..S6 (``_SIN[0]`` is S1)."""
_COS = (
    4.16666666666666019037e-02,
    -1.38888888888741095749e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
)
"""fdlibm's ``__kernel_cos`` coefficients C1..C6."""


@jit
def _kernel_sin(x, y):
    """sin(x + y) for ``|x| <= π/4``, ``y`` the tail of the reduced argument."""
    z = x * x
    v = z * x
    r = _SIN[1] + z * (_SIN[2] + z * (_SIN[3] + z * (_SIN[4] + z * _SIN[5])))
    return x - ((z * (0.5 * y - v * r) - y) - v * _SIN[0])


@jit
def _kernel_cos(x, y):
    """cos(x + y) for ``|x| <= π/4``."""
    z = x * x
    r = z * (_COS[0] + z * (_COS[1] + z * (_COS[2] + z * (_COS[3] + z * (_COS[4] + z * _COS[5])))))
    half_z = 0.5 * z
    w = 1.0 - half_z
    return w + (((1.0 - w) - half_z) + (z * r - x * y))


@jit
def _reduce(x):
    """``(n mod 4, y, tail)`` with x = n·π/2 + y + tail and ``|y + tail| <= π/4`` (about)."""
    if not abs(x) < _REDUCE_LIMIT:
        x = x % _TWO_PI  # Python's float modulo (numba mirrors it): fmod, then + 2π if negative
    n = math.floor(x * _INV_PIO2 + 0.5)
    t = x - n * _PIO2_1  # then π/2's next bits, as fdlibm's medium-size reduction
    w = n * _PIO2_2
    r = t - w
    w = n * _PIO2_2T - ((t - r) - w)
    y = r - w
    tail = (r - y) - w
    quadrant = int(n - 4.0 * math.floor(n * 0.25))
    return quadrant, y, tail


@jit
def sincos(x):
    """``(sin(x), cos(x))`` from one argument reduction, reproducible to the bit."""
    if x != x or x == math.inf or x == -math.inf:
        return math.nan, math.nan
    if -7.450580596923828e-09 < x < 7.450580596923828e-09:  # |x| < 2**-27
        return x, 1.0
    quadrant, y, tail = _reduce(x)
    s, c = _kernel_sin(y, tail), _kernel_cos(y, tail)
    if quadrant == 0:
        return s, c
    if quadrant == 1:
        return c, -s
    if quadrant == 2:
        return -s, -c
    return -c, s


@jit
def sin(x):
    """The sine, reproducible to the bit (fdlibm's ``s_sin``)."""
    return sincos(x)[0]


@jit
def cos(x):
    """The cosine, reproducible to the bit (fdlibm's ``s_cos``)."""
    return sincos(x)[1]


# ---------------------------------------------------------------------- atan2
_ATAN_HI = (
    4.63647609000806093515e-01,
    7.85398163397448278999e-01,
    9.82793723247329054082e-01,
    1.57079632679489655800e00,
)
_ATAN_LO = (
    2.26987774529616870924e-17,
    3.06161699786838301793e-17,
    1.39033110312309984516e-17,
    6.12323399573676603587e-17,
)
_ATAN = (
    3.33333333333329318027e-01,
    -1.99999999998764832476e-01,
    1.42857142725034663711e-01,
    -1.11111104054623557880e-01,
    9.09088713343650656196e-02,
    -7.69187620504482999495e-02,
    6.66107313738753120669e-02,
    -5.83357013379057348645e-02,
    4.97687799461593236017e-02,
    -3.65315727442169155270e-02,
    1.62858201153657823623e-02,
)
"""fdlibm's ``atan`` polynomial coefficients aT[0..10]."""
_PI = 3.1415926535897931160e00
_PI_LO = 1.2246467991473531772e-16


@jit
def _atan(v):
    """arctan(v) for ``v >= 0`` (fdlibm's ``s_atan``)."""
    if v > 7.378697629483821e19:  # 2**66
        return _ATAN_HI[3] + _ATAN_LO[3]
    if v < 0.4375:
        if v < 3.725290298461914e-09:  # 2**-28
            return v
        part = -1
        x = v
    elif v < 1.1875:
        if v < 0.6875:
            part = 0
            x = (2.0 * v - 1.0) / (2.0 + v)
        else:
            part = 1
            x = (v - 1.0) / (v + 1.0)
    elif v < 2.4375:
        part = 2
        x = (v - 1.5) / (1.0 + 1.5 * v)
    else:
        part = 3
        x = -1.0 / v
    z = x * x
    w = z * z
    s1 = z * (
        _ATAN[0] + w * (_ATAN[2] + w * (_ATAN[4] + w * (_ATAN[6] + w * (_ATAN[8] + w * _ATAN[10]))))
    )
    s2 = w * (_ATAN[1] + w * (_ATAN[3] + w * (_ATAN[5] + w * (_ATAN[7] + w * _ATAN[9]))))
    if part < 0:
        return x - x * (s1 + s2)
    return _ATAN_HI[part] - ((x * (s1 + s2) - _ATAN_LO[part]) - x)


@jit
def atan2(y, x):
    """The angle of (x, y) in ``[-π, π]``, reproducible to the bit (fdlibm's ``e_atan2``).

    Finite arguments only (an infinite or NaN one gives NaN); ``atan2(±0, x)`` is ±0 for
    ``x >= 0`` and ±π for ``x < 0``, as the C function's.
    """
    if not (abs(x) < math.inf and abs(y) < math.inf):
        return math.nan
    if y == 0.0:
        if x > 0.0 or (x == 0.0 and math.copysign(1.0, x) > 0.0):
            return y
        return math.copysign(_PI, y)
    if x == 0.0:
        return math.copysign(_ATAN_HI[3] + _ATAN_LO[3], y)
    a = _atan(abs(y / x))
    if x > 0.0:
        return math.copysign(a, y)
    return math.copysign(_PI - (a - _PI_LO), y)


# ---------------------------------------------------------------------- arrays
@jit
def _map(function_id, values):
    out = np.empty(values.shape[0])
    for i in range(values.shape[0]):
        if function_id == 0:
            out[i] = sin(values[i])
        elif function_id == 1:
            out[i] = cos(values[i])
        else:
            out[i] = exp(values[i])
    return out


def _apply(function_id: int, values) -> np.ndarray:
    array = np.asarray(values, dtype=np.float64)
    return _map(function_id, np.ascontiguousarray(array.ravel())).reshape(array.shape)


def sin_array(values) -> np.ndarray:
    """``sin`` of every element (a float64 array of the same shape)."""
    return _apply(0, values)


def cos_array(values) -> np.ndarray:
    """``cos`` of every element (a float64 array of the same shape)."""
    return _apply(1, values)


def exp_array(values) -> np.ndarray:
    """``exp`` of every element (a float64 array of the same shape)."""
    return _apply(2, values)


@jit
def _atan2_map(y, x):
    out = np.empty(y.shape[0])
    for i in range(y.shape[0]):
        out[i] = atan2(y[i], x[i])
    return out


def atan2_array(y, x) -> np.ndarray:
    """``atan2`` of every pair of elements of ``y`` and ``x`` (broadcast together)."""
    y_array, x_array = np.broadcast_arrays(np.asarray(y, np.float64), np.asarray(x, np.float64))
    flat = _atan2_map(np.ascontiguousarray(y_array.ravel()), np.ascontiguousarray(x_array.ravel()))
    return flat.reshape(y_array.shape)
