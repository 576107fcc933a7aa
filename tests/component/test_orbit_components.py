"""Orbit components through the in-process harness: wrappers map parameters and outputs
correctly, outputs are consistent (w_lvlh vs q_eci_lvlh), state round-trips, bad config is a
ConfigError naming the key."""

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from components import timescales
from components.errors import ConfigError
from components.orbit.kepler import KeplerOrbit
from components.testing.harness import Harness

EPOCH = "2022-09-18T12:00:00Z"
S = 10**9  # ns per s
ISS_TLE = [
    "1 25544U 98067A   22261.04293564  .00008098  00000-0  14900-3 0  9998",
    "2 25544  51.6433 236.5547 0002449 262.4353 208.9254 15.50138447359588",
]
KEPLER = {
    "semi_major_axis": "6778 km",
    "eccentricity": 0.0004,
    "inclination": "51.64 deg",
    "raan": "236.55 deg",
    "arg_perigee": "262.44 deg",
    "mean_anomaly": "10 deg",
    "j2": True,
}
CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def _circular_waypoints(times_s, a=6778e3, inc=51.64):
    orbit = KeplerOrbit(a, 0.0, math.radians(inc), 0.0, 0.0, 0.0)
    points = []
    for t in times_s:
        r, v, acc = orbit.state(t)
        points.append({"time": t, "position": r.tolist(), "velocity": v.tolist(), "acceleration": acc.tolist()})
    return orbit, points


def _run(h, n, step_ns):
    outs = [h.initialize()]
    outs += [h.step(step_ns) for _ in range(n)]
    return outs


def _check_rate_against_quaternions(outs, step_s, tol, skip=()):
    """w_lvlh at sample k vs the central difference of q_eci_lvlh at k-1, k+1 (scipy rotations)."""
    worst = 0.0
    for k in range(1, len(outs) - 1):
        if k in skip:
            continue
        qm, qp = Rotation.from_quat(outs[k - 1]["q_eci_lvlh"]), Rotation.from_quat(outs[k + 1]["q_eci_lvlh"])
        w_fd = (qp * qm.inv()).as_rotvec() / (2 * step_s)
        worst = max(worst, np.linalg.norm(w_fd - outs[k]["w_lvlh"]))
    assert worst < tol, worst
    return worst


# ---- orbit.kepler ----


def test_kepler_outputs_are_the_model_state():
    h = Harness("orbit.kepler", KEPLER, epoch=EPOCH)
    orbit = KeplerOrbit(
        6778e3, 0.0004, math.radians(51.64), math.radians(236.55), math.radians(262.44), math.radians(10), j2=True
    )
    for k, out in enumerate(_run(h, 3, 600 * S)):
        r, v, _ = orbit.state(600.0 * k)
        np.testing.assert_allclose(out["r_eci"], r, rtol=0, atol=1e-6)
        np.testing.assert_allclose(out["v_eci"], v, rtol=0, atol=1e-9)
        c = Rotation.from_quat(out["q_eci_lvlh"]).as_matrix()
        np.testing.assert_allclose(c[:, 0], r / np.linalg.norm(r), atol=1e-14)
        np.testing.assert_allclose(c[:, 2], np.cross(r, v) / np.linalg.norm(np.cross(r, v)), atol=1e-14)


def test_kepler_w_lvlh_matches_quaternion_finite_difference_over_an_orbit():
    # 1 s steps over 95 min; central difference error ~ w^3 h^2 / 6 ~ 2e-10 rad/s: tolerance 1e-9 rad/s
    h = Harness("orbit.kepler", KEPLER, epoch=EPOCH)
    outs = _run(h, 95 * 60, S)
    _check_rate_against_quaternions(outs, 1.0, 1e-9)
    # quaternion sign continuous from step to step (no q -> -q jumps)
    q = np.array([o["q_eci_lvlh"] for o in outs])
    assert np.min(np.sum(q[1:] * q[:-1], axis=1)) > 0.99


def test_kepler_time_of_perigee():
    # perigee 30 min after the epoch: |r| is a(1 - e) there and the radial velocity is zero
    params = {**KEPLER, "eccentricity": 0.1, "semi_major_axis": "8000 km", "j2": False}
    del params["mean_anomaly"]
    params["time_of_perigee"] = "2022-09-18T12:30:00Z"
    h = Harness("orbit.kepler", params, epoch=EPOCH)
    h.initialize()
    out = h.step(1800 * S)
    r, v = out["r_eci"], out["v_eci"]
    assert np.linalg.norm(r) == pytest.approx(8000e3 * 0.9, abs=1e-3)
    assert abs(r @ v) / np.linalg.norm(r) < 1e-6


