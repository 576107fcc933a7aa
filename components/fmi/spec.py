"""An exported FMU's spec (``zenorbit.json`` in its resources: type, raw parameters, epoch) made
the component it names, at export time and inside the FMU alike: the type and parameters resolved,
the instance built, each problem an ExportError naming the key or option as the CLI words it.
"""

from __future__ import annotations

from pathlib import Path
from typing import cast

SPEC_FILE = "zenorbit.json"
FILES_DIR = "files"  # under the FMU's resources: the files the parameters name (the run's config dir)
EPOCH_EXAMPLE = "2022-09-18T12:00:00Z"


class ExportError(Exception):
    """The export cannot be done; ``problems`` are one line each, naming the key or option."""

    def __init__(self, problems: list[str] | str):
        self.problems = [problems] if isinstance(problems, str) else list(problems)
        super().__init__("; ".join(self.problems))


def resolve_spec(spec: dict, files_dir: Path):
    """The spec's type and parameters resolved (a registry.Resolved); ExportError naming the key."""
    from components import registry
    from components.errors import ConfigError
    from components.sdk import RunSettings

    try:
        return registry.resolve(spec["type"], spec["parameters"], RunSettings(spec.get("epoch"), files_dir))
    except registry.Unresolved as unresolved:
        e = unresolved.errors[0]
        if unresolved.stage == "type":  # a ConfigError: the type could not be loaded
            raise ExportError(cast(ConfigError, e).message) from None
        if unresolved.stage == "parameters":
            raise ExportError([_set_problem(p, spec) for p in unresolved.errors]) from None
        if isinstance(e, ConfigError):
            raise ExportError(_set_problem(e, spec)) from None
        raise e from None


def instantiate(resolved, spec: dict):
    """``resolved.build()`` with a ConfigError turned into an ExportError naming the key."""
    from components.errors import ConfigError

    try:
        return resolved.build()
    except ConfigError as e:
        raise ExportError(_set_problem(e, spec)) from None


def _missing_epoch(spec: dict) -> str:
    return (
        f"{spec['type']} needs the run epoch (run.epoch, the UTC of t = 0): pass --epoch UTC, "
        f"e.g. --epoch {EPOCH_EXAMPLE}"
    )


def _set_problem(error, spec: dict) -> str:
    """One line for a parameter error, as the CLI's describe words it."""
    from components.sdk import EPOCH_KEY

    if error.key.split(".")[0] == EPOCH_KEY:
        return _missing_epoch(spec) if spec.get("epoch") is None else f"--epoch: {error.message}"
    return f"--set {error.key}: {error.message}" if error.key else error.message
