"""Basilisk's geomagnetic field (magneticFieldCenteredDipole, magneticFieldWMM) and magnetorquer
torque (MtbEffector) on shared cases; prints JSON. Run by ``python -m tests.basilisk geomagnetic``.

Earth orientation: each case gives C_ecef_eci as three angles (R3(a3) R1(a2) R3(a1), general
rotations, no symmetry); Basilisk gets that matrix as its planet's ``J20002Pfix`` (planet at the
origin) and the test gives the same matrix to Zenorbit's model, so the two sides share one Earth
orientation. Time: each case's UTC epoch (whole seconds) goes in Basilisk's epoch message, the
field is evaluated at simulation time 0.

The WMM2025 coefficients: Basilisk's support data fetches ``WMM2025.COF`` from the network; this
script instead gives ``configureWMMFile`` the identical file pygeomag ships (``WMM.COF``, md5
a1b6402dd23658d15affb0f31babccc7, checked here): ``ZENORBIT_WMM_DIR`` names its folder, else it is
looked for in the site-packages of the Python this venv was made from (the project's).
"""

from __future__ import annotations

import glob
import hashlib
import json
import math
import os
import sys

import numpy as np

WMM_MD5 = "a1b6402dd23658d15affb0f31babccc7"
R_E = 6378137.0

# epoch (UTC), r_eci (m), Earth orientation angles (rad): varied latitudes, longitudes, heights, dates
CASES = [
    {"epoch": "2025-01-01T00:00:00", "r_eci": [6778137.0, 0.0, 0.0], "angles": [0.3, 0.0, 0.0]},
    {"epoch": "2025-06-21T06:30:15", "r_eci": [-2561234.5, 5437812.25, 3521908.0], "angles": [1.234, 0.0021, -0.7]},
    {"epoch": "2026-03-14T05:26:53", "r_eci": [4123456.0, -3210987.0, -4876543.0], "angles": [2.71, -0.0018, 0.45]},
    {"epoch": "2027-11-02T17:45:00", "r_eci": [-6012345.0, -2345678.0, 1987654.0], "angles": [-2.2, 0.0035, 1.9]},
    {
        "epoch": "2028-02-29T23:59:59",
        "r_eci": [123456.0, 234567.0, 7078137.0],
        "angles": [0.77, 0.001, -2.5],
    },  # near the pole
    {"epoch": "2029-08-08T08:08:08", "r_eci": [5500000.0, 4400000.0, -1200000.0], "angles": [-0.9, -0.0027, 3.0]},
    {"epoch": "2029-12-31T12:00:00", "r_eci": [-4000000.0, 2000000.0, -5300000.0], "angles": [1.7, 0.0012, -1.1]},
    {"epoch": "2026-09-30T00:00:01", "r_eci": [6378137.0 + 35786e3, 1000.0, -2000.0], "angles": [0.1, 0.0, 0.2]},  # GEO
]
# one magnetorquer case: three rods along body axes (Gt = identity) and a skewed fourth, a command
# above the limit on two of them, a general attitude (MRP sigma_BN), a field in N
MTB_CASE = {
    "gt_B": [
        [1.0, 0.0, 0.0, 0.57735026918962573],
        [0.0, 1.0, 0.0, 0.57735026918962573],
        [0.0, 0.0, 1.0, 0.57735026918962573],
    ],
    "max_dipoles": [80.0, 100.0, 60.0, 30.0],
    "dipoles": [55.5, -130.0, 90.0, -12.5],
    "sigma_BN": [0.21, -0.33, 0.12],
    "b_N": [21.7e-6, -8.4e-6, 33.1e-6],
}


def rotation(angles):
    a1, a2, a3 = angles

    def r1(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])

    def r3(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])

    return r3(a3) @ r1(a2) @ r3(a1)


def wmm_file():
    folder = os.environ.get("ZENORBIT_WMM_DIR")
    if not folder:
        found = glob.glob(
            os.path.join(sys.base_prefix, "lib", "python3*", "site-packages", "pygeomag", "wmm", "WMM.COF")
        )
        if not found:
            raise SystemExit("no WMM.COF: set ZENORBIT_WMM_DIR to the folder of pygeomag's wmm/WMM.COF")
        folder = os.path.dirname(found[0])
    path = os.path.join(folder, "WMM.COF")
    with open(path, "rb") as f:
        digest = hashlib.md5(f.read()).hexdigest()
    if digest != WMM_MD5:
        raise SystemExit(f"{path}: md5 {digest}, expected {WMM_MD5} (WMM2025)")
    return path


