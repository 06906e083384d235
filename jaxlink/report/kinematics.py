"""The kinematics table of the command line (`jaxlink kinematics`): its rows, CSV file and summary.

Columns (units in the names): `input_deg` (or `input_m` for a length input), as asked for; each
unknown `NAME_rad` or `NAME_m`, with `NAME_rad_s`, `NAME_rad_s2` (or `NAME_m_s`, `NAME_m_s2`) when
the joint-variable rates are asked for: q̇ = μ ω and q̈ = ν ω² at constant input speed ω, from the
transfer functions μ = dq/dφ, ν = d²q/dφ² (`jaxlink/analysis/transfer.py`); for each point P:
`P_x_m`, `P_y_m` [, `P_vx_m_s`, `P_vy_m_s`] [, `P_ax_m_s2`, `P_ay_m_s2`]; then `converged` (1/0),
`residual_m` (max |Φ| at the returned q) and `result` (the name of the solver's code, `RESULTS`);
only where a change point was located between two rows (`jaxlink.branch_points`):
`change_point_deg` (`_m` for a length input), its input on the row nearest to it, `nan` on the
others; only where a gap was located (both rows assembled, the linkage not between them: two
toggles the rows step over): `gap_from_deg` and `gap_to_deg` (`_m`), its two toggles in the rows'
order, on the row before it (files of paths without either keep their columns).

Positions that did not assemble (result neither `converged` nor `singular`) are not data: every
solved quantity of their row is `nan`; at a `singular` position (a dead centre or toggle, assembled
to about √eps) the positions are given and the rates, velocities and accelerations (unbounded
there) are `nan`. Summaries leave `nan` out; plots break their lines there (`jaxlink/report/plot.py`).

The table is computed in SI (the input column as asked); `write_csv` and `print_summary` take
`units` to write it in the file's units (`jaxlink/report/units.py`: `P_x_mm`, `phi3_deg_s2`, …).
"""

from __future__ import annotations

import csv
import dataclasses
import sys
from typing import TextIO

import jax
import jax.numpy as jnp
import numpy as np

from ..analysis import precision as _precision
from ..analysis.transfer import transfer
from ..cache import traced
from ..model.mechanism import Mechanism
from ..results import RESULTS, Solution
from ..solvers import branch_points as _branch_points
from ..solvers import dyads as _dyads
from ..solvers.assemble import solve
from ..solvers.options import NewtonOptions, default_rtol
from . import grid as _grid
from .units import FileUnits, convert, input_unit_text

OUTPUTS = ("position", "velocity", "acceleration", "rates")
"""What `kinematics_table` can add to the positions: point velocities and accelerations, and the
rates of the unknowns (both their first and second time derivatives)."""

STATUS_COLUMNS = ("converged", "residual_m", "result")


@dataclasses.dataclass
class KinematicsTable:
    """One row per input position; `columns` name the columns of `data` (units in the names; the
    `result` column holds the code, written by its name).

    - `inputs` (N,) SI; `input_kind` "angle" | "length"; `periodic`: one full revolution.
    - `q` (N, n) as solved (finite everywhere); `points` (N, n_points, 2), `velocities`,
      `accelerations` (or None): NaN where not assembled (velocities, accelerations also where
      not converged).
    - `assembled`, `converged` (N,) bool; `result` (N,) codes.
    - `omega` rad/s (m/s for a length input); `rpm` as given (or None); `parameters` SI.
    """

    columns: list
    data: np.ndarray
    converged: np.ndarray
    assembled: np.ndarray
    result: np.ndarray
    inputs: np.ndarray
    input_kind: str
    periodic: bool
    q: np.ndarray
    points: np.ndarray
    velocities: np.ndarray | None
    accelerations: np.ndarray | None
    omega: float
    rpm: float | None
    parameters: np.ndarray
    branch_points: list = dataclasses.field(default_factory=list)
    change_points: str = "keep"

    def column(self, name: str) -> np.ndarray:
        return self.data[:, self.columns.index(name)]

    @property
    def input_values(self) -> np.ndarray:
        """The input column as printed (degrees or metres)."""
        return self.data[:, 0]

    def speed_text(self, units: FileUnits | None = None) -> str:
        """`600 rpm (ω = 62.83 rad/s)`, `ω = 1 rad/s`, or for a length input `v = 0.05 m/s`
        (`units`: in the file's units, `ω = 57.3 deg/s`, `v = 50 mm/s`)."""
        unit, factor = ("rad/s" if self.input_kind == "angle" else "m/s"), 1.0
        if units is not None:
            unit, factor = units.speed(self.input_kind)
        omega = self.omega * factor
        if self.input_kind != "angle":
            return f"v = {omega:g} {unit}"
        if self.rpm is not None:
            return f"{self.rpm:g} rpm (ω = {omega:.4g} {unit})"
        return f"ω = {omega:g} {unit}"


