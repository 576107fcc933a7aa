"""Cost of the Rerun view on run time: the same 1 kHz run with and without ``--view save:FILE.rrd``.

    python benchmarks/bench_viewer.py [--config configs/free_floating_humanoid.yaml] [--duration 5s]
                                      [--rate 30] [--repeats 3]

Runs ``orchestrator run CONFIG --set run.step=1ms --profile`` alternately without and with the view
(``--view save:...``, decimated by the orchestrator to ``--rate`` Hz of sim time) and compares the
lockstep loop time that ``--profile`` prints (start-up excluded), the whole process wall time, and
the CPU time of the whole process tree (orchestrator, components, observer: ``getrusage`` of the
reaped children), which does not depend on what else the machine is doing. Medians over
``--repeats`` pairs, run alternately.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PROFILE = re.compile(r"profile: (\d+) steps in ([0-9.]+) s wall")


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_once(config: Path, duration: str, view: str | None, workdir: Path, extra: list[str]):
    """(loop seconds from --profile, process wall seconds, steps, CPU seconds of the process tree) of one run."""
    args = [
        sys.executable,
        "-m",
        "orchestrator.cli",
        "run",
        str(config),
        "--profile",
        "--set",
        "run.step=1ms",
        "--set",
        f"run.duration={duration}",
        *extra,
    ]
    if view:
        args += ["--view", view]
    env = {**os.environ, "ZENORBIT_RUNTIME_DIR": str(workdir / "runtime")}
    started, cpu = time.perf_counter(), children_cpu()
    result = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, env=env, timeout=1800)
    wall, cpu = time.perf_counter() - started, children_cpu() - cpu
    if result.returncode != 0:
        sys.exit(f"run failed ({result.returncode}):\n{result.stderr[-2000:]}")
    match = PROFILE.search(result.stderr)
    if not match:
        sys.exit(f"no profile line in the output:\n{result.stderr[-2000:]}")
    return float(match[2]), wall, int(match[1]), cpu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default=str(ROOT / "configs" / "free_floating_humanoid.yaml"))
    parser.add_argument("--duration", default="5s", help="sim time per run (default 5s = 5000 steps)")
    parser.add_argument("--rate", default="30", help="viewer rate, Hz of sim time (default 30)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="extra overrides, e.g. components.dynamics.parameters.substeps=1",
    )
    args = parser.parse_args()
    extra = [a for kv in args.set for a in ("--set", kv)]
    with tempfile.TemporaryDirectory(prefix="zenorbit-bench-viewer-") as tmp:
        workdir = Path(tmp)
        config = Path(args.config).resolve()
        if args.rate != "30":  # the --view value has no rate: write a viewer section into a copy of the config
            import yaml

            raw = yaml.safe_load(config.read_text())
            raw["viewer"] = {"mode": "save", "file": str(workdir / "bench.rrd"), "rate": float(args.rate)}
            copy = config.parent / f".bench_viewer_{os.getpid()}.yaml"
            copy.write_text(yaml.safe_dump(raw))
        plain, viewed = [], []
        run_once(config, "0.5s", None, workdir, extra)  # warm-up (imports, caches)
        try:
            for i in range(args.repeats):
                plain.append(run_once(config, args.duration, None, workdir, extra))
                if args.rate != "30":
                    viewed.append(run_once(copy, args.duration, None, workdir, extra))
                else:
                    viewed.append(run_once(config, args.duration, f"save:{workdir / 'bench.rrd'}", workdir, extra))
                print(
                    f"  pair {i + 1}: loop {plain[-1][0]:.3f} s -> {viewed[-1][0]:.3f} s with the view; "
                    f"process {plain[-1][1]:.2f} s -> {viewed[-1][1]:.2f} s; "
                    f"CPU {plain[-1][3]:.2f} s -> {viewed[-1][3]:.2f} s",
                    flush=True,
                )
        finally:
            if args.rate != "30":
                copy.unlink(missing_ok=True)
        size = (workdir / "bench.rrd").stat().st_size if (workdir / "bench.rrd").exists() else 0
    loop_plain, loop_view = np.median([p[0] for p in plain]), np.median([v[0] for v in viewed])
    wall_plain, wall_view = np.median([p[1] for p in plain]), np.median([v[1] for v in viewed])
    cpu_plain, cpu_view = np.median([p[3] for p in plain]), np.median([v[3] for v in viewed])
    steps = plain[0][2]
    print(
        f"{Path(args.config).name}, {steps} steps at 1 kHz, view at {args.rate} Hz of sim time "
        f"({platform.processor() or platform.machine()}, {os.cpu_count()} CPUs), medians of {args.repeats}:"
    )
    print(
        f"  lockstep loop  {loop_plain:8.3f} s -> {loop_view:8.3f} s   cost {100 * (loop_view / loop_plain - 1):+6.1f} %"
        f"   ({steps / loop_plain:.0f} -> {steps / loop_view:.0f} steps/s)"
    )
    print(
        f"  whole process  {wall_plain:8.3f} s -> {wall_view:8.3f} s   cost {100 * (wall_view / wall_plain - 1):+6.1f} %"
    )
    print(f"  CPU, all procs {cpu_plain:8.3f} s -> {cpu_view:8.3f} s   cost {100 * (cpu_view / cpu_plain - 1):+6.1f} %")
    print(f"  .rrd written   {size / 1e6:.1f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
