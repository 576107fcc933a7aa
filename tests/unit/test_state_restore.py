"""A restore (a same-type swap, a restart from a checkpoint) is ``__init__(params)`` on a fresh
instance, then ``set_state`` with another instance's ``get_state``, then ``do_step`` from the
state's time: ``initialize`` is never called. For every shipped type, in the configuration the
shipped configs use (stepped in process as a Jacobi run wires them, states through the bus's
bytes encoding): the restored instance B publishes bit for bit what the original A publishes
over the following steps, given the same inputs, and B's ``get_state`` right after the restore
is A's (same keys, same bits)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from components.bus import decode_state
from components.errors import ConfigError
from components.testing.harness import Harness
from components.units import duration_ns

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"
MS = 1_000_000
S = 1_000_000_000


def bit_equal(x, y) -> bool:
    x, y = np.asarray(x), np.asarray(y)
    return x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()


def assert_same_outputs(got: dict, expected: dict, where: str) -> None:
    assert got.keys() == expected.keys(), where
    for key in expected:
        assert np.array_equal(got[key], expected[key]) and bit_equal(got[key], expected[key]), f"{where}: {key}"


def assert_same_state(got: bytes, expected: bytes, where: str) -> None:
    """Two encoded states hold the same keys and the same bits (dtype and shape included)."""
    got, expected = decode_state(got), decode_state(expected)
    assert sorted(got) == sorted(expected), where
    for key in expected:
        assert bit_equal(got[key], expected[key]), f"{where}: state {key}"


def restore(a: Harness, make) -> Harness:
    """What the orchestrator does on a restore: a fresh instance of a's type and parameters at
    a's time, given a's state (no initialize); its get_state is then a's."""
    blob = a.get_state()
    b = make(a.t_ns)
    b.set_state(blob)
    assert_same_state(b.get_state(), blob, f"{type(b.component).__name__} restored at t = {a.t_ns} ns")
    return b


