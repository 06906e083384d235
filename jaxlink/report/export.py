"""Geometry export of a kinematics table (`jaxlink kinematics --export OUT.dxf|OUT.svg`, `--plot OUT.dxf`).

Not a picture: real geometry in the file's length unit (`[mechanism] length_unit`), for a CAD
program. `geometry` collects it from the table and the linkage drawing (`jaxlink/report/drawing.py`),
`write_dxf` and `write_svg` write it. Layers (DXF layers, SVG groups with these ids):

- `PATH_<point>`: the traced path of each point of `[points]`, one polyline per run of assembled
  positions (closed over one full revolution when every position assembled; a run of a single
  position is left out);
- `JOINT_PATH_<joint>`: the same for each moving joint the drawing knows (not the ground pivots, not
  a joint at a point's place, whose path is the point's);
- `LINKAGE`: the linkage in one pose — a sketch file's own pose (solved at its `[input] start`: the
  sketch as drawn), else the first converged position (else the first assembled): every
  link as a line from joint to joint, each plate as a closed polyline (its outline: a sketch's plates,
  a loop file's bodies with three or more `[joints]`), each point's arm from its last joint as a
  polyline;
- `CONSTRUCTION`: the other vectors of the loops in that pose (frame vectors, a slider's vector,
  Cartesian vectors), lines (dashed in the DXF);
- `SLIDERS`: each slider's guide line and its block (a closed rectangle);
- `JOINTS`, `GROUND`: a small circle at each moving joint, at each ground pivot;
- `POINTS`: a small circle at each point in the pose (and at each joint of a sketch on one body
  only);
- `LABELS`: the joints' and points' names (DXF TEXT, SVG text): the names the drawing gives
  (`jaxlink/report/drawing.py`: a sketch's joint names, a loop file's `[joints]`).

A layer name keeps letters, digits, `_` and `-` of a name (other characters become `_`); one that
equals an earlier one but for case gets `_2`, `_3`, … (DXF layer names ignore case).

**DXF** (`ezdxf`, DXF R2010): `$INSUNITS` is the file's unit (4 mm, 5 cm, 6 m) and `$MEASUREMENT`
metric; paths and arms are LWPOLYLINEs (closed flag for a closed path), links and other vectors
LINEs, joints CIRCLEs. Coordinates are written exactly (shortest round-trip).

**SVG**: `viewBox` in the file's unit and `width`/`height` in mm (1:1: a drawing in metres is
1000 mm per unit); y points up as the file's y (the geometry sits in a group
`transform="scale(1,-1)"`, so the numbers in its `points`, `x1`, `cx`, … are the file's
coordinates); a closed path is a `<polygon>`, an open one a `<polyline>`, links `<line>`s, joints
`<circle>`s; the labels are outside the flipped group (at y = −y) so that they read upright.
"""

from __future__ import annotations

import dataclasses
import re
import xml.etree.ElementTree as ET

import numpy as np

from . import grid as _grid
from .drawing import drawing
from .units import LENGTH_UNITS, file_units

FORMATS = ("dxf", "svg")
"""The geometry formats, by the output's extension."""

INSUNITS = {"m": 6, "cm": 5, "mm": 4}
"""DXF `$INSUNITS` codes of the file's length units."""

LAYERS = ("LINKAGE", "CONSTRUCTION", "SLIDERS", "JOINTS", "GROUND", "POINTS", "LABELS")
"""The fixed layers (besides one `PATH_<point>` and `JOINT_PATH_<joint>` per path)."""

_COLORS = {"LINKAGE": 7, "CONSTRUCTION": 8, "SLIDERS": 8, "JOINTS": 7, "GROUND": 8, "POINTS": 1, "LABELS": 7}


@dataclasses.dataclass(frozen=True)
class Polyline:
    """Vertices `xy` (n, 2) in the file's unit on `layer`; `closed`: the last joins the first."""

    layer: str
    xy: np.ndarray
    closed: bool = False


@dataclasses.dataclass(frozen=True)
class Circle:
    layer: str
    center: np.ndarray
    radius: float


@dataclasses.dataclass(frozen=True)
class Label:
    layer: str
    at: np.ndarray
    text: str
    height: float


