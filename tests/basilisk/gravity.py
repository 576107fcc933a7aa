"""Basilisk's gravity: spherical harmonics, third bodies, and a one-day orbit under J2-J6 + Sun + Moon
+ drag + SRP.

Run in Basilisk's own environment by ``python -m tests.basilisk gravity`` (prints JSON, written to
gravity.json). Needs Basilisk and numpy only. What Basilisk is given, the same as Zenorbit:

- the field: ``components/space/data/GGM03S_20.txt`` (GGM03S to 20 x 20), read by Basilisk's
  ``SphericalHarmonicsGravityModel.loadFromFile``; J2 only and J2-J6 are that file's C20 (..C60)
  with every other coefficient zero;
- field cases: positions in ITRF (the planet-fixed frame), so no Earth rotation enters;
- third-body cases: the Sun's and the Moon's positions at the epoch as constants (Zenorbit's
  ERFA ephemeris), through Basilisk's ``PointMassGravityModel`` as its ``GravityEffector`` sums
  them (the body's pull at the spacecraft plus the pull on the central body);
- the trajectory: Basilisk's ``Spacecraft`` (hub mass ``mass``, attitude fixed at identity) with
  its RK4 integrator at a 10 s step; the Earth (central body) with the J2-J6 field and a constant
  C_itrf_gcrf (the project's at the epoch: zonal terms see only the pole); the Sun and the Moon as
  planet-state messages written every hour with the project's positions and velocities, which
  Basilisk's gravity extrapolates linearly from the time written (the test gives Zenorbit the very
  same inputs);
- drag: ``DragDynamicEffector`` (cannonball, Cd, A) with the density of ``exponentialAtmosphere``
  (one layer: ``planetRadius`` = R_E + h0, ``baseDensity`` = rho0, ``scaleHeight`` = H, so rho =
  rho0 exp(-(abs(r) - R_E - h0)/H), as Zenorbit's one-layer exponential; ``envMinReach`` lowered so
  points below h0 get it too) and the air turning with the Earth from ``zeroWindModel`` (omega =
  EARTH_RATE about the inertial z axis, as Zenorbit's drag);
- SRP: ``radiationPressure`` (cannonball, Cr, A) lit by ``eclipse`` (conical, the Earth and the
  Moon), its Sun and the eclipse's Sun and Moon written at every step's start with the hourly
  nodes' linear extrapolation.

Basilisk's environment modules run once per step: the density, the wind, the Sun for SRP and the
illumination factor are those at the step's start, held over its four RK4 stages; Zenorbit
evaluates them at every stage (tests/unit/test_space_gravity.py says what that costs in metres).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from Basilisk.architecture import astroConstants, messaging
from Basilisk.simulation import (
    dragDynamicEffector,
    eclipse,
    exponentialAtmosphere,
    gravityEffector,
    radiationPressure,
    spacecraft,
    zeroWindModel,
)
from Basilisk.utilities import SimulationBaseClass, macros

FIELD = str(Path(__file__).resolve().parents[2] / "components" / "space" / "data" / "GGM03S_20.txt")
MU_SUN = 1.32712440041279419e20  # JPL DE440, m^3/s^2 (components.space.gravity)
MU_MOON = 4.902800118457551e12

CASES = {
    "epoch": "2026-03-20T00:00:00Z",
    "points_itrf": [
        [6900000.0, -1200000.0, 2300000.0],
        [-4100000.0, 5300000.0, -3700000.0],
        [1200000.0, 800000.0, 6850000.0],
        [-2100000.0, -6200000.0, -1100000.0],
        [31000000.0, -27000000.0, 4300000.0],
    ],
    "points_eci": [
        [5100000.0, 2400000.0, 3700000.0],
        [-35000000.0, 23000000.0, 1200000.0],
        [15000000.0, -60000000.0, 20000000.0],
    ],
    "sun0": [148940183602.4005, -2322765476.932975, -1007536581.3446752],
    "moon0": [362548432.2155201, 59526624.84155544, 45826263.57843515],
    "trajectory": {
        "step": 10.0,
        "sample": 600.0,
        "degree": 6,
        "mass": 500.0,
        "drag": {
            "cd": 2.2,
            "area": 10.0,
            "altitude": 400000.0,
            "density": 3.725e-12,
            "scale_height": 58515.0,
            "earth_rate": 7.292115e-05,
            "r_earth": 6378137.0,
        },
        "srp": {"cr": 1.3, "area": 30.0, "eclipse": "conical"},
        "c_itrf_gcrf": [
            [-0.9988075304699542, 0.048754406151082334, 0.002554399609887295],
            [-0.04875415244975307, -0.9988107961603799, 0.00016153134143520915],
            [0.0025592372726897543, 3.680113223436532e-05, 0.9999967244697648],
        ],
        "r0": [-4082770.2157498575, 1334287.7954104755, -5233405.945994515],
        "v0": [-3505.6279492165468, -6755.307237668422, 1009.0360707917521],
        "nodes": [
            {
                "t": 0.0,
                "sun": [148940183602.4005, -2322765476.932975, -1007536581.3446752],
                "sun_velocity": [987.4088861828504, 27440.851323070947, 11896.163497715163],
                "moon": [362548432.2155201, 59526624.84155544, 45826263.57843515],
                "moon_velocity": [-244.52446052187656, 916.8318351503351, 484.730851430317],
            },
            {
                "t": 3600.0,
                "sun": [148943699297.24738, -2223977854.565343, -964710163.499235],
                "sun_velocity": [965.7549900897484, 27441.158527723546, 11896.289725013236],
                "moon": [361649665.07088137, 62824065.71369138, 47568885.02226744],
                "moon_velocity": [-254.78913889576737, 915.0688363488061, 483.3858638360039],
            },
            {
                "t": 7200.0,
                "sun": [148947137038.86768, -2125189154.0819716, -921883303.5039587],
                "sun_velocity": [944.1015425928877, 27441.45027646584, 11896.409136710112],
                "moon": [360713974.4758155, 66114986.18613446, 49306572.08112147],
                "moon_velocity": [-265.0373381029852, 913.2093841831028, 481.9895329060692],
            },
            {
                "t": 10800.0,
                "sun": [148950496828.9241, -2026399431.1177838, -879056025.8910785],
                "sun_velocity": [922.4485701768656, 27441.726570714833, 11896.521734077895],
                "moon": [359741422.00406986, 69399039.10860625, 51039140.050580956],
                "moon_velocity": [-275.26780853371497, 911.2535261733929, 480.54193289299013],
            },
            {
                "t": 14400.0,
                "sun": [148953778669.175, -1927608741.3138902, -836228355.1931053],
                "sun_velocity": [900.7960993393888, 27441.987412074704, 11896.627518489136],
                "moon": [358732073.7298942, 72675877.52912977, 52766404.50821892],
                "moon_velocity": [-285.4792995252868, 909.2013247982175, 479.04314614528937],
            },
            {
                "t": 18000.0,
                "sun": [148956982561.47284, -1828817140.2975802, -793400315.9340861],
                "sun_velocity": [879.1441565837076, 27442.232802338163, 11896.726491417347],
                "moon": [357686000.2314663, 75945154.74726559, 54488181.3424591],
                "moon_velocity": [-295.6705596445472, 907.0528575411776, 477.4932631214139],
            },
            {
                "t": 21600.0,
                "sun": [148960108507.76776, -1730024683.6775186, -750571932.6274525],
                "sun_velocity": [857.4927684142859, 27442.46274348607, 11896.818654436749],
                "moon": [356603276.5928862, 79206524.36921623, 56204286.78237247],
                "moon_velocity": [-305.84033697714773, 904.8082169307811, 475.8923823996951],
            },
            {
                "t": 25200.0,
                "sun": [148963156510.10287, -1631231427.0784192, -707743229.7909838],
                "sun_velocity": [835.8419613411742, 27442.677237688622, 11896.904009222697],
                "moon": [355483982.40583986, 82459640.36060338, 57914537.426029414],
                "moon_velocity": [-315.98737940996057, 902.4675105766438, 474.2406106870888],
            },
            {
                "t": 28800.0,
                "sun": [148966126570.61856, -1532437426.101204, -664914231.9294665],
                "sun_velocity": [814.1917618680212, 27442.87628730502, 11896.98255755144],
                "moon": [354328201.7692978, 85704157.10229275, 59618750.270695455],
                "moon_velocity": [-326.1104349240348, 900.0308611982324, 472.5380628228726],
            },
            {
                "t": 32400.0,
                "sun": [148969018691.54916, -1433642736.3378935, -622084963.5410808],
                "sun_velocity": [792.5421964920347, 27443.05989488429, 11897.054301300353],
                "moon": [353136023.28904206, 88939729.44375378, 61316742.741479956],
                "moon_velocity": [-336.2082518800968, 897.4984066497734, 470.7848617811115],
            },
            {
                "t": 36000.0,
                "sun": [148971832875.22583, -1334847413.3827949, -579255449.1221857],
                "sun_velocity": [770.8932917032006, 27443.228063165276, 11897.119242447865],
                "moon": [351907540.0755069, 92166012.75833935, 63008332.72095671],
                "moon_velocity": [-346.2795793106211, 894.8702999383329, 468.9811386692248],
            },
            {
                "t": 39600.0,
                "sun": [148974569124.07407, -1236051512.8121624, -536425713.1584312],
                "sun_velocity": [749.2450739765013, 27443.38079507718, 11897.177383073522],
                "moon": [350642849.74110574, 95382662.9971048, 64693338.5781544],
                "moon_velocity": [-356.32316720765635, 892.1467092376399, 467.1270327240478],
            },
            {
                "t": 43200.0,
                "sun": [148977227440.61456, -1137255090.1796398, -493595780.1227175],
                "sun_velocity": [727.5975697676497, 27443.518093738832, 11897.228725357585],
                "moon": [349342054.39585316, 98589336.74449983, 66371579.19831265],
                "moon_velocity": [-366.3377668167358, 889.3278178946945, 465.22269130422563],
            },
            {
                "t": 46800.0,
                "sun": [148979807827.4644, -1038458201.0507731, -450765674.4900898],
                "sun_velocity": [705.9508055173364, 27443.639962459685, 11897.27327158132],
                "moon": [348005260.64294267, 101785691.27142465, 68042874.01126781],
                "moon_velocity": [-376.32213092260804, 886.4138244332204, 463.2682698811575],
            },
            {
                "t": 50400.0,
                "sun": [148982310287.3342, -939660900.9592865, -407935420.71871805],
                "sun_velocity": [684.304807638362, 27443.74640473933, 11897.311024126635],
                "moon": [346632579.5719291, 104971384.591699, 69707043.02163886],
                "moon_velocity": [-386.2750141457442, 883.4049425485396, 461.2639320247924],
            },
            {
                "t": 54000.0,
                "sun": [148984734823.03043, -840863245.4415512, -365105043.26477313],
                "sun_velocity": [662.6596025198655, 27443.83742426754, 11897.341985475992],
                "moon": [345224126.7522332, 108146075.51522492, 71363906.83718443],
                "moon_velocity": [-396.1951732283007, 880.3014010997215, 459.20984938856634],
            },
            {
                "t": 57600.0,
                "sun": [148987081437.45505, -742065290.0087242, -322274566.57028544],
                "sun_velocity": [641.0152165180073, 27443.913024923913, 11897.366158212057],
                "moon": [343780022.22480315, 111309423.7028273, 73013286.6979839],
                "moon_velocity": [-406.0813673253289, 877.1034440949716, 457.10620169053107],
            },
            {
                "t": 61200.0,
                "sun": [148989350133.60382, -643267090.1613845, -279444015.06942374],
                "sun_velocity": [619.3716759557564, 27443.97321077798, 11897.383545017627],
                "moon": [342300390.49258024, 114461089.72166033, 74655004.50596502],
                "moon_velocity": [-415.93235829717383, 873.8113306704405, 454.9531766907369],
            },
            {
                "t": 64800.0,
                "sun": [148991540914.56815, -544468701.381378, -236613413.18489778],
                "sun_velocity": [597.7290071179415, 27444.017986088907, 11897.394148675332],
                "moon": [340785360.51062894, 117600735.09861921, 76288882.85322067],
                "moon_velocity": [-425.7469109955448, 870.4253350657493, 452.7509701674081],
            },
            {
                "t": 68400.0,
                "sun": [148993653783.53268, -445670179.1503804, -193782785.3359409],
                "sun_velocity": [576.08723625194, 27444.047355304763, 11897.397972067132],
                "moon": [339235065.6747246, 120728022.3750041, 77914745.05106169],
                "moon_velocity": [-435.52379355276554, 866.9457465925611, 450.4997858889893],
            },
            {
                "t": 72000.0,
                "sun": [148995688743.77795, -346871578.91035205, -150952155.9211058],
                "sun_velocity": [554.4463895558081, 27444.0613230628, 11897.395018174288],
                "moon": [337649643.809201, 123842615.16031833, 79532415.15849063],
                "moon_velocity": [-445.26177766784906, 863.3728695986028, 448.19983558410235],
            },
            {
                "t": 75600.0,
                "sun": [148997645798.67816, -248072956.0978904, -108121549.3330934],
                "sun_velocity": [532.8064931825123, 27444.059894188427, 11897.385290076723],
                "moon": [336029237.15288174, 126944178.18781467, 81141718.01157905],
                "moon_velocity": [-454.95963889734355, 859.7070234239063, 445.85133890706106],
            },
            {
                "t": 79200.0,
                "sun": [148999524951.70074, -149274366.1358418, -65290989.95505632],
                "sun_velocity": [511.1675732348611, 27444.043073694873, 11897.368790952698],
                "moon": [334373992.34591883, 130032377.36586422, 82742479.2506381],
                "moon_velocity": [-464.616156932203, 855.9485423566625, 443.4545234037288],
            },
            {
                "t": 82800.0,
                "sun": [149001326206.40845, -50475864.43252815, -22460502.160201956],
                "sun_velocity": [489.5296557620615, 27444.01086678289, 11897.345524078504],
                "moon": [332684060.4131205, 133106879.83421089, 84334525.34984368],
                "moon_velocity": [-474.2301158892033, 852.0977755774841, 441.00962447070333],
            },
            {
                "t": 86400.0,
                "sun": [149003049566.45654, 48322493.646235324, 20369889.70039659],
                "sun_velocity": [467.89276675042834, 27443.963278839572, 11897.315492827722],
                "moon": [330959596.74829924, 136167354.0159576, 85917683.64468269],
                "moon_velocity": [-483.8003045879186, 848.1550871034187, 438.516885314707],
            },
        ],
    },
}


def harmonics(degree: int, zonal: bool):
    model = gravityEffector.SphericalHarmonicsGravityModel()
    model.loadFromFile(FIELD, degree)
    if zonal:
        c = [[float(row[0])] + [0.0] * (len(row) - 1) for row in model.cBar]
        model.cBar = c
        model.sBar = [[0.0] * len(row) for row in model.sBar]
    model.initializeParameters()
    return model


def field_cases():
    out = []
    for name, degree, zonal in (("j2", 2, True), ("zonal6", 6, True), ("degree20", 20, False)):
        model = harmonics(degree, zonal)
        for r in CASES["points_itrf"]:
            out.append(
                {
                    "field": name,
                    "degree": degree,
                    "order": 0 if zonal else degree,
                    "r_itrf": r,
                    "g": [x[0] for x in model.computeField(r)],
                    "perturbation": [x[0] for x in model.computeField(r, degree, False)],
                }
            )
    return out


def third_body_cases():
    out = []
    for body, mu, s in (("sun", MU_SUN, CASES["sun0"]), ("moon", MU_MOON, CASES["moon0"])):
        model = gravityEffector.PointMassGravityModel()
        model.muBody = mu
        model.initializeParameters()
        for r in CASES["points_eci"]:
            rel = (np.array(r) - np.array(s)).tolist()
            a = np.array([x[0] for x in model.computeField(rel)]) + np.array([x[0] for x in model.computeField(s)])
            out.append({"body": body, "mu": mu, "r_eci": r, "s_eci": s, "a": a.tolist()})
    return out


def planet_state(name, position, velocity, dcm=None):
    payload = messaging.SpicePlanetStateMsgPayload()
    payload.PlanetName = name
    payload.PositionVector = position
    payload.VelocityVector = velocity
    payload.J20002Pfix = dcm if dcm is not None else np.eye(3).tolist()
    payload.J20002Pfix_dot = np.zeros((3, 3)).tolist()
    return payload


def extrapolated(nodes, t):
    """The Sun and the Moon at t (s) from the last node at or before t, as Basilisk's gravity takes them."""
    node = max((n for n in nodes if n["t"] <= t), key=lambda n: n["t"])
    return {
        body: (np.array(node[body]) + (t - node["t"]) * np.array(node[body + "_velocity"])).tolist()
        for body in ("sun", "moon")
    }