def kinematics_table(mech: Mechanism, phis, *, omega: float = 1.0, outputs=OUTPUTS[:3], p=None,
                     dtype=np.float64, input_values=None, rpm: float | None = None,
                     change_points: str = "keep") -> KinematicsTable:
    """Solve the positions at `phis` (SI) and what `outputs` (a subset of `OUTPUTS`) asks for at
    constant input speed `omega`. `input_values`: the input column as asked for (degrees for an
    angle input, metres for a length input; default `phis` converted); `rpm`: the speed as given;
    `change_points`: `"keep"` or `"smooth"` (`NewtonOptions.change_points`). The branch points
    located between consecutive rows are in `branch_points` (`located_branch_points`)."""
    outputs = tuple(outputs)
    for o in outputs:
        if o not in OUTPUTS:
            raise ValueError(f"unknown output {o!r}; choose from {', '.join(OUTPUTS)}")
    order = 2 if {"acceleration", "rates"} & set(outputs) else (1 if "velocity" in outputs else 0)
    p = np.asarray(mech.parameters if p is None else p, dtype=dtype)
    phis_a = np.asarray(phis, dtype=dtype)
    q, points, raw, resid, mu_, nu_, dpts, ddpts, scale, cand, sides, margin = _traced_arrays(
        mech, phis_a, p, order, change_points)
    result = _checked(np.asarray(raw).copy(), np.asarray(resid, dtype=float), float(scale), p)
    resid = np.asarray(resid, dtype=float)
    q = np.asarray(q)  # in the dtype of the solve (the drawing measures its rounding)
    v = a = mu = nu = None
    if order:
        with np.errstate(all="ignore"):
            mu = np.asarray(mu_, dtype=float) * omega
            v = np.asarray(dpts, dtype=float) * omega
            if order == 2:
                nu = np.asarray(nu_, dtype=float) * omega**2
                a = np.asarray(ddpts, dtype=float) * omega**2
        # finiteness is part of convergence: rates, velocities or accelerations that are not finite
        # (a NaN speed, lengths so small that Φ_q underflows) make the position `nonfinite`
        finite = np.ones(len(result), bool)
        for x in (mu, v, nu, a):
            if x is not None:
                finite &= np.all(np.isfinite(x.reshape(len(result), -1)), axis=1)
        result = np.where((result == RESULTS.converged) & ~finite, RESULTS.nonfinite, result).astype(result.dtype)
    # float32 too near a singular position for its tolerance (`jaxlink.analysis.precision`)
    solved = result
    near = _precision.imprecise(margin, order, p.dtype) & (result == RESULTS.converged)
    result = np.where(near, RESULTS.imprecise, result).astype(result.dtype)
    conv = result == RESULTS.converged
    assembled = _assembled(result)
    pts = np.where(assembled[:, None, None], np.asarray(points, dtype=float), np.nan)
    if order:
        assert mu is not None and v is not None
        mu = np.where(conv[:, None], mu, np.nan)
        v = np.where(conv[:, None, None], v, np.nan)
        if order == 2:
            assert nu is not None and a is not None
            nu = np.where(conv[:, None], nu, np.nan)
            a = np.where(conv[:, None, None], a, np.nan)
    if input_values is None:
        input_values = (np.rad2deg(np.asarray(phis, dtype=float)) if mech.input_kind == "angle"
                        else np.asarray(phis, dtype=float))
    cols = ["input_deg" if mech.input_kind == "angle" else "input_m"]
    data = [np.asarray(input_values, dtype=float)]
    q_shown = np.where(assembled[:, None], q.astype(float), np.nan)
    for j, (n, k) in enumerate(zip(mech.unknown_names, mech.unknown_kinds)):
        unit = "rad" if k == "angle" else "m"
        cols.append(f"{n}_{unit}")
        data.append(q_shown[:, j])
        if "rates" in outputs:
            assert mu is not None and nu is not None
            cols += [f"{n}_{unit}_s", f"{n}_{unit}_s2"]
            data += [mu[:, j], nu[:, j]]
    for i, pn in enumerate(mech.point_names):
        cols += [f"{pn}_x_m", f"{pn}_y_m"]
        data += [pts[:, i, 0], pts[:, i, 1]]
        if "velocity" in outputs:
            assert v is not None
            cols += [f"{pn}_vx_m_s", f"{pn}_vy_m_s"]
            data += [v[:, i, 0], v[:, i, 1]]
        if "acceleration" in outputs:
            assert a is not None
            cols += [f"{pn}_ax_m_s2", f"{pn}_ay_m_s2"]
            data += [a[:, i, 0], a[:, i, 1]]
    cols += list(STATUS_COLUMNS)
    data += [conv.astype(float), np.asarray(resid, dtype=float), result.astype(float)]
    # the candidates of the stored program hold for the solver's codes; where the re-check changed
    # which rows are assembled, `branch_points` computes them again
    same = np.array_equal(_assembled(np.asarray(raw)), _assembled(result))
    located = located_branch_points(mech, phis_a, q, solved, p, np.asarray(input_values, dtype=float),
                                    (cand, sides) if same else None)
    cols, data = _branch_point_columns(mech, located, cols, data)
    return KinematicsTable(
        cols, np.stack(data, axis=1), conv, assembled, result, np.asarray(phis, dtype=float),
        mech.input_kind, _grid.full_turn(phis, mech.input_kind), q, pts,
        v if "velocity" in outputs else None, a if "acceleration" in outputs else None,
        float(omega), rpm, p, located, change_points)


