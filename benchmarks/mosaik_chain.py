"""The 3-simulator no-op chain a -> b -> c in mosaik 3, one process per simulator, for comparison.

    <python with mosaik 3> benchmarks/mosaik_chain.py --steps 5000      # prints steps/s

Run by bench_performance.py with the interpreter of its own mosaik environment (mosaik is not a
dependency of Zenorbit). The same file is the simulator that each process runs.
"""

from __future__ import annotations

import argparse
import sys
import time

META = {
    "api_version": "3.0",
    "type": "time-based",
    "models": {"NoOp": {"public": True, "params": [], "attrs": ["u", "y"]}},
}


def simulator():
    import mosaik_api_v3

    class NoOp(mosaik_api_v3.Simulator):
        """One entity with input u and output y = 0, stepping every time unit."""

        def __init__(self):
            super().__init__(META)

        def init(self, sid, time_resolution, **params):
            return self.meta

        def create(self, num, model, **params):
            return [{"eid": f"noop{i}", "type": model} for i in range(num)]

        def step(self, t, inputs, max_advance):
            return t + 1

        def get_data(self, outputs):
            return {eid: {attr: 0.0 for attr in attrs} for eid, attrs in outputs.items()}

    mosaik_api_v3.start_simulation(NoOp())


def scenario(steps: int) -> float:
    import mosaik

    command = f"{sys.executable} {__file__} %(addr)s"
    world = mosaik.World({name: {"cmd": command} for name in "abc"}, debug=False)
    entities = [world.start(name, step_size=1).NoOp() for name in "abc"]
    world.connect(entities[0], entities[1], ("y", "u"))
    world.connect(entities[1], entities[2], ("y", "u"))
    started = time.perf_counter()
    world.run(until=steps, print_progress=False)
    return steps / (time.perf_counter() - started)


if __name__ == "__main__":
    if len(sys.argv) == 2 and not sys.argv[1].startswith("-"):
        simulator()  # started by mosaik with the address to connect to
    else:
        parser = argparse.ArgumentParser()
        parser.add_argument("--steps", type=int, default=5000)
        print(f"{scenario(parser.parse_args().steps):.1f}")
