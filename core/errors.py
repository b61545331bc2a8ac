"""User-facing errors.

A :class:`UserError` is raised for anything the user can fix (a malformed job,
a missing file, |beta| >= 1 ...).  The CLI prints its one-line message and exits
with code 2, without a traceback and without writing any file.
"""

from __future__ import annotations

from pathlib import Path


class UserError(Exception):
    """An error in the user's input, reported as one line naming the key and the file."""

    def __init__(self, message: str, key: str | None = None, file: str | Path | None = None):
        self.key = key
        self.file = str(file) if file is not None else None
        self.detail = message
        super().__init__(self.format())

    def format(self) -> str:
        where = []
        if self.file:
            where.append(self.file)
        if self.key:
            where.append(f"key '{self.key}'")
        prefix = ": ".join(where)
        return one_line(f"{prefix}: {self.detail}" if prefix else self.detail)


_CONTROL = ({c: f"\\x{c:02x}" for c in (*range(32), *range(127, 160))}
            | {10: "\\n", 13: "\\r", 9: "\\t", 0x2028: "\\u2028", 0x2029: "\\u2029"})


def one_line(text: str) -> str:
    """``text`` with control characters (C0, DEL and C1: newlines in a file name or a
    quoted value, NEL) and the Unicode line and paragraph separators escaped, so that a
    message is always exactly one line (also for ``str.splitlines``)."""
    return text.translate(_CONTROL)