def test_kepler_time_of_perigee_as_yaml_timestamp():
    # unquoted in YAML, a time arrives as a datetime; it means the same as the string
    import datetime as dt

    import yaml

    raw = yaml.safe_load("time_of_perigee: 2022-09-18T12:30:00Z")["time_of_perigee"]
    assert isinstance(raw, dt.datetime)
    params = {k: v for k, v in KEPLER.items() if k != "mean_anomaly"}
    a = Harness("orbit.kepler", {**params, "time_of_perigee": raw}, epoch=EPOCH).initialize()
    b = Harness("orbit.kepler", {**params, "time_of_perigee": "2022-09-18T12:30:00Z"}, epoch=EPOCH).initialize()
    np.testing.assert_array_equal(a["r_eci"], b["r_eci"])


@pytest.mark.parametrize(
    "change,key",
    [
        ({"eccentricity": 1.0}, "eccentricity"),
        ({"eccentricity": 1.3}, "eccentricity"),
        ({"semi_major_axis": "-6778 km"}, "semi_major_axis"),
        ({"semi_major_axis": 6778}, "semi_major_axis"),  # metres: inside the Earth
        ({"inclination": "181 deg"}, "inclination"),
        ({"inclination": -0.1}, "inclination"),
        ({"mean_anomaly": None}, "mean_anomaly"),  # neither anomaly nor time
        ({"time_of_perigee": "2022-09-18T11:00:00Z"}, "time_of_perigee"),  # both
        ({"mean_anomaly": None, "time_of_perigee": "yesterday"}, "time_of_perigee"),
        ({"semi_major_axis": "6778 parsec"}, "semi_major_axis"),
    ],
)
def test_kepler_bad_config_names_the_key(change, key):
    params = {**KEPLER, **change}
    params = {k: v for k, v in params.items() if v is not None}
    with pytest.raises(ConfigError) as info:
        Harness("orbit.kepler", params, epoch=EPOCH)
    assert info.value.key == key, str(info.value)


def test_kepler_missing_element_is_named():
    params = dict(KEPLER)
    del params["raan"]
    with pytest.raises(ConfigError) as info:
        Harness("orbit.kepler", params, epoch=EPOCH)
    assert info.value.key == "raan"


# ---- state ----


@pytest.mark.parametrize(
    "type_name,params",
    [
        ("orbit.kepler", KEPLER),
        ("orbit.sgp4", {"tle": ISS_TLE}),
    ],
)
def test_state_round_trip_gives_identical_outputs(type_name, params):
    a = Harness(type_name, params, epoch=EPOCH)
    _run(a, 40, 60 * S)  # 40 min: the quaternion has turned ~150°
    blob = a.get_state()
    b = Harness(type_name, params, epoch=EPOCH, t0_ns=a.t_ns)
    b.set_state(blob)  # never initialized: a restore, as the orchestrator's swap or restart
    for _ in range(30):
        oa, ob = a.step(60 * S), b.step(60 * S)
        for name in oa:
            np.testing.assert_array_equal(oa[name], ob[name])


# ---- orbit.sgp4 ----


def test_sgp4_outputs_are_sgp4_rotated_to_gcrf():
    # Reference: the sgp4 package called directly at the UTC Julian date of epoch + t, then our
    # TEME->GCRF rotation (verified separately in the unit tests); tolerance 1 mm, 1 µm/s.
    from sgp4.api import Satrec

    from components.orbit.tle import teme_to_gcrf_matrix

    sat = Satrec.twoline2rv(*ISS_TLE)
    epoch = timescales.parse_utc(EPOCH)
    h = Harness("orbit.sgp4", {"tle": ISS_TLE}, epoch=EPOCH)
    for k, out in enumerate(_run(h, 3, 1000 * S)):
        utc = (epoch[0], epoch[1] + 1000.0 * k / 86400.0)  # no leap second in this window
        err, r, v = sat.sgp4(*utc)
        assert err == 0
        c = teme_to_gcrf_matrix(timescales.utc_to_tt(utc), utc)
        np.testing.assert_allclose(out["r_eci"], c @ np.array(r) * 1e3, rtol=0, atol=1e-3)
        np.testing.assert_allclose(out["v_eci"], c @ np.array(v) * 1e3, rtol=0, atol=1e-6)


