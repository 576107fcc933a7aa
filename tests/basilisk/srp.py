"""Basilisk's eclipse factor, cannonball SRP force and facet SRP force and torque on shared cases.

Run in Basilisk's venv by ``python -m tests.basilisk srp``; prints one JSON document (the cases,
Basilisk's constants and its values). The Sun, the Earth and the Moon are constant messages (the
same positions on both sides: no ephemeris enters). Modules: ``eclipse`` (conical, the nearest
occulter), ``radiationPressure`` (cannonball), ``facetSRPDynamicEffector`` (static facets).
"""

import json

import numpy as np
from Basilisk.architecture import astroConstants, messaging
from Basilisk.simulation import eclipse, facetSRPDynamicEffector, radiationPressure, spacecraft
from Basilisk.utilities import RigidBodyKinematics as rbk
from Basilisk.utilities import SimulationBaseClass, macros

AU_M = astroConstants.AU * 1000.0
# Sun and Moon from the Earth's centre, m (no symmetry: no axis, no plane of the frame)
SUN = [1.0329e11, -9.712e10, -4.2103e10]
MOON = [-1.0771e8, -3.3437e8, 1.6613e8]


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def behind(centre, distance, offset, direction):
    """A point ``distance`` m behind ``centre`` on the anti-Sun side, ``offset`` m off the
    shadow's axis towards ``direction`` (made perpendicular)."""
    u = unit(np.asarray(SUN) - np.asarray(centre))
    w = np.asarray(direction, dtype=float)
    w = unit(w - (w @ u) * u)
    return (np.asarray(centre) - distance * u + offset * w).tolist()


R_E = astroConstants.REQ_EARTH * 1000.0
R_M = astroConstants.REQ_MOON * 1000.0
ECLIPSE_CASES = [
    ("full sun, LEO on the day side", [2.9e6, -4.1e6, 4.3e6]),
    ("Earth umbra", behind([0, 0, 0], 6.9e6, 1.7e6, [0.3, 1.0, -0.2])),
    ("Earth penumbra, outside the cylinder", behind([0, 0, 0], 7.1e6, R_E + 12.0e3, [1.0, -0.4, 0.6])),
    ("Earth penumbra, inside the cylinder", behind([0, 0, 0], 7.3e6, R_E - 17.0e3, [-0.5, 0.2, 1.0])),
    ("Earth penumbra, GEO", behind([0, 0, 0], 4.2e7, R_E + 1.3e5, [0.7, 0.1, -1.0])),
    ("Moon umbra", behind(MOON, 2.1e8, 3.1e5, [1.0, 0.3, 0.5])),
    ("Moon penumbra", behind(MOON, 1.7e8, R_M + 2.3e5, [-0.2, 1.0, 0.4])),
    ("near the Moon, day side", (np.asarray(MOON) + 3.0e6 * unit(np.asarray(SUN) - MOON) + [1e5, -2e5, 3e5]).tolist()),
    ("Moon antumbra (annular)", behind(MOON, 5.3e8, 1.1e5, [0.4, -1.0, 0.3])),
]

CANNONBALL_CASES = [  # position m, Cr, area m^2, illumination factor
    ([6.9e6, -1.2e6, 2.3e6], 1.3, 4.7, 1.0),
    ([-2.1e7, 3.4e7, -1.1e7], 1.8, 0.83, 0.37),
    ([1.4e8, -2.2e8, 9.0e7], 1.05, 27.5, 0.0),
]

FACETS = [  # area m^2, unit normal (body), centre of pressure from B m, specular, diffuse
    (1.2, unit([1.0, 0.1, -0.05]).tolist(), [0.61, 0.03, -0.02], 0.21, 0.43),
    (0.9, unit([-0.2, 1.0, 0.3]).tolist(), [0.05, 0.48, 0.11], 0.08, 0.66),
    (1.7, unit([0.3, -0.4, 1.0]).tolist(), [-0.1, 0.2, 0.73], 0.55, 0.2),
    (0.6, unit([-1.0, -0.3, 0.2]).tolist(), [-0.5, -0.1, 0.07], 0.0, 0.0),
    (4.4, unit([0.1, 0.2, -1.0]).tolist(), [2.3, -0.4, -0.6], 0.8, 0.1),
    (4.4, unit([-0.1, -0.2, 1.0]).tolist(), [2.3, -0.4, -0.5], 0.05, 0.35),
]
FACET_CASES = [  # position m, sigma_BN (MRP), illumination factor
    ([6.9e6, -1.2e6, 2.3e6], [0.1, -0.2, 0.3], 1.0),
    ([-4.2e6, 5.1e6, -1.7e6], [-0.35, 0.12, 0.05], 0.63),
    ([2.0e7, 1.1e7, -3.0e7], [0.4, 0.3, -0.45], 1.0),
    ([7.0e6, 2.0e5, -9.0e5], [-0.05, -0.6, 0.25], 1.0),
]


def sim():
    s = SimulationBaseClass.SimBaseClass()
    process = s.CreateNewProcess("process")
    process.addTask(s.CreateNewTask("task", macros.sec2nano(1.0)))
    return s


