"""Bus adapter: runs one component as its own process, driven over Zenoh by the orchestrator.

    python -m components.runner --connect tcp/127.0.0.1:7447 --run-id demo-1a2b3c4d --name orbit

The orchestrator starts it (or a user does, for ``launch: external``), then sends, on the
component's command key: ``instantiate`` (type + parameters), ``initialize``, steps,
``get_state``/``set_state`` and ``terminate``. All work happens on the main thread, reading one
FIFO channel; the process exits after ``terminate``, or when the orchestrator's liveliness
token goes away.
"""
from __future__ import annotations

import argparse
import os
import sys
import threading
import time
import traceback

import numpy as np

from components import bus, registry
from components.sdk import Layout, resolve_parameters


class ComponentProcess:
    """State of the adapter: the component instance and its fixed input/output layouts."""

    def __init__(self, publish):
        self.publish = publish
        self.component = None
        self.inputs = None
        self.outputs = None

    def reply(self, op: str, body: dict | None = None, blob: bytes = b"") -> None:
        self.publish(bus.encode_message(bus.REPLY, {"op": op, **(body or {})}, blob))

    def fault(self, op: str, k: int, error: str) -> None:
        self.publish(bus.encode_message(bus.FAULT, {"op": op, "k": k, "error": error}))

    def control(self, body: dict, blob: bytes) -> bool:
        """Handle a control message; False when the process should exit."""
        op = body["op"]
        if op == "instantiate":
            cls = registry.load(body["type"], body["params"].get("_config_dir"))
            params, errors = resolve_parameters(cls, body["params"])
            if errors:
                raise errors[0]
            variables = cls.declare(params)
            self.inputs = Layout([v for v in variables if v.causality == "input"])
            self.outputs = Layout([v for v in variables if v.causality == "output"])
            self.input_vector = self.inputs.start_vector()
            self.output_vector = self.outputs.start_vector()
            self.component = cls(params)
            self.reply(op, {"inputs": self.inputs.size, "outputs": self.outputs.size, "pid": os.getpid()})
        elif op == "initialize":
            self.input_vector[:] = np.frombuffer(blob, dtype=np.float64)
            result = self.component.initialize(body["t0_ns"], self.inputs.unpack(self.input_vector))
            self.outputs.pack(result, self.output_vector)
            self.reply(op, {}, self.output_vector.tobytes())
        elif op == "get_state":
            self.reply(op, {}, bus.encode_state(self.component.get_state()))
        elif op == "set_state":
            self.component.set_state(bus.decode_state(blob))
            self.reply(op)
        elif op == "terminate":
            if self.component is not None:
                self.component.terminate()
            self.reply(op)
            return False
        else:
            raise ValueError(f"unknown control operation {op!r}")
        return True

    def step(self, payload: bytes) -> None:
        k, t_ns, h_ns, inputs = bus.decode_step(payload)
        self.input_vector[:] = inputs
        started = time.perf_counter()
        result = self.component.do_step(t_ns, h_ns, self.inputs.unpack(self.input_vector))
        self.outputs.pack(result, self.output_vector)
        self.publish(bus.encode_output(k, time.perf_counter() - started, self.output_vector))


def serve(connect: str, run_id: str, name: str, generation: int) -> int:
    import zenoh

    session = zenoh.open(bus.session_config(connect=[connect]))
    token = watcher = None
    try:
        cmd_key = bus.component_key(run_id, name, generation, "cmd")
        commands = session.declare_subscriber(cmd_key, zenoh.handlers.FifoChannel(1024))
        out = bus.publisher(session, bus.component_key(run_id, name, generation, "out"))
        # the orchestrator gone (killed, machine lost): wake the main loop with a local QUIT message
        orchestrator_gone = threading.Event()
        watcher = session.liveliness().declare_subscriber(
            bus.run_key(run_id, "alive", "orchestrator"),
            lambda s: orchestrator_gone.set() if s.kind == zenoh.SampleKind.DELETE else None)
        threading.Thread(target=_quit_when_set, args=(orchestrator_gone, session, cmd_key), daemon=True).start()
        token = session.liveliness().declare_token(bus.run_key(run_id, "alive", name, str(generation)))
        process = ComponentProcess(lambda payload: out.put(payload))
        while True:
            try:
                sample = commands.recv()  # blocks; raises once the subscriber is closed
            except Exception:
                return 1
            payload = sample.payload.to_bytes()
            kind = payload[:1]
            if kind == bus.QUIT:
                print("the orchestrator went away: exiting", file=sys.stderr)
                return 1
            try:
                if kind == bus.STEP:
                    process.step(payload)
                elif not process.control(*bus.decode_message(payload)):
                    return 0
            except Exception as error:  # reported to the orchestrator, which stops the run
                op = "step" if kind == bus.STEP else bus.decode_message(payload)[0].get("op", "?")
                k = bus.decode_step(payload)[0] if kind == bus.STEP else -1
                traceback.print_exc(file=sys.stderr)
                process.fault(op, k, f"{type(error).__name__}: {error}")
    finally:
        del token, watcher
        session.close()


def _quit_when_set(event: threading.Event, session, key: str) -> None:
    event.wait()
    session.put(key, bus.QUIT)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m components.runner", description=__doc__.splitlines()[0])
    parser.add_argument("--connect", required=True, help="the orchestrator's Zenoh endpoint, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--name", required=True, help="the component's name in the config")
    parser.add_argument("--generation", type=int, default=0)
    args = parser.parse_args(argv)
    return serve(args.connect, args.run_id, args.name, args.generation)


if __name__ == "__main__":
    sys.exit(main())