@dataclasses.dataclass(frozen=True)
class BranchPoint:
    """A branch point located between rows `row` and `row + 1`: `value` as the input column prints
    it (degrees or metres), `kind` ("change point", "toggle" or "gap"), `dyad` (index in solve
    order), `smooth` (a change point crossed on the branch whose velocity is continuous), `nearest`
    (the row nearest to it; for a gap, `row`). A gap runs from the toggle `value` to the toggle
    `end` (in the rows' order): the dyad cannot be assembled between them, both rows can."""

    value: float
    kind: str
    dyad: int
    row: int
    smooth: bool
    nearest: int
    label: str = ""  # the dyad as the file names it: its loop and its two unknowns
    closing: bool = False  # between the last row and the first (a full turn)
    end: float | None = None  # a gap's second toggle


def _assembled(result):
    """Whether a row's loops closed: `converged`, `singular`, or `imprecise` (float32 near a
    singular position: its position given, its rates not)."""
    return (result == RESULTS.converged) | (result == RESULTS.singular) | (result == RESULTS.imprecise)


def located_branch_points(mech: Mechanism, phis, q, result, p, input_values, candidates=None) -> list:
    """The branch points between consecutive rows (`jaxlink.branch_points`), in row order; over a
    full turn also between the last row and the first (`row` the last, `nearest` either).
    `candidates`: its first stage's `(candidates, sides)` when already computed (the stored program
    of the table computes them)."""
    from ..solvers.branch_points import KINDS, branch_points

    n = len(np.asarray(phis))
    wrap = _grid.full_turn(phis, mech.input_kind)
    phis, q, result = _closing(np.asarray(phis), np.asarray(q), np.asarray(result), wrap)
    vals = np.asarray(input_values, dtype=float)
    if wrap:
        vals = np.concatenate([vals, vals[:1] + 360.0 * np.sign(vals[-1] - vals[0])])
    sol = Solution(q=jnp.asarray(q), points=None, result=jnp.asarray(result), stats=None)  # type: ignore[arg-type]
    bp = branch_points(mech, phis, sol, p, candidates=candidates)
    out = []
    phis = np.asarray(phis, dtype=float)

    def printed(k, x):  # as printed: the input column's unit, by the same map as the rows (degrees or metres)
        span = phis[k + 1] - phis[k]
        t = (x - phis[k]) / span if span != 0 else 0.0
        return float(vals[k] + t * (vals[k + 1] - vals[k]))

    for k, j in np.argwhere(bp.kind != 0):
        x = float(bp.input[k, j])
        kind = KINDS[int(bp.kind[k, j])]
        nearest = int(k if abs(x - phis[k]) <= abs(x - phis[k + 1]) or kind == "gap" else k + 1) % n
        end = printed(k, float(bp.end[k, j])) if kind == "gap" else None
        out.append(BranchPoint(printed(k, x), kind, int(j), int(k), bool(bp.smooth[k, j]), nearest,
                               _dyad_label(mech, int(j)), bool(k + 1 == n), end))
    return out


