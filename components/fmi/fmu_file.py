"""Which FMU a type ``fmu`` runs, and what it declares: the file a ``path`` parameter names (a
pythonfmu model built into one on first use, cached by content) and its ``modelDescription.xml``
read with FMPy, checked to be an FMI 2.0 or 3.0 co-simulation FMU; FMUError otherwise.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tempfile
import zipfile
from functools import lru_cache
from pathlib import Path

from components.errors import ConfigError


class FMUError(ConfigError):
    """A problem with the FMU file itself (missing, corrupt, not co-simulation...)."""


def fmu_file(path: str, config_dir: str | Path | None, key: str = "path") -> Path:
    """The FMU a ``path`` parameter names: an .fmu, or a pythonfmu model (.py) built on first use."""
    file = Path(path)
    if not file.is_absolute():
        file = Path(config_dir or ".") / file
    if not file.is_file():
        raise FMUError(key, f"FMU file {path!r} not found (looked for {file})")
    if file.suffix == ".py":
        return build_python_model(file, key)
    if file.suffix != ".fmu":
        raise FMUError(key, f"expected an .fmu file (or a pythonfmu model .py), got {path!r}")
    return file.resolve()


def build_python_model(script: Path, key: str = "path") -> Path:
    """Build a pythonfmu model (an ``Fmi2Slave`` subclass in ``script``) into an FMU with state
    support, cached by content under ``$XDG_CACHE_HOME/zenorbit/fmus`` (built in a child process:
    pythonfmu imports the script)."""
    import pythonfmu

    digest = hashlib.sha256(script.read_bytes() + pythonfmu.__version__.encode()).hexdigest()[:16]
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "zenorbit" / "fmus"
    target = cache / f"{script.stem}-{digest}.fmu"
    if target.is_file():
        return target
    cache.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="zenorbit-build-", dir=cache) as tmp:
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "pythonfmu",
                "build",
                "-f",
                str(script),
                "-d",
                tmp,
                "--handle-state",
                "--serialize-state",
            ],
            capture_output=True,
            text=True,
        )
        built = list(Path(tmp).glob("*.fmu"))
        if done.returncode != 0 or len(built) != 1:
            last = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no FMU written"]
            raise FMUError(key, f"pythonfmu could not build {script}: {last[0]}")
        os.replace(built[0], target)  # atomic: a concurrent build writes the same bytes
    return target


@lru_cache(maxsize=32)
def _read(file: Path, mtime_ns: int):
    import fmpy

    try:
        with zipfile.ZipFile(file) as archive:
            if "modelDescription.xml" not in archive.namelist():
                raise FMUError("path", f"{file} is not an FMU: it has no modelDescription.xml")
        return fmpy.read_model_description(str(file))
    except zipfile.BadZipFile:
        raise FMUError("path", f"{file} is not an FMU: not a zip archive (corrupt or truncated?)") from None
    except FMUError:
        raise
    except Exception as e:  # FMPy's schema validation and XML errors
        raise FMUError("path", f"{file}: cannot read its modelDescription.xml: {e}") from None


def model_description(file: Path):
    """FMPy's model description of a co-simulation FMU; FMUError otherwise."""
    md = _read(file, file.stat().st_mtime_ns)
    if md.coSimulation is None:
        kinds = "model exchange" if md.modelExchange is not None else "no interface"
        raise FMUError(
            "path",
            f"{file.name} is an FMI {md.fmiVersion} FMU for {kinds} only; "
            "Zenorbit runs co-simulation FMUs (the FMU brings its own solver)",
        )
    if not md.fmiVersion.startswith(("2.", "3.")):
        raise FMUError("path", f"{file.name} is an FMI {md.fmiVersion} FMU; Zenorbit runs FMI 2.0 and 3.0")
    return md