def planet_message(name, position):
    payload = messaging.SpicePlanetStateMsgPayload()
    payload.PositionVector = list(position)
    payload.PlanetName = name
    return messaging.SpicePlanetStateMsg().write(payload)


def eclipse_factors():
    s = sim()
    module = eclipse.Eclipse()
    module.ModelTag = "eclipse"
    messages = [planet_message("sun", SUN), planet_message("earth", [0.0, 0.0, 0.0]), planet_message("moon", MOON)]
    module.sunInMsg.subscribeTo(messages[0])
    module.addPlanetToModel(messages[1])
    module.addPlanetToModel(messages[2])
    states = []
    for _, r in ECLIPSE_CASES:
        payload = messaging.SCStatesMsgPayload()
        payload.r_BN_N = list(r)
        states.append(messaging.SCStatesMsg().write(payload))
        module.addSpacecraftToModel(states[-1])
    s.AddModelToTask("task", module)
    s.InitializeSimulation()
    s.ConfigureStopTime(0)
    s.ExecuteSimulation()
    return [module.eclipseOutMsgs[i].read().shadowFactor for i in range(len(ECLIPSE_CASES))]


def spacecraft_with(effector, r, sigma, factor, hold):
    s = sim()
    sc = spacecraft.Spacecraft()
    sc.ModelTag = "sc"
    sc.hub.r_CN_NInit = list(r)
    sc.hub.sigma_BNInit = list(sigma)
    sc.addDynamicEffector(effector)
    s.AddModelToTask("task", sc)
    sun = planet_message("sun", SUN)
    light = messaging.EclipseMsgPayload()
    light.illuminationFactor = factor
    light_msg = messaging.EclipseMsg().write(light)
    effector.sunEclipseInMsg.subscribeTo(light_msg)
    hold += [s, sc, sun, light_msg]
    return s, sun


def cannonball(r, cr, area, factor):
    effector = radiationPressure.RadiationPressure()
    effector.ModelTag = "srp"
    effector.setUseCannonballModel()
    effector.area = area
    effector.coefficientReflection = cr
    hold = []
    s, sun = spacecraft_with(effector, r, [0.0, 0.0, 0.0], factor, hold)
    effector.sunEphmInMsg.subscribeTo(sun)
    s.AddModelToTask("task", effector)
    s.InitializeSimulation()
    s.ConfigureStopTime(0)
    s.ExecuteSimulation()
    effector.computeForceTorque(0.0, 0.0)
    return np.ravel(effector.forceExternal_N).tolist()


def facets(r, sigma, factor):
    effector = facetSRPDynamicEffector.FacetSRPDynamicEffector()
    effector.ModelTag = "facets"
    effector.setNumFacets(len(FACETS))
    effector.setNumArticulatedFacets(0)
    for area, normal, centre, specular, diffuse in FACETS:
        effector.addFacet(area, np.eye(3), normal, [0.0, 0.0, 0.0], centre, diffuse, specular)
    hold = []
    s, sun = spacecraft_with(effector, r, sigma, factor, hold)
    effector.sunInMsg.subscribeTo(sun)
    s.AddModelToTask("task", effector)
    s.InitializeSimulation()
    s.ConfigureStopTime(0)
    s.ExecuteSimulation()
    effector.computeForceTorque(0.0, 0.0)
    return np.ravel(effector.forceExternal_B).tolist(), np.ravel(effector.torqueExternalPntB_B).tolist()


def main():
    out = {
        "constants": {
            "AU": AU_M,
            "SOLAR_FLUX_EARTH": astroConstants.SOLAR_FLUX_EARTH,
            "SPEED_LIGHT": float(astroConstants.SPEED_LIGHT),
            "REQ_SUN": astroConstants.REQ_SUN * 1000.0,
            "REQ_EARTH": R_E,
            "REQ_MOON": R_M,
            "facet_flux": 1368.0,
            "facet_AU": 149597870700.0,
        },  # facetSRPDynamicEffector.cpp's own
        "sun": SUN,
        "moon": MOON,
        "eclipse": [{"case": name, "r": r, "factor": f} for (name, r), f in zip(ECLIPSE_CASES, eclipse_factors())],
        "cannonball": [
            {"r": r, "cr": cr, "area": area, "factor": factor, "force_N": cannonball(r, cr, area, factor)}
            for r, cr, area, factor in CANNONBALL_CASES
        ],
        "facets": [{"area": a, "normal": n, "centre": c, "specular": sp, "diffuse": d} for a, n, c, sp, d in FACETS],
        "facet_cases": [],
    }
    for r, sigma, factor in FACET_CASES:
        force, torque = facets(r, sigma, factor)
        out["facet_cases"].append(
            {
                "r": r,
                "sigma_BN": sigma,
                "dcm_BN": rbk.MRP2C(sigma).tolist(),
                "factor": factor,
                "force_B": force,
                "torque_B": torque,
            }
        )
    print(json.dumps(out))


if __name__ == "__main__":
    main()
