"""The control server of a run: status, stop and swap requests from the CLI (`orchestrator ps`,
`stop`, `swap`), answered between steps. A bad request gets an error answer; it never ends the run."""

from __future__ import annotations

import copy
import json
from collections.abc import Mapping
from typing import Protocol

from components import registry
from components.errors import ConfigError
from orchestrator.config.connections import check_replacement, hands_over
from orchestrator.config.load import component_spec
from orchestrator.config.schema import COMPONENT
from orchestrator.config.shadows import mismatches
from orchestrator.config.specs import ComponentSpec, RunConfig
from orchestrator.config.yaml_file import ConfigErrors, apply_overrides


class SwapFailed(Exception):
    """A replacement could not start; the component it was to replace runs on."""


class StopRequested(Exception):
    """Ctrl-C, SIGTERM or `orchestrator stop`: end the run cleanly."""


def raise_stop(signum, frame):
    """The SIGTERM handler of a run."""
    raise StopRequested()


class Controlled(Protocol):
    """What the control server needs of a run."""

    config: RunConfig

    @property
    def row(self) -> int: ...  # the step boundary the run is at

    def specs(self) -> Mapping[str, ComponentSpec]: ...  # the live components, in config order

    def status(self) -> dict: ...

    def request_stop(self, reason: str) -> None: ...

    def swap(self, spec: ComponentSpec) -> int: ...  # the new generation; SwapFailed if it cannot start


class ControlServer:
    """Queries queue up as they arrive; ``serve`` answers them at a step boundary."""

    def __init__(self, run: Controlled):
        self.run = run
        self.queries: list = []

    def add(self, query) -> None:
        self.queries.append(query)

    def swap_boundary(self) -> int | None:
        """The step at which the first waiting swap can happen (a slower component is replaced at
        one of its own step boundaries), or None if no swap waits."""
        for query in self.queries:
            spec = self._swap_target(_request(query))
            if spec is not None:
                return self._boundary(spec)
        return None

    def _swap_target(self, request: dict) -> ComponentSpec | None:
        """The spec of the live component a swap request names, or None (not a swap, or no such
        component: the request is answered at once, with an error if it is one)."""
        component = request.get("component")
        if request.get("op") != "swap" or not isinstance(component, str):
            return None
        return self.run.specs().get(component)

    def _boundary(self, spec: ComponentSpec) -> int:
        """The first step boundary of ``spec``'s component at or after the run's."""
        ratio = spec.step_ns // self.run.config.step_ns
        return -(-self.run.row // ratio) * ratio

    def serve(self, quiescent: bool) -> None:
        """Answer what can be answered now; swaps only when every component is at the boundary."""
        waiting = []
        for query in self.queries:
            request = _request(query)
            target = self._swap_target(request)
            if target is not None and (not quiescent or self._boundary(target) != self.run.row):
                waiting.append(query)
                continue
            try:
                answer = self._answer(request)
            except SwapFailed as error:
                answer = {"ok": False, "error": str(error), "usage": False}
            except (KeyError, TypeError, ValueError) as error:
                answer = {"ok": False, "error": f"malformed request: {error}", "usage": True}
            query.reply(query.key_expr, json.dumps(answer))
            query.drop()
        self.queries = waiting

    def _answer(self, request: dict) -> dict:
        run = self.run
        op = request.get("op")
        if op == "status":
            return {"ok": True, **run.status()}
        if op == "stop":
            run.request_stop("stopped by request")
            return {"ok": True}
        if op == "swap":
            name = request["component"]
            specs = run.specs()
            if not isinstance(name, str) or name not in specs:
                return {"ok": False, "error": f"no component {name!r} (components: {', '.join(specs)})", "usage": True}
            old = specs[name]
            new_type = request.get("type") or old.type
            try:
                handed_over = hands_over(old, new_type, registry.load(new_type, run.config.path.parent.resolve()))
            except ConfigError as e:
                return {"ok": False, "error": f"--type: {e.message}", "usage": True}
            entry = {
                "type": new_type,
                "parameters": copy.deepcopy(old.parameters if handed_over else {}),
                "on_failure": old.on_failure,
            }
            try:
                apply_overrides(entry, [f"parameters.{s}" for s in request.get("set", [])])
                converted, problems = COMPONENT.resolve(entry, f"components.{name}")
                if problems:
                    raise ConfigErrors([str(e) for e in problems])
                spec = component_spec(
                    name,
                    {**converted, "step": old.step_ns},
                    run.config.step_ns,
                    run.config.run_settings,
                    f"components.{name}",
                )
                spec.shadow_of = old.shadow_of  # a shadow swapped stays one, and fits its main
                problems = check_replacement(spec, run.config.connections) + (
                    mismatches(specs[old.shadow_of], spec, run.config.connections) if old.shadow_of else []
                )
                if problems:
                    raise ConfigErrors(problems)
            except ConfigErrors as e:
                return {"ok": False, "error": "; ".join(e.errors), "usage": True}
            generation = run.swap(spec)
            return {"ok": True, "step": run.row, "generation": generation}
        return {"ok": False, "error": f"unknown operation {op!r} (status, stop, swap)"}


def _request(query) -> dict:
    try:
        request = json.loads(query.payload.to_bytes()) if query.payload is not None else {}
    except ValueError:
        return {}
    return request if isinstance(request, dict) else {}
