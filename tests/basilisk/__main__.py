"""Remake Basilisk's reference fixtures: ``python -m tests.basilisk [MODEL ...]`` (see __init__)."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
DEFAULT_VENV = Path.home() / ".cache" / "zenorbit" / "basilisk"


def basilisk_venv() -> Path:
    """Basilisk's environment (the fixtures' and the benchmarks')."""
    return Path(os.environ.get("ZENORBIT_BASILISK_VENV", DEFAULT_VENV))


def basilisk_python() -> Path:
    """The interpreter of Basilisk's environment, made (``pip install bsk numpy``) on first use."""
    venv = basilisk_venv()
    python = venv / "bin" / "python"
    if not python.exists():
        print(f"(making Basilisk's environment in {venv}: pip install bsk)", file=sys.stderr)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "-q", "bsk", "numpy"], check=True)
    return python


def models() -> list[str]:
    return sorted(p.stem for p in HERE.glob("*.py") if not p.stem.startswith("_"))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.basilisk", description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="*", help=f"which (default: all of {', '.join(models())})")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.models) - set(models()))
    if unknown:
        parser.error(f"no such model {', '.join(unknown)}: expected one of {', '.join(models())}")
    python = basilisk_python()
    for model in args.models or models():
        result = subprocess.run([str(python), str(HERE / f"{model}.py")], capture_output=True, text=True, cwd=HERE)
        if result.returncode != 0:
            print(
                f"{model}: Basilisk's script failed (exit {result.returncode}):\n{result.stderr[-3000:]}",
                file=sys.stderr,
            )
            return 1
        values = json.loads(result.stdout)  # a script prints one JSON document
        (HERE / f"{model}.json").write_text(json.dumps(values, indent=1) + "\n")
        print(f"{model}: wrote {HERE / f'{model}.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
