"""The outputs of a linkage whose input turns fully: each slider's stroke and each rocker's swing,
their dead-centre positions, the time ratio and the velocity ratio (mechanical advantage).

**Outputs**, classified by the mechanism's links (`kinds`): every *rocker* — the angle of a link
pivoted to the frame that does not turn fully while the input does (its angle comes back to where
it started, not ±2π, after the input's turn) —, every *slider* (a joint's position on a guide
fixed to the frame: a ram, a needle bar) and every *slot* (a block's position in the slot of a
moving link: the length the slot needs). A coupler, a connecting rod or a floating plate is none
of these: its angle is not an output. A sketch file says which links hold a frame joint and which
body each slider's line is fixed to; a loop file says it by its loops, written as the linkage's
polygon (a rocker's vector lies next to a frame vector; a slider's direction holds no unknown;
the link of a slider dyad on a frame guide is its connecting rod, wherever it is written).

**Dead centres** (limit positions of the output) are the inputs where its velocity dq/dφ is zero.
On the equally spaced samples of the turn (the closed form, `jaxlink.solvers.dyads`, and its
derivatives by forward-mode AD: q, q′ = dq/dφ, q″) every interval where q′ changes sign holds one;
it is located by Newton's method on q′ (q″ its derivative), safeguarded by bisection in the
bracket, until the step is at the rounding of the input (measured within 1e-15 rad of the closed
forms, tests/test_dyad_kinds.py). The *stroke* (slider, m) or *swing* (rocker, rad) is the
largest minus the least value of q over the turn, both taken at dead centres or flat positions.

**Flat positions.** At a change point of the turn (a dyad's links in line where its margin only
touches zero: a four-bar with s + l = p + q folding flat; `jaxlink.analysis.motion` locates them)
the closed form on its fixed sides goes on along the other branch, and an output's velocity may
jump there. Where it jumps across zero the output has an extreme that is not a dead centre (no
root of q′: a kink) — a *flat position*, at the change point's input. Its interval is split at
`FLAT_STEP` either side of the change point, the sign change across it is not searched for a
root, and the value there is the output's limit from either side (`_flat_values`), so that the
stroke and the time ratio are the closed form's (a change-point four-bar: to 1e-11, against
1.5e-6° and 3.6e-8 in the ratio when the kink was searched as a root of q′).

**Time ratio.** Between its least value (at input φ₋) and its largest (at φ₊) the output rises
while the input turns by (φ₊ − φ₋) mod 2π and falls back during the rest of the turn:
`rise` + `fall` = 2π. The time ratio is the slower stroke's input angle over the quicker's, ≥ 1
(at a constant input speed, the ratio of their durations: a shaper's quick return).

**Velocity ratio** dq/dφ (m/rad for a slider, dimensionless for a rocker; its inverse is the
mechanical advantage of an ideal linkage): its least and largest values over the turn, from the
samples refined by golden-section search (60 reductions of a two-sample bracket).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..cache import traced
from ..files import expr as _expr
from ..model.mechanism import Mechanism
from ..solvers import dyads as _dyads
from .blocks import BLOCK, in_blocks
from .golden import golden


def kinds(mech: Mechanism) -> dict:
    """The candidate outputs by the mechanism's links: unknown name -> "rocker" (the angle of a
    link pivoted to the frame), "slider" (a joint's position on a guide fixed to the frame) or
    "slot" (a block's position in the slot of a moving link: the slot's length); a coupler, a
    connecting rod, a floating plate are not outputs. A sketch file names its links
    (`Mechanism.sketch`): a link holding a frame joint is a rocker (an actuator's cylinder too, with
    a frame joint), a slider `on = "frame"` a slider, on a link a slot. A loop file by its loops
    (`_kinds_of_loops`). In unknown order; `outputs` keeps the rockers that do not turn fully."""
    lay = mech.sketch
    if lay is None:
        return _kinds_of_loops(mech)
    frame = set(lay.frame)
    found = {f"theta_{b}": "rocker" for b, js in lay.bodies
             if not (lay.input[0] == "crank" and b == lay.input[1]) and frame & set(js)}
    if lay.input[0] == "actuator" and frame & set(lay.input[1]):
        found["theta_{}_{}".format(*lay.input[1])] = "rocker"
    for j, on in lay.sliders:
        found[f"s_{j}"] = "slider" if on == "frame" else "slot"
    return {n: found[n] for n in mech.unknown_names if n in found}


def rockers(mech: Mechanism) -> tuple:
    """The angle unknowns of links pivoted to the frame (`kinds`), in unknown order."""
    return tuple(n for n, k in kinds(mech).items() if k == "rocker")


def _kinds_of_loops(mech: Mechanism) -> dict:
    """`kinds` of a loop file, from its loops written as the linkage's polygon (A0 → A → B → B0 →
    A0, as the file format teaches): an angle unknown is a rocker where its vector lies next to a
    frame vector (no unknown, no input: the vector between two frame joints) in some loop — its
    link has a joint on the frame; a length unknown is a slider where the direction it runs along
    holds no unknown and no input (a guide fixed to the frame), else a slot."""
    moving = set(mech.unknown_names) | {mech.input_name}
    angles = {n for n, k in zip(mech.unknown_names, mech.unknown_kinds) if k == "angle"}
    lengths = set(mech.unknown_names) - angles
    found: dict = {}

    def names(nodes):
        return {n.name for nd in nodes if nd is not None for n in _expr.names_in(nd)}

    for _, terms in mech.loops:
        frame = [not (names(t.nodes()) & moving) for t in terms]
        for j, t in enumerate(terms):
            if t.polar:
                held = names([t.angle]) & angles
                if len(held) == 1 and (frame[j - 1] or frame[(j + 1) % len(terms)]):
                    found[held.pop()] = "rocker"
                for n in names([t.length]) & lengths:
                    if found.get(n) != "slot":
                        found[n] = "slot" if names([t.angle]) & moving else "slider"
            else:
                for n in names(t.nodes()) & lengths:
                    found.setdefault(n, "slider")
    # the link of a slider dyad (RRP) whose joint runs on a guide fixed to the frame is the
    # connecting rod, whatever its neighbours in a loop not written around its polygon (pivoted to
    # the frame as well, the dyad could not move)
    for d in _dyads.classify(mech) or ():
        if d.kind == "RRP" and found.get(mech.unknown_names[d.unknowns[1]]) == "slider":
            if found.get(mech.unknown_names[d.unknowns[0]]) == "rocker":
                del found[mech.unknown_names[d.unknowns[0]]]
    return {n: found[n] for n in mech.unknown_names if n in found}


def _jets_of(mech, sigma, q_ref, phis, p, idx):
    """(q, q′, q″) of the unknowns `idx` (static) at the inputs `phis` (M,): (M, len(idx)) each."""
    dyads = _dyads.classify(mech)

    def q_of(phi):
        return _dyads.solve(mech, dyads, sigma, q_ref, phi, p)[0][jnp.asarray(idx)]

    def one(phi):
        t = jnp.ones_like(phi)
        (v, d1), (_, d2) = jax.jvp(lambda y: jax.jvp(q_of, (y,), (t,)), (phi,), (t,))
        return v, d1, d2

    return jax.vmap(one)(phis)


def _jets_args(mech, sigma, q_ref, phis, p):
    from .whole_curve import _arg

    p = np.asarray(p)
    return (_arg(mech, p), np.asarray(sigma, p.dtype), np.asarray(q_ref, p.dtype), np.asarray(phis, p.dtype), p)


def _jets(mech, idx, sigma, q_ref, phis, p):
    """`_jets_of` at the inputs `phis` (M,) through a stored trace (`jaxlink.cache.traced`; the
    mechanism an argument), in blocks (`in_blocks`): numpy arrays (M, len(idx))."""
    return tuple(in_blocks(np.asarray(phis, np.asarray(p).dtype), lambda xs: traced(
        "stroke_jets", _jets_of, _jets_args(mech, sigma, q_ref, xs, p), (tuple(idx),))))


def prepare(mech: Mechanism, sigma, q_ref, p) -> None:
    """Compile ahead (`jaxlink.cache.prepare`) the jets `outputs` evaluates; `sigma` and `q_ref`
    only for their shapes and dtypes."""
    from ..cache import prepare as _prepare

    idx = output_columns(mech)[1]
    if idx:
        _prepare("stroke_jets", _jets_of, _jets_args(mech, sigma, q_ref, np.zeros(BLOCK), p), (idx,))


def output_columns(mech: Mechanism) -> tuple:
    """`(names, idx)`: the candidate outputs (`kinds`) and their unknowns' indices."""
    names = list(kinds(mech))
    return names, tuple(mech.unknown_names.index(n) for n in names)


