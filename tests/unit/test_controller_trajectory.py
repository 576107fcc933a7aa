"""Controller trajectories: quintic law, the paper's parabola, Cartesian and joint waypoints,
the PID law; references are closed forms and finite differences of the sampled positions."""

import numpy as np
import pytest

from components.controller.joint_pd import JointPID, PidGains
from components.controller.trajectory import JointWaypoints, build_cartesian, max_offset, parse_cartesian, quintic
from components.errors import ConfigError
from components.rotations import exp_so3, log_so3


def test_quintic_time_law_rest_to_rest():
    assert quintic(0.9, 1.0, 2.0) == (0.0, 0.0, 0.0)
    assert quintic(3.5, 1.0, 2.0) == (1.0, 0.0, 0.0)
    s, ds, dds = quintic(2.0, 1.0, 2.0)  # halfway: s = 1/2, peak rate 15/8 / T, zero acceleration
    assert s == pytest.approx(0.5) and ds == pytest.approx(1.875 / 2.0) and dds == pytest.approx(0.0, abs=1e-15)
    h = 1e-6
    for t in np.linspace(1.05, 2.95, 11):
        s, ds, dds = quintic(t, 1.0, 2.0)
        assert ds == pytest.approx((quintic(t + h, 1.0, 2.0)[0] - quintic(t - h, 1.0, 2.0)[0]) / (2 * h), rel=1e-6)
        assert dds == pytest.approx(
            (quintic(t + h, 1.0, 2.0)[1] - quintic(t - h, 1.0, 2.0)[1]) / (2 * h), rel=1e-5, abs=1e-9
        )


def random_pose(seed):
    rng = np.random.default_rng(seed)
    return rng.normal(size=3), exp_so3(rng.normal(size=3)), exp_so3(rng.normal(size=3))


def check_derivatives(trajectory, times, h=1e-5):
    """v, a, w, dw against central differences of p, v, R, w."""
    for t in times:
        d, dp, dm = trajectory.sample(t), trajectory.sample(t + h), trajectory.sample(t - h)
        assert np.allclose(d.v, (dp.p - dm.p) / (2 * h), atol=1e-8)
        assert np.allclose(d.a, (dp.v - dm.v) / (2 * h), atol=1e-7)
        assert np.allclose(d.w, log_so3(dp.R @ dm.R.T) / (2 * h), atol=1e-8)
        assert np.allclose(d.dw, (dp.w - dm.w) / (2 * h), atol=1e-7)


def test_parabola_is_the_papers_move():
    p0, R0, R_base = random_pose(1)
    spec = parse_cartesian(
        {"type": "parabola", "start": "1 s", "duration": "10 s", "displacement": "0.5 m", "height": "100 mm"}
    )
    trajectory = build_cartesian(spec, p0, R0, R_base)

    def body(p):
        return R_base.T @ (p - p0)  # offset in the base's initial axes

    assert np.allclose(body(trajectory.sample(0.5).p), 0.0)
    assert np.allclose(body(trajectory.sample(6.0).p), [0.25, 0.0, 0.1])  # apex halfway
    assert np.allclose(body(trajectory.sample(11.0).p), [0.5, 0.0, 0.0])
    assert np.allclose(body(trajectory.sample(20.0).p), [0.5, 0.0, 0.0])
    for t in np.linspace(0.0, 12.0, 25):
        d = trajectory.sample(t)
        x, y, z = body(d.p)
        assert y == pytest.approx(0.0, abs=1e-12)  # y held
        assert z == pytest.approx(4 * 0.1 * (x / 0.5) * (1 - x / 0.5), abs=1e-12)  # parabola in x
        assert np.allclose(d.R, R0) and not np.any(d.w) and not np.any(d.dw)  # orientation kept
    check_derivatives(trajectory, np.linspace(1.1, 10.9, 9))
    world = build_cartesian({**spec, "axes": "world"}, p0, R0, R_base)
    assert np.allclose(world.sample(11.0).p - p0, [0.5, 0.0, 0.0])


