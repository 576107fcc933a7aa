"""What paces the paper's demo over the bus: its real-time factor with a dynamics of a chosen
per-step cost, and where each step's CPU time goes, process by process and thread by thread.

    python benchmarks/bench_pace.py [--cost 100 ...] [--dart] [--pinocchio] [--floor]
                                    [--dedicated true process false] [--seconds 10] [--rounds 3] [--baseline DIR]

Each variant runs configs/humanoid_tracking.yaml over the bus (``orchestrator run``, Jacobi, 1 ms)
for ``--seconds`` simulated:

- ``stand-in C us``: the dynamics replaced by benchmarks/paced_stand_ins.py, which spends C us of
  CPU time per step and returns the states of a dynamics.dart run of the demo recorded in process
  beforehand (so the controller computes on the demo's states; its torques are ignored): the demo
  as it would run with an engine of that cost;
- ``both stand-ins at 0 us`` (``--floor``): the controller replaced too, by a stand-in returning the
  recorded run's torques at no cost: what the bus, the runner and the orbit allow on their own, the
  ceiling of any engine and controller;
- ``dynamics.dart`` (``--dart``): the demo as it is;
- ``dynamics.pinocchio`` (``--pinocchio``): the demo with the other engine (``--cost`` with no
  value leaves the stand-in out);
- with ``--dedicated``, each of them with the dynamics' ``dedicated_cpu`` set to each mode given
  (true: its stepping thread on a CPU of its own; process: its whole process; false: none);
- each of them again on the Zenorbit tree ``--baseline DIR`` (a copy of another commit), for a
  before/after on the same machine.

The variants alternate, ``--rounds`` times. For each run: the real-time factor of the stepping
loop (the summary line's), and, sampled from /proc between 25% and 85% of the run, the CPU time
per step of each process's main thread, its Zenoh threads and any other thread. The figures are
medians over the rounds. Wall-clock figures on a shared machine are noisy: the load average is
printed with each run, and the CPU times hold better than the real-time factor.
"""

from __future__ import annotations

import argparse
import collections
import io
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if "--child" not in sys.argv:  # a child runs on the tree its PYTHONPATH names
    sys.path.insert(0, str(ROOT))

from components.constants import NS_PER_S  # noqa: E402

DEMO = ROOT / "configs" / "humanoid_tracking.yaml"
STAND_IN = "benchmarks.paced_stand_ins:PacedDynamics"
CONTROLLER_STAND_IN = "benchmarks.paced_stand_ins:PacedController"
TICKS = os.sysconf("SC_CLK_TCK")
ZENOH_THREADS = ("app", "rx", "tx", "acc", "net")  # Zenoh's runtime threads are named <runtime>-<n>
WINDOW = (0.25, 0.85)  # the part of the run whose CPU time is counted


def machine() -> str:
    model = platform.processor() or platform.machine()
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            model = line.split(":", 1)[1].strip()
            break
    return f"{model}, {os.cpu_count()} cores, Python {platform.python_version()}"


def record_demo(seconds: float, folder: Path) -> None:
    """The outputs of the demo's first ``seconds``, run in this process, as rows: dynamics.dart's
    in ``folder``/dynamics.npy, the controller's in ``folder``/controller.npy."""
    from components.registry import resolve
    from orchestrator.config.load import load
    from orchestrator.run.inprocess import run_in_process

    config = load(DEMO, [f"run.duration={seconds} s"])
    rows = run_in_process(config)
    start = 0
    for name, spec in config.components.items():
        size = resolve(spec.cls, spec.parameters, config.run_settings).outputs.size
        if name in ("dynamics", "controller"):
            np.save(folder / f"{name}.npy", rows[:, start : start + size])
        start += size


def descendants(pid: int) -> list[int]:
    children = collections.defaultdict(list)
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                children[int(Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()[1])].append(int(entry))
            except (OSError, IndexError):
                pass
    found, stack = [], [pid]
    while stack:
        p = stack.pop()
        found.append(p)
        stack.extend(children.get(p, ()))
    return found


