"""The tree stays clean under its tools, as pyproject.toml configures them: ruff's lint and format,
and mypy. Each runs from the project root; a failure shows what the tool said."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    "command",
    [["ruff", "check", "."], ["ruff", "format", "--check", "."], ["mypy"]],
    ids=["ruff check", "ruff format", "mypy"],
)
def test_the_tree_is_clean_under(command):
    done = subprocess.run(
        [sys.executable, "-m", *command], cwd=ROOT, capture_output=True, text=True, timeout=280, check=False
    )
    assert done.returncode == 0, f"python -m {' '.join(command)} (in {ROOT}):\n{done.stdout}{done.stderr}"
