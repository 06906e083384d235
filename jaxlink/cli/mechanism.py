"""Command group for linkages: `jaxlink scenes`, `jaxlink check`, `jaxlink kinematics`.

Also the shared option helpers other linkage commands (reactions, optimize) reuse:
`add_mechanism_arguments`, `load_from_args`, `inputs_from_args`, `input_grid`, `omega_from_args`.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import stat
import sys

import numpy as np

from ..errors import MechanismError

OUTPUTS = ("position", "velocity", "acceleration", "rates")
#: most input positions one command solves (--count, or a revolution of --step)
MAX_POSITIONS = 1_000_000
#: largest input speed |ω| (rad/s; 1e6 rad/s is about 9.5 million rpm)
MAX_OMEGA = 1e6
#: picture formats of --plot (matplotlib's, by the file's extension)
PLOT_FORMATS = ("png", "pdf", "svg", "svgz", "eps", "ps", "jpg", "jpeg", "tif", "tiff", "webp", "pgf")
#: the table formats of --csv (comma-separated text)
CSV_FORMATS = ("csv",)
#: geometry formats of --export (`jaxlink/report/export.py`); `kinematics --plot` takes .dxf too
EXPORT_FORMATS = ("dxf", "svg")


# ----------------------------------------------------------------------------- shared helpers


def enable_dtype(name: str = "float64"):
    """Turn on float64 in JAX if asked (the default for every command); returns the numpy dtype."""
    import jax

    if name == "float64":
        jax.config.update("jax_enable_x64", True)
        return np.float64
    if name == "float32":
        return np.float32
    raise MechanismError(f"--dtype must be float64 or float32, not {name!r}")


def finite(text: str) -> float:
    """argparse type: a finite float (`nan`, `inf`, `1e999` are refused, naming the option)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def check_output(option: str, path: str | None, formats: tuple | None = None) -> None:
    """Refuse, before any work, an output that cannot be written: a folder, a path through a file
    or a missing folder, a place not writable, or (`formats`) an unknown extension (`--csv
    out.xlsx`: the file would hold CSV under another format's name). `-` (standard output) and
    special files (a named pipe, a device) are written to as they are, whatever their name."""
    if path is None or path == "-":
        return
    try:
        st = os.stat(path)
    except FileNotFoundError:
        st = None
    except NotADirectoryError:
        st = None
    except OSError as exc:
        raise MechanismError(f"{option} {path}: {exc.strerror}") from None
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise MechanismError(f"{option} {path}: is a folder; give a file name")
    special = st is not None and not stat.S_ISREG(st.st_mode)
    if formats is not None and not special:
        ext = os.path.splitext(path)[1].lower().lstrip(".")
        if ext not in formats:
            raise MechanismError(f"{option} {path}: unknown format {('.' + ext) if ext else '(no extension)'}; "
                                 f"the file name must end in {_one_of(formats)}")
    if st is not None:
        if not os.access(path, os.W_OK):
            raise MechanismError(f"{option} {path}: not writable")
        return
    parent = os.path.dirname(path) or "."
    if not os.path.exists(parent):
        up = parent
        while up and not os.path.exists(up):  # the part of the path that is there
            up = os.path.dirname(up)
        if up and os.path.exists(up) and not os.path.isdir(up):
            raise MechanismError(f"{option} {path}: '{up}' is a file, not a folder")
        raise MechanismError(f"{option} {path}: the folder '{parent}' does not exist")
    if not os.path.isdir(parent):
        raise MechanismError(f"{option} {path}: '{parent}' is a file, not a folder")
    if not os.access(parent, os.W_OK):
        raise MechanismError(f"{option} {path}: the folder '{parent}' is not writable")


def _one_of(formats: tuple) -> str:
    names = ["." + f for f in formats]
    return names[0] if len(names) == 1 else "one of " + ", ".join(names)


@contextlib.contextmanager
def writing(option: str, path: str):
    """Turn an error while writing an output (a full disk) into a `MechanismError` naming the option
    and the file. An output that is a pipe whose reader went away (`--csv /dev/stdout | head -1`)
    is not one: the rest of it is dropped, nobody reads it, and the command goes on to its other
    outputs (standard output itself: `pipe.py`)."""
    try:
        yield
    except BrokenPipeError:
        return
    except OSError as exc:
        raise MechanismError(f"{option} {path}: cannot write: {exc.strerror or exc}") from None


