"""The sinker's equation of motion (docs/methods/sinker.md) and its static jamming threshold.

One degree of freedom, the sinker lift `y` (m, positive "up" in the thesis's inverted drawing,
gravity along +y). The cam track gives `y_z(t)`, its slope `alpha(t)` and `y_z'(t)`. With the
lag `l = y_z - y`:

```
y'' = P1 + [C l_+ / cos a] (P2 sin a + P3 cos a) + (k/m) (y_z' - y')          (4.25)
P1  = [m g - F_P (1 + 0.75 f / 11) - f (R1 + R2 + R3)] / m                    (4.21)
P2  = (6 f^2 / 11 - 156 f / 36) / m                                           (4.22)
P3  = (1 - 120 f^2 / 36 - 6 f / 11) / m                                       (4.23)
N   = C l / cos a  while l > 0, else 0                                        (4.26)
```

The cam's normal force `N` drives the sinker only through the fraction
`D(a, f) = m (P2 sin a + P3 cos a)`; once `D <= 0` the cam can no longer push the sinker
along the groove (static self-locking, "vzpriceni"). `D = 0` is a quadratic in `f`, solved in
closed form by `static_threshold`.

The damping `k/m` follows the log decrement `delta` of the contact oscillation,
`k/m = delta sqrt(C/m) / pi` (`delta = ln 2` gives 1065.8 1/s at C = 3.5e4 N/m),
unless it is given directly. As in the thesis's Simulink diagram it acts also out of contact
(`damping_always = 1`); `damping_always = 0` switches it off with the contact.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp

from .track import CamTrack, cam_eval


class SinkerParams(NamedTuple):
    """Physical parameters of the sinker (SI; every field an array leaf, so it can be
    `vmap`ped).

    **Fields:**

    - `m`: sinker mass (kg).
    - `C`: contact stiffness of the cam-sinker system (N/m).
    - `k_over_m`: damping per unit mass (1/s).
    - `f`: friction coefficient (groove and cam), dimensionless.
    - `R_sum`: `R1 + R2 + R3`, the preload reactions in the groove (N).
    - `F_P`: needle/yarn force (N).
    - `g`: gravity along +y (m/s^2).
    - `damping_always`: 1.0 = damping also out of contact (the thesis), 0.0 = only in contact.
    - `cos_in_N`: 1.0 = `N = C l / cos a` (the thesis), 0.0 = `N = C l` (a variant).
    """

    m: jnp.ndarray
    C: jnp.ndarray
    k_over_m: jnp.ndarray
    f: jnp.ndarray
    R_sum: jnp.ndarray
    F_P: jnp.ndarray
    g: jnp.ndarray
    damping_always: jnp.ndarray
    cos_in_N: jnp.ndarray


def damping_from_log_decrement(C, m, delta=math.log(2.0)):
    """`k/m = delta sqrt(C/m) / pi` (1/s), the logarithmic-decrement damping of docs/methods/sinker.md."""
    return delta * jnp.sqrt(C / m) / jnp.pi


def make_params(*, m=1.5e-3, C=3.5e4, k_over_m=None, log_decrement=math.log(2.0), f=0.1,
                R_sum=3.2014 + 3.1216 + 6.323, F_P=0.0, g=9.81, damping_always=True,
                cos_in_N=True) -> SinkerParams:
    """`SinkerParams` with the thesis's values; `k_over_m=None` derives it from
    `log_decrement` and `C`. Array arguments broadcast against each other."""
    m, C, f = (jnp.asarray(x, dtype=float) for x in (m, C, f))
    if k_over_m is None:
        k_over_m = damping_from_log_decrement(C, m, log_decrement)
    return SinkerParams(m=m, C=C, k_over_m=jnp.asarray(k_over_m, dtype=float), f=f,
                        R_sum=jnp.asarray(R_sum, dtype=float), F_P=jnp.asarray(F_P, dtype=float),
                        g=jnp.asarray(g, dtype=float),
                        damping_always=jnp.asarray(float(damping_always)),
                        cos_in_N=jnp.asarray(float(cos_in_N)))


def p_coefficients(p: SinkerParams):
    """`(P1, P2, P3)` of eqs. 4.21-4.23 (units m/s^2, 1/kg, 1/kg)."""
    f = p.f
    p1 = (p.m * p.g - p.F_P * (1.0 + 0.75 * f / 11.0) - f * p.R_sum) / p.m
    p2 = (6.0 * f**2 / 11.0 - 156.0 * f / 36.0) / p.m
    p3 = (1.0 - 120.0 * f**2 / 36.0 - 6.0 * f / 11.0) / p.m
    return p1, p2, p3


def drive_fraction(alpha, f):
    """`D(a, f) = m (P2 sin a + P3 cos a)`: the part of the cam's normal force that pushes the
    sinker along the groove (dimensionless). Jamming when `D <= 0`."""
    return ((6.0 * f**2 / 11.0 - 156.0 * f / 36.0) * jnp.sin(alpha)
            + (1.0 - 120.0 * f**2 / 36.0 - 6.0 * f / 11.0) * jnp.cos(alpha))


def static_threshold(alpha):
    """Friction coefficient `f*` at which `D(alpha, f*) = 0` (closed form).

    `D = a f^2 + b f + c` with `a = 6/11 sin - 120/36 cos`, `b = -(156/36 sin + 6/11 cos)`,
    `c = cos`; for `0 < alpha < 90 deg` `c > 0 > b` and the smallest positive root is
    `f* = 2c / (-b + sqrt(b^2 - 4ac))` (the cancellation-free form). Independent of m, C, R,
    F_P and k.
    """
    s, c = jnp.sin(alpha), jnp.cos(alpha)
    qa = 6.0 / 11.0 * s - 120.0 / 36.0 * c
    qb = -(156.0 / 36.0 * s + 6.0 / 11.0 * c)
    return 2.0 * c / (-qb + jnp.sqrt(qb**2 - 4.0 * qa * c))


def acceleration(p: SinkerParams, cam: CamTrack, t, u, contact, k=None):
    """`y''` (m/s^2) and `N` (N) at time `t`, state `u = (y, y')`, in contact mode `contact`
    (1.0 = the contact law is applied, 0.0 = free flight), on cam piece `k`.

    In contact the law is applied *without* the `max(l, 0)`, so that each mode's right-hand
    side is smooth; the integrator switches the mode where `l` changes sign.
    """
    yz, alpha, yz_dot = cam_eval(cam, t, k)
    p1, p2, p3 = p_coefficients(p)
    lag = yz - u[0]
    cos_fac = jnp.where(p.cos_in_N > 0.5, jnp.cos(alpha), 1.0)
    normal = contact * p.C * lag / cos_fac
    damp = jnp.where(p.damping_always > 0.5, 1.0, contact)
    acc = (p1 + normal * (p2 * jnp.sin(alpha) + p3 * jnp.cos(alpha))
           + damp * p.k_over_m * (yz_dot - u[1]))
    return acc, normal


def vector_field(p: SinkerParams, cam: CamTrack, t, u, contact, k=None):
    """`d/dt (y, y')` for the hybrid integrator (see `acceleration`)."""
    acc, _ = acceleration(p, cam, t, u, contact, k)
    return jnp.stack([u[1], acc])


def lag(cam: CamTrack, t, u, k=None):
    """`y_z - y` (m): positive while the butt presses on the cam."""
    return cam_eval(cam, t, k)[0] - u[0]


def nonsmooth_acceleration(p: SinkerParams, cam: CamTrack, t, u, k=None):
    """`y''` and `N` with the thesis's switch `N = C max(l, 0) / cos a` (no modes)."""
    contact = (lag(cam, t, u, k) > 0).astype(u.dtype)
    return acceleration(p, cam, t, u, contact, k)
