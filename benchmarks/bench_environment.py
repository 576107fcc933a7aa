"""What each space-environment model costs, as a user runs it and per step in process.

    python benchmarks/bench_environment.py [--rounds 3] [--only processes|steps] [--quick]

Whole processes: ``python -m orchestrator.cli run CFG --set ...`` (unrecorded) for each model off
and on, the wall time and the CPU time of the process and every process it waited for (os.wait4),
the variants of a round alternating, the median over rounds. Orbit models on
configs/one_day_perturbed.yaml (``orbit.numerical``) from a point-mass baseline, 6 h of 60 s run
steps (2160 RK4 steps of 10 s); the dynamics' models on configs/detumble_magnetorquer.yaml
(``dynamics.dart``, one rigid body, WMM, magnetorquers, magnetometer, B-dot), 30 min of 500 ms
steps (3600 steps). ``--match TEXT`` keeps the variants whose label holds TEXT (e.g. ``dynamics``).
Each row is the config's own ``--set`` overrides: the same text a user types.

In process (``--only steps``): the same variants' step through components.testing.harness.Harness,
CPU time per step (the orbit's 60 s step: 6 RK4 steps; the dynamics' 500 ms step with an orbit's
inputs), the median of batches, the variants alternating. A benchmark, never run by the tests; it
prints the machine and its load before and after.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

ORBIT_CONFIG, ORBIT = "configs/one_day_perturbed.yaml", "components.orbit.parameters."
DYNAMICS_CONFIG, DYNAMICS = "configs/detumble_magnetorquer.yaml", "components.dynamics.parameters."
OFF = [
    f"{ORBIT}gravity={{degree: 0, order: 0}}",
    f"{ORBIT}third_bodies=[]",
    f"{ORBIT}drag=null",
    f"{ORBIT}atmosphere=null",
    f"{ORBIT}srp=null",
]
SRP = [f"{DYNAMICS}srp=true", f"{DYNAMICS}bodies.target.srp_area=4.0", f"{DYNAMICS}bodies.target.srp_cr=1.3"]
DRAG = [f"{DYNAMICS}drag=true", f"{DYNAMICS}bodies.target.drag_area=2.0"]
WEATHER = "{model: nrlmsise00, f107: 150, f107a: 150, ap: 15}"
# (label, config, --set overrides, the variant it is measured against)
VARIANTS = (
    ("orbit: point mass (baseline)", ORBIT_CONFIG, OFF, None),
    ("orbit: harmonics J2 (2 x 0)", ORBIT_CONFIG, OFF + [f"{ORBIT}gravity={{degree: 2, order: 0}}"], 0),
    ("orbit: harmonics 20 x 20", ORBIT_CONFIG, OFF + [f"{ORBIT}gravity={{degree: 20, order: 20}}"], 0),
    ("orbit: Sun and Moon (third bodies)", ORBIT_CONFIG, OFF + [f"{ORBIT}third_bodies=[sun, moon]"], 0),
    ("orbit: drag, exponential table", ORBIT_CONFIG, OFF + [f"{ORBIT}drag={{cd: 2.2, area: 10}}"], 0),
    (
        "orbit: drag, NRLMSISE-00",
        ORBIT_CONFIG,
        OFF + [f"{ORBIT}drag={{cd: 2.2, area: 10}}", f"{ORBIT}atmosphere={WEATHER}"],
        0,
    ),
    (
        "orbit: SRP, no shadow (eclipse none)",
        ORBIT_CONFIG,
        OFF + [f"{ORBIT}srp={{cr: 1.3, area: 30}}", f"{ORBIT}eclipse=none"],
        0,
    ),
    (
        "orbit: SRP, conical eclipse",
        ORBIT_CONFIG,
        OFF + [f"{ORBIT}srp={{cr: 1.3, area: 30}}", f"{ORBIT}eclipse=conical"],
        0,
    ),
    ("orbit: everything (the config as shipped)", ORBIT_CONFIG, [], 0),
    ("dynamics: WMM (the config as shipped)", DYNAMICS_CONFIG, [], None),
    ("dynamics: dipole instead of WMM", DYNAMICS_CONFIG, [f"{DYNAMICS}magnetic_field={{model: dipole}}"], 9),
    ("dynamics: SRP, no shadow (eclipse none)", DYNAMICS_CONFIG, SRP + [f"{DYNAMICS}eclipse=none"], 9),
    ("dynamics: SRP, conical eclipse", DYNAMICS_CONFIG, SRP + [f"{DYNAMICS}eclipse=conical"], 9),
    ("dynamics: drag, exponential table", DYNAMICS_CONFIG, DRAG, 9),
    ("dynamics: drag, NRLMSISE-00", DYNAMICS_CONFIG, DRAG + [f"{DYNAMICS}atmosphere={WEATHER}"], 9),
)
DURATION = {ORBIT_CONFIG: "6h", DYNAMICS_CONFIG: "30min"}


def machine() -> str:
    from bench_performance import machine as described

    return described()


def load() -> str:
    return "load average " + ", ".join(f"{x:.1f}" for x in os.getloadavg())


def whole_run(config: str, overrides: list[str], duration: str) -> tuple[float, float]:
    """(wall s, CPU s) of ``python -m orchestrator.cli run config --set ...``, every process it waited for."""
    args = [sys.executable, "-m", "orchestrator.cli", "run", config, "--set", f"run.duration={duration}"]
    for text in overrides:
        args += ["--set", text]
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    start = time.perf_counter()
    process = subprocess.Popen(args, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - start
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed: {process.stderr.read().decode()[-2000:]}")
    return wall, usage.ru_utime + usage.ru_stime


def chosen(match: str | None) -> list[int]:
    return [k for k, (label, *_) in enumerate(VARIANTS) if match is None or match in label]


def processes(rounds: int, quick: bool, match: str | None = None) -> None:
    durations = {ORBIT_CONFIG: "1h", DYNAMICS_CONFIG: "1min"} if quick else DURATION
    print(
        f"\nWhole runs (python -m orchestrator.cli run CFG --set ...), median of {rounds} alternating rounds; "
        f"{machine()}; {load()} before"
    )
    figures: dict[int, list[tuple[float, float]]] = {k: [] for k in chosen(match)}
    for _ in range(rounds):
        for k in figures:
            _, config, overrides, _ = VARIANTS[k]
            figures[k].append(whole_run(config, overrides, durations[config]))
    print(f"({load()} after)\n")
    print("| model (config, run.duration) | wall | CPU | CPU added |\n|---|---|---|---|")
    medians = {k: (statistics.median(w for w, _ in f), statistics.median(c for _, c in f)) for k, f in figures.items()}
    for k, (wall, cpu) in medians.items():
        label, config, _, base = VARIANTS[k]
        added = "" if base is None or base not in medians else f"{cpu - medians[base][1]:+.2f} s"
        print(f"| {label} ({Path(config).name}, {durations[config]}) | {wall:.1f} s | {cpu:.2f} s | {added} |")


def parameters(config: str, overrides: list[str], component: str) -> tuple[dict, str]:
    """The component's parameters after the overrides, and the run's epoch."""
    from orchestrator.config.yaml_file import apply_overrides

    raw = yaml.safe_load((ROOT / config).read_text())
    apply_overrides(raw, overrides)
    return raw["components"][component]["parameters"], str(raw["run"]["epoch"])


def harness(config: str, overrides: list[str]):
    from components.orbit.frames import lvlh_state
    from components.orbit.kepler import KeplerOrbit
    from components.testing.harness import Harness

    if config == ORBIT_CONFIG:
        params, epoch = parameters(config, overrides, "orbit")
        h = Harness("orbit.numerical", params, config_dir=ROOT / "configs", epoch=epoch)
        h.initialize()
        return h, 60 * 10**9, None
    params, epoch = parameters(config, overrides, "dynamics")
    h = Harness("dynamics.dart", params, config_dir=ROOT / "configs", epoch=epoch)
    orbit = KeplerOrbit(6878.137e3, 0.0, np.radians(87.0), np.radians(30.0), 0.0, 0.0)

    def feed(t_s):
        r, v, a = orbit.state_tuples(t_s)
        q, w = lvlh_state(r, v, a)
        h.inputs.update(r_eci=np.array(r), v_eci=np.array(v), q_eci_lvlh=q, w_lvlh=w)
        h.inputs["target.dipole"] = np.array([20.0, -30.0, 10.0])

    feed(0.0)
    h.initialize()
    return h, 500_000_000, feed


def steps(rounds: int, quick: bool) -> None:
    batches, size = (3, 10) if quick else (5, 40)
    print(
        f"\nIn process (Harness), CPU time per step, median of {batches} batches x {rounds} alternating rounds; "
        f"{machine()}; {load()} before"
    )
    made = [harness(config, overrides) for _, config, overrides, _ in VARIANTS]
    figures: list[list[float]] = [[] for _ in VARIANTS]
    for _ in range(rounds):
        for k, (h, h_ns, feed) in enumerate(made):
            for _ in range(batches):
                start = time.process_time()
                for _ in range(size):
                    if feed is not None:
                        feed(h.t_ns / 1e9)
                    h.step(h_ns)
                figures[k].append((time.process_time() - start) / size)
    print(f"({load()} after)\n")
    print("| model | per step | added |\n|---|---|---|")
    medians = [statistics.median(f) for f in figures]
    for (label, config, _, base), value in zip(VARIANTS, medians):
        step = "60 s step, 6 RK4 steps" if config == ORBIT_CONFIG else "500 ms step"
        added = "" if base is None else f"{(value - medians[base]) * 1e6:+.0f} us"
        print(f"| {label} ({step}) | {value * 1e6:.0f} us | {added} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--only", choices=("processes", "steps"), default=None)
    parser.add_argument("--match", default=None, help="only the variants whose label holds this text")
    parser.add_argument("--quick", action="store_true", help="short runs and few batches (a smoke test of the script)")
    args = parser.parse_args()
    if args.only in (None, "steps"):
        steps(args.rounds, args.quick)
    if args.only in (None, "processes"):
        processes(args.rounds, args.quick, args.match)


if __name__ == "__main__":
    main()