class Run:
    """A shipped config's components, stepped in process as a Jacobi run wires them: initialized
    in config order (an input whose source is initialized already is sampled at t0, the others
    hold their start values), then every component steps on the others' outputs at t.

    ``shadows`` (component name -> Harness): restored instances that get the same inputs as the
    run's component of that name at every step, and whose outputs (each step) and state (at the
    end of ``step``) are checked bit for bit against it.
    """

    def __init__(self, config: str, edit=None):
        self.config = yaml.safe_load((CONFIGS / config).read_text())
        if edit is not None:  # a variant of the shipped config
            edit(self.config)
        self.step_ns = duration_ns(self.config["run"]["step"], "run.step")
        self.sources = {}  # component -> [(input, source component, output)]
        for dst, src in (self.config["connections"] or {}).items():
            (c, i), (s, o) = dst.split(".", 1), src.split(".", 1)
            self.sources.setdefault(c, []).append((i, s, o))
        self.components = {name: self.make(name) for name in self.config["components"]}
        self.outputs: dict[str, dict] = {}
        self.shadows: dict[str, Harness] = {}
        for name, h in self.components.items():  # config order
            ready = {i: h.t_ns for i, s, _ in self.sources.get(name, ()) if s in self.outputs}
            self.feed(name, h)
            h.input_times_ns = ready
            self.outputs[name] = h.initialize()
            h.input_times_ns = {}

    def make(self, name: str, t0_ns: int = 0) -> Harness:
        spec = self.config["components"][name]
        return Harness(
            spec["type"], spec.get("parameters"), t0_ns=t0_ns, epoch=self.config["run"]["epoch"], config_dir=CONFIGS
        )

    def feed(self, name: str, h: Harness) -> None:
        for i, s, o in self.sources.get(name, ()):
            if s in self.outputs:
                h.inputs[i] = self.outputs[s][o]

    @property
    def t_ns(self) -> int:
        return next(iter(self.components.values())).t_ns

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            for name, h in self.components.items():
                self.feed(name, h)
            for name, b in self.shadows.items():
                b.inputs.update(self.components[name].inputs)
            outputs = {name: h.step(self.step_ns) for name, h in self.components.items()}
            for name, b in self.shadows.items():
                assert_same_outputs(b.step(self.step_ns), outputs[name], f"{name} at t = {self.t_ns} ns")
            self.outputs = outputs
        for name, b in self.shadows.items():
            assert_same_state(b.get_state(), self.components[name].get_state(), f"{name} at t = {self.t_ns} ns")

    def restore(self, *names: str) -> None:
        """Shadow these components by restored instances from here on."""
        for name in names:
            self.shadows[name] = restore(self.components[name], lambda t0_ns, name=name: self.make(name, t0_ns))

    def run_to(self, t_s: float) -> None:
        self.step(round(t_s * S) // self.step_ns - self.t_ns // self.step_ns)


# --------------------------------------------------------------------------- the paper's demo


@pytest.fixture(scope="module")
def demo_at_9s():
    """configs/humanoid_tracking.yaml at t = 9 s: 8 s into the 10 s move of the end effector
    (94 % of its 0.5 m path)."""
    run = Run("humanoid_tracking.yaml")
    run.run_to(9.0)
    return run


def test_reanchoring_at_9s_would_fail_the_reach_check(demo_at_9s):
    """Why a restore must not re-run initialize: anchored at the pose of t = 9 s, the rest of
    the 0.5 m move would leave the arm's reach."""
    run = demo_at_9s
    fresh = run.make("controller", run.t_ns)
    run.feed("controller", fresh)  # the dynamics' state at t
    fresh.input_times_ns = {name: run.t_ns for name in fresh.inputs}
    with pytest.raises(ConfigError, match="out of reach"):
        fresh.initialize()


def test_computed_torque_dynamics_and_kepler_restore_mid_move(demo_at_9s):
    """The demo's three components restored at t = 9 s continue bit for bit for 0.3 s: the
    controller's anchor, posture, locked positions and quaternion signs, the dynamics' bodies,
    torques and orbit inputs, the orbit's quaternion sign all come from the state."""
    run = demo_at_9s
    controller = run.components["controller"]
    assert np.linalg.norm(controller.outputs["ee_position_desired"] - run.outputs["controller"]["ee_position"]) < 1e-5
    run.restore("orbit", "dynamics", "controller")
    run.step(300)
    assert run.t_ns == 9_300 * MS


def test_computed_torque_restores_the_positions_its_locked_joints_are_welded_at():
    """The demo with the locked left arm bent (the demo's is at q = 0): the restored model is
    welded where the run's initialize measured it, not at zero."""

    def bent_left_arm(config):
        q = config["components"]["dynamics"]["parameters"]["bodies"]["humanoid"]["q"]
        q.update(arm_left_1_joint=-0.4, arm_left_2_joint=0.3, arm_left_4_joint=-1.2)

    run = Run("humanoid_tracking.yaml", bent_left_arm)
    run.run_to(1.5)
    assert np.count_nonzero(decode_state(run.components["controller"].get_state())["locked_q"]) == 3
    run.restore("controller")
    run.step(100)


def test_computed_torque_restores_the_signs_of_its_output_quaternions():
    """The demo's controller on a base turning a full turn about z (inputs open loop): restored
    past the turn where q_W_ee's w changes sign, its ee_orientation keeps A's sign, not w >= 0."""
    spec = yaml.safe_load((CONFIGS / "humanoid_tracking.yaml").read_text())["components"]

    def make(t0_ns=0):
        return Harness(spec["controller"]["type"], spec["controller"]["parameters"], t0_ns=t0_ns, config_dir=CONFIGS)

    start = spec["dynamics"]["parameters"]["bodies"]["humanoid"]["q"]
    q0 = np.array([start.get(name, 0.0) for name in make().component.arm.model.movable_joints])

    def turned(h, k):
        angle = 2 * np.pi * k / 400
        h.inputs.update(q=q0, orientation=np.array([0.0, 0.0, np.sin(angle / 2), np.cos(angle / 2)]))

    a = make()
    turned(a, 0)
    a.initialize()
    for k in range(1, 341):
        turned(a, k)
        a.step(MS)
    assert a.outputs["ee_orientation"][3] < 0.0  # w >= 0 is the other sign
    b = restore(a, make)
    for k in range(341, 401):
        turned(a, k)
        turned(b, k)
        assert_same_outputs(b.step(MS), a.step(MS), f"controller at step {k}")


def test_computed_torque_restored_before_its_first_step_still_reanchors():
    """Listed before the dynamics, the controller initializes on start values and re-anchors at
    its first step; a restore between the two (a checkpoint at t0) carries that pending
    re-anchoring over. (A small move: the demo's 0.5 m one is out of reach of the start values'
    posture, q = 0.)"""

    def small_move(config):
        config["components"]["controller"]["parameters"]["trajectory"] = {
            "type": "waypoints",
            "waypoints": [{"time": 0.1, "position": [0.02, 0.0, 0.0]}],
        }

    def controller_first(config):
        small_move(config)
        config["components"] = {name: config["components"][name] for name in ("orbit", "controller", "dynamics")}

    run = Run("humanoid_tracking.yaml", controller_first)
    assert any(key.startswith("initial.") for key in decode_state(run.components["controller"].get_state()))
    run.restore("orbit", "controller", "dynamics")
    run.step(50)
    expected = Run("humanoid_tracking.yaml", small_move)  # anchored at initialize
    expected.step(50)
    assert np.allclose(
        run.outputs["controller"]["ee_position_desired"],
        expected.outputs["controller"]["ee_position_desired"],
        rtol=0,
        atol=1e-12,
    )


def test_joint_pd_restores_mid_trajectory():
    """controller.joint_pd (no shipped config: in the demo's place, as tests/component wire it)
    restored 0.8 s into a joint trajectory, its integral terms wound up: the reference and the
    integral terms come from the state."""

    def joint_pd(config):
        arm = [f"arm_right_{i}_joint" for i in range(1, 8)]
        gains = {j: {"p": 20.0, "d": 3.0, "i": 1.0, "i_clamp": 0.2} for j in arm[:4]}
        gains.update({j: {"p": 1.0, "d": 0.05} for j in arm[4:]})
        config["components"]["controller"] = {
            "type": "controller.joint_pd",
            "parameters": {
                "urdf": "../models/humanoid_torso.urdf",
                "gains": gains,
                "targets": {"arm_right_4_joint": -1.5},
                "trajectory": {
                    "start": 0.2,
                    "waypoints": [
                        {"time": 1.2, "q": {"arm_right_1_joint": -0.5}},
                        {"time": 2.0, "q": {"arm_right_2_joint": -2.0}},
                    ],
                },
            },
        }

    run = Run("humanoid_tracking.yaml", joint_pd)
    run.run_to(1.0)
    assert np.all(decode_state(run.components["controller"].get_state())["i_term"][:4] != 0.0)
    run.restore("orbit", "dynamics", "controller")
    run.step(300)


# --------------------------------------------------------------------------- dynamics and orbits


def test_dynamics_restores_in_the_free_floating_humanoid():
    """configs/free_floating_humanoid.yaml (rk4, 2 substeps, link outputs) restored at 2 s."""
    run = Run("free_floating_humanoid.yaml")
    run.run_to(2.0)
    run.restore("orbit", "dynamics")
    run.run_to(2.5)


@pytest.mark.parametrize("engine", ["dart", "pinocchio"])
def test_dynamics_restores_with_a_joint_resting_on_a_limit_stop(engine):
    """The same with the right shoulder (arm_right_2_joint) thrown against its upper limit: it
    rests on the stop from t = 2.02 s; restored at 3 s, the stop comes from the state. Either
    engine (dynamics.dart, dynamics.pinocchio)."""

    def thrown(config):
        config["components"]["dynamics"]["type"] = f"dynamics.{engine}"
        config["components"]["dynamics"]["parameters"]["bodies"]["humanoid"]["qd"]["arm_right_2_joint"] = 0.3

    run = Run("free_floating_humanoid.yaml", thrown)
    run.run_to(3.0)
    assert np.count_nonzero(decode_state(run.components["dynamics"].get_state())["humanoid.stop_side"]) == 1
    run.restore("orbit", "dynamics")
    run.run_to(4.0)


def test_dynamics_restores_in_the_gravity_gradient_libration():
    """configs/gravity_gradient_libration.yaml (10 s steps) restored after 30 min."""
    run = Run("gravity_gradient_libration.yaml")
    run.run_to(1800.0)
    run.restore("orbit", "dynamics")
    run.run_to(2400.0)


@pytest.mark.parametrize(
    "config, at, until",
    [
        ("orbit_iss_kepler.yaml", 2700.0, 2760.0),
        ("orbit_iss_sgp4.yaml", 2700.0, 2760.0),
        ("custom_path.yaml", 5340.0, 5460.0),  # across the last waypoint (90 min): after_end hold
    ],
)
def test_orbit_restores(config, at, until):
    run = Run(config)
    run.run_to(at)
    run.restore("orbit")
    run.run_to(until)


def test_orbit_fixed_restores():
    """orbit.fixed (no shipped config): a quaternion with w < 0 keeps its sign through a restore."""

    def make(t0_ns=0):
        return Harness("orbit.fixed", {"r_eci": [7e6, 0.0, 0.0], "q_eci_lvlh": [0.0, 0.6, 0.0, -0.8]}, t0_ns=t0_ns)

    a = make()
    a.initialize()
    for _ in range(3):
        a.step(S)
    b = restore(a, make)
    for _ in range(3):
        assert_same_outputs(b.step(S), a.step(S), "orbit.fixed")


# --------------------------------------------------------------------------- examples and test blocks


def test_user_component_oscillator_and_constant_restore():
    """configs/user_component.yaml: the README's oscillator and a test.constant, restored at 5 s."""
    run = Run("user_component.yaml")
    run.run_to(5.0)
    run.restore("push", "spring")
    run.run_to(5.2)


@pytest.mark.parametrize(
    "type_name, params, u",
    [
        ("test.counter", {}, None),
        ("test.constant", {"value": 2.5}, None),
        ("test.integrator", {"gain": 0.3, "x0": 1.0}, lambda k: 0.1 * k - 0.4),
        ("test.noop", {"size": 3}, lambda k: [k, -k, 0.5]),
        ("test.faulty", {"fault": "nan", "at_step": 8}, None),
    ],
)
def test_test_blocks_restore(type_name, params, u):
    """The test blocks, restored after 5 steps; test.faulty misbehaves at the same step (its
    step count is its state)."""

    def make(t0_ns=0):
        return Harness(type_name, params, t0_ns=t0_ns)

    def step(h, k):
        if u is not None:
            h.inputs["u"] = u(k)
        return h.step(MS)

    a = make()
    a.initialize()
    for k in range(5):
        step(a, k)
    b = restore(a, make)
    for k in range(5, 10):
        got, expected = step(b, k), step(a, k)
        assert got.keys() == expected.keys()
        for key in expected:
            assert bit_equal(got[key], expected[key]), (type_name, k, key)
        if type_name == "test.faulty":
            assert np.isnan(got["y"]) == (k >= 8)  # stuck at its faulty step
