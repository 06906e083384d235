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
import re
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
    """argparse with "did you mean" for a mistyped command, option or choice: an unknown option of
    a sub-command (`kinematics four-bar --rmp 60`) is refused by that sub-command (its usage, exit
    status 2) with the closest of its options, or with the commands that have it
    (`check four-bar --rpm 60`)."""

    def parse_args(self, args=None, namespace=None):  # type: ignore[override]
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            sub = getattr(self, "_subcommands", {}).get(getattr(ns, "command", None))
            target = sub if sub is not None else self
            target.error(f"unrecognized arguments: {' '.join(extras)}{_flag_hint(extras, target, self)}")
        return ns

    def error(self, message):
        m = re.search(r"argument (\S+): invalid choice: '([^']*)'", message)
        if m and " — did you mean" not in message:
            action = next((a for a in self._actions if m.group(1) in (*a.option_strings, a.metavar, a.dest)), None)
            choices = [str(c) for c in (getattr(action, "choices", None) or ())]
            close = difflib.get_close_matches(m.group(2), choices, n=1)
            if close:
                message += f" — did you mean '{close[0]}'?"
        super().error(message)


def _flag_hint(extras: list[str], parser: argparse.ArgumentParser, top: argparse.ArgumentParser) -> str:
    """" — did you mean '--rpm'?" for the first unknown option of `extras` close to one of
    `parser`'s; else, for one that another command has, " — --rpm is an option of kinematics, …"."""
    flags = [s for a in parser._actions for s in a.option_strings if s.startswith("--")]
    words = [e.split("=", 1)[0] for e in extras if e.startswith("-") and len(e) > 1]
    for word in words:
        close = _closest(word, flags)
        if close:
            return f" — did you mean '{close}'?"
    for word in words:
        owners = [name for name, p in getattr(top, "_subcommands", {}).items()
                  if any(word in a.option_strings for a in p._actions)]
        if owners:
            return f" — {word} is an option of {', '.join(owners)}"
    return ""


def _closest(word: str, names: list[str]) -> str | None:
    """The name nearest to `word` by edits (a letter added, dropped, changed, or two neighbours
    swapped), at most a third of its letters and at most 3; ties go to the name of the same
    length (`--setp` is `--step` swapped, rather than `--set` with a letter more), then to
    difflib's closer match. None if none is that near."""
    def edits(a: str, b: str) -> int:  # the optimal string alignment distance
        d = [[i + j if i * j == 0 else 0 for j in range(len(b) + 1)] for i in range(len(a) + 1)]
        for i in range(1, len(a) + 1):
            for j in range(1, len(b) + 1):
                d[i][j] = min(d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] != b[j - 1]))
                if i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]:
                    d[i][j] = min(d[i][j], d[i - 2][j - 2] + 1)
        return d[-1][-1]

    bare = word.lstrip("-")
    scored = [(edits(bare, n.lstrip("-")), abs(len(n) - len(word)), -difflib.SequenceMatcher(None, word, n).ratio(), n)
              for n in names]
    scored = [s for s in scored if s[0] <= min(3, max(1, len(bare) // 3))]
    return min(scored)[-1] if scored else None


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
    parser._subcommands = dict(sub.choices)  # type: ignore[attr-defined]
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
