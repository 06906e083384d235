"""Where a drawing of the linkage puts every vector: the geometry of the plots and animations.

A loop of the file, `Σ_j t_j = 0`, is a closed polygon whose vertices V_j = T + Σ_{i<j} t_i (vertex
j is where term j starts) are the joints of its links; the loop fixes them only up to the
translation T. The points of `[points]` are sums from the frame origin, so the vertices of their
chains (the origin, then each partial sum) are absolute positions, and so are the joints of
`[joints]` (their `at` sums). Each loop is placed by the translation that puts the most of its
vertices on such known positions at every sampled position — moving vertices counting first, then
fixed ones; a loop placed this way adds its vertices to the known positions of the loops placed
after it. The frame origin is always a known position: a loop that touches nothing else is placed
with the start of its input vector (the crank) there, else with its first vertex there. So a
loop may be written starting at any vertex and in either direction and is drawn in the same place.

What is drawn (metres, per position):

- each term of a loop by its kind: `link` (constant length, moving: a rigid bar), `frame`
  (constant vector: dashed), `slider` (variable length: drawn as a block on its guide line), or
  `variable` (a Cartesian vector with moving components: a thin line);
- joints: the vertices where a link ends, merged across loops; a joint that does not move is a
  ground pivot. Names: from `[joints]` (revolute joints at the same place), else a `[points]`
  point at the same place, else generated (`O1`, `O2`, … for ground pivots, `J1`, … for others);
- sliders: for each `slider` term, its block sits on the end of the vector that is a joint and
  its guide runs along the vector. When a `[points]` chain contains the same vector (±) the
  placement of that chain is used (a loop may be rewritten with a parallel offset; the point's
  chain says where the slider really is);
- arms: for each point, its chain from the last vertex that is a joint to the point (a coupler
  point's triangle).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ..files import expr as _expr

KINDS = ("link", "frame", "slider", "variable")


@dataclasses.dataclass
class Slider:
    """A slider: `block` (N, 2) where the block sits, `axis` (N, 2) unit vector of its guide,
    `guide` (N, 2, 2) the two ends of the guide line to draw; `term` the file's vector text."""

    block: np.ndarray
    axis: np.ndarray
    guide: np.ndarray
    term: str


@dataclasses.dataclass
class LinkageDrawing:
    """The placed linkage at every position (metres). See the module docstring.

    - `loops`: per loop, (N, n, 2) vertices; vertex j is where term j starts (the polygon closes).
    - `kinds`, `labels`: per loop, per term: one of `KINDS`, and the text of its length.
    - `placed_by`: per loop, how its translation was fixed (e.g. `vertex 1 on the origin`).
    - `joints` (N, J, 2), `joint_names` (J), `ground` (J,) bool: joints and which are ground pivots.
    - `sliders`: list of `Slider`.
    - `arms`: per point, (N, m, 2) polyline from its last joint to the point.
    - `points` (N, n_points, 2), `point_names`.
    - `shown` (N,) bool: positions that are drawn (assembled); elsewhere the arrays are NaN.
    - `extent`: the size of the drawing (m), for symbol sizes.
    """

    loops: list
    kinds: list
    labels: list
    placed_by: list
    joints: np.ndarray
    joint_names: list
    ground: np.ndarray
    sliders: list
    arms: list
    points: np.ndarray
    point_names: tuple
    shown: np.ndarray
    extent: float


def term_kind(mech, term) -> str:
    """`link`, `frame`, `slider` or `variable` (see the module docstring)."""
    moving = set(mech.unknown_names) | {mech.input_name}

    def moves(node):
        return any(n.name in moving for n in _expr.names_in(node))

    if not term.polar:
        return "variable" if moves(term.x) or moves(term.y) else "frame"
    if moves(term.length):
        return "slider"
    return "link" if moves(term.angle) else "frame"


def _length_text(term) -> str:
    if not term.polar:
        return term.text.strip()
    return term.text.split("@")[0].strip().lstrip("+-").strip()