class _Eval:
    """The jets at batches of inputs, one column per (output, point)."""

    def __init__(self, mech, idx, sigma, q_ref, p):
        self.args = (mech, idx, sigma, q_ref)
        self.p = p

    def __call__(self, x, col):
        """(q, q′, q″) of output column `col[i]` at input `x[i]`."""
        q, d1, d2 = _jets(*self.args, x, self.p)
        r = np.arange(x.shape[0])
        return q[r, col], d1[r, col], d2[r, col]


def _zeros(ev, lo, hi, col, iterations: int = 60):
    """The roots of q′ of output `col[i]` in the brackets [lo[i], hi[i]] (q′ of opposite signs at
    the ends): Newton's method on q′, each step kept inside the bracket, else bisection."""
    _, flo, _ = ev(lo, col)
    x = 0.5 * (lo + hi)
    lo, hi = lo.copy(), hi.copy()
    s = np.where(flo <= 0, 1.0, -1.0)  # s q′(lo) ≤ 0
    done = np.zeros(lo.shape, bool)
    for _ in range(iterations):
        _, v, dv = ev(x, col)
        neg = s * v < 0
        lo, hi = np.where(neg & ~done, x, lo), np.where(~neg & ~done, x, hi)
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = x - v / dv
        inside = np.isfinite(newton) & (newton > lo) & (newton < hi)
        x_new = np.where(v == 0, x, np.where(inside, newton, 0.5 * (lo + hi)))
        tiny = 4 * np.finfo(float).eps * np.maximum(np.abs(x), 1.0)
        done |= (np.abs(x_new - x) <= tiny) | (hi - lo <= tiny)
        x = np.where(done, x, x_new)
        if done.all():
            break
    return x


