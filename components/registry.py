"""Component types by name, and :func:`resolve`: the one way from a type and raw parameters
to a component's validated parameters, layouts and instance (config checks, the runner, the
in-process loop, the harness and exported FMUs).

A config's ``type`` is a registered name (``orbit.kepler``), an importable ``module:Class``, or a
Python file relative to the config, ``path/to/file.py:Class``.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from components.errors import ConfigError
from components.sdk import Component, Layout, RunSettings, layouts, resolve_parameters

TYPES = {
    # small blocks for tests and examples
    "test.counter": "components.testing.blocks:Counter",
    "test.constant": "components.testing.blocks:Constant",
    "test.integrator": "components.testing.blocks:Integrator",
    "test.noop": "components.testing.blocks:NoOp",
    "test.faulty": "components.testing.blocks:Faulty",
    "test.imager": "components.testing.blocks:Imager",
    "test.image_sum": "components.testing.blocks:ImageSum",
    # orbit
    "orbit.kepler": "components.orbit.components:KeplerComponent",
    "orbit.numerical": "components.orbit.numerical_component:NumericalComponent",
    "orbit.sgp4": "components.orbit.components:SGP4Component",
    "orbit.custom_path": "components.orbit.components:CustomPathComponent",
    "orbit.fixed": "components.orbit.components:FixedComponent",
    # dynamics
    "dynamics.dart": "components.dynamics.component:DartDynamics",
    "dynamics.pinocchio": "components.dynamics.component:PinocchioDynamics",
    # controllers
    "controller.computed_torque": "components.controller.computed_torque_component:ComputedTorqueComponent",
    "controller.joint_pd": "components.controller.joint_pd_component:JointPDComponent",
    "controller.capture": "components.controller.capture_component:CaptureComponent",
    "controller.bdot": "components.controller.bdot:BdotComponent",
    "sensor.imu": "components.sensors.components:ImuComponent",
    "sensor.force_torque": "components.sensors.components:ForceTorqueComponent",
    "sensor.relative_pose": "components.sensors.components:RelativePoseComponent",
    "sensor.magnetometer": "components.sensors.components:MagnetometerComponent",
    "sensor.camera": "components.camera.component:CameraComponent",
    # estimators
    "estimator.fiducial": "components.estimators.component:FiducialComponent",
    # FMI co-simulation FMUs (FMPy)
    "fmu": "components.fmi.imported:FMUComponent",
    # a ROS 2 node in the loop (rmw_zenoh)
    "ros2.bridge": "components.ros2.bridge:Ros2Bridge",
}


def load(type_name: object, config_dir: str | Path | None = None) -> type[Component]:
    """The Component class for ``type_name``; ConfigError (key ``type``) when it cannot be found."""
    if not isinstance(type_name, str):
        raise ConfigError("type", f"expected a component type name such as orbit.kepler, got {type_name!r}")
    target = TYPES.get(type_name, type_name)
    module_name, sep, class_name = target.rpartition(":")
    if not sep or not module_name or not class_name:
        raise ConfigError(
            "type",
            f"unknown component type {type_name!r} (known: {', '.join(TYPES)}; "
            "or give module:Class or file.py:Class; `orchestrator types` lists them)",
        )
    try:
        if module_name.endswith(".py"):
            path = Path(config_dir or ".") / module_name
            if not path.is_file():
                raise ConfigError("type", f"component file {path} not found")
            spec = importlib.util.spec_from_file_location(f"zenorbit_user_{path.stem}", path)
            assert spec is not None and spec.loader is not None, "a .py file has a spec with a loader"
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
        raise ConfigError(
            "type", f"loading {module_name!r} for type {type_name!r} failed: {type(e).__name__}: {e}"
        ) from None
    cls = getattr(module, class_name, None)
    if not (isinstance(cls, type) and issubclass(cls, Component)):
        raise ConfigError("type", f"{target!r} is not a Component subclass")
    return cls


@dataclass
class Resolved:
    """A component type with validated parameters and the layouts of its variables: all that
    comes before an instance. ``params``: the checked parameters (SI); ``typed``: what the type's
    ``validate`` made of them, which ``build`` hands to the instance."""

    cls: type[Component]
    params: dict
    typed: Any
    run: RunSettings
    inputs: Layout
    outputs: Layout

    def build(self) -> Component:
        """A new instance (FMI's instantiate)."""
        return self.cls(self.typed, self.run)


class Unresolved(Exception):
    """Why :func:`resolve` failed. ``stage``: "type" (it cannot be loaded), "parameters"
    (``errors`` holds every parameter error) or "declare" (``errors[0]`` is what declare raised)."""

    def __init__(self, stage: str, errors: Sequence[Exception]):
        super().__init__(str(errors[0]))
        self.stage, self.errors = stage, errors


def resolve(
    component_type: str | type[Component],
    params: Mapping[str, Any],
    run: RunSettings,
) -> Resolved:
    """The one way from raw parameters to a component: load the type (a name or the class),
    validate (once: its typed parameters are kept for ``build``), declare and lay out the inputs
    and outputs. Unresolved when any of it fails."""
    if isinstance(component_type, str):
        try:
            cls = load(component_type, run.config_dir)
        except ConfigError as e:
            raise Unresolved("type", [e]) from None
    else:
        cls = component_type
    checked, typed, errors = resolve_parameters(cls, params, run)
    if errors:
        raise Unresolved("parameters", errors)
    try:
        variables = cls.declare(typed, run)
    except Exception as e:  # a component's own bug too: the caller words it
        raise Unresolved("declare", [e]) from None
    return Resolved(cls, checked, typed, run, *layouts(variables))