def add_mechanism_arguments(parser: argparse.ArgumentParser, *, positions: bool = True) -> None:
    """FILE, --set, --dtype and (if `positions`) --rpm/--omega, --start/--step/--count."""
    parser.add_argument("file", metavar="FILE", help="mechanism TOML file, or a built-in scene name")
    parser.add_argument(
        "--set", action="append", default=[], metavar="NAME=VALUE",
        help="override a parameter, in the file's units (repeatable), e.g. --set l2=2.0 --set gamma=-10",
    )
    parser.add_argument("--dtype", default="float64", choices=("float64", "float32"),
                        help="floating-point precision of the solve (default float64)")
    if positions:
        speed = parser.add_mutually_exclusive_group()
        speed.add_argument("--rpm", type=finite,
                           help="input speed in revolutions per minute (an angle input only: refused for a "
                                "length input, whose speed is --omega in m/s)")
        speed.add_argument("--omega", type=finite,
                           help="input speed, SI: rad/s for an angle input, m/s for a length input (default 1: "
                                "velocities and accelerations are then the transfer functions d/dφ, d²/dφ², "
                                "or d/ds, d²/ds²)")
        parser.add_argument("--start", type=finite, default=None,
                            help="first input value: in degrees for an angle input (default 0), in the file's length "
                                 "unit (length_unit) for a length input (default the file's [input] start)")
        parser.add_argument("--step", type=finite, default=None,
                            help="input step, same unit as --start: degrees for an angle input (default 5), the file's "
                                 "length unit for a length input (no default: give --stop, or --step and --count)")
        parser.add_argument("--stop", type=finite, default=None,
                            help="last input value (same unit as --start): with --step it fixes the number of "
                                 "positions (the last one at or before --stop), with --count the spacing; a length "
                                 "input with --stop alone gets 73 positions from --start to --stop")
        parser.add_argument("--count", type=int, default=None,
                            help="number of positions (default: an angle input a full revolution, 360/step; "
                                 "a length input has no default range: give --stop or --count)")


def add_change_points_argument(parser: argparse.ArgumentParser) -> None:
    """--change-points keep|smooth (`NewtonOptions.change_points`)."""
    parser.add_argument("--change-points", default="keep", choices=("keep", "smooth"),
                        help="at a change point located between two positions (two assembly branches crossing, "
                             "e.g. a Peaucellier cell's flat rhombus): 'keep' each dyad's side (default; the path "
                             "goes on along the other branch, its velocity jumps) or 'smooth' (flip the side there: "
                             "the branch whose velocity is continuous)")


def add_units_argument(parser: argparse.ArgumentParser) -> None:
    """--units si|file (`jaxlink/report/units.py`)."""
    parser.add_argument("--units", default="si", choices=("si", "file"),
                        help="units of the CSV and the summary: 'si' (default: m, rad, m/s, rad/s, …; the input in "
                             "degrees) or 'file': the file's length_unit and angle_unit, every column named with its "
                             "unit (P_x_mm, phi3_deg, P_vx_mm_s, phi3_deg_s2, drive_torque_N_mm, …)")


def units_from_args(mech, args):
    """The `FileUnits` of `--units file` (None for `si`)."""
    from ..report.units import file_units

    return file_units(mech) if getattr(args, "units", "si") == "file" else None


def branch_point_warnings(table) -> int:
    """The located branch points as warnings on standard error; returns how many are gaps (the
    command's exit status is then 1: the linkage cannot be driven through the rows asked for)."""
    from ..report.kinematics import branch_point_text, gaps

    for b, line in zip(table.branch_points, branch_point_text(table, table.input_kind, table.change_points)):
        print(f"{'note' if b.smooth else 'warning'}: {line}", file=sys.stderr)
    return len(gaps(table))


def load_from_args(args):
    """The mechanism of FILE with the `--set` overrides applied, the whole file validated: every
    table the reader checks, `[optimize]` as `jaxlink optimize` checks it and the keys of `[study]`
    (for every command, `check` and `kinematics` too; nothing is compiled)."""
    from ..files.overrides import parse_numbers
    from ..files.reader import load
    from ..optimize.problem import check_table

    mech = load(args.file, overrides=parse_numbers(getattr(args, "set", [])))
    check_table(mech)
    if "study" in mech.tables:  # its keys (jaxlink.study is imported only for a file that has one)
        from ..study.inputs import check_study_keys

        check_study_keys(mech)
    return mech


def inputs_from_args(mech, args) -> np.ndarray:
    """Input values (SI) from --start/--step/--stop/--count (degrees for an angle input, the file's
    length unit for a length input)."""
    return input_grid(mech, args)[0]


#: positions of a length input given --stop alone (72 equal steps, as a revolution in 5° steps)
LENGTH_COUNT = 73


