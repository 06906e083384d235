"""Errors raised for bad input (files, command-line values).

Numerical failures inside jitted code are never raised: they are reported as result codes
(see `jaxlink.results.RESULTS`). Only problems a user must fix in a file or on the
command line raise `MechanismError`, whose message names the file, the line, the key and
the reason.
"""

from __future__ import annotations


class MechanismError(ValueError):
    """A mechanism or scene file (or a command-line value) is wrong.

    **Arguments:**

    - `message`: what is wrong and how to fix it.
    - `file`: the file it is in (optional).
    - `line`: 1-based line in that file (optional).
    - `key`: the TOML key, e.g. `loops.main[2]` (optional).
    """

    def __init__(self, message: str, *, file: str | None = None, line: int | None = None,
                 key: str | None = None):
        self.reason = message
        self.file = file
        self.line = line
        self.key = key
        where = []
        if file:
            where.append(str(file) + (f":{line}" if line else ""))
        if key:
            where.append(f"[{key}]")
        prefix = " ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)
