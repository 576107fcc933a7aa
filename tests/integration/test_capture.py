"""The capture scenario (configs/capture_tumbling_target.yaml) end to end: the real `orchestrator
run --record` (orbit, dynamics with the grasp weld, three sensors, controller.capture), against
closed forms and conservation laws. The reference run, the swap and the restart run the config's
six component processes over Zenoh on loopback; the others, as a campaign's cases would, run the
six in one process: the same numbers bit for bit (the determinism test checks it), on half the
CPU.

- Capture from three tumbles and offsets nothing was tuned on (not the shipped one, not the unit
  tests' scenes), each with sensor seeds of its own: the grasp closes within the dynamics' declared
  tolerance, the weld then holds (relative twist ~0, relative pose frozen).
- Momentum, environment off: total linear and angular momentum of the two bodies through approach,
  impact and detumbling; the target's momentum ends in the wheels.
- Detumble, environment on (the shipped scenario, 18 s): the assembly's inertial rate ends below
  0.1 deg/s.
- Determinism (bit-identical part files, the second run with every component in one process;
  another sensor seed changes the measurements and nothing the controller has not yet used), a
  same-type swap of the dynamics after the capture and a restart from a checkpoint after the
  capture (both bit for bit).
- Not captured is an outcome (issue 33): a target beyond the arm, a tumble too fast for the
  joints, sensor noise the estimator cannot beat: each run completes with a capture_aborted event
  whose reason carries the figures.
- The envelope: 12 tumble axes drawn uniformly over the sphere (a fixed seed nobody tuned on), each
  at 2.5 and 4 deg/s: every one captured, momentum conserved to 1e-9, wrist loads within the
  fixture's limits.

Every run the selected tests of this module need is started by one module fixture, at most
``PARALLEL`` at a time, longest first; each test waits for the runs it reads. On an idle 2-core
machine the module's 37 runs take about 2 min four at a time (260 CPU-s). Every run's processes
are checked gone when it ends. Nothing here is compared with numbers the code produced before:
the references are the URDFs, the configs and the physics.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
import re
import subprocess
import sys
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas
import pytest
import yaml
from scipy.spatial.transform import Rotation

from tests.conftest import ROOT

pytestmark = pytest.mark.integration

CONFIG = ROOT / "configs" / "capture_tumbling_target.yaml"
SERVICER_URDF = ROOT / "models" / "capture" / "servicer.urdf"
TARGET_URDF = ROOT / "models" / "capture" / "target.urdf"
ARM = [f"arm_{i}_joint" for i in range(1, 7)]
WHEELS = ["wheel_x_joint", "wheel_y_joint", "wheel_z_joint"]
H = 0.01  # run.step of the config (s)
PARALLEL = 4  # runs at a time (see the module's doc)
RUN_TIMEOUT = 600.0  # s of wall time: only there to end a run that would hang

DYNAMICS = "components.dynamics.parameters."
TARGET = DYNAMICS + "bodies.target."
ENVIRONMENT_OFF = (f"{DYNAMICS}tidal_force=false", f"{DYNAMICS}gravity_gradient=false")
# Every component in one process (`process:`), for every run but OWN_PROCESSES (see the module's doc)
ONE_PROCESS = tuple(f"components.{name}.process=capture" for name in yaml.safe_load(CONFIG.read_text())["components"])
OWN_PROCESSES = ("shipped", "swap", "restart")
SEEDS = (
    "components.pose_sensor.parameters.seed",
    "components.imu.parameters.seed",
    "components.wrist_ft.parameters.seed",
)

# The capture timeline of the config, the earliest the grasp can close: the estimator needs 12
# measurements of the 20 Hz pose sensor (the last taken at 0.55 s, published 100 ms later, seen
# by the controller at its step of 0.7 s, when it first plans), the quickest joint move lasts 1 s,
# the close along the grapple's axis 1 s (closing_time), the estimated errors must stay within
# tolerance for 0.5 s; `close` reaches the dynamics one step later and the grasp closes at the end
# of that step.
EARLIEST_CAPTURE = 0.7 + 1.0 + 1.0 + 0.5 + 2 * H
LATEST_CAPTURE = 9.5  # the tests' own deadline

WELD_TWIST = 1e-8  # m/s, rad/s: the weld's relative twist after the impact
WELD_DRIFT = 1e-9  # m, rad: drift of the welded relative pose


# --------------------------------------------------------------------------- the URDFs


def _floats(text: str | None, default: str) -> np.ndarray:
    return np.array([float(x) for x in (text or default).split()])


class Urdf:
    """What the tests take from a URDF file, read with xml.etree (not the project's reader)."""

    def __init__(self, path: Path):
        self.root = ET.parse(path).getroot()
        self.links = {link.get("name"): link for link in self.root.findall("link")}
        self.joints = {joint.get("name"): joint for joint in self.root.findall("joint")}

    def mass(self) -> float:
        return sum(
            float(link.find("inertial/mass").get("value"))
            for link in self.links.values()
            if link.find("inertial") is not None
        )

    def origin(self, joint: str) -> tuple[np.ndarray, np.ndarray]:
        o = self.joints[joint].find("origin")
        return _floats(o.get("xyz") if o is not None else None, "0 0 0"), _floats(
            o.get("rpy") if o is not None else None, "0 0 0"
        )

    def axis(self, joint: str) -> np.ndarray:
        a = self.joints[joint].find("axis")
        return _floats(a.get("xyz") if a is not None else None, "1 0 0")

    def inertia(self, link: str) -> np.ndarray:
        """The link's inertia matrix about its CoM (inertial frame axes)."""
        i = self.links[link].find("inertial/inertia")
        return np.array(
            [
                [float(i.get("ixx")), float(i.get("ixy")), float(i.get("ixz"))],
                [float(i.get("ixy")), float(i.get("iyy")), float(i.get("iyz"))],
                [float(i.get("ixz")), float(i.get("iyz")), float(i.get("izz"))],
            ]
        )

    def spin_inertia(self, joint: str) -> float:
        """The child link's moment of inertia about the joint axis (the joint's frame is the link's:
        its inertial origin has no rotation in these URDFs)."""
        a = self.axis(joint)
        return float(a @ self.inertia(self.joints[joint].find("child").get("link")) @ a / (a @ a))

    def largest_moment_bound(self, base_from_com: float) -> float:
        """An upper bound of the body's largest principal moment of inertia about its CoM, in any
        joint configuration: the sum over the links of each one's own largest moment plus its mass
        times the square of the farthest its CoM can be from the body's CoM (the base origin's
        distance from the CoM, the joint offsets from the base down to the link, its inertial
        offset). lambda_max is subadditive, and a mass m at distance r adds m r^2 at most."""
        total = 0.0
        for name, link in self.links.items():
            inertial = link.find("inertial")
            if inertial is None:
                continue
            origin = inertial.find("origin")
            offset = np.linalg.norm(_floats(origin.get("xyz") if origin is not None else None, "0 0 0"))
            farthest = base_from_com + offset + sum(np.linalg.norm(self.origin(j)[0]) for j in self.chain(name))
            mass = float(inertial.find("mass").get("value"))
            total += np.linalg.eigvalsh(self.inertia(name)).max() + mass * farthest**2
        return float(total)

    def chain(self, link: str) -> list[str]:
        """Joints from the root down to ``link``."""
        by_child = {j.find("child").get("link"): name for name, j in self.joints.items()}
        names = []
        while link in by_child:
            names.append(by_child[link])
            link = self.joints[by_child[link]].find("parent").get("link")
        return names[::-1]


SERVICER, TARGET_MODEL = Urdf(SERVICER_URDF), Urdf(TARGET_URDF)


def shoulder_and_reach() -> tuple[np.ndarray, float]:
    """arm_1_joint's position in the bus frame, and the stretched arm's length from there to the
    end effector: the sum of the joint offsets beyond arm_1_joint."""
    chain = SERVICER.chain("ee")
    first = chain.index("arm_1_joint")
    reach = sum(float(np.linalg.norm(SERVICER.origin(j)[0])) for j in chain[first + 1 :])
    return SERVICER.origin("arm_1_joint")[0], reach


# --------------------------------------------------------------------------- cases


def vector(x) -> str:
    """A YAML list for --set."""
    return "[" + ", ".join(repr(float(v)) for v in x) + "]"


@dataclasses.dataclass(frozen=True)
class Case:
    """A target whose grapple frame starts where the end effector is at arm configuration
    ``q_grasp`` (the servicer at the LVLH origin, LVLH-aligned), tumbling at ``rate`` deg/s about
    ``axis`` (target axes), its CoM at rest in LVLH; sensor seeds of its own."""

    q_grasp: tuple
    axis: tuple
    rate: float
    seed: int

    def target(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The target's base (its CoM) position, q_LVLH_target and angular velocity relative to
        LVLH (LVLH axes), from DART's kinematics of the servicer at ``q_grasp``."""
        from components.dynamics.world import BodySpec, OrbitalWorld

        probe = OrbitalWorld([BodySpec("servicer", SERVICER_URDF, q=dict(zip(ARM, self.q_grasp)))])
        probe.reset_bodies()
        T = probe.bodies["servicer"].skel.getBodyNode("ee").getTransform().matrix()
        xyz, rpy = TARGET_MODEL.origin("grapple_joint")
        R_t_g = Rotation.from_euler("xyz", rpy).as_matrix()  # grapple frame in the target's
        R_g = T[:3, :3]
        R_t = R_g @ R_t_g.T
        p_t = T[:3, 3] - R_t @ xyz
        axis = np.asarray(self.axis, dtype=float)
        w = R_t @ axis / np.linalg.norm(axis) * math.radians(self.rate)
        return p_t, Rotation.from_matrix(R_t).as_quat(), w

    def overrides(self) -> list[str]:
        p, q, w = self.target()
        return [
            f"{TARGET}position={vector(p)}",
            f"{TARGET}orientation={vector(q)}",
            f"{TARGET}twist={vector([0.0, 0.0, 0.0, *w])}",
            *(f"{key}={self.seed + i}" for i, key in enumerate(SEEDS)),
        ]


# The servicer starts in the shipped configuration (q = -0.9, 0.2, 1.6, -0.3, 1.2, 0.3); the
# grapple starts 1.1-1.3 m from the shoulder, 0.4-1.2 m and 28-100 deg from the end effector.
# Tried and dropped: the last arm pose below with the tumble axis (1, -0.4, 0.3) at 3.5 deg/s
# carries the grapple out towards a stretched elbow (1.37 m from the shoulder by 11 s); with the
# shipped sensor seeds the grasp has not closed when arm_3_joint needs its 2.5 rad/s limit for
# longer than limit_window at 10.26 s, and the controller stops the run saying so (with seeds
# 301-303 it closes at 8.62 s, before the elbow straightens: a marginal case).
CASES = {
    "near-z-1.5deg": Case((-0.5, 0.7, 1.0, -0.3, 1.0, -0.4), (0.2, -0.3, 1.0), 1.5, 101),
    "skew-2deg": Case((-0.2, 0.9, 0.8, 0.2, 0.7, 0.1), (-0.5, 1.0, 0.8), 2.0, 201),
    "near-x-3.5deg": Case((0.4, 0.3, 1.6, -0.8, 1.4, 0.7), (-1.0, 0.4, -0.3), 3.5, 301),
}

SWAP_AT, CRASH_AT, CHECKPOINT_EVERY = 10.0, 11.0, 2.0
FAST_RATE_DEG = 60.0  # the grapple 0.65 m from the CoM: 0.68 m/s
NOISY = ("2 cm", "2 deg")  # 100 times the shipped pose sensor's noise
NOISE_X5 = {
    "pose_sensor": (("position_noise", "1 mm"), ("angle_noise", "0.1 deg")),  # 5 times the shipped
    "imu": (("rate_noise", "0.005 deg/s"), ("accel_noise", "5e-5")),
    "wrist_ft": (("force_noise", "0.25 N"), ("torque_noise", "0.05 N*m")),
}
# A target 4 m out along LVLH x, turned so that its grapple faces the servicer (target z along -x).
BEYOND = {"position": [4.0, 0.0, 1.2], "orientation": Rotation.from_euler("y", -90, degrees=True).as_quat()}


def _runs() -> dict[str, dict]:
    """Every run: its --set overrides, its duration (s) and the exit code it must end with."""
    shipped = {"duration": 18.0, "sets": [], "exit": 0}
    runs = {
        "shipped": shipped,
        "shipped-again": shipped,
        "environment-off": {"duration": 20.0, "sets": list(ENVIRONMENT_OFF), "exit": 0},
        "swap": {"duration": 18.0, "sets": [f"events=[{{at: {SWAP_AT:g} s, swap: dynamics}}]"], "exit": 0},
        "restart": {
            "duration": 18.0,
            "exit": 0,
            "sets": [
                "components.dynamics.on_failure=restart",
                f"run.checkpoint_every={CHECKPOINT_EVERY:g} s",
                f"faults=[{{at: {CRASH_AT:g} s, component: dynamics, kind: crash}}]",
            ],
        },
        "other-seed": {"duration": 0.6, "sets": [f"{key}={77 + i}" for i, key in enumerate(SEEDS)], "exit": 0},
        "beyond": {
            "duration": 4.0,
            "exit": 0,
            "sets": [
                f"{TARGET}position={vector(BEYOND['position'])}",
                f"{TARGET}orientation={vector(BEYOND['orientation'])}",
                f"{TARGET}twist=[0, 0, 0, 0, 0, 0]",
            ],
        },
    }
    for name, case in CASES.items():
        runs[f"case:{name}"] = {"duration": 10.0, "sets": case, "exit": 0}
    # a tumble no arm joint can follow; sensor noise the estimator cannot beat (one approach)
    runs["too-fast"] = {
        "duration": 2.0,
        "exit": 0,
        "sets": [f"{TARGET}twist={{rate: {FAST_RATE_DEG:g} deg/s, axis: [1, 0, 0], axes: body}}"],
    }
    runs["noise-x5"] = {
        "duration": 7.0,
        "exit": 0,
        "sets": [f"components.pose_sensor.parameters.{key}={value}" for key, value in NOISE_X5["pose_sensor"]]
        + [f"components.imu.parameters.{key}={value}" for key, value in NOISE_X5["imu"]]
        + [f"components.wrist_ft.parameters.{key}={value}" for key, value in NOISE_X5["wrist_ft"]],
    }
    runs["noisy"] = {
        "duration": 14.0,
        "exit": 0,
        "sets": [
            f"components.pose_sensor.parameters.position_noise={NOISY[0]}",
            f"components.pose_sensor.parameters.angle_noise={NOISY[1]}",
            "components.controller.parameters.attempts=1",
        ],
    }
    return runs


RUNS = _runs()


def uses(*names):
    """The runs a test reads ("{case}": its ``case`` parameter's)."""

    def mark(function):
        function.capture_runs = names
        return function

    return mark


# --------------------------------------------------------------------------- running


def leftovers(run_id: str) -> list[str]:
    out = subprocess.run(["ps", "-ww", "-eo", "pid=,args="], capture_output=True, text=True).stdout
    return [line for line in out.splitlines() if "components.runner" in line and run_id in line]


@dataclasses.dataclass
class Run:
    name: str
    record: Path
    returncode: int
    stderr: str
    wall: float

    @property
    def events(self) -> list[dict]:
        return [json.loads(line) for line in (self.record / "events.jsonl").read_text().splitlines()]

    def of(self, kind: str) -> list[dict]:
        return [e for e in self.events if e["event"] == kind]

    @functools.cached_property
    def signals(self) -> pandas.DataFrame:
        return pandas.read_parquet(self.record / "signals.parquet")

    def vector(self, name: str, n: int) -> np.ndarray:
        return self.signals[[f"{name}[{i}]" for i in range(n)]].to_numpy(copy=True)

    def parts(self) -> dict[str, bytes]:
        return {
            p.name: p.read_bytes()
            for p in sorted((self.record / "signals.parquet").glob("*.parquet"))
            if not p.name.startswith(".")
        }

    @property
    def config(self) -> dict:
        return yaml.safe_load((self.record / "config.yaml").read_text())


class Runs:
    """Starts the runs the module's selected tests need, ``PARALLEL`` at a time, longest first, in
    a thread; ``runs(name)`` waits for one and returns it, checked: its exit code, and none of its
    processes left."""

    def __init__(self, base: Path, names: list[str]):
        self.base = base
        self.env = {**os.environ, "ZENORBIT_RUNTIME_DIR": str(base / "runtime")}
        self.queue = sorted(names, key=lambda n: -RUNS[n]["duration"])
        self.commands = {name: self._command(name) for name in names}  # DART places the cases' targets
        self.done = {name: threading.Event() for name in names}
        self.results: dict[str, Run | BaseException] = {}
        self.procs: dict[str, subprocess.Popen] = {}
        self.stopping = False
        self.stderr_done: dict[str, str] = {}
        self.thread = threading.Thread(target=self._work, daemon=True)
        self.thread.start()

    def _command(self, name: str) -> list[str]:
        spec = RUNS[name]
        sets = spec["sets"].overrides() if isinstance(spec["sets"], Case) else spec["sets"]
        if name not in OWN_PROCESSES:
            sets = [*sets, *ONE_PROCESS]
        args = [
            "run",
            str(CONFIG),
            "--record",
            str(self.base / name.replace(":", "-")),
            "--set",
            f"run.duration={spec['duration']:g} s",
        ]
        for s in sets:
            args += ["--set", s]
        return [sys.executable, "-m", "orchestrator.cli", *args]

    def _work(self) -> None:
        try:
            self._schedule()
        except BaseException as e:
            for name, done in self.done.items():
                if not done.is_set():
                    self.results[name] = AssertionError(f"the runs' scheduler failed: {e!r}")
                    done.set()

    def _schedule(self) -> None:
        running: dict[str, tuple[subprocess.Popen, float]] = {}
        queue = list(self.queue)
        while (queue or running) and not self.stopping:
            while queue and len(running) < PARALLEL:
                name = queue.pop(0)
                try:
                    proc = subprocess.Popen(
                        self.commands[name],
                        cwd=ROOT,
                        env=self.env,
                        stdout=subprocess.DEVNULL,
                        stderr=subprocess.PIPE,
                        text=True,
                    )
                except BaseException as e:
                    self.results[name] = e
                    self.done[name].set()
                    continue
                self.procs[name] = proc
                running[name] = (proc, time.monotonic())
                threading.Thread(target=self._drain, args=(name, proc), daemon=True).start()
            for name, (proc, started) in list(running.items()):
                if proc.poll() is None and time.monotonic() - started > RUN_TIMEOUT:
                    proc.terminate()
                if proc.poll() is not None and name in self.stderr_done:
                    del running[name]
                    self._finish(name, proc, time.monotonic() - started)
            time.sleep(0.05)

    def _drain(self, name: str, proc: subprocess.Popen) -> None:
        text = proc.stderr.read()
        proc.wait()
        self.stderr_done[name] = text

    def _finish(self, name: str, proc: subprocess.Popen, wall: float) -> None:
        record = self.base / name.replace(":", "-")
        run = Run(name, record, proc.returncode, self.stderr_done[name], wall)
        try:
            start = run.events[0]
            assert start["event"] == "start", start
            left = leftovers(start["run_id"])
            assert not left, f"{name}: processes left behind: {left}"
            self.results[name] = run
        except BaseException as e:
            self.results[name] = AssertionError(f"{name} (exit {proc.returncode}): {e}\n{run.stderr}")
        self.done[name].set()

    def __call__(self, name: str) -> Run:
        assert name in self.done, f"run {name!r} is not in the test's @uses(...)"
        if not self.done[name].wait(RUN_TIMEOUT * (1 + len(self.queue) / PARALLEL)):
            raise AssertionError(f"run {name} did not end")
        result = self.results[name]
        if isinstance(result, BaseException):
            raise result
        expected = RUNS[name]["exit"]
        assert result.returncode == expected, f"{name}: exit {result.returncode}, expected {expected}\n{result.stderr}"
        return result

    def close(self) -> None:
        """Stop launching; end what still runs (the tests that read it are over): SIGTERM stops a
        run cleanly."""
        self.stopping = True
        self.thread.join(timeout=10)
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.terminate()
        for proc in self.procs.values():
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@pytest.fixture(scope="module")
def runs(request, tmp_path_factory):
    needed = []
    for item in request.session.items:
        if item.module is not request.module:
            continue
        params = getattr(getattr(item, "callspec", None), "params", {})
        for name in getattr(item.function, "capture_runs", ()):
            name = name.format(**params)
            if name not in needed:
                needed.append(name)
    batch = Runs(tmp_path_factory.mktemp("capture"), needed)
    yield batch
    batch.close()


# --------------------------------------------------------------------------- helpers


def capture_of(run: Run) -> dict:
    captures = run.of("capture")
    assert len(captures) == 1, f"{run.name}: expected one capture event, got {captures}"
    assert captures[0]["component"] == "dynamics"
    return captures[0]


def angle(q: np.ndarray) -> np.ndarray:
    """Rotation angle of quaternions [x, y, z, w] (rows)."""
    q = np.atleast_2d(q)
    return 2.0 * np.arctan2(np.linalg.norm(q[:, :3], axis=1), np.abs(q[:, 3]))


def relative_angle(q0: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Angle between the attitude q0 and each row of q."""
    return np.linalg.norm((Rotation.from_quat(q0).inv() * Rotation.from_quat(q)).as_rotvec(), axis=1)


def momenta(run: Run) -> tuple[np.ndarray, np.ndarray]:
    """Total linear momentum and total angular momentum about W's origin (kg m/s, kg m^2/s), per
    row: each body's ``momentum`` (angular about its CoM) moved to the origin with its ``com``."""
    linear, angular = 0.0, 0.0
    for body in ("servicer", "target"):
        m = run.vector(f"dynamics.{body}.momentum", 6)
        c = run.vector(f"dynamics.{body}.com", 3)
        linear = linear + m[:, :3]
        angular = angular + m[:, 3:] + np.cross(c, m[:, :3])
    return linear, angular


def rates_deg(run: Run) -> tuple[np.ndarray, np.ndarray]:
    """Inertial angular speed of the servicer's and the target's base (deg/s), per row."""
    return tuple(
        np.degrees(np.linalg.norm(run.vector(f"dynamics.{b}.twist", 6)[:, 3:], axis=1)) for b in ("servicer", "target")
    )


def peak_wrench(run: Run) -> str:
    """The largest force and torque the end effector applied to the target."""
    wrench = run.vector("dynamics.grasp.wrench", 6)
    return f"{np.linalg.norm(wrench[:, :3], axis=1).max():.1f} N, {np.linalg.norm(wrench[:, 3:], axis=1).max():.1f} N m"


def same_bits(a: pandas.DataFrame, b: pandas.DataFrame) -> list[str]:
    """Columns whose values differ in any bit (or that one table lacks)."""
    if list(a.columns) != list(b.columns) or len(a) != len(b):
        return [f"layout: {len(a)} x {list(a.columns)[:3]}... vs {len(b)} x {list(b.columns)[:3]}..."]
    return [c for c in a.columns if a[c].to_numpy().tobytes() != b[c].to_numpy().tobytes()]


# --------------------------------------------------------------------------- 1. capture


@pytest.mark.parametrize("case", list(CASES))
@uses("case:{case}")
def test_capture_from_tumbles_and_offsets_nothing_was_tuned_on(runs, case):
    """Each case's run closes the grasp once: between EARLIEST_CAPTURE (3.22 s, the config's
    timeline) and 9.5 s, the residual relative velocity and pose errors it reports within the
    dynamics' declared grasp.tolerance (read from the resolved config). The impact changes
    velocities, not positions: the first welded row's relative pose is the reported error (to
    1e-12 m and 1e-10 rad: the report takes the angle from an acos, good to ~eps / angle). After it
    every row has grasp.closed = 1, the relative twist twist_ee_grasp below 1e-8 m/s and rad/s
    (against 1e-3 before) and the relative pose within 1e-9 m and rad of the capture's; before it
    closed = 0 and the controller had asked (close = 1)."""
    run = runs(f"case:{case}")
    event = capture_of(run)
    tolerance = run.config["components"]["dynamics"]["parameters"]["grasp"]["tolerance"]
    linear, angular = np.array(event["relative_twist"][:3]), np.array(event["relative_twist"][3:])
    t_c = event["time"]
    k = int(round(t_c / H))
    data = run.signals
    closed = data["dynamics.grasp.closed"].to_numpy()
    p = run.vector("dynamics.grasp.p_ee_grasp", 3)
    q = run.vector("dynamics.grasp.q_ee_grasp", 4)
    twist = run.vector("dynamics.grasp.twist_ee_grasp", 6)
    after = slice(k, None)
    print(
        f"\n{case}: grapple {np.linalg.norm(p[0]):.2f} m and {math.degrees(angle(q[0])[0]):.0f} deg from the end "
        f"effector at the start; capture at {t_c:.2f} s, residual {np.linalg.norm(linear) * 1e3:.3f} mm/s, "
        f"{math.degrees(np.linalg.norm(angular)):.3f} deg/s, errors {event['errors']['position'] * 1e3:.3f} mm, "
        f"{math.degrees(event['errors']['orientation']):.3f} deg; after it (to {data['time'].iloc[-1]:g} s) "
        f"twist <= {np.abs(twist[after]).max():.1e}, pose drift {np.abs(p[after] - p[k]).max():.1e} m, "
        f"{relative_angle(q[k], q[after]).max():.1e} rad; before it {np.abs(twist[k - 1]).max():.1e}; "
        f"wall {run.wall:.0f} s"
    )
    assert EARLIEST_CAPTURE - 1e-9 <= t_c <= LATEST_CAPTURE
    assert data["time"].iloc[k] == pytest.approx(t_c, abs=1e-9)
    assert np.linalg.norm(linear) <= tolerance["linear_velocity"]
    assert np.linalg.norm(angular) <= tolerance["angular_velocity"]
    assert event["errors"]["position"] <= tolerance["position"]
    assert event["errors"]["orientation"] <= tolerance["orientation"]
    assert math.isclose(np.linalg.norm(linear), event["errors"]["linear_velocity"], rel_tol=1e-9, abs_tol=1e-15)
    assert math.isclose(np.linalg.norm(angular), event["errors"]["angular_velocity"], rel_tol=1e-9, abs_tol=1e-15)
    # the impact moved nothing: the first welded row holds the reported pose errors
    assert abs(np.linalg.norm(p[k]) - event["errors"]["position"]) < 1e-12
    assert abs(angle(q[k])[0] - event["errors"]["orientation"]) < 1e-10  # the report's acos: ~eps / angle
    assert not closed[:k].any() and (closed[k:] == 1.0).all()
    assert (data["controller.close"].to_numpy()[:k] == 1.0).any()
    assert (data["controller.phase"].to_numpy()[-1]) == 5.0  # captured
    assert np.abs(twist[k - 1]).max() > 1e3 * WELD_TWIST  # there was a relative motion to cancel
    assert np.abs(twist[after]).max() < WELD_TWIST
    assert np.abs(p[after] - p[k]).max() < WELD_DRIFT
    assert relative_angle(q[k], q[after]).max() < WELD_DRIFT
    assert len(data) - k >= round(0.5 / H)  # at least 0.5 s of weld checked


# --------------------------------------------------------------------------- 2. momentum


@uses("environment-off")
def test_momentum_is_conserved_through_approach_capture_and_detumbling(runs):
    """Environment off (no tidal force, no gravity gradient: no external force or torque in W):
    the bodies' total linear momentum and their total angular momentum about W's origin stay at
    their first row's values to 1e-9 of their size, every row through the approach, the impact
    and 10 s of detumbling, while each body's own momentum changes by most of its size (the target
    gives up > 90% of its angular momentum).

    The impact: the target flies free until it, so its momentum jumps from the row before the
    capture to the capture's row by the impulse the capture event reports: linear, and angular
    about the target's CoM = the reported angular impulse about the weld point P plus
    (P - c) x the linear one, P placed from the target's pose, the URDF's grapple frame and the
    recorded q_ee_grasp, p_ee_grasp. To 1e-9 of the impulse."""
    run = runs("environment-off")
    event = capture_of(run)
    linear, angular = momenta(run)
    dl = np.linalg.norm(linear - linear[0], axis=1).max() / np.linalg.norm(linear[0])
    da = np.linalg.norm(angular - angular[0], axis=1).max() / np.linalg.norm(angular[0])
    target = run.vector("dynamics.target.momentum", 6)
    kept = np.linalg.norm(target[-1, 3:]) / np.linalg.norm(target[0, 3:])
    # the impulse
    k = int(round(event["time"] / H))
    impulse = np.array(event["impulse"])
    xyz, rpy = TARGET_MODEL.origin("grapple_joint")
    R_t = Rotation.from_quat(run.vector("dynamics.target.orientation", 4)[k])
    R_g = R_t * Rotation.from_euler("xyz", rpy)
    R_e = R_g * Rotation.from_quat(run.vector("dynamics.grasp.q_ee_grasp", 4)[k]).inv()
    p_g = run.vector("dynamics.target.position", 3)[k] + R_t.apply(xyz)
    P = p_g - R_e.apply(run.vector("dynamics.grasp.p_ee_grasp", 3)[k])
    c = run.vector("dynamics.target.com", 3)[k]
    jump = target[k] - target[k - 1]
    expected = np.concatenate([impulse[:3], impulse[3:] + np.cross(P - c, impulse[:3])])
    miss = np.abs(jump - expected).max() / np.abs(expected).max()
    print(
        f"\nenvironment off: capture at {event['time']:.2f} s; |P| {np.linalg.norm(linear[0]):.4f} kg m/s, "
        f"|L_O| {np.linalg.norm(angular[0]):.4f} kg m^2/s; largest relative change: linear {dl:.1e}, angular "
        f"{da:.1e}; the target keeps {kept:.1e} of its angular momentum; impulse "
        f"{np.linalg.norm(impulse[:3]):.2e} N s, {np.linalg.norm(impulse[3:]):.2e} N m s, the target's momentum "
        f"jump agrees to {miss:.1e}; peak grasp wrench {peak_wrench(run)}"
    )
    assert run.signals["time"].iloc[-1] > event["time"] + 10.0 - 1e-9
    assert dl <= 1e-9 and da <= 1e-9
    assert kept < 0.1
    assert miss < 1e-9


@uses("environment-off")
def test_the_targets_momentum_ends_in_the_wheels(runs):
    """Environment off. The wheels' angular momentum, I_s (qd_j + a_j . omega_bus) a_j summed over
    the three wheels (I_s = 0.2 kg m^2 and the axes a_j read from the URDF, W axes through the bus
    attitude), is ~0 before the capture (the wheels are not driven: < 1e-3 of the total) and at
    the end (20 s) holds the two bodies' whole angular momentum about the assembly's CoM (masses
    from the URDFs) but what the assembly's own rotation can carry: the rest is at most
    I_max * Omega, Omega the largest body rate plus the arm's joint rates, I_max a bound of the
    assembly's largest moment of inertia (the reduced mass times the CoMs' distance squared, plus
    each body's bound from its URDF, Urdf.largest_moment_bound). And that rest is below 2%."""
    run = runs("environment-off")
    k_c = int(round(capture_of(run)["time"] / H))
    m_s, m_t = SERVICER.mass(), TARGET_MODEL.mass()
    mom_s, mom_t = run.vector("dynamics.servicer.momentum", 6), run.vector("dynamics.target.momentum", 6)
    c_s, c_t = run.vector("dynamics.servicer.com", 3), run.vector("dynamics.target.com", 3)
    c = (m_s * c_s + m_t * c_t) / (m_s + m_t)
    total = mom_s[:, 3:] + mom_t[:, 3:] + np.cross(c_s - c, mom_s[:, :3]) + np.cross(c_t - c, mom_t[:, :3])
    R = Rotation.from_quat(run.vector("dynamics.servicer.orientation", 4))
    w_bus = R.inv().apply(run.vector("dynamics.servicer.twist", 6)[:, 3:])  # bus axes
    qd = run.vector("dynamics.servicer.qd", 9)
    joints = [name for name, joint in SERVICER.joints.items() if joint.get("type") != "fixed"]  # q's layout
    wheels = np.zeros_like(w_bus)
    for name in WHEELS:
        a = SERVICER.axis(name) / np.linalg.norm(SERVICER.axis(name))
        spin = SERVICER.spin_inertia(name) * (qd[:, joints.index(name)] + w_bus @ a)
        wheels += spin[:, None] * a
    wheels = R.apply(wheels)
    size = np.linalg.norm(total[0])
    before = np.linalg.norm(wheels[:k_c], axis=1).max() / size
    rest = np.linalg.norm(total[-1] - wheels[-1])
    # the bound of what the assembly's own rotation carries at the end
    base_s = np.linalg.norm(run.vector("dynamics.servicer.position", 3)[-1] - c_s[-1])
    base_t = np.linalg.norm(run.vector("dynamics.target.position", 3)[-1] - c_t[-1])
    reduced = m_s * m_t / (m_s + m_t)
    inertia = (
        SERVICER.largest_moment_bound(base_s)
        + TARGET_MODEL.largest_moment_bound(base_t)
        + reduced * np.linalg.norm(c_t[-1] - c_s[-1]) ** 2
    )
    servicer, target = rates_deg(run)
    omega = math.radians(max(servicer[-1], target[-1])) + np.abs(qd[-1, [joints.index(j) for j in ARM]]).sum()
    print(
        f"\nwheels hold {np.linalg.norm(wheels[-1]):.4f} of {np.linalg.norm(total[-1]):.4f} kg m^2/s about the "
        f"assembly CoM at {run.signals['time'].iloc[-1]:g} s; the rest {rest:.4f} ({rest / size:.1e} of it) <= "
        f"I_max {inertia:.0f} kg m^2 x Omega {omega:.2e} rad/s = {inertia * omega:.4f}; before the capture the "
        f"wheels held at most {before:.1e} of it; spin inertias {[SERVICER.spin_inertia(n) for n in WHEELS]} kg m^2"
    )
    assert [SERVICER.spin_inertia(n) for n in WHEELS] == [0.2, 0.2, 0.2]
    assert np.abs(np.linalg.norm(total, axis=1) - size).max() < 1e-9 * size  # conserved about the moving CoM too
    assert before < 1e-3
    assert rest <= inertia * omega
    assert rest < 0.02 * size


# --------------------------------------------------------------------------- 3. detumble


@uses("shipped")
def test_the_assembly_detumbles_below_0_1_deg_s(runs):
    """The shipped scenario (environment on) cut at 18 s: the target starts at ~2.45 deg/s inertial
    (2.5 deg/s relative to LVLH), the grasp closes, and the servicer's and the target's inertial
    rates are both below 0.1 deg/s over the last second; the wrist wrench (true) never exceeds the
    grasp load limits the controller's config declares, impact included."""
    run = runs("shipped")
    event = capture_of(run)
    servicer, target = rates_deg(run)
    last = run.signals["time"].to_numpy() >= run.signals["time"].iloc[-1] - 1.0 - 1e-9
    residual = np.array(event["relative_twist"])
    print(
        f"\nshipped: capture at {event['time']:.2f} s (residual {np.linalg.norm(residual[:3]) * 1e3:.3f} mm/s, "
        f"{math.degrees(np.linalg.norm(residual[3:])):.3f} deg/s); target {target[0]:.3f} deg/s at the start; at "
        f"{run.signals['time'].iloc[-1]:g} s servicer {servicer[-1]:.4f}, target {target[-1]:.4f} deg/s; last second "
        f"at most {max(servicer[last].max(), target[last].max()):.4f} deg/s; peak grasp wrench {peak_wrench(run)}; "
        f"wall {run.wall:.0f} s"
    )
    assert target[0] > 2.0
    assert run.signals["dynamics.grasp.closed"].iloc[-1] == 1.0 and event["time"] < run.signals["time"].iloc[-1] - 1.0
    assert servicer[last].max() < 0.1 and target[last].max() < 0.1
    wrench = np.column_stack([run.signals[f"dynamics.grasp.wrench[{i}]"] for i in range(6)])
    limits = run.config["components"]["controller"]["parameters"]
    assert np.linalg.norm(wrench[:, :3], axis=1).max() <= limits["grasp_force_limit"]
    assert np.linalg.norm(wrench[:, 3:], axis=1).max() <= limits["grasp_torque_limit"]


# --------------------------------------------------------------------------- 4. determinism


@uses("shipped", "shipped-again")
def test_the_same_config_gives_bit_identical_signals(runs):
    """Two runs of the same config (seeded sensor noise), the second with every component in one
    process (as all runs here but the reference, the swap and the restart): every part file of
    signals.parquet is the same, byte for byte."""
    a, b = runs("shipped"), runs("shipped-again")
    parts = a.parts()
    assert len(parts) == math.ceil(len(a.signals) / 1000)
    assert parts == b.parts()


@uses("shipped", "other-seed")
def test_another_sensor_seed_changes_the_measurements(runs):
    """Other seeds for the three sensors (0.6 s): every measurement output differs from the shipped
    run's from the sensor's first sample on, while the truth (every dynamics output) is the same
    bit for bit: the controller holds the arm on its joint state until its first estimate
    (0.7 s) and reads the IMU and the wrist sensor only after the capture."""
    a, b = runs("shipped"), runs("other-seed")
    n = len(b.signals)
    shipped = a.signals.iloc[:n].reset_index(drop=True)
    # the controller's grasp_distance is the last measured distance until the first estimate
    truth = [
        c
        for c in shipped.columns
        if c.startswith(("dynamics.", "orbit.", "controller.")) and c != "controller.grasp_distance"
    ]
    assert not same_bits(shipped[truth], b.signals[truth])
    # rows holding a sample: the pose sensor's first comes through its latency (valid), the others'
    # at their first step
    pose = shipped["pose_sensor.valid"].to_numpy() == 1.0
    assert (b.signals["pose_sensor.valid"].to_numpy() == pose).all()
    every = np.arange(n) >= 1
    for name, size, sampled in (
        ("pose_sensor.p", 3, pose),
        ("pose_sensor.q", 4, pose),
        ("imu.rate", 3, every),
        ("imu.specific_force", 3, every),
        ("wrist_ft.wrench", 6, every),
    ):
        x, y = a.vector(name, size)[:n], b.vector(name, size)
        assert sampled.sum() > n // 2, name
        assert np.all(np.any(x[sampled] != y[sampled], axis=1)), name


# --------------------------------------------------------------------------- 5. state after capture


@uses("shipped", "swap")
def test_a_same_type_swap_of_the_dynamics_after_the_capture_changes_nothing(runs):
    """`events: [{at: 10 s, swap: dynamics}]`, after the capture: the new dynamics process gets
    the welded state (the grasp's weld point and attitude, closed) and the run goes on bit for bit
    as without the swap, every part file the same; one capture event only, and no warning."""
    reference, swapped = runs("shipped"), runs("swap")
    event = capture_of(swapped)
    swap = swapped.of("swap")
    assert len(swap) == 1 and swap[0]["step"] == round(SWAP_AT / H) and swap[0]["state_handed_over"] is True, swap
    assert event["time"] < SWAP_AT
    # the generation swapped out says its last words on purpose: no warning of a dropped message
    assert not [e for e in swapped.events if e["event"] == "warning"], swapped.events
    assert not same_bits(reference.signals, swapped.signals)
    assert reference.parts() == swapped.parts()


@uses("shipped", "restart")
def test_a_restart_from_a_checkpoint_after_the_capture_changes_nothing(runs):
    """The dynamics (on_failure: restart) SIGKILLed at 11 s; checkpoints every 2 s: the run goes
    back to the checkpoint of 10 s, after the capture, every component in a new process, and ends
    with the recording of the run that never failed, bit for bit; one capture event only."""
    reference, restarted = runs("shipped"), runs("restart")
    event = capture_of(restarted)
    restart = restarted.of("restart")
    assert len(restart) == 1 and restart[0]["component"] == "dynamics", restart
    assert restart[0]["step"] == round(10.0 / H) and event["time"] < 10.0
    fault = restarted.of("fault")
    # the step the orchestrator had recorded when the process died (a killed process may take its
    # last unsent outputs with it)
    assert len(fault) == 1 and round(10.0 / H) < fault[0]["step"] <= round(CRASH_AT / H), fault
    logs = sorted(p.name for p in (restarted.record / "logs").iterdir())
    assert "dynamics.1.log" in logs and "controller.1.log" in logs  # every component started again
    assert not same_bits(reference.signals, restarted.signals)
    assert reference.parts() == restarted.parts()


# --------------------------------------------------------------------------- 6. not captured


@uses("beyond")
def test_a_target_beyond_the_arm_is_an_outcome_naming_the_reach(runs):
    """The target 4 m out along LVLH x, its grapple facing the servicer (3.06 m from the shoulder;
    the arm reaches 1.54 m, the sum of the URDF's joint offsets from the shoulder to the end
    effector), not turning: at the first plan after the estimator's window is full (60
    measurements at 20 Hz, the last seen at 3.05 s; until then a rate below the noise is not told
    from a slow turn) a capture_aborted event gives both figures as the geometry says (to the 0.01 m
    printed, plus the 1e-3 m the bodies drift in 3 s) and the rate it could not tell from zero; the
    run ends normally (exit 0, status completed), nothing is captured, close never rises and the arm
    holds its posture (within 1 mrad) to the end."""
    run = runs("beyond")
    shoulder, reach = shoulder_and_reach()
    xyz, _rpy = TARGET_MODEL.origin("grapple_joint")
    R_t = Rotation.from_quat(BEYOND["orientation"])
    grapple = np.array(BEYOND["position"]) + R_t.apply(xyz)
    distance = float(np.linalg.norm(grapple - shoulder))
    aborted = run.of("capture_aborted")
    assert len(aborted) == 1, run.events
    found = re.search(
        r"the grasp point is ([\d.]+) m from the shoulder, the arm reaches ([\d.]+) m", aborted[0]["reason"]
    )
    print(f"\nbeyond: {aborted[0]['reason']}; expected {distance:.3f} m and {reach:.3f} m")
    assert found, aborted[0]["reason"]
    assert "(it does not turn that the estimator can tell: " in aborted[0]["reason"]
    assert abs(float(found.group(1)) - distance) <= 0.005 + 1e-3
    assert abs(float(found.group(2)) - reach) <= 0.005
    assert 3.05 - 1e-9 <= aborted[0]["time"] <= 3.25 and aborted[0]["component"] == "controller"
    assert run.events[-1]["status"] == "completed" and not run.of("fault")
    assert not run.of("capture")
    data = run.signals
    assert (data["controller.close"].to_numpy() == 0.0).all()
    assert data["controller.phase"].iloc[-1] == 6.0  # aborted
    q = run.vector("dynamics.servicer.q", 9)[:, :6]
    assert np.abs(q - q[0]).max() < 1e-3


# --------------------------------------------------------------------------- 7. the envelope


def _envelope() -> dict[str, tuple[np.ndarray, float]]:
    """Twelve tumble axes nobody tuned on, uniform over the sphere (target axes; numpy's default
    generator, seed 2026), each at 2.5 and 4 deg/s."""
    axes = np.random.default_rng(2026).normal(size=(12, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    return {f"axis{i:02d}-{rate:g}deg": (axis, rate) for i, axis in enumerate(axes) for rate in (2.5, 4.0)}


ENVELOPE = _envelope()
# The capture closes by 3.74 s; in all 24 runs the wrist load peaks by 5.7 s (3.7 N at most after
# 6 s against the 100 N limit) and the momentum drift by 5 s: 6 s holds every asserted extreme.
ENVELOPE_DURATION = 6.0
for _name, (_axis, _rate) in ENVELOPE.items():
    RUNS[f"envelope:{_name}"] = {
        "duration": ENVELOPE_DURATION,
        "exit": 0,
        "sets": [f"{TARGET}twist={{rate: {_rate!r} deg/s, axis: {vector(_axis)}, axes: body}}", *ENVIRONMENT_OFF],
    }


@pytest.mark.parametrize("case", list(ENVELOPE))
@uses("envelope:{case}")
def test_a_tumble_about_any_axis_up_to_4_deg_s_is_captured(runs, case):
    """The shipped config with nothing changed but the target's twist (and the environment off):
    the grasp closes once, with no retreat, abort or overload; the bodies' total linear and angular
    momentum (about W's origin) stay at their first row's values to 1e-9 of their size through the
    approach, the impact and the weld to the end (6 s); the wrist wrench (true) stays within the
    fixture's load limits (grasp.force_limit and torque_limit of the resolved config)."""
    run = runs(f"envelope:{case}")
    event = capture_of(run)
    linear, angular = momenta(run)
    dl = np.linalg.norm(linear - linear[0], axis=1).max() / np.linalg.norm(linear[0])
    da = np.linalg.norm(angular - angular[0], axis=1).max() / np.linalg.norm(angular[0])
    grasp = run.config["components"]["dynamics"]["parameters"]["grasp"]
    wrench = run.vector("dynamics.grasp.wrench", 6)
    force, torque = np.linalg.norm(wrench[:, :3], axis=1).max(), np.linalg.norm(wrench[:, 3:], axis=1).max()
    print(
        f"\n{case}: capture at {event['time']:.2f} s; momentum drift linear {dl:.1e}, angular {da:.1e}; peak wrist "
        f"{force:.1f} N, {torque:.1f} N m; wall {run.wall:.0f} s"
    )
    assert not run.of("capture_aborted") and not run.of("capture_retreat") and not run.of("grasp_overload")
    assert run.signals["dynamics.grasp.closed"].iloc[-1] == 1.0
    assert dl <= 1e-9 and da <= 1e-9
    assert force <= to_si(grasp["force_limit"]) and torque <= to_si(grasp["torque_limit"])


def to_si(text) -> float:
    """'100 N' or '30 N*m' as the number (these units are SI already)."""
    return float(str(text).split()[0])


@uses("too-fast")
def test_a_tumble_too_fast_for_the_joints_is_an_outcome_naming_the_joint(runs):
    """The target tumbling at 60 deg/s: following its grapple (0.65 m from the CoM, 0.68 m/s)
    needs more than the planner's share of the URDF velocity limits everywhere on its turn, so at
    the first plan (0.7 s, the 12th measurement) the capture is given up with the joint, the rate
    it would need and its URDF limit (read from the URDF here); the run completes."""
    run = runs("too-fast")
    aborted = run.of("capture_aborted")
    assert len(aborted) == 1, run.events
    reason = aborted[0]["reason"]
    print(f"\ntoo fast: {reason}")
    found = re.search(
        r"following the grapple needs (arm_\d_joint) at ([\d.]+) rad/s, more than 0.5 of its URDF "
        r"velocity limit ([\d.]+) rad/s",
        reason,
    )
    assert found and "in a whole turn of the tumble" in reason, reason
    limit = float(SERVICER.joints[found.group(1)].find("limit").get("velocity"))
    assert float(found.group(3)) == pytest.approx(limit, abs=0.005) and float(found.group(2)) > 0.5 * limit
    assert 0.7 - 1e-9 <= aborted[0]["time"] <= 0.8
    assert run.events[-1]["status"] == "completed" and not run.of("capture")


@uses("noise-x5")
def test_five_times_the_shipped_sensor_noise_still_captures(runs):
    """Every sensor's noise 5 times the shipped config's (the pose sensor 1 mm and 0.1 deg): the
    grasp closes once, at the first approach, within the dynamics' grasp tolerance (the event's
    errors), and no retreat came first."""
    run = runs("noise-x5")
    event = capture_of(run)
    tolerance = run.config["components"]["dynamics"]["parameters"]["grasp"]["tolerance"]
    print(f"\nnoise x5: capture at {event['time']:.2f} s, errors {event['errors']}")
    assert not run.of("capture_retreat") and not run.of("capture_aborted")
    assert [e["attempt"] for e in run.of("capture_approach")] == [1]
    assert (
        event["errors"]["position"] <= tolerance["position"]
        and event["errors"]["linear_velocity"] <= tolerance["linear_velocity"]
    )


@uses("noisy")
def test_noise_the_estimator_cannot_beat_is_an_outcome_naming_the_estimate(runs):
    """Pose noise of 2 cm and 2 deg (100 times the shipped sensor's), one approach allowed: the
    estimated errors never stay within the controller's tolerances, the arm retreats after
    track_time and the capture is given up with a reason that names the estimated error that
    blocked it most, its share of the time and its mean against its tolerance; the dynamics never
    closed the grasp and the run completes."""
    run = runs("noisy")
    aborted, retreats = run.of("capture_aborted"), run.of("capture_retreat")
    assert len(aborted) == 1 and len(retreats) == 1, run.events
    reason = aborted[0]["reason"]
    print(f"\nnoisy: {reason}")
    found = re.search(
        r"^1 approach: the estimated errors did not stay within the tolerances .*: the "
        r"(position|attitude|velocity|rate) error was above \1_tolerance = ([\d.]+) (mm|deg|mm/s|deg/s) "
        r"(\d+)% of the time \(mean ([\d.]+) \3\)",
        reason,
    )
    assert found, reason
    assert float(found.group(5)) > 0.0 and int(found.group(4)) > 0
    assert not run.of("capture") and run.events[-1]["status"] == "completed"
    assert run.signals["controller.phase"].iloc[-1] == 6.0