@dataclasses.dataclass
class Geometry:
    """What `write_dxf`/`write_svg` write, in the file's length `unit`: `polylines` (two-vertex
    open ones on `LINKAGE`, `CONSTRUCTION` and `SLIDERS` are lines), `circles`, `labels`; `layers`
    in order; `pose`: the row of the table drawn in `LINKAGE` (None: a pose given apart, a
    sketch's), `title` (name and pose)."""

    unit: str
    polylines: list
    circles: list
    labels: list
    layers: list
    pose: int | None
    title: str

    def layer(self, name: str) -> list:
        """The polylines of one layer."""
        return [p for p in self.polylines if p.layer == name]


def layer_name(prefix: str, name: str, taken=()) -> str:
    """`PATH_P`: `prefix` and the name with characters other than letters, digits, `_`, `-` as `_`;
    `_2`, `_3`, … added while it equals one of `taken` but for case (DXF layer names ignore case:
    points `p` and `P` get `PATH_p` and `PATH_P_2`)."""
    base = prefix + re.sub(r"[^A-Za-z0-9_\-]", "_", name)
    seen = {t.upper() for t in taken}
    out, k = base, 1
    while out.upper() in seen:
        k += 1
        out = f"{base}_{k}"
    return out


def _pieces(xy: np.ndarray, ok: np.ndarray, periodic: bool) -> list:
    """The runs of `ok` rows of the path `xy` (N, 2) as `(vertices, closed)`, runs of one row left
    out; over a full revolution a run that wraps is joined across the end, and an unbroken one is
    closed."""
    n = len(ok)
    if periodic and n > 2 and ok.all():
        return [(xy, True)]
    out = []
    for a, b in _grid.runs(ok, periodic):
        idx = np.arange(a, b + 1) if a <= b else np.concatenate([np.arange(a, n), np.arange(0, b + 1)])
        if len(idx) >= 2:
            out.append((xy[idx], False))
    return out