def field(module, case):
    from Basilisk.architecture import messaging

    C = rotation(case["angles"])
    planet = messaging.SpicePlanetStateMsgPayload()
    planet.J20002Pfix = C.tolist()
    planet.PositionVector = [0.0, 0.0, 0.0]
    planet_msg = messaging.SpicePlanetStateMsg().write(planet)
    state = messaging.SCStatesMsgPayload()
    state.r_BN_N = case["r_eci"]
    state_msg = messaging.SCStatesMsg().write(state)
    date, time = case["epoch"].split("T")
    epoch = messaging.EpochMsgPayload()
    epoch.year, epoch.month, epoch.day = (int(x) for x in date.split("-"))
    epoch.hours, epoch.minutes, seconds = (int(x) for x in time.split(":"))
    epoch.seconds = float(seconds)
    epoch_msg = messaging.EpochMsg().write(epoch)
    module.planetPosInMsg.subscribeTo(planet_msg)
    module.epochInMsg.subscribeTo(epoch_msg)
    module.addSpacecraftToModel(state_msg)
    module.Reset(0)
    module.UpdateState(0)
    b = list(module.envOutMsgs[-1].read().magField_N)
    return {**case, "C_ecef_eci": C.tolist(), "b_eci": b}


def mtb_torque(case):
    """MtbEffector's torque (body axes) on a hub at sigma_BN, not rotating, inertia so large that
    the attitude does not move within the one 1 ms step."""
    from Basilisk.architecture import messaging
    from Basilisk.simulation import MtbEffector, spacecraft
    from Basilisk.utilities import SimulationBaseClass

    sim = SimulationBaseClass.SimBaseClass()
    sim.CreateNewProcess("p").addTask(sim.CreateNewTask("t", 1000000))
    sc = spacecraft.Spacecraft()
    sc.hub.mHub = 1.0e9
    sc.hub.IHubPntBc_B = (np.eye(3) * 1.0e12).tolist()
    sc.hub.sigma_BNInit = [[x] for x in case["sigma_BN"]]
    sc.hub.r_CN_NInit = [[7.0e6], [0.0], [0.0]]
    sc.hub.v_CN_NInit = [[0.0], [7.5e3], [0.0]]
    sim.AddModelToTask("t", sc)
    mtb = MtbEffector.MtbEffector()
    mtb.ModelTag = "mtb"
    sc.addDynamicEffector(mtb)
    sim.AddModelToTask("t", mtb)
    n = len(case["dipoles"])
    params = messaging.MTBArrayConfigMsgPayload()
    params.numMTB = n
    params.GtMatrix_B = [x for row in case["gt_B"] for x in row]  # row major, 3 x n
    params.maxMtbDipoles = case["max_dipoles"]
    cmd = messaging.MTBCmdMsgPayload()
    cmd.mtbDipoleCmds = case["dipoles"]
    mag = messaging.MagneticFieldMsgPayload()
    mag.magField_N = case["b_N"]
    msgs = (
        messaging.MTBArrayConfigMsg().write(params),
        messaging.MTBCmdMsg().write(cmd),
        messaging.MagneticFieldMsg().write(mag),
    )
    mtb.mtbParamsInMsg.subscribeTo(msgs[0])
    mtb.mtbCmdInMsg.subscribeTo(msgs[1])
    mtb.magInMsg.subscribeTo(msgs[2])
    recorder = mtb.mtbOutMsg.recorder()
    sim.AddModelToTask("t", recorder)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(1000000)
    sim.ExecuteSimulation()
    torque = [float(x) for x in recorder.mtbNetTorque_B[-1]]
    return {**case, "torque_B": torque}


def main():
    import Basilisk
    from Basilisk.simulation import magneticFieldCenteredDipole, magneticFieldWMM
    from Basilisk.utilities import simSetPlanetEnvironment

    path = wmm_file()
    dipole, wmm = [], []
    for case in CASES:
        module = magneticFieldCenteredDipole.MagneticFieldCenteredDipole()
        simSetPlanetEnvironment.centeredDipoleMagField(module, "earth")
        dipole.append(field(module, case))
        coefficients = {"g10": module.g10, "g11": module.g11, "h11": module.h11, "radius": module.planetRadius}
        module = magneticFieldWMM.MagneticFieldWMM()
        module.configureWMMFile(path)
        wmm.append(field(module, case))
    print(
        json.dumps(
            {
                "basilisk": Basilisk.__version__,
                "dipole_coefficients": coefficients,
                "dipole": dipole,
                "wmm": wmm,
                "mtb": mtb_torque(MTB_CASE),
            }
        )
    )


if __name__ == "__main__":
    main()
