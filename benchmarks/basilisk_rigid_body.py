"""One rigid spacecraft in Basilisk: point-mass Earth, gravity-gradient torque, RK4; for comparison.

    <python with bsk> benchmarks/basilisk_rigid_body.py < spec.json > result.json

Run by bench_basilisk.py with the interpreter of its own Basilisk environment (Basilisk is not a
dependency of Zenorbit). The spec (JSON on stdin, SI units, ECI = Basilisk's N frame): ``mass``,
``inertia`` (3x3 about the CoM, body axes), ``mu``, ``r``, ``v`` (CoM), ``q`` (q_N_B [x, y, z, w]),
``w`` (angular velocity, body axes), ``step_ns``, ``steps``, ``batch`` (steps per timed batch),
``sample_every`` (steps between recorded attitudes). It prints JSON: ``version``, ``cpu_ns`` and
``wall_ns`` (per step, of each batch of a run without the recorder: the process's CPU time, since
Basilisk steps its processes on a thread of its own, and the wall time) and ``q`` (q_N_B
[x, y, z, w] at ``t_ns`` = 0, sample_every steps, ... of a run with it).
"""

from __future__ import annotations

import json
import math
import sys
import time


def spacecraft_sim(spec: dict, record: bool):
    """(simulation, recorder or None), initialized: the spacecraft, Earth's point-mass gravity, the
    gravity-gradient effector and an RK4 integrator on one task of ``step_ns``."""
    from Basilisk.simulation import GravityGradientEffector, spacecraft, svIntegrators
    from Basilisk.utilities import SimulationBaseClass, simIncludeGravBody

    sim = SimulationBaseClass.SimBaseClass()
    sim.CreateNewProcess("dynamics").addTask(sim.CreateNewTask("step", spec["step_ns"]))
    body = spacecraft.Spacecraft()
    body.ModelTag = "box"
    body.hub.mHub = spec["mass"]
    body.hub.r_BcB_B = [[0.0], [0.0], [0.0]]
    body.hub.IHubPntBc_B = spec["inertia"]
    x, y, z, w = spec["q"]
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    body.hub.sigma_BNInit = [[x / (1.0 + w)], [y / (1.0 + w)], [z / (1.0 + w)]]  # MRP of q_N_B
    body.hub.omega_BN_BInit = [[c] for c in spec["w"]]
    body.hub.r_CN_NInit = [[c] for c in spec["r"]]
    body.hub.v_CN_NInit = [[c] for c in spec["v"]]
    sim.AddModelToTask("step", body)
    gravity = simIncludeGravBody.gravBodyFactory()
    earth = gravity.createCustomGravObject("earth", spec["mu"])
    earth.isCentralBody = True
    gravity.addBodiesTo(body)
    gradient = GravityGradientEffector.GravityGradientEffector()
    gradient.ModelTag = "gravity_gradient"
    gradient.addPlanetName(earth.planetName)
    body.addDynamicEffector(gradient)
    sim.AddModelToTask("step", gradient)
    integrator = svIntegrators.svIntegratorRK4(body)
    body.setIntegrator(integrator)
    recorder = None
    if record:
        recorder = body.scStateOutMsg.recorder(spec["step_ns"] * spec["sample_every"])
        sim.AddModelToTask("step", recorder)
    sim.InitializeSimulation()
    sim._keep = (body, gravity, earth, gradient, integrator)  # SWIG objects live as long as the simulation
    return sim, recorder


def quaternions(sigmas) -> list[list[float]]:
    """q_N_B [x, y, z, w] of MRPs sigma_BN ([BN] maps N components to B: the same rotation)."""
    out = []
    for s in sigmas:
        s2 = float(s[0] ** 2 + s[1] ** 2 + s[2] ** 2)
        out.append([2.0 * s[0] / (1.0 + s2), 2.0 * s[1] / (1.0 + s2), 2.0 * s[2] / (1.0 + s2), (1.0 - s2) / (1.0 + s2)])
    return [[float(c) for c in q] for q in out]


def main() -> None:
    from importlib.metadata import version

    spec = json.load(sys.stdin)
    step_ns, steps, batch = spec["step_ns"], spec["steps"], spec["batch"]
    sim, recorder = spacecraft_sim(spec, record=True)
    sim.ConfigureStopTime(steps * step_ns)
    sim.ExecuteSimulation()
    attitude = quaternions(recorder.sigma_BN)
    times = [int(t) for t in recorder.times()]
    sim, _ = spacecraft_sim(spec, record=False)
    cpu_ns, wall_ns = [], []
    for b in range(math.ceil(steps / batch)):
        n = min(batch, steps - b * batch)
        sim.ConfigureStopTime((b * batch + n) * step_ns)
        cpu, wall = time.process_time_ns(), time.perf_counter_ns()
        sim.ExecuteSimulation()
        cpu_ns.append((time.process_time_ns() - cpu) / n)
        wall_ns.append((time.perf_counter_ns() - wall) / n)
    json.dump(
        {"version": version("bsk"), "cpu_ns": cpu_ns, "wall_ns": wall_ns, "q": attitude, "t_ns": times}, sys.stdout
    )


if __name__ == "__main__":
    main()
