"""A target curve for path synthesis: points read from a CSV, NPY or SVG file, in the file's
length unit, open or closed.

- **CSV**: two columns x, y (a header is optional; its names may carry the unit, `x_mm,y_mm`;
  the unit, when named, is reported); more columns: the first two named `x*`, `y*`, else the first
  point's `NAME_x_UNIT`, `NAME_y_UNIT` (a `jaxlink kinematics --csv` table is a target). A column
  named `theta_deg` or `theta_rad` (also `input_…`, `crank_…`, `phi_…`) makes the target
  **timed**: each point is to be reached at that input angle (relative: the first point's angle is
  the search's to choose, the differences are kept).
- **NPY**: an (N, 2) array; (N, 3): x, y and the input angle in radians (timed).
- **SVG**: the `d` attribute of the first `<path>`: `M`/`m`, `L`/`l`, `H`/`h`, `V`/`v`, `C`/`c`,
  `S`/`s`, `Q`/`q`, `T`/`t`, `Z`/`z` (arcs are refused), in the SVG's user units, y as written
  (SVG's y points down: the curve is mirrored against the drawing; `flip_y` turns it back);
  each Bézier segment is sampled at 32 points.

`closed` by default when the gap from the last point back to the first is at most 1 % of the size
(the diagonal of the bounding box) or at most 1.5 × the median step between points (a loop
sampled without repeating its first point).

A timed target's inputs go one way (increasing: the crank turns positively; decreasing: the other
way) and span less than a turn; its points are kept as given (a repeated point at two inputs is a
dwell). Its match is the ordered distance (`distance.match_ordered`); `closed` there only says
whether the whole turn is checked for assembly.
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..errors import MechanismError

#: the first and last points closer than this fraction of the size make a closed curve
CLOSE_FRACTION = 0.01
_BEZIER_SAMPLES = 32


class Target(NamedTuple):
    """A target path.

    - `points`: (N, 2) float64, in `unit` (the file's length unit);
    - `closed`: whether the path is a closed loop (matched by a whole crank turn);
    - `unit`: the length unit named by the file ("" when it names none);
    - `source`: where it came from;
    - `inputs`: a timed target's input angle of each point (N,), rad (only the differences count),
      else None.
    """

    points: np.ndarray
    closed: bool
    unit: str
    source: str
    inputs: np.ndarray | None = None

    @property
    def timed(self) -> bool:
        return self.inputs is not None


def is_closed(points: np.ndarray) -> bool:
    """The default (module doc): the closing gap within `CLOSE_FRACTION` of the bounding box's
    diagonal or within 1.5 median steps."""
    pts = np.asarray(points, float)
    size = float(np.linalg.norm(pts.max(0) - pts.min(0)))
    gap = float(np.linalg.norm(pts[0] - pts[-1]))
    step = float(np.median(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    return bool(gap <= CLOSE_FRACTION * size or gap <= 1.5 * step)


def make_target(points, *, closed: bool | None = None, unit: str = "", source: str = "<array>",
                inputs=None) -> Target:
    """A `Target` from an (N, 2) array; a closed curve loses a repeated last point. `inputs`: (N,)
    the input angle (rad) of each point, a timed target (module doc)."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 3:
        raise MechanismError(f"{source}: a target needs an (N, 2) array of N >= 3 points, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise MechanismError(f"{source}: the target's points must be finite")
    if inputs is not None:
        return _timed(pts, np.asarray(inputs, dtype=float), closed, unit, source)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 0])
    pts = pts[keep]  # repeated points carry no length
    if pts.shape[0] < 3:
        raise MechanismError(f"{source}: the target has fewer than 3 distinct points")
    c = is_closed(pts) if closed is None else bool(closed)
    if c and np.linalg.norm(pts[0] - pts[-1]) <= 1e-12 * np.linalg.norm(pts.max(0) - pts.min(0)):
        pts = pts[:-1]
    return Target(pts, c, unit, source)


