"""How a command ends: the exit code of bad usage or a bad config (the others:
orchestrator/cli.py's docstring) and its error lines on stderr."""

from __future__ import annotations

import sys
from collections.abc import Iterable

USAGE_ERROR = 2


def fail(message: str, code: int = USAGE_ERROR) -> int:
    print(f"error: {message}", file=sys.stderr)
    return code


def fail_all(messages: Iterable[str]) -> int:
    """Each message on an error line; bad usage or config."""
    for message in messages:
        fail(message)
    return USAGE_ERROR
