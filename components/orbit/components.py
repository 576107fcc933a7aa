"""Orbit component types: thin wrappers mapping parameters to the orbit models and the models'
states to the four outputs every orbit component publishes.

Every orbit component has no inputs and the four outputs of ``ORBIT_OUTPUTS`` (declared in
:func:`components.signals.orbit_signals`; SI, ECI = GCRF axes). LVLH: x radial outward, z along
r × v, y = z × x. The quaternion's sign is kept continuous from step to step (q and -q are the
same rotation); that last sign is the components' only state (``get_state`` -> ``q_previous``),
so outputs are otherwise a pure function of time.
The run epoch reaches a component as ``run.epoch`` (ISO-8601 UTC, :class:`components.sdk.RunSettings`),
from the orchestrator; ``run.config_dir`` likewise, for relative paths.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import ClassVar

import numpy as np

from components.constants import NS_PER_S
from components.errors import ConfigError
from components.orbit import plots as orbit_plots
from components.orbit import ros as orbit_ros
from components.orbit.frames import lvlh_dcm, lvlh_floats, lvlh_state
from components.orbit.kepler import ElementError, KeplerOrbit, check_elements
from components.orbit.view import OrbitView
from components.plotting import Plot
from components.rotations import continuous, opposite
from components.schema import Float, ListOf, Record, Str, UtcTime, Vector
from components.sdk import EPOCH_KEY, Component, Parameter, RunSettings, Variable
from components.signals import orbit_signals

ORBIT_OUTPUTS = tuple(orbit_signals("output"))


def epoch_text(run: RunSettings) -> str:
    """The run epoch (UTC text); ConfigError if missing."""
    if run.epoch is None:
        raise ConfigError(EPOCH_KEY, "the run epoch was not given to the component (expected run.epoch)")
    return run.epoch


def _epoch(run: RunSettings) -> tuple[float, float]:
    """The run epoch as a UTC two-part Julian date; ConfigError if missing or unreadable."""
    from components import timescales

    try:
        return timescales.parse_utc(epoch_text(run))
    except ValueError as e:
        raise ConfigError(EPOCH_KEY, str(e)) from None


class OrbitComponent(Component):
    """Shared lifecycle: subclasses implement ``_sample(t_s) -> (r, v, q, w)``."""

    variables: ClassVar[tuple[Variable, ...] | None] = ORBIT_OUTPUTS  # a subclass's None: declare() gives them
    plots: ClassVar[tuple[Plot, ...]] = (orbit_plots.TRACK,)
    view = OrbitView
    rosbag = orbit_ros.ROS_EXPORT

    def __init__(self, params, run):
        super().__init__(params, run)
        self._q_previous: np.ndarray | tuple[float, ...] | None = None

    def _sample(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _outputs_at(self, t_ns: int) -> dict[str, np.ndarray] | np.ndarray:
        r, v, q, w = self._sample(t_ns / NS_PER_S)
        q = continuous(q, self._q_previous)
        self._q_previous = q
        return {"r_eci": r, "v_eci": v, "q_eci_lvlh": q, "w_lvlh": w}

    def initialize(self, t0_ns, inputs):
        return self._outputs_at(t0_ns)

    def do_step(self, t_ns, h_ns, inputs):
        return self._outputs_at(t_ns + h_ns)

    def get_state(self):
        q = np.zeros(4) if self._q_previous is None else self._q_previous
        return {"q_previous": np.array(q, dtype=np.float64)}

    def set_state(self, state):
        q = np.asarray(state.get("q_previous", np.zeros(4)), dtype=np.float64)
        self._q_previous = None if not np.any(q) else q


ELEMENTS = (
    # plausible: from inside the Earth (a bare 6778 meant in km) out past the Moon
    Parameter(
        "semi_major_axis",
        "float",
        unit="m",
        plausible=(6.3e6, 1e9),
        description="semi-major axis a (m), e.g. '6778 km'",
    ),
    Parameter("eccentricity", "float", unit="1", description="eccentricity, 0 <= e < 1"),
    # angles: a bare 51.6 meant in degrees is 51.6 rad, beyond a turn
    Parameter("inclination", "float", unit="rad", plausible=(0.0, math.pi), description="inclination, 0 to 180 deg"),
    Parameter(
        "raan",
        "float",
        unit="rad",
        plausible=(-2 * math.pi, 2 * math.pi),
        description="right ascension of the ascending node",
    ),
    Parameter(
        "arg_perigee", "float", unit="rad", plausible=(-2 * math.pi, 2 * math.pi), description="argument of perigee"
    ),
    Parameter(
        "mean_anomaly",
        "float",
        unit="rad",
        default=None,
        plausible=(-2 * math.pi, 2 * math.pi),
        description="mean anomaly at run.epoch (or give time_of_perigee)",
    ),
    Parameter(
        "time_of_perigee",
        UtcTime(),
        default=None,
        description="UTC time of a perigee passage, e.g. '2022-09-18T11:30:00Z' (or give mean_anomaly)",
    ),
)
"""The classical elements at run.epoch, shared by orbit.kepler (mean) and orbit.numerical (osculating)."""


def check_element_parameters(params) -> None:
    """ConfigError unless the elements are an ellipse above the surface with one of mean_anomaly, time_of_perigee."""
    from components.timescales import parse_utc

    try:
        check_elements(params["semi_major_axis"], params["eccentricity"], params["inclination"])
    except ElementError as e:
        raise ConfigError(e.key, e.message) from None
    given = [k for k in ("mean_anomaly", "time_of_perigee") if params.get(k) is not None]
    if not given:
        raise ConfigError("mean_anomaly", "expected mean_anomaly (at run.epoch) or time_of_perigee (UTC), got neither")
    if len(given) == 2:
        raise ConfigError("time_of_perigee", "expected mean_anomaly or time_of_perigee, got both")
    if params.get("time_of_perigee") is not None:
        try:
            parse_utc(params["time_of_perigee"])
        except ValueError as e:
            raise ConfigError("time_of_perigee", str(e)) from None


def epoch_mean_anomaly(params, run: RunSettings, mean_rate: float) -> float:
    """The mean anomaly at run.epoch (rad): given, or from time_of_perigee at ``mean_rate`` (rad/s)."""
    from components import timescales

    if params.get("time_of_perigee") is not None:
        return mean_rate * timescales.seconds_between(timescales.parse_utc(params["time_of_perigee"]), _epoch(run))
    return float(params["mean_anomaly"])


class KeplerComponent(OrbitComponent):
    """Keplerian orbit about the Earth, optionally with J2 secular drift (type ``orbit.kepler``).

    Two-body ellipse of the given elements (mean elements at run.epoch, ECI/GCRF equator and
    x axis); with ``j2: true`` Ω, ω and M drift at the first-order secular J2 rates, and the
    published velocity is the exact time derivative of the position (see
    :class:`components.orbit.kepler.KeplerOrbit`). Earth constants: WGS 84 / EGM96
    (mu = 3.986004418e14 m^3/s^2, R = 6378137 m, J2 = 1.08262668e-3).

    """

    type_name = "orbit.kepler"
    parameters = ELEMENTS + (
        Parameter(
            "j2", "bool", default=False, description="apply J2 secular drift of RAAN, argument of perigee, mean anomaly"
        ),
    )

    @classmethod
    def validate(cls, params, run):
        check_element_parameters(params)
        return params

    def __init__(self, params, run):
        super().__init__(params, run)
        orbit = KeplerOrbit(
            params["semi_major_axis"],
            params["eccentricity"],
            params["inclination"],
            params["raan"],
            params["arg_perigee"],
            0.0,
            j2=params["j2"],
        )
        orbit.m0 = epoch_mean_anomaly(params, run, orbit.mean_rate)
        self.orbit = orbit

    def _sample(self, t_s):
        r, v, a = self.orbit.state_tuples(t_s)
        q, w = lvlh_state(r, v, a)
        return np.array(r), np.array(v), q, w

    def _outputs_at(self, t_ns: int) -> np.ndarray:
        """``_sample`` and the sign continuity of the base's, in floats, as one vector (r_eci, v_eci,
        q_eci_lvlh, w_lvlh): one array a step instead of six and a dict (the same numbers)."""
        r, v, a = self.orbit.state_tuples(t_ns / NS_PER_S)
        q, w = lvlh_floats(r, v, a)
        p = self._q_previous
        if p is not None and opposite(q, p):
            q = (-q[0], -q[1], -q[2], -q[3])
        self._q_previous = q  # (get_state makes it an array)
        return np.array(r + v + q + w)


class SGP4Component(OrbitComponent):
    """A TLE propagated with SGP4 (``sgp4`` package), converted from TEME to GCRF (type ``orbit.sgp4``).

    Propagated at run.epoch + t (UTC, leap seconds counted). TEME -> GCRF by IAU 2006/2000A
    precession-nutation and the equation of the equinoxes through ERFA, UT1 = UTC (see
    :mod:`components.orbit.tle`; rotation error ~ milliarcseconds, centimetres at LEO). r_eci and
    v_eci are SGP4's position and velocity rotated to GCRF; q_eci_lvlh is built from them and
    w_lvlh is the rate of that frame, by a central difference of the LVLH attitude over ±0.5 s
    (error ~1e-11 rad/s; SGP4's velocity is not exactly the derivative of its position,
    differing by ~1 cm/s, so the frame's own rate is used rather than a formula in r and v).
    A propagation failure (decay, eccentricity out of range) raises RuntimeError with sgp4's
    SGP4_ERRORS text; a failure already at run.epoch is a ConfigError on ``tle``/``tle_file``.

    """

    type_name = "orbit.sgp4"
    parameters = (
        Parameter(
            "tle",
            ListOf(Str(), min_items=2, max_items=2),
            default=None,
            description="TLE as [line1, line2] (or give tle_file)",
        ),
        Parameter(
            "tle_file", "str", default=None, description="path of a TLE file, relative to the config (or give tle)"
        ),
    )
    RATE_HALF_STEP = 0.5  # s, half-width of the central difference giving w_lvlh

    @classmethod
    def _lines(cls, params, run: RunSettings) -> tuple[str, tuple[str, str]]:
        """(key, validated lines); ConfigError naming tle or tle_file."""
        from components.orbit.tle import TLEFormatError, check_tle, read_tle_file

        tle, tle_file = params.get("tle"), params.get("tle_file")
        if (tle is None) == (tle_file is None):
            raise ConfigError(
                "tle",
                "expected either tle: [line1, line2] or tle_file: PATH, got " + ("neither" if tle is None else "both"),
            )
        if tle is not None:
            try:
                return "tle", check_tle(tle[0], tle[1])
            except TLEFormatError as e:
                raise ConfigError("tle", str(e)) from None
        path = Path(tle_file)
        if not path.is_absolute():
            path = Path(run.config_dir or ".") / path
        try:
            return "tle_file", read_tle_file(path)
        except OSError as e:
            raise ConfigError("tle_file", f"cannot read {path}: {e.strerror or e}") from None
        except TLEFormatError as e:
            raise ConfigError("tle_file", f"{path}: {e}") from None

    @classmethod
    def validate(cls, params, run):
        from components.orbit.tle import SGP4Propagator

        key, lines = cls._lines(params, run)
        if run.epoch is None:
            return params
        try:
            SGP4Propagator(*lines).teme(_epoch(run))
        except RuntimeError as e:
            raise ConfigError(key, f"cannot propagate to run.epoch {run.epoch}: {e}") from None
        return params

    def __init__(self, params, run):
        from components import timescales
        from components.orbit.tle import SGP4Propagator

        super().__init__(params, run)
        _, lines = self._lines(params, run)
        self.propagator = SGP4Propagator(*lines)
        self.epoch_tai = timescales.utc_to_tai(_epoch(run))

    def _utc(self, t_s: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """(UTC, TT) two-part Julian dates t_s seconds after run.epoch (leap seconds counted)."""
        from components import timescales

        tai = (self.epoch_tai[0], self.epoch_tai[1] + t_s / timescales.SECONDS_PER_DAY)
        return timescales.tai_to_utc(tai), timescales.tai_to_tt(tai)

    def _sample(self, t_s):
        from components.orbit.tle import teme_to_gcrf_matrix
        from components.rotations import log_so3, matrix_to_quat

        utc, tt = self._utc(t_s)
        c = teme_to_gcrf_matrix(tt, utc)  # UT1 ~ UTC
        r_teme, v_teme = self.propagator.teme(utc)
        r, v = c @ r_teme, c @ v_teme
        # rate of the published LVLH frame: central difference of its attitude over ±d, with the
        # TEME->GCRF matrix of t (its own rotation, < 1e-11 rad/s, is left out)
        d = self.RATE_HALF_STEP
        frames = []
        for offset in (-d, d):
            rs, vs = self.propagator.teme(self._utc(t_s + offset)[0])
            frames.append(lvlh_dcm(c @ rs, c @ vs))
        w = log_so3(frames[1] @ frames[0].T) / (2.0 * d)
        return r, v, matrix_to_quat(lvlh_dcm(r, v)), w


WAYPOINT = Record(
    "Waypoint",
    (
        Parameter("time", Float("s"), description="time since run.epoch"),
        Parameter("position", Vector(3, "m", plausible=(-1e9, 1e9)), description="position, ECI"),
        Parameter("velocity", Vector(3, "m/s", plausible=(-2e4, 2e4)), description="velocity, ECI"),
        Parameter("acceleration", Vector(3, "m/s^2", plausible=(-100.0, 100.0)), description="acceleration, ECI"),
    ),
    description="one point of orbit.custom_path's path",
)


class CustomPathComponent(OrbitComponent):
    """A path through ECI waypoints, interpolated by a C2 quintic Hermite spline (type ``orbit.custom_path``).

    Each waypoint gives time (s since run.epoch), position (m), velocity (m/s) and acceleration
    (m/s^2) in ECI; the spline matches all three at every waypoint. LVLH is built from the
    spline's r and v; w_lvlh = (|r| (a·z)/|h|) x + (|h|/|r|^2) z with the spline's a (exact for
    the path, including the out-of-plane term). Times must strictly increase and the first must
    be <= 0 (the path covers the run's start). Past the last waypoint ``after_end`` chooses:
    ``hold`` freezes all four outputs at their values at the last waypoint; ``error`` fails the
    step. r and v must not be parallel (LVLH undefined) at any waypoint.

    """

    type_name = "orbit.custom_path"
    parameters = (
        Parameter("waypoints", ListOf(WAYPOINT, min_items=2), description="at least 2, times increasing"),
        Parameter(
            "after_end",
            "str",
            choices=("hold", "error"),
            description="past the last waypoint: hold the last outputs or fail",
        ),
    )

    @classmethod
    def _spline(cls, params):
        from components.orbit.spline import QuinticHermiteSpline, SplineError

        t, r, v, a = (
            np.array([point[key] for point in params["waypoints"]])
            for key in ("time", "position", "velocity", "acceleration")
        )
        for k in range(1, len(t)):
            if not t[k] > t[k - 1]:
                raise ConfigError(
                    f"waypoints[{k}].time",
                    f"expected times strictly increasing, got "
                    f"{float(t[k])!r} s after {float(t[k - 1])!r} s (waypoints[{k - 1}])",
                )
        if t[0] > 0.0:
            raise ConfigError(
                "waypoints[0].time", f"expected <= 0 s (the path must cover the run's start), got {float(t[0])!r} s"
            )
        for k in range(len(t)):
            h = np.linalg.norm(np.cross(r[k], v[k]))
            if not h > 1e-12 * np.linalg.norm(r[k]) * max(float(np.linalg.norm(v[k])), 1e-300):
                raise ConfigError(
                    f"waypoints[{k}].velocity",
                    f"expected a velocity not parallel to the position (LVLH needs r x v != 0), "
                    f"got r = {r[k].tolist()} m, v = {v[k].tolist()} m/s",
                )
        try:
            return QuinticHermiteSpline(t, r, v, a)
        except SplineError as e:  # pragma: no cover - the checks above come first
            raise ConfigError("waypoints", str(e)) from None

    @classmethod
    def validate(cls, params, run):
        cls._spline(params)
        return params

    def __init__(self, params, run):
        super().__init__(params, run)
        self.spline = self._spline(params)
        self.after_end = params["after_end"]

    def _sample(self, t_s):
        if t_s > self.spline.end:
            if self.after_end == "error":
                raise RuntimeError(
                    f"orbit.custom_path: t = {t_s!r} s is past the last waypoint "
                    f"({self.spline.end!r} s) and after_end is 'error'"
                )
            t_s = self.spline.end
        if t_s < self.spline.start:
            raise RuntimeError(
                f"orbit.custom_path: t = {t_s!r} s is before the first waypoint ({self.spline.start!r} s)"
            )
        r, v, a = self.spline.evaluate(t_s)
        try:
            q, w = lvlh_state(r, v, a)
        except ValueError as e:
            raise RuntimeError(f"orbit.custom_path at t = {t_s!r} s: {e}") from None
        return r, v, q, w


class FixedComponent(OrbitComponent):
    """A fixed point: constant r_eci and q_eci_lvlh, zero velocity and rate (type ``orbit.fixed``).

    Not an orbit: for tests and for scenes away from any orbit. ``q_eci_lvlh`` must be a unit
    quaternion to 1e-3; it is normalized.

    """

    type_name = "orbit.fixed"
    parameters = (
        Parameter("r_eci", "vector", unit="m", shape=(3,), plausible=(-1e9, 1e9), description="position in ECI"),
        Parameter(
            "q_eci_lvlh",
            "vector",
            unit="1",
            shape=(4,),
            default=np.array([0.0, 0.0, 0.0, 1.0]),
            description="attitude quaternion [x, y, z, w], LVLH -> ECI",
        ),
    )

    @classmethod
    def validate(cls, params, run):
        q = np.asarray(params["q_eci_lvlh"], dtype=np.float64)
        if not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > 1e-3:
            raise ConfigError(
                "q_eci_lvlh",
                f"expected a unit quaternion [x, y, z, w] (norm 1 within 1e-3), "
                f"got {q.tolist()} (norm {np.linalg.norm(q):.6g})",
            )
        if not np.all(np.isfinite(params["r_eci"])):
            raise ConfigError("r_eci", f"expected finite values in m, got {np.asarray(params['r_eci']).tolist()}")
        return params

    def __init__(self, params, run):
        super().__init__(params, run)
        self.r = np.array(params["r_eci"], dtype=np.float64)
        q = np.asarray(params["q_eci_lvlh"], dtype=np.float64)
        self.q = q / np.linalg.norm(q)

    def _sample(self, t_s):
        return self.r.copy(), np.zeros(3), self.q.copy(), np.zeros(3)