def _timed(pts: np.ndarray, t: np.ndarray, closed: bool | None, unit: str, source: str) -> Target:
    if t.shape != (pts.shape[0],):
        raise MechanismError(f"{source}: a timed target needs one input angle per point, got {t.shape} for "
                             f"{pts.shape[0]} points")
    if not np.all(np.isfinite(t)):
        raise MechanismError(f"{source}: the target's input angles must be finite")
    dt = np.diff(t)
    if not (np.all(dt > 0) or np.all(dt < 0)):
        raise MechanismError(f"{source}: a timed target's input angles must go one way (all increasing or all "
                             "decreasing), every point at its own angle")
    if np.linalg.norm(pts - pts.mean(0), axis=1).max() <= 1e-12 * max(1.0, float(np.abs(pts).max())):
        raise MechanismError(f"{source}: a timed target's points are all one point: nothing to match")
    span = abs(float(t[-1] - t[0]))
    if span >= 2 * np.pi:
        raise MechanismError(f"{source}: a timed target's input angles span {math.degrees(span):.6g}°: at most "
                             "one turn (less than 360°) from the first point to the last")
    c = is_closed(pts) if closed is None else bool(closed)
    return Target(pts, c, unit, source, t.copy())


def load_target(path: str | Path, *, closed: bool | None = None, flip_y: bool = False) -> Target:
    """Read a target from a `.csv`, `.npy` or `.svg` file (see the module doc)."""
    p = Path(path)
    if not p.exists():
        raise MechanismError(f"{p}: no such target file")
    ext = p.suffix.lower()
    unit = ""
    inputs = None
    if ext == ".npy":
        pts = np.load(p, allow_pickle=False)
        if pts.ndim == 2 and pts.shape[1] == 3:
            pts, inputs = pts[:, :2], pts[:, 2]
    elif ext == ".csv" or ext == ".txt":
        pts, unit, inputs = _read_csv(p)
    elif ext == ".svg":
        pts = _read_svg(p)
    else:
        raise MechanismError(f"{p}: a target is a .csv, .npy or .svg file")
    pts = np.asarray(pts, float)
    if flip_y:
        pts = pts * np.array([1.0, -1.0])
    return make_target(pts, closed=closed, unit=unit, source=str(p), inputs=inputs)


#: a timed target's input column: its name and its unit
_INPUT_COLUMN = re.compile(r"(theta|input|crank|phi)\w*?[_ \[(]+(deg|rad)[\])]*", re.IGNORECASE)


def _read_csv(p: Path) -> tuple[np.ndarray, str, np.ndarray | None]:
    rows = [r for r in csv.reader(p.read_text().splitlines()) if r and any(c.strip() for c in r)]
    if not rows:
        raise MechanismError(f"{p}: empty target file")
    header = None
    try:
        [float(c) for c in rows[0][:2]]
    except ValueError:
        header, rows = [c.strip() for c in rows[0]], rows[1:]
    ix, iy, unit = 0, 1, ""
    if header is not None:
        xs = [i for i, h in enumerate(header) if h.lower().startswith("x")]
        ys = [i for i, h in enumerate(header) if h.lower().startswith("y")]
        low = [h.lower() for h in header]
        # a point's columns as `jaxlink kinematics --csv` writes them: NAME_x_UNIT, NAME_y_UNIT
        pairs = [(i, low.index(h[:m.start()] + "_y" + h[m.end():])) for i, h in enumerate(low)
                 if (m := re.search(r"_x(?=_[a-z]+$|$)", h)) and h[:m.start()] + "_y" + h[m.end():] in low]
        if xs and ys:
            ix, iy = xs[0], ys[0]
        elif pairs:
            ix, iy = pairs[0]
        m = re.fullmatch(r"(?:\w+_)?x[_ \[(]*([A-Za-z]+)[\])]*", header[ix].strip(), re.IGNORECASE)
        unit = m.group(1) if m else ""
    it = [(i, mm.group(2).lower()) for i, h in enumerate(header or [])
          if (mm := _INPUT_COLUMN.fullmatch(h.strip())) is not None]
    try:
        pts = np.array([[float(r[ix]), float(r[iy])] for r in rows])
    except (ValueError, IndexError) as e:
        raise MechanismError(f"{p}: a target CSV has two numeric columns x, y ({e})") from None
    if not it:
        return pts, unit, None
    i, u = it[0]
    try:
        t = np.array([float(r[i]) for r in rows])
    except (ValueError, IndexError) as e:
        name = (header or [""] * (i + 1))[i]
        raise MechanismError(f"{p}: column {name!r} (the input angle of each point) must be numeric ({e})") from None
    return pts, unit, np.radians(t) if u == "deg" else t


