"""Where ``package://NAME/...`` URIs and xacro's ``$(find NAME)`` point: ROS packages as robot
descriptions ship them.

A package NAME is looked up, first match wins, in:

1. the config's ``run.packages`` map (name -> directory, relative to the config file), handed to
   every component as the run parameter ``_packages`` (absolute paths);
2. ``ROS_PACKAGE_PATH`` (``:``-separated directories): a directory NAME in one of them, one of
   them that is the package itself (its ``package.xml`` names NAME, or its own name is NAME), or a
   sub-directory whose ``package.xml`` names NAME (two levels down at most);
3. ``AMENT_PREFIX_PATH`` and ``CMAKE_PREFIX_PATH``: ``<prefix>/share/NAME``;
4. installed Python packages that ship robot descriptions: ``<site>/cmeel.prefix/share/NAME``
   (cmeel wheels such as ``example-robot-data``), ``<site>/NAME`` and
   ``<site>/NAME-with-underscores`` holding a ``package.xml``, for every ``sys.path`` entry.

``PackageError`` names the package and every place looked.
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path
from urllib.parse import unquote

from components.extras import PACKAGES, install_command

_PACKAGE_NAME = re.compile(r"<name>\s*([^<\s]+)\s*</name>")


class PackageError(LookupError):
    """A package (or a file in it) that cannot be found; the message says where it looked."""


def _xml_name(directory: Path) -> str | None:
    try:
        m = _PACKAGE_NAME.search((directory / "package.xml").read_text(errors="replace"))
    except OSError:
        return None
    return m.group(1) if m else None


def _ros_package_path(name: str, roots: Iterable[str]) -> tuple[Path | None, list[str]]:
    looked = []
    for root in roots:
        if not root:
            continue
        base = Path(root).expanduser()
        looked.append(f"ROS_PACKAGE_PATH {base}")
        if not base.is_dir():
            continue
        if _xml_name(base) == name or (base.name == name and not (base / name).is_dir()):
            return base, looked
        if (base / name).is_dir():
            return base / name, looked
        for pattern in ("*/package.xml", "*/*/package.xml"):
            for xml in sorted(base.glob(pattern)):
                if _xml_name(xml.parent) == name:
                    return xml.parent, looked
    return None, looked


def find_package(name: str, packages: Mapping[str, str] | None = None) -> tuple[Path | None, list[str]]:
    """The directory of package ``name`` and the places looked (see the module doc)."""
    looked: list[str] = []
    if packages and name in packages:
        path = Path(packages[name])
        looked.append(f"run.packages.{name} ({path})")
        if path.is_dir():
            return path, looked
    elif packages:
        looked.append(f"run.packages ({', '.join(packages) or 'empty'})")
    else:
        looked.append("run.packages (none given)")
    found, where = _ros_package_path(name, os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep))
    looked += where or ["ROS_PACKAGE_PATH (not set)"]
    if found is not None:
        return found, looked
    for variable in ("AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH"):
        for prefix in filter(None, os.environ.get(variable, "").split(os.pathsep)):
            candidate = Path(prefix) / "share" / name
            looked.append(f"{variable} {candidate}")
            if candidate.is_dir():
                return candidate, looked
    sites = []
    for entry in sys.path:
        if entry and Path(entry).is_dir() and entry not in sites:
            sites.append(entry)
    for site in sites:
        for candidate in (
            Path(site) / "cmeel.prefix" / "share" / name,
            Path(site) / name,
            Path(site) / name.replace("-", "_"),
        ):
            if candidate.is_dir() and (candidate.parent.name == "share" or (candidate / "package.xml").is_file()):
                return candidate, looked
    looked.append(
        "installed Python packages (<site-packages>/cmeel.prefix/share/NAME, <site-packages>/NAME with a package.xml)"
    )
    return None, looked


def not_found(name: str, looked: list[str]) -> str:
    """The package ``name`` not found, where it was looked for, and, for one a Zenorbit extra ships
    (example-robot-data), that extra and its install command."""
    extra = PACKAGES.get(name)
    ships = f": it comes with the extra [{extra}], {install_command(extra)}" if extra else ""
    return f"package {name!r} not found{ships} (looked in: {'; '.join(looked)})"


def resolve_uri(uri: str, base: Path, packages: Mapping[str, str] | None = None) -> Path:
    """The file a URDF's ``filename`` names: ``package://NAME/rest``, ``file:///abs`` or a path
    (relative to ``base``, the URDF's directory); PackageError naming the URI and where it looked."""
    if uri.startswith("package://"):
        rest = unquote(uri[len("package://") :])
        name, _, relative = rest.partition("/")
        directory, looked = find_package(name, packages)
        if directory is None:
            raise PackageError(
                f"{uri}: {not_found(name, looked)}; give its directory in run.packages or ROS_PACKAGE_PATH"
            )
        path = directory / relative
        if not path.is_file():
            raise PackageError(f"{uri}: no file {relative!r} in package {name!r} ({directory})")
        return path.resolve()
    if uri.startswith("file://"):
        path = Path(unquote(uri[len("file://") :]))
    else:
        path = Path(uri)
    if not path.is_absolute():
        path = base / path
    if not path.is_file():
        raise PackageError(f"{uri}: file {path} not found")
    return path.resolve()


def process_xacro(path: Path, packages: Mapping[str, str] | None = None) -> str:
    """The URDF text of a ``.xacro`` file, ``$(find NAME)`` resolved as ``package://NAME``;
    PackageError for a package not found, ValueError for anything else xacro refuses."""
    try:
        import xacro
        from xacro import substitution_args
    except ImportError as e:  # pragma: no cover - a dependency of the project
        raise ValueError(f"{path}: reading a .xacro needs the xacro package (pip install xacro): {e}") from None

    def find(name: str) -> str:
        directory, looked = find_package(name, packages)
        if directory is None:
            raise PackageError(f"$(find {name}) in {path.name}: {not_found(name, looked)}")
        return str(directory)

    saved = (
        substitution_args._eval_find,
        dict(substitution_args._eval_dict) if hasattr(substitution_args, "_eval_dict") else None,
    )
    substitution_args._eval_find = find
    if hasattr(substitution_args, "_eval_dict"):
        substitution_args._eval_dict["find"] = find
    try:
        document = xacro.process_file(str(path))
        return document.toxml()
    except PackageError:
        raise
    except Exception as e:  # xacro raises its own XacroException, NameError, ... for a bad file
        for cause in (e.__cause__, getattr(e, "exc", None)):  # xacro wraps it in .exc or as the cause
            if isinstance(cause, PackageError):
                raise cause from None
        raise ValueError(f"{path}: xacro could not process it: {type(e).__name__}: {e}") from None
    finally:
        substitution_args._eval_find = saved[0]
        if saved[1] is not None:
            substitution_args._eval_dict.clear()
            substitution_args._eval_dict.update(saved[1])