def length_unit_name(mech) -> str:
    """The file's length unit as written (m, cm, mm)."""
    return {1.0: "m", 1e-2: "cm", 1e-3: "mm"}.get(mech.units.length, "m")


def grid_values(mech, args) -> np.ndarray:
    """The input values --start/--step/--stop/--count ask for, in the options' unit (degrees for
    an angle input, the file's length unit for a length input), computed in decimal so that they
    print as asked (15.0, not 14.999999999999998). Raises `MechanismError` for a grid that is
    not one: a zero step, a step away from --stop, all three of --step, --count, --stop, a length
    input without a range (it has no default: give --stop, or --step and --count)."""
    from decimal import Decimal

    from ..report.grid import exact_grid

    angle = mech.input_kind == "angle"
    start, step, count = args.start, args.step, args.count
    stop = getattr(args, "stop", None)
    if start is None:
        # a length input from the file's [input] start, as written (12 digits: no SI round-trip noise)
        start = 0.0 if angle else float(f"{float(mech.from_si(mech.input_name, mech.input_start)):.12g}")
    for option, value in (("--start", start), ("--step", step), ("--stop", stop)):
        if value is not None and not math.isfinite(value):
            raise MechanismError(f"{option} {value}: must be a finite number")
    if step is not None and step == 0:
        raise MechanismError("--step must be a non-zero finite number")
    if count is not None and count < 1:
        raise MechanismError(f"--count {count}: must be at least 1")
    if count is not None and count > MAX_POSITIONS:
        raise MechanismError(f"--count {count}: at most {MAX_POSITIONS} positions in one command")
    unit = "°" if angle else " " + length_unit_name(mech)
    if stop is not None:
        if step is not None and count is not None:
            raise MechanismError("--step, --count and --stop: give two of them (with --start), not all three")
        span = Decimal(repr(float(stop))) - Decimal(repr(float(start)))
        if step is None and (count is None and angle):
            step = 5.0 if span >= 0 else -5.0
        if step is not None:
            if span != 0 and (span > 0) != (step > 0):
                raise MechanismError(f"--step {step:g} runs away from --stop {stop:g} (--start {start:g}): give a step "
                                     f"of the other sign")
            n = int(span / Decimal(repr(float(step)))) + 1  # the last position at or before --stop
            if n > MAX_POSITIONS:
                raise MechanismError(f"--start {start:g} to --stop {stop:g} in steps of {step:g} would be {n} "
                                     f"positions, more than {MAX_POSITIONS}; use a larger step")
            vals = exact_grid(start, step, n)
        else:
            n = LENGTH_COUNT if count is None else count
            if n == 1 and span != 0:
                raise MechanismError(f"--count 1 with --stop {stop:g}: one position cannot span --start {start:g} to "
                                     "--stop; give --count 2 or more, or leave out --stop")
            first = Decimal(repr(float(start)))
            vals = np.array([float(first + span * k / max(n - 1, 1)) for k in range(n)])
    elif angle:
        step = 5.0 if step is None else step
        if count is None:
            turn = 360.0 / abs(step)
            if turn > MAX_POSITIONS:
                raise MechanismError(f"--step {step:g}: a revolution would be {turn:.3g} positions, more than "
                                     f"{MAX_POSITIONS}; use a larger step or give --count")
            count = max(1, int(round(turn)))
        vals = exact_grid(start, step, count)
    else:
        if step is None or count is None:
            raise MechanismError(
                f"the input '{mech.input_name}' is a length (a driven slider or cylinder): it has no default range; "
                f"give --stop (the last value, in {length_unit_name(mech)}; {LENGTH_COUNT} positions from --start, "
                f"default the file's [input] start {start:g}), or --step and --count")
        vals = exact_grid(start, step, count)
    from ..files.reader import DOMAINS

    # the inputs in SI within the domain of their kind (the file format's limits)
    limit = DOMAINS[mech.input_kind][1] / (math.pi / 180.0 if angle else mech.units.length)
    for option, value, what in (("--start", vals[0], "the first input"), ("--stop", vals[-1], "the last input")):
        if not abs(value) <= limit:
            given = {"--start": start, "--stop": stop if stop is not None else step}.get(option)
            shown = option if option == "--start" or stop is not None else "--step"
            raise MechanismError(f"{shown} {given:g}: {what} ({value:g}) is out of range: inputs are within "
                                 f"±{limit:g}{unit}")
    return vals


