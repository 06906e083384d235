"""Unknown keys: every table of a linkage file or a cam-follower scene is checked against the keys
it reads, and a key it does not read is refused — a misspelt key (`lenght_unit = "mm"`) is not
left out silently (the lengths then read in metres), it names the file, the line, the key and the
key it was probably meant to be (`difflib`).

Every reader refuses through `check_keys` (the linkage tables: `reader.py`, `bodies.py`,
`sketch.py`, `sketch_bodies.py`; `[optimize]`: `jaxlink/optimize/problem.py`; `[study]`:
`jaxlink/study/inputs.py`; the cam-follower scenes: `jaxlink/cam/scene.py`), with its own error
factory, which finds the line of the key in the text that was parsed.
"""

from __future__ import annotations

import difflib
from typing import Callable, Iterable, Mapping

from ..errors import MechanismError


def suggest(name: str, candidates: Iterable[str]) -> str:
    """` (did you mean 'X'?)` for the candidate closest to `name` (`difflib`), "" if none is close."""
    close = difflib.get_close_matches(str(name), [str(c) for c in candidates], n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""


def unknown_key(key: str, known: Iterable[str], table: str) -> str:
    """The message refusing `key` in `[table]`: the suggestion and the keys the table has."""
    known = sorted(map(str, known))
    listed = ", ".join(known) if known else "none (the table must be empty)"
    return f"unknown key '{key}' in [{table}]{suggest(key, known)}; known keys: {listed}"


def check_keys(d: Mapping, known: Iterable[str], table: str,
               refuse: Callable[..., MechanismError]) -> None:
    """Refuse the first key of `d` not in `known`: `refuse(message, key)` makes the error (with
    the file and the line of `key`); `table` names the table in the message (`mechanism`,
    `bodies.crank`, `study.tolerances.coupler`)."""
    known = set(known)
    for k in d:
        if k not in known:
            raise refuse(unknown_key(str(k), known, table), str(k))