def test_sgp4_w_lvlh_matches_quaternion_finite_difference():
    # the frame's own rate; 1 s steps over 20 min, tolerance 1e-9 rad/s (as for Kepler)
    h = Harness("orbit.sgp4", {"tle": ISS_TLE}, epoch=EPOCH)
    outs = _run(h, 1200, S)
    _check_rate_against_quaternions(outs, 1.0, 1e-9)
    # J2 and drag: the out-of-plane rate component is present (~1e-6 rad/s at most)
    x_rates = [o["w_lvlh"] @ Rotation.from_quat(o["q_eci_lvlh"]).apply([1, 0, 0]) for o in outs]
    assert 1e-7 < max(map(abs, x_rates)) < 1e-5


def test_sgp4_tle_file_relative_to_config_dir(tmp_path):
    (tmp_path / "tles").mkdir()
    (tmp_path / "tles" / "iss.txt").write_text("ISS (ZARYA)\n" + "\n".join(ISS_TLE) + "\n")
    a = Harness("orbit.sgp4", {"tle_file": "tles/iss.txt"}, epoch=EPOCH, config_dir=tmp_path)
    b = Harness("orbit.sgp4", {"tle": ISS_TLE}, epoch=EPOCH)
    np.testing.assert_array_equal(a.initialize()["r_eci"], b.initialize()["r_eci"])


@pytest.mark.parametrize(
    "params,key,match",
    [
        ({}, "tle", "got neither"),
        ({"tle": ISS_TLE, "tle_file": "x.tle"}, "tle", "got both"),
        ({"tle": ISS_TLE[:1]}, "tle", "expected list of 2 str, got 1"),
        ({"tle": [ISS_TLE[0][:68] + "1", ISS_TLE[1]]}, "tle", "line 1, column 69: checksum: expected 8"),
        ({"tle": [ISS_TLE[0], ISS_TLE[1][:26] + "x" + ISS_TLE[1][27:]]}, "tle", "line 2, columns 27-33: eccentricity"),
        ({"tle_file": "missing.tle"}, "tle_file", "cannot read"),
    ],
)
def test_sgp4_bad_config_names_the_key(params, key, match):
    with pytest.raises(ConfigError, match=match) as info:
        Harness("orbit.sgp4", params, epoch=EPOCH)
    assert info.value.key == key


DECAYING = [
    "1 28872U 05037B   05333.02012661  .25992681  00000-0  24476-3 0  1534",
    "2 28872  96.4736 157.9986 0303955 244.0492 110.6523 16.46015938 10708",
]  # SGP4-VER: decays at ~55 min


def test_sgp4_decay_during_the_run_is_a_runtime_error_with_sgp4_text():
    h = Harness("orbit.sgp4", {"tle": DECAYING}, epoch="2005-11-29T00:29:00Z")  # TLE epoch + ~0 min
    h.initialize()
    with pytest.raises(
        RuntimeError, match=r"SGP4 error 6 .*mrt is less than 1\.0 which indicates the satellite has decayed"
    ):
        for _ in range(120):
            h.step(60 * S)


def test_sgp4_decayed_at_epoch_is_a_config_error():
    with pytest.raises(ConfigError, match=r"cannot propagate to run\.epoch .*decayed") as info:
        Harness("orbit.sgp4", {"tle": DECAYING}, epoch="2005-11-29T03:00:00Z")
    assert info.value.key == "tle"


# ---- orbit.custom_path ----


def test_custom_path_passes_through_waypoints_and_matches_orbit_nearby():
    times = [0.0, 300.0, 600.0, 900.0]
    orbit, points = _circular_waypoints(times)
    h = Harness("orbit.custom_path", {"waypoints": points, "after_end": "error"}, epoch=EPOCH)
    outs = _run(h, 900, S)
    for t in times:
        out, (r, v, _) = outs[int(t)], orbit.state(t)
        np.testing.assert_allclose(out["r_eci"], r, rtol=0, atol=1e-6)
        np.testing.assert_allclose(out["v_eci"], v, rtol=0, atol=1e-9)
    # between waypoints 5 min apart the spline is within 1 m of the circular orbit it samples
    assert max(np.linalg.norm(outs[k]["r_eci"] - orbit.state(k)[0]) for k in range(0, 901, 10)) < 1.0
    _check_rate_against_quaternions(outs, 1.0, 1e-9)