def _dyad_label(mech: Mechanism, j: int) -> str:
    """`loop 'D' (eps, zeta)`: the loop of dyad j (solve order) and the unknowns it solves."""
    from ..solvers.dyads import classify

    dyads = classify(mech)
    if dyads is None or j >= len(dyads):
        return f"dyad {j + 1}"
    d = dyads[j]
    return f"loop '{mech.loops[d.loop][0]}' ({', '.join(mech.unknown_names[i] for i in d.unknowns)})"


def _branch_point_columns(mech: Mechanism, located: list, cols: list, data: list):
    """`change_point_deg` (`_m` for a length input), added only where some change point was
    located: on the row nearest to each, its input; nan elsewhere. `gap_from_deg`, `gap_to_deg`
    only where some gap was located: on the row before each, its two toggles. (A toggle is not a
    column: the rows past it are already `cannot_assemble`; the summary and the warning name it.)"""
    unit = "deg" if mech.input_kind == "angle" else "m"
    n = len(data[0])
    here = [b for b in located if b.kind == "change point"]
    if here:
        col = np.full(n, np.nan)
        for b in here:
            col[b.nearest] = b.value
        cols, data = cols + [f"change_point_{unit}"], data + [col]
    gaps = [b for b in located if b.kind == "gap"]
    if gaps:
        lo, hi = np.full(n, np.nan), np.full(n, np.nan)
        for b in gaps:
            lo[b.row % n], hi[b.row % n] = b.value, b.end
        cols, data = cols + [f"gap_from_{unit}", f"gap_to_{unit}"], data + [lo, hi]
    return cols, data


def gaps(table_or_list) -> list:
    """The located gaps (`BranchPoint`s of kind "gap"): where the linkage cannot be driven from one
    row to the next although both assemble."""
    return [b for b in getattr(table_or_list, "branch_points", table_or_list) if b.kind == "gap"]