def geometry(mech, table, pose: tuple | None = None) -> Geometry:
    """The paths of a kinematics table and its linkage in one pose (see the module docstring), in
    the file's length unit. `pose`: `(q, input)` (SI) of the pose to draw instead of a row of the
    table — a sketch file's own pose, solved at its `[input] start` (`jaxlink kinematics` passes it
    for a sketch, so that the drawing is the sketch as drawn, not the table's first input)."""
    units = file_units(mech)
    s = units.length_factor
    d = drawing(mech, table.q, table.inputs, table.parameters, table.assembled)
    polylines: list = []
    circles: list = []
    labels: list = []
    layers: list = []

    for i, name in enumerate(mech.point_names):
        xy = np.asarray(table.points[:, i], dtype=float) * s
        ok = np.asarray(table.assembled, bool) & np.isfinite(xy).all(axis=1)
        lay = layer_name("PATH_", name, layers)
        layers.append(lay)
        polylines += [Polyline(lay, v, c) for v, c in _pieces(xy, ok, table.periodic)]
    point_names = set(mech.point_names)
    for k, name in enumerate(d.joint_names):
        if d.ground[k] or point_names & set(name.split("/")):
            continue
        xy = d.joints[:, k] * s
        ok = np.asarray(d.shown, bool) & np.isfinite(xy).all(axis=1)
        lay = layer_name("JOINT_PATH_", name, layers)
        layers.append(lay)
        polylines += [Polyline(lay, v, c) for v, c in _pieces(xy, ok, table.periodic)]
    layers += list(LAYERS)

    points = np.asarray(table.points, dtype=float)
    title = mech.name
    if pose is not None:  # the pose given, drawn from a drawing of its own (row 0)
        q, phi = pose
        d = drawing(mech, np.asarray(q, float)[None], np.asarray([phi], float), table.parameters, np.ones(1, bool))
        points, row, value = d.points, 0, mech.from_si(mech.input_name, float(phi))
        title += f" at input {_grid.format_input(float(f'{value:.12g}'), table.input_kind)} (the sketched pose)"
    else:
        conv, shown = np.flatnonzero(table.converged), np.flatnonzero(d.shown)
        if not (conv.size or shown.size):
            return Geometry(units.length, polylines, circles, labels, layers, None, title + " (no position assembled)")
        row = int(conv[0]) if conv.size else int(shown[0])
        title += f" at input {_grid.format_input(table.input_values[row], table.input_kind)}"
    size = d.extent * s
    seen: list = []  # a link in two loops is drawn once
    for v_all, kinds in zip(d.loops, d.kinds):
        v = v_all[row] * s
        n = len(kinds)
        for j, kind in enumerate(kinds):
            seg = np.stack([v[j], v[(j + 1) % n]])
            if not np.isfinite(seg).all() or np.hypot(*(seg[1] - seg[0])) <= 1e-12 * size:
                continue
            lay = "LINKAGE" if kind == "link" else "CONSTRUCTION"
            key = (lay, *sorted(map(tuple, np.round(seg / max(size, 1e-300), 9))))
            if key in seen:
                continue
            seen.append(key)
            polylines.append(Polyline(lay, seg))
    for body in d.bodies:  # a sketch's links (lines) and plates (closed outlines), a loop file's plates
        xy = body.outline[row] * s
        if np.isfinite(xy).all():
            polylines.append(Polyline("LINKAGE", xy, body.plate))
    for arm in d.arms:
        xy = arm[row] * s
        if len(xy) >= 2 and np.isfinite(xy).all():
            polylines.append(Polyline("LINKAGE", xy))
    h, w = 0.05 * size, 0.032 * size  # as the plots draw a block
    for sl in d.sliders:
        guide = sl.guide[row] * s
        if np.isfinite(guide).all():
            polylines.append(Polyline("SLIDERS", guide))
        u = sl.axis[row]
        nrm = np.array([-u[1], u[0]])
        b = sl.block[row] * s
        if np.isfinite(b).all():
            polylines.append(Polyline("SLIDERS", np.array([b - h * u - w * nrm, b + h * u - w * nrm,
                                                           b + h * u + w * nrm, b - h * u + w * nrm]), True))
    r, text_h = 0.012 * size, 0.03 * size
    for k, name in enumerate(d.joint_names):
        c = d.joints[row, k] * s
        if np.isfinite(c).all():
            circles.append(Circle("GROUND" if d.ground[k] else "JOINTS", c, r))
            labels.append(Label("LABELS", c + np.array([1.5 * r, 1.5 * r]), name, text_h))
    joint_names = set(d.joint_names)
    for i, name in enumerate(d.mark_names):  # a sketch's joints on one body only: points of it
        c = d.marks[row, i] * s
        if np.isfinite(c).all() and name not in mech.point_names:
            circles.append(Circle("POINTS", c, 0.6 * r))
            labels.append(Label("LABELS", c + np.array([1.5 * r, -1.5 * r - text_h]), name, text_h))
    for i, name in enumerate(mech.point_names):
        c = np.asarray(points[row, i], dtype=float) * s
        if np.isfinite(c).all():
            circles.append(Circle("POINTS", c, 0.6 * r))
            if name not in joint_names:
                labels.append(Label("LABELS", c + np.array([1.5 * r, -1.5 * r - text_h]), name, text_h))
    return Geometry(units.length, polylines, circles, labels, layers, None if pose is not None else row,
                    title)


def _is_line(p: Polyline) -> bool:
    return len(p.xy) == 2 and not p.closed and not p.layer.startswith(("PATH_", "JOINT_PATH_"))


def write_dxf(path: str, geo: Geometry) -> None:
    """`geo` as a DXF file (R2010, `$INSUNITS` the file's unit), one layer per `geo.layers`."""
    import ezdxf

    doc = ezdxf.new("R2010", setup=True)  # setup: the standard line types (DASHED)
    doc.header["$INSUNITS"] = INSUNITS[geo.unit]
    doc.header["$MEASUREMENT"] = 1  # metric
    for k, name in enumerate(geo.layers):
        doc.layers.add(name, color=_COLORS.get(name, 1 + k % 6),
                       linetype="DASHED" if name == "CONSTRUCTION" else "Continuous")
    msp = doc.modelspace()
    for p in geo.polylines:
        xy = [(float(x), float(y)) for x, y in p.xy]
        if _is_line(p):
            msp.add_line(xy[0], xy[1], dxfattribs={"layer": p.layer})
        else:
            msp.add_lwpolyline(xy, format="xy", close=p.closed, dxfattribs={"layer": p.layer})
    for c in geo.circles:
        msp.add_circle((float(c.center[0]), float(c.center[1])), float(c.radius), dxfattribs={"layer": c.layer})
    for t in geo.labels:
        msp.add_text(t.text, height=float(t.height), dxfattribs={"layer": t.layer}).set_placement(
            (float(t.at[0]), float(t.at[1])))
    doc.saveas(path)


