"""B-dot detumbling: the law (:class:`BdotLaw`, no I/O) and its component type ``controller.bdot``.

| quantity | formula | unit, frame |
|---|---|---|
| field rate | dB/dt_k = (b_k - b_(k-1)) / h, successive magnetometer samples h apart | T/s, body axes |
| command | m = -k dB/dt | A m^2, body axes |
| saturation | m <- m / max(1, max_i abs(m_i) / m_max,i) (scaled as a whole: its direction kept) | A m^2 |

In body axes dB/dt = -w x B + (the field's own change along the orbit, about 2n |B|), so the
torque m x B = -k (B x (w x B)) = -k |B|^2 w_perp damps the rate across the field: the body's
rate falls with a time constant of about J / (k |B|^2) until it is of the order of the orbit's
rate (the field turns twice per orbit in a polar orbit). Stabilski, Avanzini and Giulietti
(Acta Astronautica 2012) give the gain k |B|^2 ~ 2 n (1 + sin xi) J_min for the fastest decay
(xi: the orbit's inclination to the geomagnetic equator).

The first step has one sample: no rate yet, the command is zero. The command computed at step t
from the sample at t is the output at t + h (held over the next step by the dynamics).
"""

from __future__ import annotations

import numpy as np

from components.constants import NS_PER_S
from components.plotting import Plot
from components.schema import Float, OneOf, Vector
from components.sdk import Component, Parameter, Variable


class BdotLaw:
    """m = -k dB/dt from successive samples, scaled into ``max_dipole`` (per axis, A m^2)."""

    def __init__(self, gain: float, max_dipole):
        self.gain = float(gain)
        self.max_dipole = np.broadcast_to(np.asarray(max_dipole, dtype=float), (3,)).copy()
        self.last_b: np.ndarray | None = None

    def command(self, b: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        """(dipole command A m^2, dB/dt T/s) from the sample ``b`` (T) taken h seconds after the last."""
        b = np.asarray(b, dtype=float)
        if self.last_b is None:
            rate = np.zeros(3)
        else:
            rate = (b - self.last_b) / h
        self.last_b = b.copy()
        m = -self.gain * rate
        scale = np.max(np.abs(m) / self.max_dipole)
        return (m / scale if scale > 1.0 else m), rate


def _dipole_and_rate(run, c):
    from components.plotting import new_figure

    m, rate = run.variable(f"{c}.dipole"), run.variable(f"{c}.b_rate")
    if m is None:
        return {}
    fig = new_figure(9.0, 6.0)
    ax = fig.add_subplot(2, 1, 1)
    for k, axis in enumerate("xyz"):
        ax.plot(run.time, m[:, k], linewidth=0.8, label=f"m_{axis}")
    ax.set(ylabel="A m^2", title=f"{c}: commanded dipole, body axes")
    ax.legend(loc="upper right", fontsize="x-small")
    ax.grid(True, alpha=0.3)
    if rate is not None:
        ax = fig.add_subplot(2, 1, 2)
        ax.semilogy(run.time, np.linalg.norm(rate, axis=1) * 1e9, color="k", linewidth=0.8)
        ax.set(ylabel="nT/s", title=f"{c}: |dB/dt| measured in body axes")
        ax.grid(True, alpha=0.3, which="both")
    ax.set_xlabel("time (s)")
    return {f"{c}_bdot.png": fig}


class BdotComponent(Component):
    """B-dot detumbling from a magnetometer (type ``controller.bdot``): m = -k dB/dt, saturated
    (the law and its figures: :mod:`components.controller.bdot`). Connect ``b`` to a
    ``sensor.magnetometer``'s ``b`` (or the dynamics' ``<body>.b_body``) and ``dipole`` to the
    dynamics' ``<body>.dipole``. State: the last sample and the last outputs."""

    type_name = "controller.bdot"
    plots = (Plot("{c}_bdot.png", "the commanded dipole and |dB/dt| over time", _dipole_and_rate),)
    parameters = (
        Parameter("gain", Float("A*m^2*s/T", positive=True, plausible=(1e2, 1e10)), description="k in m = -k dB/dt"),
        Parameter(
            "max_dipole",
            OneOf(
                (
                    Float("A*m^2", positive=True, plausible=(1e-3, 1e3)),
                    Vector(3, "A*m^2", minimum=0.0, plausible=(0.0, 1e3)),
                )
            ),
            description="the largest dipole per body axis: one for every axis or one per axis (the command "
            "is scaled as a whole to fit)",
        ),
    )
    variables = (
        Variable("b", "input", (3,), "T", [0.0] * 3, "measured magnetic field, body axes"),
        Variable("dipole", "output", (3,), "A*m^2", [0.0] * 3, "commanded dipole, body axes"),
        Variable("b_rate", "output", (3,), "T/s", [0.0] * 3, "dB/dt, body axes, from the last two samples"),
    )

    def __init__(self, params, run):
        self.law = BdotLaw(params["gain"], params["max_dipole"])
        self.out = {"dipole": np.zeros(3), "b_rate": np.zeros(3)}

    def initialize(self, t0_ns, inputs):
        return self.out

    def do_step(self, t_ns, h_ns, inputs):
        m, rate = self.law.command(inputs["b"], h_ns / NS_PER_S)
        self.out = {"dipole": m, "b_rate": rate}
        return self.out

    def get_state(self):
        last = self.law.last_b
        return {
            "has_last": np.bool_(last is not None),
            "last_b": np.zeros(3) if last is None else last.copy(),
            "dipole": self.out["dipole"].copy(),
            "b_rate": self.out["b_rate"].copy(),
        }

    def set_state(self, state):
        self.law.last_b = np.array(state["last_b"], dtype=float).reshape(3) if bool(state["has_last"]) else None
        self.out = {
            "dipole": np.array(state["dipole"], dtype=float).reshape(3),
            "b_rate": np.array(state["b_rate"], dtype=float).reshape(3),
        }