def input_grid(mech, args) -> tuple:
    """`(phis, values)`: the inputs of `grid_values` in SI, and as a table prints them (degrees for
    an angle input, metres for a length input)."""
    vals = grid_values(mech, args)
    if mech.input_kind == "angle":
        return np.deg2rad(vals), vals
    unit = mech.units.length
    inv = 1.0 / unit
    si = vals / inv if float(round(inv)) == inv else vals * unit  # 1.5 mm / 1000 prints as 0.0015
    return si, si


def grid_text(mech, args) -> str:
    """One line saying which inputs a command solves, in the unit of its options:
    `input       s (length) from 40 to 120 mm, step 1 mm: 81 positions`."""
    vals = grid_values(mech, args)
    angle = mech.input_kind == "angle"
    u = "°" if angle else " " + length_unit_name(mech)
    text = f"input       {mech.input_name} ({mech.input_kind}) from {vals[0]:g}{u}"
    if len(vals) > 1:
        step = float(np.round(vals[1] - vals[0], 12))
        text += f" to {vals[-1]:g}{u}, step {step:g}{u}"
    return text + f": {len(vals)} position{'s' if len(vals) != 1 else ''}"


def omega_from_args(args, mech=None) -> float:
    """The input speed (SI) of --rpm or --omega (1 by default), finite and within ±`MAX_OMEGA`:
    rad/s for an angle input, m/s for a length input (`mech` given: --rpm is refused for a length
    input, whose speed is not a number of revolutions)."""
    if mech is not None and mech.input_kind != "angle" and getattr(args, "rpm", None) is not None:
        raise MechanismError(f"--rpm {args.rpm:g}: the input '{mech.input_name}' is a length (a driven slider or "
                             "cylinder), not a crank; give its speed with --omega in m/s")
    for option, value, scale in (("--rpm", getattr(args, "rpm", None), 2.0 * math.pi / 60.0),
                                 ("--omega", getattr(args, "omega", None), 1.0)):
        if value is not None:
            if not (math.isfinite(value) and abs(value * scale) <= MAX_OMEGA):
                limit = MAX_OMEGA / scale
                speed = "rad/s" if mech is None or mech.input_kind == "angle" else "m/s"
                raise MechanismError(f"{option} {value:g}: the input speed must be finite and within ±{limit:.6g}"
                                     + (" rpm" if option == "--rpm" else f" {speed}"))
            return float(value) * scale
    return 1.0


# ----------------------------------------------------------------------------- commands


