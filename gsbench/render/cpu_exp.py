"""The exponential and the dtype rounding of the `cpu` rasterizer's kernels (gsbench/render/cpu_kernels.py).

Both are polynomials with no library call, so the loops around them vectorise: `_exp32` in float32
arithmetic for the float32 working dtype (half the vector width of float64), `_exp` in float64 for
float64. `_expw` picks by the argument's dtype; `_like` rounds a float64 to the working dtype.
"""
from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import intrinsic, overload

_OPTS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)


def _bits_as(int_type, float_type):
    """An intrinsic taking an integer of int_type to the float of float_type with the same bits
    (vectorisable, unlike a view of an array)."""
    @intrinsic
    def bitcast(typingctx, x):
        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], context.get_value_type(float_type))
        return float_type(int_type), codegen
    return bitcast


_i64_as_f64 = _bits_as(types.int64, types.float64)
_i32_as_f32 = _bits_as(types.int32, types.float32)


_LN2_HI = 6.93147180369123816490e-01      # ln 2 split so that n * _LN2_HI is exact for |n| < 2^20
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e+00


@njit(inline="always", **_OPTS)
def _exp(x):
    """exp(x) for x <= 0 in float64, without a library call (so loops around it vectorise).

    x is clamped to [-708, 0] (NaN -> -708): callers use it only where the exponent is <= 0 and
    mask every other lane. exp(x) = 2^n exp(r), n = round(x / ln 2), |r| <= ln 2 / 2, exp(r) by its
    degree-12 Taylor polynomial (truncation < 2e-16 relative): about 1 ulp in float64; rounded to
    float32 it is the correctly rounded expf on all 5 million samples of a test.
    """
    x = x if x > -708.0 else -708.0
    x = x if x < 0.0 else 0.0
    n = np.floor(x * _INV_LN2 + 0.5)
    r = (x - n * _LN2_HI) - n * _LN2_LO
    # Estrin's scheme: the same polynomial in about a third of Horner's dependent-operation depth
    r2 = r * r
    r4 = r2 * r2
    r8 = r4 * r4
    q0 = (1.0 + r) + (0.5 + r * (1.0 / 6.0)) * r2
    q1 = (1.0 / 24.0 + r * (1.0 / 120.0)) + (1.0 / 720.0 + r * (1.0 / 5040.0)) * r2
    q2 = (1.0 / 40320.0 + r * (1.0 / 362880.0)) + (1.0 / 3628800.0 + r * (1.0 / 39916800.0)) * r2
    p = (q0 + q1 * r4) + (q2 + (1.0 / 479001600.0) * r4) * r8
    return p * _i64_as_f64((np.int64(n) + 1023) << 52)


_F32 = np.float32


@njit(inline="always", **_OPTS)
def _exp32(x):
    """exp(x) for float32 x <= 0 in float32 arithmetic, without a library call: within 1.01 ulp of
    the exact value (a test checks it on 2 million samples; PyTorch's own CPU expf is specified
    within 1 ulp), at half the vector width of `_exp`.

    x is clamped to [-87, 0] (exp(-87) = 1.6e-38 is still a normal float32; callers mask every lane
    below log(ALPHA_MIN) anyway). exp(x) = 2^n exp(r), n = round(x / ln 2), r = x - n ln 2 with
    ln 2 split in two (n * 0.693359375 is exact), and exp(r) = 1 + r + r^2 q(r), q of degree 5
    (Cephes' expf coefficients) by Estrin's scheme; the small terms are added to 1 last.
    """
    x = x if x > _F32(-87.0) else _F32(-87.0)
    x = x if x < _F32(0.0) else _F32(0.0)
    n = np.floor(x * _F32(1.44269504) + _F32(0.5))
    r = (x - n * _F32(0.693359375)) - n * _F32(-2.12194440e-4)
    z = r * r
    z2 = z * z
    c01 = _F32(5.0000001201e-1) + r * _F32(1.6666665459e-1)
    c23 = _F32(4.1665795894e-2) + r * _F32(8.3334519073e-3)
    c45 = _F32(1.3981999507e-3) + r * _F32(1.9875691500e-4)
    q = (c01 + c23 * z) + c45 * z2
    p = (q * z + r) + _F32(1.0)
    return p * _i32_as_f32((np.int32(n) + np.int32(127)) << np.int32(23))


def _expw(x):
    """exp(x) for x <= 0 in the working dtype: `_exp32` for float32, `_exp` for float64."""
    return x


@overload(_expw, inline="always")
def _expw_impl(x):
    if x == types.float32:
        return lambda x: _exp32(x)
    return lambda x: _exp(x)


def _like(x, ref):
    """x (float64) rounded to the dtype of `ref` (the working dtype)."""
    return x


@overload(_like, inline="always")
def _like_impl(x, ref):
    if ref == types.float32:
        return lambda x, ref: np.float32(x)
    return lambda x, ref: x
