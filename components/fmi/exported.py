"""Zenorbit component types as FMI 2.0 co-simulation FMUs (``orchestrator export-fmu``).

:func:`export_fmu` fixes a type's parameters at export time and packages it with pythonfmu's
builder (nothing is compiled: pythonfmu ships its binary). The FMU's resources hold
``zenorbit.json`` (type, raw parameters, epoch), a copy of the ``components`` package, and under
``files/`` every file a parameter names (relative paths keep their place; at run time
``_config_dir`` is that ``files`` directory). The slave that runs inside:
:class:`components.fmi.slave.ComponentSlave`; the spec made a component, here and there:
:mod:`components.fmi.spec`.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

from components.fmi.spec import FILES_DIR, SPEC_FILE, ExportError, instantiate, resolve_spec

OUTSIDE_DIR = "_outside"  # files/ place of a parameter's file that lies above the config dir
IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
PACKAGE_DIR = Path(__file__).resolve().parents[1]  # the components package

SCRIPT = '''"""FMU entry point written by orchestrator export-fmu: Zenorbit type {type_name!r}.

The parameters, the Zenorbit code and the files they name are in this FMU's resources.
"""
from components.fmi.slave import ComponentSlave

_HELD = [globals()]   # see ComponentSlave.__init__: the first instantiation drops this reference


class ZenorbitFmu(ComponentSlave):
    """{type_name!r} as an FMI 2.0 co-simulation FMU (see resources/zenorbit.json)."""
'''


def export_fmu(type_name: str, parameters: dict, out: Path, epoch: str | None, config_dir: Path) -> Path:
    """Write ``out`` (NAME.fmu, model identifier NAME): type ``type_name`` with its raw
    ``parameters`` fixed (as a config gives them; the CLI's ``--set``), relative paths read from
    ``config_dir``, ``epoch`` the UTC of t = 0 (needed by types that read run.epoch).
    ExportError on any problem."""
    from components import bus

    out, config_dir = Path(out), Path(config_dir).resolve()
    if out.suffix != ".fmu":
        raise ExportError(f"-o {out}: the output must be a .fmu file, e.g. -o {out.stem or 'model'}.fmu")
    identifier = out.stem
    if not IDENTIFIER.match(identifier):
        suggestion = re.sub(r"\W", "_", identifier)
        suggestion = suggestion if IDENTIFIER.match(suggestion) else f"fmu_{suggestion}"
        raise ExportError(
            f"-o {out.name}: the file name is the FMU's model identifier and must be a C identifier "
            f"(letters, digits and _, not starting with a digit), e.g. -o {suggestion}.fmu"
        )
    if epoch is not None:
        epoch = _checked_epoch(epoch)
    given = bus.jsonable(parameters)

    with tempfile.TemporaryDirectory(prefix="zenorbit-fmu-") as temporary:
        staging = Path(temporary) / "resources"
        files_dir = staging / FILES_DIR
        files_dir.mkdir(parents=True)
        type_in_fmu = _copy_type_file(type_name, config_dir, files_dir)
        parameters = _copy_named_files(given, config_dir, files_dir)
        spec = {
            "type": type_in_fmu,
            "parameters": parameters,
            "epoch": epoch,
            "model_identifier": identifier,
            "exported_type": type_name,
        }
        # the checks the slave does when the FMU is instantiated, here with errors worth reading
        try:
            resolved = resolve_spec(spec, files_dir)
            instantiate(resolved, spec).terminate()
        except ExportError:
            raise
        except Exception as e:  # the type's own code failed: one line naming it, no traceback
            raise ExportError(f"{type_name}: instantiating it failed: {type(e).__name__}: {e}") from None

        (staging / SPEC_FILE).write_text(json.dumps(spec, indent=2, sort_keys=True) + "\n")
        shutil.copytree(
            PACKAGE_DIR, staging / "components", ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc")
        )
        # pythonfmu imports the script by module name: one name per export, not a cached module
        digest = hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:12]
        module = f"zenorbit_fmu_{identifier}_{digest}"
        script = Path(temporary) / f"{module}.py"
        script.write_text(SCRIPT.format(type_name=type_name))
        built = _build(script, Path(temporary) / out.name, staging, resolved.cls.restorable())
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            shutil.move(built, out)
        except OSError as e:
            raise ExportError(f"-o {out}: cannot write the FMU there ({e.strerror or e})") from None
    return out


def _build(script: Path, destination: Path, staging: Path, restorable: bool) -> Path:
    from pythonfmu.builder import FmuBuilder

    saved_path = list(sys.path)
    try:
        return Path(
            FmuBuilder.build_FMU(
                script,
                dest=destination,
                project_files=[staging / SPEC_FILE, staging / "components", staging / FILES_DIR],
                canGetAndSetFMUstate=restorable,
                canSerializeFMUstate=restorable,
            )
        )
    finally:
        sys.path[:] = saved_path  # the builder leaves the script's (temporary) directory on it
        sys.modules.pop(script.stem, None)


def _checked_epoch(epoch: str) -> str:
    from components.errors import ConfigError
    from components.schema import UtcTime

    try:
        return UtcTime().convert(epoch, "--epoch")
    except ConfigError as e:
        raise ExportError(f"--epoch: {e.message}") from None


def _place_in_files(relative: str) -> str:
    """Where a file named by a relative path goes under files/: the same path, or, for one above
    the config dir (../x), a path under files/_outside (the parameter is rewritten to it)."""
    normal = os.path.normpath(relative)
    parts = Path(normal).parts
    if parts and parts[0] == "..":
        return Path(OUTSIDE_DIR, *("up" if p == ".." else p for p in parts)).as_posix()
    return Path(normal).as_posix()


def _copy_file(relative: str, config_dir: Path, files_dir: Path) -> str | None:
    """Copy config_dir/relative into files/ and return its path there, if it is an existing file."""
    if not relative or Path(relative).is_absolute():
        return None
    source = config_dir / relative
    try:
        if not source.is_file():
            return None
    except OSError:  # a string too long or odd to be a path
        return None
    place = _place_in_files(relative)
    target = files_dir / place
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy2(source, target)
    return place


def _copy_named_files(value, config_dir: Path, files_dir: Path):
    """The parameters with every relative path to an existing file copied under files/ (and
    rewritten when it had to move); absolute paths and other strings as they are."""
    if isinstance(value, dict):
        return {k: _copy_named_files(v, config_dir, files_dir) for k, v in value.items()}
    if isinstance(value, list):
        return [_copy_named_files(v, config_dir, files_dir) for v in value]
    if isinstance(value, str):
        place = _copy_file(value, config_dir, files_dir)
        return value if place is None or place == Path(value).as_posix() else place
    return value


def _copy_type_file(type_name: str, config_dir: Path, files_dir: Path) -> str:
    """A ``file.py:Class`` type's file goes into files/ too (its own imports do not)."""
    module, sep, class_name = type_name.rpartition(":")
    if not sep or not module.endswith(".py"):
        return type_name
    place = _copy_file(module, config_dir, files_dir)
    return type_name if place is None else f"{place}:{class_name}"


def fmu_summary(path: Path) -> dict[str, Any]:
    """Counts and options read back from an FMU's modelDescription.xml."""
    with zipfile.ZipFile(path) as archive:
        root = ElementTree.fromstring(archive.read("modelDescription.xml"))
    causalities = [v.get("causality") for v in root.iter("ScalarVariable")]
    co_simulation = root.find("CoSimulation")
    if co_simulation is None:
        raise ValueError(f"{path}: modelDescription.xml has no CoSimulation element")
    return {
        "fmi_version": root.get("fmiVersion"),
        "model_identifier": co_simulation.get("modelIdentifier"),
        "inputs": causalities.count("input"),
        "outputs": causalities.count("output"),
        "state": co_simulation.get("canGetAndSetFMUstate") == "true",
    }