def register(sub) -> None:
    p = sub.add_parser("scenes", help="list the built-in scenes (--copy NAME: write one's file to edit)",
                       description="List the built-in scenes: name, one-line description and, below, the "
                                   "scene's file. Any FILE argument accepts these names. --copy NAME [DEST] "
                                   "writes a scene's file to edit (DEST: a .toml file or a folder; default "
                                   "NAME.toml here).")
    p.add_argument("--copy", metavar="NAME", default=None,
                   help="write the built-in scene NAME's file to DEST (a .toml file, or a folder: NAME.toml in "
                        "it; default ./NAME.toml), to edit and give as FILE; an existing file is refused "
                        "without --force")
    p.add_argument("dest", metavar="DEST", nargs="?", default=None, help="--copy: where to write the file")
    p.add_argument("--force", action="store_true", help="--copy: overwrite DEST if it exists")
    p.set_defaults(func=cmd_scenes)

    p = sub.add_parser(
        "check", help="check a mechanism file and report its structure",
        description="Validate a mechanism file (every table, [bodies], [joints], [loads], [environment] "
                    "and [optimize], as `optimize` checks it, included) and report parameters (with their "
                    "inferred units), "
                    "unknowns, loops, equations, bodies and joints, mobility and whether the guess "
                    "assembles. "
                    "Exit status 2 with a one-line message naming file, line, key and reason when "
                    "the file is wrong; 1 when it is valid but cannot be assembled at its start.",
    )
    add_mechanism_arguments(p, positions=False)
    p.set_defaults(func=cmd_check)

    p = sub.add_parser(
        "kinematics", help="positions, velocities, accelerations over a revolution",
        description=(
            "Solve the loop equations over the input positions (closed-form dyads where every block "
            "of the structure is a dyad, else Newton with continuation; see `jaxlink check`) and "
            "write one row per position. CSV columns: input_deg (input_m for a length input), as asked "
            "for; each unknown as NAME_rad or NAME_m [with --outputs rates: NAME_rad_s, NAME_rad_s2 or "
            "NAME_m_s, NAME_m_s2]; for each point P: P_x_m, P_y_m [, P_vx_m_s, P_vy_m_s] "
            "[, P_ax_m_s2, P_ay_m_s2]; converged (1/0); residual_m; result (converged, singular, "
            "cannot_assemble, ...). Velocities and accelerations are exact (forward-mode AD, Jacobian "
            "solves) at constant input speed. A position that did not assemble is nan in every solved "
            "column (and is left out of the summary and the plots); at a singular one (dead centre, "
            "toggle) the positions are given and the rates are nan. Exit status 1 when some position "
            "did not converge (the warning lists the input ranges) or the linkage cannot be assembled "
            "between two rows that both assemble (a gap: the warning names its two toggles; columns "
            "gap_from_deg, gap_to_deg). --units file writes the same columns in "
            "the file's length and angle units (P_x_mm, phi3_deg, …); --export OUT.dxf|OUT.svg (or --plot "
            "OUT.dxf) writes the paths and the linkage as geometry in the file's length unit."
        ),
    )
    add_mechanism_arguments(p)
    p.add_argument("--outputs", default="position,velocity,acceleration",
                   help="comma-separated subset of position,velocity,acceleration,rates (default: the first "
                        "three): the points' velocities and accelerations, and 'rates' of the joint variables "
                        "(each unknown's NAME_rad_s, NAME_rad_s2 for an angle, NAME_m_s, NAME_m_s2 for a length: "
                        "a link's angular velocity and acceleration, a slider's speed and acceleration along "
                        "its guide)")
    p.add_argument("--csv", metavar="OUT", help="write the table to this CSV file (default: print a summary)")
    add_units_argument(p)
    add_change_points_argument(p)
    p.add_argument("--plot", metavar="OUT.png",
                   help="plot the point paths and the curves over the input (a picture: .png, .pdf, .svg, …); "
                        "OUT.dxf writes the geometry, as --export does")
    p.add_argument("--export", metavar="OUT.dxf",
                   help="write the geometry in the file's length unit: the traced paths of the points and moving "
                        "joints and the linkage in one pose (a sketch's own, else the first position), as layers of a "
                        "DXF file (.dxf) or groups of "
                        "an SVG file (.svg)")
    p.add_argument("--animate", metavar="OUT.gif", help="animated GIF of the moving linkage")
    p.add_argument("--json", metavar="OUT.json",
                   help="write the summary as JSON: the run, every column's least and largest value (in the CSV's "
                        "units), and with --numbers the designer's numbers (SI)")
    p.add_argument("--whole-curve", action="store_true",
                   help="trace the whole closed curve instead of the input positions: a linkage of dyads whose "
                        "input cannot turn fully runs to a limit position, turns back on the toggling dyad's other "
                        "side, and so on until the curve closes (positions only; --count positions per turn, "
                        "default 720; --csv, --plot, --units apply)")
    p.add_argument("--numbers", action="store_true",
                   help="add the designer's numbers to the summary and the JSON, as `check` prints them (Grashof, "
                        "range of motion, transmission angles, strokes, dead centres, time ratio, velocity ratio): "
                        "a full turn's analysis, one to two seconds more")
    p.set_defaults(func=cmd_kinematics)


def _whole_curve(mech, args) -> int:
    """`kinematics --whole-curve`: the closed curve through the limit positions."""
    for option in ("start", "step", "stop", "rpm", "omega", "export", "animate", "json"):
        if getattr(args, option, None) not in (None, False):
            raise MechanismError(f"--whole-curve traces positions along the whole curve: --{option} does not apply")
    if args.plot and args.plot.lower().endswith(".dxf"):
        raise MechanismError("--plot: --whole-curve draws a picture (.png, .pdf, .svg, …), not a DXF")
    if args.count is not None and not 8 <= args.count <= MAX_POSITIONS:
        raise MechanismError(f"--count {args.count}: positions per turn of the whole curve, 8 to {MAX_POSITIONS}")
    from ..analysis.whole_curve import whole_curve
    from ..report import whole_curve as _report

    wc = whole_curve(mech, samples=args.count or 720)
    if wc is None:
        raise MechanismError("--whole-curve needs a linkage made of dyads (every loop closed in closed form) driven "
                             f"by an angle; '{mech.name}' is not (`jaxlink check` says how it is solved)")
    units = units_from_args(mech, args)
    info = sys.stderr if args.csv == "-" else sys.stdout
    for line in _report.summary(mech, wc):
        print(line, file=info)
    if args.csv:
        with writing("--csv", args.csv):
            _report.write_csv(args.csv, mech, wc, units)
        if args.csv != "-":
            print(f"wrote {args.csv}: {len(wc.input)} rows", file=info)
    if args.plot:
        with writing("--plot", args.plot):
            _report.plot(args.plot, mech, wc)
        print(f"wrote {args.plot}", file=info)
    return 0


