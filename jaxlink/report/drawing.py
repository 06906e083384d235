"""Where a drawing of the linkage puts every joint, body and vector: the geometry of the plots,
animations and the geometry export.

**A sketch file** (`mech.sketch`, a `jaxlink.files.sketch.Layout`) is drawn from its joints and
links, at the positions `mech.joint_positions` gives: a pin at every real joint (a joint of two or
more bodies, a frame joint, a slider's joint, an actuator's end; the frame's are ground pivots); a
joint on one body only is a mark (a point of that body, no pin); each body a `Body` (a bar, or a
plate outlined by its joints' convex hull when three or more are not on one line); each slider a
block on its guide, the line fixed to its body through the slider's joint, the direction of the
loop vector whose length is `s_<joint>` (on the frame fixed, on a link turning with it); the crank
or actuator the `Drive`. The derived loops are not drawn.

**A loop file** is drawn from its loops. A loop of the file, `Σ_j t_j = 0`, is a closed polygon
whose vertices V_j = T + Σ_{i<j} t_i (vertex j is where term j starts) are the joints of its links;
the loop fixes them only up to the translation T. The points of `[points]` are sums from the frame
origin, so the vertices of their chains (the origin, then each partial sum) are absolute positions,
and so are the joints of `[joints]` (their `at` sums). Each loop is placed by the translation that
puts the most of its vertices on such known positions at every sampled position — moving vertices
counting first, then fixed ones; a loop placed this way adds its vertices to the known positions of
the loops placed after it. The frame origin is always a known position: a loop that touches nothing
else is placed with the start of its input vector (the crank) there, else with its first vertex
there. So a loop may be written starting at any vertex and in either direction and is drawn in the
same place.

What is drawn (metres, per position):

- each term of a loop by its kind: `link` (constant length, moving: a rigid bar), `frame`
  (constant vector: dashed), `slider` (variable length: drawn as a block on its guide line), or
  `variable` (a Cartesian vector with moving components: a thin line);
- joints: the revolute joints of `[joints]` where the file has them (in its order, with its names;
  a joint of the ground is a ground pivot; joints at one place are one pin, `A/B`), then the loop
  vertices that are joints, merged across loops: where a link ends on another body, a frame vector
  or a slider. Two link vectors of one body (the same moving names in their angles: a coupler
  point's offsets) meet at a joint only where that vertex does not move (the body's frame pivot),
  and so does the foot of a slider vector whose angle moves (an oscillating cylinder's trunnion);
  a vertex joint that does not move is a ground pivot. Its name: a `[points]` point at the same
  place, else generated (`O1`, `O2`, … for ground pivots, `J1`, … for others);
- plates: the bodies of `[bodies]` with three or more revolute `[joints]` not on one line;
- the drive: the link vector whose angle is the input, about its end that does not move;
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
class Body:
    """A rigid body as a designer draws it: `name` (the file's link or body name), `joints` the
    names of its joints and points (file order), `outline` (N, m, 2) the polygon drawn: a bar's two
    ends, or a plate's convex hull (counter-clockwise, closed by the drawing); `plate`: whether it is
    drawn as a shaded plate (three or more joints not on one line)."""

    name: str
    joints: tuple
    outline: np.ndarray
    plate: bool


@dataclasses.dataclass
class Drive:
    """The input, marked on the drawing: `kind` "crank" (`ends` (N, 2, 2): its frame pivot, then its
    other joint) or "actuator" (its two joints); `name` the crank's link (or the input's name);
    `sense` +1 when the input grows over the table (counter-clockwise for a crank), −1 otherwise."""

    kind: str
    name: str
    ends: np.ndarray
    sense: float


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
    - `bodies`: list of `Body` — the links and plates of a sketch file; for a loop file with
      `[joints]` tables, the bodies with three or more of them (plates; its bars are loop terms).
    - `marks` (N, K, 2), `mark_names`: the joints of a sketch file on one body only (a point of that
      body, drawn as a point, not as a pin).
    - `drive`: the input (`Drive`), or None when it cannot be told.
    - `source`: "sketch" (drawn from the file's joints and links: `loops` is empty) or "loops".
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
    bodies: list = dataclasses.field(default_factory=list)
    marks: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0, 2)))
    mark_names: tuple = ()
    drive: Drive | None = None
    source: str = "loops"

    def describe(self) -> dict:
        """What the drawing shows, by name: `joints` (pins), `ground` (the joints with a ground
        symbol), `points` (the reported points), `marks` (points of one body), `bars` and `plates`
        (body names; `plates` maps each to its joints), `sliders` (the vector texts, or the slider
        joints of a sketch), `drive` (kind, name) or None."""
        return {
            "joints": list(self.joint_names),
            "ground": [n for n, g in zip(self.joint_names, self.ground) if g],
            "points": list(self.point_names),
            "marks": list(self.mark_names),
            "bars": [b.name for b in self.bodies if not b.plate],
            "plates": {b.name: list(b.joints) for b in self.bodies if b.plate},
            "sliders": [s.term for s in self.sliders],
            "drive": None if self.drive is None else (self.drive.kind, self.drive.name),
        }


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
        if mech.sketch is not None:  # the sketch's joints: their own vector sums
            out.append((mech.joint_positions(qk, phik, p), jnp.zeros((0, 2), qk.dtype)))
        return out

    q = jnp.asarray(q)
    res = jax.jit(jax.vmap(one))(q, jnp.asarray(phis, dtype=q.dtype))
    res = [(np.asarray(v, dtype=float), np.asarray(a, dtype=float)) for v, a in res]
    nl, npt, nj = len(mech.loops), len(mech.points), len(joints)
    sketch = res[nl + npt + nj][0] if mech.sketch is not None else None
    return res[:nl], res[nl:nl + npt], res[nl + npt:nl + npt + nj], sketch


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
    sketch = mech.sketch is not None
    kinds = [] if sketch else [[term_kind(mech, t) for t in terms] for _, terms in mech.loops]
    labels = [] if sketch else [[_length_text(t) for t in terms] for _, terms in mech.loops]
    if not shown.any():  # nothing assembled: nothing to draw
        nan = np.full((n_rows, 1, 2), np.nan)
        loops = [] if sketch else [np.full((n_rows, len(t), 2), np.nan) for _, t in mech.loops]
        return LinkageDrawing(loops, kinds, labels, ["not placed: no position assembled"] * len(loops),
                              np.zeros((n_rows, 0, 2)), [], np.zeros(0, bool), [], [nan for _ in mech.points],
                              np.full((n_rows, len(mech.points), 2), np.nan), tuple(mech.point_names), shown,
                              float(mech.length_scale(p)), source="sketch" if sketch else "loops")
    loop_vec, point_vec, joint_vec, sketch_xy = _vectors(mech, q, phis, p)
    rows = np.flatnonzero(shown)
    sample = rows[np.unique(np.linspace(0, len(rows) - 1, min(len(rows), 16)).round().astype(int))]
    scale = float(mech.length_scale(p))
    if tol is None:  # what "the same position" means: rounding of the dtype the positions came in
        tol = max(1e-7, 1000 * float(jnp.finfo(jnp.asarray(q).dtype).eps)) * scale
    hide = ~shown
    chains = [_partial_sums(vec) for vec, _ in point_vec]
    pts = np.stack([ch[:, -1] for ch in chains], axis=1) if chains else np.zeros((n_rows, 0, 2))
    pts = pts.copy()
    pts[hide] = np.nan
    sense = float(np.sign(phis[-1] - phis[0])) if len(phis) > 1 and phis[-1] != phis[0] else 1.0
    if sketch:
        return _sketch_drawing(mech, sketch_xy, loop_vec, chains, pts, shown, sample, tol, scale, sense)

    known = _Known(sample, tol)
    known.add(np.zeros((n_rows, 2)), "the origin")
    for (name, _), ch in zip(mech.points, chains):
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

    loops = []
    for c in range(len(mech.loops)):
        v = shifts[c][:, None, :] + rel[c]
        v[hide] = np.nan
        loops.append(v)

    # joints: the file's [joints] where it has them, then the loop vertices that are joints
    # (`_vertex_role`), merged across loops
    joints: list = []
    ground_of: list = []
    file_names: list = []
    for jt, pos in file_joints:
        if jt.kind != "revolute":
            continue
        same = [k for k, other in enumerate(joints) if _close(other, pos, sample, tol)]
        if same:  # revolute joints at one place: one pin, its names joined
            file_names[same[0]] += f"/{jt.name}"
            ground_of[same[0]] = ground_of[same[0]] or -1 in (jt.a, jt.b)
            continue
        joints.append(pos)
        ground_of.append(-1 in (jt.a, jt.b))
        file_names.append(jt.name)
    roles = [[_vertex_role(mech, terms, kd, j) for j in range(len(kd))] for (_, terms), kd in zip(mech.loops, kinds)]
    for c, v in enumerate(loops):
        for j in range(v.shape[1]):
            role = roles[c][j]
            if role is None or any(_close(other, v[:, j], sample, tol) for other in joints):
                continue
            still = bool(_fixed(v[:, j][:, None], sample, tol)[0])
            if role == "joint" or still:  # one body's vectors, a turning guide: a joint where it is a pivot
                joints.append(v[:, j])
                ground_of.append(None)
    J = np.stack(joints, axis=1) if joints else np.zeros((n_rows, 0, 2))
    fixed = _fixed(J, sample, tol) if joints else np.zeros(0, bool)
    ground = np.array([bool(f) if g is None else g for g, f in zip(ground_of, fixed)], dtype=bool)
    names = file_names + _joint_names(J[:, len(file_names):], ground[len(file_names):], file_joints, chains,
                                      mech.point_names, sample, tol)

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
    J = J.copy()
    J[hide] = np.nan
    allxy = np.concatenate([v[shown].reshape(-1, 2) for v in loops] + [pts[shown].reshape(-1, 2)])
    extent = float(np.ptp(allxy, axis=0).max()) if allxy.size else scale
    bodies = _file_plates(mech, file_joints, J, names, shown, sample, tol)
    drive = _loop_drive(mech, loops, kinds, sample, tol, sense)
    return LinkageDrawing(loops, kinds, labels, [how[c] for c in range(len(mech.loops))], J, names, ground,
                          sliders, arms, pts, tuple(mech.point_names), shown, extent or scale, bodies,
                          np.zeros((n_rows, 0, 2)), (), drive, "loops")


def _vertex_role(mech, terms, kinds, j) -> str | None:
    """Whether vertex j of a loop (between terms j − 1 and j) is a joint: "joint" where a link ends
    on another body, a frame vector or a slider; "pivot" where it is a joint only if it does not
    move: two link vectors of one body (the same moving names in their angles: a coupler point's
    offsets meet there, unless it is the body's frame pivot), or the foot of a guide that turns (a
    slider vector whose angle moves: an oscillating cylinder's trunnion); None otherwise."""
    a, b = kinds[j - 1], kinds[j]
    if "link" in (a, b):
        if a == b == "link" and _angle_names(mech, terms[j - 1]) == _angle_names(mech, terms[j]):
            return "pivot"
        return "joint"
    if any(k == "slider" and _angle_names(mech, t) for k, t in ((a, terms[j - 1]), (b, terms[j]))):
        return "pivot"
    return None


def _angle_names(mech, term) -> frozenset:
    """The moving names (unknowns, the input) in a polar term's angle: the body it is fixed to."""
    if not term.polar:
        return frozenset()
    moving = set(mech.unknown_names) | {mech.input_name}
    return frozenset(n.name for n in _expr.names_in(term.angle) if n.name in moving)


def _file_plates(mech, file_joints, J, names, shown, sample, tol) -> list:
    """The bodies of a loop file's `[joints]` tables that hold three or more revolute joints, as plates
    (their bars are the loops' link vectors)."""
    if mech.bodies is None:
        return []
    out = []
    for b, body in enumerate(mech.bodies.bodies):
        mine = [jt.name for jt, _ in file_joints if jt.kind == "revolute" and b in (jt.a, jt.b)]
        idx = [names.index(n) for n in mine if n in names]
        if len(idx) >= 3:
            body_drawing = _body(body.name, tuple(mine), J[:, idx], shown, tol)
            if body_drawing.plate:
                out.append(body_drawing)
    return out


def _loop_drive(mech, loops, kinds, sample, tol, sense) -> Drive | None:
    """The crank of a loop file: the link vector whose angle is the input, turning about its end
    that does not move (None for a length input or when no such vector has a fixed end)."""
    if mech.input_kind != "angle":
        return None
    for (_, terms), kd, v in zip(mech.loops, kinds, loops):
        for j, term in enumerate(terms):
            if kd[j] != "link" or mech.input_name not in _angle_names(mech, term):
                continue
            a, b = v[:, j], v[:, (j + 1) % v.shape[1]]
            for pivot, tip in ((a, b), (b, a)):
                if _fixed(pivot[:, None], sample, tol)[0]:
                    return Drive("crank", mech.input_name, np.stack([pivot, tip], axis=1), sense)
    return None


def _hull(xy, tol) -> list:
    """Indices of the convex hull of points `xy` (m, 2), counter-clockwise (Andrew's monotone chain);
    points on an edge are left out."""
    order = sorted(range(len(xy)), key=lambda i: (xy[i][0], xy[i][1]))

    def cross(o, a, b):
        return (xy[a][0] - xy[o][0]) * (xy[b][1] - xy[o][1]) - (xy[a][1] - xy[o][1]) * (xy[b][0] - xy[o][0])

    def half(seq):
        out: list = []
        for i in seq:
            while len(out) >= 2 and cross(out[-2], out[-1], i) <= tol:
                out.pop()
            out.append(i)
        return out

    lower, upper = half(order), half(order[::-1])
    return lower[:-1] + upper[:-1]


def _body(name, joints, xy, shown, tol) -> Body:
    """A body through the positions `xy` (N, m, 2) of its joints: a plate outlined by their convex
    hull (found at the first shown position: a rigid body keeps it), or a bar between its two
    farthest joints when they lie on one line."""
    k0 = int(np.flatnonzero(shown)[0])
    pose = xy[k0]
    if len(joints) >= 3:
        size = max(float(np.ptp(pose, axis=0).max()), 1e-300)
        hull = _hull(pose, tol * size)
        if len(hull) >= 3:
            return Body(name, tuple(joints), xy[:, hull], True)
    d = np.linalg.norm(pose[:, None] - pose[None], axis=-1)
    i, k = np.unravel_index(int(np.argmax(d)), d.shape)
    return Body(name, tuple(joints), xy[:, [i, k]], False)


def _sketch_drawing(mech, xy, loop_vec, chains, pts, shown, sample, tol, scale, sense) -> LinkageDrawing:
    """The drawing of a sketch file, from its layout (`jaxlink.files.sketch.Layout`): joints where
    two or more bodies meet, the frame's joints (ground pivots), the sliders' joints and the
    actuator's ends; a joint on one body only is a mark (a point of that body); links as bars,
    plates as polygons; each slider's block on its guide (the frame's fixed, a body's slot moving
    with it); the crank or actuator as the drive. `xy` (N, J, 2): the positions of every joint."""
    lay = mech.sketch
    n_rows = xy.shape[0]
    hide = ~shown
    xy = xy.copy()
    xy[hide] = np.nan
    names = [n for n, _ in lay.joints]
    index = {n: i for i, n in enumerate(names)}
    frame = set(lay.frame)
    on_bodies = {n: sum(n in js for _, js in lay.bodies) for n in names}
    slid = {j for j, _ in lay.sliders}
    ends = tuple(lay.input[1]) if lay.input[0] == "actuator" else ()
    real = [n for n in names if n in frame or on_bodies[n] >= 2 or n in slid or n in ends]
    marks = [n for n in names if n not in real]
    J = xy[:, [index[n] for n in real]].reshape(n_rows, len(real), 2)
    M = xy[:, [index[n] for n in marks]].reshape(n_rows, len(marks), 2)
    ground = np.array([n in frame for n in real], dtype=bool)
    bodies = [_body(b, js, xy[:, [index[j] for j in js]], shown, tol) for b, js in lay.bodies]
    allxy = np.concatenate([xy[shown].reshape(-1, 2), pts[shown].reshape(-1, 2)])
    allxy = allxy[np.isfinite(allxy).all(axis=1)]
    extent = (float(np.ptp(allxy, axis=0).max()) if allxy.size else scale) or scale

    sliders = []
    body_joints = {FRAME_BODY: tuple(lay.frame), **dict(lay.bodies)}
    for j, on in lay.sliders:
        axis = _slider_axis(mech, loop_vec, f"s_{j}")
        if axis is None:
            continue
        sliders.append(_slot(xy[:, index[j]], axis, [xy[:, index[k]] for k in body_joints[on]], shown, sample, tol,
                             extent, j))
    drive = None
    if lay.input[0] == "crank":
        js = dict(lay.bodies)[lay.input[1]]
        drive = Drive("crank", lay.input[1], xy[:, [index[js[0]], index[js[1]]]], sense)
    elif lay.input[0] in ("link", "slider"):  # a floating link's angle, a slider's position: no motor drawn
        drive = None
    else:
        drive = Drive("actuator", mech.input_name, xy[:, [index[ends[0]], index[ends[1]]]], sense)
    arms = []
    for ch in chains:  # a reported point that is no joint of the sketch hangs from nothing: no arm
        arm = ch[:, -1:].copy()
        arm[hide] = np.nan
        arms.append(arm)
    return LinkageDrawing([], [], [], [], J, real, ground, sliders, arms, pts, tuple(mech.point_names), shown,
                          extent, bodies, M, tuple(marks), drive, "sketch")


FRAME_BODY = "frame"


def _slider_axis(mech, loop_vec, unknown: str):
    """The unit vector (N, 2) of the line of the slider whose position is `unknown`: the angle of the
    loop vector whose length it is."""
    for (_, terms), (_, axis) in zip(mech.loops, loop_vec):
        for j, term in enumerate(terms):
            if term.polar and any(n.name == unknown for n in _expr.names_in(term.length)):
                return axis[:, j]
    return None


def _slot(block, axis, body_xy, shown, sample, tol, extent, name) -> Slider:
    """A slider of a sketch: its block at `block` (N, 2), its guide on the line along `axis` through
    it, fixed to the body whose joints are at `body_xy` (list of (N, 2)). The guide covers the block's
    travel along the line (in the body: the line moves with it) and the body's joint on the line, if
    one is (a slot through the lever's pivot, a cylinder from its trunnion)."""
    u = axis / np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-300)
    normal = np.stack([-u[:, 1], u[:, 0]], axis=-1)
    ref, on_line = body_xy[0], False
    for r in body_xy:
        off = np.sum((r - block) * normal, axis=-1)
        if float(np.nanmax(np.abs(off[sample]))) < tol:
            ref, on_line = r, True
            break
    t = np.sum((block - ref) * u, axis=-1)  # the block's place on the line, from the foot of `ref`
    foot = block - t[:, None] * u
    ok = shown & np.isfinite(t)
    lo, hi = float(t[ok].min()), float(t[ok].max())
    if on_line:
        lo, hi = min(lo, 0.0), max(hi, 0.0)
    margin = 0.1 * (hi - lo) + 0.08 * extent
    guide = np.full(block.shape[:1] + (2, 2), np.nan)
    guide[ok, 0] = foot[ok] + (lo - margin) * u[ok]
    guide[ok, 1] = foot[ok] + (hi + margin) * u[ok]
    block = block.copy()
    block[~shown] = np.nan
    return Slider(block, u, guide, name)


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