def branch_point_text(table_or_list, input_kind: str, change_points: str = "keep",
                      units: FileUnits | None = None) -> list:
    """One line per located branch point: where (`units`: in the file's units), and which branch
    the solve continues on."""
    located = getattr(table_or_list, "branch_points", table_or_list)
    unit, factor = input_unit_text(input_kind, units)
    lines = []
    for b in located:
        who = b.label or f"dyad {b.dyad + 1}"
        rows = "the last row and the first" if b.closing else f"rows {b.row + 1} and {b.row + 2}"
        where = f"{b.kind} at input {b.value * factor:.10g}{unit} ({who}, between {rows})"
        if b.kind == "gap":
            assert b.end is not None
            lines.append(f"gap from input {b.value * factor:.10g}{unit} to {b.end * factor:.10g}{unit} ({who}, "
                         f"between {rows}): the linkage cannot be assembled there, two toggles (limit positions) "
                         "between two rows that assemble; it cannot be driven from one row to the other (no "
                         "--change-points continues through it)")
        elif b.kind == "toggle":
            lines.append(f"{where}: a limit position, the linkage cannot be driven past it")
        elif b.smooth:
            lines.append(f"{where}: the solve continues smoothly through it (the branch whose velocity is "
                         "continuous; --change-points keep to stay on the dyad's side)")
        else:
            lines.append(f"{where}: the solve keeps the dyad's side and continues on the other branch (its "
                         "velocity jumps here); --change-points smooth to continue smoothly")
    return lines


def _closing(phis, q, result, wrap: bool):
    """(phis, q, result) with the first row again after the last, one revolution on, when `wrap`
    (a full turn: the interval from the last row back to the first is checked too)."""
    if not wrap:
        return phis, q, result
    xp = jnp if isinstance(phis, jax.Array) else np
    turn = 2 * np.pi * xp.sign(phis[-1] - phis[0])
    return (xp.concatenate([phis, phis[:1] + turn]), xp.concatenate([q, q[:1]]),
            xp.concatenate([result, result[:1]]))


def _arrays(mech: Mechanism, phis, p, order: int, change_points: str, wrap: bool):
    """The table's whole computation as one function of (mech, phis, p): the solve with its points,
    the residual at the returned q, the transfer functions up to `order` (empty when not asked),
    the length scale of the tolerance, and the branch-point candidates between consecutive rows
    (`branch_points`' cheap first stage: the intervals where one may lie, and each row's sides;
    with `wrap`, also from the last row back to the first)."""
    sol = solve(mech, phis, p=p, options=NewtonOptions(change_points=change_points))
    # the residual at the returned q, for every row (the solver's own is measured where it stopped)
    resid = jax.vmap(lambda qq, ph: jnp.max(jnp.abs(mech.residual(qq, ph, p))))(sol.q, phis)
    empty: jax.Array | None = jnp.zeros((0,), p.dtype)
    mu = nu = dpts = ddpts = empty
    if order:
        tr = transfer(mech, phis, sol.q, p=p, order=order)
        mu, dpts = tr.mu, tr.dpoints
        if order == 2:
            nu, ddpts = tr.nu, tr.ddpoints
    phis_c, q_c, result_c = _closing(phis, sol.q, sol.result, wrap)
    cand, sides = _branch_points.candidates(mech, phis_c, q_c, p, result_c)
    # the least reach margin of each row (S = sin² between a dyad's links; NaN without dyads)
    dyads = _dyads.classify(mech)
    n = phis.shape[0]
    if dyads:
        margin = jax.vmap(lambda sg, qq, ph: jnp.min(_dyads.reach_margins(mech, dyads, sg, qq, ph, p)))(
            sides[:n], sol.q, phis)
    else:
        margin = jnp.full((n,), jnp.nan, p.dtype)
    return (sol.q, sol.points, sol.result, resid, mu, nu, dpts, ddpts, mech.length_scale(p), cand, sides,
            margin)