def cmd_scenes(args) -> int:
    from ..scenes import copy, describe, named, scene_paths

    if args.copy is not None:
        name, dest = args.copy, args.dest
        src = named(name)
        if dest is not None and not os.path.isdir(dest):
            check_output("--copy", dest, ("toml",))
        written = copy(name, dest, force=args.force)
        print(f"wrote {written} (a copy of {src}): edit it, then e.g. jaxlink check {written}")
        return 0
    if args.force or args.dest is not None:
        raise MechanismError(f"{'--force' if args.force else args.dest!r} goes with --copy NAME [DEST]")
    paths = scene_paths()
    width = max((len(n) for n in paths), default=0)
    for name, path in paths.items():
        print(f"{name:<{width}}  {describe(path)}")
        print(f"{'':<{width}}  {path}")
    return 0


def _print_designer_numbers(mech, lu: str, out=None) -> None:
    """The numbers a designer judges a linkage by (`jaxlink.report.designer`)."""
    from ..report import designer

    fbs, m = designer.compute(mech)
    for line in designer.lines(mech, fbs, m, lu):
        print(line, file=out or sys.stdout)


def _sum_text(terms) -> str:
    """A vector sum as written: `a @ phi + b @ psi - (x, y)`."""
    out = ""
    for t in terms:
        text = t.text.strip()
        if not out:
            out = text
        elif text.startswith("-"):
            out += " - " + text[1:].strip()
        else:
            out += " + " + text.lstrip("+").strip()
    return out


def _start_arrays(mech, phi, p):
    """What `check` computes at `[input] start` (a stored trace: `jaxlink.cache.traced`): the
    solve from the guesses (`q`, result code, residual, Newton steps) and the Jacobian Φ_q there.
    The start is solved as the first of two equal inputs: XLA compiles a solve of one input
    (degenerate shapes) to other instructions, whose last bits can differ from the same input in
    a batch (three of the built-in scenes); as one of two, the numbers are those of every batched
    solve, the first input of `jaxlink.analysis.motion`'s turn included (tests/test_check_start.py)."""
    import jax
    import jax.numpy as jnp

    from ..solvers.assemble import solve

    sol = solve(mech, jnp.stack([phi, phi]), p, points=False)
    q = sol.q[0]
    return q, sol.result[0], sol.residual[0], sol.steps[0], jax.jacfwd(mech.residual)(q, phi, p)


def _at_start(mech, dtype) -> tuple:
    """`(q, result code, residual, Newton steps, Jacobian)` at `[input] start` (numpy), solved in
    `dtype`: a linkage of dyads driven by an angle takes it from the designer's numbers' turn (its
    first input, in their dtype: the same numbers as the start solved alone); else the start alone
    (`_start_arrays`, a stored trace)."""
    import jax

    from ..analysis import motion as _motion
    from ..cache import traced

    p = np.asarray(mech.parameters, dtype)  # the solve in the asked dtype
    at_start = _motion.start(mech) if p.dtype == jax.dtypes.canonicalize_dtype(np.float64) else None
    if at_start is None:
        at_start = traced("check_start", _start_arrays, (
            mech.replace(parameters=p, guess=np.asarray(mech.guess, dtype)), np.asarray(mech.input_start, dtype), p))
    return tuple(np.asarray(x) for x in at_start)


def sketched_pose(mech, dtype) -> tuple | None:
    """`(q, input)` of a sketch file's own pose — the solve at its `[input] start`, where its
    joints are drawn — for the exports (`--export`, `--plot OUT.dxf`); None for a loop file, or
    when the start does not assemble (the exports then draw the table's first position)."""
    from ..cache import traced
    from ..results import RESULTS

    if mech.sketch is None:
        return None
    p = np.asarray(mech.parameters, dtype)
    q, result = (np.asarray(x) for x in traced("check_start", _start_arrays, (  # the start alone, as `check`'s
        mech.replace(parameters=p, guess=np.asarray(mech.guess, dtype)), np.asarray(mech.input_start, dtype), p))[:2])
    return (q, float(mech.input_start)) if int(result) == RESULTS.converged else None