def _extremes(ev, grid, v, col, sign):
    """The least (sign 1) or largest (sign −1) q′ of output `col[i]` (`sign[i]`, so that both
    extremes of every output refine at once), refined by golden section."""
    vs = sign * v[:, col]
    k = np.argmin(vs, axis=0)
    n = grid.shape[0] - 1
    a, b = grid[np.maximum(k - 1, 0)], grid[np.minimum(k + 1, n)]
    x1, x2, f1, f2 = golden(lambda x: sign * ev(x, col)[1], a, b, 60)
    best_x = np.where(f1 <= f2, x1, x2)
    best = np.minimum(f1, f2)
    samp = vs[k, np.arange(len(col))]
    return np.where(samp < best, samp, best) * sign, np.where(samp < best, grid[k], best_x)


def _with_flats(ev, grid, q, v, flats, angle):
    """The turn's samples `grid` (N + 1,: the start again at the end) with two inputs at
    `FLAT_STEP` either side of every flat position in `flats` (periodic: one at the start adds
    its sides at the turn's end and beginning) and the samples nearer to one than that left out
    (the closed form's rate is not defined at a change point): `(x, q, q′, across)`, `x` sorted
    over one turn and closed (its first input again, a turn on, at the end), the angles unwrapped
    onto the samples' turn, `across` per interval whether a flat position lies inside it."""
    if not flats:
        return grid, q, v, np.zeros(len(grid) - 1, bool)
    turn = grid[-1] - grid[0]
    flats = np.asarray(flats, float)
    sides = np.concatenate([flats - FLAT_STEP, flats + FLAT_STEP])
    sides = grid[0] + np.mod(sides - grid[0], turn)
    base = grid[:-1]
    dist = np.abs(np.remainder(base[:, None] - flats[None, :] + turn / 2, turn) - turn / 2)
    far = np.all(dist > FLAT_STEP, axis=1)
    m = q.shape[1]
    qs, vs = np.empty((len(sides), m)), np.empty((len(sides), m))
    for j in range(m):
        qs[:, j], vs[:, j], _ = ev(sides, np.full(len(sides), j))
    near = np.clip(np.searchsorted(grid, sides), 0, len(grid) - 1)  # unwrapped like the sample beside it
    qs = np.where(angle, qs + 2 * np.pi * np.round((q[near] - qs) / (2 * np.pi)), qs)
    x = np.concatenate([base[far], sides])
    order = np.argsort(x, kind="stable")
    x, qa, va = x[order], np.concatenate([q[:-1][far], qs])[order], np.concatenate([v[:-1][far], vs])[order]
    x = np.append(x, x[0] + turn)
    qa, va = np.vstack([qa, qa[:1] + (q[-1] - q[0])]), np.vstack([va, va[:1]])
    inside = [np.any((flats > x[i]) & (flats < x[i + 1]) | (flats + turn > x[i]) & (flats + turn < x[i + 1]))
              for i in range(len(x) - 1)]
    return x, qa, va, np.asarray(inside)