def cpu_sample(root: int, exclude: int) -> dict[tuple[str, str], float]:
    """CPU seconds so far of every thread of ``root``'s process tree but ``exclude``, by (process,
    thread group): processes by their --name (components) or as the orchestrator; groups main,
    zenoh, other."""
    sample: dict[tuple[str, str], float] = collections.Counter()
    for pid in descendants(root):
        try:
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode().split("\0")
            name = argv[argv.index("--name") + 1] if "--name" in argv else "orchestrator"
            for tid in os.listdir(f"/proc/{pid}/task"):
                if int(tid) == exclude:
                    continue
                fields = Path(f"/proc/{pid}/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
                comm = Path(f"/proc/{pid}/task/{tid}/comm").read_text().strip()
                group = "main" if int(tid) == pid else "zenoh" if comm.split("-")[0] in ZENOH_THREADS else "other"
                sample[(name, group)] += (int(fields[11]) + int(fields[12])) / TICKS
        except (OSError, ValueError, IndexError):
            pass  # a process or thread that ended meanwhile
    return sample


def cpu_window(run, root: int, exclude: int, window: tuple[float, float], out: list) -> None:
    """From a thread of the orchestrator's process: CPU samples when the run's recorded rows pass
    the two fractions of ``window``; ``out`` gets (sample, row) twice."""
    steps = run.config.steps
    for fraction in window:
        while run.row < fraction * steps:
            if run.loop_s:  # the loop ended (too early for this sample)
                return
            time.sleep(0.005)
        sample, row = cpu_sample(root, exclude), run.row
        out.append((sample, row))


def child(overrides: list[str]) -> None:
    """One bus run of the demo with ``overrides``, from this process (the orchestrator); prints
    JSON: the real-time factor and the CPU us per step by process and thread group."""
    import json
    import threading

    from orchestrator.config.load import load
    from orchestrator.run.engine import Run

    run = Run(load(DEMO, overrides), out=io.StringIO())
    samples: list = []
    sampler = threading.Thread(
        target=lambda: cpu_window(run, os.getpid(), threading.get_native_id(), WINDOW, samples), daemon=True
    )
    sampler.start()
    if run.execute() != 0:
        raise SystemExit(f"the run failed: {overrides}")
    sampler.join(timeout=1.0)
    budget = {}
    if len(samples) == 2:
        (a, ka), (b, kb) = samples
        budget = {"/".join(key): (b[key] - a.get(key, 0.0)) / (kb - ka) * 1e6 for key in b}
    json.dump({"factor": run.config.steps * run.config.step_ns / NS_PER_S / run.loop_s, "budget": budget}, sys.stdout)


def bus_run(overrides: list[str], tree: Path) -> tuple[float, dict]:
    """(real-time factor, CPU us per step by "process/group") of one run on Zenorbit tree ``tree``."""
    import json

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tree), str(ROOT)])}
    result = subprocess.run(
        [sys.executable, __file__, "--child", *overrides], cwd=tree, env=env, capture_output=True, text=True
    )
    if result.returncode != 0:
        raise SystemExit(f"the run failed ({' '.join(overrides)}):\n{result.stderr[-3000:]}")
    data = json.loads(result.stdout)
    return data["factor"], data["budget"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cost", type=float, nargs="*", default=[100.0], help="stand-in costs, us per step (100)")
    parser.add_argument("--dart", action="store_true", help="also the demo with dynamics.dart")
    parser.add_argument("--pinocchio", action="store_true", help="also the demo with dynamics.pinocchio")
    parser.add_argument(
        "--floor", action="store_true", help="also both the dynamics and the controller as stand-ins at 0 us"
    )
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated seconds per run (10)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--baseline", type=Path, help="another Zenorbit tree to run each variant on as well")
    parser.add_argument(
        "--dedicated",
        nargs="*",
        choices=("true", "process", "false"),
        default=[],
        help="run each variant with the dynamics' dedicated_cpu set to each of these (default: the config's)",
    )
    parser.add_argument("--child", nargs="*", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        child(args.child)
        return
    print(f"machine: {machine()}; load average {load()}")
    recorded = Path(tempfile.mkdtemp(prefix="zenorbit-pace-"))
    record_demo(args.seconds, recorded)
    duration = f"run.duration={args.seconds:g} s"

    def stand_in(name: str, kind: str, cost: float) -> list[str]:
        """The overrides that put stand-in ``kind`` of ``cost`` us per step in place of ``name``."""
        return [
            f"components.{name}.type={kind}",
            f"components.{name}.parameters.replay={recorded / f'{name}.npy'}",
            f"components.{name}.parameters.cost={cost:g} us",
        ]

    variants = {f"stand-in {c:g} us": [duration, *stand_in("dynamics", STAND_IN, c)] for c in args.cost}
    if args.floor:
        variants["both stand-ins at 0 us"] = [
            duration,
            *stand_in("dynamics", STAND_IN, 0),
            *stand_in("controller", CONTROLLER_STAND_IN, 0),
        ]
    if args.dart:
        variants["dynamics.dart"] = [duration]
    if args.pinocchio:
        variants["dynamics.pinocchio"] = [duration, "components.dynamics.type=dynamics.pinocchio"]
    if args.dedicated:
        variants = {
            f"{label}, dedicated_cpu {mode}": [*overrides, f"components.dynamics.dedicated_cpu={mode}"]
            for label, overrides in variants.items()
            for mode in args.dedicated
        }
    trees = {"": ROOT} if args.baseline is None else {"": ROOT, " (baseline)": args.baseline.resolve()}
    results = collections.defaultdict(list)
    for r in range(args.rounds):
        for variant, overrides in variants.items():
            for suffix, tree in trees.items():
                factor, budget = bus_run(overrides, tree)
                results[variant + suffix].append((factor, budget))
                print(
                    f"  round {r + 1}: {variant + suffix:<48} real-time factor {factor:5.2f}   (load average {load()})",
                    flush=True,
                )
    print(
        f"\nthe demo over the bus, {args.seconds:g} s simulated, medians of {args.rounds} rounds "
        f"(CPU per step between {WINDOW[0]:.0%} and {WINDOW[1]:.0%} of the run):"
    )
    for label, runs in results.items():
        print(
            f"\n{label}: real-time factor {np.median([f for f, _ in runs]):.2f} "
            f"(runs: {', '.join(f'{f:.2f}' for f, _ in runs)})"
        )
        keys = sorted({k for _, b in runs for k in b})
        processes = list(dict.fromkeys(k.split("/")[0] for k in keys))
        print(f"  {'CPU us per step':<16}{'main':>8}{'zenoh':>8}{'other':>8}{'total':>8}")
        total = 0.0
        for process in processes:
            cells = [
                float(np.median([b.get(f"{process}/{g}", 0.0) for _, b in runs])) for g in ("main", "zenoh", "other")
            ]
            total += sum(cells)
            print(f"  {process:<16}" + "".join(f"{c:8.1f}" for c in cells) + f"{sum(cells):8.1f}")
        print(f"  {'all':<16}{'':>24}{total:8.1f}   (= {total / 1e3:.2f} CPU-ms per simulated ms)")


def load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


if __name__ == "__main__":
    main()