def cmd_check(args) -> int:
    dtype = enable_dtype(args.dtype)
    from ..model import structure as _structure
    from ..results import RESULTS
    from ..solvers.closed_form import method_for
    from ..solvers.options import NewtonOptions

    mech = load_from_args(args)
    if mech.bodies is not None:  # what `reactions` checks before it solves
        from ..model import bodies as _bodies

        _bodies.model(mech)
    from ..analysis import motion as _motion

    _motion.prepare(mech)  # the designer's numbers' programs compile side by side (cold: 2 cores)
    print(f"mechanism   {mech.name}  ({mech.file})")
    if mech.description:
        print(f"            {mech.description}")
    lu = [k for k, v in {"m": 1.0, "mm": 1e-3, "cm": 1e-2}.items() if v == mech.units.length][0]
    au = "deg" if mech.units.angle != 1.0 else "rad"
    unit = {"length": lu, "angle": au, "number": ""}
    print(f"units       lengths in {lu}, angles in {au} (SI inside)")
    print(f"parameters  {len(mech.parameter_names)}: " + ", ".join(
        f"{n} = {mech.from_si(n, v):g}{(' ' + unit[k]) if unit[k] else ''}"
        for n, v, k in zip(mech.parameter_names, mech.parameters, mech.parameter_kinds)))
    if mech.derived:
        values = mech.derived_values(np.asarray(mech.parameters, np.float64))
        print(f"derived     {len(mech.derived)}: " + ", ".join(
            f"{n} = {text} = {float(values[n]) / mech.kind_factor(k):g}{(' ' + unit[k]) if unit[k] else ''}"
            for n, text, k, _ in mech.derived))
    print(f"input       {mech.input_name} ({mech.input_kind}), guesses hold at "
          f"{mech.from_si(mech.input_name, mech.input_start):g} {unit[mech.input_kind]}")
    print(f"unknowns    {mech.n_unknowns}: " + ", ".join(
        f"{n} ({k})" for n, k in zip(mech.unknown_names, mech.unknown_kinds)))
    print(f"loops       {len(mech.loops)} independent: " + "; ".join(
        f"{n} ({len(t)} vectors)" for n, t in mech.loops))
    if mech.sketch is not None:  # what was derived from the joints and links
        for n, terms in mech.loops:
            print(f"            {n}: {_sum_text(terms)} = 0")
    print(f"equations   {mech.n_equations} scalar (x and y of each loop)")
    if mech.sketch is not None:
        lay = mech.sketch
        sliders = "".join(f"; slider {j} on {b}" for j, b in lay.sliders)
        if lay.input[0] == "crank":
            pivot = dict(lay.bodies)[lay.input[1]][0]
            drive = f"{mech.input_name}, the angle of link {lay.input[1]} about {pivot}"
        elif lay.input[0] == "link":
            first, second = dict(lay.bodies)[lay.input[1]][:2]
            drive = f"{mech.input_name}, the angle of link {lay.input[1]} ({first} → {second})"
        elif lay.input[0] == "slider":
            drive = f"{mech.input_name}, the position of slider {lay.input[1]} on its line"
        else:
            drive = f"{mech.input_name}, the length of the actuator {lay.input[1][0]}–{lay.input[1][1]}"
        print(f"sketch      frame {', '.join(lay.frame)}; links " + ", ".join(
            f"{b} ({' '.join(js)}{': a plate' if len(js) > 2 else ''})" for b, js in lay.bodies)
            + f"{sliders}; input: {drive}")
        print("points      " + ("\n            ".join(f"{n} = {_sum_text(t)}" for n, t in mech.points) or "(none)"))
    else:
        print(f"points      {', '.join(mech.point_names) or '(none)'}")
    if mech.bodies is not None:
        mdl = mech.bodies
        names = ("ground", *mdl.body_names)
        drive = (f"with a force along [input] axis, from {names[mdl.input_base + 1]}" if mdl.drive_force
                 else "with a torque")
        print(f"bodies      {len(mdl.bodies)} moving: {', '.join(mdl.body_names)}; the input drives "
              f"{mdl.body_names[mdl.input_body]} {drive}")
        print(f"joints      {len(mdl.joints)}: " + ", ".join(
            f"{j.name} ({j.kind} {names[j.a + 1]}–{names[j.b + 1]})" for j in mdl.joints))
        loads = [*(f.name for f in mdl.forces), *(t.name for t in mdl.torques), *(s.name for s in mdl.springs)]
        print(f"loads       {', '.join(loads) or '(none)'}; gravity ({mdl.gravity[0]:g}, {mdl.gravity[1]:g}) m/s²")
    info = _structure.structure(mech)
    print(f"mobility    {info['mobility_loops']} from the loops "
          "(unknowns + 1 input − equations)")
    if info.get("grubler") is not None:
        g = info["grubler"]
        print(f"            {g['mobility']} by Grübler: u = {g['members']} members, s = {g['joint_count']} "
              f"joint count, n = 3(u−1) − 2s; independent loops k = s − u + 1 = {g['loops']}")
    q, result, resid, steps, jac = _at_start(mech, dtype)
    code = int(result)
    cond = np.linalg.cond(jac)
    how = ("closed-form dyads" if method_for(mech, NewtonOptions()) == "closed_form"
           else f"{int(steps)} Newton steps")
    print(f"assembly    at the start: {RESULTS.names[code]} (residual {float(resid):.2e} m, "
          f"{how}, Jacobian condition number {cond:.3g})")
    if code in (RESULTS.converged, RESULTS.singular):  # singular: assembled, at a toggle or change point
        print("            start configuration: " + ", ".join(
            f"{n} = {mech.from_si(n, float(v)):.6g}" for n, v in zip(mech.unknown_names, q)))
        if code == RESULTS.singular:
            print("            the start is a singular position (a dead centre, toggle or change point): "
                  "the numbers below follow the branch of the guesses away from it")
        _print_designer_numbers(mech, lu)
        return 0
    print(f"            {RESULTS.messages[code]}", file=sys.stderr)
    return 1


