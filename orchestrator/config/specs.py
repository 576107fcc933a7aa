"""What a valid run config is, as typed structures: a run, its components, events and faults."""

from __future__ import annotations

import builtins
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from components.sdk import Component, Layout, RunSettings, Variable
from orchestrator.hosts.bus_config import BusSpec


@dataclass
class ComponentSpec:
    name: str
    type: str
    cls: builtins.type[Component]  # builtins': the field above hides the name in the class
    step_ns: int
    parameters: dict  # raw, as in the config (+ injected run parameters)
    resolved: dict  # validated, SI
    typed: Any  # what the type's validate made of them (declare, preflight and __init__ get it)
    run: RunSettings  # the run's settings it was resolved with
    inputs: Layout
    outputs: Layout
    launch: str = "local"
    dedicated_cpu: bool | str = False  # true: its stepping thread on a CPU of its own; "process": all its threads
    on_failure: str = "stop"  # or "restart": the run goes back to its last checkpoint
    process: str | None = None  # its process group: the components naming it share one process
    shadow_of: str | None = None  # the component this one shadows (orchestrator/config/shadows.py)
    implausible: list = field(default_factory=list)  # "<key>: why" of parameters outside their plausible range

    @property
    def key(self) -> str:
        """Its entry in the config file."""
        return f"components.{self.shadow_of}.shadow" if self.shadow_of else f"components.{self.name}"

    @property
    def variables(self) -> dict[str, Variable]:
        return {
            v.name: v for v in self.inputs.variables + self.inputs.frames + self.outputs.variables + self.outputs.frames
        }


@dataclass
class ViewerSpec:
    """The live view: ``mode`` spawn | web | save (Rerun) or foxglove; ``file`` for save; ``rate_hz``
    of sim time; ``port`` for foxglove."""

    mode: str
    file: Path | None
    rate_hz: float
    open_browser: bool = False
    port: int = 8765


@dataclass
class Ros2Spec:
    """The live ROS 2 view: ``transport`` as chosen (rclpy or zenoh; ``why``: how), the ``python``
    that runs rclpy, the ROS side's router ``endpoint`` (zenoh), ``domain_id``, ``distro``,
    ``topics`` (None: all), ``rate_hz`` of sim time."""

    endpoint: str
    domain_id: int
    distro: str
    topics: list[str] | None
    rate_hz: float
    transport: str = "zenoh"
    python: str | None = None
    why: str = ""


@dataclass
class Event:
    at_ns: int
    swap: str
    type: str
    parameters: dict
    spec: ComponentSpec  # the new generation's, checked against the one it replaces


@dataclass(frozen=True)
class Fault:
    """An injected failure: ``component`` fails in its first step at or after ``at_ns``."""

    at_ns: int
    component: str
    kind: str
    duration_ns: int | None = None


@dataclass
class RunConfig:
    path: Path
    name: str
    epoch: str
    duration_ns: int
    step_ns: int
    algorithm: str
    realtime: float
    step_timeout_s: float
    start_timeout_s: float
    components: dict[str, ComponentSpec]
    connections: list[tuple[str, str, str, str]]  # (dst component, dst var, src component, src var)
    listen: list[str]
    bus: BusSpec
    join_timeout_s: float
    events: list[Event] = field(default_factory=list)
    faults: list[Fault] = field(default_factory=list)
    checkpoint_ns: int | None = None
    max_restarts: int = 3
    viewer: ViewerSpec | None = None
    ros2: Ros2Spec | None = None
    resolved: dict = field(default_factory=dict)  # the config as written to config.yaml
    packages: dict = field(default_factory=dict)  # run.packages: name -> absolute directory
    notes: list = field(
        default_factory=list
    )  # warnings found by the check (implausible values, physics), one line each
    record_flush_s: float = 1.0  # run.record_flush
    expect: str | None = None  # run.expect: the outcome the run must come to

    @property
    def steps(self) -> int:
        return self.duration_ns // self.step_ns

    @property
    def run_settings(self) -> RunSettings:
        """What every component gets besides its own parameters."""
        return RunSettings(self.epoch, self.path.parent.resolve(), self.packages)
