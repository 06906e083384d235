"""Stitch-cam tracks of the knitting sinker (the cam profile equations of docs/methods/sinker.md).

A cam is a straight rise at `a1`, a transition of radius `R` from `a1` to `a2`, and a straight
descent at `a2`, over a horizontal length `L`. The butt moves along the cam at the constant
speed `v = omega D / 2`, so the horizontal position is `x = v t`. The transition is either the
exact circular arc or the thesis's polygon of chords of length about `q` (0.1 mm).

Both are stored in one padded table of *pieces*: piece `k` starts at time `t0[k]`, position
`(x0[k], y0[k])`, and is a straight line of slope angle `alpha0[k]` (`is_arc[k] = 0`) or a
circular arc whose slope angle starts at `alpha0[k]` (`is_arc[k] = 1`):

```
line:  alpha = alpha0,                          y_z = y0 + (x - x0) tan(alpha0)
arc:   sin(alpha) = sin(alpha0) + (x - x0)/R,   y_z = y0 + R (cos(alpha0) - cos(alpha))
       y_z'(t) = v tan(alpha)
```

Within one piece the track is smooth, so integrators stop at every piece boundary and
evaluate the track with the piece index of the current step (`cam_eval(cam, t, k)`), which
keeps each step's right-hand side smooth even for the polygon's slope jumps. Padded pieces
have `t0 = +inf`. All tables built together share one padding, so geometries (exact and
polygon alike) can be stacked and `vmap`ped.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np


class CamGeometry(NamedTuple):
    """Parameters of one stitch cam (SI units, angles in radians).

    **Fields:**

    - `name`: label such as `"R10-45"`.
    - `radius`: transition radius `R` (m).
    - `rise_angle`: `a1` (rad), 30 deg in the seed.
    - `descent_angle`: `a2` (rad), 45/50/55 deg in the seed.
    - `length`: horizontal cam length `L` (m), 19.88 mm.
    - `split`: horizontal split of the straight parts, rise : descent (5.9 : 5.4).
    - `arc`: `"exact"` or `"polygon"`.
    - `chord`: nominal chord length `q` of the polygon (m), 0.1 mm.
    """

    name: str
    radius: float
    rise_angle: float
    descent_angle: float
    length: float = 19.88e-3
    split: tuple[float, float] = (5.9, 5.4)
    arc: str = "exact"
    chord: float = 1e-4


class CamTrack(NamedTuple):
    """A cam track as a padded table of pieces (a pytree of arrays; see the module docstring).

    **Fields** (shapes `[P]` for `P` padded pieces, scalars otherwise):

    - `t0, x0, y0, alpha0, is_arc`: start time (s), start position (m), start slope angle
      (rad) and kind (1.0 = arc) of each piece; padding has `t0 = inf`.
    - `radius`: arc radius (m).
    - `speed`: butt speed `v` (m/s).
    - `t_rise`: end of the straight rise (s). `t_descent`: start of the straight descent (s).
    - `t_end`: passage time `T = L / v` (s).
    - `descent_angle`: `a2` (rad), which governs static jamming.
    """

    t0: jnp.ndarray
    x0: jnp.ndarray
    y0: jnp.ndarray
    alpha0: jnp.ndarray
    is_arc: jnp.ndarray
    radius: jnp.ndarray
    speed: jnp.ndarray
    t_rise: jnp.ndarray
    t_descent: jnp.ndarray
    t_end: jnp.ndarray
    descent_angle: jnp.ndarray


def butt_speed(n_rpm: float, diameter: float) -> float:
    """Butt speed `v = omega D / 2 = pi n D / 60` (m/s) for `n` in rev/min and `D` in m."""
    return math.pi * n_rpm * diameter / 60.0


def seed_geometries(*, arc: str = "exact") -> list[CamGeometry]:
    """The six stitch cams of the thesis: R10/R20 times descent 45/50/55 deg (rise 30 deg)."""
    out = []
    for a2 in (45, 50, 55):
        for r in (10, 20):
            out.append(CamGeometry(f"R{r}-{a2}", r * 1e-3, math.radians(30.0), math.radians(a2),
                                   arc=arc))
    return out


def _pieces(geom: CamGeometry) -> tuple[list[tuple[float, float, float, float]], float, float]:
    """Pieces `(x0, y0, alpha0, is_arc)` in metres/radians, and the x of the rise end and
    of the descent start."""
    a1, a2, r, big_l = geom.rise_angle, geom.descent_angle, geom.radius, geom.length
    s1, s2 = geom.split
    if not (0.0 < a1 < a2 < math.pi / 2):
        raise ValueError(f"{geom.name}: need 0 < rise angle < descent angle < 90 deg")
    if geom.arc == "exact":
        x_arc = r * (math.sin(a2) - math.sin(a1))
        y_arc = r * (math.cos(a1) - math.cos(a2))
        x1 = (big_l - x_arc) * s1 / (s1 + s2)
        y1 = x1 * math.tan(a1)
        pieces = [(0.0, 0.0, a1, 0.0), (x1, y1, a1, 1.0), (x1 + x_arc, y1 + y_arc, a2, 0.0)]
        return pieces, x1, x1 + x_arc
    if geom.arc != "polygon":
        raise ValueError(f"{geom.name}: arc must be 'exact' or 'polygon', not {geom.arc!r}")
    arc_len = r * (a2 - a1)
    p = max(1, int(round(arc_len / geom.chord)))
    dl, da = arc_len / p, (a2 - a1) / p
    angles = [a1 + i * da for i in range(1, p + 1)]
    x_arc = sum(dl * math.cos(a) for a in angles)
    x1 = (big_l - x_arc) * s1 / (s1 + s2)
    y1 = x1 * math.tan(a1)
    pieces = [(0.0, 0.0, a1, 0.0)]
    x, y = x1, y1
    for a in angles:
        pieces.append((x, y, a, 0.0))
        x += dl * math.cos(a)
        y += dl * math.sin(a)
    # The last chord has slope a2 = the descent's slope: merge them into one piece.
    pieces[-1] = (pieces[-1][0], pieces[-1][1], a2, 0.0)
    return pieces, x1, x1 + x_arc


def make_cam(geoms: CamGeometry | list[CamGeometry], speed: float, *, pad_to: int | None = None
             ) -> CamTrack:
    """Build the piece table of one geometry, or stack several (leading batch axis).

    **Arguments:**

    - `geoms`: one `CamGeometry` or a list of them.
    - `speed`: butt speed `v` (m/s), see `butt_speed`.
    - `pad_to`: number of table rows (default: the largest piece count).
    """
    single = isinstance(geoms, CamGeometry)
    glist: list[CamGeometry] = [geoms] if isinstance(geoms, CamGeometry) else list(geoms)
    built = [_pieces(g) for g in glist]
    n_rows = max(len(p) for p, _, _ in built)
    if pad_to is not None:
        if pad_to < n_rows:
            raise ValueError(f"pad_to={pad_to} is smaller than the {n_rows} pieces needed")
        n_rows = pad_to
    cols: dict[str, list] = {k: [] for k in CamTrack._fields}
    for g, (pieces, x_rise, x_desc) in zip(glist, built):
        tab = np.full((n_rows, 4), np.nan)
        tab[: len(pieces)] = np.asarray(pieces)
        t0 = tab[:, 0] / speed
        t0[len(pieces):] = np.inf
        tab[len(pieces):] = tab[len(pieces) - 1]  # harmless values in the padding
        cols["t0"].append(t0)
        cols["x0"].append(tab[:, 0])
        cols["y0"].append(tab[:, 1])
        cols["alpha0"].append(tab[:, 2])
        cols["is_arc"].append(tab[:, 3])
        cols["radius"].append(g.radius)
        cols["speed"].append(speed)
        cols["t_rise"].append(x_rise / speed)
        cols["t_descent"].append(x_desc / speed)
        cols["t_end"].append(g.length / speed)
        cols["descent_angle"].append(g.descent_angle)
    arrays = {k: jnp.asarray(np.asarray(v, dtype=np.float64)) for k, v in cols.items()}
    if single:
        arrays = {k: v[0] for k, v in arrays.items()}
    return CamTrack(**arrays)


def cam_segment(cam: CamTrack, t):
    """Index of the piece containing time `t` (the later piece at a boundary)."""
    k = jnp.sum(cam.t0 <= t) - 1
    return jnp.clip(k, 0, cam.t0.shape[-1] - 1)


def cam_eval(cam: CamTrack, t, k=None):
    """Track at time `t`: `(y_z, alpha, y_z')` in m, rad, m/s.

    With a piece index `k`, that piece's formula is used (extended smoothly past its ends);
    otherwise the piece containing `t`.
    """
    if k is None:
        k = cam_segment(cam, t)
    x0, y0, a0, is_arc = cam.x0[k], cam.y0[k], cam.alpha0[k], cam.is_arc[k]
    dx = cam.speed * t - x0
    # arc: sin(alpha) = sin(a0) + dx / R  (clipped: a step never leaves its piece by much)
    s = jnp.clip(jnp.sin(a0) + dx / cam.radius, -0.999, 0.999)
    alpha_arc = jnp.arcsin(s)
    y_arc = y0 + cam.radius * (jnp.cos(a0) - jnp.cos(alpha_arc))
    y_line = y0 + dx * jnp.tan(a0)
    arc = is_arc > 0.5
    alpha = jnp.where(arc, alpha_arc, a0)
    yz = jnp.where(arc, y_arc, y_line)
    return yz, alpha, cam.speed * jnp.tan(alpha)


def cam_profile(cam: CamTrack, ts):
    """`(y_z, alpha, y_z')` on an array of times (the piece containing each time)."""
    import jax

    return jax.vmap(lambda t: cam_eval(cam, t))(jnp.asarray(ts))
