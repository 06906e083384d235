"""The `jaxlink` command line.

Each group of commands lives in its own module with a `register(subparsers)` function that adds
its sub-commands; a sub-command's handler takes the parsed `argparse.Namespace` and returns an
exit status.

One error path: bad input (a file, an option, an output that cannot be written) raises
`MechanismError` (or an `OSError` of the output), printed here as one line on standard error with
exit status 2; a valid request that cannot be solved (an unassemblable design) returns 1 from its
handler. Anything else is a bug: one "internal error" line (the traceback with `--debug`) and exit
status 3. A closed standard output (`jaxlink scenes | head -1`, `kinematics --csv x.csv | true`) stops
nothing: what is printed is dropped, the files asked for are written (`pipe.py`).
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import importlib
import os
import sys
import time

from ..errors import MechanismError
from .pipe import quiet_closed_pipes

# Modules that add sub-commands (each has `register(subparsers)`).
COMMAND_MODULES = (
    "jaxlink.cli.mechanism",
    "jaxlink.cli.cam",
    "jaxlink.cli.reactions",
    "jaxlink.cli.optimize",
    "jaxlink.cli.study",
    "jaxlink.cli.synthesize",
)


class _Parser(argparse.ArgumentParser):
    """argparse with "did you mean" for a mistyped command."""

    def error(self, message):
        if "invalid choice:" in message and "argument COMMAND" in message:
            word = message.split("invalid choice:", 1)[1].split("'")[1] if "'" in message else ""
            names = [a.dest for a in getattr(self, "_commands", [])]
            close = difflib.get_close_matches(word, names, n=1)
            if close:
                message += f" — did you mean '{close[0]}'?"
        super().error(message)


def _version() -> str:
    from .. import __version__

    return f"jaxlink {__version__}"


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="jaxlink",
        description=(
            "Planar mechanisms (linkages, cam followers) in JAX: loop-closure solver (closed-form "
            "dyads where the structure allows, else Newton with continuation), kinematics, "
            "reactions, design search, cam-follower dynamics. A FILE argument is a mechanism TOML "
            "file or the name of a built-in scene (see `jaxlink scenes`)."
        ),
    )
    parser.add_argument("--version", action="version", version=_version())
    parser.add_argument("--debug", action="store_true", help="show the traceback of an internal error")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    parser._commands = list(sub._choices_actions)  # type: ignore[attr-defined]
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command of `argv` (default: the command line's); its exit status. Standard output
    and error closing early (`| head -1`) stop nothing (`pipe.py`). A command's handler finds in
    `args.started` the `time.perf_counter()` time a time limit counts from: the process's start for
    the command line's own arguments (`process_started`: importing JAX counts), else this call's."""
    started = process_started() if argv is None else time.perf_counter()
    with quiet_closed_pipes():
        return _main(argv, started)


def process_started() -> float:
    """The `time.perf_counter()` time this process started at (Linux: its start time in
    /proc/self/stat against the boot clock, to the kernel's tick); where that cannot be read, now."""
    now = time.perf_counter()
    try:
        with open("/proc/self/stat", encoding="ascii") as fh:
            ticks = int(fh.read().rsplit(")", 1)[1].split()[19])  # field 22, starttime
        age = time.clock_gettime(time.CLOCK_BOOTTIME) - ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, AttributeError, IndexError):
        return now
    return now - age if 0.0 <= age < 3600.0 else now


def _main(argv: list[str] | None, started: float) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.started = started
    name = f"jaxlink {args.command}"
    from ..cache import cancel_prepared, enable_compilation_cache, one_command

    enable_compilation_cache()  # JAXLINK_CACHE_DIR: a repeated command loads its compiled code
    try:
        with one_command():
            try:
                return int(args.func(args) or 0)
            finally:
                cancel_prepared()  # programs compiled ahead that the command did not get to
    except MechanismError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # not from standard output or error (`pipe.py`): an output that is a pipe
        with contextlib.suppress(OSError):
            print(f"{name}: error: an output's reader went away before the command ended; what it had to "
                  "write may be missing", file=sys.stderr)
        return 2
    except OSError as exc:  # an input or output file that cannot be read or written
        where = f": {exc.filename}" if getattr(exc, "filename", None) else ""
        print(f"{name}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug: say so in one line, the traceback only with --debug
        if args.debug:
            raise
        print(f"{name}: internal error: {type(exc).__name__}: {exc} — a bug in jaxlink; please report it with "
              f"this command line (`jaxlink --debug {args.command} …` shows the traceback)", file=sys.stderr)
        return 3



def run() -> int:
    """The `jaxlink` command (`[project.scripts]`, `python -m jaxlink.cli`): `main` on the command
    line's arguments, then the process's objects frozen (`gc.freeze`) so that the interpreter's
    exit does not walk them all in its last garbage collections (`check four-bar`: 0.2–0.3 s of a
    2 s command went to the exit). Nothing is lost: the output is flushed and the files closed by
    the commands and at exit as before; only cyclic garbage is left to the end of the process.
    Not in `main`, which tests and programs call in a process that goes on. A compilation still
    running in a thread (a time-limited `synthesize` that stopped waiting for it at its limit:
    `cache.unfinished`) is not waited for: the output flushed, the process ends at once
    (`os._exit`; its files are written and closed by then), where a normal exit would join XLA's
    compiling threads, or tear the interpreter down under them."""
    import gc

    from ..cache import unfinished

    rc = main()
    if unfinished():
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        os._exit(rc)
    gc.freeze()
    return rc
