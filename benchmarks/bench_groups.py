"""Process groups against one process per component, as a user runs them (issue 36).

    python benchmarks/bench_groups.py [--rounds 3] [--seconds 5] [--only demo,capture,rigid,loop,campaign]
                                      [--cases 4] [--basilisk-us 10.7]

Each scenario runs as ``orchestrator run`` (a process of its own, on this tree) once separate (the
shipped config) and once grouped (``components.<name>.process``), the two alternating ``--rounds``
times; each figure is the median over the rounds, with every run's figure printed:

- ``demo``: the paper's demo (configs/humanoid_tracking.yaml, ``--seconds`` simulated) with
  ``dynamics.dart`` and with ``dynamics.pinocchio``, grouped: the dynamics and the controller in
  one process (the config's commented ``process: loop`` lines); real-time factor of the stepping
  loop (the summary line's), and the same components stepped one after another in one process
  (orchestrator/run/inprocess.py), for the bus against one process;
- ``capture``: the capture scenario (configs/capture_tumbling_target.yaml), grouped the same way;
- ``rigid``: a rigid spacecraft, configs/gravity_gradient_libration.yaml at 1 s steps for two
  orbits with ``dynamics.pinocchio`` (rk4, gravity gradient), grouped: the orbit and the dynamics;
  per step: the stepping loop's wall time over the steps (the summary line's real-time factor,
  start-up excluded), unrecorded and recorded (``--record``), against Basilisk's per step
  (``--basilisk-us``, as ``benchmarks/bench_basilisk.py`` measures it; with its environment in
  place, Basilisk is run in every round instead);
- ``loop``: 3 no-op components in a loop, per step, against a Zenoh round trip between two
  processes (benchmarks/bench_lockstep.py), grouped: all three in one process;
- ``campaign``: ``orchestrator sweep`` of ``--cases`` short cases of the capture scenario
  (``dynamics.pinocchio``, 5 s each, the tumble dispersed), cases per minute of wall time.

A benchmark, never run by the tests: it names the machine and its load average.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_performance import machine, noop_loop, run_config  # noqa: E402

from tests.basilisk.__main__ import basilisk_venv  # noqa: E402

CONFIGS = ROOT / "configs"
DEMO = CONFIGS / "humanoid_tracking.yaml"
CAPTURE = CONFIGS / "capture_tumbling_target.yaml"
RIGID = CONFIGS / "gravity_gradient_libration.yaml"
LOOP = ["dynamics", "controller"]  # the members of the demo's and capture's commented group
PINOCCHIO = ["components.dynamics.type=dynamics.pinocchio"]
RIGID_STEPS = 11106  # two orbits of 6778 km at 1 s
BASILISK_VENV = basilisk_venv()  # bench_basilisk.py's, the fixtures'
SUMMARY = re.compile(
    r"(\d+) steps? of (\d+), ([\d.e+]+) s simulated; ([\d.]+) s wall "
    r"\(([\d.]+) s stepping, real-time factor ([\d.]+)\)"
)


def grouped(names: list[str], group: str = "loop") -> list[str]:
    return [f"components.{name}.process={group}" for name in names]


def orchestrator_run(config: Path, overrides: list[str], record: bool = False) -> dict:
    """One ``orchestrator run`` on this tree: its summary line's figures."""
    command = [sys.executable, "-m", "orchestrator.cli", "run", str(config)]
    for override in overrides:
        command += ["--set", override]
    with tempfile.TemporaryDirectory() as folder:
        if record:
            command += ["--record", str(Path(folder) / "rec")]
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        result = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=1800)
    match = SUMMARY.search(result.stderr + result.stdout)
    if result.returncode != 0 or match is None:
        raise SystemExit(f"the run failed ({config.name} {' '.join(overrides)}):\n{result.stderr[-3000:]}")
    rows, _, sim_s, wall_s, _, factor = match.groups()
    return {"steps": int(rows), "sim_s": float(sim_s), "wall_s": float(wall_s), "factor": float(factor)}


def in_process_factor(config: Path, overrides: list[str]) -> float:
    """Real-time factor of the config's components stepped one after another in this process."""
    from orchestrator.config.load import load
    from orchestrator.run.inprocess import run_in_process

    loaded = load(config, overrides)
    timing: dict = {}
    run_in_process(loaded, timing=timing)
    return loaded.steps * loaded.step_ns * 1e-9 / timing["loop_s"]


