"""The orbit's plot (``orchestrator plot``): altitude, ground track, and r, v over time."""

from __future__ import annotations

import numpy as np

from components.plotting import Plot, RecordedRun, new_figure


def track(run: RecordedRun, c: str) -> dict:
    """Altitude, ground track, and r, v over time of an orbit component's r_eci, v_eci."""
    import erfa

    from components import timescales
    from components.constants import R_EARTH

    t = run.time
    r, v = run.vector(f"{c}.r_eci", 3), run.vector(f"{c}.v_eci", 3)
    if r is None:
        return {}
    utc = timescales.parse_utc(str((run.config.get("run") or {}).get("epoch")))
    angle = np.array([erfa.era00(utc[0], utc[1] + s / 86400.0) for s in t])  # Earth rotation, UT1 ~ UTC
    x = np.cos(angle) * r[:, 0] + np.sin(angle) * r[:, 1]  # Earth-fixed
    y = -np.sin(angle) * r[:, 0] + np.cos(angle) * r[:, 1]
    radius = np.linalg.norm(r, axis=1)
    fig = new_figure(11.0, 7.0)
    ax = fig.add_subplot(2, 2, 1)
    altitude = (radius - R_EARTH) / 1e3
    ax.plot(t, altitude, color="k", linewidth=1.0)
    ax.ticklabel_format(axis="y", useOffset=False)
    if np.ptp(altitude) < 1.0:  # a circular orbit: no axis of rounding noise
        ax.set_ylim(altitude.mean() - 1.0, altitude.mean() + 1.0)
    ax.set(xlabel="time (s)", ylabel="km", title=f"{c}: altitude above {R_EARTH / 1e3:g} km")
    ax = fig.add_subplot(2, 2, 2)
    lon, lat = np.degrees(np.arctan2(y, x)), np.degrees(np.arcsin(r[:, 2] / radius))
    jumps = np.abs(np.diff(lon, prepend=lon[0])) > 180  # break the line at +-180
    ax.plot(np.where(jumps, np.nan, lon), lat, color="tab:blue", linewidth=1.0)
    ax.set(
        xlim=(-180, 180),
        ylim=(-90, 90),
        xlabel="longitude (deg)",
        ylabel="latitude (deg)",
        title=f"{c}: ground track (spherical Earth)",
    )
    for i, (vector, unit, what) in enumerate(
        ((r / 1e3, "km", "r_eci"), (v / 1e3 if v is not None else None, "km/s", "v_eci"))
    ):
        ax = fig.add_subplot(2, 2, 3 + i)
        if vector is not None:
            for k, axis in enumerate("xyz"):
                ax.plot(t, vector[:, k], linewidth=1.0, label=axis)
            ax.legend(loc="upper right", fontsize="small")
        ax.set(xlabel="time (s)", ylabel=unit, title=f"{c}.{what} (ECI)")
    for ax in fig.axes:
        ax.grid(True, alpha=0.3)
    return {f"{c}_track.png": fig}


TRACK = Plot("{c}_track.png", "altitude, ground track (spherical Earth, UT1 = UTC), r_eci and v_eci over time", track)


TERMS = ("point_mass", "harmonics", "sun", "moon", "drag", "srp")
"""orbit.numerical's accelerations, each published as ``a_<term>_eci``."""


LABELS = {
    "point_mass": "point mass (GM)",
    "harmonics": "harmonics (J2 and up)",
    "sun": "Sun (third body)",
    "moon": "Moon (third body)",
    "drag": "drag",
    "srp": "solar radiation pressure",
}


def accelerations(run: RecordedRun, c: str) -> dict:
    """The magnitude of each acceleration orbit.numerical publishes (``a_<term>_eci``), log scale;
    a zero (SRP in eclipse) is a gap in its line, each label gives the term's mean over the run."""
    t = run.time
    vectors = [(term, run.vector(f"{c}.a_{term}_eci", 3)) for term in TERMS]
    found = [(term, a) for term, a in vectors if a is not None]
    if not found:
        return {}
    fig = new_figure(10.0, 5.5)
    ax = fig.add_subplot(1, 1, 1)
    for k, (term, a) in enumerate(found):
        magnitude = np.linalg.norm(a, axis=1)
        ax.semilogy(
            t / 3600.0,
            np.where(magnitude > 0.0, magnitude, np.nan),
            linewidth=1.0,
            linestyle="-" if k < 5 else "--",
            label=f"{LABELS[term]}: {magnitude.mean():.2g}",
        )
    ax.set(
        xlabel="time since run.epoch (h)",
        ylabel="acceleration magnitude (m/s^2)",
        title=f"{c}: each acceleration term (ECI; a gap: zero, e.g. SRP in eclipse)",
    )
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", title="term: mean (m/s^2)")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return {f"{c}_accelerations.png": fig}


ACCELERATIONS = Plot(
    "{c}_accelerations.png", "magnitude of each acceleration term over time (orbit.numerical)", accelerations
)