def test_custom_path_out_of_plane_rate_from_spline_acceleration():
    # an out-of-plane acceleration bends the orbit plane: w_lvlh gets an x component, and it
    # still matches the quaternions' finite difference (tolerance 1e-9 rad/s; measured 3e-10).
    # The joint at 200 s is skipped: the spline is C2, so the jerk, hence dw/dt, jumps there and
    # a central difference straddling it is off by O(h * jump) ~ 1e-7 rad/s.
    _, points = _circular_waypoints([0.0, 200.0, 400.0])
    for p in points:
        r, v = np.array(p["position"]), np.array(p["velocity"])
        z = np.cross(r, v) / np.linalg.norm(np.cross(r, v))
        p["acceleration"] = (np.array(p["acceleration"]) + 0.05 * z).tolist()
    h = Harness("orbit.custom_path", {"waypoints": points, "after_end": "error"}, epoch=EPOCH)
    outs = _run(h, 400, S)
    _check_rate_against_quaternions(outs, 1.0, 1e-9, skip=(200,))
    x_rate = outs[200]["w_lvlh"] @ Rotation.from_quat(outs[200]["q_eci_lvlh"]).apply([1, 0, 0])
    assert x_rate > 1e-6


def test_custom_path_hold_and_error_after_end():
    _, points = _circular_waypoints([0.0, 60.0, 120.0])
    held = Harness("orbit.custom_path", {"waypoints": points, "after_end": "hold"}, epoch=EPOCH)
    outs = _run(held, 5, 30 * S)  # up to 150 s
    for name in outs[4]:
        np.testing.assert_array_equal(outs[5][name], outs[4][name])  # 150 s holds the 120 s values
    np.testing.assert_allclose(outs[4]["r_eci"], points[2]["position"], atol=1e-6)
    strict = Harness("orbit.custom_path", {"waypoints": points, "after_end": "error"}, epoch=EPOCH)
    _run(strict, 4, 30 * S)  # exactly at the last waypoint: fine
    with pytest.raises(RuntimeError, match="past the last waypoint"):
        strict.step(30 * S)


def test_custom_path_accepts_units():
    points = [
        {"time": "0 s", "position": ["6778 km", 0, 0], "velocity": [0, "7.669 km/s", 0], "acceleration": [-8.68, 0, 0]},
        {
            "time": "1 min",
            "position": ["6775 km", "460 km", 0],
            "velocity": ["-0.52 km/s", "7.65 km/s", 0],
            "acceleration": [-8.66, -0.59, 0],
        },
    ]
    h = Harness("orbit.custom_path", {"waypoints": points, "after_end": "hold"}, epoch=EPOCH)
    np.testing.assert_array_equal(h.initialize()["r_eci"], [6778e3, 0, 0])


def _points(times):
    return [
        {"time": t, "position": [7e6, 0, 0], "velocity": [0, 7.5e3, 0], "acceleration": [-8.1, 0, 0]} for t in times
    ]


@pytest.mark.parametrize(
    "params,key,match",
    [
        ({"waypoints": _points([0.0])}, "waypoints", "at least 2 items, got 1"),
        (
            {"waypoints": _points([0.0, 20.0, 10.0])},
            "waypoints[2].time",
            "strictly increasing, got 10.0 s after 20.0 s",
        ),
        ({"waypoints": _points([0.0, 10.0, 10.0])}, "waypoints[2].time", "strictly increasing"),
        ({"waypoints": _points([5.0, 10.0])}, "waypoints[0].time", "expected <= 0 s"),
        ({"waypoints": "nope"}, "waypoints", "expected a list"),
        (
            {"waypoints": [{"time": 0, "position": [7e6, 0, 0], "velocity": [0, 7.5e3, 0]}] + _points([10.0])},
            "waypoints[0].acceleration",
            "missing required key",
        ),
        (
            {"waypoints": [{**_points([0.0])[0], "velocity": [1, 2]}] + _points([10.0])},
            "waypoints[0].velocity",
            "expected 3 values",
        ),
        (
            {"waypoints": [{**_points([0.0])[0], "jerk": [0, 0, 0]}] + _points([10.0])},
            "waypoints[0].jerk",
            "unknown key",
        ),
        ({"waypoints": [{**_points([0.0])[0], "time": "3 parsec"}] + _points([10.0])}, "waypoints[0].time", "unit"),
        (
            {"waypoints": [{**_points([0.0])[0], "velocity": [1e3, 0, 0]}] + _points([10.0])},
            "waypoints[0].velocity",
            "not parallel",
        ),
    ],
)
def test_custom_path_bad_config_names_the_key(params, key, match):
    params = {"after_end": "hold", **params}
    with pytest.raises(ConfigError, match=match) as info:
        Harness("orbit.custom_path", params, epoch=EPOCH)
    assert info.value.key == key


def test_custom_path_after_end_is_required_and_checked():
    with pytest.raises(ConfigError) as info:
        Harness("orbit.custom_path", {"waypoints": _points([0.0, 10.0])}, epoch=EPOCH)
    assert info.value.key == "after_end"
    with pytest.raises(ConfigError, match="hold, error") as info:
        Harness("orbit.custom_path", {"waypoints": _points([0.0, 10.0]), "after_end": "wrap"}, epoch=EPOCH)
    assert info.value.key == "after_end"


