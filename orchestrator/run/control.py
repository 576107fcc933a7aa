"""The control server of a run: status, stop and swap requests from the CLI (`orchestrator ps`,
`stop`, `swap`), answered between steps. A bad request gets an error answer; it never ends the run."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import TYPE_CHECKING, Protocol, cast

from components import queries, registry
from components.errors import ConfigError
from components.message_codec import Malformed
from orchestrator.config.component_specs import component_spec
from orchestrator.config.connections import check_replacement, hands_over
from orchestrator.config.schema import COMPONENT
from orchestrator.config.shadows import mismatches
from orchestrator.config.specs import ComponentSpec, RunConfig
from orchestrator.config.yaml_file import ConfigErrors, apply_overrides

if TYPE_CHECKING:
    import zenoh

Request = queries.Status | queries.Stop | queries.Swap  # queries.CONTROL_REQUESTS
Answer = queries.RunStatus | queries.Stopping | queries.Swapped | queries.Refused


class SwapFailed(Exception):
    """A replacement could not start; the component it was to replace runs on."""


class StopRequested(BaseException):
    """Ctrl-C, SIGTERM or `orchestrator stop`: end the run cleanly. A BaseException, as
    KeyboardInterrupt is: the signal lands wherever the main thread is, and an ``except Exception``
    there (a decode, a retry) must not swallow the stop."""


def raise_stop(signum, frame):
    """The SIGTERM handler of a run."""
    raise StopRequested()


class Controlled(Protocol):
    """What the control server needs of a run."""

    config: RunConfig

    @property
    def row(self) -> int: ...  # the step boundary the run is at

    def specs(self) -> Mapping[str, ComponentSpec]: ...  # the live components, in config order

    def status(self) -> queries.RunStatus: ...

    def request_stop(self, reason: str) -> None: ...

    def swap(self, spec: ComponentSpec) -> int: ...  # the new generation; SwapFailed if it cannot start


class ControlServer:
    """Queries queue up as they arrive (with their requests, or why they are malformed); ``serve``
    answers them at a step boundary."""

    def __init__(self, run: Controlled):
        self.run = run
        self.queries: list[tuple[zenoh.Query, Request | str]] = []

    def add(self, query: zenoh.Query) -> None:
        request: Request | str
        try:
            payload = query.payload.to_bytes() if query.payload is not None else b""
            request = cast(Request, queries.decode_control_request(payload))  # one of CONTROL_REQUESTS
        except Malformed as e:
            request = f"malformed request: {e}"
        self.queries.append((query, request))

    def swap_boundary(self) -> int | None:
        """The step at which the first waiting swap can happen (a slower component is replaced at
        one of its own step boundaries), or None if no swap waits."""
        for _, request in self.queries:
            spec = self._swap_target(request)
            if spec is not None:
                return self._boundary(spec)
        return None

    def _swap_target(self, request) -> ComponentSpec | None:
        """The spec of the live component a swap request names, or None (not a swap, or no such
        component: the request is answered at once, with an error if it is one)."""
        return self.run.specs().get(request.component) if type(request) is queries.Swap else None

    def _boundary(self, spec: ComponentSpec) -> int:
        """The first step boundary of ``spec``'s component at or after the run's."""
        ratio = spec.step_ns // self.run.config.step_ns
        return -(-self.run.row // ratio) * ratio

    def serve(self, quiescent: bool) -> None:
        """Answer what can be answered now; swaps only when every component is at the boundary."""
        waiting = []
        for query, request in self.queries:
            target = self._swap_target(request)
            if target is not None and (not quiescent or self._boundary(target) != self.run.row):
                waiting.append((query, request))
                continue
            try:
                answer = queries.Refused(request, usage=True) if isinstance(request, str) else self._answer(request)
            except SwapFailed as error:
                answer = queries.Refused(str(error), usage=False)
            except (KeyError, TypeError, ValueError) as error:
                answer = queries.Refused(f"malformed request: {error}", usage=True)
            query.reply(query.key_expr, answer.encode())
            query.drop()
        self.queries = waiting

    def _answer(self, request: Request) -> Answer:
        run = self.run
        if type(request) is queries.Status:
            return run.status()
        if type(request) is queries.Stop:
            run.request_stop("stopped by request")
            return queries.Stopping()
        request = cast(queries.Swap, request)  # the one left
        name, specs = request.component, run.specs()
        if name not in specs:
            return queries.Refused(f"no component {name!r} (components: {', '.join(specs)})", usage=True)
        old = specs[name]
        new_type = request.type or old.type
        try:
            handed_over = hands_over(old, new_type, registry.load(new_type, run.config.path.parent.resolve()))
        except ConfigError as e:
            return queries.Refused(f"--type: {e.message}", usage=True)
        entry = {
            "type": new_type,
            "parameters": copy.deepcopy(old.parameters if handed_over else {}),
            "on_failure": old.on_failure,
        }
        try:
            apply_overrides(entry, [f"parameters.{s}" for s in request.set])
            converted, errors = COMPONENT.resolve(entry, f"components.{name}")
            if errors:
                raise ConfigErrors([str(e) for e in errors])
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
            return queries.Refused("; ".join(e.errors), usage=True)
        generation = run.swap(spec)
        return queries.Swapped(run.row, generation)
