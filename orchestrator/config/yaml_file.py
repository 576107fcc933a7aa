"""Reading a config file: YAML with duplicate keys refused, and ``--set KEY=VALUE`` overrides."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml


class ConfigErrors(Exception):
    """All problems found in one config, each ``file: key: message``."""

    def __init__(self, errors: list[str]):
        super().__init__("\n".join(errors))
        self.errors = errors


class _UniqueKeyLoader(yaml.SafeLoader):
    """YAML loader that refuses duplicate keys (PyYAML silently keeps the last one)."""


def _mapping(loader, node, deep=False):
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(None, None, f"duplicate key {key!r}", key_node.start_mark)
        seen.add(key)
    return loader.construct_mapping(node, deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)


def parse_override(text: str) -> tuple[list[str], Any]:
    """``a.b.c=VALUE`` -> (["a", "b", "c"], VALUE parsed as YAML)."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise ConfigErrors([f"--set {text!r}: expected KEY=VALUE, e.g. run.duration=2s"])
    try:
        parsed = yaml.load(value, Loader=_UniqueKeyLoader) if value.strip() else ""
    except yaml.YAMLError as e:
        raise ConfigErrors([f"--set {text!r}: value is not valid YAML ({e})"]) from None
    return key.strip().split("."), parsed


def apply_overrides(raw: dict, overrides: list[str]) -> None:
    for text in overrides:
        path, value = parse_override(text)
        components = raw.get("components")
        if path[0] == "components" and len(path) > 2 and isinstance(components, dict) and path[1] not in components:
            raise ConfigErrors(
                [f"--set {text!r}: no component {path[1]!r} (components: {', '.join(map(str, components)) or 'none'})"]
            )
        node = raw
        for i, part in enumerate(path[:-1]):
            child = node.get(part) if isinstance(node, dict) else None
            if child is None:
                child = node[part] = {}
            if not isinstance(child, dict):
                raise ConfigErrors([f"--set {text!r}: {'.'.join(path[: i + 1])} is not a mapping"])
            node = child
        node[path[-1]] = value


def _yaml_problem(error: yaml.YAMLError, text: str) -> str:
    """' at line L, column C: problem', then the line and a caret under the column, each on its own line."""
    mark = getattr(error, "problem_mark", None)
    problem = " ".join(str(getattr(error, "problem", None) or error).split())
    if mark is None:
        return f": {problem}"
    context = getattr(error, "context", None)
    lines = text.splitlines()
    source = lines[mark.line] if mark.line < len(lines) else ""
    return (
        f" at line {mark.line + 1}, column {mark.column + 1}: {problem}"
        + (f" ({context})" if context else "")
        + f"\n    {source}\n    {' ' * mark.column}^"
    )


def read_yaml(path: Path) -> dict:
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as e:
        raise ConfigErrors([f"{path}: cannot read config ({e.strerror})"]) from None
    except UnicodeDecodeError as e:
        line = path.read_bytes()[: e.start].count(b"\n") + 1
        raise ConfigErrors(
            [f"{path}: not UTF-8 text (byte 0x{e.object[e.start]:02x} at line {line}); save the config as UTF-8"]
        ) from None
    try:
        raw = yaml.load(text, Loader=_UniqueKeyLoader)
    except yaml.YAMLError as e:
        raise ConfigErrors([f"{path}: not valid YAML{_yaml_problem(e, text)}"]) from None
    if not isinstance(raw, dict):
        raise ConfigErrors([f"{path}: expected a mapping with run, components, connections"])
    return raw
