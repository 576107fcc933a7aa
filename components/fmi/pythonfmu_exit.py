"""pythonfmu's binary held until a Python host exits: shared by FMUs Zenorbit exports
(components.fmi.exported) and pythonfmu FMUs it imports (components.fmi.imported), without
importing pythonfmu itself.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

_HELD_BINARIES: dict[str, Any] = {}


def hold_binary_until_exit(resources: Path, model_identifier: str) -> None:
    """Work around pythonfmu 0.7 crashing a Python process at exit.

    When a C++ library loaded after the FMU's binary binds to it (importing DART does), the
    binary can no longer be unloaded, and at exit its PyState is deleted twice (a static
    destructor, then its unload hook): heap corruption, abort. Holding the binary and calling its
    own finalizePythonInterpreter before the interpreter exits deletes it once. Only where the
    host process is Python itself: when pythonfmu started the interpreter, it finalizes it.
    """
    import ctypes

    if not sys.platform.startswith("linux") or os.path.realpath("/proc/self/exe") != os.path.realpath(sys.executable):
        return
    binary = str(resources.parent / "binaries" / "linux64" / f"{model_identifier}.so")
    if binary in _HELD_BINARIES:
        return
    try:  # RTLD_NOLOAD: only the binary already loaded (not the builder's instance)
        library = ctypes.CDLL(binary, mode=os.RTLD_NOLOAD | os.RTLD_NOW)
    except OSError:
        return
    if not hasattr(library, "finalizePythonInterpreter"):  # not a pythonfmu binary
        return
    if not _HELD_BINARIES:
        import atexit

        atexit.register(_release_binaries)
    _HELD_BINARIES[binary] = library


def _release_binaries() -> None:
    for library in _HELD_BINARIES.values():
        library.finalizePythonInterpreter()