def cmd_kinematics(args) -> int:
    dtype = enable_dtype(args.dtype)
    outputs = [o.strip() for o in args.outputs.split(",") if o.strip()]
    for o in outputs:
        if o not in OUTPUTS:
            raise MechanismError(f"--outputs: unknown output '{o}'; choose from {', '.join(OUTPUTS)}")
    check_output("--csv", args.csv, CSV_FORMATS)
    check_output("--plot", args.plot, PLOT_FORMATS + ("dxf",))
    check_output("--export", args.export, EXPORT_FORMATS)
    check_output("--animate", args.animate, ("gif",))
    check_output("--json", args.json, ("json",))
    for option in ("--plot", "--export"):
        if getattr(args, option[2:]) == "-":
            raise MechanismError(f"{option} -: give a file name (a drawing is not written to standard output)")
    mech = load_from_args(args)
    if args.whole_curve:
        return _whole_curve(mech, args)
    phis, values = input_grid(mech, args)
    omega = omega_from_args(args, mech)
    units = units_from_args(mech, args)
    if args.numbers:  # their programs compile beside the table's
        from ..analysis import motion as _motion

        _motion.prepare(mech)
    from ..report import kinematics as _report

    table = _report.kinematics_table(mech, phis, omega=omega, outputs=outputs, dtype=dtype, input_values=values,
                                     rpm=getattr(args, "rpm", None), change_points=args.change_points)
    gaps = branch_point_warnings(table)
    bad = int((~table.converged).sum())
    info = sys.stderr if args.csv == "-" else sys.stdout  # `--csv -`: the table alone on standard output
    print(grid_text(mech, args), file=info)
    _report.print_summary(table, info, every_row_hint=not args.csv, units=units)
    numbers = None
    if args.numbers:
        from ..report import designer

        numbers = designer.compute(mech)
        lu = {1.0: "m", 1e-3: "mm", 1e-2: "cm"}.get(mech.units.length, "m")
        for line in designer.lines(mech, numbers[0], numbers[1], lu):
            print(line, file=info)
    if args.json:
        from ..report import designer

        doc = None if numbers is None else designer.to_json(mech, numbers[0], numbers[1])
        with writing("--json", args.json):
            _report.write_json(args.json, mech, table, units, doc)
        print(f"wrote {args.json}", file=info)
    if args.csv:
        with writing("--csv", args.csv):
            _report.write_csv(args.csv, table, units)
        if args.csv != "-":
            print(f"wrote {args.csv}: {len(phis)} rows, {len(table.columns)} columns", file=info)
    dxf_plot = bool(args.plot) and args.plot.lower().endswith(".dxf")  # not a picture: the geometry
    pose = sketched_pose(mech, dtype) if args.export or dxf_plot else None  # a sketch: drawn as sketched
    for option, path in (("--plot", args.plot if dxf_plot else None), ("--export", args.export)):
        if path:
            from ..report import export as _export

            with writing(option, path):
                _export.export(path, mech, table, pose)
            print(f"wrote {path} (geometry in {_export.file_units(mech).length})", file=info)
    picture = args.plot if args.plot and not dxf_plot else None
    if picture or args.animate:
        from ..report import plot as _plot

        if picture:
            with writing("--plot", picture):
                _plot.plot_kinematics(picture, mech, table)
            print(f"wrote {args.plot}", file=info)
        if args.animate:
            with writing("--animate", args.animate):
                _plot.animate(args.animate, mech, table)
            print(f"wrote {args.animate}", file=info)
    if bad:
        print(f"warning: {bad} of {len(phis)} positions did not converge (converged = 0 in the table): "
              + _report.failure_summary(table), file=sys.stderr)
        return 1
    return 1 if gaps else 0
