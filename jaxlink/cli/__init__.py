"""The `jaxlink` command line.

Each group of commands lives in its own module with a `register(subparsers)` function that
adds its sub-commands; a sub-command's handler takes the parsed `argparse.Namespace` and
returns an exit status. Bad input raises `MechanismError`, printed here as one line
(no traceback) with exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import MechanismError

# Modules that add sub-commands (each has `register(subparsers)`).
COMMAND_MODULES = (
    "jaxlink.cli.mechanism",
    "jaxlink.cli.cam",
    "jaxlink.cli.reactions",
    "jaxlink.cli.optimize",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="jaxlink",
        description=(
            "Planar mechanisms (linkages, cam followers): vectorized Newton loop-closure solver "
            "in JAX, kinematics, reactions, design search, cam-follower dynamics. "
            "A FILE argument is a mechanism TOML file or the name of a built-in scene "
            "(see `jaxlink scenes`)."
        ),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:  # a command group not shipped in this build
            if exc.name == name:
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except MechanismError as exc:
        print(f"jaxlink {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"jaxlink {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"jaxlink {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
