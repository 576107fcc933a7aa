"""Runs across hosts against loopback: the lockstep rate and the demo's real-time factor with the
components on other hosts over TLS, the cost of TLS per step, and how soon a cut link is seen.

    sudo python benchmarks/bench_hosts.py [--repeats 3] [--steps 5000]

Hosts are network namespaces on one link (tests/hosts/netns.py): the orchestrator on one, two
components on two others (`orchestrator join`). Each figure alternates its variants (A B A B...)
so that a busy machine weighs on both alike; medians and their ratios are printed.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.hosts.netns import Network, missing  # noqa: E402

SUMMARY = re.compile(r"(\d+) steps of \d+.*?\(([\d.]+) s stepping, real-time factor ([\d.]+)\)")

RING = """run: {{name: ring, epoch: 2022-09-18T12:00:00Z, duration: {steps} ms, step: 1 ms}}
bus: {{listen: [{listen}], tls: {tls}}}
components:
  a: {{type: test.noop}}
  b: {{type: test.noop, launch: {launch}}}
  c: {{type: test.noop, launch: {launch}}}
connections: {{b.u: a.y, c.u: b.y, a.u: c.y}}
"""

CHAIN = """run: {{name: cut, epoch: 2022-09-18T12:00:00Z, duration: 10 min, step: 1 ms, realtime: 1, step_timeout: 10 min}}
bus: {{listen: [tcp/0.0.0.0:0], lease: {lease}}}
components:
  src: {{type: test.constant, parameters: {{value: 1.0}}}}
  b: {{type: test.integrator, launch: external}}
  c: {{type: test.integrator, launch: external}}
