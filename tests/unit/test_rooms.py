"""Rooms with one job (issue 46): no module of the product over 500 lines, no class over 300, and a
function over 60 lines only where a reason is written, as a ``# long: <why>`` line directly above it
(above its decorators, if any)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PRODUCT = ("components", "orchestrator")
MODULE_LINES, CLASS_LINES, FUNCTION_LINES = 500, 300, 60
MARKER = "# long:"


def oversized(path: Path, text: str) -> list[str]:
    """What in one module is over its limit, each as ``path:line name (N lines, limit L)``."""
    lines = text.splitlines()
    found = []
    if len(lines) > MODULE_LINES:
        found.append(f"{path}: {len(lines)} lines, limit {MODULE_LINES}")
    for node in ast.walk(ast.parse(text)):
        if not isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        size = node.end_lineno - node.lineno + 1
        if isinstance(node, ast.ClassDef):
            if size > CLASS_LINES:
                found.append(f"{path}:{node.lineno} class {node.name}: {size} lines, limit {CLASS_LINES}")
            continue
        first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
        above = lines[first - 2].strip() if first >= 2 else ""
        if size > FUNCTION_LINES and not (above.startswith(MARKER) and above[len(MARKER) :].strip()):
            found.append(
                f"{path}:{node.lineno} {node.name}: {size} lines, limit {FUNCTION_LINES} "
                f"(or say why it stays whole: '{MARKER} <why>' above it)"
            )
    return found


def test_no_room_is_over_its_size():
    found = [
        problem
        for folder in PRODUCT
        for path in sorted((ROOT / folder).rglob("*.py"))
        for problem in oversized(path.relative_to(ROOT), path.read_text())
    ]
    assert not found, "\n".join(found)


def _function(lines: int, marker: str = "") -> str:
    body = "".join(f"    x{i} = {i}\n" for i in range(lines - 1))
    return f"{marker}def f():\n{body}"


def test_the_size_check_finds_a_long_function_a_big_class_and_a_big_module():
    assert oversized(Path("m.py"), _function(FUNCTION_LINES)) == []
    assert [p.split(" ")[1] for p in oversized(Path("m.py"), _function(FUNCTION_LINES + 1))] == ["f:"]
    assert oversized(Path("m.py"), _function(FUNCTION_LINES + 1, "# long: a table\n")) == []
    assert len(oversized(Path("m.py"), _function(FUNCTION_LINES + 1, "# long:\n"))) == 1  # a reason, not a marker
    big_class = "class C:\n" + "".join(f"    x{i} = {i}\n" for i in range(CLASS_LINES))
    assert [p.split(" ")[1:3] for p in oversized(Path("m.py"), big_class)] == [["class", "C:"]]
    module = "".join(f"x{i} = {i}\n" for i in range(MODULE_LINES + 1))
    assert oversized(Path("m.py"), module) == [f"m.py: {MODULE_LINES + 1} lines, limit {MODULE_LINES}"]
