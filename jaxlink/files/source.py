"""Reading a scene or mechanism file's text and its TOML, with every way it can fail refused as a
`MechanismError` naming the file: a directory, a named pipe or a device given as FILE, a file over
`MAX_BYTES`, text that is not UTF-8 (with the line and column of the first bad byte), TOML that is
not valid or whose values are nested more than `MAX_NESTING` levels deep.

Shared by the linkage files (`jaxlink/files/reader.py`) and the cam-follower scenes
(`jaxlink/cam/scene.py`).
"""

from __future__ import annotations

import os
import pathlib
import re
import stat

from ..errors import MechanismError

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]

#: largest file read (bytes): a mechanism or scene file is a few kilobytes
MAX_BYTES = 4 * 1024 * 1024
#: most levels of tables, arrays and inline tables inside one another
MAX_NESTING = 16


def _kind(mode: int) -> str | None:
    """What a non-regular file is, in words (None for a regular file)."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a named pipe"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def read_source(source: str | os.PathLike) -> tuple[pathlib.Path, str]:
    """`(path, text)` of a FILE argument: a path, else a built-in scene name (`jaxlink/scenes`).

    Raises `MechanismError` when it names a directory, a pipe or a device, is larger than
    `MAX_BYTES`, or is not UTF-8 text."""
    from ..scenes import resolve

    p = pathlib.Path(source)
    try:
        st = p.stat()
    except OSError:
        st = None
    if st is not None:
        what = _kind(st.st_mode)
        if what is not None:
            raise MechanismError(f"{source} is {what}, not a mechanism or scene file (a TOML file)")
        if st.st_size > MAX_BYTES:
            raise MechanismError(f"{source} is {st.st_size} bytes; a mechanism or scene file is at most "
                                 f"{MAX_BYTES} bytes")
    path = resolve(str(source))
    data = path.read_bytes()[:MAX_BYTES + 1]
    if len(data) > MAX_BYTES:
        raise MechanismError(f"{path} is larger than {MAX_BYTES} bytes, the most a mechanism or scene file may be")
    return path, decode(data, str(path))


def decode(data: bytes, file: str) -> str:
    """`data` as UTF-8 text; a `MechanismError` with the line and column of the first byte that is
    not (e.g. a `°` saved as Latin-1)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise MechanismError(
            f"not UTF-8 text: byte 0x{data[exc.start]:02x} at column {col} (save the file as UTF-8; "
            "a '°' or 'µ' written in Latin-1 or Windows-1252 is the usual cause)", file=file, line=line,
        ) from None


def parse_toml(text: str, file: str) -> dict:
    """The TOML table of `text`; a `MechanismError` (with the line where TOML gives one) when it is
    not valid TOML or nests values more than `MAX_NESTING` levels deep."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        message, line = _located(str(exc), text)
        raise MechanismError(f"not valid TOML: {message}", file=file, line=line) from None
    except ValueError as exc:  # e.g. an integer of more digits than Python converts
        raise MechanismError(f"not valid TOML: {exc}", file=file) from None
    except RecursionError:
        raise MechanismError(f"values nested too deeply (more than {MAX_NESTING} levels of arrays and "
                             "tables inside one another)", file=file) from None
    key, levels = _deepest(data)
    if levels > MAX_NESTING:
        raise MechanismError(f"values nested {levels} levels deep; at most {MAX_NESTING} levels of arrays and "
                             "tables inside one another", file=file, key=key)
    return data


def _located(message: str, text: str) -> tuple[str, int | None]:
    """tomllib's `message` and the line it names, except where tomllib names a later line than the
    mistake's. An array left open (`b = [1, 2` with its `]` forgotten) is found only at the next
    value, on the next line that is not blank or a comment: "Unclosed array (at line 13, column
    1)" for the `b` of line 12. The line given is then that of the last text before that point —
    where the `]` (or a `,` between two values) is missing."""
    m = re.search(r"\(at line (\d+), column (\d+)\)", message)
    lines = text.splitlines()
    if m:
        line, col = int(m.group(1)), int(m.group(2))
    elif message.startswith("Unclosed array") and "end of document" in message:
        line, col = len(lines) + 1, 1
    else:
        return message, None
    if not message.startswith("Unclosed array"):
        return message, line
    # that line's text before the column, then the lines above (1-based numbers)
    before = [(line, lines[line - 1][:col - 1])] if line <= len(lines) else []
    before += [(k + 1, lines[k]) for k in range(min(line, len(lines) + 1) - 2, -1, -1)]
    for at, part in before:
        if part.strip() and not part.lstrip().startswith("#"):
            if at == line:
                return message, line
            read = f"line {line}, column {col}" if m else "the end of the file"
            return (f"an array not closed: ']' (or a ',' between two values) missing on line {at}, after its "
                    f"last value (TOML read on to {read}: Unclosed array)"), at
    return message, line


def _deepest(data: dict) -> tuple[str, int]:
    """(dotted key of the first top-level entry, deepest level) of a parsed TOML table, without
    recursion (the table itself is level 0)."""
    best, where = 0, ""
    stack: list = [(v, 1, str(k)) for k, v in data.items()]
    while stack:
        value, level, top = stack.pop()
        if level > best:
            best, where = level, top
        if level > MAX_NESTING:
            break
        if isinstance(value, dict):
            stack += [(v, level + 1, top) for v in value.values()]
        elif isinstance(value, list):
            stack += [(v, level + 1, top) for v in value]
    return where, best