def test_waypoints_pass_through_each_pose_and_are_smooth():
    p0, R0, R_base = random_pose(2)
    spec = parse_cartesian(
        {
            "type": "waypoints",
            "start": 1.0,
            "waypoints": [
                {"time": 3.0, "position": [0.1, 0.0, 0.05]},
                {"time": "5 s", "position": [0.1, -0.2, 0.0], "rotation": [0.0, 0.0, 0.4]},
                {"time": 8.0, "position": [0.0, 0.0, 0.0], "rotation": ["20 deg", 0.0, 0.0]},
            ],
        }
    )
    trajectory = build_cartesian(spec, p0, R0, R_base)
    for t, offset, rotation in (
        (1.0, [0, 0, 0], [0, 0, 0]),
        (3.0, [0.1, 0, 0.05], [0, 0, 0]),
        (5.0, [0.1, -0.2, 0], [0, 0, 0.4]),
        (8.0, [0, 0, 0], [np.radians(20), 0, 0]),
    ):
        d = trajectory.sample(t)
        assert np.allclose(d.p, p0 + R_base @ offset, atol=1e-12)
        assert np.allclose(d.R, exp_so3(R_base @ np.array(rotation)) @ R0, atol=1e-12)
        assert np.allclose(d.v, 0.0) and np.allclose(d.w, 0.0)  # rest at each waypoint
    check_derivatives(trajectory, [1.5, 2.2, 3.7, 4.4, 6.0, 7.3])
    assert [k for k, _ in trajectory.checkpoints()] == [f"waypoints[{i}].position" for i in range(3)]


@pytest.mark.parametrize(
    "spec, key",
    [
        ({"type": "spiral"}, "trajectory.type"),
        ({"type": "parabola", "start": 0}, "trajectory.duration"),
        ({"type": "parabola", "duration": "10 kg"}, "trajectory.duration"),
        ({"type": "parabola", "duration": 10, "heigth": 0.1}, "trajectory.heigth"),
        ({"type": "parabola", "duration": -1}, "trajectory.duration"),
        ({"type": "waypoints", "waypoints": []}, "trajectory.waypoints"),
        ({"type": "waypoints", "waypoints": [{"time": 2, "position": [0, 0]}]}, "trajectory.waypoints[0].position"),
        ({"type": "waypoints", "waypoints": [{"time": 2}, {"time": 1}]}, "trajectory.waypoints[1].time"),
        ({"type": "waypoints", "axes": "tool", "waypoints": [{"time": 2}]}, "trajectory.axes"),
    ],
)
def test_bad_trajectories_name_the_key(spec, key):
    with pytest.raises(ConfigError) as error:
        parse_cartesian(spec)
    assert error.value.key == key


def test_max_offset_for_reach_checks():
    assert max_offset(parse_cartesian({"type": "parabola", "duration": 1, "displacement": 0.5, "height": 0.1}))[
        1
    ] == pytest.approx(0.5)
    key, size = max_offset(
        parse_cartesian(
            {
                "type": "waypoints",
                "waypoints": [{"time": 1, "position": [0.1, 0, 0]}, {"time": 2, "position": [0, 3, 4]}],
            }
        )
    )
    assert (key, size) == ("waypoints[1].position", pytest.approx(5.0))


def test_joint_waypoints():
    trajectory = JointWaypoints([0.0, 1.0], 1.0, [2.0, 4.0], [[1.0, 1.0], [1.0, -1.0]])
    assert np.allclose(trajectory.sample(0.0)[0], [0.0, 1.0])
    assert np.allclose(trajectory.sample(1.5)[0], [0.5, 1.0])
    assert np.allclose(trajectory.sample(3.0)[0], [1.0, 0.0])
    q, qd, qdd = trajectory.sample(5.0)
    assert np.allclose(q, [1.0, -1.0]) and not np.any(qd) and not np.any(qdd)


def test_pid_matches_hand_computation_and_saturates():
    pid = JointPID(
        PidGains(
            p=np.array([10.0, 10.0]), i=np.array([2.0, 2.0]), d=np.array([1.0, 1.0]), i_clamp=np.array([0.5, 0.5])
        ),
        effort=np.array([100.0, 3.0]),
    )
    tau = pid.torque([0.1, 1.0], [0.0, 0.0], np.array([0.0, 0.0]), np.array([0.2, 0.0]), dt=0.01)
    # p e + i_term (i e dt) + d (qd_d - qd)
    assert np.allclose(tau, [10 * 0.1 + 2 * 0.1 * 0.01 - 0.2, 3.0])  # second joint saturated at 3 N m
    for _ in range(10000):
        pid.torque([0.1, 1.0], [0.0, 0.0], np.zeros(2), np.zeros(2), dt=0.01)
    assert np.allclose(pid.i_term, [0.5, 0.5])  # anti-windup clamp