connections: {{b.u: src.y, c.u: b.x}}
"""


def cli(host, *args) -> list[str]:
    command = [sys.executable, "-m", "orchestrator.cli", *map(str, args)]
    return host.command(*command) if host is not None else command


def run(network, args: list, external: list[str], directory: Path) -> tuple[int, float, float]:
    """(steps, stepping seconds, real-time factor) of `orchestrator run ARGS --record DIR` on host
    orch (or here, without a network), its external components joined from hosts a and b."""
    record = directory / f"rec{time.monotonic_ns()}"
    orchestrator = subprocess.Popen(
        cli(network and network["orch"], "run", *args, "--record", record),
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    joins = []
    for name, host in zip(external, ("a", "b")):
        path = record / "join" / f"{name}.join"
        while not path.exists():
            time.sleep(0.05)
        joins.append(
            subprocess.Popen(
                cli(network[host], "join", path), cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
            )
        )
    _, err = orchestrator.communicate(timeout=900)
    for join in joins:
        join.wait(timeout=60)
    found = SUMMARY.search(err)
    if orchestrator.returncode or not found:
        raise SystemExit(f"run failed:\n{err}")
    return int(found.group(1)), float(found.group(2)), float(found.group(3))


def detection(network, directory: Path, lease: str) -> float:
    """Seconds from pulling host a's cable to the orchestrator's error naming the lost component."""
    config = directory / "cut.yaml"
    config.write_text(CHAIN.format(lease=lease))
    record = directory / f"cut{time.monotonic_ns()}"
    orchestrator = subprocess.Popen(
        cli(network["orch"], "run", config, "--record", record),
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    joins = []
    for name, host in (("b", "a"), ("c", "b")):
        path = record / "join" / f"{name}.join"
        while not path.exists():
            time.sleep(0.05)
        joins.append(
            subprocess.Popen(
                cli(network[host], "join", path), cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
            )
        )
    signals = record / "signals.parquet"
    while not any(p.suffix == ".parquet" and not p.name.startswith(".") for p in signals.glob("*")):
        time.sleep(0.05)  # stepping: the first 1000 rows are in
    network.cut("a")
    cut = time.monotonic()
    try:
        for line in orchestrator.stderr:
            if line.startswith("error:"):
                return time.monotonic() - cut
        raise SystemExit("the run ended without an error")
    finally:
        orchestrator.wait(timeout=60)
        network.mend("a")
        for join in joins:
            join.kill()
            join.wait()


def median(values: list[float]) -> float:
    values = sorted(values)
    return values[len(values) // 2] if len(values) % 2 else sum(values[len(values) // 2 - 1 :][:2]) / 2


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--demo", default="3 s", help="simulated time of each demo run")
    parser.add_argument("--only", choices=("ring", "demo", "cut"), help="this figure alone")
    args = parser.parse_args()
    if missing():
        raise SystemExit(f"cannot run: {missing()}")
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}; load {os.getloadavg()[0]:.1f}"
    )
    directory = Path(tempfile.mkdtemp(prefix="bench-hosts-"))
    os.environ["ZENORBIT_RUNTIME_DIR"] = str(directory / "runtime")
    with Network(["orch", "a", "b"]) as network:
        if args.only in (None, "ring"):
            ring_figures(network, directory, args)
        if args.only in (None, "demo"):
            demo_figures(network, directory, args)
        if args.only in (None, "cut"):
            seen = [detection(network, directory, "1 s") for _ in range(args.repeats)]
            print(
                f"\ncut link (bus.lease 1 s): seen after {', '.join(f'{s:.2f}' for s in seen)} s "
                f"(median {median(seen):.2f} s)"
            )


def ring_figures(network, directory: Path, args) -> None:
    ring = {}
    for name, listen, tls, launch in (
        ("loopback", "tcp/127.0.0.1:0", "false", "local"),
        ("hosts, TLS", "tcp/0.0.0.0:0", "auto", "external"),
        ("hosts, plain TCP", "tcp/0.0.0.0:0", "false", "external"),
    ):
        path = directory / f"ring-{len(ring)}.yaml"
        path.write_text(RING.format(steps=args.steps, listen=listen, tls=tls, launch=launch))
        ring[name] = (path, ["b", "c"] if launch == "external" else [])
    rates: dict[str, list[float]] = {name: [] for name in ring}
    for _ in range(args.repeats):
        for name, (path, external) in ring.items():
            steps, stepping, _ = run(network if external else None, [path], external, directory)
            rates[name].append(steps / stepping)
    base = median(rates["loopback"])
    print(f"\nlockstep, 3 no-op components in a ring (b and c on hosts a and b), {args.steps} steps of 1 ms:")
    for name, values in rates.items():
        print(
            f"  {name:<18} {median(values):7.0f} steps/s ({1e6 / median(values):5.0f} us/step), "
            f"x{median(values) / base:.2f} of loopback"
        )
    tls_cost = 1e6 / median(rates["hosts, TLS"]) - 1e6 / median(rates["hosts, plain TCP"])
    print(f"  TLS per step (hosts, TLS against hosts, plain TCP): {tls_cost:+.0f} us", flush=True)


def demo_figures(network, directory: Path, args) -> None:
    demo = ROOT / "configs" / "humanoid_tracking.yaml"
    common = ["--set", f"run.duration={args.demo}", "--set", "components.dynamics.dedicated_cpu=false"]
    variants = {
        "loopback": common,
        "hosts, TLS": common
        + [
            "--set",
            "bus.listen=[tcp/0.0.0.0:0]",
            "--set",
            "components.dynamics.launch=external",
            "--set",
            "components.controller.launch=external",
        ],
    }
    factors: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(args.repeats):
        for name, extra in variants.items():
            external = ["dynamics", "controller"] if name != "loopback" else []
            factors[name].append(run(network if external else None, [demo, *extra], external, directory)[2])
    print(f"\ndemo (configs/humanoid_tracking.yaml, {args.demo}; dynamics and controller on hosts a and b):")
    for name, values in factors.items():
        print(
            f"  {name:<18} real-time factor {median(values):5.2f} (x{median(values) / median(factors['loopback']):.2f} "
            f"of loopback; runs: {', '.join(f'{v:.2f}' for v in values)})",
            flush=True,
        )


if __name__ == "__main__":
    main()
