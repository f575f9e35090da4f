"""3x3 determinant and inverse, written out, for compiled kernels.

numba's np.linalg needs SciPy (not a dependency) and allocates; these work on any 3x3
array (a view such as F[p] included), allocate nothing, and are inlined into the caller
at numba's IR level (inline="always"), so they compile under the caller's fastmath flags
and cost no call.

The two use different operation orders, each kept from the code it replaced so that
the DEM kernel and the MPM volume update give bitwise the same results as before: det3
expands along the first row with alternating signs, inv3 sums the first row against its
cofactors. In exact arithmetic both give det a; in floating point they may differ in the
last bit, and under fastmath the compiler's rewriting depends on the caller (a constant
entry, say, is folded in), so the last bits are not portable between call sites anyway.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True, inline="always")
def det3(a):
    """det a of a 3x3 array, by cofactor expansion along the first row:
    a00 (a11 a22 - a12 a21) - a01 (a10 a22 - a12 a20) + a02 (a10 a21 - a11 a20)."""
    return (a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1])
            - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
            + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]))


@njit(cache=True, inline="always")
def inv3(a, out):
    """out = a^-1 of a 3x3 array (the adjugate over det a); returns det a.

    out must not be a: a is still read after out is first written. det a is the first
    row of a times its cofactors, a00 c00 + a01 c01 + a02 c02. Nothing tests for a
    singular a: out then holds infinities or NaNs (numpy error model), or the division
    raises ZeroDivisionError (Python error model).
    """
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    inv = 1.0 / det
    out[0, 0] = c00 * inv
    out[1, 0] = c01 * inv
    out[2, 0] = c02 * inv
    out[0, 1] = (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) * inv
    out[1, 1] = (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) * inv
    out[2, 1] = (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) * inv
    out[0, 2] = (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) * inv
    out[1, 2] = (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) * inv
    out[2, 2] = (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) * inv
    return det
