"""Small helpers for messages a user reads."""


def count(n: int, noun: str, plural: str | None = None) -> str:
    """'1 step', '2 steps', '0 connections'; ``plural`` for irregular nouns."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"
