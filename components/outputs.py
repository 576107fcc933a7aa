"""Whether a command can write where it is told, asked before it starts any work, so that an
output it cannot write is refused (exit 2, naming the path) instead of failing after the work.

Nothing is created: the nearest part of the path that exists must be a directory this process may
write into (a path under a regular file, or in a directory it may not write, is refused; root
writes almost anywhere, but not under a file)."""

from __future__ import annotations

import os
from pathlib import Path


def output_problem(path: str | Path, flag: str, kind: str = "directory") -> str | None:
    """Why ``flag path`` (a ``directory`` to create or fill, or a ``file`` to write) cannot be
    written; None when it can be (as far as can be told without writing)."""
    path = Path(path)
    flag = flag if flag.endswith(":") else flag + " "  # "--view save:FILE", "--out FILE"
    if kind == "file" and path.is_dir():
        return f"{flag}{path}: expected a file to write, got a directory"
    if kind == "directory" and path.exists() and not path.is_dir():
        return f"{flag}{path}: expected a directory, got a file"
    existing = path if kind == "directory" else path.parent
    existing = Path(os.path.abspath(existing))
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        return f"{flag}{path}: cannot write there: {existing} is a file, not a directory"
    if not os.access(existing, os.W_OK | os.X_OK):
        return f"{flag}{path}: cannot write there: no permission to write in {existing}"
    return None