_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def _read_svg(p: Path) -> np.ndarray:
    import xml.etree.ElementTree as ET

    root = ET.parse(p).getroot()
    for el in root.iter():
        if el.tag.rsplit("}", 1)[-1] == "path" and el.get("d"):
            return svg_path_points(el.get("d", ""), source=str(p))
    raise MechanismError(f"{p}: no <path> with a 'd' attribute")


def svg_path_points(d: str, *, source: str = "<svg>") -> np.ndarray:
    """The points of an SVG path's `d` attribute (its first sub-path and any that follow, joined)."""
    tokens = re.findall(rf"[MmLlHhVvCcSsQqTtZzAa]|{_NUM}", d)
    out: list[np.ndarray] = []
    cur = np.zeros(2)
    start = np.zeros(2)
    last_ctrl: np.ndarray | None = None
    cmd = ""
    prev = ""
    i = 0

    def nums(k):
        nonlocal i
        vals = []
        for _ in range(k):
            if i >= len(tokens) or re.fullmatch(r"[A-Za-z]", tokens[i]):
                raise MechanismError(f"{source}: SVG path command {cmd!r} needs {k} numbers")
            vals.append(float(tokens[i]))
            i += 1
        return np.array(vals)

    t = np.linspace(0.0, 1.0, _BEZIER_SAMPLES + 1)[1:, None]
    while i < len(tokens):
        if re.fullmatch(r"[A-Za-z]", tokens[i]):
            cmd = tokens[i]
            i += 1
        elif not cmd:
            raise MechanismError(f"{source}: an SVG path starts with a command")
        rel = cmd.islower()
        base = cur if rel else np.zeros(2)
        c = cmd.upper()
        ctrl: np.ndarray | None = None
        if c == "Z":
            cur = start.copy()
            out.append(cur[None])
            cmd = ""
            continue
        if c == "A":
            raise MechanismError(f"{source}: SVG arcs (A) are not read; convert them to Béziers")
        if c == "M":
            cur = base + nums(2)
            start = cur.copy()
            out.append(cur[None])
            cmd = "l" if rel else "L"
        elif c == "L":
            cur = base + nums(2)
            out.append(cur[None])
        elif c == "H":
            cur = np.array([(cur[0] if rel else 0.0) + nums(1)[0], cur[1]])
            out.append(cur[None])
        elif c == "V":
            cur = np.array([cur[0], (cur[1] if rel else 0.0) + nums(1)[0]])
            out.append(cur[None])
        elif c in "CS":
            if c == "C":
                c1 = base + nums(2)
            else:
                c1 = 2 * cur - last_ctrl if last_ctrl is not None and prev in "CS" else cur
            c2, end = base + nums(2), base + nums(2)
            seg = ((1 - t) ** 3 * cur + 3 * (1 - t) ** 2 * t * c1 + 3 * (1 - t) * t ** 2 * c2 + t ** 3 * end)
            out.append(seg)
            cur, ctrl = end, c2
        elif c in "QT":
            if c == "Q":
                c1 = base + nums(2)
            else:
                c1 = 2 * cur - last_ctrl if last_ctrl is not None and prev in "QT" else cur
            end = base + nums(2)
            out.append((1 - t) ** 2 * cur + 2 * (1 - t) * t * c1 + t ** 2 * end)
            cur, ctrl = end, c1
        else:  # pragma: no cover - the tokenizer admits nothing else
            raise MechanismError(f"{source}: unknown SVG path command {cmd!r}")
        last_ctrl, prev = ctrl, c
    if not out:
        raise MechanismError(f"{source}: the SVG path is empty")
    return np.concatenate(out, axis=0)


def arclength_resample(points: np.ndarray, n: int, closed: bool) -> np.ndarray:
    """n points equally spaced in arclength along the polyline (closed: along the loop, the
    closing segment included, n spacings; open: from the first to the last point, n − 1 spacings)."""
    pts = np.asarray(points, float)
    if closed:
        pts = np.concatenate([pts, pts[:1]], axis=0)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = s[-1]
    if not total > 0 or not math.isfinite(total):
        raise MechanismError("a curve of zero length cannot be resampled")
    q = total * (np.arange(n) / n if closed else np.linspace(0.0, 1.0, n))
    x = np.interp(q, s, pts[:, 0])
    y = np.interp(q, s, pts[:, 1])
    return np.stack([x, y], axis=1)