def _vectors(mech, q, phis, p):
    """Per position: every term vector of the loops, points and joints, and the unit vector of
    the angle of every polar loop and point term (zeros for Cartesian terms)."""
    joints = [] if mech.bodies is None else [j.at for j in mech.bodies.joints]
    groups = [t for _, t in mech.loops] + [t for _, t in mech.points] + [tuple(a) for a in joints]

    def one(qk, phik):
        env = mech.env(qk, phik, p)
        out = []
        for terms in groups:
            vec, axis = [], []
            for term in terms:
                x, y = mech.term_vector(term, env)
                vec.append(jnp.stack([jnp.asarray(x, qk.dtype), jnp.asarray(y, qk.dtype)]))
                if term.polar:
                    c, s = mech.unit_vector(term.angle, env)
                    axis.append(jnp.stack([jnp.asarray(c, qk.dtype), jnp.asarray(s, qk.dtype)]))
                else:
                    axis.append(jnp.zeros(2, qk.dtype))
            out.append((jnp.stack(vec), jnp.stack(axis)))
        return out

    q = jnp.asarray(q)
    res = jax.jit(jax.vmap(one))(q, jnp.asarray(phis, dtype=q.dtype))
    res = [(np.asarray(v, dtype=float), np.asarray(a, dtype=float)) for v, a in res]
    nl, npt = len(mech.loops), len(mech.points)
    return res[:nl], res[nl:nl + npt], res[nl + npt:]


def _partial_sums(vec):
    """(N, m, 2) vectors -> (N, m + 1, 2): 0, t0, t0 + t1, …"""
    zero = np.zeros_like(vec[:, :1])
    return np.concatenate([zero, np.cumsum(vec, axis=1)], axis=1)


class _Known:
    """Known absolute positions (N, 2) with a description each."""

    def __init__(self, sample, tol):
        self.arrays, self.names, self.sample, self.tol = [], [], sample, tol

    def add(self, arr, name):
        self.arrays.append(arr)
        self.names.append(name)

    def stacked(self):
        return np.stack(self.arrays, axis=1)  # (N, K, 2)

    def hits(self, verts, exclude=()):
        """(n,) bool: which of the vertices (N, n, 2) lie on a known position at every sampled row."""
        a = self.stacked()[self.sample]
        keep = [i for i in range(a.shape[1]) if i not in exclude]
        a = a[:, keep]
        d = np.linalg.norm(verts[self.sample][:, :, None, :] - a[:, None, :, :], axis=-1)  # (S, n, K)
        return (np.nanmax(d, axis=0) < self.tol).any(axis=1)


def _fixed(arr, sample, tol):
    """Whether positions (N, …, 2) do not move over the sampled rows: (…) bool."""
    a = arr[sample]
    return np.nanmax(np.linalg.norm(a - a[:1], axis=-1), axis=0) < tol


def _input_vertex(mech, terms) -> int | None:
    for j, term in enumerate(terms):
        if any(n.name == mech.input_name for node in term.nodes() for n in _expr.names_in(node)):
            return j
    return None


def _place(rel, joint, kin, terms, known, sample, tol, exclude):
    """Best translation of one loop with relative vertices `rel` (N, n, 2): returns `(score,
    translation (N, 2), description)`. A candidate pins vertex k on known position m. Its evidence
    is the vertices that then lie on known positions at every sampled row, the pinned one counted
    only when it is pinned on a moving position and the loop then keeps some vertex still (a loop
    with a ground pivot; any vertex can be pinned on anything). The score counts the evidence —
    moving joints (`joint` (n,) bool: a link ends there), joints, moving vertices, all — then the
    vertices that stand still (a loop with two ground pivots pinned by one of them), then prefers
    the start of the input vector `kin` on the origin, then the earliest vertex. `exclude`: indices
    of known positions not to use (the loop's own vertices, when it is placed again)."""
    best = None
    a_all = known.stacked()
    anchor_still = _fixed(a_all, sample, tol)
    for m in range(a_all.shape[1]):
        if m in exclude:
            continue
        for k in range(rel.shape[1]):
            shift = a_all[:, m] - rel[:, k]
            verts = shift[:, None, :] + rel
            hit = known.hits(verts, exclude)
            moving = ~_fixed(verts, sample, tol)
            still = int((~moving).sum())
            if anchor_still[m] or still == 0:
                hit[k] = False
            bonus = int(known.names[m] == "the origin" and k == kin)
            score = (int((hit & moving & joint).sum()), int((hit & joint).sum()), int((hit & moving).sum()),
                     int(hit.sum()), still, bonus, -k)
            if best is None or score > best[0]:
                best = (score, shift, f"vertex {k} (where {terms[k].text.strip()!r} starts) on {known.names[m]}")
    return best