def _traced_arrays(mech: Mechanism, phis, p, order: int, change_points: str = "keep"):
    """`_arrays` through jaxlink's stored traces (`jaxlink/cache.py`): a repeated command with the
    same structure, sizes and dtype traces nothing. The mechanism is an argument of the stored
    program (its guesses choose the branch), never a constant inside it."""
    guess = np.asarray(mech.guess, dtype=np.asarray(p).dtype)
    wrap = _grid.full_turn(phis, mech.input_kind)
    return traced("kinematics_table", _arrays, (mech.replace(parameters=p, guess=guess), phis, p),
                  (order, change_points, wrap))


def _checked(result, resid, scale: float, p):
    """The solver's codes, re-checked: an assembled row whose residual at the returned q is not
    finite is `nonfinite`, one whose residual exceeds twice the tolerance (rtol × length scale;
    max(rtol, √eps) × scale at a `singular` row) is `max_steps` — whatever the solver's stopping
    rule said."""
    dtype = np.asarray(p).dtype
    rtol = default_rtol(dtype)
    loose = max(rtol, float(np.sqrt(np.finfo(dtype).eps)))
    limit = 2.0 * scale * np.where(result == RESULTS.singular, loose, rtol)
    assembled = (result == RESULTS.converged) | (result == RESULTS.singular)
    out = np.where(assembled & ~np.isfinite(resid), RESULTS.nonfinite, result)
    out = np.where(assembled & np.isfinite(resid) & ~(resid <= limit), RESULTS.max_steps, out)
    return out.astype(result.dtype)


def write_csv(out, table: KinematicsTable, units: FileUnits | None = None) -> None:
    """The table as CSV to `out`: a path, `-` (standard output) or an open text file. Numbers are
    printed exactly (shortest round-trip), `nan` where not data; `result` by name. `units`: the
    columns in the file's units (`jaxlink/report/units.py`; default SI)."""
    if isinstance(out, str):
        if out == "-":
            _write_rows(sys.stdout, table, units)
            return
        with open(out, "w", newline="") as fh:
            _write_rows(fh, table, units)
        return
    _write_rows(out, table, units)


def _write_rows(fh: TextIO, table: KinematicsTable, units: FileUnits | None = None) -> None:
    columns, data = convert(table.columns, table.data, units)
    w = csv.writer(fh, lineterminator="\n")
    w.writerow(columns)
    ic, ir = columns.index("converged"), columns.index("result")
    for row in data:
        out = ["nan" if np.isnan(x) else repr(float(x)) for x in row]
        out[ic] = str(int(row[ic]))
        out[ir] = RESULTS.name(int(row[ir]))
        w.writerow(out)


def write_json(path: str, mech: Mechanism, table: KinematicsTable, units: FileUnits | None = None,
               designer: dict | None = None) -> None:
    """The run's summary as JSON to `path` (`-`: standard output): the input and speed, how many
    positions converged (per result code), every column's least and largest value over the
    assembled rows (named and valued as in the CSV: `units`), the branch points located between
    rows (`branch_points_json`) and `designer` (the designer's numbers,
    `jaxlink.report.designer.to_json`, or null)."""
    import json

    columns, data = convert(table.columns, table.data, units)
    rows = table.assembled
    cols = {}
    for j, name in enumerate(columns):
        if name in ("converged", "result"):
            continue
        col = data[rows, j]
        col = col[np.isfinite(col)]
        cols[name] = {"min": float(col.min()) if col.size else None, "max": float(col.max()) if col.size else None}
    codes, counts = np.unique(table.result, return_counts=True)
    doc = {
        "mechanism": mech.name,
        "file": mech.file,
        "units": "si" if units is None else "file",
        "input": {"name": mech.input_name, "kind": table.input_kind, "column": columns[0],
                  "first": float(data[0, 0]), "last": float(data[-1, 0]), "count": int(len(data))},
        "speed": {"omega_rad_s" if table.input_kind == "angle" else "speed_m_s": float(table.omega),
                  "rpm": None if table.rpm is None else float(table.rpm)},
        "positions": {"count": int(len(data)), "converged": int(table.converged.sum()),
                      "results": {RESULTS.name(int(c)): int(n) for c, n in zip(codes, counts)}},
        "columns": cols,
        "branch_points": branch_points_json(table, units),
        "designer": designer,
    }
    text = json.dumps(doc, indent=2, allow_nan=False) + "\n"
    if path == "-":
        sys.stdout.write(text)
        return
    with open(path, "w") as fh:
        fh.write(text)


