"""The command line: scenes, check, kinematics (CSV columns and units, --outputs, --set, plots)."""

import csv
import subprocess
import sys

import numpy as np
from closed_forms import slider_crank_offset


def run(*args):
    return subprocess.run([sys.executable, "-m", "jaxlink.cli", *args], capture_output=True, text=True)


def test_scenes_lists_the_builtin_scenes():
    r = run("scenes")
    assert r.returncode == 0
    names = {line.split()[0] for line in r.stdout.splitlines()}
    assert {"four-bar", "slider-crank", "sewing-feed", "needle-arachne", "needle-arachne-original"} <= names


def test_check_reports_structure():
    r = run("check", "sewing-feed")
    assert r.returncode == 0, r.stderr
    assert "unknowns    4: phi3 (angle), phi4 (angle), phi5 (angle), phi6 (angle)" in r.stdout
    assert "loops       2 independent" in r.stdout
    assert "mobility    1" in r.stdout
    assert "assembly    at the start: converged" in r.stdout


def test_kinematics_csv_columns_and_values(tmp_path):
    out = tmp_path / "sc.csv"
    r = run("kinematics", "slider-crank", "--rpm", "600", "--step", "10", "--csv", str(out),
            "--set", "h2=30")
    assert r.returncode == 0, r.stderr
    rows = list(csv.reader(open(out)))
    assert rows[0] == ["input_deg", "psi13_rad", "p14_m", "A_x_m", "A_y_m", "A_vx_m_s", "A_vy_m_s",
                       "A_ax_m_s2", "A_ay_m_s2", "B_x_m", "B_y_m", "B_vx_m_s", "B_vy_m_s", "B_ax_m_s2",
                       "B_ay_m_s2", "converged", "residual_m", "result"]
    assert all(r[-1] == "converged" for r in rows[1:])
    data = np.array([r[:-1] for r in rows[1:]], dtype=float)
    assert data.shape == (36, 17)
    phis = np.deg2rad(data[:, 0])
    _, p14 = slider_crank_offset(0.012, np.pi / 2, 0.030, 0.080, 0.0, phis)  # h2 = 30 mm via --set
    assert np.abs(data[:, 2] - p14).max() < 1e-13
    # crank pin A moves on a circle at omega = 600 rpm: |v| = omega * h2, |a| = omega² h2
    w = 600 * 2 * np.pi / 60
    assert np.allclose(np.hypot(data[:, 5], data[:, 6]), w * 0.030, rtol=1e-12)
    assert np.allclose(np.hypot(data[:, 7], data[:, 8]), w * w * 0.030, rtol=1e-12)
    assert np.all(data[:, 15] == 1) and np.all(data[:, 16] < 1e-15)


def test_kinematics_positions_only_and_plot(tmp_path):
    out = tmp_path / "f.csv"
    png = tmp_path / "f.png"
    r = run("kinematics", "four-bar", "--outputs", "position", "--start", "10", "--step", "30",
            "--count", "4", "--csv", str(out), "--plot", str(png))
    assert r.returncode == 0, r.stderr
    rows = list(csv.reader(open(out)))
    assert rows[0] == ["input_deg", "phi3_rad", "phi4_rad", "P_x_m", "P_y_m", "converged", "residual_m", "result"]
    assert [float(x[0]) for x in rows[1:]] == [10.0, 40.0, 70.0, 100.0]
    assert png.stat().st_size > 10_000


def test_kinematics_reports_unreachable_positions(tmp_path):
    out = tmp_path / "nb.csv"
    r = run("kinematics", "four-bar", "--set", "b=40", "--set", "c=30", "--csv", str(out))
    assert r.returncode == 1
    assert "did not converge" in r.stderr and "cannot_assemble at 135°–225°" in r.stderr
    rows = list(csv.reader(open(out)))
    conv = np.array([float(x[rows[0].index("converged")]) for x in rows[1:]])
    assert 0 < conv.sum() < len(conv)
    # a row that did not converge is not data (tests/test_report.py checks every column)
    assert all(x[rows[0].index("P_x_m")] == "nan" for x, c in zip(rows[1:], conv) if c == 0)
