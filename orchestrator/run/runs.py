"""Runs alive on this machine, so that `orchestrator ps`, `stop` and `swap` can find them.

Each run writes a small JSON file (run id, name, Zenoh endpoint, pid, and the run's secret, which
a process needs to join its bus) in a per-user runtime directory while it lives, readable by that
user alone; the CLI reads them and talks to the run over Zenoh.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path


def directory() -> Path:
    base = os.environ.get("ZENORBIT_RUNTIME_DIR") or os.environ.get("XDG_RUNTIME_DIR") or tempfile.gettempdir()
    path = Path(base) / f"zenorbit-{os.getuid()}"
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    (path / "runs").mkdir(mode=0o700, exist_ok=True)
    return path / "runs"


def register(run_id: str, name: str, endpoint: str, config: Path, secret: str, settings: dict | None = None) -> None:
    """Make a run findable; its entry holds the run's secret and the CLI's bus settings (with
    TLS, the paths of its certificate and key), so only its user may read it."""
    entry = {
        "run_id": run_id,
        "name": name,
        "endpoint": endpoint,
        "pid": os.getpid(),
        "config": str(config),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "secret": secret,
        "settings": settings or {},
    }
    # written under a hidden name, then renamed: a reader never sees half an entry
    final = directory() / f"{run_id}.json"
    partial = final.with_name(f".{final.name}.{os.getpid()}")
    descriptor = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "w") as file:
        file.write(json.dumps(entry))
    os.replace(partial, final)


def unregister(run_id: str) -> None:
    (directory() / f"{run_id}.json").unlink(missing_ok=True)


def alive() -> list[dict]:
    """Registered runs whose orchestrator process still exists (stale files are removed)."""
    result = []
    for path in sorted(directory().glob("*.json")):
        try:
            entry = json.loads(path.read_text())
            os.kill(entry["pid"], 0)
        except (ValueError, KeyError, FileNotFoundError):  # not an entry (or gone since listed): not removed
            continue
        except ProcessLookupError:  # its orchestrator is gone (killed): a stale entry
            path.unlink(missing_ok=True)
            continue
        except PermissionError:
            pass
        result.append(entry)
    return result


def find(name: str) -> list[dict]:
    """Runs whose name or run id is ``name``."""
    return [r for r in alive() if name in (r["name"], r["run_id"])]