def branch_points_json(table, units: FileUnits | None = None) -> list:
    """The located branch points as JSON objects: `kind` ("change point", "toggle", "gap"),
    `input` (as the input column: degrees, or the length unit of `units`; a gap's first toggle),
    `end` (a gap's second toggle, else null), `dyad` (its loop and unknowns), `rows` (the two rows,
    counted from 1, it lies between) and `smooth` (a change point crossed smoothly)."""
    _, factor = input_unit_text(table.input_kind, units)
    n = len(table.data)
    return [{"kind": b.kind, "input": b.value * factor, "end": None if b.end is None else b.end * factor,
             "dyad": b.label, "rows": [b.row + 1, (b.row + 1) % n + 1], "smooth": b.smooth}
            for b in table.branch_points]


def failure_summary(table: KinematicsTable) -> str:
    """`19 × cannot_assemble at 135°–225°: <what to do>` for every code other than converged."""
    return _grid.failure_text(table.result, table.input_values, table.input_kind, table.periodic)


def print_summary(table: KinematicsTable, out: TextIO, every_row_hint: bool = True,
                  units: FileUnits | None = None) -> None:
    """Counts, the largest residual of the converged rows, and min/max of every column over the rows
    where it is data (positions that did not assemble are left out). `units`: in the file's units
    (the columns as `write_csv` names them; default SI)."""
    n = len(table.data)
    columns, data = convert(table.columns, table.data, units)
    rates = any(c.endswith(("_s", "_s2")) for c in columns)
    speed = f" at {table.speed_text(units)}" if rates else ""
    lu = "m" if units is None else units.length
    resid = data[:, columns.index(f"residual_{lu}")][table.converged]
    rtext = f", max residual {resid.max():.2e} {lu}" if resid.size else ""
    out.write(f"{n} positions{speed}, {int(table.converged.sum())} converged{rtext}\n")
    missing = int((~table.assembled).sum())
    if missing:
        out.write(f"{missing} positions not assembled (nan in the table, left out below)\n")
    vague = int((table.result == RESULTS.imprecise).sum())
    if vague:
        out.write(f"{vague} positions imprecise (float32 too near a change point, toggle or dead centre for its "
                  "tolerance: positions given, rates nan; --dtype float64)\n")
    width = max(len(c) for c in columns)
    out.write(f"{'column':<{width}}  {'min':>14} {'max':>14}\n")
    for j, c in enumerate(columns):
        if c in ("converged", "result", f"residual_{lu}") or c.startswith(("change_point_", "gap_")):
            continue
        col = data[:, j]
        col = col[np.isfinite(col)]
        if col.size:
            out.write(f"{c:<{width}}  {col.min():14.6g} {col.max():14.6g}\n")
        else:
            out.write(f"{c:<{width}}  {'nan':>14} {'nan':>14}\n")
    for line in branch_point_text(table, table.input_kind, table.change_points, units):
        out.write(line + "\n")
    if every_row_hint:
        out.write("(use --csv OUT to write every row)\n")


def plot_kinematics(path: str, mech: Mechanism, table: KinematicsTable) -> None:
    """See `jaxlink/report/plot.py`."""
    from .plot import plot_kinematics as _plot

    _plot(path, mech, table)


def animate(path: str, mech: Mechanism, table: KinematicsTable, fps: int = 15, progress: bool = True) -> None:
    """See `jaxlink/report/plot.py`."""
    from .plot import animate as _animate

    _animate(path, mech, table, fps=fps, progress=progress)