def rigid_overrides() -> list[str]:
    return ["run.step=1 s", f"run.duration={RIGID_STEPS} s", *PINOCCHIO]


def campaign_file(folder: Path, cases: int, group: bool) -> Path:
    grid = {"run.duration": ["5 s"], "components.dynamics.type": ["dynamics.pinocchio"]}
    if group:
        grid.update({f"components.{name}.process": ["loop"] for name in LOOP})
    campaign = {
        "config": str(CAPTURE),
        "samples": cases,
        "seed": 36,
        "grid": grid,
        "disperse": {"components.dynamics.parameters.bodies.target.twist.rate": {"uniform": ["0.5 deg/s", "4 deg/s"]}},
        "outcomes": {"captured": "capture", "aborted": "capture_aborted"},
    }
    path = folder / ("grouped.yaml" if group else "separate.yaml")
    path.write_text(yaml.safe_dump(campaign))
    return path


def sweep_rate(cases: int, group: bool) -> float:
    """Cases per minute of an ``orchestrator sweep`` (wall time of the whole command)."""
    with tempfile.TemporaryDirectory() as folder:
        path = campaign_file(Path(folder), cases, group)
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        started = time.perf_counter()
        result = subprocess.run(
            [sys.executable, "-m", "orchestrator.cli", "sweep", str(path), "--out", str(Path(folder) / "out")],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=3600,
        )
        wall = time.perf_counter() - started
    if result.returncode != 0:
        raise SystemExit(f"the sweep failed:\n{result.stderr[-3000:]}")
    return cases / wall * 60