def drawing(mech, q, phis, p, shown, tol: float | None = None) -> LinkageDrawing:
    """Place the linkage (see the module docstring) at solved positions `q` (N, n), inputs `phis`
    (N,) SI, parameters `p` (P,); `shown` (N,) bool: the assembled positions (the others are NaN).
    `tol` (m): the distance below which two positions are the same (default max(1e-7, 1000 eps) of
    the dtype of `q` times the length scale: positions solved in float32 are close to 1e-4)."""
    shown = np.asarray(shown, dtype=bool)
    p = jnp.asarray(p)
    n_rows = len(shown)
    kinds = [[term_kind(mech, t) for t in terms] for _, terms in mech.loops]
    labels = [[_length_text(t) for t in terms] for _, terms in mech.loops]
    if not shown.any():  # nothing assembled: nothing to draw
        nan = np.full((n_rows, 1, 2), np.nan)
        return LinkageDrawing([np.full((n_rows, len(t), 2), np.nan) for _, t in mech.loops], kinds, labels,
                              ["not placed: no position assembled"] * len(mech.loops), np.zeros((n_rows, 0, 2)),
                              [], np.zeros(0, bool), [], [nan for _ in mech.points],
                              np.full((n_rows, len(mech.points), 2), np.nan), tuple(mech.point_names), shown,
                              float(mech.length_scale(p)))
    loop_vec, point_vec, joint_vec = _vectors(mech, q, phis, p)
    rows = np.flatnonzero(shown)
    sample = rows[np.unique(np.linspace(0, len(rows) - 1, min(len(rows), 16)).round().astype(int))]
    scale = float(mech.length_scale(p))
    if tol is None:  # what "the same position" means: rounding of the dtype the positions came in
        tol = max(1e-7, 1000 * float(jnp.finfo(jnp.asarray(q).dtype).eps)) * scale
    known = _Known(sample, tol)
    known.add(np.zeros((n_rows, 2)), "the origin")
    chains = []
    for (name, _), (vec, _) in zip(mech.points, point_vec):
        ch = _partial_sums(vec)
        chains.append(ch)
        for i in range(1, ch.shape[1]):
            known.add(ch[:, i], f"vertex {i} of the chain of point {name}")
    file_joints = []
    if mech.bodies is not None:
        for jt, (vec, _) in zip(mech.bodies.joints, joint_vec):
            pos = vec.sum(axis=1)
            file_joints.append((jt, pos))
            known.add(pos, f"joint {jt.name}")

    # relative vertices of each loop: vertex j = start of term j
    rel = [_partial_sums(vec)[:, :-1] for vec, _ in loop_vec]
    inputs = [_input_vertex(mech, terms) for _, terms in mech.loops]
    is_joint = [np.array([_ends_link(kd, j) for j in range(len(kd))]) for kd in kinds]
    order, placed, shifts, how, own = [], {}, {}, {}, {}
    pending = list(range(len(mech.loops)))
    while pending:
        cand = []
        for c in pending:
            sc = _place(rel[c], is_joint[c], inputs[c], mech.loops[c][1], known, sample, tol, ())
            cand.append((sc[0], -c, c, sc))
        cand.sort(reverse=True)
        _, _, c, (score, shift, text) = cand[0]
        pending.remove(c)
        placed[c], shifts[c], how[c] = score, shift, text
        own[c] = list(range(len(known.arrays), len(known.arrays) + rel[c].shape[1]))
        for j in range(rel[c].shape[1]):
            known.add(shift + rel[c][:, j], f"vertex {j} of loop {mech.loops[c][0]}")
        order.append(c)
    # a second pass: each loop against every other placed loop (a better anchor may come later)
    for c in order:
        sc = _place(rel[c], is_joint[c], inputs[c], mech.loops[c][1], known, sample, tol, set(own[c]))
        if sc[0][:4] > placed[c][:4]:
            placed[c], shifts[c], how[c] = sc
            for j, idx in enumerate(own[c]):
                known.arrays[idx] = sc[1] + rel[c][:, j]

    hide = ~shown
    loops = []
    for c in range(len(mech.loops)):
        v = shifts[c][:, None, :] + rel[c]
        v[hide] = np.nan
        loops.append(v)

    # joints: loop vertices at the end of a link, merged across loops
    joints: list = []
    for c, v in enumerate(loops):
        for j in range(v.shape[1]):
            if is_joint[c][j] and not any(_close(other, v[:, j], sample, tol) for other in joints):
                joints.append(v[:, j])
    J = np.stack(joints, axis=1) if joints else np.zeros((n_rows, 0, 2))
    ground = _fixed(J, sample, tol) if joints else np.zeros(0, bool)
    names = _joint_names(J, ground, file_joints, chains, mech.point_names, sample, tol)

    # sliders
    sliders: list = []
    for c, (vec, axis) in enumerate(loop_vec):
        for j, kind in enumerate(kinds[c]):
            if kind != "slider":
                continue
            start, end = loops[c][:, j], loops[c][:, (j + 1) % loops[c].shape[1]]
            for ch, (pvec, _) in zip(chains, point_vec):
                for i in range(pvec.shape[1]):
                    for sgn in (1.0, -1.0):
                        if _close(pvec[:, i], sgn * vec[:, j], sample, tol):
                            start, end = ch[:, i], ch[:, i + 1]
            s = _slider(start, end, axis[:, j], J, shown, sample, tol, mech.loops[c][1][j].text.strip())
            if not any(_close(s.block, o.block, sample, tol) and
                       np.allclose(np.abs(np.sum(s.axis[sample] * o.axis[sample], -1)), 1) for o in sliders):
                sliders.append(s)

    # point arms: from the last vertex of the chain that is a joint
    arms = []
    for ch in chains:
        last = 0
        for i in range(ch.shape[1]):
            if any(_close(ch[:, i], J[:, k], sample, tol) for k in range(J.shape[1])):
                last = i
        arm = ch[:, last:].copy()
        arm[hide] = np.nan
        arms.append(arm)
    pts = np.stack([ch[:, -1] for ch in chains], axis=1) if chains else np.zeros((n_rows, 0, 2))
    pts = pts.copy()
    pts[hide] = np.nan
    J = J.copy()
    J[hide] = np.nan
    allxy = np.concatenate([v[shown].reshape(-1, 2) for v in loops] + [pts[shown].reshape(-1, 2)])
    extent = float(np.ptp(allxy, axis=0).max()) if allxy.size else scale
    return LinkageDrawing(loops, kinds, labels, [how[c] for c in range(len(mech.loops))], J, names, ground,
                          sliders, arms, pts, tuple(mech.point_names), shown, extent or scale)