def trajectory():
    case = CASES["trajectory"]
    step = case["step"]
    sim = SimulationBaseClass.SimBaseClass()
    process = sim.CreateNewProcess("p")
    process.addTask(sim.CreateNewTask("t", macros.sec2nano(step)))
    sc = spacecraft.Spacecraft()
    sc.ModelTag = "sc"
    sc.hub.mHub = case["mass"]
    sim.AddModelToTask("t", sc, None, 0)  # last: the environment and the effectors read first

    earth = gravityEffector.GravBodyData()
    earth.planetName = "earth"
    earth.isCentralBody = True
    earth.gravityModel = harmonics(case["degree"], True)
    earth.mu = earth.gravityModel.muBody
    earth.radEquator = earth.gravityModel.radEquator
    bodies = {"earth": earth}
    for body, mu in (("sun", MU_SUN), ("moon", MU_MOON)):
        b = gravityEffector.GravBodyData()
        b.planetName = body
        b.mu = mu
        point = gravityEffector.PointMassGravityModel()
        point.muBody = mu
        b.gravityModel = point
        bodies[body] = b
    messages = {}
    earth_msg = messaging.SpicePlanetStateMsg().write(planet_state("earth", [0.0] * 3, [0.0] * 3, case["c_itrf_gcrf"]))
    earth.planetBodyInMsg.subscribeTo(earth_msg)
    for body in ("sun", "moon"):
        messages[body] = messaging.SpicePlanetStateMsg()
        bodies[body].planetBodyInMsg.subscribeTo(messages[body])
    sc.gravField.gravBodies = spacecraft.GravBodyVector(list(bodies.values()))
    sc.hub.r_CN_NInit = case["r0"]
    sc.hub.v_CN_NInit = case["v0"]

    d = case["drag"]
    atmosphere = exponentialAtmosphere.ExponentialAtmosphere()
    atmosphere.ModelTag = "atmosphere"
    atmosphere.planetRadius = d["r_earth"] + d["altitude"]
    atmosphere.baseDensity = d["density"]
    atmosphere.scaleHeight = d["scale_height"]
    atmosphere.envMinReach = -1e7  # below h0 too (its default, -1 m, gives 0 there)
    atmosphere.addSpacecraftToModel(sc.scStateOutMsg)
    wind = zeroWindModel.ZeroWindModel()
    wind.ModelTag = "wind"
    wind.setPlanetOmega_N([0.0, 0.0, d["earth_rate"]])
    wind.planetPosInMsg.subscribeTo(earth_msg)
    wind.addSpacecraftToModel(sc.scStateOutMsg)
    drag = dragDynamicEffector.DragDynamicEffector()
    drag.ModelTag = "drag"
    drag.coreParams.dragCoeff = d["cd"]
    drag.coreParams.projectedArea = d["area"]
    drag.atmoDensInMsg.subscribeTo(atmosphere.envOutMsgs[0])
    drag.windVelInMsg.subscribeTo(wind.envOutMsgs[0])
    sc.addDynamicEffector(drag)

    light = {"sun": messaging.SpicePlanetStateMsg(), "moon": messaging.SpicePlanetStateMsg()}
    shadow = eclipse.Eclipse()
    shadow.ModelTag = "eclipse"
    shadow.sunInMsg.subscribeTo(light["sun"])
    shadow.addPlanetToModel(earth_msg)
    shadow.addPlanetToModel(light["moon"])
    shadow.addSpacecraftToModel(sc.scStateOutMsg)
    srp = radiationPressure.RadiationPressure()
    srp.ModelTag = "srp"
    srp.setUseCannonballModel()
    srp.area = case["srp"]["area"]
    srp.coefficientReflection = case["srp"]["cr"]
    srp.sunEphmInMsg.subscribeTo(light["sun"])
    srp.sunEclipseInMsg.subscribeTo(shadow.eclipseOutMsgs[0])
    sc.addDynamicEffector(srp)
    for priority, model in ((40, atmosphere), (40, wind), (40, shadow), (20, drag), (20, srp)):
        sim.AddModelToTask("t", model, None, priority)

    recorder = sc.scStateOutMsg.recorder(macros.sec2nano(case["sample"]))
    sim.AddModelToTask("t", recorder)
    density = atmosphere.envOutMsgs[0].recorder(macros.sec2nano(case["sample"]))
    sim.AddModelToTask("t", density)
    sunlit = shadow.eclipseOutMsgs[0].recorder(macros.sec2nano(step))
    sim.AddModelToTask("t", sunlit)

    def write_nodes(node):
        when = macros.sec2nano(node["t"])
        for body in ("sun", "moon"):
            messages[body].write(planet_state(body, node[body], node[body + "_velocity"]), when)

    def write_light(t):
        """The Sun and the Moon for the step from t (what the call at t + step integrates over)."""
        for body, position in extrapolated(case["nodes"], t).items():
            light[body].write(planet_state(body, position, [0.0] * 3), macros.sec2nano(t))

    nodes = {n["t"]: n for n in case["nodes"]}
    write_nodes(case["nodes"][0])
    write_light(0.0)
    sim.InitializeSimulation()
    end, k = case["nodes"][-1]["t"], 0
    while k * step < end:
        k += 1
        sim.ConfigureStopTime(macros.sec2nano(k * step))
        sim.ExecuteSimulation()
        if k * step in nodes:
            write_nodes(nodes[k * step])
        write_light(k * step)
    factors = np.asarray(sunlit.shadowFactor)
    return {
        "t": (recorder.times() * 1e-9).tolist(),
        "r_eci": recorder.r_BN_N.tolist(),
        "v_eci": recorder.v_BN_N.tolist(),
        "density": np.asarray(density.neutralDensity).tolist(),
        "steps_in_shadow": int(np.sum(factors < 1.0)),
        "steps_in_penumbra": int(np.sum((factors > 0) & (factors < 1))),
    }


def constants():
    """Basilisk's radii, solar flux and AU (m, W/m^2) that its eclipse and radiationPressure use."""
    return {
        "REQ_SUN": astroConstants.REQ_SUN * 1e3,
        "REQ_EARTH": astroConstants.REQ_EARTH * 1e3,
        "REQ_MOON": astroConstants.REQ_MOON * 1e3,
        "SOLAR_FLUX_EARTH": astroConstants.SOLAR_FLUX_EARTH,
        "AU": astroConstants.AU * 1e3,
    }


if __name__ == "__main__":
    print(
        json.dumps(
            {
                "cases": CASES,
                "constants": constants(),
                "fields": field_cases(),
                "third_body": third_body_cases(),
                "trajectory": trajectory(),
            }
        )
    )