def _num(x: float) -> str:
    return repr(float(x))


def _xy(xy) -> str:
    return " ".join(f"{_num(x)},{_num(y)}" for x, y in xy)


def svg_tree(geo: Geometry) -> ET.Element:
    """The SVG document of `geo` (see the module docstring)."""
    xy = [p.xy for p in geo.polylines] + [np.atleast_2d(c.center) for c in geo.circles]
    xy += [np.atleast_2d(t.at) for t in geo.labels]
    pts = np.concatenate(xy) if xy else np.zeros((1, 2))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = float(max(hi[0] - lo[0], hi[1] - lo[1], 1e-12))
    pad = 0.05 * span
    x0, x1, y0, y1 = lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad
    mm = 1000.0 * next(u for u, n in LENGTH_UNITS.items() if n == geo.unit)  # mm per file unit
    svg = ET.Element("svg", {
        "xmlns": "http://www.w3.org/2000/svg", "version": "1.1",
        "width": f"{_num((x1 - x0) * mm)}mm", "height": f"{_num((y1 - y0) * mm)}mm",
        "viewBox": f"{_num(x0)} {_num(-y1)} {_num(x1 - x0)} {_num(y1 - y0)}",
    })
    ET.SubElement(svg, "title").text = geo.title
    ET.SubElement(svg, "desc").text = (f"jaxlink geometry in {geo.unit} (viewBox in {geo.unit}; y up: the group "
                                       "'geometry' is flipped by scale(1,-1), its coordinates are the file's)")
    width = _num(span / 400.0)
    top = ET.SubElement(svg, "g", {"id": "geometry", "transform": "scale(1,-1)", "fill": "none",
                                   "stroke-linecap": "round", "stroke-linejoin": "round", "stroke-width": width})
    colors = {"LINKAGE": "#333333", "CONSTRUCTION": "#999999", "SLIDERS": "#777777", "JOINTS": "#333333",
              "GROUND": "#777777", "POINTS": "#d62728"}
    cycle = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22")
    groups: dict = {}
    for k, name in enumerate(geo.layers):
        if name == "LABELS":
            continue
        attrs = {"id": name, "stroke": colors.get(name, cycle[k % len(cycle)])}
        if name == "CONSTRUCTION":
            attrs["stroke-dasharray"] = f"{_num(span / 100)} {_num(span / 200)}"
        groups[name] = ET.SubElement(top, "g", attrs)
    for p in geo.polylines:
        g = groups[p.layer]
        if _is_line(p):
            (ax, ay), (bx, by) = p.xy
            ET.SubElement(g, "line", {"x1": _num(ax), "y1": _num(ay), "x2": _num(bx), "y2": _num(by)})
        else:
            ET.SubElement(g, "polygon" if p.closed else "polyline", {"points": _xy(p.xy)})
    for c in geo.circles:
        ET.SubElement(groups[c.layer], "circle", {"cx": _num(c.center[0]), "cy": _num(c.center[1]),
                                                  "r": _num(c.radius), "fill": "white"})
    if "LABELS" in geo.layers:
        size = _num(geo.labels[0].height) if geo.labels else "1"
        g = ET.SubElement(svg, "g", {"id": "LABELS", "font-family": "sans-serif", "font-size": size,
                                     "fill": "#222222"})
        for t in geo.labels:  # upright: outside the flipped group, at y = −y
            ET.SubElement(g, "text", {"x": _num(t.at[0]), "y": _num(-t.at[1])}).text = t.text
    return svg


def write_svg(path: str, geo: Geometry) -> None:
    """`geo` as an SVG file (see the module docstring)."""
    tree = ET.ElementTree(svg_tree(geo))
    ET.indent(tree)
    tree.write(path, encoding="utf-8", xml_declaration=True)


def export(path: str, mech, table, pose: tuple | None = None) -> None:
    """Write the geometry of `table` to `path`, DXF or SVG by its extension (`FORMATS`); `pose`:
    as `geometry`'s."""
    ext = path.rsplit(".", 1)[-1].lower() if "." in path else ""
    if ext not in FORMATS:
        raise ValueError(f"{path}: the geometry formats are {', '.join('.' + f for f in FORMATS)}")
    geo = geometry(mech, table, pose)
    (write_dxf if ext == "dxf" else write_svg)(path, geo)
