"""An independent numpy/scipy reference solution of the sinker model (needs scipy, a dev
dependency). Used by the tests and `experiments/sinker_jamming.py` only.

Cam track and right-hand side are re-derived here from the formulas (no JAX code is
shared), and the integration is scipy's `solve_ivp` (DOP853 by default) at tight
tolerances, restarted at every cam piece boundary and at every contact change, which is
located by a terminal, directional event on `y_z - y = 0`; `max_step` keeps events from being
stepped over.
"""

from __future__ import annotations

import math

import numpy as np


def cam_pieces(radius, rise, descent, *, length=19.88e-3, split=(5.9, 5.4), speed,
               arc="exact", chord=1e-4):
    """List of pieces `(t_start, kind, x0, y0, a0)`, kind "line" or "arc"; and `t_end`."""
    if arc == "exact":
        x_arc = radius * (math.sin(descent) - math.sin(rise))
        y_arc = radius * (math.cos(rise) - math.cos(descent))
        x1 = (length - x_arc) * split[0] / sum(split)
        y1 = x1 * math.tan(rise)
        pcs = [("line", 0.0, 0.0, rise), ("arc", x1, y1, rise),
               ("line", x1 + x_arc, y1 + y_arc, descent)]
    else:
        arc_len = radius * (descent - rise)
        p = max(1, round(arc_len / chord))
        dl = arc_len / p
        angles = [rise + i * (descent - rise) / p for i in range(1, p + 1)]
        x1 = (length - sum(dl * math.cos(a) for a in angles)) * split[0] / sum(split)
        pcs = [("line", 0.0, 0.0, rise)]
        x, y = x1, x1 * math.tan(rise)
        for a in angles:
            pcs.append(("line", x, y, a))
            x, y = x + dl * math.cos(a), y + dl * math.sin(a)
    return [(x0 / speed, kind, x0, y0, a0) for kind, x0, y0, a0 in pcs], length / speed


def _track(piece, radius, speed, t):
    _, kind, x0, y0, a0 = piece
    dx = speed * t - x0
    if kind == "line":
        a = a0
        yz = y0 + dx * math.tan(a0)
    else:
        a = math.asin(min(0.999, max(-0.999, math.sin(a0) + dx / radius)))
        yz = y0 + radius * (math.cos(a0) - math.cos(a))
    return yz, a, speed * math.tan(a)


def reference_solution(*, radius, rise_deg=30.0, descent_deg, f, C, k_over_m, m=1.5e-3,
                       R_sum=3.2014 + 3.1216 + 6.323, F_P=0.0, g=9.81, n_rpm=350.0,
                       diameter=0.096, arc="exact", ts=None, method="DOP853", rtol=1e-12,
                       atol=1e-15, max_step=2e-6):
    """Integrate the sinker from rest over one cam passage; returns `(ts, Y, info)` with
    `Y[:, 0] = y`, `Y[:, 1] = y'` at `ts` (default 2001 points on `[0, T]`), `info` a dict
    with `nfev`, `events` (number of contact changes) and `event_times` (s)."""
    from scipy.integrate import solve_ivp

    speed = math.pi * n_rpm * diameter / 60.0
    pieces, t_end = cam_pieces(radius, math.radians(rise_deg), math.radians(descent_deg),
                               speed=speed, arc=arc)
    if ts is None:
        ts = np.linspace(0.0, t_end, 2001)
    p1 = (m * g - F_P * (1 + 0.75 * f / 11) - f * R_sum) / m
    p2 = (6 * f**2 / 11 - 156 * f / 36) / m
    p3 = (1 - 120 * f**2 / 36 - 6 * f / 11) / m

    def rhs_factory(piece, contact):
        def rhs(t, u):
            yz, a, yzd = _track(piece, radius, speed, t)
            acc = p1 + k_over_m * (yzd - u[1])
            if contact:
                acc += C * (yz - u[0]) / math.cos(a) * (p2 * math.sin(a) + p3 * math.cos(a))
            return [u[1], acc]
        return rhs

    def event_factory(piece, contact):
        def ev(t, u):
            return _track(piece, radius, speed, t)[0] - u[0]
        ev.terminal = True
        ev.direction = -1 if contact else 1
        return ev

    bounds = [pc[0] for pc in pieces[1:]] + [t_end]
    t, u, contact = 0.0, np.zeros(2), True
    out = np.full((len(ts), 2), np.nan)
    nfev, event_times = 0, []
    for piece, t_stop in zip(pieces, bounds):
        while t < t_stop:
            sol = solve_ivp(rhs_factory(piece, contact), (t, t_stop), u, method=method,
                            rtol=rtol, atol=atol, max_step=max_step, dense_output=True,
                            events=event_factory(piece, contact))
            nfev += sol.nfev
            t_new = sol.t[-1]
            sel = (ts >= t) & (ts <= t_new)
            if sel.any():
                out[sel] = sol.sol(ts[sel]).T
            t, u = t_new, sol.y[:, -1]
            if sol.status == 1:  # contact change
                contact = not contact
                event_times.append(t)
    return np.asarray(ts), out, {"nfev": nfev, "events": len(event_times),
                                 "event_times": event_times}
