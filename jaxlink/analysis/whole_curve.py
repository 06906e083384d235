"""The whole closed curve of a linkage whose input cannot turn fully: traced through its limit
positions, switching branch there.

A dyadic linkage (`jaxlink.solvers.dyads`) driven by an angle that reaches only an interval
[lower, upper] still moves on a closed curve: at a limit position one dyad toggles (its two links
come into line, its reach margin is 0), the input has to turn back, and the dyad goes on in its
other assembly (its side σ flips). `whole_curve` walks that curve from the lower limit of the
file's branch, forward then back, flipping at each limit the σ of the dyad whose margin reaches 0,
until it returns to where it started with the branches it started with (a four-bar
triple-rocker: two segments; a Watt linkage driven by one rocker: its figure-eight, both halves).
A branch on which the input turns fully is one segment, a full turn.

Each end is located by bisection on the toggling dyad's reach margin (`dyads.reach_margins`,
smooth and with a simple root there) between the last assembled sample and the first one that is
not, to adjacent floats of the input; the end is the float on the side where the margin is ≤ 0,
where the closed form puts the dyad in line (h = 0): the same position on both branches, so the
curve closes to rounding. The samples are `samples` per turn; a window where
the linkage cannot assemble narrower than their spacing is not seen here (`jaxlink check` certifies
the file's branch between samples: `jaxlink.analysis.motion`).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ..cache import traced
from ..model.mechanism import Mechanism
from ..solvers import dyads as _dyads
from .blocks import in_blocks


@dataclasses.dataclass(frozen=True)
class WholeCurve:
    """The traced curve (SI).

    - `segments`: `(from, to, sigma)` per segment, in order: the input runs from `from` to `to`
      with the dyads on the sides `sigma` (a tuple of ±1, solve order of `dyads.classify`);
    - `full_turn`: the first segment is a full turn (the input turns fully on the file's branch);
    - `input` (N,), `segment` (N,) the segment of each position, `q` (N, n), `points` (N, K, 2):
      the positions along the curve, each segment from its first end to its last (both included;
      a segment's last position is the next one's first).
    """

    segments: tuple
    full_turn: bool
    input: np.ndarray
    segment: np.ndarray
    q: np.ndarray
    points: np.ndarray


def _margins(mech, sigma, q_ref, phis, p):
    """Every dyad's reach margin at the inputs `phis` (M,): (M, n_dyads) (a stored trace:
    `jaxlink.cache.traced`, the mechanism an argument)."""
    dyads = _dyads.classify(mech)
    return jax.vmap(lambda ph: _dyads.reach_margins(mech, dyads, sigma, q_ref, ph, p))(phis)


def margins_blocked(mech, sigma, q_ref, x, p):
    """Every dyad's reach margin at the inputs `x` (M,) on the branches σ, through one stored
    program (`_margins`) in blocks of `blocks.BLOCK` (`blocks.in_blocks`: one compiled shape for
    the limits' grid and bisection, the certificate's steps and a window's dyad — the program
    `check` compiles ahead): numpy (M, n_dyads)."""
    pj = np.asarray(p)
    arg = _arg(mech, pj)
    sig, q_ref = np.asarray(sigma, dtype=pj.dtype), np.asarray(q_ref, dtype=pj.dtype)
    return in_blocks(np.asarray(x, pj.dtype),
                     lambda xs: (traced("reach_margins", _margins, (arg, sig, q_ref, xs, pj)),))[0]


def _arg(mech, p):
    """The mechanism as a stored program's argument: its numbers `p`, its guesses in p's dtype."""
    return mech.replace(parameters=p, guess=np.asarray(mech.guess, dtype=np.asarray(p).dtype))


def _positions(mech, dyads, sigma, q_ref, phis, p):
    def one(ph):
        q = _dyads.solve(mech, dyads, sigma, q_ref, ph, p)[0]
        return q, mech.point_positions(q, ph, p)

    return jax.vmap(one)(phis)


_positions_jit = jax.jit(_positions, static_argnums=(1,))


def limit(mech: Mechanism, dyads, sigma, q_ref, p, phi0: float, direction: float, samples: int,
          step: float | None = None):
    """Where the branch σ ends going from φ0 in `direction` (±1): `(a, b, j)`, the adjacent
    floats on either side of the toggle of dyad j (its reach margin > 0 at a, ≤ 0 at b), or None
    if the branch goes on for a whole turn (`samples` per turn; a length input: `samples` steps of
    `step`). Bisection on the margin from the last sample where every dyad assembles: it needs
    only the margin's sign, so it finds the same floats whatever the compiler does with the
    arithmetic around it."""
    h = 2 * np.pi / samples if step is None else step
    del dyads  # (classified again inside the stored program)

    def margins(phis):
        return margins_blocked(mech, sigma, q_ref, phis, p)

    grid = phi0 + direction * h * np.arange(1, samples + 1)
    m = margins(grid)
    bad = np.flatnonzero((m <= 0).any(axis=1))
    if not bad.size:
        return None
    k = int(bad[0])
    j = int(np.argmin(m[k]))
    a = phi0 if k == 0 else float(grid[k - 1])
    b = float(grid[k])
    for _ in range(200):  # to adjacent floats
        mid = 0.5 * (a + b)
        if mid in (a, b):
            break
        if margins([mid])[0, j] > 0:
            a = mid
        else:
            b = mid
    return a, b, j


def whole_curve(mech: Mechanism, p=None, *, samples: int = 3600) -> WholeCurve | None:
    """The whole closed curve of `mech` (design `p`, SI, default the file's) from the branch of
    its guesses; None unless its input is an angle and every block is a dyad. `samples` positions
    per turn find the limits (then bisected) and sample the curve."""
    dyads = _dyads.classify(mech)
    if dyads is None or mech.input_kind != "angle":
        return None
    pj = jnp.asarray(np.asarray(mech.parameters if p is None else p, dtype=np.float64))
    start = float(mech.input_start)
    q_ref, _, _, sigma0 = _dyads.solve_nearest(mech, dyads, jnp.asarray(mech.guess), jnp.asarray(start), pj)
    sigma0 = np.asarray(sigma0, dtype=np.float64)
    def end(sigma, phi0, d):
        e = limit(mech, dyads, sigma, q_ref, pj, phi0, d, samples)
        return None if e is None else (e[1], e[2])

    back = end(sigma0, start, -1.0)
    if back is None:  # the input turns fully on this branch
        segments = [(start, start + 2 * np.pi, tuple(sigma0))]
        full = True
    else:
        full = False
        first = back[0]
        sigma, phi, d = sigma0.copy(), first, 1.0
        segments = []
        for _ in range(4 * 2 ** len(dyads)):
            e = end(sigma, phi, d)
            if e is None:  # a branch that turns fully after a flip: trace the turn and go on
                to = phi + d * 2 * np.pi
                segments.append((phi, to, tuple(sigma)))
                phi = to
                continue
            segments.append((phi, e[0], tuple(sigma)))
            sigma = sigma.copy()
            sigma[e[1]] = -sigma[e[1]]
            phi, d = e[0], -d
            if d > 0 and np.array_equal(sigma, sigma0) and abs(phi - first) <= 1e-9:
                break
        else:
            raise RuntimeError("the whole curve did not close")  # a guard: the walk is finite
    span = sum(abs(b - a) for a, b, _ in segments)
    inputs, seg, qs, pts = [], [], [], []
    for i, (a, b, sigma) in enumerate(segments):
        n = max(2, int(np.ceil(abs(b - a) / span * samples)) + 1)
        phis = np.linspace(a, b, n)
        q, xy = _positions_jit(mech, dyads, jnp.asarray(sigma), q_ref, jnp.asarray(phis), pj)
        inputs.append(phis)
        seg.append(np.full(n, i))
        qs.append(np.asarray(q))
        pts.append(np.asarray(xy))
    return WholeCurve(tuple(segments), full, np.concatenate(inputs), np.concatenate(seg),
                      np.concatenate(qs), np.concatenate(pts))
