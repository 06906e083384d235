"""Command `jaxlink reactions`: joint reactions and the drive (a torque, or a length input's force)
over the input positions.

The table, CSV and plot are made by `jaxlink/report/reactions.py` (its docstring lists the CSV
columns). Rows where the kinematics did not converge or the kinetostatic system is singular hold
`nan` and name their result (and the exit status is 1; the warning lists the input ranges); so is
a gap between two rows that both assemble (the warning names its two toggles).
"""

from __future__ import annotations

import sys

from ..report.reactions import failure_summary, plot, print_summary, reactions_table, write_csv
from .mechanism import (
    CSV_FORMATS,
    PLOT_FORMATS,
    add_change_points_argument,
    add_mechanism_arguments,
    add_units_argument,
    branch_point_warnings,
    check_output,
    enable_dtype,
    grid_text,
    input_grid,
    load_from_args,
    omega_from_args,
    units_from_args,
    writing,
)


def register(sub) -> None:
    p = sub.add_parser(
        "reactions", help="joint reactions and the drive torque (a length input: the drive force)",
        description=(
            "Kinetostatics (d'Alembert): solve the positions, then at every position the linear system of "
            "force and moment balances of all moving bodies (from the file's [bodies], [joints], [loads], "
            "[environment]) for the joint reactions and the drive, at constant input speed. The drive is a "
            "torque for an angle input (a crank), a force along [input] axis for a length input (a "
            "cylinder, a driven slider). CSV columns: input_deg (input_m for a length input); for each joint "
            "J: J_Fx_N, J_Fy_N (force on the second listed body from the first); drive_torque_N_m (on the "
            "input body, counter-clockwise +) or, for a length input, drive_force_N (+ pushes towards a "
            "larger input); result (converged, or why not: the position solve's code such as "
            "cannot_assemble, or singular). Rows that cannot be solved hold nan and make the exit status 1, "
            "as does a gap between two rows (the linkage cannot be assembled between them: two toggles). "
            "Give the speed with --rpm or --omega (default 1 rad/s; a length input: --omega in m/s)."
        ),
    )
    add_mechanism_arguments(p)
    p.add_argument("--csv", metavar="OUT", help="write the table to this CSV file (default: print a summary)")
    add_units_argument(p)
    add_change_points_argument(p)
    p.add_argument("--plot", metavar="OUT.png", help="plot the reaction magnitudes and the drive torque (or force)")
    p.set_defaults(func=cmd_reactions)


def cmd_reactions(args) -> int:
    dtype = enable_dtype(args.dtype)
    check_output("--csv", args.csv, CSV_FORMATS)
    check_output("--plot", args.plot, PLOT_FORMATS)
    from ..model import bodies as _bodies

    mech = load_from_args(args)
    _bodies.model(mech)  # a file without bodies is refused before the solve
    phis, values = input_grid(mech, args)  # the input column exactly as asked (no rad round trip)
    omega = omega_from_args(args, mech)
    units = units_from_args(mech, args)
    table = reactions_table(mech, phis, omega=omega, dtype=dtype, input_values=values,
                            rpm=getattr(args, "rpm", None), change_points=args.change_points)
    gaps = branch_point_warnings(table)
    info = sys.stderr if args.csv == "-" else sys.stdout  # `--csv -`: the table alone on standard output
    print(grid_text(mech, args), file=info)
    if args.csv:
        with writing("--csv", args.csv):
            write_csv(args.csv, table, units)
        if args.csv != "-":
            print(f"wrote {args.csv}: {len(phis)} rows, {len(table.columns)} columns", file=info)
    else:
        print_summary(table, sys.stdout, units)
    if args.plot:
        with writing("--plot", args.plot):
            plot(args.plot, mech, table)
        print(f"wrote {args.plot}", file=info)
    bad = ~table.ok
    if bad.any():
        print(f"warning: {int(bad.sum())} of {len(phis)} positions have no reactions (nan in the table): "
              + failure_summary(table), file=sys.stderr)
        return 1
    return 1 if gaps else 0