def _ends_link(kinds, j) -> bool:
    """Whether vertex j of a loop (between terms j − 1 and j) is a joint: a link ends there."""
    return "link" in (kinds[j - 1], kinds[j])


def _close(a, b, sample, tol) -> bool:
    return bool(np.nanmax(np.linalg.norm(a[sample] - b[sample], axis=-1)) < tol)


def _joint_names(J, ground, file_joints, chains, point_names, sample, tol) -> list:
    names, n_ground, n_moving = [], 0, 0
    for k in range(J.shape[1]):
        found = [jt.name for jt, pos in file_joints if jt.kind == "revolute" and _close(pos, J[:, k], sample, tol)]
        if not found:
            found = [n for n, ch in zip(point_names, chains) if _close(ch[:, -1], J[:, k], sample, tol)]
        if found:
            names.append("/".join(found))
        elif ground[k]:
            n_ground += 1
            names.append(f"O{n_ground}")
        else:
            n_moving += 1
            names.append(f"J{n_moving}")
    return names


def _slider(start, end, axis, J, shown, sample, tol, text) -> Slider:
    """The block on the end of the vector start→end that is a joint (else the end that moves,
    else `end`), the guide along `axis` through the other end over the block's travel."""

    def is_joint(x):
        return any(_close(x, J[:, k], sample, tol) for k in range(J.shape[1]))

    moves_s, moves_e = not _fixed(start[:, None], sample, tol)[0], not _fixed(end[:, None], sample, tol)[0]
    if is_joint(end) and (not is_joint(start) or moves_e or not moves_s):
        block, foot = end, start
    elif is_joint(start):
        block, foot = start, end
    else:
        block, foot = (start, end) if moves_s and not moves_e else (end, start)
    u = axis / np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-300)
    t = np.sum((block - foot) * u, axis=-1)
    guide = np.full(block.shape[:1] + (2, 2), np.nan)
    ok = shown
    if ok.any():
        fixed_guide = _fixed(foot[:, None], sample, tol)[0] and _fixed(u[:, None], sample, 1e-9)[0]
        span = max(float(np.ptp(t[ok])), 1e-12)
        if fixed_guide:
            lo, hi = float(t[ok].min()), float(t[ok].max())
            margin = 0.25 * span + 0.02 * max(abs(lo), abs(hi))
            guide[ok, 0] = foot[ok] + (lo - margin) * u[ok]
            guide[ok, 1] = foot[ok] + (hi + margin) * u[ok]
        else:  # a guide that moves (rotates about its foot): from the foot past the block
            margin = 0.15 * float(np.abs(t[ok]).max())
            guide[ok, 0] = foot[ok] + np.minimum(0.0, t[ok] - margin)[:, None] * u[ok]
            guide[ok, 1] = foot[ok] + np.maximum(0.0, t[ok] + margin)[:, None] * u[ok]
    block = block.copy()
    block[~shown] = np.nan
    return Slider(block, u, guide, text)
