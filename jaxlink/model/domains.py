"""The domain of every parameter of a mechanism, defined once.

The file reader refuses a value outside it (with the file, line and key, or on `--set`:
`jaxlink/files/reader.py`), and every batched evaluator — the study's (`jaxlink.study.responses`),
the design search's (`jaxlink.optimize.evaluator`) and the synthesis's feasibility — counts a
design with a value outside it as infeasible (`inside`, jittable): a design the file could not
hold is never evaluated as if it could.

**The domains** (SI; `DOMAINS`: (smallest non-zero magnitude, largest magnitude)):

- a *link length* — a parameter standing alone as the LENGTH of a term `NAME @ ANGLE` of a loop
  or a point (`link_lengths`) — is ≥ 0: 0, or from a nanometre to 1000 km when it is a loop's;
- any other length (a coordinate, an offset, a slider's position) within ±1000 km, however small;
- an angle within ±1e4 rad (about 1600 turns); a pure number within ±1e9.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

#: SI domain of each kind of value: (smallest non-zero magnitude, largest magnitude). A link length
#: from a nanometre to 1000 km (or 0); any other length (a coordinate, an offset) within ±1000 km,
#: however small; angles within ±1e4 rad (about 1600 turns), pure numbers within ±1e9.
DOMAINS = {"link length": (1e-9, 1e6), "length": (0.0, 1e6), "angle": (0.0, 1e4), "number": (0.0, 1e9)}


def link_lengths(groups, names) -> tuple[frozenset, frozenset]:
    """(the parameters standing alone as the LENGTH of a term `NAME @ ANGLE` of a loop, those of a
    loop or a point) among `names`; `groups`: the loops and the points, each a sequence of
    `(name, terms)`. The first are link lengths (`DOMAINS["link length"]`), all must be ≥ 0."""
    from ..files import expr as _expr

    names = set(names)
    out: list[set] = []
    for group in groups:
        out.append({t.length.name for _, terms in group for t in terms
                    if t.polar and isinstance(t.length, _expr.Name) and t.length.name in names})
    loops = out[0] if out else set()
    return frozenset(loops), frozenset(set().union(*out))


def bounds(structure) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lower, upper, smallest non-zero magnitude) of each of the structure's parameters (SI; the
    order of `parameter_names`): a link length [0, 1e6] (a loop's: 0 or ≥ 1e-9), a point's length
    term [0, 1e6], another length ±1e6, an angle ±1e4, a number ±1e9. Kept on the structure."""
    structure = getattr(structure, "structure", structure)  # a Mechanism's
    cached = structure.__dict__.get("_domains")
    if cached is not None:
        return cached
    links, signed = link_lengths((structure.loops, structure.points), structure.parameter_names)
    lo, hi, tiny = [], [], []
    for name, kind in zip(structure.parameter_names, structure.parameter_kinds):
        what = "link length" if name in links and kind == "length" else (kind or "number")
        small, big = DOMAINS[what]
        lo.append(0.0 if name in signed else -big)
        hi.append(big)
        tiny.append(small)
    out = (np.asarray(lo, float), np.asarray(hi, float), np.asarray(tiny, float))
    object.__setattr__(structure, "_domains", out)
    return out


def inside(structure, p):
    """Whether the parameters `p` (SI, (P,) or (B, P)) are all within their domains (`bounds`);
    jittable, False for a NaN. Every batched evaluator ands its feasibility with it."""
    lo, hi, tiny = bounds(structure)
    xp = jnp if not isinstance(p, np.ndarray) else np
    a = xp.abs(p)
    ok = (p >= lo) & (p <= hi) & ~((a > 0) & (a < tiny))
    return xp.all(ok, axis=-1)


def joints_inside(joints, links) -> bool:
    """Whether a mechanism given by its joints' positions `joints` (J, 2) (SI) and its links (each
    a sequence of joint indices) holds values a file can: every coordinate a length (±1e6 m) and
    every distance between two joints of a link a link length (0, or 1e-9 m to 1e6 m). The
    synthesis's designs, written as sketches (joints and links), are held to it."""
    joints = np.asarray(joints, float)
    if not np.all(np.isfinite(joints)) or np.any(np.abs(joints) > DOMAINS["length"][1]):
        return False
    small, big = DOMAINS["link length"]
    for link in links:
        idx = list(link)
        for k, i in enumerate(idx):
            d = np.hypot(*(joints[idx[k + 1:]] - joints[i]).T)
            if np.any(d > big) or np.any((d > 0) & (d < small)):
                return False
    return True
