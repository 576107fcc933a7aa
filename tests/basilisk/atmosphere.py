"""Basilisk's atmospheric densities for the shared cases: ``msisAtmosphere`` (NRLMSISE-00) and
``exponentialAtmosphere``. Prints JSON; run with Basilisk's interpreter (``python -m tests.basilisk atmosphere``).

NRLMSISE-00 (``MSIS_CASES``): each case is a UTC instant (whole seconds), a geodetic point
(latitude, longitude in deg, height in m above the WGS 84 ellipsoid) and the space-weather indices
(F10.7 of the previous day, its 81-day average, the daily Ap), fed to Basilisk's 23 ``SwDataMsg``
inputs (every 3-hour ap equal to the daily Ap: Basilisk runs the model in daily-Ap mode, switch 9 =
1). Basilisk turns a position into latitude, longitude and altitude by a *sphere* of radius
``planetRadius`` (geodeticConversion ``PCI2LLA`` without a polar radius); so that it evaluates the
model at the same point as Zenorbit (which converts to WGS 84 geodetic coordinates), it is given a
planet-fixed frame (the planet message's ``J20002Pfix``, a turn ``theta`` about z and a tilt
``tilt`` about x, different per case) and the inertial position whose spherical coordinates in
that frame are the geodetic latitude, longitude and height (radius ``planetRadius`` + height). The
script also writes the inverse it expects Basilisk to apply (``lla``) so a test can see the point.
Basilisk uses ``gtd7`` below 500 km and ``gtd7d`` (anomalous oxygen in the total) from 500 km.

Exponential (``EXPONENTIAL_CASES``): rho = baseDensity exp(-(|r| - planetRadius) / scaleHeight) at
a position r; each band of Zenorbit's table as one exponential (planetRadius = R_E + h0), and one
single layer.
"""

from __future__ import annotations

import json
import math
import os
import time

import numpy as np

R_EARTH = 6378137.0  # m: the sphere Basilisk's conversion uses, here the WGS 84 semi-major axis

# (UTC y, m, d, h, min, s), latitude deg, longitude deg, height m, F10.7, F10.7a, Ap, theta deg, tilt deg
MSIS_CASES = [
    ((2026, 3, 20, 8, 3, 20), 51.6, -70.0, 400e3, 150.0, 150.0, 4.0, 23.0, 0.0),
    ((2026, 3, 20, 20, 0, 0), -33.0, 151.2, 200e3, 150.0, 150.0, 4.0, 101.5, 0.3),
    ((2026, 6, 21, 12, 0, 0), 80.2, 10.0, 250e3, 70.0, 72.0, 3.0, -40.0, 0.0),
    ((2026, 6, 21, 2, 30, 0), -62.5, -120.0, 300e3, 250.0, 200.0, 50.0, 200.0, -0.2),
    ((2026, 9, 1, 17, 45, 10), 5.0, 77.7, 350e3, 180.0, 160.0, 15.0, 3.0, 0.1),
    ((2026, 12, 2, 23, 59, 59), -5.5, -179.5, 450e3, 95.0, 110.0, 27.0, 330.0, 0.0),
    ((2025, 1, 15, 6, 0, 0), 28.5, -80.6, 499e3, 130.0, 140.0, 7.0, 15.0, 0.05),
    ((2025, 1, 15, 6, 0, 0), 28.5, -80.6, 501e3, 130.0, 140.0, 7.0, 15.0, 0.05),
    ((2025, 7, 4, 14, 10, 0), 45.0, 2.3, 550e3, 200.0, 190.0, 80.0, 250.0, 0.0),
    ((2024, 5, 11, 3, 0, 0), -45.0, 60.0, 600e3, 220.0, 180.0, 207.0, 80.0, -0.1),
    ((2024, 2, 29, 10, 20, 30), 70.0, -150.0, 700e3, 65.0, 68.0, 2.0, 170.0, 0.0),
    ((2023, 10, 31, 19, 0, 0), -80.0, 135.0, 800e3, 160.0, 155.0, 12.0, 290.0, 0.2),
    ((2023, 4, 1, 0, 0, 0), 12.3, -45.6, 220e3, 300.0, 250.0, 120.0, 45.0, 0.0),
    ((2022, 8, 15, 9, 9, 9), -20.0, -10.0, 780e3, 110.0, 120.0, 5.0, 12.0, 0.0),
]

# altitude (m) of the point, base altitude h0 (m), density at h0 (kg/m^3), scale height (m)
EXPONENTIAL_CASES = [
    (412.5e3, 400e3, 3.725e-12, 58.515e3),
    (199.0e3, 180e3, 5.464e-10, 29.740e3),
    (655.0e3, 600e3, 1.454e-13, 71.835e3),
    (1200e3, 1000e3, 3.019e-15, 268.00e3),
    (96.0e3, 90e3, 3.396e-6, 5.382e3),
    (431.7e3, 400e3, 4e-12, 60e3),  # one layer (Basilisk gives 0 below planetRadius - 1 m: no case there)
]


