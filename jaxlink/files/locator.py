"""Line numbers of TOML keys and items in the text that was parsed, for error messages."""

from __future__ import annotations

import re


class Locator:
    """Finds the line of a TOML key (or of an item's text) for error messages."""

    def __init__(self, text: str):
        self.lines = text.splitlines()

    def line(self, table: str | None, key: str | None = None, item: str | None = None) -> int | None:
        current = ""
        start = None
        for i, raw in enumerate(self.lines):
            s = raw.strip()
            m = re.match(r"^\[\s*([^\]]+?)\s*\]", s)
            if m and not s.startswith("[["):
                current = m.group(1).strip()
                if table is not None and key is None and current == table:
                    return i + 1
                continue
            if table is not None and current != table:
                continue
            if key is not None and re.match(r'^\s*"?' + re.escape(key) + r'"?\s*=', raw):
                start = i
                break
        if start is None:
            return None
        if item is None:
            return start + 1
        for j in range(start, len(self.lines)):
            if item in self.lines[j]:
                return j + 1
        return start + 1
