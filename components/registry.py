"""Component types by name.

A config's ``type`` is a registered name (``orbit.kepler``), an importable ``module:Class``, or a
Python file relative to the config, ``path/to/file.py:Class``.
"""
from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path

from components.errors import ConfigError
from components.sdk import Component

TYPES = {
    # small blocks for tests and examples
    "test.counter": "components.testing.blocks:Counter",
    "test.constant": "components.testing.blocks:Constant",
    "test.integrator": "components.testing.blocks:Integrator",
    "test.noop": "components.testing.blocks:NoOp",
    "test.faulty": "components.testing.blocks:Faulty",
    # orbit
    "orbit.kepler": "components.orbit.components:KeplerComponent",
    "orbit.sgp4": "components.orbit.components:SGP4Component",
    "orbit.custom_path": "components.orbit.components:CustomPathComponent",
    "orbit.fixed": "components.orbit.components:FixedComponent",
    # dynamics
    "dynamics.dart": "components.dynamics.component:DartDynamics",
    # controllers
    "controller.computed_torque": "components.controller.components:ComputedTorqueComponent",
    "controller.joint_pd": "components.controller.components:JointPDComponent",
    # FMI co-simulation FMUs (FMPy)
    "fmu": "components.fmi.imported:FMUComponent",
}


def load(type_name: str, config_dir: str | Path | None = None) -> type[Component]:
    """The Component class for ``type_name``; ConfigError (key ``type``) when it cannot be found."""
    if not isinstance(type_name, str):
        raise ConfigError("type", f"expected a component type name such as orbit.kepler, got {type_name!r}")
    target = TYPES.get(type_name, type_name)
    module_name, sep, class_name = target.rpartition(":")
    if not sep or not module_name or not class_name:
        raise ConfigError("type", f"unknown component type {type_name!r} (known: {', '.join(TYPES)}; "
                                  "or give module:Class or file.py:Class; `orchestrator types` lists them)")
    try:
        if module_name.endswith(".py"):
            path = Path(config_dir or ".") / module_name
            if not path.is_file():
                raise ConfigError("type", f"component file {path} not found")
            spec = importlib.util.spec_from_file_location(f"zenorbit_user_{path.stem}", path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[spec.name] = module
            spec.loader.exec_module(module)
        else:
            module = importlib.import_module(module_name)
    except ConfigError:
        raise
    except ImportError as e:
        raise ConfigError("type", f"cannot import {module_name!r} for type {type_name!r}: {e}") from None
    except Exception as e:  # the user's module fails while loading: one line naming it
        raise ConfigError("type", f"loading {module_name!r} for type {type_name!r} failed: "
                                  f"{type(e).__name__}: {e}") from None
    cls = getattr(module, class_name, None)
    if not (isinstance(cls, type) and issubclass(cls, Component)):
        raise ConfigError("type", f"{target!r} is not a Component subclass")
    return cls