def rotation(theta_deg: float, tilt_deg: float) -> np.ndarray:
    """A planet-fixed frame's rotation from the inertial one (J20002Pfix: r_P = M r_N)."""
    t, a = math.radians(theta_deg), math.radians(tilt_deg)
    rz = np.array([[math.cos(t), math.sin(t), 0.0], [-math.sin(t), math.cos(t), 0.0], [0.0, 0.0, 1.0]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), math.sin(a)], [0.0, -math.sin(a), math.cos(a)]])
    return rx @ rz


def msis_case(case) -> dict:
    from Basilisk.architecture import messaging
    from Basilisk.simulation import msisAtmosphere
    from Basilisk.utilities import SimulationBaseClass

    utc, lat, lon, height, f107, f107a, ap, theta, tilt = case
    sim = SimulationBaseClass.SimBaseClass()
    sim.CreateNewProcess("p").addTask(sim.CreateNewTask("t", 1_000_000_000))
    atmosphere = msisAtmosphere.MsisAtmosphere()
    atmosphere.ModelTag = "msis"
    atmosphere.planetRadius = R_EARTH
    keep = []
    epoch = messaging.EpochMsgPayload()
    epoch.year, epoch.month, epoch.day, epoch.hours, epoch.minutes = utc[:5]
    epoch.seconds = float(utc[5])
    keep.append(messaging.EpochMsg().write(epoch))
    atmosphere.epochInMsg.subscribeTo(keep[-1])
    for k in range(23):  # 0: daily Ap, 1-20: 3-hour ap, 21: F10.7 81-day average, 22: F10.7 previous day
        payload = messaging.SwDataMsgPayload()
        payload.dataValue = f107a if k == 21 else f107 if k == 22 else ap
        keep.append(messaging.SwDataMsg().write(payload))
        atmosphere.swDataInMsgs[k].subscribeTo(keep[-1])
    M = rotation(theta, tilt)
    planet = messaging.SpicePlanetStateMsgPayload()
    planet.PositionVector = [0.0, 0.0, 0.0]
    planet.J20002Pfix = M.tolist()
    keep.append(messaging.SpicePlanetStateMsg().write(planet))
    atmosphere.planetPosInMsg.subscribeTo(keep[-1])
    phi, lam, radius = math.radians(lat), math.radians(lon), R_EARTH + height
    r_P = radius * np.array([math.cos(phi) * math.cos(lam), math.cos(phi) * math.sin(lam), math.sin(phi)])
    r_N = M.T @ r_P
    state = messaging.SCStatesMsgPayload()
    state.r_BN_N = r_N.tolist()
    keep.append(messaging.SCStatesMsg().write(state))
    atmosphere.addSpacecraftToModel(keep[-1])
    sim.AddModelToTask("t", atmosphere)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(0)
    sim.ExecuteSimulation()
    out = atmosphere.envOutMsgs[0].read()
    r_back = M @ r_N  # Basilisk's PCI2PCPF, then its spherical conversion
    lla = [
        math.degrees(math.atan2(r_back[2], math.hypot(r_back[0], r_back[1]))),
        math.degrees(math.atan2(r_back[1], r_back[0])),
        float(np.linalg.norm(r_back) - R_EARTH),
    ]
    return {
        "utc": list(utc),
        "latitude": lat,
        "longitude": lon,
        "height": height,
        "f107": f107,
        "f107a": f107a,
        "ap": ap,
        "J20002Pfix": M.tolist(),
        "r_BN_N": r_N.tolist(),
        "lla": lla,
        "density": out.neutralDensity,
        "temperature": out.localTemp,
    }


def exponential_case(case) -> dict:
    from Basilisk.architecture import messaging
    from Basilisk.simulation import exponentialAtmosphere
    from Basilisk.utilities import SimulationBaseClass

    altitude, h0, rho0, scale = case
    sim = SimulationBaseClass.SimBaseClass()
    sim.CreateNewProcess("p").addTask(sim.CreateNewTask("t", 1_000_000_000))
    atmosphere = exponentialAtmosphere.ExponentialAtmosphere()
    atmosphere.ModelTag = "exponential"
    atmosphere.planetRadius = R_EARTH + h0
    atmosphere.baseDensity = rho0
    atmosphere.scaleHeight = scale
    r = (R_EARTH + altitude) * np.array([0.48, -0.6, 0.64])  # a unit vector, off every axis
    state = messaging.SCStatesMsgPayload()
    state.r_BN_N = r.tolist()
    msg = messaging.SCStatesMsg().write(state)
    atmosphere.addSpacecraftToModel(msg)
    sim.AddModelToTask("t", atmosphere)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(0)
    sim.ExecuteSimulation()
    return {
        "r": r.tolist(),
        "h0": h0,
        "rho0": rho0,
        "scale_height": scale,
        "density": atmosphere.envOutMsgs[0].read().neutralDensity,
    }


def main() -> None:
    os.environ["TZ"] = "UTC"  # Basilisk's epoch goes through mktime (local time)
    time.tzset()
    from Basilisk import __version__

    print(
        json.dumps(
            {
                "basilisk": __version__,
                "R_EARTH": R_EARTH,
                "msis": [msis_case(c) for c in MSIS_CASES],
                "exponential": [exponential_case(c) for c in EXPONENTIAL_CASES],
            }
        )
    )


if __name__ == "__main__":
    main()
