"""Output in the file's units (`--units file`) and geometry export (`kinematics --export`, `--plot OUT.dxf`).

The file-unit tables are checked against the SI table of the same command converted by hand (exact
factors: 1000 from m to mm, 180/π from rad to deg); the exported DXF (read back by ezdxf) and SVG
(parsed by xml.etree) against the solver's positions in mm and the four-bar's joints from its
geometry (crank pin on a circle of radius a about the origin, rocker pin at b from it along phi3).
The commands run in-process on the default grid of `tests/test_report.py` (the same stored
program: nothing new to compile)."""

import csv
import io
import math
import xml.etree.ElementTree as ET

import ezdxf
import numpy as np
import pytest

import jaxlink as jl
from jaxlink.cli import build_parser, main
from jaxlink.report import export
from jaxlink.report.reactions import ReactionsTable, print_summary, write_csv
from jaxlink.report.units import FileUnits, convert, file_units

SVG = "{http://www.w3.org/2000/svg}"


def run(capsys, *args):
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def read(path):
    rows = list(csv.reader(open(path)))
    return rows[0], rows[1:]


def numbers(rows, j):
    return np.array([float(r[j]) for r in rows])


def test_kinematics_in_file_units_is_si_converted(tmp_path, capsys):
    si, mm = tmp_path / "si.csv", tmp_path / "mm.csv"
    args = ("kinematics", "four-bar", "--outputs", "position,velocity,acceleration,rates", "--rpm", "60")
    assert run(capsys, *args, "--csv", str(si))[0] == 0
    code, stdout, _ = run(capsys, *args, "--units", "file", "--csv", str(mm))
    assert code == 0
    h_si, r_si = read(si)
    h_mm, r_mm = read(mm)
    assert h_mm == ["input_deg", "phi3_deg", "phi3_deg_s", "phi3_deg_s2", "phi4_deg", "phi4_deg_s", "phi4_deg_s2",
                    "P_x_mm", "P_y_mm", "P_vx_mm_s", "P_vy_mm_s", "P_ax_mm_s2", "P_ay_mm_s2", "converged",
                    "residual_mm", "result"]
    assert len(r_mm) == len(r_si) == 72
    deg = 180.0 / math.pi
    for j, (a, b) in enumerate(zip(h_si, h_mm)):
        if a in ("converged", "result"):
            assert [r[j] for r in r_si] == [r[j] for r in r_mm]
            continue
        factor = 1.0 if a == "input_deg" else (deg if "_rad" in a else 1000.0)
        np.testing.assert_allclose(numbers(r_mm, j), numbers(r_si, j) * factor, rtol=1e-15, atol=0, err_msg=b)
    # the summary in the same units
    head = next(x for x in stdout.splitlines() if " positions at " in x)
    assert "at 60 rpm (ω = 360 deg/s)" in head and head.endswith(" mm")
    line = next(x for x in stdout.splitlines() if x.startswith("P_x_mm "))
    lo, hi = map(float, line.split()[1:])
    j = h_si.index("P_x_m")
    assert lo == pytest.approx(numbers(r_si, j).min() * 1000, rel=1e-6)
    assert hi == pytest.approx(numbers(r_si, j).max() * 1000, rel=1e-6)


def test_reactions_in_file_units(tmp_path):
    """`reactions --units file`: the forces stay in N, the torque goes to N·mm, the input stays in
    degrees (a table made by hand: the conversion is the report's, the solve is not needed)."""
    cols = ["input_deg", "A_Fx_N", "A_Fy_N", "drive_torque_N_m", "result"]
    data = np.array([[0.0, 1.5, -2.0, 0.25, 0.0], [90.0, 3.0, 4.0, -0.125, 0.0]])
    table = ReactionsTable(cols, data, np.ones(2, bool), np.zeros(2, int), ("A",), 2 * math.pi, rpm=60.0)
    mm = file_units(jl.load("slider-crank-mass"))
    assert mm == ("mm", "deg", 1000.0, 180.0 / math.pi)
    write_csv(str(tmp_path / "r.csv"), table, mm)
    head, rows = read(tmp_path / "r.csv")
    assert head == ["input_deg", "A_Fx_N", "A_Fy_N", "drive_torque_N_mm", "result"]
    assert [[float(x) for x in r[:-1]] for r in rows] == [[0.0, 1.5, -2.0, 250.0], [90.0, 3.0, 4.0, -125.0]]
    out = io.StringIO()
    print_summary(table, out, mm)
    text = out.getvalue()
    torque = next(x for x in text.splitlines() if x.startswith("drive torque"))
    assert "60 rpm (ω = 360 deg/s)" in text and torque.split()[2:] == ["250", "0", "(N·mm,", "largest", "|τ|)"]
    assert build_parser().parse_args(["reactions", "slider-crank-mass", "--units", "file"]).units == "file"