# ---- orbit.fixed ----


def test_fixed_is_constant():
    q = [0.0, 0.0, math.sin(0.3), math.cos(0.3)]
    h = Harness("orbit.fixed", {"r_eci": ["7000 km", 0, 0], "q_eci_lvlh": q}, epoch=EPOCH)
    for out in _run(h, 3, 10 * S):
        np.testing.assert_array_equal(out["r_eci"], [7e6, 0, 0])
        np.testing.assert_allclose(out["q_eci_lvlh"], q, atol=1e-15)
        np.testing.assert_array_equal(out["v_eci"], np.zeros(3))
        np.testing.assert_array_equal(out["w_lvlh"], np.zeros(3))
    default = Harness("orbit.fixed", {"r_eci": [7e6, 0, 0]}, epoch=EPOCH)
    np.testing.assert_array_equal(default.initialize()["q_eci_lvlh"], [0, 0, 0, 1])


@pytest.mark.parametrize(
    "params,key",
    [
        ({"r_eci": [7e6, 0, 0], "q_eci_lvlh": [0, 0, 0, 2]}, "q_eci_lvlh"),
        ({"r_eci": [7e6, 0, 0], "q_eci_lvlh": [0, 0, 1]}, "q_eci_lvlh"),
        ({"r_eci": [7e6, 0]}, "r_eci"),
        ({}, "r_eci"),
    ],
)
def test_fixed_bad_config_names_the_key(params, key):
    with pytest.raises(ConfigError) as info:
        Harness("orbit.fixed", params, epoch=EPOCH)
    assert info.value.key == key


# ---- shipped configs ----


def _shipped_orbit_at(name: str, t: float):
    """(r, v) in ECI at t s after run.epoch of the orbit a shipped config describes, computed
    without the component: the file's elements in SI (kepler), the sgp4 package rotated to GCRF
    (sgp4), the circular orbit the waypoints sample (custom_path, within mm of it near a waypoint)."""
    if name == "orbit_iss_kepler.yaml":
        orbit = KeplerOrbit(
            6778e3, 0.0004, math.radians(51.64), math.radians(236.55), math.radians(262.44), 0.0, j2=True
        )
        return orbit.state(t)[:2]
    if name == "orbit_iss_sgp4.yaml":
        from sgp4.api import Satrec

        from components.orbit.tle import teme_to_gcrf_matrix

        epoch = timescales.parse_utc(EPOCH)
        utc = (epoch[0], epoch[1] + t / 86400.0)
        err, r, v = Satrec.twoline2rv(*ISS_TLE).sgp4(*utc)
        assert err == 0
        c = teme_to_gcrf_matrix(timescales.utc_to_tt(utc), utc)
        return c @ np.array(r) * 1e3, c @ np.array(v) * 1e3
    return _circular_waypoints([t])[0].state(t)[:2]


@pytest.mark.parametrize(
    "name, r_tol, v_tol",
    [("orbit_iss_kepler.yaml", 1e-6, 1e-9), ("orbit_iss_sgp4.yaml", 1e-3, 1e-6), ("custom_path.yaml", 1e-3, 1e-4)],
)
def test_shipped_configs_validate_and_start(name, r_tol, v_tol):
    """Each shipped orbit config, loaded as a run loads it, gives after its first 1 s step the
    orbit its file describes: r and v as vectors, the LVLH frame of that r and v (x radial, z
    along r x v) and its rate (the in-plane h / r^2 about z, plus J2's out-of-plane ~1e-6 rad/s)."""
    from components.orbit.frames import lvlh_dcm
    from orchestrator.config.load import load

    cfg = load(CONFIGS / name)
    (spec,) = cfg.components.values()
    assert cfg.epoch == EPOCH and (name != "orbit_iss_sgp4.yaml" or spec.parameters["tle"] == ISS_TLE)
    h = Harness(spec.type, spec.parameters, epoch=cfg.epoch, config_dir=CONFIGS)
    out = h.step(S)
    r, v = _shipped_orbit_at(name, 1.0)
    np.testing.assert_allclose(out["r_eci"], r, rtol=0, atol=r_tol)
    np.testing.assert_allclose(out["v_eci"], v, rtol=0, atol=v_tol)
    np.testing.assert_allclose(Rotation.from_quat(out["q_eci_lvlh"]).as_matrix(), lvlh_dcm(r, v), rtol=0, atol=1e-9)
    np.testing.assert_allclose(out["w_lvlh"], np.cross(r, v) / np.dot(r, r), rtol=0, atol=3e-6)
