"""The magnetic field and magnetorquers in the dynamics (components/dynamics/magnetic.py), the
magnetometer and the B-dot controller, through the in-process harness."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from components.rotations import quat_to_matrix
from components.space.geomagnetic import GeomagneticField
from components.testing.harness import Harness
from tests import validation

ROOT = Path(__file__).resolve().parents[2]
EPOCH = "2026-03-20T00:00:00Z"
R_ECI, V_ECI = np.array([2100e3, -6200e3, 2300e3]), np.array([6900.0, 1800.0, -1500.0])
Q_BASE = np.array([0.18, -0.27, 0.41, 0.0])
Q_BASE[3] = np.sqrt(1 - Q_BASE[:3] @ Q_BASE[:3])
W_BASE = np.array([0.03, -0.05, 0.07])
INERTIA = np.diag([33.33333333, 59.33333333, 59.33333333])  # models/target.urdf about its CoM = base origin


def dynamics(engine: str, model: str = "dipole", magnetorquers=True, environment=False) -> Harness:
    params = {
        "bodies": {
            "target": {
                "urdf": str(ROOT / "models" / "target.urdf"),
                "position": [1.5, -2.0, 0.5],
                "orientation": Q_BASE.tolist(),
                "twist": [0.0, 0.0, 0.0, *W_BASE],
            }
        },
        "tidal_force": environment,
        "gravity_gradient": environment,
        "magnetic_field": {"model": model},
    }
    if magnetorquers:
        params["magnetorquers"] = {"target": {"max_dipole": [100.0, 60.0, 100.0]}}
    h = Harness(f"dynamics.{engine}", params, epoch=EPOCH)
    h.inputs.update(r_eci=R_ECI, v_eci=V_ECI, q_eci_lvlh=np.array([0.0, 0.0, 0.0, 1.0]), w_lvlh=np.zeros(3))
    return h


@pytest.mark.parametrize("engine", ["dart", "pinocchio"])
def test_magnetorquer_torque_drives_both_engines(engine):
    """Angular acceleration under m x B (m saturated on y) against Euler's equations with the
    field of the model at the base origin."""
    h = dynamics(engine)
    out = h.initialize()
    R = quat_to_matrix(Q_BASE)
    B = GeomagneticField("dipole", EPOCH).b_eci(R_ECI + np.array([1.5, -2.0, 0.5]), 0)
    assert out["target.b_body"] == pytest.approx(R.T @ B, rel=1e-12)
    component = h.component
    free = component.world.forward_dynamics("target")["dv_W_base"][3:6]  # no dipole yet
    h.inputs["target.dipole"] = np.array([40.0, -90.0, 25.0])
    component.magnetics.apply(h._input_views())
    alpha = component.world.forward_dynamics("target")["dv_W_base"][3:6]
    m = np.array([40.0, -60.0, 25.0])  # saturated at 60 on y
    torque_W = np.cross(R @ m, B)
    I_W = R @ INERTIA @ R.T
    w_W = W_BASE  # (twist in W axes)
    assert free == pytest.approx(np.linalg.solve(I_W, -np.cross(w_W, I_W @ w_W)), rel=1e-9)
    expected = np.linalg.solve(I_W, torque_W)
    validation.check("mtb_dynamics", float(np.linalg.norm((alpha - free) - expected) / np.linalg.norm(expected)))
    out = h.step(50_000_000)
    assert out["target.mtb_torque"] == pytest.approx(np.cross(m, R.T @ B), rel=1e-12)


def test_magnetic_outputs_are_off_by_default_and_need_the_field():
    from components.errors import ConfigError

    params = {"bodies": {"target": {"urdf": str(ROOT / "models" / "target.urdf")}}}
    h = Harness("dynamics.dart", params, epoch=EPOCH)
    assert not any("b_body" in k or "dipole" in k for k in [*h.outputs, *h.inputs])
    assert h.component.magnetics is None
    with pytest.raises(ConfigError, match=r"magnetorquers\.target.*expected magnetic_field"):
        Harness("dynamics.dart", {**params, "magnetorquers": {"target": {"max_dipole": 10.0}}}, epoch=EPOCH)


def test_state_restores_the_field_and_torque_bit_for_bit():
    a = dynamics("dart", model="wmm", environment=True)
    a.inputs["target.dipole"] = np.array([12.0, -30.0, 8.0])
    for _ in range(3):
        a.step(100_000_000)
    blob = a.get_state()
    b = dynamics("dart", model="wmm", environment=True)
    b.t_ns = a.t_ns
    b.set_state(blob)
    b.inputs["target.dipole"] = a.inputs["target.dipole"]
    for _ in range(3):
        out_a, out_b = a.step(100_000_000), b.step(100_000_000)
        for key in out_a:
            assert np.array_equal(out_a[key], out_b[key]), key


def test_magnetometer_adds_its_bias_and_seeded_noise():
    params = {"seed": 3, "noise": 40e-9, "bias": [1e-7, -2e-7, 0.0]}
    h = Harness("sensor.magnetometer", params)
    b_true = np.array([21e-6, -8e-6, 33e-6])
    h.inputs["b_true"] = b_true
    samples = np.array([h.step(100_000_000)["b"] for _ in range(2000)])
    error = samples - b_true
    assert error.mean(axis=0) == pytest.approx([1e-7, -2e-7, 0.0], abs=4 * 40e-9 / np.sqrt(2000))
    assert error.std(axis=0) == pytest.approx([40e-9] * 3, rel=0.1)
    again = Harness("sensor.magnetometer", params)
    again.inputs["b_true"] = b_true
    assert np.array_equal(again.step(100_000_000)["b"], samples[0])


def test_bdot_commands_minus_gain_times_the_field_rate_scaled_into_its_limit():
    h = Harness("controller.bdot", {"gain": 2e7, "max_dipole": [50.0, 50.0, 20.0]})
    h.inputs["b"] = np.array([20e-6, -5e-6, 30e-6])
    assert np.array_equal(h.step(500_000_000)["dipole"], np.zeros(3))  # one sample: no rate yet
    h.inputs["b"] = np.array([20.4e-6, -5.3e-6, 30.1e-6])
    out = h.step(500_000_000)
    rate = np.array([0.4e-6, -0.3e-6, 0.1e-6]) / 0.5
    assert out["b_rate"] == pytest.approx(rate, rel=1e-9)
    assert out["dipole"] == pytest.approx(-2e7 * rate, rel=1e-9)  # (16, -12, -4): within limits
    h.inputs["b"] = np.array([22.4e-6, -5.3e-6, 30.1e-6])  # x rate 4e-6 T/s: -80 A m^2
    out = h.step(500_000_000)
    assert out["dipole"] == pytest.approx([-50.0, 0.0, 0.0], abs=1e-9)  # scaled as a whole into 50
