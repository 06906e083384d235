"""`atan2` and `sincos` as vectorized arithmetic: the closed form's transcendentals.

XLA on the CPU evaluates `jnp.arctan2` in float64 one element at a time (≈ 17 ns per element on
2 cores, about numpy's cost on one); the closed-form solve spends most of its time there (one
`atan2` per solved angle). This one is a few multiplications, one or two divisions and selects
that XLA vectorizes: 2.6 ns per element, at most 2 ulp from numpy's `arctan2` (mean 0.09 ulp,
measured on 1e6 random points; `tests/test_angles.py`). The method is Cephes' `atan` (S. L.
Moshier): the ratio of the smaller to the larger coordinate t ∈ [0, 1]; for t > 0.66 the identity
atan t = π/4 + atan((t − 1)/(t + 1)); a rational approximation of degree 4/5 in t²; the quadrant
from the signs (π/2 and π with the low-order bits Cephes adds, `_MOREBITS`).

Special values as the C library's: atan2(±0, x > 0) = ±0, atan2(±0, x < 0) = ±π, atan2(y, 0) =
±π/2, NaN in, NaN out. Not handled (the solver never asks): infinite arguments and x = −0.
The derivative is the exact one, (x dy − y dx) / (x² + y²).

`sincos` (the cosines and sines of the inputs, one pair per position) likewise: XLA's float64
`cos` and `sin` cost ≈ 27–43 ns per element together, these ≈ 3–4 ns. The method is the C
library's (fdlibm, as in musl): x = n π/2 + r by Cody–Waite with π/2 in three parts (the first
two of 33 bits, so that n times each is exact for |n| < 2²⁰; fdlibm's second round, always) and
r kept as a head and a tail; minimax polynomials of degree 13 (sin) and 14 (cos) on [−π/4, π/4];
the quadrant n mod 4 swaps and negates them. Within 1 ulp of numpy's for |x| ≤ 1e5
(`tests/test_angles.py`); an array with any element beyond (or not finite) takes the C library's
for all of it.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
      -1.228866684490136173410e2, -6.485021904942025371773e1)
_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
      4.853903996359136964868e2, 1.945506571482613964425e2)
_MOREBITS = 6.123233995736765886130e-17  # π/2 − fl(π/2)


@jax.custom_jvp
def atan2(y, x):
    """The angle of the vector (x, y) in (−π, π], elementwise (see the module)."""
    ax, ay = jnp.abs(x), jnp.abs(y)
    swap = ay > ax
    num, den = jnp.where(swap, ax, ay), jnp.where(swap, ay, ax)
    t = num / jnp.where(den == 0, 1.0, den)  # in [0, 1]
    big = t > 0.66
    u = jnp.where(big, (t - 1.0) / (t + 1.0), t)
    z = u * u
    p = (((_P[0] * z + _P[1]) * z + _P[2]) * z + _P[3]) * z + _P[4]
    q = ((((z + _Q[0]) * z + _Q[1]) * z + _Q[2]) * z + _Q[3]) * z + _Q[4]
    r = u + u * (z * p / q)
    r = jnp.where(big, (jnp.pi / 4 + 0.5 * _MOREBITS) + r, r)  # atan t ∈ [0, π/4]
    r = jnp.where(swap, (jnp.pi / 2 + _MOREBITS) - r, r)  # ∈ [0, π/2]
    r = jnp.where(x < 0, (jnp.pi + 2 * _MOREBITS) - r, r)  # ∈ [0, π]
    return jnp.where(jnp.signbit(y), -r, r)


@atan2.defjvp
def _atan2_jvp(primals, tangents):
    y, x = primals
    dy, dx = tangents
    r2 = x * x + y * y
    return atan2(y, x), (x * dy - y * dx) / jnp.where(r2 == 0, 1.0, r2)


# fdlibm's π/2 split (__rem_pio2, second round) and kernel polynomials (__sin, __cos)
_INVPIO2 = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e+00  # the first 33 bits of π/2
_PIO2_2 = 6.07710050630396597660e-11  # the next 33 bits
_PIO2_2T = 2.02226624879595063154e-21  # π/2 − _PIO2_1 − _PIO2_2
_S = (-1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
      2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)
_C = (4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
      -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)
SINCOS_MAX = 1e5  # |x| up to which the reduction is within 1 ulp (measured); beyond: the C library's


def _sincos_reduced(x):
    fn = jnp.round(x * _INVPIO2)  # n, as a float
    t = x - fn * _PIO2_1  # exact (33-bit constant, |n| < 2^20)
    w = fn * _PIO2_2
    r = t - w
    w = fn * _PIO2_2T - ((t - r) - w)
    y0 = r - w  # x − n π/2 = y0 + y1, to about 118 bits
    y1 = (r - y0) - w
    z = y0 * y0
    v = z * z
    rs = _S[1] + z * (_S[2] + z * _S[3]) + z * v * (_S[4] + z * _S[5])
    vs = z * y0
    s = y0 - ((z * (0.5 * y1 - vs * rs) - y1) - vs * _S[0])
    rc = z * (_C[0] + z * (_C[1] + z * _C[2])) + v * v * (_C[3] + z * (_C[4] + z * _C[5]))
    hz = 0.5 * z
    wc = 1.0 - hz
    c = wc + (((1.0 - wc) - hz) + (z * rc - y0 * y1))
    n = fn - 4.0 * jnp.floor(fn * 0.25)  # quadrant, 0 … 3
    odd = (n == 1.0) | (n == 3.0)
    sn, cn = jnp.where(odd, c, s), jnp.where(odd, s, c)
    sn = jnp.where(n >= 2.0, -sn, jnp.where(x == 0, x, sn))  # sin(−0) = −0
    cn = jnp.where((n == 1.0) | (n == 2.0), -cn, cn)
    return cn, sn


def _sincos_libm(x):
    return jnp.cos(x), jnp.sin(x)


@jax.custom_jvp
def sincos(x):
    """(cos x, sin x), elementwise (see the module). float64 by arithmetic where every |x| ≤
    `SINCOS_MAX`; otherwise, and in other dtypes, `jnp.cos` and `jnp.sin`. Under `vmap` of a
    batched x both are evaluated (the choice is then a select)."""
    x = jnp.asarray(x)
    if x.dtype != jnp.float64:
        return _sincos_libm(x)
    # (a NaN anywhere makes the largest |x| NaN, and the comparison False)
    return jax.lax.cond(jnp.max(jnp.abs(x), initial=0.0) <= SINCOS_MAX, _sincos_reduced, _sincos_libm, x)


@sincos.defjvp
def _sincos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    c, s = sincos(x)
    return (c, s), (-s * dx, c * dx)