def _fourbar_joints(phi_deg, phi3_rad):
    """The crank pin A and rocker pin B of the built-in four-bar (mm): a = 20, b = 60, B0 = (55, 0)."""
    phi = np.deg2rad(phi_deg)
    A = 20.0 * np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    return A, A + 60.0 * np.stack([np.cos(phi3_rad), np.sin(phi3_rad)], axis=-1)


def test_dxf_and_svg_geometry_in_the_file_unit(tmp_path, capsys):
    si, dxf, svg = tmp_path / "si.csv", tmp_path / "f.dxf", tmp_path / "f.svg"
    code, stdout, _ = run(capsys, "kinematics", "four-bar", "--csv", str(si), "--plot", str(dxf), "--export", str(svg))
    assert code == 0 and f"wrote {dxf} (geometry in mm)" in stdout
    head, rows = read(si)
    P = np.stack([numbers(rows, head.index("P_x_m")), numbers(rows, head.index("P_y_m"))], axis=1) * 1000.0
    A, B = _fourbar_joints(numbers(rows, 0), numbers(rows, head.index("phi3_rad")))
    A0, B0 = np.zeros(2), np.array([55.0, 0.0])

    doc = ezdxf.readfile(dxf)
    assert doc.header["$INSUNITS"] == 4  # millimetres
    layers = {lay.dxf.name for lay in doc.layers}
    assert {"PATH_P", "LINKAGE", "CONSTRUCTION", "JOINTS", "GROUND", "LABELS"} <= layers
    msp = doc.modelspace()
    path, = msp.query('LWPOLYLINE[layer=="PATH_P"]')
    assert path.closed  # one full revolution, every position assembled
    np.testing.assert_allclose(np.array(path.get_points("xy")), P, rtol=0, atol=1e-9)
    joint_paths = [e for e in msp.query("LWPOLYLINE") if e.dxf.layer.startswith("JOINT_PATH_")]
    assert len(joint_paths) == 2  # the crank pin and the rocker pin; the ground pivots do not move
    paths = sorted((np.array(e.get_points("xy")) for e in joint_paths), key=lambda v: np.ptp(v[:, 1]))
    np.testing.assert_allclose(paths[0], B, rtol=0, atol=1e-9)  # the rocker pin swings less high than the crank
    np.testing.assert_allclose(paths[1], A, rtol=0, atol=1e-9)
    # the linkage at its first position: crank, coupler, rocker as lines; joints and pivots as circles
    links = {tuple(sorted([tuple(np.round(e.dxf.start, 6))[:2], tuple(np.round(e.dxf.end, 6))[:2]]))
             for e in msp.query('LINE[layer=="LINKAGE"]')}
    pts = [np.round(x, 6) + 0.0 for x in (A0, A[0], B[0], B0)]
    assert links == {tuple(sorted([tuple(pts[i]), tuple(pts[k])])) for i, k in ((0, 1), (1, 2), (2, 3))}
    centres = {layer: sorted(tuple(np.round(c.dxf.center, 6)[:2] + 0.0) for c in msp.query(f'CIRCLE[layer=="{layer}"]'))
               for layer in ("JOINTS", "GROUND")}
    assert centres == {"JOINTS": sorted([tuple(pts[1]), tuple(pts[2])]),
                       "GROUND": sorted([tuple(pts[0]), tuple(pts[3])])}

    root = ET.parse(svg).getroot()
    assert root.tag == SVG + "svg" and root.get("width").endswith("mm")
    x0, y0, w, h = map(float, root.get("viewBox").split())
    assert float(root.get("width")[:-2]) == pytest.approx(w) and float(root.get("height")[:-2]) == pytest.approx(h)
    geo = root.find(f"{SVG}g[@id='geometry']")
    assert geo.get("transform") == "scale(1,-1)"  # y up: the file's coordinates, flipped for the screen
    poly, = geo.find(f"{SVG}g[@id='PATH_P']")
    assert poly.tag == SVG + "polygon"  # closed
    xy = np.array([[float(v) for v in p.split(",")] for p in poly.get("points").split()])
    np.testing.assert_allclose(xy, P, rtol=0, atol=1e-9)
    # every path lies inside the view (x, −y in the flipped group)
    assert (x0 <= P[:, 0]).all() and (P[:, 0] <= x0 + w).all() and (y0 <= -P[:, 1]).all() and (-P[:, 1] <= y0 + h).all()
    lines = geo.find(f"{SVG}g[@id='LINKAGE']").findall(f"{SVG}line")
    ends = {tuple(sorted([(round(float(ln.get("x1")), 6) + 0.0, round(float(ln.get("y1")), 6) + 0.0),
                          (round(float(ln.get("x2")), 6) + 0.0, round(float(ln.get("y2")), 6) + 0.0)]))
            for ln in lines}
    assert ends == links