FLAT_STEP = 1e-4
"""The distance (rad) either side of a flat position (a change point) at which the output is read:
the closed form is smooth on either side, but not at the change point itself, where the margin
S ≈ c (φ − φ*)² under its square root is rounding (its value there is off by about √eps). At
this distance S is about 1e-8 c, its rounding 1e-8 of it, and the value q(φ*), continuous, comes
from either side to second order (`_flat_values`: the error ~ q‴ FLAT_STEP³ / 6)."""


def _flat_values(ev, x, col):
    """The value of output `col[i]` at the flat position `x[i]`: the mean of its second-order
    Taylor extrapolations from `FLAT_STEP` on either side (q − δ q′ + δ² q″ / 2, δ signed)."""
    est = []
    for d in (-FLAT_STEP, FLAT_STEP):
        qd, vd, ad = ev(x + d, col)
        est.append(qd - d * vd + 0.5 * d * d * ad)
    lo, hi = est
    hi = hi + 2 * np.pi * np.round((lo - hi) / (2 * np.pi))  # an angle wrapped between the sides (a slider's
    return 0.5 * (lo + hi)  # two estimates differ by far less than 2π: no shift)


def outputs(mech: Mechanism, dyads, sigma, q0, phis, p, flats=()) -> list:
    """The outputs' numbers over the full turn sampled by `phis` (N + 1,: the start again at the
    end) on the branches σ (the closed form with reference `q0`), design `p` (SI). `flats`: the
    turn's change points (`jaxlink.analysis.motion`), where the closed form on its fixed sides
    goes on along the other branch and an output's rate may jump. One dict per output, in
    unknown order: `name`, `kind` ("slider" | "rocker"), `min`, `max`, `stroke` (SI),
    `dead_centres` (a list of (input, value) in input order, where the rate is zero),
    `flat_positions` (the change points where the rate jumps across zero: an extreme of the output
    that is not a dead centre, (input, value)), `min_at`, `max_at` (the dead centre or flat
    position of the least and largest value), `min_flat`, `max_flat` (whether that is a flat
    position), `rise`, `fall` (input angles, rad), `time_ratio`, `velocity_min`,
    `velocity_min_at`, `velocity_max`, `velocity_max_at`."""
    del dyads  # unused (the jets classify the structure themselves)
    names, idx = output_columns(mech)
    if not names:
        return []
    kind = kinds(mech)
    ev = _Eval(mech, idx, sigma, q0, p)
    grid = np.asarray(phis, float)
    m = len(idx)
    cols = np.arange(m)
    q, v, _ = _jets(mech, idx, sigma, q0, grid, p)
    angle = np.array([mech.unknown_kinds[i] == "angle" for i in idx])
    q = np.where(angle, np.unwrap(q, axis=0), q)
    keep = ~angle | (np.abs(q[-1] - q[0]) < np.pi)  # a rocker comes back; a crank turns
    ext, ext_at = _extremes(ev, grid, v, np.concatenate([cols, cols]), np.repeat([1.0, -1.0], m))
    vmin, vmin_at, vmax, vmax_at = ext[:m], ext_at[:m], ext[m:], ext_at[m:]
    # dead centres: q′ changes sign on an interval (or is zero at a sample); a flat position splits
    # its interval at FLAT_STEP either side of it, and a sign change across it is a jump, not a root
    x, qx, vx, across = _with_flats(ev, grid, q, v, list(flats), angle)
    change = (vx[:-1] * vx[1:] < 0) | ((vx[:-1] == 0) & (vx[1:] != 0))
    ks, cs = np.nonzero(change & ~across[:, None])
    roots = _zeros(ev, x[ks], x[ks + 1], cs) if ks.size else np.zeros(0)
    vals = ev(roots, cs)[0] if ks.size else np.zeros(0)
    fk, fc = np.nonzero(change & across[:, None])  # the rate jumps across zero at a flat position
    both = np.concatenate([np.asarray(flats, float), np.asarray(flats, float) + (grid[-1] - grid[0])])
    fx = np.array([float(both[(both > x[k]) & (both < x[k + 1])][0]) for k in fk]) if fk.size else np.zeros(0)
    fvals = _flat_values(ev, fx, fc) if fk.size else np.zeros(0)
    out = []
    for j, name in enumerate(names):
        if not keep[j]:
            continue
        mine, flat = cs == j, fc == j
        at = np.concatenate([roots[mine], fx[flat]])
        val = np.concatenate([vals[mine], fvals[flat]])
        near = np.concatenate([qx[ks[mine], j], qx[fk[flat], j]])
        is_flat = np.concatenate([np.zeros(mine.sum(), bool), np.ones(flat.sum(), bool)])
        order = np.argsort(at, kind="stable")
        at, val, near, is_flat = at[order], val[order], near[order], is_flat[order]
        if angle[j]:  # the refined values near the unwrapped samples
            val = val + 2 * np.pi * np.round((near - val) / (2 * np.pi))
        entry = {"name": name, "kind": kind[name],
                 "dead_centres": list(zip(at[~is_flat], val[~is_flat])),
                 "flat_positions": list(zip(at[is_flat], val[is_flat])),
                 "velocity_min": float(vmin[j]), "velocity_min_at": float(vmin_at[j]),
                 "velocity_max": float(vmax[j]), "velocity_max_at": float(vmax_at[j])}
        if at.size >= 2:
            lo, hi = int(np.argmin(val)), int(np.argmax(val))
            rise = float(np.mod(at[hi] - at[lo], 2 * np.pi))
            fall = 2 * np.pi - rise
            entry.update(min=float(val[lo]), max=float(val[hi]), stroke=float(val[hi] - val[lo]),
                         min_at=float(at[lo]), max_at=float(at[hi]), rise=rise, fall=fall,
                         time_ratio=max(rise, fall) / min(rise, fall), min_flat=bool(is_flat[lo]),
                         max_flat=bool(is_flat[hi]))
        else:  # no dead centre: a constant output (no stroke)
            entry.update(min=float(q[:, j].min()), max=float(q[:, j].max()), stroke=float(np.ptp(q[:, j])),
                         min_at=None, max_at=None, rise=None, fall=None, time_ratio=None, min_flat=False,
                         max_flat=False)
        out.append(entry)
    return out


