"""One-degree-of-freedom revolute linkages grown by dyads.

A topology places its joints in order: frame joints `F0, F1, F2` (indices 0–2; F0 is the crank's
pivot), the crank joint `C` (index 3) turning about F0, then each further joint attached to two
earlier joints by two lengths and a branch sign (a dyad: circle–circle intersection). A dyad whose
two parents lie on one rigid body adds a point of that body (a ternary link, a coupler point); on
two different bodies it adds two binary links. So the four-bar with its coupler point, the Watt and
Stephenson six-bars and, growing further, eight-bars are all such lists (`grow`). The traced point
is any moving joint. A dyad may end at a joint other links already use (a frame pivot, the crank
pin): that pin then joins three links.

A dyad may instead be a **slider** (RRP, `slide`): its joint is attached to its first parent by a
link and moves on a line fixed to the frame, the line through its second parent — a frame joint no
other dyad uses, only the guide's anchor — and the joint's own position in the pose. The four-bar's
rocker so becomes the slider-crank's slider; `topologies(sliders=True)` adds every built-in's
variants with one or more of its eligible dyads (`slidable`) sliding.

A dyad may also be a **slotted lever** (RPR, `lever`): a lever turning about a frame joint (its
first parent) through whose slot the block pinned at its second parent (a moving joint) slides, the
slot on the line through the pivot (the Whitworth quick return, the crank-shaper, the oscillating
cylinder); the dyad's joint is a point of the lever. The lever's angle is that of the line from its
pivot to the block's pin, so it has no toggle: it fails only where the pin passes over the pivot.
`topologies(levers=True)` adds every built-in's variants with one of its eligible dyads
(`leverable`) a slotted lever.

The topologies of one search are padded to the same number of dyads so that all of them share one
batched program (`as_arrays`): padding dyads are inactive.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

N_FRAME = 3
CRANK = 3
#: the most dyads of a searched topology: 4 + 16 = 20 joints at most (LInK's largest)
MAX_DYADS = 16
MAX_JOINTS = CRANK + 1 + MAX_DYADS
FRAME_BODY = -1
#: added to a slider dyad's second parent in `as_arrays` (more than any joint index): the kind travels
#: with the parents, one array for every program
SLIDER = 32
#: added to the second parent of a dyad that is a point of a rigid body (`rigid`) in `as_arrays`
RIGID = 64
#: added to the second parent of a slotted-lever dyad (`lever`) in `as_arrays` (decoded first: the largest)
LEVER = 128


class Topology(NamedTuple):
    """A dyadic linkage. `dyads[k] = (p1, p2)`: joint `CRANK + 1 + k` is attached to joints p1 and
    p2; `traced`: the joint whose path is matched; `sliders`: the dyads (indices k) whose joint is
    attached to p1 only and slides on the frame's line through the frame joint p2 and its own pose
    position (`slide`); `levers`: the dyads whose joint is a point of a lever turning about the frame
    joint p1, through whose slot the block pinned at p2 slides (`lever`)."""

    name: str
    dyads: tuple[tuple[int, int], ...]
    traced: int
    sliders: tuple[int, ...] = ()
    levers: tuple[int, ...] = ()

    @property
    def n_joints(self) -> int:
        """Joints of the linkage (the frame joints it uses included, a guide's anchor not)."""
        return len(self.used_frame()) + 1 + len(self.dyads)

    @property
    def n_links(self) -> int:
        """Links, the frame and each slider's and slotted lever's block included."""
        return 1 + len(bodies(self)) + len(self.sliders) + len(self.levers)

    def used_frame(self) -> list[int]:
        """The frame joints that are joints of the linkage (F0 and every pivot of a dyad's link)."""
        return sorted({0} | {p for k, d in enumerate(self.dyads) for i, p in enumerate(d)
                             if p < N_FRAME and not (i == 1 and k in self.sliders)})


def grow(topo: Topology, p1: int, p2: int, *, name: str | None = None, trace: bool = True) -> Topology:
    """The topology with one more joint attached to joints p1 and p2 (traced when `trace`)."""
    j = CRANK + 1 + len(topo.dyads)
    if not (0 <= p1 < j and 0 <= p2 < j) or p1 == p2:
        raise ValueError(f"a dyad attaches to two different earlier joints, got {p1}, {p2}")
    if p1 < N_FRAME and p2 < N_FRAME:
        raise ValueError("a dyad on two frame joints does not move")
    return Topology(name or topo.name, topo.dyads + ((p1, p2),), j if trace else topo.traced, topo.sliders,
                    topo.levers)


def _rockers(topo: Topology) -> list[tuple[int, int]]:
    """(dyad k, its frame joint) of every dyad that is a rocker: neither a slider nor a lever yet, on
    one frame joint other than the crank's pivot and a moving joint of another body (not a point of a
    body already holding both) — what `slidable` and `leverable` may replace."""
    out = []
    for k, (p1, p2) in enumerate(topo.dyads):
        if k in topo.sliders or k in topo.levers or (p1 < N_FRAME) == (p2 < N_FRAME):
            continue
        f, other = (p1, p2) if p1 < N_FRAME else (p2, p1)
        if f == 0 or any(f in b and other in b for b in bodies(_prefix(topo, k))):
            continue
        out.append((k, f))
    return out


def slidable(topo: Topology) -> list[int]:
    """The dyads that may become sliders (`slide`): rockers (`_rockers`) whose frame joint no other
    dyad uses."""
    return [k for k, f in _rockers(topo) if not any(f in d for i, d in enumerate(topo.dyads) if i != k)]


def slide(topo: Topology, k: int, *, name: str | None = None) -> Topology:
    """The topology with dyad `k` a slider (`slidable`): its joint J, attached to the dyad's moving
    parent by a link, moves on the frame's line through the dyad's frame joint (the guide's anchor)
    and J's pose position; the frame joint is stored second. Named `NAME+slider-J<j>` by default
    (the four-bar's: `slider-crank`)."""
    if k not in slidable(topo):
        raise ValueError(f"{topo.name}: dyad {k} cannot become a slider (`slidable`: {slidable(topo)})")
    dyads = _frame_joint(topo, k, first=False)
    j = CRANK + 1 + k
    if name is None:
        name = "slider-crank" if topo.name == "four-bar" else f"{topo.name}+slider-J{j}"
    return Topology(name, dyads, topo.traced, tuple(sorted(topo.sliders + (k,))), topo.levers)


def _frame_joint(topo: Topology, k: int, *, first: bool) -> tuple[tuple[int, int], ...]:
    """`topo.dyads` with dyad `k`'s frame joint stored first (a lever's pivot) or second (a slider's
    guide anchor)."""
    p1, p2 = topo.dyads[k]
    if (p1 < N_FRAME) != first:
        p1, p2 = p2, p1
    return topo.dyads[:k] + ((p1, p2),) + topo.dyads[k + 1:]


def _prefix(topo: Topology, k: int) -> Topology:
    """The topology of the dyads before dyad `k`."""
    return Topology(topo.name, topo.dyads[:k], topo.traced, tuple(i for i in topo.sliders if i < k),
                    tuple(i for i in topo.levers if i < k))


def leverable(topo: Topology) -> list[int]:
    """The dyads that may become slotted levers (`lever`): the rockers (`_rockers`)."""
    return [k for k, _ in _rockers(topo)]


def lever(topo: Topology, k: int, *, name: str | None = None) -> Topology:
    """The topology with dyad `k` a slotted lever (`leverable`): its joint J a point of a lever turning
    about the dyad's frame joint, through whose slot (on the line through the pivot) the block pinned
    at the dyad's moving parent slides; the pivot stored first. Named `NAME+lever-J<j>` by default."""
    if k not in leverable(topo):
        raise ValueError(f"{topo.name}: dyad {k} cannot become a slotted lever (`leverable`: {leverable(topo)})")
    return Topology(name or f"{topo.name}+lever-J{CRANK + 1 + k}", _frame_joint(topo, k, first=True), topo.traced,
                    topo.sliders, tuple(sorted(topo.levers + (k,))))


def with_levers(topo: Topology) -> list[Topology]:
    """`topo`'s variants with one of its `leverable` dyads a slotted lever."""
    return [lever(topo, k) for k in leverable(topo)]


def _walk(topo: Topology) -> tuple[list[tuple[int, ...]], list[bool]]:
    """(`bodies`, `rigid`): the bodies grown dyad by dyad, and which dyads added a point of one."""
    out: list[list[int]] = [[0, CRANK]]
    flags = []
    frame = set(range(N_FRAME))
    for k, (p1, p2) in enumerate(topo.dyads):
        j = CRANK + 1 + k
        if k in topo.sliders or k in topo.levers:
            # a slider: the link to it (its block no body of joints); a slotted lever: the lever, its
            # pivot and J (the block pinned at p2 no body of joints)
            out.append([p1, j])
            flags.append(False)
            continue
        home = [b for b in out if p1 in b and p2 in b]
        flags.append(bool(home))
        if home:
            home[0].append(j)
        elif p1 in frame and p2 in frame:  # pragma: no cover - refused by grow
            raise ValueError("a dyad on two frame joints")
        else:
            out.append([p1, j])
            out.append([p2, j])
    return [tuple(b) for b in out], flags


def bodies(topo: Topology) -> list[tuple[int, ...]]:
    """The moving rigid bodies, each a tuple of joints (its first joint its reference; the crank
    first): a dyad on two joints of one body adds a point of it, else two binary links."""
    return _walk(topo)[0]


def rigid(topo: Topology) -> list[bool]:
    """Per dyad: whether it is a point of a rigid body (its two parents on one body, `bodies`): its
    triangle never changes, so its reach margin is a constant of the design, not a limit of the
    motion — a point on the line of a link (margin 0: the feed dog on its carrier's line) is as
    good as any (`tracer`)."""
    return _walk(topo)[1]


def _four_bar() -> Topology:
    t = Topology("four-bar", (), CRANK)
    t = grow(t, CRANK, 1, trace=False)  # B: the coupler on the rocker F1–B   (joint 4)
    return grow(t, CRANK, 4)            # P: the coupler point on C–B          (joint 5)


def _six_bar(name: str, x1: str, x2: str) -> Topology:
    """The four-bar and a dyad D between a point X1 of one body and a point X2 of another, traced at a
    point E on the link X1–D. Points: the coupler's P, a new point of the crank (on F0–C) or of the
    rocker (on F1–B), the frame's F2."""
    t = _four_bar()
    t = Topology(name, t.dyads, t.traced)
    at = {}
    for body in (x1, x2):
        if body == "coupler":
            at[body] = 5
        elif body == "frame":
            at[body] = 2
        elif body == "crank":
            t = grow(t, 0, CRANK, trace=False)
            at[body] = CRANK + len(t.dyads)
        elif body == "rocker":
            t = grow(t, 1, 4, trace=False)
            at[body] = CRANK + len(t.dyads)
    t = grow(t, at[x1], at[x2], trace=False)
    d = CRANK + len(t.dyads)
    return grow(t, at[x1], d)


#: the six-bars of `topologies`: (name, the body of X1, the body of X2)
SIX_BARS = (("watt-coupler-crank", "coupler", "crank"), ("watt-coupler-rocker", "coupler", "rocker"),
            ("watt-rocker-frame", "rocker", "frame"), ("watt-crank-frame", "crank", "frame"),
            ("stephenson-coupler-frame", "coupler", "frame"), ("stephenson-rocker-crank", "rocker", "crank"))
#: the eight-bars of `topologies`: the six-bars they grow from, and the joints their last dyad ends at
EIGHT_FROM = ("watt-coupler-crank", "watt-coupler-rocker", "stephenson-coupler-frame")
EIGHT_AT = {"crank-pivot": 0, "rocker-pivot": 1, "crank-pin": CRANK}


def _eight_bar(six: Topology, at: str) -> Topology:
    """The six-bar and one more dyad D' between its traced point E (a point of its last link) and the
    joint `at` (`EIGHT_AT`: the frame pivot of the crank or of the rocker, or the crank pin), traced
    at a point of the new link E–D': eight links. Grown from an eight-bar the same way: a ten-bar."""
    nj = CRANK + 1 + len(six.dyads)
    t = grow(six, six.traced, EIGHT_AT[at], name=f"{six.name}+{at}", trace=False)
    return grow(t, six.traced, nj)


def _grown(t: Topology) -> list[Topology]:
    """`_eight_bar` of `t` at each joint of `EIGHT_AT` not already on its traced link."""
    on_traced = {j for b in bodies(t) if t.traced in b for j in b}
    return [_eight_bar(t, at) for at, j in EIGHT_AT.items() if j not in on_traced]


def with_sliders(topo: Topology) -> list[Topology]:
    """`topo`'s variants with one or more of its `slidable` dyads sliders, fewest sliders first."""
    from itertools import combinations

    ks = slidable(topo)
    out = []
    for n in range(1, len(ks) + 1):
        for sub in combinations(ks, n):
            t = topo
            for k in sub:
                t = slide(t, k, name=None if n == 1 and t is topo else f"{t.name}+slider-J{CRANK + 1 + k}")
            out.append(t)
    return out


def topologies(max_links: int = 8, *, sliders: bool = False, levers: bool = False) -> list[Topology]:
    """The built-in topologies up to `max_links` links (the frame included): the four-bar with a
    coupler point; the six-bars — Watt (the two ternary links adjacent) with the dyad between
    coupler and crank, coupler and rocker, rocker and frame, crank and frame; Stephenson (not
    adjacent) between coupler and frame, rocker and crank; the eight-bars grown from three of
    the six-bars (`EIGHT_FROM`) by a dyad from the traced link to a frame pivot or the crank pin
    (`_eight_bar`), where that joint is not already on the traced link; the ten-bars (12 joints)
    grown from every eight-bar the same way (`max_links` ≥ 10). `sliders`: after those, each one's
    variants with sliders (`with_sliders`: the slider-crank, …), in the same order; `levers`: then
    each one's variants with a slotted lever (`with_levers`)."""
    out = [_four_bar()]
    six = [_six_bar(*s) for s in SIX_BARS]
    out += six
    eight = [e for t in six if t.name in EIGHT_FROM for e in _grown(t)]
    out += eight
    if max_links >= 10:
        out += [g for e in eight for g in _grown(e)]
    base = list(out)
    if sliders:
        out += [v for t in base for v in with_sliders(t)]
    if levers:
        out += [v for t in base for v in with_levers(t)]
    return [t for t in out if t.n_links <= max_links]


class TopologyArrays(NamedTuple):
    """Topologies as padded arrays, one row per topology (a batch shares one program)."""

    parents: np.ndarray  # (…, D, 2) int32
    active: np.ndarray   # (…, D) bool
    traced: np.ndarray   # (…,) int32


def as_arrays(topos: list[Topology]) -> TopologyArrays:
    """Stack topologies, padding each to the most dyads among them (inactive, attached to C and F1);
    a slider dyad's second parent + `SLIDER` (`tracer.trace` with `sliders`), a rigid body's point's
    + `RIGID` (`rigid`), a slotted lever's + `LEVER` (`tracer.trace` with `sliders`)."""
    nd = max(len(t.dyads) for t in topos)
    par = np.zeros((len(topos), nd, 2), np.int32)
    act = np.zeros((len(topos), nd), bool)
    for i, t in enumerate(topos):
        if len(t.dyads) > MAX_DYADS:
            raise ValueError(f"{t.name}: more than {MAX_DYADS} dyads")
        par[i, :, 0], par[i, :, 1] = CRANK, 1
        fixed = rigid(t)
        for k, (p1, p2) in enumerate(t.dyads):
            par[i, k] = (p1, p2 + SLIDER * (k in t.sliders) + RIGID * fixed[k] + LEVER * (k in t.levers))
            act[i, k] = True
    return TopologyArrays(par, act, np.array([t.traced for t in topos], np.int32))