@pytest.mark.parametrize("unit,code,mm", [("m", 6, 1000.0), ("cm", 5, 10.0), ("mm", 4, 1.0)])
def test_units_of_the_writers(tmp_path, unit, code, mm):
    geo = export.Geometry(unit, [export.Polyline("PATH_P", np.array([[0.0, 0.0], [1.5, 2.0], [3.0, 0.5]]))],
                          [], [], ["PATH_P", *export.LAYERS], 0, "t")
    export.write_dxf(str(tmp_path / "g.dxf"), geo)
    doc = ezdxf.readfile(tmp_path / "g.dxf")
    assert doc.header["$INSUNITS"] == code
    root = export.svg_tree(geo)
    x0, y0, w, h = map(float, root.get("viewBox").split())
    assert float(root.get("width")[:-2]) == pytest.approx(w * mm)  # 1:1 in millimetres
    assert x0 < 0.0 < 3.0 < x0 + w and y0 < -2.0 and 0.0 < y0 + h


def test_file_unit_names_and_factors():
    mm = FileUnits("mm", "deg", 1000.0, 180.0 / math.pi)
    cols, data = convert(["input_m", "x_rad_m_s", "a_m_rad_s2", "T_N_m", "J_Fx_N", "result"],
                         np.array([[0.3e-3, 1.0, 1.0, 2.0, 5.0, 0.0]]), mm)
    assert cols == ["input_mm", "x_rad_mm_s", "a_m_deg_s2", "T_N_mm", "J_Fx_N", "result"]
    assert data[0].tolist() == [0.3, 1000.0, 180.0 / math.pi, 2000.0, 5.0, 0.0]  # the input as asked: 0.3
    rad = FileUnits("m", "rad", 1.0, 1.0)
    cols, data = convert(["input_deg", "phi_rad"], np.array([[180.0, 1.0]]), rad)
    assert cols == ["input_rad", "phi_rad"] and data[0].tolist() == [math.pi, 1.0]


def test_layer_names_are_distinct_in_a_dxf():
    taken = ["PATH_P"]
    assert export.layer_name("PATH_", "p", taken) == "PATH_p_2"
    assert export.layer_name("JOINT_PATH_", "A/B", taken) == "JOINT_PATH_A_B"


def test_export_refuses_a_picture_format(tmp_path, capsys):
    code, _, stderr = run(capsys, "kinematics", "four-bar", "--export", str(tmp_path / "x.png"))
    assert code == 2 and "--export" in stderr and ".dxf, .svg" in stderr


def test_a_sketch_is_exported_in_its_sketched_pose(tmp_path, capsys):
    """A sketch drawn with its crank at 40° is exported in that pose (the joints where the file puts
    them), not at the table's first input (0°); its paths are still the table's. The pose closes the
    loop: B is on the coupler circle about A and the rocker circle about B0 (numpy, here)."""
    a, b, c, d = 20.0, 60.0, 45.0, 55.0
    A = a * np.array([math.cos(math.radians(40)), math.sin(math.radians(40))])
    B0 = np.array([d, 0.0])
    e = B0 - A
    L = np.hypot(*e)
    along = (b * b - c * c + L * L) / (2 * L)
    B = A + along * e / L + math.sqrt(b * b - along * along) * np.array([-e[1], e[0]]) / L  # the upper branch
    text = f"""
[mechanism]
name = "posed"
length_unit = "mm"
angle_unit = "deg"

[sketch]
frame = ["A0", "B0"]

[sketch.input]
crank = "crank"

[sketch.joints]
A0 = [0, 0]
B0 = [{d!r}, 0]
A = [{float(A[0])!r}, {float(A[1])!r}]
B = [{float(B[0])!r}, {float(B[1])!r}]

[sketch.links]
crank = ["A0", "A"]
coupler = ["A", "B"]
rocker = ["B0", "B"]
"""
    src, dxf = tmp_path / "posed.toml", tmp_path / "posed.dxf"
    src.write_text(text, encoding="utf-8")
    code, stdout, err = run(capsys, "kinematics", str(src), "--outputs", "position", "--export", str(dxf))
    assert code == 0, err
    msp = ezdxf.readfile(dxf).modelspace()
    joints = sorted(tuple(np.round(ci.dxf.center, 9)[:2] + 0.0) for ci in msp.query('CIRCLE[layer=="JOINTS"]'))
    assert joints == sorted(tuple(np.round(v, 9) + 0.0) for v in (A, B))
    crank_path = [np.array(p.get_points("xy")) for p in msp.query("LWPOLYLINE") if p.dxf.layer == "PATH_A"]
    assert len(crank_path) == 1 and np.allclose(crank_path[0][0], [a, 0.0], atol=1e-9)  # the table starts at 0°