def outputs_over(mech: Mechanism, sigma, q0, lo: float, hi: float, p, samples: int) -> list:
    """The outputs' ranges while a length input (an actuator) runs over [lo, hi] (SI) on the
    branches σ (the closed form with reference `q0`): one dict per output (`kinds`), in unknown
    order — `name`, `kind`, `min`, `max`, `stroke` (the swing of a rocker, SI), `min_at`,
    `max_at` (the input there), `dead_centres` (inputs inside the range where the output's rate is
    zero: an extreme there, (input, value)). The extremes are those of `samples` + 1 equally
    spaced inputs, the ends and the roots of q′ between them (Newton's method on q′, `_zeros`;
    not in the first and last intervals, where a toggle's rate is rounding: the ends stand for
    them).
    Where the range ends at a toggle, the output's rate grows without bound there: no velocity
    ratio is given (`velocity_*` None), nor a time ratio (the input does not turn)."""
    names, idx = output_columns(mech)
    if not names:
        return []
    kind = kinds(mech)
    ev = _Eval(mech, idx, sigma, q0, p)
    grid = np.linspace(lo, hi, samples + 1)
    q, v, _ = _jets(mech, idx, sigma, q0, grid, p)
    angle = np.array([mech.unknown_kinds[i] == "angle" for i in idx])
    q = np.where(angle, np.unwrap(q, axis=0), q)
    change = (v[:-1] * v[1:] < 0) | ((v[:-1] == 0) & (v[1:] != 0))
    change[[0, -1]] = False  # beside a toggle the rate is rounding over a vanishing root: the ends count
    ks, cs = np.nonzero(change)
    roots = _zeros(ev, grid[ks], grid[ks + 1], cs) if ks.size else np.zeros(0)
    vals = ev(roots, cs)[0] if ks.size else np.zeros(0)
    out = []
    for j, name in enumerate(names):
        mine = cs == j
        val = vals[mine]
        if angle[j]:  # the refined values near the unwrapped samples
            val = val + 2 * np.pi * np.round((q[ks[mine], j] - val) / (2 * np.pi))
        at = np.concatenate([[grid[0], grid[-1]], roots[mine]])
        every = np.concatenate([[q[0, j], q[-1, j]], val])
        lo_i, hi_i = int(np.argmin(every)), int(np.argmax(every))
        out.append({"name": name, "kind": kind[name], "min": float(every[lo_i]), "max": float(every[hi_i]),
                    "stroke": float(every[hi_i] - every[lo_i]), "min_at": float(at[lo_i]),
                    "max_at": float(at[hi_i]), "dead_centres": list(zip(roots[mine], val)),
                    "flat_positions": [], "min_flat": False, "max_flat": False, "rise": None, "fall": None,
                    "time_ratio": None, "velocity_min": None, "velocity_min_at": None, "velocity_max": None,
                    "velocity_max_at": None})
    return out
