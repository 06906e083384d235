"""Line numbers of TOML tables, keys and items in the text that was parsed, for error messages.

Every reader (`jaxlink/files/reader.py`, `jaxlink/files/bodies.py`, `jaxlink/cam/scene.py`) builds
one `Locator` from the very text it gave to `tomllib`, so the lines it reports are those of that
text, whether it came from a file, an edited file or a string.
"""

from __future__ import annotations

import dataclasses
import re

# `[table]` or `[[array.of.tables]]` alone on its line (bare or quoted keys, dots, a trailing
# comment). A line of a multi-line array such as `[1, 2],` or `["a @ phi"]` is not a header.
_HEADER = re.compile(r"""^(\[\[?)\s*([A-Za-z0-9_\-]+(?:\s*\.\s*[A-Za-z0-9_\-"']+)*|"[^"]*")\s*(\]\]?)\s*(#.*)?$""")


@dataclasses.dataclass(frozen=True)
class _Section:
    table: str  # dotted name, spaces and quotes removed
    index: int | None  # occurrence of an array of tables `[[table]]`, None for `[table]`
    header: int | None  # 0-based line of the header, None for the root table
    start: int  # first line of the body
    stop: int  # one past the last line


class Locator:
    """Finds the 1-based line of a table's header, of a key in a table, or of an item (a piece of
    text, e.g. one term of a list) in a key's value. Built once from the text."""

    def __init__(self, text: str):
        self.lines = text.splitlines()
        heads: list[tuple[int, str, int | None, int | None]] = [(0, "", None, None)]
        count: dict[str, int] = {}
        for i, raw in enumerate(self.lines):
            m = _HEADER.match(raw.strip())
            if not m or len(m.group(1)) != len(m.group(3)):
                continue
            name = re.sub(r"""\s*\.\s*""", ".", m.group(2)).replace('"', "").replace("'", "")
            index = None
            if m.group(1) == "[[":
                index = count.get(name, 0)
                count[name] = index + 1
            heads.append((i + 1, name, index, i))
        self._sections = tuple(
            _Section(name, index, header, start, heads[k + 1][0] - 1 if k + 1 < len(heads) else len(self.lines))
            for k, (start, name, index, header) in enumerate(heads)
        )

    def _matching(self, table: str, index: int | None):
        return [s for s in self._sections if s.table == table and (index is None or s.index == index)]

    def line(self, table: str | None, key: str | None = None, item: str | None = None, *,
             index: int | None = None) -> int | None:
        """Line of `[table]` (no `key`), of `key = ...` in it (or of the header `[table.key]`), or
        of the first line from that key to the end of its table containing `item`. `index` picks
        the occurrence of an array of tables `[[table]]` (default: the first). None if not found."""
        if table is None:
            return None
        sections = self._matching(table, index)
        if key is None:
            for s in sections:
                if s.header is not None:
                    return s.header + 1
            return None
        pattern = re.compile(r"""^\s*["']?""" + re.escape(key) + r"""["']?\s*=""")
        for s in sections:
            for i in range(s.start, s.stop):
                if pattern.match(self.lines[i]):
                    if item is not None:
                        for j in range(i, s.stop):
                            if item in self.lines[j]:
                                return j + 1
                    return i + 1
        # a sub-table `[table.key]` written as its own header
        sub = self.line(f"{table}.{key}" if table else key)
        if sub is not None and item is not None:
            for s in self._matching(f"{table}.{key}" if table else key, None):
                for j in range(s.start, s.stop):
                    if item in self.lines[j]:
                        return j + 1
        return sub
