"""The install's optional parts (pyproject.toml's extras) and the message a feature gives when its
extra is not installed: what is missing, and the command that installs it.

The default install runs the demo; an extra brings what only some features need (hundreds of MB
each): the robots of example-robot-data, the Rerun viewer, OpenCV, FMPy and pythonfmu.
"""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version
from importlib.util import find_spec
from pathlib import Path

from components.errors import ConfigError

#: extra -> {module: the distribution that brings it} (robots: a ROS package, in PACKAGES)
MODULES = {
    "view": {"rerun": "rerun-sdk"},
    "vision": {"cv2": "opencv-python-headless"},
    "fmi": {"fmpy": "fmpy", "pythonfmu": "pythonfmu"},
}

#: ROS packages an extra ships as a pip wheel of the same name -> that extra
PACKAGES = {"example-robot-data": "robots"}


def install_command(extra: str) -> str:
    """``pip install -e ".[EXTRA]"`` in this clone (its path when run elsewhere); from an index otherwise."""
    root = Path(__file__).resolve().parents[1]
    if not (root / "pyproject.toml").is_file():
        return f'pip install "zenorbit[{extra}]"'
    here = "." if root == Path.cwd().resolve() else str(root)
    return f'pip install -e "{here}[{extra}]"'


def _installed(distribution: str) -> bool:
    try:
        version(distribution)
    except PackageNotFoundError:
        return False
    return True


def missing(extra: str, feature: str) -> str | None:
    """Why ``feature`` cannot work here (a module or ROS package of its ``extra`` is not installed), or None."""
    absent = [dist for module, dist in MODULES.get(extra, {}).items() if find_spec(module) is None]
    absent += [name for name, ships in PACKAGES.items() if ships == extra and not _installed(name)]
    if not absent:
        return None
    return f"{feature} needs the extra [{extra}] ({', '.join(absent)} not installed): {install_command(extra)}"


def require(extra: str, feature: str, key: str = "") -> None:
    """ConfigError(key) when ``feature``'s extra is not installed: check and run exit 2 saying so."""
    if problem := missing(extra, feature):
        raise ConfigError(key, problem)