def basilisk_step_us() -> float | None:
    """Basilisk's CPU per step of the same rigid body (bench_basilisk.py), if its environment exists."""
    python = BASILISK_VENV / "bin" / "python"
    if not python.exists():
        return None
    from bench_basilisk import Scenario

    scenario = Scenario("dynamics.pinocchio", 10**9, 2.0)
    if not hasattr(basilisk_step_us, "start"):
        basilisk_step_us.start = scenario.zenorbit()[0]
    return float(np.median(scenario.basilisk(python, basilisk_step_us.start)["cpu_ns"])) * 1e-3


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds (3)")
    parser.add_argument("--seconds", type=float, default=5.0, help="simulated seconds of the demo and capture (5)")
    parser.add_argument("--only", default="demo,capture,rigid,loop,campaign", help="scenarios, comma-separated")
    parser.add_argument("--cases", type=int, default=4, help="cases of the campaign (4)")
    parser.add_argument("--loop-steps", type=int, default=5000, help="steps of the no-op loop (5000)")
    parser.add_argument(
        "--basilisk-us", type=float, default=10.7, help="Basilisk's per step, us, when its environment is absent (10.7)"
    )
    args = parser.parse_args()
    only = set(args.only.split(","))
    short = [f"run.duration={args.seconds} s"]
    # (label, a function of no argument giving the figure), separate and grouped alternate within a round
    variants: list[tuple[str, object]] = []
    if "demo" in only:
        for engine, extra in (("dart", []), ("pinocchio", PINOCCHIO)):
            variants += [
                (f"demo {engine}, separate", lambda e=extra: orchestrator_run(DEMO, short + e)["factor"]),
                (
                    f"demo {engine}, grouped",
                    lambda e=extra: orchestrator_run(DEMO, short + e + grouped(LOOP))["factor"],
                ),
            ]
        variants.append(("demo dart, one process", lambda: in_process_factor(DEMO, short)))
    if "capture" in only:
        variants += [
            ("capture, separate", lambda: orchestrator_run(CAPTURE, short)["factor"]),
            ("capture, grouped", lambda: orchestrator_run(CAPTURE, short + grouped(LOOP))["factor"]),
        ]
    if "rigid" in only:
        rigid = rigid_overrides()
        both = grouped(["orbit", "dynamics"], "rigid")
        variants += [
            ("rigid us/step, separate", lambda: 1e6 / orchestrator_run(RIGID, rigid)["factor"]),
            ("rigid us/step, separate, recorded", lambda: 1e6 / orchestrator_run(RIGID, rigid, record=True)["factor"]),
            ("rigid us/step, grouped", lambda: 1e6 / orchestrator_run(RIGID, rigid + both)["factor"]),
            (
                "rigid us/step, grouped, recorded",
                lambda: 1e6 / orchestrator_run(RIGID, rigid + both, record=True)["factor"],
            ),
        ]
        if not (BASILISK_VENV / "bin" / "python").exists():
            print(
                f"(no Basilisk environment: its per step is --basilisk-us, {args.basilisk_us} us; "
                f"python benchmarks/bench_basilisk.py makes it)"
            )
        variants.append(("Basilisk us/step", lambda: basilisk_step_us() or args.basilisk_us))
    if "loop" in only:
        from bench_lockstep import round_trip

        text = noop_loop(3, args.loop_steps)
        group = "".join(f"  n{i}: {{type: test.noop, parameters: {{size: 1}}, process: ring}}\n" for i in range(3))
        grouped_text = re.sub(r"(?m)^  n\d: .*\n", "", text).replace("components:\n", "components:\n" + group)
        variants += [
            ("loop us/step, separate", lambda: 1e6 / run_config(text)),
            ("loop us/step, grouped", lambda: 1e6 / run_config(grouped_text)),
            ("zenoh round trip us", lambda: float(np.median(round_trip(args.loop_steps))) * 1e6),
        ]
    if "campaign" in only:
        variants += [
            ("campaign cases/min, separate", lambda: sweep_rate(args.cases, False)),
            ("campaign cases/min, grouped", lambda: sweep_rate(args.cases, True)),
        ]

    print(f"machine: {machine()}; load average {load()}")
    figures: dict[str, list[float]] = {label: [] for label, _ in variants}
    for r in range(args.rounds):
        for label, figure in variants:
            figures[label].append(figure())
            print(f"  round {r + 1}: {label:<36} {figures[label][-1]:10.2f}   (load {load()})", flush=True)
    median = {label: float(np.median(values)) for label, values in figures.items()}
    print(f"\nmedians of {args.rounds} alternating rounds; load average {load()}")
    for label, value in median.items():
        print(f"  {label:<36} {value:10.2f}   ({', '.join(f'{v:.2f}' for v in figures[label])})")
    print("\n| ratio | separate | grouped |\n|---|---|---|")
    m = median.get
    if "rigid us/step, separate" in median:
        base = m("Basilisk us/step")
        print(
            f"| rigid body per step / Basilisk's ({base:.1f} us) | {m('rigid us/step, separate') / base:.1f}x "
            f"({m('rigid us/step, separate, recorded') / base:.1f}x recorded) | "
            f"{m('rigid us/step, grouped') / base:.1f}x ({m('rigid us/step, grouped, recorded') / base:.1f}x recorded) |"
        )
    if "demo dart, separate" in median:
        print(
            f"| demo, pinocchio / dart (real-time factor) | {m('demo pinocchio, separate') / m('demo dart, separate'):.2f}x | "
            f"{m('demo pinocchio, grouped') / m('demo dart, grouped'):.2f}x |"
        )
    if "loop us/step, separate" in median:
        rtt = m("zenoh round trip us")
        print(
            f"| 3 no-op in a loop per step / Zenoh round trip ({rtt:.0f} us) | {m('loop us/step, separate') / rtt:.2f}x | "
            f"{m('loop us/step, grouped') / rtt:.2f}x |"
        )
    if "demo dart, separate" in median:
        one = m("demo dart, one process")
        print(
            f"| demo (dart) over the bus / one process (real-time factor {one:.2f}) | "
            f"{m('demo dart, separate') / one:.2f}x | {m('demo dart, grouped') / one:.2f}x |"
        )
    if "demo pinocchio, grouped" in median:
        print(f"demo, dynamics.pinocchio, controller grouped: real-time factor {m('demo pinocchio, grouped'):.2f}")
    if "campaign cases/min, separate" in median:
        print(
            f"campaign ({args.cases} cases of {CAPTURE.name}, 5 s): {m('campaign cases/min, separate'):.1f} cases/min "
            f"separate, {m('campaign cases/min, grouped'):.1f} grouped "
            f"({m('campaign cases/min, grouped') / m('campaign cases/min, separate'):.2f}x)"
        )


if __name__ == "__main__":
    main()
